"""A chassis-dynamometer coastdown directory: ``dyno_coastdown.csv`` + ``dyno.toml``.

``dyno_coastdown.csv``: ``time_s, speed_mps`` (optionally ``run``; one coastdown per run id).
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

import numpy as np
import pandas as pd

from .checks import read_csv_table, write_atomically
from .vehicle import read_toml_file


@dataclass
class DynoCoastdown:
    """A dynamometer coastdown: the speed table, the inertia setting (kg), the set
    coefficients used (N, N/(km/h), N/(km/h)^2) and, when simulated, the true parasitic losses."""

    runs: pd.DataFrame
    inertia_kg: float
    set_coefficients: tuple[float, float, float]
    parasitic_truth: tuple[float, float, float] | None = None


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
    runs = read_csv_table(csv)
    for col in ("time_s", "speed_mps"):
        if col not in runs:
            raise ValueError(f"{csv}: missing column {col}")
    for col in ("time_s", "speed_mps"):
        bad = np.flatnonzero(~np.isfinite(runs[col].to_numpy(float)))
        if bad.size:
            raise ValueError(f"{csv}: column {col}, row {int(bad[0]) + 1}: not a finite number")
    doc = read_toml_file(toml)
    dyno = doc.get("dyno")
    if not isinstance(dyno, dict) or "inertia_kg" not in dyno or "set_coefficients" not in dyno:
        raise ValueError(f"{toml}: needs a [dyno] table with inertia_kg and set_coefficients")
    inertia = float(dyno["inertia_kg"])
    if not inertia > 0:
        raise ValueError(f"{toml}: [dyno] inertia_kg must be positive, got {inertia}")
    truth = doc.get("truth", {}).get("parasitic_coefficients")
    return DynoCoastdown(runs, inertia, _three(dyno["set_coefficients"], str(toml), "set_coefficients"),
                         None if truth is None else _three(truth, str(toml), "[truth] parasitic_coefficients"))


def save_dyno(d: DynoCoastdown, path: str | os.PathLike) -> Path:
    """Write ``dyno_coastdown.csv`` and ``dyno.toml`` into ``path``."""
    lines = ["[dyno]", f"inertia_kg = {d.inertia_kg!r}",
             f"set_coefficients = [{', '.join(repr(float(x)) for x in d.set_coefficients)}]"]
    if d.parasitic_truth is not None:
        lines += ["", "[truth]", f"parasitic_coefficients = [{', '.join(repr(float(x)) for x in d.parasitic_truth)}]"]
    return write_atomically(path, {"dyno_coastdown.csv": d.runs.to_csv(index=False, float_format="%.10g"),
                                   "dyno.toml": "\n".join(lines) + "\n"})
