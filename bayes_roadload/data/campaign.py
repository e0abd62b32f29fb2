"""The campaign data contract: load, validate and save a directory of coastdown runs.

A campaign directory holds ``runs.csv`` (or ``runs.parquet``), ``vehicle.toml`` and, for
simulated campaigns, ``truth.json``.  The format is documented in ``docs/data-format.md``.
Loading validates everything and raises :class:`CampaignError` naming the file, the column and
the row at fault; saving validates first and writes nothing when the input is refused.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import pandas as pd

from .. import config

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
    "mass_kg",
)
KNOWN_COLUMNS = REQUIRED_COLUMNS + OPTIONAL_COLUMNS

# Columns whose names say a unit the contract does not use: refuse rather than guess.
_AMBIGUOUS_HINTS = {
    "speed": "speed_mps (m/s)",
    "speed_kph": "speed_mps (m/s): divide km/h by 3.6",
    "speed_kmh": "speed_mps (m/s): divide km/h by 3.6",
    "speed_mph": "speed_mps (m/s): multiply mph by 0.44704",
    "velocity": "speed_mps (m/s)",
    "time": "time_s (seconds)",
    "t": "time_s (seconds)",
    "airspeed": "airspeed_mps (m/s)",
    "yaw": "yaw_rad (radians)",
    "yaw_deg": "yaw_rad (radians): multiply degrees by pi/180",
    "temperature": "temperature_k (kelvin)",
    "temperature_c": "temperature_k (kelvin): add 273.15",
    "pressure": "pressure_pa (pascal)",
    "pressure_kpa": "pressure_pa (pascal): multiply kPa by 1000",
    "pressure_hpa": "pressure_pa (pascal): multiply hPa by 100",
}

_CHANNEL_LIMITS = {
    # column: (low, high, what a value outside usually means)
    "speed_mps": (0.0, config.MAX_SPEED_MPS, "negative, or km/h in a m/s column"),
    "airspeed_mps": (0.0, config.MAX_SPEED_MPS, "negative, or km/h in a m/s column"),
    "yaw_rad": (-math.pi / 2, math.pi / 2, "degrees in a radian column"),
    "temperature_k": (200.0, 350.0, "degrees Celsius in a kelvin column"),
    "pressure_pa": (50_000.0, 120_000.0, "kPa, hPa or bar in a pascal column"),
    "mass_kg": config.MASS_RANGE_KG + ("not a test mass in kg",),
}


class CampaignError(ValueError):
    """A campaign was refused; the message names the file, column and row."""


@dataclass(frozen=True)
class Vehicle:
    """``[vehicle]`` of vehicle.toml, SI units.

    ``effective_mass_kg`` is M_e = M + I_w / R_r^2 (eq. 2.2); it may be given directly or as
    ``rotating_inertia_kgm2`` with ``rolling_radius_m``.
    """

    mass_kg: float
    effective_mass_kg: float
    frontal_area_m2: float
    rolling_radius_m: float = 0.28
    length_m: float = 4.5


@dataclass(frozen=True)
class Anemometer:
    """``[anemometer]``: true = factor x reading (thesis section 4.7.3)."""

    airspeed_factor: float = 1.0
    yaw_factor: float = 1.0


@dataclass
class Campaign:
    """A loaded, validated campaign.

    Attributes
    ----------
    runs : one row per sample, contract columns (wheel torques already converted to
        ``driveline_force_n``).
    vehicle, anemometer : from vehicle.toml.
    tunnel : the optional ``[tunnel]`` table (KD, CD0, CL0, KL, yaw_deg, cd).
    truth : the true parameters of a simulated campaign, else None.
    meta : free-form provenance (e.g. the simulation case), saved in vehicle.toml ``[meta]``.
    """

    runs: pd.DataFrame
    vehicle: Vehicle
    anemometer: Anemometer = field(default_factory=Anemometer)
    tunnel: dict[str, Any] | None = None
    truth: dict[str, float] | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        self.runs = validate_runs(self.runs, "runs")
        validate_vehicle(self.vehicle, "vehicle")

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

    def directions(self) -> dict:
        """run id -> +1/-1 (every run +1 when the column is absent)."""
        return run_directions(self.runs)

    def pairs(self) -> list[tuple]:
        """Opposite-direction pairs of run ids: by the ``pair`` column when present, else
        consecutive runs in file order.  A run left without a partner is dropped."""
        by_column = pairs_by_column(self.runs)
        return by_column if by_column is not None else consecutive_pairs(self.run_ids)

    def subset(self, run_ids) -> "Campaign":
        """The campaign restricted to some runs (order as given)."""
        return Campaign(subset_table(self.runs, run_ids), self.vehicle, self.anemometer,
                        self.tunnel, self.truth, dict(self.meta))

    def to_batch(self):
        """The runs as a padded :class:`~bayes_roadload.physics.RunBatch` (time from each
        run's first sample) and the list of run ids in batch order.  ``meta["pad_to_samples"]``
        pads every run to at least that many samples (studies of many same-sized campaigns then
        share one compiled fit)."""
        from ..physics.atmosphere import air_density_kgpm3
        from ..physics.integrate import make_run, stack_runs

        runs = []
        v = self.vehicle
        for rid, g in self.runs.groupby("run", sort=False):
            t = g["time_s"].to_numpy(float)
            pressure = g["pressure_pa"].to_numpy(float) if "pressure_pa" in g else config.REFERENCE_PRESSURE_PA
            temp = g["temperature_k"].to_numpy(float) if "temperature_k" in g else config.REFERENCE_TEMPERATURE_K
            direction = float(g["direction"].iloc[0]) if "direction" in g else 1.0
            start = float(g["position_m"].iloc[0]) if "position_m" in g else 0.0
            # a run's own test mass (several masses in one campaign): the rotating inertia, and so
            # M_e - M, does not change with the load
            mass = float(g["mass_kg"].iloc[0]) if "mass_kg" in g else v.mass_kg
            runs.append(make_run(
                t - t[0],
                g["speed_mps"].to_numpy(float),
                airspeed_mps=g["airspeed_mps"].to_numpy(float) if "airspeed_mps" in g else None,
                yaw_rad=g["yaw_rad"].to_numpy(float) if "yaw_rad" in g else None,
                driveline_force_n=g["driveline_force_n"].to_numpy(float) if "driveline_force_n" in g else None,
                air_density_kgpm3=np.broadcast_to(np.asarray(air_density_kgpm3(pressure, temp)), t.shape),
                temperature_k=temp,
                direction=direction,
                start_position_m=start,
                mass_kg=mass,
                effective_mass_kg=v.effective_mass_kg + (mass - v.mass_kg),
                frontal_area_m2=v.frontal_area_m2,
            ))
        return stack_runs(runs, self.meta.get("pad_to_samples")), self.run_ids


# --------------------------------------------------------------------------- validation

def _plain(x):
    """A numpy scalar as the Python value (run ids print and serialise cleanly)."""
    return x.item() if hasattr(x, "item") else x


def _fail(where: str, column: str | None, row: int | None, what: str):
    parts = [where]
    if column is not None:
        parts.append(f"column '{column}'")
    if row is not None:
        parts.append(f"row {row}")
    raise CampaignError(": ".join([", ".join(parts), what]))


def check_columns(df: pd.DataFrame, known, required, hints: Mapping[str, str], what: str, where: str) -> list:
    """Refuse a table's unknown columns (naming the likely unit mistake from ``hints``) and
    missing ``required`` ones; ``what`` names the table in the message ("the contract", "an
    interval campaign", ...).  Returns the column names.  Every data kind validates with it."""
    cols = list(df.columns)
    for c in cols:
        if c not in known:
            hint = hints.get(str(c).strip().lower())
            _fail(where, str(c), None, f"unknown column; did you mean {hint}?" if hint
                  else f"unknown column; {what} knows {', '.join(known)}")
    for c in required:
        if c not in cols:
            _fail(where, c, None, "required column is missing")
    return cols


def check_numeric(df: pd.DataFrame, columns, limits: Mapping[str, tuple], where: str) -> None:
    """Convert ``columns`` of ``df`` to float in place, refusing a value that is not a finite
    number and one outside its ``limits[column] = (low, high, what it probably is)``, naming
    the row.  Every data kind validates with it."""
    for c in columns:
        values = pd.to_numeric(df[c], errors="coerce").to_numpy(float)
        bad = ~np.isfinite(values)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            _fail(where, c, i + 1, f"value {df[c].iloc[i]!r} is not a finite number")
        df[c] = values
        if c in limits:
            lo, hi, meaning = limits[c]
            out = (values < lo) | (values > hi)
            if out.any():
                i = int(np.flatnonzero(out)[0])
                _fail(where, c, i + 1, f"value {values[i]:g} outside [{lo:g}, {hi:g}] ({meaning})")


def check_direction_codes(df: pd.DataFrame, where: str) -> None:
    """Refuse a ``direction`` value other than +1 / -1 (when the column is present)."""
    if "direction" not in df:
        return
    d = df["direction"].to_numpy()
    bad = ~np.isin(d, (-1.0, 1.0))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        _fail(where, "direction", i + 1, f"direction code {d[i]:g} is not +1 or -1")


def check_contiguous(rows: np.ndarray, rid, what: str, where: str) -> None:
    """Refuse a run whose rows (positions in the table) are not one block; ``what`` names
    them ("samples", "bands", ...)."""
    if np.any(np.diff(rows) != 1):
        _fail(where, "run", int(rows[np.flatnonzero(np.diff(rows) != 1)[0] + 1]) + 1,
              f"the {what} of run {rid!r} are not contiguous")


def check_time_increases(t: np.ndarray, rows: np.ndarray, rid, where: str) -> None:
    """Refuse a run whose times ``t`` (its rows' ``time_s``) do not strictly increase."""
    dt = np.diff(t)
    if np.any(dt <= 0):
        _fail(where, "time_s", int(rows[np.flatnonzero(dt <= 0)[0] + 1]) + 1, f"time does not increase within run {rid!r}")


def check_run_constants(df: pd.DataFrame, rows: np.ndarray, columns, rid, where: str) -> None:
    """Refuse a run-level column (of ``columns`` present in ``df``) that changes within the run."""
    for c in columns:
        if c in df:
            vals = df[c].to_numpy()[rows]
            if np.any(vals != vals[0]):
                _fail(where, c, int(rows[np.flatnonzero(vals != vals[0])[0]]) + 1, f"{c} changes within run {rid!r}")


# --------------------------------------------------------------------------- run tables
# What every kind of campaign (speed traces, intervals, distance-time, steady state) asks of
# its table of runs: one row per sample, band or marker with a ``run`` column.

def run_ids_of(table: pd.DataFrame) -> list:
    """Run ids in file order, as plain Python values."""
    return [_plain(r) for r in pd.unique(table["run"])]


def run_directions(table: pd.DataFrame) -> dict:
    """run id -> +1/-1 (every run +1 when the column is absent)."""
    if "direction" not in table:
        return {r: 1 for r in run_ids_of(table)}
    return {_plain(r): int(d) for r, d in table.groupby("run", sort=False)["direction"].first().items()}


def pairs_by_column(table: pd.DataFrame) -> list[tuple] | None:
    """Pairs of run ids by the ``pair`` column (groups of two runs), None without it."""
    if "pair" not in table:
        return None
    groups = table.groupby("pair", sort=False)["run"].unique()
    return [tuple(_plain(r) for r in g) for g in groups if len(g) == 2]


def consecutive_pairs(ids: list) -> list[tuple]:
    """Consecutive runs in file order; a run left without a partner is dropped."""
    return [(ids[i], ids[i + 1]) for i in range(0, len(ids) - 1, 2)]


def subset_table(table: pd.DataFrame, run_ids) -> pd.DataFrame:
    """The rows of some runs, in the order of ``run_ids``, re-indexed."""
    keep = table[table["run"].isin(list(run_ids))]
    order = {r: i for i, r in enumerate(run_ids)}
    return keep.sort_values("run", key=lambda s: s.map(order), kind="stable").reset_index(drop=True)


def validate_runs(df: pd.DataFrame, where: str = "runs.csv") -> pd.DataFrame:
    """Check a runs table against the contract and return a normalised copy.

    Rows are reported 1-based over the data rows (row 1 is the first line after the header).
    Wheel torques are converted to ``driveline_force_n`` by the caller (:func:`load_campaign`),
    which knows the rolling radius.
    """
    df = df.copy()
    cols = check_columns(df, KNOWN_COLUMNS, REQUIRED_COLUMNS, _AMBIGUOUS_HINTS, "the contract", where)
    if len(df) == 0:
        _fail(where, None, None, "no samples")
    if df["run"].isna().any():
        _fail(where, "run", int(np.flatnonzero(df["run"].isna().to_numpy())[0]) + 1, "missing run id")
    check_numeric(df, [c for c in cols if c != "run"], _CHANNEL_LIMITS, where)
    check_direction_codes(df, where)
    if ("wheel_torque_left_nm" in cols) != ("wheel_torque_right_nm" in cols):
        _fail(where, "wheel_torque_left_nm" if "wheel_torque_left_nm" not in cols else "wheel_torque_right_nm",
              None, "wheel torques need both the left and the right column")
    if "wheel_torque_left_nm" in cols and "driveline_force_n" in cols:
        _fail(where, "driveline_force_n", None,
              "give either driveline_force_n or the wheel torques, not both (ambiguous)")

    positions = np.arange(len(df))
    for rid, idx in df.groupby("run", sort=False).indices.items():
        rid = _plain(rid)
        rows = positions[idx]
        if len(rows) < config.MIN_RUN_SAMPLES:
            _fail(where, "run", int(rows[0]) + 1,
                  f"run {rid!r} has {len(rows)} samples; at least {config.MIN_RUN_SAMPLES} are needed")
        check_contiguous(rows, rid, "samples", where)
        check_time_increases(df["time_s"].to_numpy()[rows], rows, rid, where)
        check_run_constants(df, rows, ("direction", "pair", "mass_kg"), rid, where)
    return df.reset_index(drop=True)


def validate_vehicle(v: Vehicle, where: str = "vehicle.toml") -> None:
    lo, hi = config.MASS_RANGE_KG
    for key in ("mass_kg", "effective_mass_kg"):
        val = getattr(v, key)
        if not (math.isfinite(val) and lo <= val <= hi):
            _fail(where, f"[vehicle] {key}", None, f"{val!r} is outside the physical range [{lo}, {hi}] kg")
    if v.effective_mass_kg < v.mass_kg:
        _fail(where, "[vehicle] effective_mass_kg", None,
              f"{v.effective_mass_kg} kg is less than the test mass {v.mass_kg} kg (eq. 2.2: M_e = M + I/R^2)")
    if v.effective_mass_kg > 1.5 * v.mass_kg:
        _fail(where, "[vehicle] effective_mass_kg", None,
              f"{v.effective_mass_kg} kg is more than 1.5 x the test mass: check the rotating inertia")
    lo, hi = config.AREA_RANGE_M2
    if not (math.isfinite(v.frontal_area_m2) and lo <= v.frontal_area_m2 <= hi):
        _fail(where, "[vehicle] frontal_area_m2", None, f"{v.frontal_area_m2!r} is outside [{lo}, {hi}] m^2")
    if not (0.01 <= v.rolling_radius_m <= 2.0):
        _fail(where, "[vehicle] rolling_radius_m", None, f"{v.rolling_radius_m!r} is outside [0.01, 2] m")


def _vehicle_from_toml(doc: dict, where: str) -> tuple[Vehicle, Anemometer, dict | None, dict]:
    if "vehicle" not in doc:
        _fail(where, "[vehicle]", None, "table is missing")
    t = dict(doc["vehicle"])
    known = {"mass_kg", "effective_mass_kg", "frontal_area_m2", "rolling_radius_m",
             "rotating_inertia_kgm2", "length_m"}
    for k in t:
        if k not in known:
            _fail(where, f"[vehicle] {k}", None, f"unknown key; known: {', '.join(sorted(known))}")
    for k in ("mass_kg", "frontal_area_m2"):
        if k not in t:
            _fail(where, f"[vehicle] {k}", None, "required key is missing")
    radius = float(t.get("rolling_radius_m", 0.28))
    if "effective_mass_kg" in t and "rotating_inertia_kgm2" in t:
        _fail(where, "[vehicle] effective_mass_kg", None,
              "give effective_mass_kg or rotating_inertia_kgm2, not both (ambiguous)")
    if "effective_mass_kg" in t:
        me = float(t["effective_mass_kg"])
    elif "rotating_inertia_kgm2" in t:
        if "rolling_radius_m" not in t:
            _fail(where, "[vehicle] rolling_radius_m", None, "needed with rotating_inertia_kgm2")
        me = float(t["mass_kg"]) + float(t["rotating_inertia_kgm2"]) / radius**2
    else:
        _fail(where, "[vehicle] effective_mass_kg", None,
              "required key is missing (or give rotating_inertia_kgm2 and rolling_radius_m)")
    vehicle = Vehicle(float(t["mass_kg"]), me, float(t["frontal_area_m2"]), radius,
                      float(t.get("length_m", 4.5)))
    validate_vehicle(vehicle, where)
    a = dict(doc.get("anemometer", {}))
    for k in a:
        if k not in ("airspeed_factor", "yaw_factor"):
            _fail(where, f"[anemometer] {k}", None, "unknown key; known: airspeed_factor, yaw_factor")
    anem = Anemometer(float(a.get("airspeed_factor", 1.0)), float(a.get("yaw_factor", 1.0)))
    for k in ("airspeed_factor", "yaw_factor"):
        if not 0.5 <= getattr(anem, k) <= 2.0:
            _fail(where, f"[anemometer] {k}", None, f"{getattr(anem, k)} is outside [0.5, 2]")
    tunnel = doc.get("tunnel")
    if tunnel is not None:
        tunnel = dict(tunnel)
        if ("yaw_deg" in tunnel) != ("cd" in tunnel):
            _fail(where, "[tunnel]", None, "a C_D(yaw) table needs both yaw_deg and cd")
    return vehicle, anem, tunnel, dict(doc.get("meta", {}))


def _read_vehicle(root: Path):
    return read_vehicle_file(root / "vehicle.toml")


def read_vehicle_file(path) -> tuple:
    """``vehicle.toml`` (or any file of its format) as (vehicle, anemometer, tunnel, meta),
    validated; refused with the file's name when missing or not TOML."""
    vfile = Path(path)
    if not vfile.exists():
        raise CampaignError(f"{vfile}: missing")
    try:
        doc = tomllib.loads(vfile.read_text())
    except tomllib.TOMLDecodeError as e:
        raise CampaignError(f"{vfile}: not valid TOML ({e})") from e
    return _vehicle_from_toml(doc, str(vfile))


def _load_interval_campaign(root: Path, intervals: Path):
    from .intervals import IntervalCampaign, read_intervals, validate_intervals

    vehicle, anem, tunnel, meta = _read_vehicle(root)
    df = validate_intervals(read_intervals(intervals), str(intervals))
    tfile = root / "truth.json"
    truth = json.loads(tfile.read_text()) if tfile.exists() else None
    return IntervalCampaign(df, vehicle, anem, tunnel, truth, meta)


def _load_distance_campaign(root: Path, distances: Path):
    from .distances import DistanceCampaign, read_distances, validate_distances

    vehicle, anem, tunnel, meta = _read_vehicle(root)
    df = validate_distances(read_distances(distances), str(distances))
    tfile = root / "truth.json"
    truth = json.loads(tfile.read_text()) if tfile.exists() else None
    return DistanceCampaign(df, vehicle, anem, tunnel, truth, meta)


def load_campaign(path: str | os.PathLike) -> Campaign:
    """Load and validate a campaign directory (see ``docs/data-format.md``): a
    :class:`Campaign` of speed traces (``runs.csv`` / ``runs.parquet``), an
    :class:`~bayes_roadload.data.intervals.IntervalCampaign` of speed-gate interval times
    (``intervals.csv``), a :class:`~bayes_roadload.data.distances.DistanceCampaign` of
    distance-time records (``distances.csv``), a :class:`~bayes_roadload.data.spindown.SpindownCampaign` of wheel
    spin-downs (``spindown.csv``) or a :class:`~bayes_roadload.data.steady.SteadyCampaign` of
    steady-state torque tests (``steady.csv``)."""
    root = Path(path)
    if not root.is_dir():
        raise CampaignError(f"{root}: not a campaign directory")
    csv, parquet = root / "runs.csv", root / "runs.parquet"
    intervals = root / "intervals.csv"
    distances = root / "distances.csv"
    kinds = [f.name for f in (csv, parquet, intervals, distances, root / "spindown.csv", root / "steady.csv")
             if f.exists()]
    if len(set(kinds) - {"runs.csv", "runs.parquet"}) + any(k.startswith("runs.") for k in kinds) > 1:
        raise CampaignError(f"{root}: {' and '.join(kinds)} present (ambiguous campaign kind): one data file "
                            "per campaign directory")
    if (root / "spindown.csv").exists():
        from .spindown import load_spindown

        return load_spindown(root)
    if (root / "steady.csv").exists():
        from .steady import load_steady

        return load_steady(root)
    if intervals.exists() and (csv.exists() or parquet.exists()):
        raise CampaignError(f"{root}: both intervals.csv and runs.csv/parquet present (ambiguous campaign kind)")
    if distances.exists():
        return _load_distance_campaign(root, distances)
    if intervals.exists():
        return _load_interval_campaign(root, intervals)
    if csv.exists() and parquet.exists():
        raise CampaignError(f"{root}: both runs.csv and runs.parquet present (ambiguous)")
    if csv.exists():
        runs_file = csv
        df = pd.read_csv(csv)
    elif parquet.exists():
        runs_file = parquet
        try:
            df = pd.read_parquet(parquet)
        except ImportError as e:  # pragma: no cover - depends on optional pyarrow
            raise CampaignError(f"{parquet}: reading parquet needs pyarrow ({e})") from e
    else:
        raise CampaignError(f"{root}: runs.csv (or runs.parquet, or intervals.csv for speed-gate interval "
                            "times, or distances.csv for distance-time records) is missing")
    vehicle, anem, tunnel, meta = _read_vehicle(root)
    df = validate_runs(df, str(runs_file))
    if "wheel_torque_left_nm" in df:
        df["driveline_force_n"] = (df.pop("wheel_torque_left_nm") + df.pop("wheel_torque_right_nm")) / vehicle.rolling_radius_m
    truth = None
    tfile = root / "truth.json"
    if tfile.exists():
        truth = json.loads(tfile.read_text())
    return Campaign(df, vehicle, anem, tunnel, truth, meta)


# --------------------------------------------------------------------------- saving

def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def vehicle_toml(c: Campaign) -> str:
    """The vehicle.toml text of a campaign."""
    v = c.vehicle
    lines = ["[vehicle]"]
    for k in ("mass_kg", "effective_mass_kg", "frontal_area_m2", "rolling_radius_m", "length_m"):
        lines.append(f"{k} = {_toml_value(getattr(v, k))}")
    lines += ["", "[anemometer]",
              f"airspeed_factor = {_toml_value(c.anemometer.airspeed_factor)}",
              f"yaw_factor = {_toml_value(c.anemometer.yaw_factor)}"]
    for name, table in (("tunnel", c.tunnel), ("meta", c.meta)):
        if table:
            lines += ["", f"[{name}]"] + [f"{k} = {_toml_value(val)}" for k, val in table.items()]
    return "\n".join(lines) + "\n"


def save_campaign(c: Campaign, path: str | os.PathLike, fmt: str = "csv") -> Path:
    """Validate and write a campaign directory; nothing is written if validation fails.

    Files are written to a temporary directory beside ``path`` and moved into place.
    """
    kind = getattr(c, "kind", "traces")
    interval_kind = kind == "intervals"
    distance_kind = kind == "distances"
    if interval_kind:
        from .intervals import validate_intervals

        if fmt != "csv":
            raise ValueError("an interval campaign is written as intervals.csv (fmt='csv')")
        c.intervals = validate_intervals(c.intervals, "intervals")
    elif distance_kind:
        from .distances import validate_distances

        if fmt != "csv":
            raise ValueError("a distance-time campaign is written as distances.csv (fmt='csv')")
        c.markers = validate_distances(c.markers, "distances")
    else:
        c.runs = validate_runs(c.runs, "runs")
    validate_vehicle(c.vehicle, "vehicle")
    root = Path(path)
    root.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".campaign-", dir=root.parent))
    try:
        runs = None if interval_kind or distance_kind else c.runs.copy()
        if interval_kind:
            c.intervals.to_csv(tmp / "intervals.csv", index=False, float_format="%.10g")
        elif distance_kind:
            c.markers.to_csv(tmp / "distances.csv", index=False, float_format="%.12g")
        elif fmt == "csv":
            runs.to_csv(tmp / "runs.csv", index=False, float_format="%.10g")
        elif fmt == "parquet":
            runs.to_parquet(tmp / "runs.parquet", index=False)
        else:
            raise ValueError(f"fmt must be 'csv' or 'parquet', not {fmt!r}")
        (tmp / "vehicle.toml").write_text(vehicle_toml(c))
        if c.truth is not None:
            (tmp / "truth.json").write_text(json.dumps(c.truth, indent=2, sort_keys=True) + "\n")
        root.mkdir(exist_ok=True)
        for stale in ("runs.csv", "runs.parquet", "intervals.csv", "distances.csv", "truth.json"):
            (root / stale).unlink(missing_ok=True)
        for f in tmp.iterdir():
            shutil.move(str(f), root / f.name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return root
