"""The classical baseline: nonlinear least squares of measured against integrated speed.

Thesis chapter 5 (``ROADLOAD_MODEL.md`` section 6): for a group of runs sharing the free
coefficients (one run, one opposite-direction pair, or every run), minimise

    S(x) = sum_runs sum_i (v_meas,i - v_calc,i(x))^2

where ``v_calc`` integrates the coastdown equation (eq. 5.4) with RK4 on the sample grid from
the first measured speed, using the measured relative airspeed, yaw and driveline force.  The
standard errors come from the Jacobian at the optimum, ``cov = s^2 (J^T J)^-1`` with
``s^2 = S / (n - p)``; groups are combined by the inverse-variance weighted mean (eq. 5.15,
5.16) and the between-group spread is reported as the thesis did (% standard deviation over
pairs).  Two departures from the thesis: by default (``LsqSettings(initial_speed="fitted")``)
each run's initial speed is estimated too, which makes the standard errors honest under speed
noise (the thesis' measured v0, ``initial_speed="measured"``, makes them ~10x too small and is
kept to reproduce its tables); and quantities the data do not identify (a singular Jacobian
direction) are reported with SE = inf instead of a number.

Implementation notes: the optimiser works on scaled parameters ``x / config.PARAMETER_SCALES``
so every unknown is O(1); the residual and its exact Jacobian (``jax.jacfwd``) are jitted once
per (model, free parameters) and, because every group of a grouping is padded to the same
[runs, samples] shape, one compiled function serves all groups.
"""

from __future__ import annotations

import functools
import math
import os
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Mapping

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
from scipy.optimize import least_squares

from .. import config
from ..physics.atmosphere import REFERENCE_AIR_DENSITY_KGPM3
from ..physics.integrate import RunBatch, bucket_length, integrate_batch, pad_batch
from ..physics.model import DragModel
from ..physics.roadload import road_load_summary
from .spec import ModelSpec, load_model_spec

GROUPINGS = ("run", "pair", "all")
SUMMARY_COLUMNS = ("parameter", "mean", "sd", "q2.5", "q50", "q97.5", "r_hat", "ess_bulk", "ess_tail")
"""The columns of ``summary.csv`` shared by every fitting method (issue-3 contract)."""
DERIVED = ("F50_N", "F0_N", "F1_N_per_kph", "F2_N_per_kph2")
"""Derived road-load figures at reference conditions in still air (contract names)."""
F50_PARTS = ("F50_tyre_N", "F50_aero_N", "F50_driveline_N", "F50_undriven_N")
"""The parts of F50_N by effect (reported in per_group.csv and fit.json)."""
Z95 = 1.959963984540054
"""Two-sided 95 % point of the standard normal."""

@dataclass(frozen=True)
class LsqSettings:
    """Settings of the least-squares fit.

    Parameters
    ----------
    method : {"lm", "trf"}
        ``scipy.optimize.least_squares`` method (Levenberg-Marquardt by default, as MINPACK).
    ftol, xtol, gtol : float
        Convergence tolerances (tight: on noise-free data the fit recovers the inputs to
        ~1e-8 relative).
    max_nfev : int
        Maximum residual evaluations per group.
    reference_speed_mps : float
        Speed of the headline road-load figure F50_N (50 mph = 22.352 m/s).
    roadload_speeds_kph : tuple of float
        Speeds (km/h) at which the still-air road load is evaluated to fit
        F = F0 + F1 v + F2 v^2 (exact when the model is quadratic in v; with lift unloading the
        small cubic part is projected onto the quadratic over this range).
    integrator : IntegratorConfig
        RK4 substeps per sample interval.
    initial_speed : {"measured", "fitted"}
        ``"fitted"`` (default): the initial speed of each run is estimated too (see below).
        ``"measured"`` (the thesis' method): every run is integrated from its first measured
        speed.  With speed noise that sample's error shifts the whole calculated trace, the
        residuals are correlated along the run, and the covariance-based standard errors are
        too small (by ~10x at 0.05 m/s noise).  ``"fitted"``: the initial speed of each run is
        estimated too (a nuisance offset from the first sample, which then counts as a datum),
        so the residuals are independent and the standard errors honest.
    rank_rcond : float
        Singular values of the scaled Jacobian below ``rank_rcond`` x the largest are
        treated as zero (about sqrt(machine epsilon): J^T J squares the condition number).
        Quantities depending on the corresponding directions are reported unidentified.
    """

    method: str = "lm"
    ftol: float = 1e-12
    xtol: float = 1e-12
    gtol: float = 1e-12
    max_nfev: int = 200
    reference_speed_mps: float = config.SPEED_50MPH_MPS
    roadload_speeds_kph: tuple[float, ...] = config.ROADLOAD_FIT_SPEEDS_KPH
    integrator: config.IntegratorConfig = config.DEFAULT_INTEGRATOR
    initial_speed: str = "fitted"
    rank_rcond: float = 1e-8

    def __post_init__(self):
        if self.initial_speed not in ("measured", "fitted"):
            raise ValueError(f"initial_speed must be 'measured' or 'fitted', not {self.initial_speed!r}")


DEFAULT_LSQ = LsqSettings()
V0_OFFSET_SCALE_MPS = 0.1
"""Scale of the fitted initial-speed offsets (``initial_speed="fitted"``), m/s."""


# ----------------------------------------------------------------------------- statistics

def weighted_mean(values, ses) -> tuple[float, float]:
    """Inverse-variance weighted mean and its standard error (thesis eq. 5.15, 5.16).

    x_bar = sum(x_i / s_i^2) / sum(1 / s_i^2),  s_bar = (sum 1 / s_i^2)^(-1/2).

    Groups with a non-finite standard error (an unidentified quantity) get no weight, and
    the result is NaN when no group has one; if some have s_i = 0 their plain mean is
    returned with s_bar = 0.
    """
    x = np.asarray(values, float)
    s = np.asarray(ses, float)
    ok = np.isfinite(x) & np.isfinite(s)
    if not ok.any():
        return math.nan, math.nan
    x, s = x[ok], s[ok]
    if np.any(s == 0):
        return float(np.mean(x[s == 0])), 0.0
    w = 1.0 / s**2
    return float(np.sum(w * x) / np.sum(w)), float(np.sum(w) ** -0.5)


def between_group_spread(values) -> tuple[float, float, float]:
    """Plain mean, sample standard deviation (ddof 1) and std as % of |mean| over groups
    (the thesis' test-to-test spread); std is NaN for a single group."""
    x = np.asarray(values, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return math.nan, math.nan, math.nan
    mean = float(np.mean(x))
    std = float(np.std(x, ddof=1)) if x.size > 1 else math.nan
    pct = 100.0 * std / abs(mean) if mean != 0 else math.nan
    return mean, std, pct


# ----------------------------------------------------------------------------- results

@dataclass(frozen=True)
class GroupFit:
    """The least-squares fit of one group of runs.

    Attributes
    ----------
    label : str
    run_ids : tuple
    estimate, se : free parameter and derived quantity -> value / standard error (SI).
    cov : [p, p] covariance of the free parameters (SI), order of ``LsqResult.free``;
        rows and columns of unidentified parameters are NaN.
    ssr_m2ps2 : sum of squared speed residuals (m^2/s^2).
    rms_residual_mps : sqrt(ssr / n_samples).
    n_samples : residuals counted (real samples; minus each run's initial point when it is not fitted).
    success, nfev, message : from the optimiser.
    condition_number : of the scaled Jacobian at the optimum (large: poorly identified).
    fit_time_s : wall time of this group's optimisation.
    v0_offset_mps : fitted initial speed minus the first measured speed, per run (empty
        unless ``initial_speed="fitted"``).
    unidentified : free parameters and derived quantities the data do not identify (their
        direction lies in the Jacobian's numerical null space; SE = inf).  E.g. K_D without
        cross-wind, or A_D vs A_t with a fitted driveline polynomial.
    """

    label: str
    run_ids: tuple
    estimate: dict[str, float]
    se: dict[str, float]
    cov: np.ndarray
    ssr_m2ps2: float
    rms_residual_mps: float
    n_samples: int
    success: bool
    nfev: int
    message: str
    condition_number: float
    fit_time_s: float
    v0_offset_mps: tuple[float, ...] = ()
    unidentified: tuple[str, ...] = ()


@dataclass(frozen=True)
class LsqResult:
    """Result of :func:`fit_lsq`.

    Attributes
    ----------
    model_name, description : of the model spec.
    grouping : "run", "pair" or "all".
    free : the free parameters; ``derived`` : the derived quantities (both contract names).
    groups : per-group fits; ``per_group`` : the same as a DataFrame.
    weighted_mean, weighted_se : eq. 5.15 / 5.16 over groups, per free parameter and derived
        quantity.
    between_mean, between_std, between_std_pct : plain spread over groups.
    fixed : the values of the fixed parameters (SI).
    truth : the campaign's true parameters when simulated, else None.
    compile_time_s, fit_time_s : jit compilation of the residual and its Jacobian (first
        call) and the total optimisation time of all groups (s).
    settings : the :class:`LsqSettings` used.
    """

    model_name: str
    description: str
    grouping: str
    free: tuple[str, ...]
    derived: tuple[str, ...]
    groups: tuple[GroupFit, ...]
    per_group: pd.DataFrame
    weighted_mean: dict[str, float]
    weighted_se: dict[str, float]
    between_mean: dict[str, float]
    between_std: dict[str, float]
    between_std_pct: dict[str, float]
    fixed: dict[str, float] = field(default_factory=dict)
    truth: dict[str, float] | None = None
    compile_time_s: float = math.nan
    fit_time_s: float = math.nan
    settings: LsqSettings = DEFAULT_LSQ

    @property
    def quantities(self) -> tuple[str, ...]:
        """Free parameters then derived quantities: the rows of ``summary.csv``."""
        return self.free + self.derived

    def summary(self) -> pd.DataFrame:
        """The ``summary.csv`` table: weighted mean, its SE, normal 95 % bounds."""
        rows = []
        for q in self.quantities:
            m, s = self.weighted_mean[q], self.weighted_se[q]
            rows.append({"parameter": q, "mean": m, "sd": s, "q2.5": m - Z95 * s, "q50": m,
                         "q97.5": m + Z95 * s, "r_hat": math.nan, "ess_bulk": math.nan,
                         "ess_tail": math.nan})
        return pd.DataFrame(rows, columns=list(SUMMARY_COLUMNS))


# ----------------------------------------------------------------------------- the fit

@functools.lru_cache(maxsize=32)
def _compiled(model: DragModel, free: tuple[str, ...], integrator: config.IntegratorConfig,
              fit_v0: bool):
    """Jitted residual and Jacobian in scaled parameters for one (model, free) pair.

    ``residual(theta, fixed, batch)`` returns the masked residuals v_meas - v_calc of a
    [R, N] batch flattened to [R N]; jit retraces only when the batch shape changes.  With
    ``fit_v0`` the last R entries of ``theta`` are the runs' initial-speed offsets in units
    of :data:`V0_OFFSET_SCALE_MPS`.
    """
    scales = jnp.asarray([config.PARAMETER_SCALES[p] for p in free])
    n_free = len(free)

    def residual(theta, fixed, batch):
        params = dict(fixed)
        params.update({p: theta[i] * scales[i] for i, p in enumerate(free)})
        v0 = batch.speed_mps[:, 0] + V0_OFFSET_SCALE_MPS * theta[n_free:] if fit_v0 else None
        v, _ = integrate_batch(model, params, batch, v0_mps=v0, integrator=integrator)
        return jnp.where(batch.mask, batch.speed_mps - v, 0.0).reshape(-1)

    return jax.jit(residual), jax.jit(jax.jacfwd(residual))


@functools.lru_cache(maxsize=32)
def _compiled_figures(model: DragModel, free: tuple[str, ...], settings: LsqSettings):
    """Jitted :func:`roadload_figures` of the free parameters (SI) and its Jacobian, for the
    delta-method standard errors of the derived figures."""

    def figures(theta_phys, fixed, curve, vehicle):
        params = dict(fixed)
        params.update({p: theta_phys[i] for i, p in enumerate(free)})
        return roadload_figures(model, params, mass_kg=vehicle[0], frontal_area_m2=vehicle[1],
                                driveline_curve=curve, settings=settings)

    return jax.jit(figures), jax.jit(jax.jacfwd(figures))


def _lsq_batch(campaign, spec: ModelSpec) -> tuple[RunBatch, list]:
    """The campaign's runs as ``spec`` reads them (:meth:`ModelSpec.to_batch`) as a batch padded to the next of
    :data:`~bayes_roadload.config.LSQ_PAD_SIZES_PER_OCTAVE` lengths per doubling
    (:func:`~bayes_roadload.physics.integrate.bucket_length`), and the run ids.  The residual and
    its Jacobian take the batch as an argument (:func:`_compiled`), so campaigns of the same
    number of runs and nearly the same length share their compiled programs (within a process,
    and across processes through the persistent compilation cache); padded samples leave the
    fit unchanged (masked)."""
    batch, run_ids = spec.to_batch(campaign)
    return pad_batch(batch, bucket_length(batch.time_s.shape[-1], config.LSQ_PAD_SIZES_PER_OCTAVE)), run_ids


def _select(batch: RunBatch, idx) -> RunBatch:
    idx = np.asarray(idx)
    return RunBatch(*(jnp.asarray(x)[idx] for x in batch))


def lsq_groups(campaign, grouping: str) -> list[tuple[str, tuple]]:
    """The groups of runs :func:`fit_lsq` fits one by one for ``grouping`` ("run", "pair",
    "all"): (label, run ids); refused (ValueError) when the campaign cannot be grouped so."""
    return _groups(campaign, grouping, list(campaign.run_ids))


def _groups(campaign, grouping: str, run_ids: list) -> list[tuple[str, tuple]]:
    if grouping == "run":
        return [(str(r), (r,)) for r in run_ids]
    if grouping == "pair":
        pairs = campaign.pairs()
        if not pairs:
            raise ValueError("grouping 'pair' (--grouping pair): the campaign has no opposite-direction pairs "
                             "(use grouping 'run' or 'all')")
        return [("+".join(str(r) for r in p), tuple(p)) for p in pairs]
    if grouping == "all":
        return [("all", tuple(run_ids))]
    raise ValueError(f"grouping must be one of {GROUPINGS}, not {grouping!r}")


def _driveline_curve(campaign, run_ids) -> np.ndarray:
    """Quadratic fit (c2, c1, c0) of the logged driveline force against speed over the
    group's runs (thesis 5.5.1), so a measured driveline can enter the road-load figures."""
    if not campaign.has_driveline:
        return np.zeros(3)
    rows = campaign.runs[campaign.runs["run"].isin(list(run_ids))]
    return np.polyfit(rows["speed_mps"].to_numpy(float), rows["driveline_force_n"].to_numpy(float), 2)


def roadload_figures(model: DragModel, params: Mapping[str, Any], *, mass_kg: float,
                     frontal_area_m2: float, driveline_curve=(0.0, 0.0, 0.0),
                     settings: LsqSettings = DEFAULT_LSQ) -> jnp.ndarray:
    """Road-load figures at reference conditions in still air, as a JAX vector.

    Evaluates the model's terms with v_r = v, psi = 0, rho = 1.1882 kg/m^3 (100 kPa,
    293.2 K), tyre temperature at the reference, no acceleration, no gradient.

    Parameters
    ----------
    model, params : the drag model and a complete or partial parameter mapping (SI).
    mass_kg, frontal_area_m2 : the vehicle.
    driveline_curve : (c2, c1, c0) of the measured driveline force in N against v in m/s,
        used by the ``driveline_measured`` term (zeros otherwise).  :func:`fit_lsq` fits it
        to the group's logged channel (thesis 5.5.1); its own uncertainty is not propagated.
    settings : reference speed and the speed grid of the quadratic fit.

    Returns
    -------
    jnp.ndarray
        ``[F50_N, F0_N, F1_N_per_kph, F2_N_per_kph2, F50_tyre_N, F50_aero_N,
        F50_driveline_N, F50_undriven_N]``; F = F0 + F1 v + F2 v^2 with v in km/h is the
        least-squares quadratic through the total on ``settings.roadload_speeds_kph``.
    """
    figures = road_load_summary(model, params, mass_kg, frontal_area_m2, driveline_curve=driveline_curve,
                                reference_speed_mps=settings.reference_speed_mps,
                                fit_speeds_kph=settings.roadload_speeds_kph)
    return jnp.stack([figures[k] for k in DERIVED + F50_PARTS])


@dataclass(frozen=True)
class _Covariance:
    """s^2 (J^T J)^+ from the SVD of the scaled Jacobian, with its null space.

    Singular values below ``rcond * s_max`` are treated as zero: the directions they span
    are not identified by the data.  A linear combination g of the (scaled) parameters is
    estimable when g is orthogonal to that null space; its standard error is then
    sqrt(g cov g^T) (the pseudo-inverse is exact for estimable functions), otherwise inf.
    """

    cov: np.ndarray
    null: np.ndarray  # [p, k] orthonormal basis of the unidentified directions
    condition_number: float

    @classmethod
    def from_jacobian(cls, jac: np.ndarray, ssr: float, dof: int, rcond: float) -> "_Covariance":
        _, s, vt = np.linalg.svd(jac, full_matrices=False)
        cond = float(s[0] / s[-1]) if s[-1] > 0 else math.inf
        keep = s > rcond * s[0]
        sigma2 = ssr / dof if dof > 0 else math.nan
        v = vt[keep].T
        return cls(sigma2 * (v / s[keep] ** 2) @ v.T, vt[~keep].T, cond)

    def se(self, g: np.ndarray) -> float:
        """Standard error of g . theta (g a row over the scaled parameters)."""
        g = np.asarray(g, float)
        norm = float(np.linalg.norm(g))
        if norm == 0.0:
            return 0.0
        if self.null.size and float(np.linalg.norm(g @ self.null)) > _ESTIMABLE_TOL * norm:
            return math.inf
        var = float(g @ self.cov @ g)
        return math.sqrt(var) if var >= 0 else math.nan


_ESTIMABLE_TOL = 1e-6


def fit_lsq(campaign, spec: ModelSpec | str | os.PathLike = "four_term", grouping: str = "pair", *,
            initial: Mapping[str, float] | None = None, hold: Mapping[str, float] | None = None,
            settings: LsqSettings = DEFAULT_LSQ) -> LsqResult:
    """Fit a model variant to a campaign by least squares, group by group.

    Parameters
    ----------
    campaign : :class:`~bayes_roadload.data.Campaign`
    spec : ModelSpec, or a model name / path for :func:`~bayes_roadload.inference.spec.load_model_spec`.
    grouping : {"run", "pair", "all"}
        Runs sharing one set of free coefficients: each run alone, each opposite-direction
        pair (the thesis' practice), or the whole campaign.
    initial : free parameter -> starting value (SI); defaults to the spec's ``initial``, else
        the model default.
    hold : free parameter -> value (SI) at which it is held while the others are fitted: the
        same fit as with the parameter fixed in the spec, through the compiled programs of the
        unheld fit (the solver's unknowns are the unheld ones, the residual's Jacobian keeps
        their columns); a held parameter's estimate is its value, its standard error 0.
    settings : optimiser tolerances and reference conditions.

    Returns
    -------
    LsqResult
    """
    if not isinstance(spec, ModelSpec):
        spec = load_model_spec(spec)
    if grouping not in GROUPINGS:
        raise ValueError(f"grouping must be one of {GROUPINGS}, not {grouping!r}")
    model, fixed, free = spec.build(campaign)
    if not free:
        raise ValueError(f"model {spec.name!r} has no free parameter to fit")
    defaults = model.defaults
    hold = dict(hold or {})
    if unknown := sorted(set(hold) - set(free)):
        raise ValueError(f"hold: {', '.join(unknown)} not free in model {spec.name!r}")
    start = {p: hold.get(p, (initial or {}).get(p, spec.initial.get(p, defaults[p]))) for p in free}
    scales = np.asarray([config.PARAMETER_SCALES[p] for p in free])
    theta0 = np.asarray([start[p] for p in free]) / scales

    batch, run_ids = _lsq_batch(campaign, spec)
    index = {r: i for i, r in enumerate(run_ids)}
    fit_v0 = settings.initial_speed == "fitted"
    fun, jac = _compiled(model, free, settings.integrator, fit_v0)
    fixed_j = {k: jnp.asarray(v, float) for k, v in fixed.items()}
    groups = _groups(campaign, grouping, run_ids)
    vehicle = jnp.asarray([campaign.vehicle.mass_kg, campaign.vehicle.frontal_area_m2])
    figures_j, figures_jac = _compiled_figures(model, free, settings)
    derived_names = DERIVED + F50_PARTS

    n_runs = len(groups[0][1])  # every group of a grouping has the same number of runs
    x0 = np.concatenate([theta0, np.zeros(n_runs)]) if fit_v0 else theta0
    n_fit = len(x0)
    solved = np.asarray([i for i in range(n_fit) if i >= len(free) or free[i] not in hold], int)
    unit_solved = np.eye(n_fit)[:, solved]  # full vector -> the solver's unknowns

    def full(x):
        out = x0.copy()
        out[solved] = x
        return out

    t_compile = time.perf_counter()
    first = _select(batch, [index[r] for r in groups[0][1]])
    jax.block_until_ready(fun(jnp.asarray(x0), fixed_j, first))
    jax.block_until_ready(jac(jnp.asarray(x0), fixed_j, first))
    compile_time = time.perf_counter() - t_compile

    fits = []
    t_all = time.perf_counter()
    for label, ids in groups:
        t0 = time.perf_counter()
        b = _select(batch, [index[r] for r in ids])
        res = least_squares(
            lambda x: np.asarray(fun(jnp.asarray(full(x)), fixed_j, b)),
            x0[solved],
            jac=lambda x: np.asarray(jac(jnp.asarray(full(x)), fixed_j, b))[:, solved],
            method=settings.method, ftol=settings.ftol, xtol=settings.xtol, gtol=settings.gtol,
            max_nfev=settings.max_nfev)
        # with the measured initial speed each run's first residual is 0 by construction
        n = int(np.asarray(b.mask).sum()) - (0 if fit_v0 else len(ids))
        ssr = float(np.sum(res.fun**2))
        cv = _Covariance.from_jacobian(np.asarray(res.jac), ssr, n - len(solved), settings.rank_rcond)
        p = len(free)
        x_full = full(res.x)
        cov_full = unit_solved @ cv.cov @ unit_solved.T  # held parameters: zero rows and columns
        cov = cov_full[:p, :p] * np.outer(scales, scales)  # marginal over the v0 offsets
        est_phys = x_full[:p] * scales
        v0_offsets = tuple(float(x) * V0_OFFSET_SCALE_MPS for x in x_full[p:])
        estimate = dict(zip(free, (float(x) for x in est_phys)))
        se = {q: cv.se(unit_solved[i]) * scales[i] for i, q in enumerate(free)}
        curve = _driveline_curve(campaign, ids)
        d = np.asarray(figures_j(jnp.asarray(est_phys), fixed_j, jnp.asarray(curve), vehicle))
        g = np.asarray(figures_jac(jnp.asarray(est_phys), fixed_j, jnp.asarray(curve), vehicle))
        g = np.concatenate([g * scales, np.zeros((g.shape[0], n_fit - p))], axis=1)
        for k, name in enumerate(derived_names):
            estimate[name] = float(d[k])
            se[name] = cv.se(g[k] @ unit_solved)
        unidentified = tuple(q for q in free + derived_names if math.isinf(se[q]))
        for i, q in enumerate(free):
            if q in unidentified:
                cov[i, :] = cov[:, i] = math.nan
        if unidentified:
            warnings.warn(
                f"least squares, model {spec.name!r}, group {label}: {', '.join(unidentified)} "
                f"not identified by the speed data (Jacobian condition number "
                f"{cv.condition_number:.3g}); their standard errors are reported as inf",
                RuntimeWarning, stacklevel=2)
        fits.append(GroupFit(
            label=label, run_ids=tuple(ids), estimate=estimate, se=se, cov=cov, ssr_m2ps2=ssr,
            rms_residual_mps=math.sqrt(ssr / n) if n > 0 else math.nan, n_samples=n,
            success=bool(res.success), nfev=int(res.nfev), message=str(res.message),
            condition_number=cv.condition_number, fit_time_s=time.perf_counter() - t0,
            v0_offset_mps=v0_offsets, unidentified=unidentified))
    fit_time = time.perf_counter() - t_all

    quantities = free + derived_names
    wm, ws, bm, bs, bp = {}, {}, {}, {}, {}
    for q in quantities:
        wm[q], ws[q] = weighted_mean([f.estimate[q] for f in fits], [f.se[q] for f in fits])
        bm[q], bs[q], bp[q] = between_group_spread([f.estimate[q] for f in fits])
    return LsqResult(
        model_name=spec.name, description=spec.description, grouping=grouping, free=free,
        derived=DERIVED, groups=tuple(fits), per_group=_per_group_frame(fits, quantities),
        weighted_mean=wm, weighted_se=ws, between_mean=bm, between_std=bs, between_std_pct=bp,
        fixed={k: float(v) for k, v in fixed.items()}, truth=campaign.truth,
        compile_time_s=compile_time, fit_time_s=fit_time, settings=settings)


def linear_sensitivities(campaign, spec: ModelSpec | str, shifts: Mapping[str, tuple[Any, Any, float]],
                         settings: LsqSettings = DEFAULT_LSQ) -> tuple[LsqResult, dict[str, dict[str, float]]]:
    """First-order sensitivities of the joint least-squares estimate (one group) to changes of
    the campaign, without refitting: for each ``key -> (campaign_plus, campaign_minus, h)`` (the
    campaign shifted by +h and -h in some declared value), by the implicit function theorem at
    the optimum x* of the unshifted campaign (one Gauss-Newton step):

        dx/ds = -(J^T J)^+ J^T dr/ds,   dr/ds = (r(x*; plus) - r(x*; minus)) / (2 h),

    J the residuals' Jacobian at x* (free coefficients and the runs' initial-speed offsets), and
    for every derived figure q (F50_N, F0_N, ...) ``dq/ds = (dq/dtheta) dtheta/ds`` plus its
    direct change at fixed coefficients (a mass or an area enters the figures themselves).
    Equal to central differences of refits to first order in h; one residual evaluation per
    shifted campaign instead of a refit.  Returns the unshifted fit and key -> quantity ->
    sensitivity (a key whose shifted campaigns change the model's structure is left out)."""
    if not isinstance(spec, ModelSpec):
        spec = load_model_spec(spec)
    base = fit_lsq(campaign, spec, grouping="all", settings=settings)
    g0 = base.groups[0]
    model, fixed, free = spec.build(campaign)
    fit_v0 = settings.initial_speed == "fitted"
    fun, jac = _compiled(model, free, settings.integrator, fit_v0)
    figures_j, figures_jac = _compiled_figures(model, free, settings)
    scales = np.asarray([config.PARAMETER_SCALES[q] for q in free])
    theta = np.asarray([g0.estimate[q] for q in free])
    x = np.concatenate([theta / scales, np.asarray(g0.v0_offset_mps) / V0_OFFSET_SCALE_MPS]) if fit_v0 \
        else theta / scales
    batch, run_ids = _lsq_batch(campaign, spec)
    fixed_j = {k: jnp.asarray(v, float) for k, v in fixed.items()}
    jmat = np.asarray(jac(jnp.asarray(x), fixed_j, batch))
    gmat = np.asarray(figures_jac(jnp.asarray(theta), fixed_j, jnp.asarray(_driveline_curve(campaign, run_ids)),
                                  jnp.asarray([campaign.vehicle.mass_kg, campaign.vehicle.frontal_area_m2])))
    names = DERIVED + F50_PARTS
    out: dict[str, dict[str, float]] = {}
    for key, (plus, minus, h) in shifts.items():
        parts = []
        for c in (plus, minus):
            m, fx, fr = spec.build(c)
            # the same terms and air model (compared by name: terms may hold arrays, e.g. a
            # tunnel table), so the compiled residual of the unshifted campaign applies
            if type(m.air) is not type(model.air) or tuple(m.term_names) != tuple(model.term_names) \
                    or tuple(fr) != tuple(free):
                break
            fxj = {k: jnp.asarray(v, float) for k, v in fx.items()}
            b, ids = _lsq_batch(c, spec)
            vehicle = jnp.asarray([c.vehicle.mass_kg, c.vehicle.frontal_area_m2])
            parts.append((np.asarray(fun(jnp.asarray(x), fxj, b)),
                          np.asarray(figures_j(jnp.asarray(theta), fxj, jnp.asarray(_driveline_curve(c, ids)), vehicle))))
        if len(parts) < 2:
            continue
        dr = (parts[0][0] - parts[1][0]) / (2.0 * h)
        dx = -np.linalg.lstsq(jmat, dr, rcond=settings.rank_rcond)[0]
        dtheta = dx[:len(free)] * scales
        direct = (parts[0][1] - parts[1][1]) / (2.0 * h)
        dfig = gmat @ dtheta + direct
        row = {q: float(dtheta[i]) for i, q in enumerate(free)}
        row.update({q: float(dfig[k]) for k, q in enumerate(names)})
        out[key] = row
    return base, out


def _per_group_frame(fits: list[GroupFit], quantities) -> pd.DataFrame:
    rows = []
    for f in fits:
        row: dict[str, Any] = {"group": f.label, "runs": ";".join(str(r) for r in f.run_ids)}
        for q in quantities:
            row[q] = f.estimate[q]
            row[f"{q}_se"] = f.se[q]
        if f.v0_offset_mps:
            row["v0_offset_mps"] = ";".join(f"{x:.6g}" for x in f.v0_offset_mps)
        row["unidentified"] = ";".join(f.unidentified)
        row.update(rms_residual_mps=f.rms_residual_mps, n_samples=f.n_samples,
                   success=f.success, nfev=f.nfev, condition_number=f.condition_number,
                   fit_time_s=f.fit_time_s)
        rows.append(row)
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------- outputs

def _json_safe(x):
    if isinstance(x, dict):
        return {str(k): _json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_safe(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def lsq_record(result: LsqResult) -> dict[str, Any]:
    """The ``fit.json`` of a least-squares fit (JSON-safe: non-finite numbers as null): method,
    model, grouping, free and fixed parameters, weighted means (eq. 5.15) and standard errors
    (eq. 5.16), the between-group spread, reference conditions, convergence and timings.
    ``summary.csv`` (:meth:`LsqResult.summary`) has exactly the columns of :data:`SUMMARY_COLUMNS`:
    per free parameter and derived figure, the weighted mean, its standard error, normal 95 %
    bounds and median = mean; the MCMC diagnostics ``r_hat``, ``ess_bulk``, ``ess_tail`` are empty."""
    doc = {
        "method": "lsq",
        "model": result.model_name,
        "description": result.description,
        "grouping": result.grouping,
        "n_groups": len(result.groups),
        "free": list(result.free),
        "fixed": result.fixed,
        "weighted_mean": result.weighted_mean,
        "weighted_se": result.weighted_se,
        "between_group": {"mean": result.between_mean, "std": result.between_std,
                          "std_pct": result.between_std_pct},
        "initial_speed": result.settings.initial_speed,
        "reference": {"speed_mps": result.settings.reference_speed_mps,
                      "air_density_kgpm3": REFERENCE_AIR_DENSITY_KGPM3,
                      "temperature_k": config.REFERENCE_TEMPERATURE_K, "air": "still",
                      "F_units": "F = F0 + F1 v + F2 v^2, v in km/h"},
        "all_converged": all(f.success for f in result.groups),
        "compile_time_s": result.compile_time_s,
        "fit_time_s": result.fit_time_s,
        "truth": result.truth,
    }
    return _json_safe(doc)


def _fmt(x: float) -> str:
    if x is None or not math.isfinite(x):
        return "-"
    return f"{x:.4g}"


def format_lsq_table(result: LsqResult, truth: Mapping[str, float] | None = None) -> str:
    """A plain-text table of the fit for the command line.

    Columns: weighted mean +- SE (eq. 5.15, 5.16), between-group mean, std and std %, and,
    when a truth is given (default: the campaign's), the truth and the error in %.
    """
    truth = result.truth if truth is None else truth
    head = ["quantity", "weighted mean", "SE", "group mean", "group std", "std %"]
    if truth:
        head += ["truth", "error %"]
    rows = []
    for q in result.quantities:
        m = result.weighted_mean[q]
        row = [q, _fmt(m), _fmt(result.weighted_se[q]), _fmt(result.between_mean[q]),
               _fmt(result.between_std[q]), _fmt(result.between_std_pct[q])]
        if truth:
            t = truth.get(q)
            row += [_fmt(t) if t is not None else "-",
                    _fmt(100.0 * (m - t) / t) if t not in (None, 0) else "-"]
        rows.append(row)
    widths = [max(len(r[i]) for r in [head] + rows) for i in range(len(head))]
    line = lambda r: "  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(zip(r, widths)))  # noqa: E731
    title = (f"least squares, model {result.model_name}, grouping {result.grouping} "
             f"({len(result.groups)} group{'s' if len(result.groups) != 1 else ''}, "
             f"all converged: {all(f.success for f in result.groups)})")
    return "\n".join([title, line(head), line(["-" * w for w in widths])] + [line(r) for r in rows])
