"""MAP + Laplace fits that share one compilation across same-shaped campaigns.

:func:`~bayes_roadload.inference.nuts.find_map` compiles the potential of each fit (its
:class:`~bayes_roadload.inference.shift.PotentialProgram`, which that fit's Type B step
reuses).  A study that fits many simulated campaigns of the same size (test planning, the
withheld-effect suite) would spend most of its time compiling.  Here one
:class:`CompiledProblem` per structure of problem is kept in the process: the same potential
program, the data (the padded runs, the run effects' sensitivities and offsets, the vehicle
and the fixed values) as *arguments*, so every campaign with the same model, run count and
padded length reuses one compilation of the numpyro potential and its gradient
(:func:`numpyro.infer.util.potential_energy`), the map between constrained and unconstrained
values, the run-effect linearisation and the road load of the draws.

:func:`fit_laplace` is the cheap fit: the same problem, starting values, re-linearisation
and trust-region Newton as the NUTS path (:func:`~bayes_roadload.inference.nuts.
prepare_problem`, :func:`~bayes_roadload.inference.nuts.newton_map`), then independent
draws of the Laplace approximation (Gaussian in numpyro's unconstrained, O(1)-scaled
coordinates) mapped to the physical parameters -- or, by default, those draws corrected by
importance sampling: draws of a multivariate Student-t around the MAP with the Laplace
covariance (inflated when the weights are poor), weighted by posterior / proposal density, the weights Pareto-smoothed
(:func:`arviz.psislw`, PSIS) and the draws resampled by them.  The plain Gaussian is too
narrow where the posterior is skewed: on hierarchical fits of 2 pairs its 95 % half-widths
were 0.65-0.77 of NUTS' (0.85-0.94 with 6 pairs; ``docs/planning.md``), because the
run-to-run spreads' posterior has a long right tail.  The Pareto k of the weights is reported
(``pareto_k``; above 0.7 the correction is unreliable and the fit fails its gate).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from numpyro.infer.util import constrain_fn, potential_energy, unconstrain_fn

from .. import config
from ..data.campaign import Campaign
from ..physics.roadload import road_load_summary
from .bayes import (
    FitProblem,
    _effects_posterior,
    build_problem,
    coastdown_model,
    population_sample,
    run_effect_reference,
    run_sensitivities,
)
from .nuts import MapResult, initial_values, newton_map, unconstrained_posterior
from .results import draws_at_once
from .shift import PotentialProgram
from .spec import ModelSpec

DEFAULT_LAPLACE_DRAWS = config.LAPLACE_DRAWS
PROPOSAL_DF = config.LAPLACE_PROPOSAL_DF
PROPOSAL_FAMILIES = ("t", "normal")
PROPOSAL_COMBINATIONS = ("mixture", "sequential")

_CACHE: list["CompiledProblem"] = []
_CACHE_MAX = 16


def _with_placeholders(problem: FitProblem) -> FitProblem:
    """A hierarchical problem before its run effects are linearised, with zero sensitivities
    and offsets of their final shapes: the same structure as after (its compiled functions
    take them as data)."""
    if problem.varying and problem.run_jacobian is None:
        r, n, k = problem.n_runs, np.shape(problem.batch.time_s)[-1], len(problem.varying)
        return dataclasses.replace(problem, run_jacobian=np.zeros((r, n, k)), run_offsets=np.zeros((r, k)))
    return problem


@dataclass
class CompiledProblem:
    """The jitted functions of one structure of problem, with the data as arguments.

    Built on the problem's :class:`~bayes_roadload.inference.shift.PotentialProgram` (the
    potential and its gradient in the O(1)-scaled coordinates ``y``, and the constrained values,
    as the MAP of a NUTS fit and its Type B step use them), which decides what is data (every
    array and float of the problem: the runs, the run effects' sensitivities, the mass, the fixed
    values) and what is structure (the model variant, priors, sites, shapes): every problem of
    the same structure reuses the compilation.  Adds the functions of a Laplace fit: the
    potential of many draws, the start's scaled coordinates, the run-effect linearisation, the
    run effects' means and the road load of the draws.

    Attributes
    ----------
    program : the potential program (its ``template``, ``unravel``, ``scale``, ``run_index``).
    sites : the sample sites (a start may also hold deterministic ones, e.g. the tyre-lag
        model's coefficients beside its apparent ones).
    """

    program: PotentialProgram
    sites: tuple[str, ...] = ()
    _fns: dict = field(default_factory=dict)

    @property
    def template(self) -> FitProblem:
        return self.program.template

    @property
    def scale(self) -> np.ndarray:
        return self.program.scale

    @property
    def run_index(self) -> np.ndarray:
        return self.program.run_index

    @property
    def unravel(self):
        return self.program.unravel

    @classmethod
    def build(cls, problem: FitProblem, init: dict[str, Any]) -> "CompiledProblem":
        problem = _with_placeholders(problem)
        # the sites from an abstract trace (nuts.unconstrained_posterior): running the model
        # op by op took ~3 s per kind of campaign
        z0 = unconstrained_posterior(problem, init).z0
        self = cls(program=PotentialProgram(problem, z0), sites=tuple(z0))
        self._compile()
        return self

    def data(self, problem: FitProblem) -> list | None:
        """``problem``'s data as the compiled functions take them; None for another structure."""
        return self.program.data_of(_with_placeholders(problem))

    def _data(self, problem: FitProblem) -> list:
        data = self.data(problem)
        if data is None:
            raise ValueError("the problem's structure differs from the compiled one")
        return data

    def _compile(self) -> None:
        program, unravel, scale = self.program, self.program.unravel, jnp.asarray(self.program.scale)
        with_data, sites = program.with_data, self.sites

        def objective(y, leaves):
            return potential_energy(coastdown_model, (with_data(leaves),), {}, unravel(y * scale))

        def to_scaled(init, leaves):
            z = unconstrain_fn(coastdown_model, (with_data(leaves),), {}, {k: init[k] for k in sites})
            return ravel_pytree(z)[0] / scale

        def constrain(y, leaves):
            return constrain_fn(coastdown_model, (with_data(leaves),), {}, unravel(y * scale),
                                return_deterministic=True)

        def linearise(base, v0, leaves):
            problem = with_data(leaves)
            return run_sensitivities(problem, base, v0, problem.batch)

        def effect_means(sample, leaves):
            return _effects_posterior(with_data(leaves), sample)[0]

        def derived(values, leaves):
            p = with_data(leaves)
            return road_load_summary(p.model, dict(p.fixed, **values), p.mass_kg, p.frontal_area_m2,
                                     driveline_curve=p.driveline_curve)

        # the potential of many draws in batches (results.draws_at_once): all 2000 importance
        # draws of a 24-pair campaign at once held 8.6 GB, and the batch door then cleared JAX's
        # caches after every other refit (docs/planning.md section 7)
        batch = draws_at_once(program.template)

        def objective_many(ys, leaves):
            return jax.lax.map(lambda y: objective(y, leaves), ys, batch_size=batch)

        self._fns = {
            "to_scaled": jax.jit(to_scaled), "f_many": jax.jit(objective_many),
            "constrain_many": jax.jit(jax.vmap(constrain, in_axes=(0, None))),
            "linearise": jax.jit(linearise), "effect_means": jax.jit(effect_means),
            "derived": jax.jit(jax.vmap(derived, in_axes=(0, None))),
        }

    # ------------------------------------------------------------------ pieces
    def potential(self, problem: FitProblem, y: np.ndarray) -> tuple[Any, Any]:
        """The potential and its gradient at the scaled point ``y``."""
        return self.program.fg(self._data(problem), y)

    def potential_many(self, problem: FitProblem, ys: np.ndarray) -> np.ndarray:
        """The potential at each scaled point of ``ys`` [n, d], in batches."""
        return np.asarray(self._fns["f_many"](jnp.asarray(ys), self._data(problem)))

    def to_scaled(self, problem: FitProblem, init: dict[str, Any]) -> np.ndarray:
        """The scaled coordinates of the constrained values ``init`` (its sample sites)."""
        return self._scaled(init, self._data(problem))

    def _scaled(self, init: dict[str, Any], data: list) -> np.ndarray:
        return np.asarray(self._fns["to_scaled"]({k: jnp.asarray(v) for k, v in init.items()}, data))

    def constrained_many(self, problem: FitProblem, ys: np.ndarray) -> dict[str, Any]:
        """The constrained and deterministic values of each scaled point of ``ys``."""
        return self._fns["constrain_many"](jnp.asarray(ys), self._data(problem))

    def effect_means(self, problem: FitProblem, sample: dict[str, Any]) -> np.ndarray:
        """The run effects' means at one population sample (:func:`~bayes_roadload.inference.
        bayes.population_sample`)."""
        return np.asarray(self._fns["effect_means"]({k: jnp.asarray(v) for k, v in sample.items()},
                                                    self._data(problem)))

    def derived(self, problem: FitProblem, values: dict[str, Any]) -> dict[str, Any]:
        """The road load of draws of the free parameters (arrays [draw])."""
        return self._fns["derived"]({k: jnp.asarray(v) for k, v in values.items()}, self._data(problem))

    def linearise(self, problem: FitProblem, reference: dict[str, Any], offsets=None) -> FitProblem:
        """:func:`~bayes_roadload.inference.bayes.linearise_run_effects`, compiled once."""
        if not problem.varying:
            return problem
        base, offsets = run_effect_reference(problem, reference, offsets)
        jac = self._fns["linearise"](base, jnp.asarray(reference["v0_mps"], float), self._data(problem))
        return dataclasses.replace(problem, run_jacobian=np.asarray(jac), run_offsets=offsets)

    def find_map(self, problem: FitProblem, init: dict[str, Any], max_iter: int = 200) -> MapResult:
        """MAP and Laplace covariance of ``problem`` (same structure as the template) from the
        constrained starting values ``init``."""
        t0 = time.perf_counter()
        data = self._data(problem)
        y0 = self._scaled(init, data)
        res = newton_map(lambda y: self.program.fg(data, y), y0, self.run_index, self.scale, max_iter=max_iter)
        z = self.unravel(jnp.asarray(res["y"] * self.scale))
        constrained = self.program.constrained(data, np.asarray(res["y"]) * self.scale)
        return MapResult.of(res, z, constrained, time.perf_counter() - t0)


def compiled_problem(problem: FitProblem, init: dict[str, Any]) -> CompiledProblem:
    """The :class:`CompiledProblem` of ``problem``'s structure (the last ``_CACHE_MAX`` kept in
    this process)."""
    for hit in _CACHE:
        if hit.data(problem) is not None:
            return hit
    if len(_CACHE) >= _CACHE_MAX:
        _CACHE.pop(0)
    hit = CompiledProblem.build(problem, init)
    _CACHE.append(hit)
    return hit


@dataclass
class LaplaceFit:
    """A MAP + Laplace fit: the problem, the MAP, and draws of the Gaussian approximation.

    ``samples`` maps every sample site, and the road load of :data:`~bayes_roadload.inference.
    results.DERIVED`, to arrays [1, draw, ...] (one "chain", like :class:`~bayes_roadload.
    inference.nuts.NutsFit`)."""

    problem: FitProblem
    map: MapResult
    samples: dict[str, np.ndarray]
    timings: dict[str, float] = field(default_factory=dict)
    truth: dict | None = None
    diagnostics: dict[str, float] = field(default_factory=dict)


def _proposal_logpdf(e: np.ndarray, family: str, inflation: float) -> np.ndarray:
    """Log density of whitened offsets ``e`` [n, d] under the proposal of ``family`` whose
    covariance is the Laplace one times ``inflation**2`` ("t": multivariate t with
    ``PROPOSAL_DF`` degrees of freedom; "normal": Gaussian), normalised (the log determinant of
    the Laplace factor, shared by every proposal, left out)."""
    from scipy import stats

    d = e.shape[1]
    if family == "t":
        return stats.multivariate_t(loc=np.zeros(d), shape=inflation**2 * np.eye(d), df=PROPOSAL_DF).logpdf(e)
    if family == "normal":
        return stats.norm(scale=inflation).logpdf(e).sum(axis=1)
    raise ValueError(f"proposal family must be one of {PROPOSAL_FAMILIES}, got {family!r}")


def _proposal_offsets(n: int, d: int, family: str, inflation: float, rng: np.random.Generator) -> np.ndarray:
    """``n`` whitened offsets [n, d] of the proposal of ``family`` scaled by ``inflation``."""
    if family == "t":
        nu = PROPOSAL_DF
        return inflation * rng.standard_normal((n, d)) / np.sqrt(rng.chisquare(nu, n) / nu)[:, None]
    if family == "normal":
        return inflation * rng.standard_normal((n, d))
    raise ValueError(f"proposal family must be one of {PROPOSAL_FAMILIES}, got {family!r}")


def _proposal_draws(y_map: np.ndarray, chol: np.ndarray, n: int, family: str, inflation: float,
                    rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``n`` draws of a proposal centred on the MAP with the Laplace covariance times
    ``inflation**2`` (:func:`_proposal_offsets`) and the log proposal density of each (up to a
    constant shared by the draws)."""
    e = _proposal_offsets(n, y_map.size, family, inflation, rng)
    return y_map + e @ chol.T, _proposal_logpdf(e, family, inflation)


def _mixture_draws(y_map: np.ndarray, chol: np.ndarray, n: int, family: str, inflations: tuple[float, ...],
                   rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``n`` draws of the equal-weight mixture of the proposals scaled by ``inflations``, an
    equal share from each (the deterministic mixture of Veach and Guibas 1995, Owen and Zhou
    2000): each draw is weighted against the mixture's density, so the narrow components give
    the bulk its resolution and the wide ones bound the weights in the tails, in one pass of
    ``n`` posterior evaluations.  Returns the draws and their log mixture density (up to the
    shared constant of :func:`_proposal_logpdf`)."""
    from scipy.special import logsumexp

    shares = np.full(len(inflations), n // len(inflations))
    shares[: n - shares.sum()] += 1
    e = np.concatenate([_proposal_offsets(int(m), y_map.size, family, s, rng) for m, s in zip(shares, inflations)])
    log_components = np.stack([np.log(m / n) + _proposal_logpdf(e, family, s) for m, s in zip(shares, inflations)])
    return y_map + e @ chol.T, logsumexp(log_components, axis=0)


def _importance_draws(comp: CompiledProblem, problem: FitProblem, y_map: np.ndarray, chol: np.ndarray, draws: int,
                      rng: np.random.Generator, family: str = config.LAPLACE_PROPOSAL_FAMILY,
                      inflations: tuple[float, ...] = config.LAPLACE_PROPOSAL_INFLATION,
                      combine: str = config.LAPLACE_PROPOSAL_COMBINE,
                      ) -> tuple[np.ndarray, float, float, float, int]:
    """``draws`` draws of the posterior by PSIS from proposals of ``family`` around the MAP
    (module docstring).  ``combine`` "mixture": one set of ``draws`` draws of the mixture of
    the Laplace covariance scaled by each of ``inflations`` (:func:`_mixture_draws`);
    "sequential": the proposal scaled by the first factor of ``inflations``, the next while the
    Pareto k exceeds :data:`~bayes_roadload.config.LAPLACE_GOOD_PARETO_K`, the one with the
    smallest k kept (up to ``len(inflations) x draws`` evaluations).  Returns resampled draws,
    Pareto k, effective sample size, the inflation used (NaN for a mixture) and the number of
    posterior evaluations."""
    import arviz as az

    if combine not in PROPOSAL_COMBINATIONS:
        raise ValueError(f"combine must be one of {PROPOSAL_COMBINATIONS}, got {combine!r}")
    if combine == "mixture":
        proposals = [(lambda: _mixture_draws(y_map, chol, draws, family, tuple(inflations), rng), math.nan)]
    else:
        proposals = [((lambda s=s: _proposal_draws(y_map, chol, draws, family, s, rng)), s) for s in inflations]
    best, evaluations = None, 0
    for propose, inflation in proposals:
        ys, log_q = propose()
        log_p = -comp.potential_many(problem, ys)
        evaluations += draws
        log_w = np.where(np.isfinite(log_p), log_p - log_q, -np.inf)
        lw, k = az.psislw(log_w - np.max(log_w[np.isfinite(log_w)]))
        k = float(np.asarray(k))
        if best is None or k < best[1]:
            best = (ys, k, np.asarray(lw, float), inflation)
        if k <= config.LAPLACE_GOOD_PARETO_K:
            break
    ys, k, lw, inflation = best
    w = np.exp(lw - lw.max())
    w = w / w.sum()
    idx = rng.choice(draws, size=draws, p=w)
    return ys[idx], k, float(1.0 / np.sum(w**2)), inflation, evaluations


def fit_laplace(campaign: Campaign, spec: ModelSpec | str = "four_term", *, pooling: str = "pooled",
                noise: str = "integrated", robust: bool = False, draws: int = DEFAULT_LAPLACE_DRAWS,
                seed: int = 0, start: dict[str, float] | None = None, importance: bool = True,
                proposal: str = config.LAPLACE_PROPOSAL_FAMILY,
                inflations: tuple[float, ...] = config.LAPLACE_PROPOSAL_INFLATION,
                combine: str = config.LAPLACE_PROPOSAL_COMBINE) -> LaplaceFit:
    """MAP + Laplace fit of a campaign, compiled once per kind of campaign.

    The same starting values (:func:`~bayes_roadload.inference.nuts.initial_values`) and, for
    the hierarchical model, the same re-linearisation at the first MAP's run effects as
    :func:`~bayes_roadload.inference.nuts.fit_nuts`; then ``draws`` independent draws of the
    Gaussian approximation at the MAP -- with ``importance`` (default) corrected by
    Pareto-smoothed importance sampling (module docstring) from ``proposal`` ("t" or "normal")
    proposals scaled by ``inflations``, their mixture or in turn (``combine``,
    :func:`_importance_draws`).  ``start`` (sample site -> value: the free parameters, and the
    noise scales and spreads where known) replaces the least-squares start
    (:func:`~bayes_roadload.inference.nuts.initial_values`).

    Campaigns with the same model, number of runs and padded length share one compilation:
    give simulated campaigns a common ``meta["pad_to_samples"]``.
    """
    t0 = time.perf_counter()
    problem = build_problem(campaign, spec, pooling=pooling, noise=noise, robust=robust)
    init = initial_values(problem, campaign, start)
    comp = compiled_problem(problem, init)
    problem = comp.linearise(problem, init)
    if problem.varying:
        first = comp.find_map(problem, init)
        means = comp.effect_means(problem, population_sample(problem, first.constrained))
        problem = comp.linearise(problem, first.constrained, means)
        init = dict(init, **{k: v for k, v in first.constrained.items() if k in init})
    result = comp.find_map(problem, init)
    rng = np.random.default_rng(seed)
    y_map = np.asarray(ravel_pytree(result.z)[0]) / comp.scale
    cov_y = result.cov / np.outer(comp.scale, comp.scale)
    chol = np.linalg.cholesky(cov_y + 1e-12 * np.eye(y_map.size))
    diagnostics = {"pareto_k": float("nan"), "is_ess": float("nan"), "proposal_inflation": float("nan"),
                   "is_evaluations": 0}
    t_is = time.perf_counter()
    if importance:
        ys, k, ess, inflation, evaluations = _importance_draws(comp, problem, y_map, chol, draws, rng, proposal,
                                                               tuple(inflations), combine)
        diagnostics = {"pareto_k": k, "is_ess": ess, "proposal_inflation": inflation,
                       "is_evaluations": evaluations}
    else:
        ys = y_map + rng.standard_normal((draws, y_map.size)) @ chol.T
    constrained = comp.constrained_many(problem, ys)
    samples = {k: np.asarray(v)[None] for k, v in constrained.items()}
    derived = comp.derived(problem, {k: samples[k][0] for k in problem.free})
    samples.update({k: np.asarray(v)[None] for k, v in derived.items()})
    fit = LaplaceFit(problem=problem, map=result, samples=samples, truth=campaign.truth, diagnostics=diagnostics)
    fit.timings = {"map_s": result.time_s, "importance_s": time.perf_counter() - t_is if importance else 0.0,
                   "fit_s": time.perf_counter() - t0}
    return fit
