"""The interval-time campaign kind: speed-gate records instead of speed traces.

A speed-gate logger (Racelogic VBOX "Coastdown", the NBR / "split" method, a speed trap) keeps
per run the time to coast through consecutive speed bands, not the speed trace.  Such a
campaign is a directory with ``intervals.csv`` (instead of ``runs.csv``) and the same
``vehicle.toml`` (and, simulated, ``truth.json``); :func:`~bayes_roadload.data.load_campaign`
returns an :class:`IntervalCampaign` for it.  One row per band; the format is in
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
    pairs_by_column,
    plain_value,
    read_truth,
    refuse,
    run_directions,
    run_ids_of,
    run_rows,
    subset_table,
    truth_files,
)
from .uncertainty import TypeBChannels
from .vehicle import VEHICLE_FILE, Anemometer, Vehicle, read_vehicle_file, validate_vehicle, vehicle_toml

KIND = "intervals"
FILES = ("intervals.csv",)
DESCRIPTION = "speed-gate interval times"
OPTIONS: tuple[str, ...] = ()
OPTIONAL_FILES: tuple[str, ...] = ()

INTERVAL_REQUIRED = ("run", "speed_start_mps", "speed_end_mps", "interval_s")
RUN_CONSTANT_COLUMNS = ("direction", "pair", "window", "valid", "run_distance_m", "start_time_of_day_s",
                        "temperature_k", "pressure_pa", "relative_humidity_pct", "mass_kg")
INTERVAL_OPTIONAL = RUN_CONSTANT_COLUMNS
INTERVAL_COLUMNS = INTERVAL_REQUIRED + INTERVAL_OPTIONAL
_TEXT_COLUMNS = ("run", "pair", "window")

_INTERVAL_HINTS = dict(UNIT_HINTS, **{
    "speed_start_kph": "speed_start_mps (m/s): divide km/h by 3.6",
    "speed_end_kph": "speed_end_mps (m/s): divide km/h by 3.6",
    "interval": "interval_s (seconds)",
    "time": "interval_s (the time to coast through the band, seconds)",
    "t": "interval_s (the time to coast through the band, seconds)",
    "time_s": "interval_s (the time to coast through the band, seconds)",
    "speed_mps": "speed_start_mps and speed_end_mps (an interval campaign has no speed trace)",
})

_LIMITS = {
    "speed_start_mps": (0.0, config.MAX_SPEED_MPS, "negative, or km/h in a m/s column"),
    "speed_end_mps": (0.0, config.MAX_SPEED_MPS, "negative, or km/h in a m/s column"),
    "interval_s": (0.0, 3600.0, "not a band time in seconds"),
    "run_distance_m": (0.0, 1.0e5, "not a distance in metres"),
    "start_time_of_day_s": (0.0, 86400.0, "seconds since midnight"),
    **AMBIENT_LIMITS,
    "mass_kg": config.MASS_RANGE_KG + ("not a test mass in kg",),
}


@dataclass
class IntervalCampaign:
    """A loaded, validated interval-time campaign.

    Attributes
    ----------
    intervals : one row per speed band (columns of :data:`INTERVAL_COLUMNS`); the bands of a
        run are contiguous rows in falling speed, each ending where the next starts.
    vehicle, anemometer, tunnel, truth, meta : as :class:`~bayes_roadload.data.Campaign`
        (the anemometer is unused: speed-gate records carry no air data).
    """

    intervals: pd.DataFrame
    vehicle: Vehicle
    anemometer: Anemometer = field(default_factory=Anemometer)
    tunnel: dict[str, Any] | None = None
    truth: dict[str, Any] | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    kind = KIND
    type_b_channels = TypeBChannels("intervals", speed=("speed_start_mps", "speed_end_mps"))

    def __post_init__(self):
        self.intervals = validate_intervals(self.intervals, "intervals")
        validate_vehicle(self.vehicle, "vehicle")

    has_anemometer = False
    has_driveline = False
    has_track_survey = False  # track.csv is read with speed traces only

    @property
    def run_ids(self) -> list:
        return run_ids_of(self.intervals)

    def run_table(self) -> pd.DataFrame:
        """One row per run: run, direction, pair, window, valid, band count, total time, and
        the optional run constants."""
        g = self.intervals.groupby("run", sort=False)
        out = g.first()[[c for c in RUN_CONSTANT_COLUMNS if c in self.intervals]].copy()
        out["bands"] = g.size()
        out["total_time_s"] = g["interval_s"].sum()
        out["speed_start_mps"] = g["speed_start_mps"].first()
        out["speed_end_mps"] = g["speed_end_mps"].last()
        out.index = [plain_value(r) for r in out.index]
        out.index.name = "run"
        return out.reset_index()

    def directions(self) -> dict:
        return run_directions(self.intervals)

    def windows(self) -> dict:
        """run id -> window label ("all" when the column is absent)."""
        if "window" not in self.intervals:
            return {r: "all" for r in self.run_ids}
        return {plain_value(r): str(w) for r, w in self.intervals.groupby("run", sort=False)["window"].first().items()}

    def pairs(self) -> list[tuple]:
        """Opposite-direction pairs: by the ``pair`` column, else consecutive runs of the same
        window with opposite directions, in file order."""
        by_column = pairs_by_column(self.intervals)
        if by_column is not None:
            return by_column
        d, w = self.directions(), self.windows()
        out, waiting = [], {}
        for r in self.run_ids:
            other = waiting.get(w[r])
            if other is not None and d[other] != d[r]:
                out.append((other, r))
                waiting[w[r]] = None
            else:
                waiting[w[r]] = r
        return out

    def subset(self, run_ids) -> "IntervalCampaign":
        """The campaign restricted to some runs (order as given)."""
        return IntervalCampaign(subset_table(self.intervals, run_ids), self.vehicle, self.anemometer, self.tunnel,
                                self.truth, dict(self.meta))


def validate_intervals(df: pd.DataFrame, where: str = "intervals.csv") -> pd.DataFrame:
    """Check an interval table against the contract and return a normalised copy (rows
    1-based over the data rows)."""
    df = df.copy()
    cols = check_columns(df, INTERVAL_COLUMNS, INTERVAL_REQUIRED, _INTERVAL_HINTS, "an interval campaign", where)
    check_not_empty(df, "intervals", where)
    for c in _TEXT_COLUMNS:
        if c in cols:
            check_no_missing(df, c, f"missing {c}", where)
    if "window" in cols:
        df["window"] = df["window"].astype(str)
    check_numeric(df, [c for c in cols if c not in _TEXT_COLUMNS], _LIMITS, where)
    check_humidity_percent(df, where)
    if (df["interval_s"] <= 0).any():
        i = int(np.flatnonzero(df["interval_s"].to_numpy() <= 0)[0])
        refuse(where, "interval_s", i + 1, "a band time must be positive")
    drop = df["speed_start_mps"].to_numpy() - df["speed_end_mps"].to_numpy()
    if (drop <= 0).any():
        i = int(np.flatnonzero(drop <= 0)[0])
        refuse(where, "speed_end_mps", i + 1, "the band's end speed is not below its start speed (a coastdown "
              "decelerates)")
    check_direction_codes(df, where)
    if "valid" in cols and not np.isin(df["valid"].to_numpy(), (0.0, 1.0)).all():
        i = int(np.flatnonzero(~np.isin(df["valid"].to_numpy(), (0.0, 1.0)))[0])
        refuse(where, "valid", i + 1, "valid must be 1 (run used) or 0 (run excluded)")
    for rid, rows in run_rows(df):
        check_contiguous(rows, rid, "bands", where)
        start = df["speed_start_mps"].to_numpy()[rows]
        end = df["speed_end_mps"].to_numpy()[rows]
        gap = np.abs(start[1:] - end[:-1]) > 1e-6
        if gap.any():
            i = int(rows[np.flatnonzero(gap)[0] + 1])
            refuse(where, "speed_start_mps", i + 1, f"run {rid!r}: a band does not start where the previous one "
                  "ended (bands must be consecutive, in falling speed)")
        check_run_constants(df, rows, RUN_CONSTANT_COLUMNS, rid, where)
    check_pair_groups(df, where)
    return df.reset_index(drop=True)


def read_intervals(path) -> pd.DataFrame:
    """``intervals.csv`` as a table (window labels as text)."""
    return read_csv_table(path, dtype={"window": str})


def load(root: str | os.PathLike) -> IntervalCampaign:
    """Load and validate an interval campaign directory (``intervals.csv``, ``vehicle.toml``,
    optional ``truth.json``)."""
    root = Path(root)
    f = data_file(root, "intervals.csv")
    vehicle, anem, tunnel, meta = read_vehicle_file(root / VEHICLE_FILE)
    df = validate_intervals(read_intervals(f), str(f))
    return IntervalCampaign(df, vehicle, anem, tunnel, read_truth(root), meta)


def files(c: IntervalCampaign, fmt: str = "csv") -> dict[str, str]:
    """The files of an interval campaign directory (name -> text), validated first:
    ``intervals.csv``, ``vehicle.toml``, ``truth.json`` when the truth is known."""
    check_csv_format(fmt, "an interval campaign", "intervals.csv")
    c.intervals = validate_intervals(c.intervals, "intervals")
    return ({"intervals.csv": c.intervals.to_csv(index=False, float_format="%.10g"), VEHICLE_FILE: vehicle_toml(c)}
            | truth_files(c.truth))
