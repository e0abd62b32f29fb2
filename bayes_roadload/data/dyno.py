"""A chassis-dynamometer coastdown directory: ``dyno_coastdown.csv`` + ``dyno.toml``.

``dyno_coastdown.csv``: ``time_s, speed_mps`` (optionally ``run``; one coastdown per run id);
``speed_kph`` / ``speed_mph`` / ``time_ms`` are converted, and the table is checked as speed
traces are (:func:`validate_dyno_runs`: file, column and row named in a refusal).
``dyno.toml``::

    [dyno]
    inertia_kg = 1500.0              # the dynamometer's inertia setting
    set_coefficients = [a, b, c]     # set load during the coastdown: N, N/(km/h), N/(km/h)^2

    [truth]                          # optional, written by the simulator
    parasitic_coefficients = [a, b, c]
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from .. import config
from .checks import (
    CHANNEL_LIMITS,
    UNIT_HINTS,
    check_columns,
    check_contiguous,
    check_no_missing,
    check_not_empty,
    check_numeric,
    check_time_increases,
    read_csv_table,
    run_rows,
    write_atomically,
)
from .units import check_plausible_road_load, convert_units
from .vehicle import read_toml_file

DYNO_COLUMNS = ("run", "time_s", "speed_mps")
DYNO_REQUIRED = ("time_s", "speed_mps")


@dataclass
class DynoCoastdown:
    """A dynamometer coastdown: the speed table, the inertia setting (kg), the set
    coefficients used (N, N/(km/h), N/(km/h)^2) and, when simulated, the true parasitic losses."""

    runs: pd.DataFrame
    inertia_kg: float
    set_coefficients: tuple[float, float, float]
    parasitic_truth: tuple[float, float, float] | None = None
    conversions: tuple[dict, ...] = ()
    """Columns converted to SI on load (``speed_kph`` -> ``speed_mps``, ...), as
    :meth:`~bayes_roadload.data.units.Conversion.record`."""


def _three(value, where: str, key: str) -> tuple[float, float, float]:
    if not isinstance(value, list) or len(value) != 3 or not all(isinstance(x, (int, float)) for x in value):
        raise ValueError(f"{where}: {key} must be a list of three numbers [a N, b N/(km/h), c N/(km/h)^2]")
    return tuple(float(x) for x in value)


def load_dyno(root: str | os.PathLike) -> DynoCoastdown:
    """Read and validate a dynamometer coastdown directory (module docstring)."""
    root = Path(root)
    csv, toml = root / "dyno_coastdown.csv", root / "dyno.toml"
    for f in (csv, toml):
        if not f.is_file():
            raise ValueError(f"{root}: a dynamometer coastdown needs {f.name} (docs/standards.md)")
    doc = read_toml_file(toml)
    dyno = doc.get("dyno")
    if not isinstance(dyno, dict) or "inertia_kg" not in dyno or "set_coefficients" not in dyno:
        raise ValueError(f"{toml}: needs a [dyno] table with inertia_kg and set_coefficients")
    inertia = float(dyno["inertia_kg"])
    if not inertia > 0:
        raise ValueError(f"{toml}: [dyno] inertia_kg must be positive, got {inertia}")
    truth = doc.get("truth", {}).get("parasitic_coefficients")
    runs, conversions = validate_dyno_runs(read_csv_table(csv), str(csv), inertia)
    return DynoCoastdown(runs, inertia, _three(dyno["set_coefficients"], str(toml), "set_coefficients"),
                         None if truth is None else _three(truth, str(toml), "[truth] parasitic_coefficients"),
                         tuple(c.record() for c in conversions))


def validate_dyno_runs(df: pd.DataFrame, where: str, inertia_kg: float) -> tuple[pd.DataFrame, list]:
    """Check a dynamometer coastdown table with the speed traces' checks; returns the table in SI
    and the conversions made.

    Columns whose name states a unit (``speed_kph``, ``speed_mph``, ``time_ms``) are converted
    (:func:`~bayes_roadload.data.units.convert_units`); unknown or unit-ambiguous columns, a
    missing ``time_s`` / ``speed_mps``, values that are not finite numbers, speeds outside
    [0, 100] m/s, the rows of a run not contiguous and time not strictly increasing within a run
    are refused naming the file, column and 1-based row; so are speeds or times whose implied
    road load, read on the inertia setting as the mass at the reference air density, says they
    were logged in km/h or mph, or in milliseconds
    (:func:`~bayes_roadload.data.units.check_plausible_road_load`).
    """
    df, conversions = convert_units(df, where)
    cols = check_columns(df, DYNO_COLUMNS, DYNO_REQUIRED, UNIT_HINTS, "a dynamometer coastdown", where)
    check_not_empty(df, "samples", where)
    if "run" in cols:
        check_no_missing(df, "run", "missing run id", where)
    check_numeric(df, DYNO_REQUIRED, CHANNEL_LIMITS, where)
    table = df if "run" in cols else df.assign(run=1)
    for rid, rows in run_rows(table):
        check_contiguous(rows, rid, "samples", where)
        check_time_increases(df["time_s"].to_numpy()[rows], rows, rid, where)
    time_column = next((c.column for c in conversions if c.to == "time_s"), "time_s")
    rho = config.REFERENCE_PRESSURE_PA / (config.GAS_CONSTANT_AIR_J_PER_KG_K * config.REFERENCE_TEMPERATURE_K)
    check_plausible_road_load(table, where, inertia_kg, inertia_kg, rho, time_column)
    return df.reset_index(drop=True), conversions


def save_dyno(d: DynoCoastdown, path: str | os.PathLike) -> Path:
    """Write ``dyno_coastdown.csv`` and ``dyno.toml`` into ``path``."""
    lines = ["[dyno]", f"inertia_kg = {d.inertia_kg!r}",
             f"set_coefficients = [{', '.join(repr(float(x)) for x in d.set_coefficients)}]"]
    if d.parasitic_truth is not None:
        lines += ["", "[truth]", f"parasitic_coefficients = [{', '.join(repr(float(x)) for x in d.parasitic_truth)}]"]
    return write_atomically(path, {"dyno_coastdown.csv": d.runs.to_csv(index=False, float_format="%.10g"),
                                   "dyno.toml": "\n".join(lines) + "\n"})
