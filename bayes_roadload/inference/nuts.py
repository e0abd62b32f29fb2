"""Fast, diagnosed NUTS: MAP -> Laplace preconditioning -> parallel chains -> gates.

1. **Start.** The classical joint least-squares fit (:func:`.lsq.fit_lsq`, all runs, initial
   speeds fitted) gives the coefficients, each run's initial speed and noise level.
2. **MAP.** The negative log posterior of the numpyro model, in numpyro's unconstrained
   space and divided by a diagonal scale so every unknown is O(1), is minimised by a
   trust-region Newton method (``scipy.optimize.minimize``, ``trust-exact``) with exact JAX
   gradients and a Hessian by central differences of them that exploits the run structure
   (:func:`fd_hessian`: its cost does not grow with the number of runs).  Non-finite values
   are guarded (:func:`newton_map`): rejected steps, a smaller difference step, a fallback to
   L-BFGS-B, eigenvalue clipping, all recorded in :class:`MapResult`; a failure names the
   stage, the run or parameter and a remedy (:class:`~bayes_roadload.errors.FitStageError`).
3. **Laplace.** With L L^T the inverse Hessian at the MAP, NUTS runs on whitened coordinates
   ``x = x_MAP + L u`` in which the posterior is close to a standard normal, and the chains
   start from independent draws of that approximation.  On this posterior (AD, BD, CD0
   correlated beyond 0.9) that turns 1023-step trees into trees of a few steps.
4. **NUTS** (numpyro), chains in parallel on the CPU cores, warm-up adapting the step size
   and a mass matrix in the whitened coordinates (dense on small problems, diagonal on large
   ones: :class:`bayes_roadload.config.SamplerConfig`).
5. **Gates** (:class:`bayes_roadload.config.Gates`): split R-hat, bulk and tail ESS,
   divergences, E-BFMI, tree-depth saturation.  A fit that fails them says so
   (:mod:`.results`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import math
import os
import threading
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from numpyro.infer import MCMC, NUTS, init_to_value
from numpyro.handlers import seed, substitute
from numpyro.infer.util import _get_model_transforms, get_potential_fn, initialize_model, transform_fn
from scipy.optimize import minimize
from tqdm import tqdm

from .. import config
from ..data.campaign import Campaign
from ..errors import FitStageError, stage
from .bayes import (
    APPARENT_SITES,
    FitProblem,
    build_problem,
    linearise_run_effects,
    run_effect_means,
    with_apparent,
)
from .problem import Problem
from .lsq import DEFAULT_LSQ, LsqSettings, fit_lsq
from .spec import SOFTPLUS_FRACTION_AT_BOUND, ModelSpec, without_free

log = logging.getLogger(__name__)


@dataclass
class MapResult:
    """The MAP and its Laplace approximation in numpyro's unconstrained space.

    Attributes
    ----------
    z : unconstrained values of the sample sites at the MAP.
    constrained : the same in the model's (physical) units.
    cov : [n, n] Laplace covariance of the flattened unconstrained vector (ravel order of
        ``z``), the inverse of the Hessian of the negative log posterior.
    success : the optimiser converged, or stopped with the gradient of the scaled objective
        below ``1e-3`` in every coordinate or with a Newton decrement below
        :data:`MAP_NEWTON_DECREMENT` (trust-exact stops with "a bad approximation" once the
        objective no longer changes in floating point).
    newton_decrement : ``g' H^-1 g`` at the MAP (inf when the Hessian is not positive definite;
        null in ``diagnostics.json``).
    n_iter, message : from the optimiser.
    grad_max : largest |gradient| of the scaled objective at the MAP.
    neg_log_posterior : at the MAP.
    time_s : wall time of the optimisation (including compilation).
    min_eigenvalue : smallest eigenvalue of the Hessian in scaled coordinates (before any
        clipping); <= 0 means the MAP is not a strict local optimum.
    map_method : the optimiser whose optimum is kept, ``"trust-exact"`` or ``"L-BFGS-B"``.
    map_fallback : why the fallback optimiser or Hessian estimate was used; "" when not.
    hessian_regularised : eigenvalues of the Hessian were clipped, or the Hessian was replaced
        by the L-BFGS-B estimate, to make the Laplace covariance positive definite.
    n_eigenvalues_clipped : how many eigenvalues were clipped (:func:`laplace_covariance`).
    hessian_step : difference step of the final Hessian (:func:`finite_hessian`; 0 when it
        was replaced).
    """

    z: dict[str, Any]
    constrained: dict[str, Any]
    cov: np.ndarray
    success: bool
    n_iter: int
    message: str
    grad_max: float
    neg_log_posterior: float
    time_s: float
    min_eigenvalue: float
    map_method: str = "trust-exact"
    map_fallback: str = ""
    hessian_regularised: bool = False
    n_eigenvalues_clipped: int = 0
    hessian_step: float = 1e-4
    newton_decrement: float = math.nan

    @classmethod
    def of(cls, res: dict[str, Any], z: dict[str, Any], constrained: dict[str, Any], time_s: float) -> "MapResult":
        """The MAP of a :func:`newton_map` result ``res`` at ``z`` (``constrained``)."""
        return cls(z=z, constrained=constrained, cov=res["cov"], success=res["success"], n_iter=res["n_iter"],
                   message=res["message"], grad_max=res["grad_max"], neg_log_posterior=res["fun"], time_s=time_s,
                   min_eigenvalue=res["min_eigenvalue"], map_method=res["map_method"],
                   map_fallback=res["map_fallback"], hessian_regularised=res["hessian_regularised"],
                   n_eigenvalues_clipped=res["n_eigenvalues_clipped"], hessian_step=res["hessian_step"],
                   newton_decrement=res["newton_decrement"])

    def diagnostics(self) -> dict[str, Any]:
        """The optimiser's and the Hessian's guards, for ``diagnostics.json``."""
        return {"map_method": self.map_method, "map_fallback": self.map_fallback,
                "newton_decrement": float(self.newton_decrement) if math.isfinite(self.newton_decrement) else None,
                "hessian_regularised": bool(self.hessian_regularised),
                "n_eigenvalues_clipped": int(self.n_eigenvalues_clipped), "hessian_step": float(self.hessian_step)}


@dataclass
class NutsFit:
    """A finished NUTS fit: draws, sampler statistics, timings and the MAP it started from.

    ``samples`` maps every sample and deterministic site to an array [chain, draw, ...];
    ``stats`` holds ``diverging``, ``num_steps``, ``energy``, ``accept_prob``, ``tree_depth``
    ([chain, draw]).
    """

    problem: Problem
    samples: dict[str, np.ndarray]
    stats: dict[str, np.ndarray]
    map: MapResult | None
    sampler: config.SamplerConfig
    timings: dict[str, float] = field(default_factory=dict)
    truth: dict | None = None
    retries: list[dict[str, Any]] = field(default_factory=list)
    chain_method: dict[str, str] = field(default_factory=dict)
    noise_scaled_rates: dict[str, float] | None = None
    """The rates of :func:`noise_scaled_coordinates` by coordinate name when the fit was sampled
    in those coordinates, else None."""
    coordinates: str = ""
    """What :func:`sample_problem` changed in the sampled coordinates before the first attempt
    (the problem's alternative coordinates when its MAP's Laplace approximation reached a wall,
    :meth:`~bayes_roadload.inference.problem.Problem.beyond_support`, or when the sampler asked
    for them: :func:`start_coordinates`), with why; "" when nothing."""


def _site_scales(problem: Problem, z: dict[str, Any]) -> dict[str, Any]:
    """O(1) scaling of each unconstrained site: real-valued coefficients by their typical
    magnitude (config.PARAMETER_SCALES), initial speeds by 0.05 m/s, positive sites by 1 (their
    unconstrained coordinate is already dimensionless: log of the value, or, for a normal prior
    truncated from below, about (value - bound) / (0.05 x prior scale):
    :func:`~bayes_roadload.inference.spec.soft_lower_truncated_normal`)."""
    scales = {}
    apparent = {site: n for n, site in APPARENT_SITES.items()}
    for site, value in z.items():
        s = 1.0
        name = apparent.get(site, site)  # an apparent coefficient is scaled as its own
        prior = problem.priors.get(name)  # the coefficients' priors (sites without one are nuisances)
        if name in problem.free and prior is not None and prior.dist == "normal" and prior.low is None and prior.high is None:
            s = config.PARAMETER_SCALES.get(name, 1.0)
        elif name == "v0_mps":
            s = 0.05
        scales[site] = jnp.full(jnp.shape(value), s, dtype=float)
    return scales


def _still_air_spec(spec: ModelSpec) -> ModelSpec:
    """The spec without its latent wind: the start of a latent-wind fit (over a pair the wind's
    force cancels to first order, so the still-air joint fit is close)."""
    return dataclasses.replace(without_free(spec, [p for p in ("head_wind_mps",) if p in spec.free]), air="still")


def _latent_wind_start(problem: FitProblem, campaign: Campaign, init: dict, first: np.ndarray) -> dict:
    """Start of a latent-wind fit: still-air least squares of each run alone (seed 001's
    approach), the coefficients' medians over the runs, each run's initial speed and noise from
    its own fit, no wind (the joint still-air fit of a head/tail-wind pair can stop in a poor
    local minimum: measured 3 m/s off in one run's initial speed)."""
    r = problem.n_runs
    v0, sigma = first.copy(), np.full(r, 0.05)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            lsq = fit_lsq(campaign, _still_air_spec(problem.spec), grouping="run")
        index = {rid: i for i, rid in enumerate(problem.run_ids)}
        for k in problem.free:
            vals = [g.estimate.get(k, math.nan) for g in lsq.groups]
            vals = [x for x in vals if math.isfinite(x)]
            if vals:
                init[k] = float(np.median(vals))
        for g in lsq.groups:
            i = index.get(g.run_ids[0]) if g.run_ids else None
            if i is not None and g.v0_offset_mps:
                v0[i] = first[i] + float(g.v0_offset_mps[0])
                sigma[i] = max(float(g.rms_residual_mps), 1e-3)
    except Exception:  # noqa: BLE001 - the prior centres are a valid fallback start
        pass
    init["head_wind_mps"] = jnp.asarray(problem.initial["head_wind_mps"])
    for k in problem.free:
        prior = problem.priors[k]
        if prior.low is not None:
            init[k] = max(float(init[k]), prior.low + 1e-6 * config.PARAMETER_SCALES.get(k, 1.0))
    init["v0_mps"] = jnp.asarray(v0)
    init["sigma_mps"] = jnp.asarray(sigma)
    if problem.integrated_noise:
        init["q_mps_per_sqrt_s"] = 0.002
    if problem.robust:
        init["student_df"] = 10.0
    return init


START_PRIOR_Z = 4.0
"""A least-squares estimate further than this many prior standard deviations from a normal
prior's location is not used as a start (:func:`most_implausible_estimate`)."""


def most_implausible_estimate(priors: dict, estimate: dict[str, float]) -> str | None:
    """The free parameter whose least-squares estimate lies furthest outside its normal prior,
    when more than :data:`START_PRIOR_Z` prior scales from the prior's location (or not
    finite); None when every estimate is inside.  Least squares has no prior: on few or short
    runs its estimates trade along ridges into values the prior all but excludes (the lag gain
    at -0.30 /(m/s) against 0.0057 +- 0.003 on an exact-SBC campaign of two pairs, so that the
    apparent C_D0 of that start was negative; C_D0 26 on a light car's speed traces), and such a
    start is worse than the prior's centre: the MAP from it stopped at a local optimum."""
    worst, worst_z = None, START_PRIOR_Z
    for k, prior in priors.items():
        if prior.dist != "normal" or not prior.scale or k not in estimate:
            continue
        z = abs(estimate[k] - prior.loc) / prior.scale if math.isfinite(estimate[k]) else math.inf
        if z > worst_z:
            worst, worst_z = k, z
    return worst


def start_lsq_settings(problem: FitProblem) -> LsqSettings:
    """The least-squares start's settings for ``problem``: every run's initial speed fitted with
    the coefficients (the default, :data:`~bayes_roadload.inference.lsq.DEFAULT_LSQ`) while
    the dense Jacobian of every padded sample against both stays within
    :data:`~bayes_roadload.config.LSQ_START_MAX_JACOBIAN_BYTES`, else the measured first
    speeds and the coefficients alone (a Jacobian of one column per coefficient)."""
    jacobian_bytes = 8.0 * np.size(problem.batch.speed_mps) * (len(problem.free) + problem.n_runs)
    if jacobian_bytes <= config.LSQ_START_MAX_JACOBIAN_BYTES:
        return DEFAULT_LSQ
    log.info("least-squares start: the measured first speeds (fitting all %d runs' speeds would need a "
             "%.1f GB Jacobian)", problem.n_runs, jacobian_bytes / 1e9)
    return dataclasses.replace(DEFAULT_LSQ, initial_speed="measured")


def least_squares_start(problem: FitProblem, campaign: Campaign):
    """The classical joint least-squares fit that starts a problem: ``(group, centres)``, the
    fit of every run together (:class:`~bayes_roadload.inference.lsq.LsqGroup`) and the free
    parameters held at their prior's centre because their estimate lay far outside the prior
    (:func:`most_implausible_estimate`: the worst first, the others refitted with it there,
    until none is left; ``fit_lsq(..., hold=centres)``, whose refits reuse the first fit's
    compiled programs); None when the fit fails (the prior centres are a valid start)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            settings = start_lsq_settings(problem)
            g = fit_lsq(campaign, problem.spec, grouping="all", settings=settings).groups[0]
            centres: dict[str, float] = {}
            free = {k: v for k, v in problem.priors.items() if k in problem.free}
            while (worst := most_implausible_estimate({k: v for k, v in free.items() if k not in centres},
                                                      g.estimate)) is not None:
                centres[worst] = free[worst].center  # the others refitted with it there
                g = fit_lsq(campaign, problem.spec, grouping="all", hold=centres, settings=settings).groups[0]
        return g, centres
    except Exception:  # noqa: BLE001 - the prior centres are a valid fallback start
        return None


BOUND_REACH_SD = 3.0
"""A least-squares estimate within this many of its standard errors of its prior's lower bound
(or without a finite standard error) marks a posterior that reaches the bound
(:func:`soften_bounds`)."""


def soften_bounds(problem: FitProblem, start_fit) -> FitProblem:
    """``problem`` with the softplus coordinate of every free parameter whose posterior reaches
    its prior's lower bound set to :data:`~bayes_roadload.inference.spec.SOFTPLUS_FRACTION_AT_BOUND`
    of the prior's scale (``Prior.softness``), judged from the least-squares start
    ``start_fit`` (:func:`least_squares_start`): an estimate within :data:`BOUND_REACH_SD`
    standard errors of the bound, one without a finite standard error (not identified), or one
    held at its prior's centre.  The others keep
    :data:`~bayes_roadload.inference.spec.SOFTPLUS_FRACTION`, whose coordinate keeps ridges
    straight away from the bound.  Only the coordinates change, not the posterior; without a
    least-squares start (None) the problem is returned as it is."""
    if start_fit is None:
        return problem
    g, centres = start_fit
    softened = {}
    for k in problem.free:
        prior = problem.priors.get(k)
        if prior is None or prior.dist != "normal" or prior.low is None or prior.high is not None:
            continue
        est, se = g.estimate.get(k, math.nan), g.se.get(k, math.nan)
        reaches = (k in centres or not (math.isfinite(est) and math.isfinite(se))
                   or est - prior.low < BOUND_REACH_SD * se)
        if reaches:
            softened[k] = dataclasses.replace(prior, softness=SOFTPLUS_FRACTION_AT_BOUND)
    if not softened:
        return problem
    log.info("softplus coordinate widened next to the bound for %s", ", ".join(sorted(softened)))
    return dataclasses.replace(problem, priors={**problem.priors, **softened})


_NOT_RUN = object()


def initial_values(problem: FitProblem, campaign: Campaign, start: dict[str, float] | None = None,
                   lsq=_NOT_RUN) -> dict[str, Any]:
    """Constrained starting values from the classical joint least-squares fit, or, with
    ``start`` (free parameter -> value, e.g. a known population mean), from those values, the
    first measured speeds and sigma 0.05 m/s without the least-squares fit; ``start`` may also
    give the integrated noise's intensity ``q_mps_per_sqrt_s`` and the spreads ``tau_*``
    (positive values; otherwise they start at 0.002 and at their prior's mode).  An estimate its
    prior all but excludes (:func:`most_implausible_estimate`) starts at the prior's centre and
    the others are refitted with it there, the worst first, until none is left
    (:func:`least_squares_start`; ``lsq``: its result, None for a failed fit, when already computed).
    Latent-wind problems start from per-run still-air fits (:func:`_latent_wind_start`)."""
    init: dict[str, Any] = dict(problem.initial)
    r = problem.n_runs
    first = np.asarray(problem.batch.speed_mps[:, 0])
    v0, sigma = first.copy(), np.full(r, 0.05)
    if start is not None:
        init.update({k: float(v) for k, v in start.items() if k in problem.free})
    elif problem.latent_wind:
        return with_apparent(problem, _latent_wind_start(problem, campaign, init, first))
    else:
        start_fit = least_squares_start(problem, campaign) if lsq is _NOT_RUN else lsq
        if start_fit is not None:
            g, centres = start_fit
            init.update(centres)
            for k in problem.free:
                val = g.estimate.get(k, math.nan)
                if math.isfinite(val) and math.isfinite(g.se.get(k, math.nan)):
                    init[k] = float(val)
            if g.v0_offset_mps:
                v0 = first + np.asarray(g.v0_offset_mps)
            if math.isfinite(g.rms_residual_mps):
                sigma = np.full(r, max(g.rms_residual_mps, 1e-3))
    for k in problem.free:
        prior = problem.priors[k]
        if prior.low is not None:
            init[k] = max(init[k], prior.low + 1e-6 * config.PARAMETER_SCALES.get(k, 1.0))
    init["v0_mps"] = jnp.asarray(v0)
    init["sigma_mps"] = jnp.asarray(sigma)
    if problem.integrated_noise:
        init["q_mps_per_sqrt_s"] = 0.002
    if problem.robust:
        init["student_df"] = 10.0
    for name in problem.varying:
        init[f"tau_{name}"] = 0.5 * config.TAU_PRIOR_SCALES[name]
    if start is not None:  # noise intensity and spreads known from elsewhere (a source fit's posterior)
        for k in (("q_mps_per_sqrt_s",) if problem.integrated_noise else ()) + tuple(f"tau_{n}" for n in problem.varying):
            v = start.get(k)
            if v is not None and math.isfinite(v) and v > 0.0:
                init[k] = float(v)
    return with_apparent(problem, init)


@dataclass
class Posterior:
    """The posterior of one problem as numpyro sees it: a potential (negative log density) on
    the flattened unconstrained vector.

    Attributes
    ----------
    problem : the fit problem (:class:`~bayes_roadload.inference.problem.Problem`).
    z0 : unconstrained starting values (dict of sites).
    potential_fn : dict of unconstrained sites -> potential energy.
    postprocess_fn : unconstrained sites -> constrained sites and deterministic sites.
    unravel : flat vector -> dict of sites (ravel order of ``z0``).
    scale : flat O(1) scaling of the unconstrained coordinates (:func:`_site_scales`).
    run_index : flat vector of the run each coordinate belongs to (-1 for shared ones): the
        sparsity the finite-difference Hessian exploits.
    """

    problem: Problem
    z0: dict[str, Any]
    potential_fn: Any
    postprocess_fn: Any
    unravel: Any
    scale: np.ndarray
    run_index: np.ndarray

    @property
    def flat0(self) -> np.ndarray:
        return np.asarray(ravel_pytree(self.z0)[0])


def site_layout(problem: Problem, z0: dict[str, Any]) -> tuple[Any, np.ndarray, np.ndarray]:
    """Of the unconstrained sites ``z0``: the flat vector's ``unravel``, its O(1) ``scale``
    (:func:`_site_scales`) and ``run_index`` (the run of each coordinate, -1 for shared ones;
    the problem's :attr:`~bayes_roadload.inference.problem.Problem.hessian_runs`)."""
    _, unravel = ravel_pytree(z0)
    scale = np.asarray(ravel_pytree(_site_scales(problem, z0))[0])
    r = problem.hessian_runs
    run_of = {k: (np.arange(r) if np.shape(v) == (r,) and r > 1 else np.full(np.size(v), -1))
              for k, v in z0.items()}
    run_index = np.asarray(ravel_pytree({k: jnp.asarray(v) for k, v in run_of.items()})[0]).astype(int)
    return unravel, scale, run_index


def _traced_potential(problem: Problem, init: dict[str, Any]):
    """numpyro's potential and postprocessing of ``problem`` and the unconstrained ``init``,
    from a trace of the model that is abstract (``jax.eval_shape``: traced, never executed), or
    None when that does not apply (a latent site without a value in ``init``, enumerated
    sites, a support that depends on traced values)."""
    substituted = substitute(seed(problem.numpyro_model, 0), substitute_fn=init_to_value(values=init))
    box: dict[str, Any] = {}

    def model_trace():
        box["info"] = _get_model_transforms(substituted, (problem,), {})
        return 0.0

    try:
        jax.eval_shape(model_trace)
        inv_transforms, replay_model, has_enum, tr = box["info"]
        latent = [k for k, site in tr.items() if site["type"] == "sample" and not site["is_observed"]]
        if has_enum or any(k not in init for k in latent):
            return None
        z0 = transform_fn(inv_transforms, {k: init[k] for k in latent}, invert=True)
        flat = np.asarray(ravel_pytree(z0)[0])  # a leaked tracer fails here
    except Exception as e:  # noqa: BLE001 - numpyro's own initialisation is the fallback
        log.debug("abstract trace of the model not usable (%s: %s): numpyro's initialisation instead",
                  type(e).__name__, e)
        return None
    if not np.all(np.isfinite(flat)):
        return None
    potential_fn, postprocess_fn = get_potential_fn(problem.numpyro_model, inv_transforms,
                                                    replay_model=replay_model, model_args=(problem,))
    return z0, potential_fn, postprocess_fn


def unconstrained_posterior(problem: Problem, init: dict[str, Any]) -> Posterior:
    """numpyro's potential of ``problem``, starting at the constrained values ``init``.

    The site transforms come from an abstract trace of the model (:func:`_traced_potential`):
    numpyro's ``initialize_model`` runs the model and its gradient op by op once, which at 36
    runs took ~15 s of dispatch and small compilations against ~0.6 s for the trace; the
    potential is the same function.  Falls back to ``initialize_model`` where the trace does not
    apply."""
    traced = _traced_potential(problem, init)
    if traced is not None:
        z0, potential_fn, postprocess_fn = traced
    else:
        info, potential_fn, postprocess_fn, _ = initialize_model(
            jax.random.PRNGKey(0), problem.numpyro_model, model_args=(problem,),
            init_strategy=init_to_value(values=init), validate_grad=False)
        z0 = info.z
    unravel, scale, run_index = site_layout(problem, z0)
    return Posterior(problem=problem, z0=z0, potential_fn=potential_fn, postprocess_fn=postprocess_fn,
                     unravel=unravel, scale=scale, run_index=run_index)


def fd_hessian(grad_fn, y: np.ndarray, run_index: np.ndarray, step: float = 1e-4) -> np.ndarray:
    """Hessian by central differences of an exact gradient, exploiting that coordinates of
    different runs do not interact (the log posterior is a sum over runs given the shared
    parameters).

    Every shared coordinate is perturbed on its own; the per-run coordinates are perturbed
    all runs at once, one group per position within a run (Curtis, Powell and Reid 1974), so
    the cost is 2 x (shared + per-run coordinates of one run) gradients, whatever the number
    of runs.  ``y`` should be O(1)-scaled so that one ``step`` suits every coordinate.
    """
    y = np.asarray(y, float)
    n = y.size
    shared = np.flatnonzero(run_index < 0)
    per_run = np.flatnonzero(run_index >= 0)
    position = np.full(n, -1)
    for r in np.unique(run_index[per_run]):
        idx = np.flatnonzero(run_index == r)
        position[idx] = np.arange(idx.size)
    groups = [np.array([j]) for j in shared] + [np.flatnonzero(position == k) for k in range(position.max() + 1)]
    h = np.zeros((n, n))
    col_of_run = np.full(run_index.max() + 1 if per_run.size else 0, -1)
    for cols in groups:
        e = np.zeros(n)
        e[cols] = step
        d = (np.asarray(grad_fn(y + e)) - np.asarray(grad_fn(y - e))) / (2.0 * step)
        if run_index[cols[0]] < 0:
            h[:, cols[0]] = d
        else:  # a column per run: row i of run r belongs to the column of run r
            col_of_run[:] = -1
            col_of_run[run_index[cols]] = cols
            j = col_of_run[run_index[per_run]]
            ok = j >= 0
            h[per_run[ok], j[ok]] = d[per_run[ok]]
    h[np.ix_(shared, per_run)] = h[np.ix_(per_run, shared)].T
    return 0.5 * (h + h.T)


class _NonFiniteHessian(ArithmeticError):
    """The finite-difference Hessian at an iterate holds inf or NaN at every step tried."""


def _coordinate_names(z: dict[str, Any]) -> list[str]:
    """Names of the flat unconstrained coordinates (ravel order of ``z``): ``site`` or
    ``site[i]``."""
    names: list[str] = []
    for name in sorted(z):  # ravel_pytree flattens a dict in sorted key order
        size = int(np.size(z[name]))
        names += [name] if np.ndim(z[name]) == 0 else [f"{name}[{i}]" for i in range(size)]
    return names


def finite_hessian(grad_fn, y: np.ndarray, run_index: np.ndarray,
                   steps: tuple[float, ...] = (1e-4, 1e-6)) -> tuple[np.ndarray, float]:
    """:func:`fd_hessian` at the first of ``steps`` that gives a finite matrix; returns the
    Hessian and the step used.  Raises :class:`_NonFiniteHessian` when none does (the
    gradient is not finite next to ``y``)."""
    for step in steps:
        with np.errstate(all="ignore"):
            h = fd_hessian(grad_fn, y, run_index, step=step)
        if np.all(np.isfinite(h)):
            return h, step
    raise _NonFiniteHessian(f"the Hessian by central differences is not finite at steps {steps}")


def laplace_covariance(hmat: np.ndarray, floor: float = 1e-8) -> tuple[np.ndarray, float, int]:
    """Inverse of a symmetric Hessian with its eigenvalues clipped from below at ``floor``
    times the largest (at least ``floor``): the Laplace covariance of a MAP that is not a
    strict optimum in every direction stays positive definite, with the flat directions
    given a wide (not infinite) spread.  Returns the covariance, the smallest eigenvalue
    before clipping and the number of eigenvalues clipped."""
    eigval, eigvec = np.linalg.eigh(0.5 * (hmat + hmat.T))
    low = floor * max(float(eigval.max()), 1.0)
    clipped = np.maximum(eigval, low)
    return (eigvec / clipped) @ eigvec.T, float(eigval.min()), int(np.sum(eigval < low))


def _name_of(names: list[str] | None, j: int) -> str:
    return names[j] if names is not None and j < len(names) else f"coordinate {j}"


MAP_NEWTON_DECREMENT = 1e-8
"""A MAP is converged when its Newton decrement ``g' H^-1 g`` (twice the decrease a Newton step
would still give, in nats) is below this: the optimum is then within 1e-4 posterior standard
deviations in every direction, whatever the coordinates' scales (Boyd and Vandenberghe, Convex
Optimization, 9.5.1: the decrement is affine invariant, the gradient's size is not).  On a
campaign of little noise the data fix a combination of A_D, B_D and C_D0 1e4 times more
tightly than the O(1) scaling assumes: trust-exact then stops on rounding ("a bad approximation")
with |g| up to 1e-2 along that combination while the decrement is 1e-13."""


def newton_map(fg, y0: np.ndarray, run_index: np.ndarray, scale: np.ndarray, *,
               max_iter: int = 200, names: list[str] | None = None, progress: bool = False) -> dict[str, Any]:
    """Trust-region Newton (``scipy.optimize.minimize``, ``trust-exact``) on O(1)-scaled
    coordinates ``y`` with the exact gradient and the Hessian by :func:`fd_hessian` of it,
    guarded against non-finite values.

    * The objective is +inf wherever it, or its gradient, is not finite, so the optimisers
      reject such a step and shrink it (the integrated speed of an extreme trial point can
      overflow while the start is fine).
    * A Hessian that is not finite at an iterate is retried at a smaller difference step
      (:func:`finite_hessian`); when that fails too, or trust-exact raises, the MAP falls back
      to L-BFGS-B on the same objective from the best point found so far.
    * The Laplace covariance is the inverse Hessian at the optimum with eigenvalues clipped
      (:func:`laplace_covariance`); if that Hessian is not finite either, the L-BFGS-B
      inverse-Hessian estimate is used.

    Parameters
    ----------
    fg : the objective and its gradient on the scaled vector, ``fg(y) -> (value, gradient)``
        (one compiled program: ``jax.jit(jax.value_and_grad(objective))``; compiling the
        value on its own as well took a third of the gradient's compilation).
    y0 : scaled start.
    run_index : run of each coordinate (-1 shared), for :func:`fd_hessian`.
    scale : the coordinates' scale (``x = y * scale``).
    max_iter : iteration limit of each optimiser.
    names : names of the coordinates (:func:`_coordinate_names`), for error messages.
    progress : show a progress bar of the objective's evaluations and its best value.

    Returns
    -------
    dict with ``y`` (the optimum, scaled), ``cov`` (the Laplace covariance of the unscaled
    vector ``y * scale``), ``success`` (converged, the largest |gradient| below ``1e-3``, or
    the Newton decrement ``g' H^-1 g`` below :data:`MAP_NEWTON_DECREMENT`), ``newton_decrement``,
    ``n_iter``, ``message``, ``grad_max``, ``fun``, ``min_eigenvalue`` (of the scaled
    Hessian, before clipping), ``map_method`` (the optimiser whose result is kept:
    ``"trust-exact"`` or ``"L-BFGS-B"``), ``map_fallback`` (why the fallback ran, "" when it
    did not), ``hessian_step`` (difference step of the final Hessian; 0 when the L-BFGS-B
    estimate replaced it), ``n_eigenvalues_clipped`` and ``hessian_regularised`` (any
    eigenvalue clipped, or the Hessian replaced).

    Raises
    ------
    FitStageError
        (stage ``"map"``) when the objective or its gradient is not finite at the start,
        naming the first non-finite coordinate, or no finite optimum is found.
    """
    y0 = np.asarray(y0, float)
    best = {"y": y0.copy(), "f": math.inf}
    bar = tqdm(desc="MAP", unit=" evaluations", disable=not progress, leave=False, dynamic_ncols=True)
    last: dict[bytes, tuple[float, np.ndarray]] = {}

    def evaluate(y) -> tuple[float, np.ndarray]:
        """Value and gradient at ``y``; (+inf, 0) where either is not finite.  The last point
        is cached (scipy asks for the value and the gradient at the same point in turn)."""
        y = np.asarray(y, float)
        key = y.tobytes()
        if key not in last:
            with np.errstate(all="ignore"):
                v, d = fg(y)
                v, d = float(v), np.asarray(d, float)
            ok = math.isfinite(v) and bool(np.all(np.isfinite(d)))
            last.clear()
            last[key] = (v, d) if ok else (math.inf, np.zeros_like(y))
            if ok and v < best["f"]:
                best.update(y=y.copy(), f=v)
                bar.set_postfix_str(f"-log p {v:.6g}", refresh=False)
            bar.update()
        return last[key]

    def fun(y):
        return evaluate(y)[0]

    def jac(y):
        return evaluate(y)[1]

    def g(y):
        return fg(y)[1]

    f0, g0 = fg(y0)
    f0, g0 = float(f0), np.asarray(g0, float)
    if not math.isfinite(f0):
        raise FitStageError("map", f"the log posterior is not finite at the least-squares start ({f0})",
                            remedy="check the campaign for runs whose speed does not decrease; "
                                   "--method lsq shows the start")
    bad = np.flatnonzero(~np.isfinite(g0))
    if bad.size:
        j = int(bad[0])
        run = int(run_index[j]) if run_index[j] >= 0 else None
        raise FitStageError("map", f"the gradient of the log posterior is not finite at the start "
                            f"({bad.size} coordinates)", parameter=_name_of(names, j), run=run,
                            remedy="check that run's channels; fix the parameter in the model file or "
                                   "give it a prior that excludes the boundary")

    def penalised(y):  # L-BFGS-B's line search needs finite values: a wall above the best
        v, d = evaluate(y)
        return (v, d) if math.isfinite(v) else (best["f"] + 1e6 * (1.0 + abs(best["f"])), d)

    last_hessian: dict[bytes, tuple[np.ndarray, float]] = {}

    def hess(y):  # the last one kept: trust-exact's Hessian at its final iterate is the Laplace one
        y = np.asarray(y, float)
        last_hessian.clear()
        last_hessian[y.tobytes()] = finite_hessian(g, y, run_index)
        return last_hessian[y.tobytes()][0]

    method, fallback, n_iter, message = "trust-exact", "", 0, ""
    res = None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            res = minimize(fun, y0, jac=jac, hess=hess, method="trust-exact",
                           options={"maxiter": max_iter, "gtol": 1e-6})
        y, n_iter, message = np.asarray(res.x, float), int(res.nit), str(res.message)
        if not math.isfinite(float(res.fun)):
            raise _NonFiniteHessian("trust-exact ended at a non-finite objective")
    except (_NonFiniteHessian, np.linalg.LinAlgError, ValueError) as e:
        fallback = f"trust-exact failed ({type(e).__name__}: {e}); L-BFGS-B from the best point"
    lbfgs_inv = None
    if fallback:
        method = "L-BFGS-B"
        for _ in range(20):  # a line search that ends on the wall stops early: restart from the best
            start_f = best["f"]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                res = minimize(penalised, best["y"], jac=True, method="L-BFGS-B",
                               options={"maxiter": 20 * max_iter, "gtol": 1e-8, "ftol": 1e-15, "maxcor": 30})
            n_iter += int(res.nit)
            if not best["f"] < start_f or float(np.max(np.abs(evaluate(best["y"])[1]))) < 1e-6:
                break
        y, message = np.asarray(best["y"], float), str(res.message)
        lbfgs_inv = res.hess_inv.todense() if hasattr(res, "hess_inv") else None
        if not math.isfinite(float(res.fun)):
            raise FitStageError("map", "no finite optimum of the log posterior was found (trust-region Newton "
                                "and L-BFGS-B both failed)")
    bar.close()
    fval, grad = fg(y)
    fval, grad = float(fval), np.asarray(grad, float)
    grad_max = float(np.max(np.abs(grad))) if np.all(np.isfinite(grad)) else math.inf
    decrement = math.inf   # unless the Hessian at the optimum is positive definite
    try:
        hmat, step = last_hessian.get(y.tobytes()) or finite_hessian(g, y, run_index, steps=(1e-4, 1e-6, 1e-3))
        cov_y, min_eig, n_clipped = laplace_covariance(hmat)
        replaced = False
        if min_eig > 0.0 and np.all(np.isfinite(grad)):   # unclipped: clipping would understate it
            decrement = float(grad @ np.linalg.solve(0.5 * (hmat + hmat.T), grad))
    except (_NonFiniteHessian, np.linalg.LinAlgError):
        if lbfgs_inv is None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                r2 = minimize(penalised, y, jac=True, method="L-BFGS-B", options={"maxiter": max_iter, "maxcor": 30})
            lbfgs_inv = r2.hess_inv.todense()
        cov_y, min_eig_inv, n_clipped = laplace_covariance(np.linalg.inv(0.5 * (lbfgs_inv + lbfgs_inv.T)))
        min_eig, step, replaced = min_eig_inv, 0.0, True
        fallback = (fallback + "; " if fallback else "") + "Hessian not finite at the optimum: L-BFGS-B estimate"
    converged = bool(res is not None and res.success and method == "trust-exact")
    return {"y": y, "cov": cov_y * np.outer(scale, scale),
            "success": converged or grad_max < 1e-3 or decrement < MAP_NEWTON_DECREMENT,
            "newton_decrement": decrement,
            "n_iter": n_iter, "message": message, "grad_max": grad_max, "fun": fval,
            "min_eigenvalue": min_eig, "map_method": method, "map_fallback": fallback, "hessian_step": step,
            "n_eigenvalues_clipped": n_clipped, "hessian_regularised": bool(n_clipped > 0 or replaced)}


def find_map(problem: FitProblem, init: dict[str, Any], *, max_iter: int = 200,
             posterior: Posterior | None = None, progress: bool = False) -> MapResult:
    """MAP by trust-region Newton on the O(1)-scaled unconstrained parameters, and the
    Laplace covariance from the Hessian there (:func:`newton_map`).

    Gradients are exact (JAX, forward ODE sensitivities); the Hessian is central differences of
    them with the run structure exploited (:func:`fd_hessian`), so its cost does not grow with
    the number of runs and no second-order derivative has to be compiled.  ``init`` (constrained
    starting values) is ignored when a ``posterior`` built from them is given.  The campaign's
    data are arguments of the compiled potential
    (:func:`~bayes_roadload.inference.shift.potential_program`), so that the fit's Type B step
    reuses it on its shifted campaigns; where they cannot be, constants.
    """
    t0 = time.perf_counter()
    with stage("map"):
        post = posterior or unconstrained_posterior(problem, init)
        scale = post.scale
        fg, constrain = _map_functions(problem, post)
        log.info("MAP: %d unknowns, trust-region Newton from the least-squares start ...", post.flat0.size)
        res = newton_map(fg, post.flat0 / scale, post.run_index,
                         scale, max_iter=max_iter, names=_coordinate_names(post.z0), progress=progress)
        z_map = post.unravel(jnp.asarray(res["y"] * scale))
        constrained = constrain(z_map)
    log.info("MAP: %s, %d iterations, max |gradient| %.2g, %.1f s%s", res["map_method"], res["n_iter"],
             res["grad_max"], time.perf_counter() - t0, f" ({res['map_fallback']})" if res["map_fallback"] else "")
    return MapResult.of(res, z_map, constrained, time.perf_counter() - t0)


def _map_functions(problem: FitProblem, post: Posterior):
    """(value and gradient of the potential in the scaled coordinates ``y``, the constrained and
    deterministic values of an unconstrained point ``z``) for :func:`find_map`: from the
    problem's :class:`~bayes_roadload.inference.shift.PotentialProgram` (the data as arguments),
    or, where the problem's data cannot be arguments, compiled with them as constants.  Both
    jitted: with deterministic sites numpyro's postprocessing runs the whole model (the
    tyre-lag model's coefficients), which op by op took ~9 s at 36 runs."""
    from .shift import potential_program

    try:
        program = potential_program(problem, post.z0)
        data = program.data_of(problem)
        if data is not None and np.array_equal(program.scale, post.scale):
            def fg(y):
                return program.fg(data, y)

            def constrain(z):
                return program.constrained(data, ravel_pytree(z)[0])

            fg(post.flat0 / post.scale)   # compiles; raises here if it cannot
            return fg, constrain
    except Exception as e:  # noqa: BLE001 - the data as constants instead
        log.debug("MAP: potential with the data as arguments not usable (%s: %s)", type(e).__name__, e)

    def objective(y):
        return post.potential_fn(post.unravel(y * post.scale))

    return jax.jit(jax.value_and_grad(objective)), jax.jit(post.postprocess_fn)


def _physical_memory_bytes() -> float | None:
    try:
        return float(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def chain_method(sampler: config.SamplerConfig, problem: Problem) -> tuple[str, str]:
    """numpyro's ``chain_method`` for ``sampler`` on ``problem``, and why.

    "parallel" (one XLA device per chain) when there are enough devices and the projected
    growth of resident memory, :data:`~bayes_roadload.config.PARALLEL_CHAIN_GROWTH_BYTES` x
    observations x chains x (warm-up + draws), stays within
    :data:`~bayes_roadload.config.PARALLEL_CHAIN_MEMORY_FRACTION` of the machine's memory;
    else "sequential" (flat memory, about 1.7x the sampling time on two cores)."""
    chains = sampler.num_chains
    if chains <= 1:
        return "sequential", "one chain"
    if jax.local_device_count() < chains:
        return "sequential", f"{jax.local_device_count()} XLA device(s) for {chains} chains"
    growth = config.PARALLEL_CHAIN_GROWTH_BYTES * problem.n_observations * chains \
        * (sampler.num_warmup + sampler.num_samples)
    memory = _physical_memory_bytes()
    if memory is not None and growth > config.PARALLEL_CHAIN_MEMORY_FRACTION * memory:
        return "sequential", (f"parallel chains would hold ~{growth / 1e9:.1f} GB more while sampling "
                              f"({problem.n_observations} observations), over "
                              f"{config.PARALLEL_CHAIN_MEMORY_FRACTION:g} of this machine's "
                              f"{memory / 1e9:.1f} GB")
    return "parallel", f"{chains} chains on {jax.local_device_count()} XLA devices"


def collect_warmup(mcmc: MCMC) -> None:
    """Make ``mcmc.run`` keep the warm-up draws as well as the samples, so that warm-up and
    sampling run as one compiled program (``mcmc.warmup`` then ``mcmc.run`` compiles the
    sampler twice) and the warm-up's share of the leapfrog steps can be measured.

    numpyro has no public option for this: this is the one use of its private
    ``MCMC._set_collection_params(lower, upper, collection_size, phase)`` (numpyro 0.22).
    ``tests/inference/test_nuts.py::test_collect_warmup_keeps_every_draw`` checks the signature
    and the effect against the installed numpyro and fails on an upgrade that changes either.
    """
    total = mcmc.num_warmup + mcmc.num_samples
    mcmc._set_collection_params(0, total, total)


def laplace_cholesky(cov: np.ndarray, jitter: float = 1e-12) -> np.ndarray:
    """Lower-triangular L with L L^T = ``cov``, computed scale-invariantly: L = D chol(R) with
    D the standard deviations and R = D^-1 cov D^-1 the correlations, ``jitter`` added to R's
    diagonal only when R is not numerically positive definite.

    The unconstrained coordinates' variances span many decades (B_D's about 1e-10, a softplus
    coordinate's about 1e2), so a jitter relative to the largest variance, added to every
    diagonal element, would inflate the smallest conditional variances and shrink the step size
    NUTS adapts in the whitened coordinates (``tests/inference/test_nuts.py``: on such a
    covariance 1e-14 x the largest variance left a whitened variance of 0.005 instead of 1)."""
    cov = 0.5 * (np.asarray(cov, float) + np.asarray(cov, float).T)
    sd = np.sqrt(np.diag(cov))
    corr = cov / np.outer(sd, sd)
    try:
        chol = np.linalg.cholesky(corr)
    except np.linalg.LinAlgError:
        chol = np.linalg.cholesky(corr + jitter * np.eye(len(sd)))
    return sd[:, None] * chol


NOISE_METRIC_SHIFT = 2.0
"""Whitened units below the MAP at which :func:`noise_scaled_coordinates` measures how the
other coordinates' curvature grows as the integrated noise's intensity falls."""


def noise_scaled_coordinates(flat_map, cov: np.ndarray, j: int, grad_y: Callable, scale: np.ndarray,
                             run_index: np.ndarray, shift: float = NOISE_METRIC_SHIFT, max_rate: float = 1.0):
    """Whitened coordinates u of the unconstrained vector x in which the other coordinates'
    scale follows coordinate ``j`` (the log of the integrated noise's intensity q).

    With ``j`` ordered first (permutation P) and L L^T = P cov P^T::

        x = x_MAP + P^T L [u_0, exp(a_1 u_0) u_1, ..., exp(a_{n-1} u_0) u_{n-1}],

    whose Jacobian determinant is det L exp(u_0 sum(a)): the potential in u is the potential in
    x less u_0 sum(a), so the posterior is the same whatever the rates a.  The rates make the
    coordinates' conditional scale follow the posterior's: the Hessian's diagonal in u is
    measured (central differences of the exact gradient, :func:`fd_hessian`) at the MAP and
    ``shift`` whitened units below it in u_0, and a_i = log(h_i(-shift) / h_i(0)) / (2 shift)
    (a conditional sd that falls as exp(a_i u_0)), clipped to [0, ``max_rate``].

    ``grad_y``: gradient of the potential in the O(1)-scaled coordinates y = x / ``scale``.
    Returns (u -> x, u -> log Jacobian less log det L, the rates a)."""
    flat_map = jnp.asarray(flat_map)
    n = flat_map.size
    perm = np.r_[j, np.delete(np.arange(n), j)]
    inverse = np.argsort(perm)
    cov_p = cov[np.ix_(perm, perm)]
    chol = laplace_cholesky(cov_p)
    basis = chol[inverse, :]  # x - x_MAP = basis @ (scaled u)

    def diagonal_at(u0: float) -> np.ndarray:
        x = np.asarray(flat_map) + basis[:, 0] * u0
        h_y = fd_hessian(grad_y, x / scale, run_index)
        h_x = h_y / np.outer(scale, scale)
        return np.einsum("ij,ik,kj->j", basis, h_x, basis)

    with np.errstate(all="ignore"):
        ratio = diagonal_at(-shift)[1:] / diagonal_at(0.0)[1:]
    rates = np.clip(np.where(np.isfinite(ratio) & (ratio > 0), np.log(ratio) / (2.0 * shift), 0.0), 0.0, max_rate)
    a = jnp.asarray(rates)
    total = float(rates.sum())
    basis_j = jnp.asarray(basis)

    def to_x(u):
        s = jnp.concatenate([jnp.ones(1), jnp.exp(a * u[0])])
        return flat_map + basis_j @ (s * u)

    def log_jacobian(u):
        return u[0] * total

    return to_x, log_jacobian, rates


def whitening(problem: Problem, post: Posterior, map_result: MapResult, sampler: config.SamplerConfig):
    """The map from NUTS' whitened coordinates u to the unconstrained vector x, and its log
    Jacobian (less a constant): x = x_MAP + L u with L L^T the Laplace covariance, or, with
    ``sampler.noise_scaled_metric`` on a problem with one integrated noise intensity
    ``q_mps_per_sqrt_s``, :func:`noise_scaled_coordinates`.  Returns (u -> x, u -> log Jacobian,
    the rates by coordinate name or None in the Laplace coordinates alone)."""
    flat_map, _ = ravel_pytree(map_result.z)
    names = _coordinate_names(map_result.z)
    q_at = [i for i, name in enumerate(names) if name.split("[")[0] == "q_mps_per_sqrt_s"]
    if sampler.noise_scaled_metric and len(q_at) == 1:
        j = q_at[0]
        fg, _ = _map_functions(problem, post)
        to_x, log_jacobian, rates = noise_scaled_coordinates(
            flat_map, map_result.cov, j, lambda y: fg(jnp.asarray(y))[1], np.asarray(post.scale), post.run_index)
        log.info("NUTS: coordinates scaled with log q, rates %s", np.array2string(rates, precision=2))
        others = [name for i, name in enumerate(names) if i != j]
        return to_x, log_jacobian, {name: float(r) for name, r in zip(others, rates)}
    chol = jnp.asarray(laplace_cholesky(map_result.cov))

    def to_x(u):
        return flat_map + chol @ u

    def log_jacobian(u):
        return 0.0

    return to_x, log_jacobian, None


def mass_matrix(sampler: config.SamplerConfig, n: int, hierarchical: bool = False) -> str:
    """The metric warm-up adapts in the Laplace-whitened coordinates of ``n`` dimensions:
    ``sampler.mass_matrix``, where "auto" is "dense" up to
    :data:`~bayes_roadload.config.DENSE_MASS_MAX_DIM` dimensions; above, "diag" for a
    ``hierarchical`` posterior (run-to-run spreads, whose Laplace fit at the joint mode is
    poorest) and "identity" (the Laplace whitening kept, only the step size adapted) for the
    others (:class:`~bayes_roadload.config.SamplerConfig`)."""
    if sampler.mass_matrix != "auto":
        return sampler.mass_matrix
    if n <= config.DENSE_MASS_MAX_DIM:
        return "dense"
    return "diag" if hierarchical else "identity"


def run_nuts(problem: Problem, *, sampler: config.SamplerConfig = config.DEFAULT_SAMPLER,
             map_result: MapResult | None = None, posterior: Posterior | None = None,
             more_draws: Callable[[NutsFit], int] | None = None) -> NutsFit:
    """Sample the posterior of ``problem`` with NUTS.

    With ``sampler.precondition == "laplace"`` NUTS runs on whitened coordinates
    ``x = x_MAP + L u`` (``L L^T`` the Laplace covariance of the unconstrained vector), where
    every direction is O(1) and nearly uncorrelated; warm-up then adapts the step size and the
    mass matrix in ``u`` (``sampler.mass_matrix``; it corrects the directions the Laplace
    approximation gets wrong on small campaigns, where the coefficients widen with the noise
    scales).  Chains start from independent draws of the
    Laplace approximation.

    ``more_draws(fit)``, when given, reads the finished fit and returns how many more draws per
    chain to take (0: none): the same chains then continue from their last state with the
    adapted step size and mass matrix, and the fit returned holds the first and the further
    draws (``sampler.num_samples`` their sum, ``timings["extension_s"]`` the further draws' time,
    included in ``sampling_s``).
    """
    key = jax.random.PRNGKey(sampler.seed)
    fields = ("diverging", "num_steps", "energy", "accept_prob")
    if sampler.precondition == "laplace":
        if map_result is None:
            raise ValueError("precondition='laplace' needs the MAP result")
        post = posterior or unconstrained_posterior(problem, map_result.constrained)
        potential_fn, postprocess_fn = post.potential_fn, post.postprocess_fn
        flat_map, unravel = ravel_pytree(map_result.z)
        n = flat_map.size
        to_x, log_jacobian, rates = whitening(problem, post, map_result, sampler)

        # jitted: numpyro evaluates the potential and its gradient once at the start of a chain
        # outside its compiled loop (one chain, or chains one after the other), which op by op
        # took ~5 s per chain on one pair
        @jax.jit
        def whitened_potential(u):
            return potential_fn(unravel(to_x(u))) - log_jacobian(u)

        mass = mass_matrix(sampler, n, hierarchical=problem.settings().get("pooling") == "hierarchical")
        kernel = NUTS(potential_fn=whitened_potential, dense_mass=mass == "dense",
                      adapt_mass_matrix=mass != "identity",
                      target_accept_prob=sampler.target_accept, max_tree_depth=sampler.max_tree_depth)
        init_params = jnp.asarray(np.random.default_rng(sampler.seed).standard_normal((sampler.num_chains, n)))
        if sampler.num_chains == 1:
            init_params = init_params[0]
    else:
        kernel = NUTS(problem.numpyro_model, target_accept_prob=sampler.target_accept, max_tree_depth=sampler.max_tree_depth)
        init_params = None
        rates = None
    args = () if sampler.precondition == "laplace" else (problem,)
    # Warm-up and sampling in one compiled program (``mcmc.warmup`` then ``mcmc.run`` compiles
    # the sampler twice); the warm-up draws are collected only to split the time between the
    # phases by their leapfrog steps, then dropped.
    method, why = chain_method(sampler, problem)
    if method == "sequential" and sampler.num_chains > 1:
        log.info("chains one after the other: %s", why)
    iteration_bars = sampler.progress_bar and sampler.iteration_bars
    mcmc = MCMC(kernel, num_warmup=sampler.num_warmup, num_samples=sampler.num_samples,
                num_chains=sampler.num_chains, chain_method=method, progress_bar=iteration_bars)
    collect_warmup(mcmc)
    log.info("NUTS: %d chain%s x (%d warm-up + %d draws), target acceptance %.2f ...", sampler.num_chains,
             "s" if sampler.num_chains > 1 else "", sampler.num_warmup, sampler.num_samples, sampler.target_accept)
    t0 = time.perf_counter()
    # warm-up and sampling are one compiled program: a failure in either is the "sampling" stage
    beat = 0.0 if iteration_bars else sampler.heartbeat_s
    bar = sampler.progress_bar and not iteration_bars
    with stage("sampling"), heartbeat("NUTS (warm-up and sampling)", beat, bar=bar):
        mcmc.run(key, *args, init_params=init_params, extra_fields=fields)
        raw = jax.block_until_ready(mcmc.get_samples(group_by_chain=True))
    elapsed = time.perf_counter() - t0
    keep = slice(sampler.num_warmup, None)
    raw = jax.tree_util.tree_map(lambda a: np.asarray(a[:, keep]), raw)
    extra_all = {k: np.asarray(v) for k, v in mcmc.get_extra_fields(group_by_chain=True).items()}
    steps = extra_all["num_steps"].astype(float)
    warm_share = steps[:, :sampler.num_warmup].sum() / max(steps.sum(), 1.0)
    extra = {k: v[:, keep] for k, v in extra_all.items()}
    timings = {"warmup_s": warm_share * elapsed, "sampling_s": (1.0 - warm_share) * elapsed}
    log.info("NUTS: %.1f s (warm-up %.1f s, sampling %.1f s)", elapsed, timings["warmup_s"], timings["sampling_s"])

    def finished(raw, extra, sampler) -> NutsFit:
        if sampler.precondition == "laplace":
            u = jnp.asarray(raw).reshape(sampler.num_chains, sampler.num_samples, -1)
            x = jax.vmap(jax.vmap(to_x))(u)
            constrained = jax.jit(jax.vmap(jax.vmap(lambda xi: postprocess_fn(unravel(xi)))))(x)
            samples = {k: np.asarray(v) for k, v in constrained.items()}
        else:
            samples = {k: np.asarray(v) for k, v in raw.items()}
        samples.update(problem.postprocess(samples, seed=sampler.seed))
        stats = dict(extra, tree_depth=np.ceil(np.log2(extra["num_steps"] + 1.0)).astype(int))
        for c in range(sampler.num_chains):  # one plain line per chain (progress bars only on a terminal)
            log.info("chain %d/%d: %d + %d draws, %.1f leapfrog steps per draw, %d divergences, max tree depth %d",
                     c + 1, sampler.num_chains, sampler.num_warmup, sampler.num_samples,
                     float(stats["num_steps"][c].mean()), int(np.sum(stats["diverging"][c])),
                     int(stats["tree_depth"][c].max()))
        return NutsFit(problem=problem, samples=samples, stats=stats, map=map_result, sampler=sampler,
                       timings=dict(timings), chain_method={"method": method, "reason": why},
                       noise_scaled_rates=rates)

    fit = finished(raw, extra, sampler)
    more = more_draws(fit) if more_draws is not None else 0
    if more > 0:
        # the same chains go on from their last state with the step size and mass matrix that
        # warm-up adapted (numpyro's ``post_warmup_state``): the first draws are kept
        log.info("NUTS: %d more draws per chain of the same chains ...", more)
        mcmc.post_warmup_state = mcmc.last_state
        mcmc.num_samples = more
        t0 = time.perf_counter()
        with stage("sampling"), heartbeat("NUTS (further draws)", beat, bar=bar,
                                          expected_s=timings["sampling_s"] * more / sampler.num_samples):
            mcmc.run(mcmc.post_warmup_state.rng_key, *args, extra_fields=fields)
            raw_more = jax.block_until_ready(mcmc.get_samples(group_by_chain=True))
        timings["extension_s"] = time.perf_counter() - t0
        timings["sampling_s"] += timings["extension_s"]
        log.info("NUTS: %.1f s for the further draws", timings["extension_s"])
        raw = jax.tree_util.tree_map(lambda a, b: np.concatenate([a, np.asarray(b)], axis=1), raw, raw_more)
        extra_more = mcmc.get_extra_fields(group_by_chain=True)
        extra = {k: np.concatenate([v, np.asarray(extra_more[k])], axis=1) for k, v in extra.items()}
        fit = finished(raw, extra, dataclasses.replace(sampler, num_samples=sampler.num_samples + more))
    return fit


@contextlib.contextmanager
def heartbeat(what: str, every_s: float, expected_s: float | None = None, bar: bool = False):
    """Show that a block (a compiled program that reports nothing until it ends) is running,
    from a daemon thread: with ``bar``, a progress bar of the time so far on standard error,
    redrawn every half second (of the time left when ``expected_s`` is given);
    otherwise ``what`` with the time so far logged at INFO every ``every_s`` seconds
    (``SamplerConfig.heartbeat_s``), with the time left at ``expected_s``.  Nothing when
    ``every_s`` is 0 and there is no bar, or INFO is not shown."""
    if not log.isEnabledFor(logging.INFO) or (every_s <= 0.0 and not bar):
        yield
        return
    done = threading.Event()
    t0 = time.perf_counter()

    def beat():
        while not done.wait(every_s):
            so_far = time.perf_counter() - t0
            left = "" if expected_s is None else f", about {max(expected_s - so_far, 0.0):.0f} s left at the first attempt's pace"
            log.info("%s: still running after %.0f s%s", what, so_far, left)

    def draw():
        total = None if expected_s is None else max(expected_s, 1.0)
        form = "{desc}: {elapsed}" if total is None else "{desc}: {percentage:3.0f}%|{bar}| {elapsed}, about {remaining} left"
        with tqdm(total=total, desc=what, bar_format=form, leave=False, dynamic_ncols=True) as line:
            while not done.wait(0.5):
                so_far = time.perf_counter() - t0
                line.n = so_far if total is None else min(so_far, total)
                line.refresh()

    thread = threading.Thread(target=draw if bar else beat, name="bayes-roadload-heartbeat", daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()


def prepare_problem(problem: FitProblem, campaign: Campaign) -> tuple[FitProblem, dict[str, Any]]:
    """Starting values (:func:`initial_values`) and the run effects' sensitivities about them
    (:func:`~bayes_roadload.inference.bayes.linearise_run_effects`, hierarchical problems):
    re-linearised once, at each run's conditional-mean effects at a first MAP.  Returns the
    problem ready to sample and the constrained starting values."""
    start_fit = None if problem.latent_wind else least_squares_start(problem, campaign)
    problem = soften_bounds(problem, start_fit)
    init = initial_values(problem, campaign, lsq=start_fit)
    problem = linearise_run_effects(problem, init)
    if problem.varying:  # re-linearise each run at its own coefficients (bayes module docstring)
        first = find_map(problem, {}, posterior=unconstrained_posterior(problem, init))
        problem = linearise_run_effects(problem, first.constrained, run_effect_means(problem, first.constrained))
        init = dict(init, **{k: v for k, v in first.constrained.items() if k in init})
    return problem, init


def fit_nuts(campaign: Campaign, spec: ModelSpec | str = "four_term", *, pooling: str = "pooled",
             noise: str = "integrated", robust: bool = False,
             sampler: config.SamplerConfig = config.DEFAULT_SAMPLER) -> NutsFit:
    """Fit every run of a campaign jointly with NUTS (see the module docstring)."""
    t0 = time.perf_counter()
    problem, init = prepare_problem(build_problem(campaign, spec, pooling=pooling, noise=noise, robust=robust), campaign)
    start_s = time.perf_counter() - t0
    fit = sample_problem(problem, init, sampler, campaign.truth)
    fit.timings["start_s"] = start_s
    return fit


def campaign_sampler(sampler: config.SamplerConfig, problem: Problem) -> config.SamplerConfig:
    """``sampler`` with ``target_accept`` raised to ``small_campaign_target_accept`` when the
    problem has at most ``small_campaign_runs`` runs (:class:`~bayes_roadload.config.SamplerConfig`)."""
    small = sampler.small_campaign_target_accept
    if small is None or len(problem.run_ids) > sampler.small_campaign_runs or sampler.target_accept >= small:
        return sampler
    return dataclasses.replace(sampler, target_accept=small)


def quiet_trace_sampler(sampler: config.SamplerConfig, map_result: MapResult | None) -> config.SamplerConfig:
    """``sampler`` with ``target_accept`` raised to ``quiet_trace_target_accept`` when the MAP
    puts the speed noise ``sigma_mps`` of the median run below the likelihood's floor
    (:data:`~bayes_roadload.config.SPEED_NOISE_FLOOR_MPS`): the trace was logged with less
    noise than the model's floor, and the noise scales' posteriors then meet walls that diverge
    at a step size adapted to the bulk (:class:`~bayes_roadload.config.SamplerConfig`)."""
    quiet = sampler.quiet_trace_target_accept
    if quiet is None or map_result is None or sampler.target_accept >= quiet:
        return sampler
    sigma = map_result.constrained.get("sigma_mps")
    if sigma is None or not float(np.median(np.asarray(sigma))) < config.SPEED_NOISE_FLOOR_MPS:
        return sampler
    log.info("speed noise below the likelihood's floor (median MAP sigma %.2g m/s): target acceptance %.2f",
             float(np.median(np.asarray(sigma))), quiet)
    return dataclasses.replace(sampler, target_accept=quiet)


def sample_problem(problem: Problem, init: dict[str, Any], sampler: config.SamplerConfig = config.DEFAULT_SAMPLER,
                   truth: dict | None = None) -> NutsFit:
    """MAP from the constrained starting values ``init`` (with the Laplace preconditioning),
    then NUTS (:func:`run_nuts`) on any :class:`~bayes_roadload.inference.problem.Problem`;
    the fit's ``truth`` is ``truth``.  A campaign of few runs is sampled at the sampler's
    small-campaign target acceptance (:func:`campaign_sampler`), a trace logged with less noise
    than the likelihood's floor at its quiet-trace acceptance (:func:`quiet_trace_sampler`).
    A first attempt that fails its gates is retried once: its chains continued when only more
    draws are missing (:data:`CONTINUED_GATES`), else sampled anew with :func:`remedy`'s
    sampler, after divergences in the problem's alternative coordinates where it has them
    (:func:`retry_coordinates`); ``fit.retries`` records which.  A problem whose MAP's Laplace
    approximation puts :data:`~bayes_roadload.config.MAX_BEYOND_SUPPORT_SHARE` or more beyond a
    coefficient's support in the sampled coordinates (:meth:`~.problem.Problem.beyond_support`),
    or every problem that has them when ``sampler.coordinates`` is "alternative", is sampled in
    its alternative coordinates from the start, with their own MAP (:func:`start_coordinates`;
    ``fit.coordinates`` says so)."""
    sampler = campaign_sampler(sampler, problem)
    map_result = post = None
    walled = ""
    if sampler.precondition == "laplace":
        post = unconstrained_posterior(problem, init)
        map_result = find_map(problem, {}, posterior=post, progress=sampler.progress_bar)
        other, why = start_coordinates(problem, map_result, sampler)
        if other is not None:
            first_map_s = map_result.time_s
            problem, post, map_result, walled = _in_coordinates(other, sampler)
            map_result.time_s += first_map_s
            walled = f"{walled} ({why})"
        sampler = quiet_trace_sampler(sampler, map_result)
    checked: dict[str, Any] = {}

    def more_draws(fit: NutsFit) -> int:
        """The first attempt's gates; as many draws again when only more draws are missing."""
        from .results import gate_check  # results imports this module

        checked["failed"], checked["extremes"] = gate_check(fit)
        checked["first_s"] = fit.timings["warmup_s"] + fit.timings["sampling_s"]
        if checked["failed"] and set(checked["failed"]) <= CONTINUED_GATES:
            ext = checked["extremes"]
            why = (f"; largest R-hat {ext['max_r_hat']:.4f} on {ext['max_r_hat_quantity']}, which chains that have "
                   "converged exceed 1.01 in several per cent of fits of many runs by chance (docs/calibration.md, "
                   "\"A fit's own false-alarm rate\")") if "r_hat" in checked["failed"] else ""
            log.warning("gates failed (%s%s): %d more draws per chain of the same chains",
                        ", ".join(checked["failed"]), why, sampler.num_samples)
            return sampler.num_samples
        return 0

    retry = sampler.retry and sampler.num_warmup >= config.DEFAULT_SAMPLER.num_warmup \
        and sampler.num_samples >= config.DEFAULT_SAMPLER.num_samples
    fit = run_nuts(problem, sampler=sampler, map_result=map_result, posterior=post,
                   more_draws=more_draws if retry else None)
    map_s = map_result.time_s if map_result is not None else None
    failed = checked.get("failed")
    if failed:
        first = {k: (v if not isinstance(v, float) else round(v, 5) if math.isfinite(v) else None)
                 for k, v in checked["extremes"].items()}  # JSON has no NaN
        continued = "extension_s" in fit.timings
        coordinates = ""
        if not continued:
            second = remedy(sampler, failed)
            other = retry_coordinates(problem, map_result, failed)
            if other is not None:
                problem, post, map_result, coordinates = _in_coordinates(other, sampler)
                map_s += map_result.time_s
            log.warning("gates failed (%s): retrying once with %d + %d draws per chain, target acceptance %.2f%s",
                        ", ".join(failed), second.num_warmup, second.num_samples, second.target_accept,
                        f", {coordinates}" if coordinates else "")
            fit = run_nuts(problem, sampler=second, map_result=map_result, posterior=post)
            fit.timings["first_attempt_s"] = checked["first_s"]
        kept = fit.sampler  # the settings of the draws kept
        fit.retries = [{"failed": failed, "first_attempt_s": round(checked["first_s"], 3), "first_attempt": first,
                        "continued": continued, "num_warmup": kept.num_warmup, "num_samples": kept.num_samples,
                        "target_accept": kept.target_accept, "seed": kept.seed, "coordinates": coordinates}]
    if map_s is not None:
        fit.timings["map_s"] = map_s
    fit.coordinates = walled
    fit.truth = truth
    return fit


def start_coordinates(problem: Problem, map_result: MapResult, sampler: config.SamplerConfig
                      ) -> tuple[tuple[Problem, dict[str, Any], str] | None, str]:
    """The coordinates a first attempt samples in, other than the problem's own: its
    alternative ones (:meth:`~.problem.Problem.alternative_coordinates`, started from the MAP
    ``map_result``) when ``sampler.coordinates`` is "alternative", or when the MAP's Laplace
    approximation puts :data:`~bayes_roadload.config.MAX_BEYOND_SUPPORT_SHARE` or more beyond a
    coefficient's support in the problem's own (:meth:`~.problem.Problem.beyond_support`: a wall
    in the sampled space, on which NUTS diverges); with why.  ``(None, "")``: its own."""
    if sampler.coordinates == "alternative":
        other = problem.alternative_coordinates(map_result.constrained)
        if other is None:
            return None, ""
        log.info("sampled in %s (sampler coordinates \"alternative\")", other[2])
        return other, "sampler coordinates \"alternative\""
    beyond = problem.beyond_support(map_result.z, map_result.cov)
    if beyond < config.MAX_BEYOND_SUPPORT_SHARE:
        return None, ""
    other = problem.alternative_coordinates(map_result.constrained)
    if other is None:
        return None, ""
    log.warning("MAP: %.1f %% of its Laplace approximation lies where a coefficient leaves its prior's "
                "support (a wall in the sampled coordinates, on which NUTS diverges): %s", 100 * beyond, other[2])
    return other, f"{100 * beyond:.1f} % of the Laplace approximation beyond a support"


def _in_coordinates(other: tuple[Problem, dict[str, Any], str], sampler: config.SamplerConfig
                    ) -> tuple[Problem, Any, MapResult, str]:
    """The problem of :meth:`~.problem.Problem.alternative_coordinates`'s answer ``other``
    (problem, constrained start, label), its unconstrained posterior, its MAP from that start
    and the label."""
    problem, start, label = other
    post = unconstrained_posterior(problem, start)
    return problem, post, find_map(problem, {}, posterior=post, progress=sampler.progress_bar), label


def retry_coordinates(problem: Problem, map_result: MapResult | None, failed: list[str]
                      ) -> tuple[Problem, dict[str, Any], str] | None:
    """The coordinates of the retry after divergences: the problem's alternative
    (:meth:`~bayes_roadload.inference.problem.Problem.alternative_coordinates`), started from
    the first attempt's MAP; None (the same coordinates) after other gates, without a MAP, or
    for a problem with one set of coordinates.  Divergences that the geometry of the sampled
    coordinates makes are not removed by a smaller step: the tyre-lag default on the eco-car's
    GNSS traces diverged in its apparent coefficients at target acceptance 0.95 and 0.99 (107
    and more of 2000 draws) and not once with A_D, B_D, C_D0 sampled directly
    (docs/calibration.md, real data)."""
    if "divergences" not in failed or map_result is None:
        return None
    return problem.alternative_coordinates(map_result.constrained)


CONTINUED_GATES = frozenset({"r_hat", "ess_bulk", "ess_tail"})
"""Gates that more draws of the same, adapted chains remedy: when the first attempt fails only
these, :func:`sample_problem` continues its chains for as many draws again (the first draws are
kept, warm-up is not repeated) instead of a new run (:func:`remedy`).  Measured on the 18-pair
reference (docs/performance.md): its first attempt's R-hat miss was the folded R-hat of one
quantity of ~80 at 1.0101, with bulk split R-hat 0.999-1.000 everywhere."""


def remedy(sampler: config.SamplerConfig, failed: list[str]) -> config.SamplerConfig | None:
    """The sampler of a new run after the gates ``failed`` (None: nothing to retry), used when a
    gate other than those more draws remedy failed (:data:`CONTINUED_GATES`).

    Divergences: the step size was too large for the curvature met (with few runs, where the
    integrated-noise intensity q is small and the coefficients' posterior narrows with it), so
    the target acceptance rises to 0.99 (measured on thesis case 14, one pair: 10 divergences
    of 2000 draws at 0.8, 3 at 0.95, none at 0.99, for 2.2x the leapfrog steps of 0.8).  Warm-up
    and draws double in every retry: R-hat, ESS, E-BFMI and tree depth fail when the chains had
    too few draws or too short an adaptation, and the smaller steps after divergences make the
    draws more correlated (measured on thesis cases 9, 14, 15 at one pair: the retry at 0.99 with
    the same draws was free of divergences but missed R-hat 1.01 by 0.002-0.004).  A new seed
    makes the retry's chains independent of the first run's.
    """
    if not failed:
        return None
    changes: dict[str, Any] = {"seed": sampler.seed + 1, "retry": False, "num_warmup": 2 * sampler.num_warmup,
                               "num_samples": 2 * sampler.num_samples}
    if "divergences" in failed:
        changes["target_accept"] = max(sampler.target_accept, 0.99)
    return dataclasses.replace(sampler, **changes)
