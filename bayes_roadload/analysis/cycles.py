"""Drive cycles and the posterior of the road-load work over them.

Road-load work over a cycle (the quantity reported by :func:`cycle_work`)::

    W = sum_i F(v_i) v_i dt_i,   F(v) = f0 + f1 v + f2 v^2   (v in km/h, F in N)

with the cycle's speed trace v_i (1 Hz tables, trapezoidal weights dt_i), i.e. the energy the
road-load force dissipates while the vehicle follows the trace (level road, reference
conditions, still air).  It is linear in the coefficients, ``W = c0 f0 + c1 f1 + c2 f2`` with
``c_k = sum_i v_i^k (v_i / 3.6) dt_i``, so its posterior is exact draw by draw.  Its variance is
shared among the coefficients by their Shapley effects (:func:`variance_shares`): non-negative
shares that sum to one even though f0, f1 and f2 are strongly correlated.

The positive tractive work ``sum_i max(F(v_i) + M_e a_i, 0) v_i dt_i`` (with inertia, the
energy the wheels must deliver; a_i the central difference of the trace at sample i) is
reported beside it when an effective mass is given, and so is the cycle energy demand in the
per-step form of UN GTR 15 Annex 7 section 5 (:func:`cycle_energy_demand_j`): each step
between two samples at its mean speed, its acceleration the step's difference, its force kept
where positive.  The per-step form is a little above the central-difference one on the standard
cycles (the central difference smooths the acceleration peaks before the positive part is taken).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd

from .. import config

COEFFICIENTS = ("F0_N", "F1_N_per_kph", "F2_N_per_kph2")
CYCLES = {
    "wltc3b": "WLTC class 3b (UN GTR 15, Annex 1)",
    "nedc": "NEDC (UNECE Regulation 83: ECE-15 x4 + EUDC)",
    "ftp75": "FTP-75 (US EPA, 40 CFR part 86: UDDS + first 505 s)",
    "hwfet": "HWFET (US EPA, 40 CFR part 600)",
}


@dataclass(frozen=True)
class Cycle:
    """A speed trace: ``time_s`` (increasing) and ``speed_kph`` (>= 0)."""

    name: str
    time_s: np.ndarray
    speed_kph: np.ndarray

    @property
    def duration_s(self) -> float:
        return float(self.time_s[-1] - self.time_s[0])

    @property
    def distance_km(self) -> float:
        return float(np.trapezoid(self.speed_kph * config.KPH_TO_MPS, self.time_s)) / 1000.0


def _check(name: str, table: pd.DataFrame) -> Cycle:
    for col in ("time_s", "speed_kph"):
        if col not in table:
            raise ValueError(f"{name}: a cycle table needs columns time_s, speed_kph (missing {col})")
    cols = {c: pd.to_numeric(table[c], errors="coerce").to_numpy(float) for c in ("time_s", "speed_kph")}
    for col, x in cols.items():
        bad = np.flatnonzero(~np.isfinite(x))
        if bad.size:
            raise ValueError(f"{name}, column {col}, row {int(bad[0]) + 1}: {table[col].iloc[bad[0]]!r} is not a "
                             "finite number")
    t, v = cols["time_s"], cols["speed_kph"]
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        raise ValueError(f"{name}: column time_s does not increase at row {int(back[0]) + 2}")
    neg = np.flatnonzero(v < 0)
    if neg.size:
        raise ValueError(f"{name}: column speed_kph is negative at row {int(neg[0]) + 1}")
    return Cycle(name, t, v)


def load_cycle(name_or_path: str | Path) -> Cycle:
    """A packaged cycle (``wltc3b``, ``nedc``, ``ftp75``, ``hwfet``; sources in
    ``bayes_roadload/cycles/README.md``) or a CSV file with ``time_s, speed_kph``."""
    key = str(name_or_path).lower()
    if key in CYCLES:
        with resources.files("bayes_roadload.cycles").joinpath(f"{key}.csv").open() as f:
            return _check(key, pd.read_csv(f))
    path = Path(name_or_path)
    if not path.is_file():
        raise ValueError(f"{name_or_path}: not a packaged cycle ({', '.join(CYCLES)}) nor a CSV file")
    return _check(str(path), pd.read_csv(path))


def _weights(cycle: Cycle) -> np.ndarray:
    """Trapezoidal time weights dt_i (s)."""
    dt = np.diff(cycle.time_s)
    w = np.zeros_like(cycle.time_s)
    w[:-1] += dt / 2
    w[1:] += dt / 2
    return w


def work_coefficients_j(cycle: Cycle) -> np.ndarray:
    """``c_k = sum_i v_i^k (v_i / 3.6) dt_i`` (J per unit of f_k), so ``W = c . (f0, f1, f2)``."""
    v = cycle.speed_kph
    moving = v * config.KPH_TO_MPS * _weights(cycle)
    return np.array([moving.sum(), (v * moving).sum(), (v**2 * moving).sum()])


def _draws(samples: Mapping[str, np.ndarray]) -> np.ndarray:
    missing = [k for k in COEFFICIENTS if k not in samples]
    if missing:
        raise ValueError(f"posterior draws lack {', '.join(missing)}")
    return np.stack([np.asarray(samples[k], float).reshape(-1) for k in COEFFICIENTS], axis=1)


def _row(quantity: str, unit: str, x: np.ndarray) -> dict:
    return {"quantity": quantity, "unit": unit, "mean": float(x.mean()), "sd": float(x.std(ddof=1)),
            "q2.5": float(np.quantile(x, 0.025)), "q50": float(np.quantile(x, 0.5)),
            "q97.5": float(np.quantile(x, 0.975))}


def variance_shares(coef: np.ndarray, draws: np.ndarray) -> np.ndarray:
    """Shapley effects of the coefficients in Var(W), W = draws @ coef, as shares (sum 1; NaN
    when W has no spread).

    With v(S) = Var(E[W | f_S]) = Cov(W, f_S) Cov(f_S)^-1 Cov(f_S, W) (exact for a Gaussian
    posterior: the variance of W that knowing the coefficients in S would remove), coefficient
    k's share is phi_k / Var(W), phi_k = sum over S not holding k of |S|! (n - |S| - 1)! / n!
    (v(S + k) - v(S)) (Owen 2014; Song, Nelson and Staum 2016).  The phi_k are non-negative and
    sum to v(all) = Var(W); for independent coefficients phi_k = c_k^2 Var(f_k).  (The
    covariance split c_k Cov(f_k, W) / Var(W) also sums to one but goes negative when the
    coefficients are correlated, as f0, f1, f2 are.)
    """
    from itertools import combinations
    from math import factorial

    coef = np.asarray(coef, float)
    draws = np.asarray(draws, float)
    w = draws @ coef
    cov = np.cov(np.column_stack([draws, w]), rowvar=False)
    if not cov[-1, -1] > 0:  # a posterior without spread: no share to give
        return np.full(coef.shape, np.nan)
    n = len(coef)
    c_ff, c_fw = cov[:n, :n], cov[:n, -1]

    def explained(subset: tuple[int, ...]) -> float:
        if not subset:
            return 0.0
        idx = list(subset)
        return float(c_fw[idx] @ np.linalg.lstsq(c_ff[np.ix_(idx, idx)], c_fw[idx], rcond=None)[0])

    phi = np.zeros(n)
    for k in range(n):
        others = [j for j in range(n) if j != k]
        for size in range(n):
            weight = factorial(size) * factorial(n - size - 1) / factorial(n)
            for subset in combinations(others, size):
                phi[k] += weight * (explained(tuple(sorted(subset + (k,)))) - explained(subset))
    return phi / phi.sum()


def cycle_energy_demand_j(draws: np.ndarray, cycle: Cycle, effective_mass_kg: float) -> np.ndarray:
    """Cycle energy demand per draw (J), step by step as UN GTR 15 Annex 7 section 5 states it
    (the form as the project recalls it: its text is not among the references checked)::

        E = sum_i max(F_i, 0) d_i,   F_i = f0 + f1 vm_i + f2 vm_i^2 + M_e a_i,
        vm_i = (v_i + v_(i-1)) / 2,  a_i = (v_i - v_(i-1)) / (3.6 dt_i),  d_i = vm_i / 3.6 dt_i

    (v in km/h, ``draws`` rows (f0, f1, f2); GTR 15 takes M_e = 1.03 x the test mass)."""
    v = np.asarray(cycle.speed_kph, float)
    dt = np.diff(np.asarray(cycle.time_s, float))
    vm = 0.5 * (v[1:] + v[:-1])
    accel = np.diff(v) * config.KPH_TO_MPS / dt
    force = draws[:, :1] + draws[:, 1:2] * vm + draws[:, 2:3] * vm**2 + effective_mass_kg * accel
    return np.maximum(force, 0.0) @ (vm * config.KPH_TO_MPS * dt)


def cycle_work(samples: Mapping[str, np.ndarray], cycle: Cycle | str, *,
               effective_mass_kg: float | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Posterior of the road-load work over ``cycle`` (module docstring).

    Parameters
    ----------
    samples : posterior draws of ``F0_N``, ``F1_N_per_kph``, ``F2_N_per_kph2`` (any shape).
    cycle : a :class:`Cycle` or a name / path for :func:`load_cycle`.
    effective_mass_kg : M_e; when given, the positive tractive work and the cycle energy
        demand are reported too.

    Returns
    -------
    (work, shares): ``work`` rows ``road_load_work`` (kJ), ``road_load_work_per_km`` (kJ/km)
    [, ``tractive_work_positive`` (kJ), ``cycle_energy_demand`` (kJ, :func:`cycle_energy_demand_j`)] with ``mean, sd, q2.5, q50, q97.5``; ``shares`` rows
    per coefficient with ``variance_share`` of the road-load work.
    """
    cyc = cycle if isinstance(cycle, Cycle) else load_cycle(cycle)
    f = _draws(samples)
    coef = work_coefficients_j(cyc)
    w_kj = f @ coef / 1000.0
    rows = [_row("road_load_work", "kJ", w_kj), _row("road_load_work_per_km", "kJ/km", w_kj / cyc.distance_km)]
    if effective_mass_kg is not None:
        v = cyc.speed_kph
        accel = np.gradient(v * config.KPH_TO_MPS, cyc.time_s)
        force = f[:, :1] + f[:, 1:2] * v + f[:, 2:3] * v**2 + effective_mass_kg * accel
        power = np.maximum(force, 0.0) * v * config.KPH_TO_MPS
        rows.append(_row("tractive_work_positive", "kJ", power @ _weights(cyc) / 1000.0))
        rows.append(_row("cycle_energy_demand", "kJ", cycle_energy_demand_j(f, cyc, effective_mass_kg) / 1000.0))
    work = pd.DataFrame(rows)
    work.insert(0, "cycle", cyc.name)
    shares = pd.DataFrame({"cycle": cyc.name, "parameter": COEFFICIENTS,
                           "work_coefficient_j": coef, "variance_share": variance_shares(coef, f)})
    return work, shares


def predict_speed_trace(samples: Mapping[str, np.ndarray], effective_mass_kg: float, *, v0_kph: float,
                        duration_s: float, dt_s: float = 0.1, power_w: float = 0.0,
                        v_end_kph: float = 5.0) -> pd.DataFrame:
    """Posterior predictive speed trace of a manoeuvre on a level road in still air:
    ``M_e dv/dt = P / v - F(v)`` (a coastdown when ``power_w`` is 0, a constant-power
    acceleration otherwise), RK4 per draw from ``v0_kph``; a coastdown stops at ``v_end_kph``.
    Coefficients at other ambient conditions come from
    :func:`~bayes_roadload.analysis.standards.to_conditions`.

    Returns ``time_s, mean_kph, q2.5_kph, q50_kph, q97.5_kph`` over the draws still moving,
    up to the time the last draw stops.
    """
    f = _draws(samples)
    kph = 1.0 / config.KPH_TO_MPS

    def accel(v):  # m/s^2, v in m/s
        vk = v * kph
        drag = f[:, 0] + f[:, 1] * vk + f[:, 2] * vk**2
        return (power_w / np.maximum(v, 0.1) - drag) / effective_mass_kg

    n = int(round(duration_s / dt_s)) + 1
    v = np.full(f.shape[0], v0_kph * config.KPH_TO_MPS)
    out = np.empty((n, v.size))
    out[0] = v
    for i in range(1, n):
        k1 = accel(v)
        k2 = accel(v + 0.5 * dt_s * k1)
        k3 = accel(v + 0.5 * dt_s * k2)
        k4 = accel(v + dt_s * k3)
        v = v + dt_s / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        out[i] = v
    speed = out * kph
    if power_w == 0.0:
        stopped = np.maximum.accumulate(speed < v_end_kph, axis=0)
        speed = np.where(stopped, np.nan, speed)
    moving = ~np.all(np.isnan(speed), axis=1)
    speed = speed[moving]  # rows after every draw has stopped are dropped
    with warnings.catch_warnings():  # rows where some draws have stopped
        warnings.simplefilter("ignore", RuntimeWarning)
        return pd.DataFrame({"time_s": np.arange(n)[moving] * dt_s, "mean_kph": np.nanmean(speed, axis=1),
                             "q2.5_kph": np.nanquantile(speed, 0.025, axis=1),
                             "q50_kph": np.nanquantile(speed, 0.5, axis=1),
                             "q97.5_kph": np.nanquantile(speed, 0.975, axis=1)})
