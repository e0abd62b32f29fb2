"""The distance-time campaign kind: the times at which each run passes known distances.

Markers along the track (cones filmed by a camera, the light gates of a speed trap, lines on a
model track: seed 002's speed-trap method) give per run the time the vehicle passes each known
distance, not a speed trace.  Such a campaign is a directory with ``distances.csv`` (instead of
``runs.csv`` or ``intervals.csv``: two of them together are refused as ambiguous) and the same
``vehicle.toml`` (and, simulated, ``truth.json``); :func:`~bayes_roadload.data.load_campaign`
returns a :class:`DistanceCampaign` for it.  One row per marker passed; the format is in
``docs/data-format.md``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .. import config
from .ambient import check_humidity_percent
from .checks import (
    AMBIENT_LIMITS,
    read_csv_table,
    UNIT_HINTS,
    check_columns,
    check_contiguous,
    check_csv_format,
    check_direction_codes,
    check_no_missing,
    check_not_empty,
    check_numeric,
    check_pair_groups,
    check_run_constants,
    data_file,
    plain_value,
    read_truth,
    refuse,
    run_directions,
    run_ids_of,
    run_rows,
    subset_table,
    table_pairs,
    truth_files,
)
from .uncertainty import TypeBChannels
from .vehicle import VEHICLE_FILE, Anemometer, Vehicle, read_vehicle_file, validate_vehicle, vehicle_toml

KIND = "distances"
FILES = ("distances.csv",)
DESCRIPTION = "distance-time records"
OPTIONS: tuple[str, ...] = ()
OPTIONAL_FILES: tuple[str, ...] = ()

DISTANCE_REQUIRED = ("run", "distance_m", "time_s")
DISTANCE_RUN_CONSTANT = ("direction", "pair", "mass_kg", "temperature_k", "pressure_pa", "relative_humidity_pct")
DISTANCE_OPTIONAL = DISTANCE_RUN_CONSTANT
DISTANCE_COLUMNS = DISTANCE_REQUIRED + DISTANCE_OPTIONAL
_TEXT_COLUMNS = ("run", "pair")

_DISTANCE_HINTS = dict(UNIT_HINTS, **{
    "distance": "distance_m (metres)",
    "distance_km": "distance_m (metres): multiply km by 1000",
    "distance_ft": "distance_m (metres): multiply feet by 0.3048",
    "position_m": "distance_m (the marker's distance along the run, metres)",
    "time_ms": "time_s (seconds): divide ms by 1000",
    "speed_mps": "a speed trace (runs.csv); a distance-time campaign holds only distance_m and time_s",
    "interval_s": "a speed-gate campaign (intervals.csv); a distance-time campaign holds distance_m and time_s",
})

_LIMITS = {
    "distance_m": (-1.0e5, 1.0e5, "not a distance in metres"),
    **AMBIENT_LIMITS,
    "mass_kg": config.MASS_RANGE_KG + ("not a test mass in kg",),
}


@dataclass
class DistanceCampaign:
    """A loaded, validated distance-time campaign.

    Attributes
    ----------
    markers : one row per marker passed (columns of :data:`DISTANCE_COLUMNS`); the markers of a
        run are contiguous rows in increasing distance and time.
    vehicle, anemometer, tunnel, truth, meta : as :class:`~bayes_roadload.data.Campaign` (the
        anemometer is unused: a distance-time record carries no air data).
    """

    markers: pd.DataFrame
    vehicle: Vehicle
    anemometer: Anemometer = field(default_factory=Anemometer)
    tunnel: dict[str, Any] | None = None
    truth: dict[str, Any] | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    kind = KIND
    type_b_channels = TypeBChannels("markers")  # surveyed markers and a clock: no speed sensor
    has_anemometer = False
    has_driveline = False
    has_track_survey = False  # track.csv is read with speed traces only

    def __post_init__(self):
        self.markers = validate_distances(self.markers, "distances")
        validate_vehicle(self.vehicle, "vehicle")

    @property
    def run_ids(self) -> list:
        return run_ids_of(self.markers)

    def run_table(self) -> pd.DataFrame:
        """One row per run: run, the run constants present, the number of markers, the
        distance and time between the first and the last, and the mean speed over them."""
        g = self.markers.groupby("run", sort=False)
        out = g.first()[[c for c in DISTANCE_RUN_CONSTANT if c in self.markers]].copy()
        out["markers"] = g.size()
        out["span_m"] = g["distance_m"].last() - g["distance_m"].first()
        out["span_s"] = g["time_s"].last() - g["time_s"].first()
        out["mean_speed_mps"] = out["span_m"] / out["span_s"]
        out.index = [plain_value(r) for r in out.index]
        out.index.name = "run"
        return out.reset_index()

    def directions(self) -> dict:
        """run id -> +1/-1 (every run +1 when the column is absent)."""
        return run_directions(self.markers)

    def masses_kg(self) -> dict:
        """run id -> the run's test mass (``[vehicle] mass_kg`` when the column is absent)."""
        if "mass_kg" not in self.markers:
            return {r: float(self.vehicle.mass_kg) for r in self.run_ids}
        return {plain_value(r): float(m) for r, m in self.markers.groupby("run", sort=False)["mass_kg"].first().items()}

    def pairs(self) -> list[tuple]:
        """Opposite-direction pairs: by the ``pair`` column, else consecutive runs in file order."""
        return table_pairs(self.markers, self.run_ids)

    def subset(self, run_ids) -> "DistanceCampaign":
        """The campaign restricted to some runs (order as given)."""
        return DistanceCampaign(subset_table(self.markers, run_ids), self.vehicle, self.anemometer, self.tunnel,
                                self.truth, dict(self.meta))


def validate_distances(df: pd.DataFrame, where: str = "distances.csv") -> pd.DataFrame:
    """Check a distance-time table against the contract and return a normalised copy (rows
    1-based over the data rows).

    Refused: unknown or unit-ambiguous columns, missing required ones, non-finite values,
    values out of range, the markers of a run not contiguous, distance or time not strictly
    increasing within a run, fewer than ``config.MIN_DISTANCE_MARKERS`` markers in a run, a
    mean speed between two markers outside ``config.DISTANCE_SEGMENT_SPEED_RANGE_MPS`` (km or
    mm in the metre column, ms in the second column), a run-level column changing within a run.
    """
    df = df.copy()
    cols = check_columns(df, DISTANCE_COLUMNS, DISTANCE_REQUIRED, _DISTANCE_HINTS, "a distance-time campaign", where)
    check_not_empty(df, "markers", where)
    for c in _TEXT_COLUMNS:
        if c in cols:
            check_no_missing(df, c, f"missing {c}", where)
    check_numeric(df, [c for c in cols if c not in _TEXT_COLUMNS], _LIMITS, where)
    check_humidity_percent(df, where)
    check_direction_codes(df, where)
    lo_v, hi_v = config.DISTANCE_SEGMENT_SPEED_RANGE_MPS
    for rid, rows in run_rows(df):
        check_contiguous(rows, rid, "markers", where)
        if len(rows) < config.MIN_DISTANCE_MARKERS:
            refuse(where, "run", int(rows[0]) + 1, f"run {rid!r} passes {len(rows)} markers; at least "
                  f"{config.MIN_DISTANCE_MARKERS} are needed (its speed at the first is unknown)")
        x = df["distance_m"].to_numpy()[rows]
        t = df["time_s"].to_numpy()[rows]
        for name, d in (("distance_m", np.diff(x)), ("time_s", np.diff(t))):
            if np.any(d <= 0):
                i = int(rows[np.flatnonzero(d <= 0)[0] + 1])
                refuse(where, name, i + 1, f"{name} does not increase within run {rid!r} (markers in the order "
                      "passed, distances counted along the direction of travel)")
        speed = np.diff(x) / np.diff(t)
        out = (speed < lo_v) | (speed > hi_v)
        if out.any():
            i = int(rows[np.flatnonzero(out)[0] + 1])
            refuse(where, "time_s", i + 1, f"run {rid!r}: mean speed {speed[out][0]:g} m/s since the previous marker "
                  f"is outside [{lo_v:g}, {hi_v:g}] m/s (km or mm in distance_m, or ms in time_s?)")
        check_run_constants(df, rows, DISTANCE_RUN_CONSTANT, rid, where)
    check_pair_groups(df, where)
    return df.reset_index(drop=True)


def read_distances(path) -> pd.DataFrame:
    """``distances.csv`` as a table."""
    return read_csv_table(path)


def load(root: str | os.PathLike) -> DistanceCampaign:
    """Load and validate a distance-time campaign directory (``distances.csv``,
    ``vehicle.toml``, optional ``truth.json``)."""
    root = Path(root)
    f = data_file(root, "distances.csv")
    vehicle, anem, tunnel, meta = read_vehicle_file(root / VEHICLE_FILE)
    df = validate_distances(read_distances(f), str(f))
    return DistanceCampaign(df, vehicle, anem, tunnel, read_truth(root), meta)


def files(c: DistanceCampaign, fmt: str = "csv") -> dict[str, str]:
    """The files of a distance-time campaign directory (name -> text), validated first:
    ``distances.csv``, ``vehicle.toml``, ``truth.json`` when the truth is known."""
    check_csv_format(fmt, "a distance-time campaign", "distances.csv")
    c.markers = validate_distances(c.markers, "distances")
    return ({"distances.csv": c.markers.to_csv(index=False, float_format="%.12g"), VEHICLE_FILE: vehicle_toml(c)}
            | truth_files(c.truth))
