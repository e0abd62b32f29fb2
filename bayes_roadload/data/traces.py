"""The speed-trace campaign kind: ``runs.csv`` (or ``runs.parquet``) + ``vehicle.toml``.

A campaign directory holds ``runs.csv`` (or ``runs.parquet``), ``vehicle.toml``, optionally a
level survey of the track (``track.csv``, :mod:`~bayes_roadload.data.track`) and, for
simulated campaigns, ``truth.json``.  One row per sample of a coastdown run; the format is in
``docs/data-format.md``.  Loading validates everything and raises
:class:`~bayes_roadload.data.checks.CampaignError` naming the file, the column and the row at
fault; saving validates first and writes nothing when the input is refused.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .. import config
from .ambient import air_density, check_humidity_percent, mean_air_density
from ..physics.integrate import make_run, stack_runs
from .checks import (
    read_csv_table,
    CHANNEL_LIMITS,
    UNIT_HINTS,
    CampaignError,
    check_columns,
    check_contiguous,
    check_direction_codes,
    check_min_samples,
    check_no_missing,
    check_not_empty,
    check_numeric,
    check_pair_groups,
    numeric_and_text_ids,
    check_run_constants,
    check_time_increases,
    check_anemometer_pair,
    check_wheel_torque_pair,
    read_truth,
    refuse,
    run_directions,
    run_ids_of,
    run_rows,
    subset_table,
    table_pairs,
    truth_files,
    wheel_torque_force_n,
)
from .units import check_plausible_airspeed, check_plausible_road_load, convert_units
from .track import TRACK_FILE, check_runs_on_track, grade_at, validate_track
from .uncertainty import TypeBChannels
from .vehicle import VEHICLE_FILE, Anemometer, Vehicle, read_vehicle_file, validate_vehicle, vehicle_toml

KIND = "traces"
FILES = ("runs.csv", "runs.parquet")
DESCRIPTION = "speed traces"
OPTIONS: tuple[str, ...] = ("speed_unit", "airspeed_unit")
OPTIONAL_FILES: tuple[str, ...] = (TRACK_FILE,)

REQUIRED_COLUMNS = ("run", "time_s", "speed_mps")
OPTIONAL_COLUMNS = (
    "direction",
    "pair",
    "airspeed_mps",
    "yaw_rad",
    "driveline_force_n",
    "wheel_torque_left_nm",
    "wheel_torque_right_nm",
    "distance_m",
    "position_m",
    "temperature_k",
    "pressure_pa",
    "relative_humidity_pct",
    "mass_kg",
)
KNOWN_COLUMNS = REQUIRED_COLUMNS + OPTIONAL_COLUMNS
RUN_CONSTANT_COLUMNS = ("direction", "pair", "mass_kg")


@dataclass
class Campaign:
    """A loaded, validated campaign of speed traces.

    Attributes
    ----------
    runs : one row per sample, contract columns (wheel torques already converted to
        ``driveline_force_n``).
    vehicle, anemometer : from vehicle.toml.
    tunnel : the optional ``[tunnel]`` table (KD, CD0, CL0, KL, yaw_deg, cd).
    truth : the true parameters of a simulated campaign, else None.
    meta : free-form provenance (e.g. the simulation case), saved in vehicle.toml ``[meta]``.
    track : the level survey of the track (``position_m``, ``elevation_m``; ``track.csv``),
        else None; with it the runs must log ``position_m`` inside the surveyed stretch.
    """

    runs: pd.DataFrame
    vehicle: Vehicle
    anemometer: Anemometer = field(default_factory=Anemometer)
    tunnel: dict[str, Any] | None = None
    truth: dict[str, float] | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    track: pd.DataFrame | None = None

    kind = KIND
    # the position along the track is a GNSS or surveyed coordinate, which a speed sensor's scale
    # error does not move (nor the surveyed grade read at it)
    type_b_channels = TypeBChannels("runs", speed=("speed_mps", "distance_m"), force=("driveline_force_n",))

    def __post_init__(self):
        self.runs = validate_runs(self.runs, "runs")
        validate_vehicle(self.vehicle, "vehicle")
        if self.track is not None:
            self.track = validate_track(self.track, "track")
            check_runs_on_track(self.runs, self.track, "runs")

    @property
    def run_ids(self) -> list:
        """Run ids in file order, as plain Python values."""
        return run_ids_of(self.runs)

    @property
    def has_anemometer(self) -> bool:
        return "airspeed_mps" in self.runs and "yaw_rad" in self.runs

    @property
    def has_driveline(self) -> bool:
        return "driveline_force_n" in self.runs

    @property
    def has_track_survey(self) -> bool:
        """Whether the campaign states the track's elevation (``track.csv``)."""
        return self.track is not None

    def directions(self) -> dict:
        """run id -> +1/-1 (every run +1 when the column is absent)."""
        return run_directions(self.runs)

    def pairs(self) -> list[tuple]:
        """Opposite-direction pairs of run ids: by the ``pair`` column when present, else
        consecutive runs in file order.  A run left without a partner is dropped, and so is a
        ``pair`` group of 40 CFR 1037 split segments (:func:`~.checks.check_pair_groups`)."""
        return table_pairs(self.runs, self.run_ids)

    def subset(self, run_ids) -> "Campaign":
        """The campaign restricted to some runs (order as given)."""
        return Campaign(subset_table(self.runs, run_ids), self.vehicle, self.anemometer,
                        self.tunnel, self.truth, dict(self.meta), self.track)

    def _airspeed_readings(self, g: pd.DataFrame):
        """One run's airspeed readings with the anemometer's stated yaw calibration applied
        (:meth:`~bayes_roadload.data.vehicle.Anemometer.yaw_corrected_airspeed`); None without
        the anemometer (its two channels come together: :func:`~.checks.check_anemometer_pair`)."""
        if "airspeed_mps" not in g:
            return None
        return self.anemometer.yaw_corrected_airspeed(g["airspeed_mps"].to_numpy(float), g["yaw_rad"].to_numpy(float))

    def to_batch(self):
        """The runs as a padded :class:`~bayes_roadload.physics.RunBatch` (time from each
        run's first sample; the surveyed grade at each logged position when the campaign has a
        track survey, :func:`~bayes_roadload.data.track.grade_at`) and the list of run ids in
        batch order.  ``meta["pad_to_samples"]``
        pads every run to at least that many samples (studies of many same-sized campaigns then
        share one compiled fit); with ``BAYES_ROADLOAD_SHARE_PROGRAMS=1`` the length is then
        rounded up to the next of :data:`~bayes_roadload.config.PAD_SIZES_PER_OCTAVE` sizes per
        doubling (:func:`~bayes_roadload.physics.integrate.bucket_length`), so that campaigns of
        nearly the same length share their compiled programs too."""
        runs = []
        v = self.vehicle
        for rid, g in self.runs.groupby("run", sort=False):
            t = g["time_s"].to_numpy(float)
            temp = g["temperature_k"].to_numpy(float) if "temperature_k" in g else config.REFERENCE_TEMPERATURE_K
            direction = float(g["direction"].iloc[0]) if "direction" in g else 1.0
            start = float(g["position_m"].iloc[0]) if "position_m" in g else 0.0
            # a run's own test mass (several masses in one campaign): the rotating inertia, and so
            # M_e - M, does not change with the load
            mass = float(g["mass_kg"].iloc[0]) if "mass_kg" in g else v.mass_kg
            runs.append(make_run(
                t - t[0],
                g["speed_mps"].to_numpy(float),
                airspeed_mps=self._airspeed_readings(g),
                yaw_rad=g["yaw_rad"].to_numpy(float) if "yaw_rad" in g else None,
                driveline_force_n=g["driveline_force_n"].to_numpy(float) if "driveline_force_n" in g else None,
                air_density_kgpm3=air_density(g),
                temperature_k=temp,
                track_grade_rad=grade_at(self.track, g["position_m"].to_numpy(float)) if self.track is not None else None,
                direction=direction,
                start_position_m=start,
                mass_kg=mass,
                effective_mass_kg=v.effective_mass_kg + (mass - v.mass_kg),
                frontal_area_m2=v.frontal_area_m2,
            ))
        return stack_runs(runs, self.meta.get("pad_to_samples"), config.PAD_SIZES_PER_OCTAVE), self.run_ids


def validate_runs(df: pd.DataFrame, where: str = "runs.csv") -> pd.DataFrame:
    """Check a runs table against the contract and return a normalised copy.

    Rows are reported 1-based over the data rows (row 1 is the first line after the header).
    Wheel torques are converted to ``driveline_force_n`` by the caller (:func:`load`), which
    knows the rolling radius.
    """
    df = df.copy()
    cols = check_columns(df, KNOWN_COLUMNS, REQUIRED_COLUMNS, UNIT_HINTS, "the contract", where)
    check_anemometer_pair(cols, where)
    check_not_empty(df, "samples", where)
    check_no_missing(df, "run", "missing run id", where)
    check_numeric(df, numeric_and_text_ids(df, [c for c in cols if c != "run"], ("pair",), where), CHANNEL_LIMITS,
                  where)
    check_humidity_percent(df, where)
    check_direction_codes(df, where)
    if check_wheel_torque_pair(cols, where) and "driveline_force_n" in cols:
        refuse(where, "driveline_force_n", None,
               "give either driveline_force_n or the wheel torques, not both (ambiguous)")
    for rid, rows in run_rows(df):
        check_min_samples(rows, rid, where)
        check_contiguous(rows, rid, "samples", where)
        check_time_increases(df["time_s"].to_numpy()[rows], rows, rid, where)
        check_run_constants(df, rows, RUN_CONSTANT_COLUMNS, rid, where)
        check_moving(df["speed_mps"].to_numpy(float)[rows], rows, rid, where)
    check_pair_groups(df, where, split_segments=True)
    return df.reset_index(drop=True)


def check_moving(speed_mps: np.ndarray, rows: np.ndarray, rid, where: str) -> None:
    """Refuse a run with a sample at or below :data:`~bayes_roadload.config.STANDSTILL_MPS`,
    naming its first such row: the coastdown model describes a rolling vehicle, so a run ends
    before the vehicle stops."""
    slow = np.flatnonzero(speed_mps <= config.STANDSTILL_MPS)
    if slow.size:
        i = int(slow[0])
        refuse(where, "speed_mps", int(rows[i]) + 1,
               f"run {rid!r}: speed {speed_mps[i]:g} m/s, at or below standstill ({config.STANDSTILL_MPS:g} m/s): "
               "the model describes a rolling vehicle; end the run at its last sample above that speed")


def read_runs(root: str | os.PathLike) -> tuple[pd.DataFrame, Path]:
    """The runs table of a campaign directory as read, and its file; refused when both
    ``runs.csv`` and ``runs.parquet`` are present or neither is."""
    root = Path(root)
    csv, parquet = (root / name for name in FILES)
    if csv.exists() and parquet.exists():
        raise CampaignError(f"{root}: both runs.csv and runs.parquet present (ambiguous)")
    if csv.exists():
        return read_csv_table(csv), csv
    if parquet.exists():
        try:
            return pd.read_parquet(parquet), parquet
        except ImportError as e:  # pragma: no cover - depends on optional pyarrow
            raise CampaignError(f"{parquet}: reading parquet needs pyarrow ({e})") from e
    raise CampaignError(f"{root}: runs.csv (or runs.parquet) is missing")


def load(root: str | os.PathLike, speed_unit: str | None = None, airspeed_unit: str | None = None) -> Campaign:
    """Load and validate a speed-trace campaign directory (``runs.csv`` or ``runs.parquet``,
    ``vehicle.toml``, optional ``track.csv`` and ``truth.json``).

    Columns whose name states a non-SI unit, and the speed / airspeed columns whose unit
    ``speed_unit`` / ``airspeed_unit`` state (``mps``, ``kph``, ``mph``), are converted to SI
    (:func:`~bayes_roadload.data.units.convert_units`; recorded in ``meta["conversions"]``);
    speeds whose implied road load says they were logged in km/h or mph are refused
    (:func:`~bayes_roadload.data.units.check_plausible_road_load`), and so are times whose implied
    road load says they were logged in milliseconds (``time_ms`` is converted), and airspeeds
    exceeding the speeds by more than any admitted wind and plausible in km/h or mph
    (:func:`~bayes_roadload.data.units.check_plausible_airspeed`).  Wheel torques become
    ``driveline_force_n`` = (left + right) / R_r.
    """
    root = Path(root)
    df, runs_file = read_runs(root)
    vehicle, anem, tunnel, meta = read_vehicle_file(root / VEHICLE_FILE)
    df, conversions = convert_units(df, str(runs_file), speed_unit, airspeed_unit)
    df = validate_runs(df, str(runs_file))
    check_plausible_airspeed(df, str(runs_file), anem.airspeed_factor)
    time_column = next((c.column for c in conversions if c.to == "time_s"), "time_s")
    check_plausible_road_load(df, str(runs_file), vehicle.effective_mass_kg, vehicle.mass_kg, mean_air_density(df),
                              time_column)
    if "wheel_torque_left_nm" in df:
        df["driveline_force_n"] = wheel_torque_force_n(df, vehicle.rolling_radius_m)
    if conversions:
        meta = dict(meta, conversions=[c.record() for c in conversions])
    track = None
    if (root / TRACK_FILE).exists():
        track = validate_track(read_csv_table(root / TRACK_FILE), str(root / TRACK_FILE))
        check_runs_on_track(df, track, str(runs_file))
    return Campaign(df, vehicle, anem, tunnel, read_truth(root), meta, track)


def files(c: Campaign, fmt: str = "csv") -> dict[str, str | bytes]:
    """The files of a speed-trace campaign directory (name -> content), validated first:
    ``runs.csv`` (``fmt="csv"``) or ``runs.parquet`` (``fmt="parquet"``), ``vehicle.toml``,
    ``track.csv`` with a track survey, ``truth.json`` when the truth is known."""
    c.runs = validate_runs(c.runs, "runs")
    if fmt == "csv":
        out: dict[str, str | bytes] = {"runs.csv": c.runs.to_csv(index=False, float_format="%.10g")}
    elif fmt == "parquet":
        out = {"runs.parquet": c.runs.to_parquet(None, index=False)}
    else:
        raise ValueError(f"fmt must be 'csv' or 'parquet', not {fmt!r}")
    if c.track is not None:
        c.track = validate_track(c.track, "track")
        check_runs_on_track(c.runs, c.track, "runs")
        out[TRACK_FILE] = c.track.to_csv(index=False, float_format="%.10g")
    return out | {VEHICLE_FILE: vehicle_toml(c)} | truth_files(c.truth)
