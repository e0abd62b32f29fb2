"""``bayes-roadload predict``: the road-load work over a drive cycle and the predicted speed
trace of another manoeuvre, from a fit's posterior draws (:mod:`.cycles`, conditions via
:func:`.standards.to_conditions`)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd

from .. import config
from .cycles import cycle_work, predict_speed_trace
from .standards import load_draws, to_conditions


def run_predict(source: str | os.PathLike | Mapping[str, np.ndarray], cycle: str, *, effective_mass_kg: float,
                temperature_k: float = config.REFERENCE_TEMPERATURE_K,
                pressure_pa: float = config.REFERENCE_PRESSURE_PA, mass_kg_change: float = 0.0,
                v0_kph: float = 120.0, duration_s: float = 300.0, power_w: float = 0.0,
                out_dir: str | os.PathLike | None = None) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """Cycle work (at reference conditions, :func:`~.cycles.cycle_work`) and a predicted trace
    of a coastdown (``power_w`` 0) or constant-power run at ``temperature_k`` / ``pressure_pa``
    with the effective mass changed by ``mass_kg_change`` (the tyre coefficients f0, f1 scale
    with the mass, the aerodynamic f2 does not).  With ``out_dir``: ``cycle_work.csv``,
    ``cycle_work_shares.csv``, ``predicted_trace.csv``.

    Returns (work, shares, trace)."""
    draws = load_draws(source) if isinstance(source, (str, os.PathLike)) else source
    work, shares = cycle_work(draws, cycle, effective_mass_kg=effective_mass_kg)
    cond = to_conditions(draws, temperature_k, pressure_pa)
    mass = effective_mass_kg + mass_kg_change
    ratio = mass / effective_mass_kg
    cond = {"F0_N": cond["F0_N"] * ratio, "F1_N_per_kph": cond["F1_N_per_kph"] * ratio,
            "F2_N_per_kph2": cond["F2_N_per_kph2"]}
    trace = predict_speed_trace(cond, mass, v0_kph=v0_kph, duration_s=duration_s, power_w=power_w)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        work.to_csv(out / "cycle_work.csv", index=False)
        shares.to_csv(out / "cycle_work_shares.csv", index=False)
        trace.to_csv(out / "predicted_trace.csv", index=False)
    return work, shares, trace


def format_cycle_work(work: pd.DataFrame, shares: pd.DataFrame) -> str:
    """Plain-text cycle work (mean [2.5 %, 97.5 %]) and the variance shares."""
    lines = [f"  {work['cycle'].iloc[0]} road-load work:"]
    for _, r in work.iterrows():
        lines.append(f"  {r['quantity']:<24} {r['mean']:10.5g} {r['unit']:<6} [{r['q2.5']:.5g}, {r['q97.5']:.5g}]")
    lines.append("  variance share: " + ", ".join(f"{p} {s:.0%}" for p, s in
                                                   zip(shares["parameter"], shares["variance_share"])))
    return "\n".join(lines)
