"""``bayes-roadload predict``: the road-load work over a drive cycle and the predicted speed
trace of another manoeuvre, from a fit's posterior draws (:mod:`.cycles`, conditions via
:func:`.standards.to_conditions`)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping, NamedTuple

import numpy as np
import pandas as pd

from .. import config
from .cycles import cycle_work, predict_speed_trace
from .standards import load_draws, to_conditions


def _coefficient(draws: Mapping[str, np.ndarray], fixed: Mapping[str, object], name: str):
    """A parameter's draws, else the model's fixed number, else None."""
    if name in draws:
        return np.asarray(draws[name], float).reshape(-1)
    value = fixed.get(name)
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def mass_changed(draws: Mapping[str, np.ndarray], mass_kg_change: float, *,
                 mass_kg: float | None = None, effective_mass_kg: float,
                 fixed: Mapping[str, object] | None = None) -> dict[str, np.ndarray]:
    """The F0/F1/F2 draws (reference conditions) of the vehicle ``mass_kg_change`` kg heavier.

    Only the tyres' rolling loss carries the weight.  With the fit's tyre coefficients (``AD``
    and, where the model has them, ``BD`` and the v^2 coefficient C_R
    ``tyre_quadratic_s2_per_m2``, from the draws or the model's ``fixed`` values), the added
    load dM g adds its rolling loss dM g [A_D + B_D v + C_R (v^2 - a - b v)] (eq. 2.38 with the
    SAE J2452 speed law; a + b v :data:`~bayes_roadload.physics.terms.TYRE_QUADRATIC_LINE`),
    v = V / 3.6 for V in km/h: F0 gains dM g (A_D - C_R a), F1 dM g (B_D - C_R b) / 3.6, F2
    dM g C_R / 3.6^2; the driveline loss and the aerodynamic drag are unchanged.  Draws without
    ``AD`` (a kind that fits F0-F2 directly) scale F0 and F1 by the test mass ratio
    (M + dM) / M (``mass_kg``; the effective mass's ratio without it), the whole of F0 and F1
    then taken as rolling loss."""
    from ..physics.terms import TYRE_QUADRATIC_LINE

    fixed = fixed or {}
    f0, f1, f2 = (np.asarray(draws[k], float).reshape(-1) for k in ("F0_N", "F1_N_per_kph", "F2_N_per_kph2"))
    if mass_kg_change == 0.0:
        return {"F0_N": f0, "F1_N_per_kph": f1, "F2_N_per_kph2": f2}
    ad = _coefficient(draws, fixed, "AD")
    if ad is None:
        base = mass_kg if mass_kg is not None else effective_mass_kg
        ratio = (base + mass_kg_change) / base
        return {"F0_N": f0 * ratio, "F1_N_per_kph": f1 * ratio, "F2_N_per_kph2": f2}
    bd = _coefficient(draws, fixed, "BD")
    cr = _coefficient(draws, fixed, "tyre_quadratic_s2_per_m2")
    bd = 0.0 if bd is None else bd
    cr = 0.0 if cr is None else cr
    a, b = (float(x) for x in TYRE_QUADRATIC_LINE)
    weight = mass_kg_change * config.GRAVITY_MPS2
    kph = config.KPH_TO_MPS
    return {"F0_N": f0 + weight * (ad - cr * a), "F1_N_per_kph": f1 + weight * (bd - cr * b) * kph,
            "F2_N_per_kph2": f2 + weight * cr * kph**2}


class Prediction(NamedTuple):
    """What :func:`run_predict` computes: the cycle work of the fitted vehicle (``work``,
    ``shares``), the predicted trace (``trace``) and, for a mass change, the cycle work of the
    changed vehicle (``work_mass_changed``; None without one)."""

    work: pd.DataFrame
    shares: pd.DataFrame
    trace: pd.DataFrame
    work_mass_changed: pd.DataFrame | None = None


def run_predict(source: str | os.PathLike | Mapping[str, np.ndarray], cycle: str, *, effective_mass_kg: float,
                temperature_k: float = config.REFERENCE_TEMPERATURE_K,
                pressure_pa: float = config.REFERENCE_PRESSURE_PA, mass_kg_change: float = 0.0,
                mass_kg: float | None = None, fixed: Mapping[str, object] | None = None,
                v0_kph: float = 120.0, duration_s: float = 300.0, power_w: float = 0.0,
                out_dir: str | os.PathLike | None = None) -> Prediction:
    """Cycle work (at reference conditions, :func:`~.cycles.cycle_work`) and a predicted trace
    of a coastdown (``power_w`` 0) or constant-power run at ``temperature_k`` / ``pressure_pa``
    of the vehicle ``mass_kg_change`` kg heavier (:func:`mass_changed`: the rolling loss
    carries the weight; the effective mass, which the trace decelerates, gains the same kg, the
    rotating inertia unchanged).  With a mass change the cycle work of the changed vehicle too
    (reference conditions, its F0-F2 from :func:`mass_changed`, its inertia M_e + dM; column
    ``mass_change_kg``).  ``mass_kg``: the fit's test mass; ``fixed``: the fit's model's fixed
    parameter values (its tyre coefficients where they are not sampled).  With ``out_dir``:
    ``cycle_work.csv``, ``cycle_work_shares.csv``, ``predicted_trace.csv`` and, with a mass
    change, ``cycle_work_mass_changed.csv``."""
    draws = load_draws(source) if isinstance(source, (str, os.PathLike)) else source
    work, shares = cycle_work(draws, cycle, effective_mass_kg=effective_mass_kg)
    heavier = mass_changed(draws, mass_kg_change, mass_kg=mass_kg, effective_mass_kg=effective_mass_kg, fixed=fixed)
    work_changed = None
    if mass_kg_change != 0.0:
        work_changed, _ = cycle_work(heavier, cycle, effective_mass_kg=effective_mass_kg + mass_kg_change)
        work_changed["mass_change_kg"] = float(mass_kg_change)
    cond = to_conditions(heavier, temperature_k, pressure_pa)
    trace = predict_speed_trace(cond, effective_mass_kg + mass_kg_change, v0_kph=v0_kph, duration_s=duration_s,
                                power_w=power_w)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        work.to_csv(out / "cycle_work.csv", index=False)
        shares.to_csv(out / "cycle_work_shares.csv", index=False)
        trace.to_csv(out / "predicted_trace.csv", index=False)
        if work_changed is not None:
            work_changed.to_csv(out / "cycle_work_mass_changed.csv", index=False)
    return Prediction(work, shares, trace, work_changed)


def format_cycle_work(work: pd.DataFrame, shares: pd.DataFrame, work_mass_changed: pd.DataFrame | None = None) -> str:
    """Plain-text cycle work (mean [2.5 %, 97.5 %]) and the variance shares; with
    ``work_mass_changed``, the changed vehicle's work after them."""
    def rows(frame: pd.DataFrame) -> list[str]:
        return [f"  {r['quantity']:<24} {r['mean']:10.5g} {r['unit']:<6} [{r['q2.5']:.5g}, {r['q97.5']:.5g}]"
                for _, r in frame.iterrows()]

    lines = [f"  {work['cycle'].iloc[0]} road-load work:", *rows(work)]
    lines.append("  variance share: " + ", ".join(f"{p} {s:.0%}" for p, s in
                                                   zip(shares["parameter"], shares["variance_share"])))
    if work_mass_changed is not None:
        dm = float(work_mass_changed["mass_change_kg"].iloc[0])
        lines += [f"  with the test mass {dm:+g} kg (reference conditions):", *rows(work_mass_changed)]
    return "\n".join(lines)
