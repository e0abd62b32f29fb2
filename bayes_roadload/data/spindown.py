"""The wheel spin-down campaign kind (thesis section 5.6): ``spindown.csv`` + ``vehicle.toml``.

One row per sample of a wheel decelerating freely off the ground:

========================  =====  ========  ==============================================
column                    unit   required  meaning
========================  =====  ========  ==============================================
``run``                   id     yes       one spin-down; its samples are contiguous rows
``time_s``                s      yes       strictly increasing within a run
``wheel_speed_radps``     rad/s  one of    the wheel's angular speed, or ...
``wheel_speed_mps``       m/s    the two   ... its tread speed omega R_r (never both)
``wheel``                 id     no        which wheel (e.g. ``nearside``), constant in a run
========================  =====  ========  ==============================================

``vehicle.toml`` has a ``[spindown]`` table: ``wheel_inertia_kgm2`` (the wheel's polar moment of
inertia about its axle, one number for every wheel or a table ``{nearside = 0.9, ...}``),
``undriven_wheels`` (how many undriven wheels the vehicle has, default 2: the vehicle's
A_u, B_u are their sum) and optionally ``rolling_radius_m`` (else ``[vehicle] rolling_radius_m``;
both given and different is refused as ambiguous), and optionally ``[uncertainty]`` (Type B
standard uncertainties, :mod:`.uncertainty`: the speed scale and the wheel inertias,
``rotating_inertia_rel``).  Speeds in rpm, km/h, Hz or degrees per
second are refused with the conversion to make.  The samples are shifted so each run starts at
t = 0 and speeds are kept as tread speeds (m/s).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .. import config
from .checks import (
    read_csv_table,
    check_columns,
    check_contiguous,
    check_csv_format,
    check_min_samples,
    check_no_missing,
    check_not_empty,
    check_numeric,
    check_run_constants,
    check_time_increases,
    data_file,
    read_truth,
    refuse,
    run_ids_of,
    run_rows,
    truth_files,
)
from .uncertainty import UNCERTAINTY_TABLE, TypeBChannels, uncertainty_from_toml
from .vehicle import VEHICLE_FILE, read_toml_file, toml_table, toml_value

KIND = "spindown"
FILES = ("spindown.csv",)
DESCRIPTION = "spin-down campaigns"
OPTIONS = ("wheel_inertia_kgm2", "rolling_radius_m")
OPTIONAL_FILES: tuple[str, ...] = ()

SPEED_COLUMNS = ("wheel_speed_radps", "wheel_speed_mps")
KNOWN_COLUMNS = ("run", "time_s", "wheel") + SPEED_COLUMNS

_AMBIGUOUS_HINTS = {
    "wheel_speed": "wheel_speed_radps (rad/s) or wheel_speed_mps (tread speed, m/s)",
    "wheel_speed_rpm": "wheel_speed_radps (rad/s): multiply rpm by 2 pi / 60",
    "wheel_speed_hz": "wheel_speed_radps (rad/s): multiply rev/s by 2 pi",
    "wheel_speed_degps": "wheel_speed_radps (rad/s): multiply deg/s by pi / 180",
    "wheel_speed_kph": "wheel_speed_mps (m/s): divide km/h by 3.6",
    "wheel_speed_kmh": "wheel_speed_mps (m/s): divide km/h by 3.6",
    "wheel_speed_mph": "wheel_speed_mps (m/s): multiply mph by 0.44704",
    "speed_mps": "wheel_speed_mps (the tread speed of the wheel, m/s)",
    "time": "time_s (seconds)",
}
_SPINDOWN_KEYS = ("wheel_inertia_kgm2", "undriven_wheels", "rolling_radius_m")
DEFAULT_WHEEL = "wheel"
"""Wheel id of runs without a ``wheel`` column."""


@dataclass
class SpindownCampaign:
    """A loaded, validated spin-down campaign.

    Attributes
    ----------
    runs : ``run``, ``wheel``, ``time_s`` (from 0 in each run), ``wheel_speed_mps`` (tread speed).
    wheel_inertia_kgm2 : wheel id -> polar moment of inertia (kg m^2).
    rolling_radius_m : R_r (m).
    undriven_wheels : the vehicle's number of undriven wheels.
    truth : per-wheel ``Aw_n``/``Bw_nspm`` tables and the totals ``Au``, ``Bu`` of a simulation.
    """

    runs: pd.DataFrame
    wheel_inertia_kgm2: dict[str, float]
    rolling_radius_m: float
    undriven_wheels: int = 2
    truth: dict[str, Any] | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    kind = KIND
    type_b_channels = TypeBChannels("runs", speed=("wheel_speed_mps",), vehicle=False, wheel_inertia=True)

    def __post_init__(self):
        self.runs = validate_spindown(self.runs, "spindown", self.rolling_radius_m)
        validate_spindown_setup(self.wheel_inertia_kgm2, self.rolling_radius_m, self.undriven_wheels,
                                sorted(self.runs["wheel"].unique()), "spindown setup")

    @property
    def run_ids(self) -> list:
        return run_ids_of(self.runs)

    @property
    def wheels(self) -> list[str]:
        """The wheels tested, in order of first appearance."""
        return [str(w) for w in pd.unique(self.runs["wheel"])]


def validate_spindown(df: pd.DataFrame, where: str = "spindown.csv", rolling_radius_m: float | None = None
                      ) -> pd.DataFrame:
    """Check a spin-down table and return it normalised (``wheel_speed_mps``, ``wheel`` as text,
    each run's time from 0).  ``rolling_radius_m`` converts ``wheel_speed_radps``."""
    df = df.copy()
    cols = check_columns(df, KNOWN_COLUMNS, ("run", "time_s"), _AMBIGUOUS_HINTS, "a spin-down table", where)
    given = [c for c in SPEED_COLUMNS if c in cols]
    if not given:
        refuse(where, "wheel_speed_radps", None, "required: wheel_speed_radps (rad/s) or wheel_speed_mps (m/s)")
    if len(given) == 2:
        refuse(where, "wheel_speed_mps", None, "give wheel_speed_radps or wheel_speed_mps, not both (ambiguous)")
    check_not_empty(df, "samples", where)
    check_no_missing(df, "run", "missing run id", where)
    check_numeric(df, ("time_s",) + tuple(given), {}, where)
    if given[0] == "wheel_speed_radps":
        if rolling_radius_m is None:
            refuse(where, "wheel_speed_radps", None, "needs the rolling radius ([spindown] or [vehicle] "
                                                    "rolling_radius_m) to give the tread speed")
        df["wheel_speed_mps"] = df.pop("wheel_speed_radps") * float(rolling_radius_m)
    v = df["wheel_speed_mps"].to_numpy()
    out = (v <= 0.0) | (v > config.MAX_SPEED_MPS)
    if out.any():
        i = int(np.flatnonzero(out)[0])
        refuse(where, given[0], i + 1, f"tread speed {v[i]:g} m/s outside (0, {config.MAX_SPEED_MPS:g}] (a stopped "
                                      "wheel, a negative value, or rpm / km/h in the column)")
    df["wheel"] = df["wheel"].astype(str) if "wheel" in cols else DEFAULT_WHEEL
    t_all = df["time_s"].to_numpy().copy()
    for rid, rows in run_rows(df):
        check_min_samples(rows, rid, where)
        check_contiguous(rows, rid, "samples", where)
        t = t_all[rows]
        check_time_increases(t, rows, rid, where)
        check_run_constants(df, rows, ("wheel",), rid, where)
        t_all[rows] = t - t[0]
    df["time_s"] = t_all
    return df[["run", "wheel", "time_s", "wheel_speed_mps"]].reset_index(drop=True)


def validate_spindown_setup(inertia: dict[str, float], radius: float, undriven: int, wheels, where: str) -> None:
    """The wheel inertias, rolling radius and number of undriven wheels against the wheels tested."""
    lo, hi = config.WHEEL_INERTIA_RANGE_KGM2
    for w, value in inertia.items():
        if not (math.isfinite(value) and lo <= value <= hi):
            refuse(where, f"[spindown] wheel_inertia_kgm2 ({w})", None,
                  f"{value!r} kg m^2 is outside [{lo:g}, {hi:g}] (kg cm^2 or g m^2 in a kg m^2 key?)")
    missing = [w for w in wheels if w not in inertia]
    if missing:
        refuse(where, "[spindown] wheel_inertia_kgm2", None,
              f"no inertia for wheel {missing[0]!r} (give one number, or one per wheel: {', '.join(map(str, wheels))})")
    if not (0.01 <= radius <= 2.0):
        refuse(where, "rolling_radius_m", None, f"{radius!r} is outside [0.01, 2] m")
    if isinstance(undriven, bool) or int(undriven) != undriven or undriven < 1:
        refuse(where, "[spindown] undriven_wheels", None, f"{undriven!r} is not a positive whole number")
    if len(wheels) > undriven:
        refuse(where, "[spindown] undriven_wheels", None,
              f"{len(wheels)} wheels tested ({', '.join(map(str, wheels))}) but the vehicle has {undriven} undriven wheels")


def read_spindown_setup(vehicle_file: Path | None, *, wheel_inertia_kgm2: float | None = None,
                        rolling_radius_m: float | None = None) -> tuple[Any, float, int, dict]:
    """``[spindown]`` of ``vehicle_file`` (may be None when the arguments give everything):
    (inertia: a number or a wheel -> number table, rolling radius, undriven wheels, meta).
    An argument that contradicts the file is refused as ambiguous."""
    doc: dict = {}
    where = str(vehicle_file) if vehicle_file is not None else "arguments"
    if vehicle_file is not None and Path(vehicle_file).exists():
        doc = read_toml_file(vehicle_file)
    table = dict(doc.get("spindown", {}))
    for k in table:
        if k not in _SPINDOWN_KEYS:
            refuse(where, f"[spindown] {k}", None, f"unknown key; known: {', '.join(_SPINDOWN_KEYS)}")
    radii = {}
    if "rolling_radius_m" in table:
        radii["[spindown] rolling_radius_m"] = float(table["rolling_radius_m"])
    if "rolling_radius_m" in doc.get("vehicle", {}):
        radii["[vehicle] rolling_radius_m"] = float(doc["vehicle"]["rolling_radius_m"])
    if rolling_radius_m is not None:
        radii["--rolling-radius-m"] = float(rolling_radius_m)
    if len(set(radii.values())) > 1:
        refuse(where, "rolling_radius_m", None, "different rolling radii given ("
              + ", ".join(f"{k} = {v:g}" for k, v in radii.items()) + "): ambiguous")
    if not radii:
        refuse(where, "rolling_radius_m", None, "missing: give [spindown] or [vehicle] rolling_radius_m "
                                               "(or --rolling-radius-m)")
    inertia = table.get("wheel_inertia_kgm2")
    if wheel_inertia_kgm2 is not None:
        if inertia is not None and (isinstance(inertia, dict) or float(inertia) != float(wheel_inertia_kgm2)):
            refuse(where, "[spindown] wheel_inertia_kgm2", None,
                  f"the file gives {inertia!r} and --wheel-inertia-kgm2 {wheel_inertia_kgm2:g}: ambiguous")
        inertia = float(wheel_inertia_kgm2)
    if inertia is None:
        refuse(where, "[spindown] wheel_inertia_kgm2", None,
              "missing: the wheel's polar moment of inertia (kg m^2) is needed to turn deceleration into drag")
    undriven = table.get("undriven_wheels", config.DEFAULT_UNDRIVEN_WHEELS)
    meta = dict(doc.get("meta", {}))
    if UNCERTAINTY_TABLE in doc:  # Type B standard uncertainties (data.uncertainty), carried in meta
        meta[UNCERTAINTY_TABLE] = uncertainty_from_toml(doc[UNCERTAINTY_TABLE], where)
    return inertia, next(iter(radii.values())), undriven, meta


def inertia_per_wheel(inertia, wheels) -> dict[str, float]:
    """One inertia for every wheel, from a number or a table."""
    if isinstance(inertia, dict):
        return {str(k): float(v) for k, v in inertia.items()}
    return {str(w): float(inertia) for w in wheels}


def load(root: str | os.PathLike, *, wheel_inertia_kgm2: float | None = None,
         rolling_radius_m: float | None = None) -> SpindownCampaign:
    """Load and validate a spin-down campaign directory (``spindown.csv``, ``vehicle.toml``
    with ``[spindown]``, optional ``truth.json``); the arguments stand in for (or must agree
    with) the file's wheel inertia and rolling radius."""
    root = Path(root)
    f = data_file(root, "spindown.csv")
    vfile = root / VEHICLE_FILE
    inertia, radius, undriven, meta = read_spindown_setup(
        vfile if vfile.exists() else None, wheel_inertia_kgm2=wheel_inertia_kgm2, rolling_radius_m=rolling_radius_m)
    df = validate_spindown(read_csv_table(f), str(f), radius)
    wheels = [str(w) for w in pd.unique(df["wheel"])]
    inertia = inertia_per_wheel(inertia, wheels)
    validate_spindown_setup(inertia, radius, undriven, wheels, str(vfile))
    return SpindownCampaign(df, inertia, radius, int(undriven), read_truth(root), meta)


load_spindown = load


def spindown_toml(c: SpindownCampaign) -> str:
    """The vehicle.toml text of a spin-down campaign: ``[spindown]``, ``[meta]`` and ``[uncertainty]``."""
    lines = ["[spindown]", f"rolling_radius_m = {toml_value(float(c.rolling_radius_m))}",
             f"undriven_wheels = {toml_value(int(c.undriven_wheels))}", "", "[spindown.wheel_inertia_kgm2]"]
    lines += [f"{json.dumps(str(w))} = {toml_value(float(v))}" for w, v in c.wheel_inertia_kgm2.items()]
    meta = {k: v for k, v in c.meta.items() if k != UNCERTAINTY_TABLE}
    return "\n".join(lines + toml_table("meta", meta) + toml_table(UNCERTAINTY_TABLE, c.meta.get(UNCERTAINTY_TABLE))) + "\n"


def files(c: SpindownCampaign, fmt: str = "csv") -> dict[str, str]:
    """The files of a spin-down campaign directory (name -> text), validated first:
    ``spindown.csv`` (tread speeds in ``wheel_speed_mps``), ``vehicle.toml``, ``truth.json``
    when the truth is known."""
    check_csv_format(fmt, "a spin-down campaign", "spindown.csv")
    c.runs = validate_spindown(c.runs, "spindown", c.rolling_radius_m)
    return ({"spindown.csv": c.runs.to_csv(index=False, float_format="%.10g"), VEHICLE_FILE: spindown_toml(c)}
            | truth_files(c.truth))


def save_spindown(c: SpindownCampaign, path: str | os.PathLike) -> Path:
    """Validate and write a spin-down campaign directory (:func:`~bayes_roadload.data.io.save_campaign`)."""
    from .io import save_campaign  # io imports this module: its registry lists the kinds

    return save_campaign(c, path)
