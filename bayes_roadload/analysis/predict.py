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


def mass_changed(draws: Mapping[str, np.ndarray], mass_kg_change: float, *,
                 mass_kg: float | None = None, effective_mass_kg: float) -> dict[str, np.ndarray]:
    """The F0/F1/F2 draws (reference conditions) of the vehicle ``mass_kg_change`` kg heavier.

    Only the tyres' rolling loss carries the weight: with the fit's tyre coefficients in the
    draws (``AD``, ``BD``: the rolling loss M g (A_D + B_D v), eq. 2.38), F0 gains
    dM g A_D and F1 gains dM g B_D / 3.6 (per km/h), the driveline loss and the aerodynamic
    F2 unchanged (a model's tyre v^2 term, C_R, adds dM g C_R / 3.6^2 to F2: not added, 0.6 %
    of a car's F2 for 300 kg at C_R 1e-6).  Draws without them (a kind that fits F0-F2 directly) scale F0 and F1 by
    the test mass ratio (M + dM) / M (``mass_kg``; the effective mass's ratio without it), the
    whole of F0 and F1 then taken as rolling loss."""
    f0, f1, f2 = (np.asarray(draws[k], float).reshape(-1) for k in ("F0_N", "F1_N_per_kph", "F2_N_per_kph2"))
    if mass_kg_change == 0.0:
        return {"F0_N": f0, "F1_N_per_kph": f1, "F2_N_per_kph2": f2}
    if "AD" in draws and "BD" in draws:
        weight = mass_kg_change * config.GRAVITY_MPS2
        ad, bd = (np.asarray(draws[k], float).reshape(-1) for k in ("AD", "BD"))
        return {"F0_N": f0 + weight * ad, "F1_N_per_kph": f1 + weight * bd * config.KPH_TO_MPS, "F2_N_per_kph2": f2}
    base = mass_kg if mass_kg is not None else effective_mass_kg
    ratio = (base + mass_kg_change) / base
    return {"F0_N": f0 * ratio, "F1_N_per_kph": f1 * ratio, "F2_N_per_kph2": f2}


def run_predict(source: str | os.PathLike | Mapping[str, np.ndarray], cycle: str, *, effective_mass_kg: float,
                temperature_k: float = config.REFERENCE_TEMPERATURE_K,
                pressure_pa: float = config.REFERENCE_PRESSURE_PA, mass_kg_change: float = 0.0,
                mass_kg: float | None = None, v0_kph: float = 120.0, duration_s: float = 300.0,
                power_w: float = 0.0, out_dir: str | os.PathLike | None = None
                ) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """Cycle work (at reference conditions, :func:`~.cycles.cycle_work`) and a predicted trace
    of a coastdown (``power_w`` 0) or constant-power run at ``temperature_k`` / ``pressure_pa``
    of the vehicle ``mass_kg_change`` kg heavier (:func:`mass_changed`: the rolling loss
    carries the weight; the effective mass, which the trace decelerates, gains the same kg, the
    rotating inertia unchanged).  ``mass_kg``: the fit's test mass.  With ``out_dir``:
    ``cycle_work.csv``, ``cycle_work_shares.csv``, ``predicted_trace.csv``.

    Returns (work, shares, trace)."""
    draws = load_draws(source) if isinstance(source, (str, os.PathLike)) else source
    work, shares = cycle_work(draws, cycle, effective_mass_kg=effective_mass_kg)
    heavier = mass_changed(draws, mass_kg_change, mass_kg=mass_kg, effective_mass_kg=effective_mass_kg)
    cond = to_conditions(heavier, temperature_k, pressure_pa)
    trace = predict_speed_trace(cond, effective_mass_kg + mass_kg_change, v0_kph=v0_kph, duration_s=duration_s,
                                power_w=power_w)
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
