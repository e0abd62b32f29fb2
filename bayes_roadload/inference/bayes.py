"""numpyro models of a coastdown campaign: all runs fitted jointly.

The drag model, which parameters are free, fixed or given priors, come from a model variant
(``models/*.toml``, :mod:`.spec`).  Two poolings:

``pooled``
    One set of coefficients (AD, BD, CD0, KD, and At, Bt, Ct when the driveline is modelled)
    for every run.
``hierarchical``
    Run-level AD, BD, CD0 (those of them that are free) around population means, with
    population spreads ``tau_AD, tau_BD, tau_CD0`` in each parameter's own units: the thesis'
    "system noise" and its test-to-test spread (table 8.3).  Non-centred:
    ``AD_run = AD + tau_AD * AD_z``, ``AD_z ~ N(0, 1)``.

Every run has its own initial speed ``v0_mps`` and speed noise ``sigma_mps``.  The residual
between measured and integrated speed is white measurement noise plus an integrated
(random-walk) error ``q_mps_per_sqrt_s`` shared by the runs: the sensor noise on the measured
inputs (airspeed, yaw, driveline force) and unmodelled forces are integrated by the equation of
motion, so a likelihood with independent residuals gives intervals that are too narrow
(:mod:`bayes_roadload.physics.residuals`).  ``noise="white"`` drops the integrated part;
``robust=True`` scores the innovations with a Student-t (``student_df``).

Priors of the coefficients are those of the model file (physical units); a free parameter
without one gets a wide normal around its default (``10 x`` its typical scale).  Nuisance
priors (:data:`bayes_roadload.config.NOISE_PRIORS`, ``TAU_PRIOR_SCALES``): ``sigma_mps`` half-
normal(0.1 m/s); ``v0_mps`` normal(first sample, 0.5 m/s); ``q_mps_per_sqrt_s`` Gamma(2) with
mean 0.005 m/s/sqrt(s) (vanishes at 0: inputs are never noise-free, and a boundary-avoiding
prior removes the funnel at q -> 0, Chung et al. 2013); ``tau_*`` Gamma(2) with means 10 %,
25 %, 5 % of typical AD, BD, CD0 (likewise boundary-avoiding); ``student_df`` Gamma(2, 0.1).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist

from .. import config
from ..data.campaign import Campaign
from ..physics.integrate import RunBatch, integrate_batch, integrate_batch_forward_sensitivity
from ..physics.model import DragModel
from ..physics.residuals import local_level_loglik, local_level_loglik_batch
from .spec import ModelSpec, Prior, load_model_spec

POOLINGS = ("pooled", "hierarchical")
NOISE_MODELS = ("integrated", "white")
HIERARCHICAL_PARAMETERS = ("AD", "BD", "CD0")
"""Coefficients that vary from run to run in the hierarchical model (when free)."""


@dataclass(frozen=True, eq=False)
class FitProblem:
    """Everything a Bayesian fit of one campaign needs, resolved once.

    Attributes
    ----------
    spec : the model variant.
    model : the drag model built for this campaign.
    fixed : values of every parameter that is not free (SI).
    free : names of the free parameters.
    priors : free parameter -> prior (physical units).
    batch : the campaign's runs, padded.
    run_ids : run ids in batch order.
    pooling, noise, robust : see the module docstring.
    mass_kg, frontal_area_m2 : the vehicle (for the derived road load).
    driveline_curve : (c2, c1, c0) of a measured driveline loss against speed (zeros if none).
    initial : starting values of the free parameters (SI).
    gradients : "forward" differentiates the ODE by forward sensitivities (fast reverse-mode
        gradients for NUTS, :func:`~bayes_roadload.physics.integrate_batch_forward_sensitivity`);
        "reverse" by reverse mode through the scan (needed for Hessians, used by the MAP).
    """

    spec: ModelSpec
    model: DragModel
    fixed: dict[str, float]
    free: tuple[str, ...]
    priors: dict[str, Prior]
    batch: RunBatch
    run_ids: tuple
    pooling: str = "pooled"
    noise: str = "integrated"
    robust: bool = False
    mass_kg: float = config.THESIS_VEHICLE["mass_kg"]
    frontal_area_m2: float = config.THESIS_VEHICLE["frontal_area_m2"]
    driveline_curve: tuple[float, float, float] = (0.0, 0.0, 0.0)
    initial: dict[str, Any] = field(default_factory=dict)
    gradients: str = "forward"

    @property
    def n_runs(self) -> int:
        return len(self.run_ids)

    @property
    def varying(self) -> tuple[str, ...]:
        """Free parameters that vary by run (hierarchical pooling)."""
        if self.pooling != "hierarchical":
            return ()
        return tuple(p for p in HIERARCHICAL_PARAMETERS if p in self.free)


def default_prior(name: str, model: DragModel) -> Prior:
    """A wide normal around the model default, for a free parameter without a prior."""
    scale = 10.0 * config.PARAMETER_SCALES.get(name, 1.0)
    return Prior(dist="normal", loc=float(model.defaults.get(name, 0.0)), scale=scale)


def measured_driveline_curve(campaign: Campaign) -> tuple[float, float, float]:
    """Least-squares quadratic (c2, c1, c0) of the logged driveline force against speed."""
    if not campaign.has_driveline:
        return (0.0, 0.0, 0.0)
    v = campaign.runs["speed_mps"].to_numpy(float)
    f = campaign.runs["driveline_force_n"].to_numpy(float)
    c2, c1, c0 = np.polyfit(v, f, 2)
    return (float(c2), float(c1), float(c0))


def build_problem(campaign: Campaign, spec: ModelSpec | str = "four_term", *, pooling: str = "pooled",
                  noise: str = "integrated", robust: bool = False) -> FitProblem:
    """Resolve a model variant against a campaign."""
    if pooling not in POOLINGS:
        raise ValueError(f"pooling must be one of {POOLINGS}, not {pooling!r}")
    if noise not in NOISE_MODELS:
        raise ValueError(f"noise must be one of {NOISE_MODELS}, not {noise!r}")
    spec = load_model_spec(spec) if isinstance(spec, str) else spec
    model, fixed, free = spec.build(campaign)
    priors = {p: spec.priors.get(p) or default_prior(p, model) for p in free}
    batch, run_ids = campaign.to_batch()
    initial = {p: float(spec.initial.get(p, priors[p].center)) for p in free}
    return FitProblem(spec=spec, model=model, fixed={k: float(v) for k, v in fixed.items()}, free=tuple(free),
                      priors=priors, batch=batch, run_ids=tuple(run_ids), pooling=pooling, noise=noise,
                      robust=robust, mass_kg=campaign.vehicle.mass_kg,
                      frontal_area_m2=campaign.vehicle.frontal_area_m2,
                      driveline_curve=measured_driveline_curve(campaign), initial=initial)


def free_parameters(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> dict[str, jnp.ndarray]:
    """The free drag-model parameters of one draw: shape [] (shared) or [R] (per run)."""
    return {n: (sample[f"{n}_run"] if n in problem.varying else sample[n]) for n in problem.free}


def run_parameters(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> dict[str, jnp.ndarray]:
    """Every drag-model parameter of one draw (fixed ones included)."""
    params = {k: jnp.asarray(v) for k, v in problem.fixed.items()}
    params.update(free_parameters(problem, sample))
    return params


def integrated_speed(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> jnp.ndarray:
    """[R, N] speed integrated from each run's initial speed for one draw."""
    if problem.gradients == "forward":
        return integrate_batch_forward_sensitivity(problem.model, problem.fixed, free_parameters(problem, sample),
                                                   problem.batch, sample["v0_mps"])
    return integrate_batch(problem.model, run_parameters(problem, sample), problem.batch, sample["v0_mps"])[0]


def speed_residuals(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> jnp.ndarray:
    """[R, N] measured minus integrated speed for one draw."""
    return problem.batch.speed_mps - integrated_speed(problem, sample)


def run_log_likelihood(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> jnp.ndarray:
    """[R] log-likelihood of each run's speed trace for one draw."""
    resid = speed_residuals(problem, sample)
    q = sample.get("q_mps_per_sqrt_s", jnp.zeros(()))
    sigma = sample["sigma_mps"]
    b = problem.batch
    if problem.robust:
        df = sample["student_df"]
        return jax.vmap(lambda r, t, m, s: local_level_loglik(r, t, m, s, q, df))(resid, b.time_s, b.mask, sigma)
    return local_level_loglik_batch(resid, b.time_s, b.mask, sigma, q)


def coastdown_model(problem: FitProblem) -> None:
    """The numpyro model (see the module docstring).  Sample sites use the contract names."""
    r = problem.n_runs
    sample: dict[str, jnp.ndarray] = {}
    for name in problem.free:
        sample[name] = numpyro.sample(name, problem.priors[name].to_numpyro())
    for name in problem.varying:
        # Gamma(2): no mass piling at tau = 0, so the joint mode (the MAP the sampler is
        # whitened at) is not degenerate (Chung et al. 2013)
        tau = numpyro.sample(f"tau_{name}", dist.Gamma(2.0, 2.0 / config.TAU_PRIOR_SCALES[name]))
        with numpyro.plate("run", r):
            z = numpyro.sample(f"{name}_z", dist.Normal(0.0, 1.0))
        sample[f"{name}_run"] = numpyro.deterministic(f"{name}_run", sample[name] + tau * z)
    first = problem.batch.speed_mps[:, 0]
    with numpyro.plate("run", r):
        sample["v0_mps"] = numpyro.sample("v0_mps", dist.Normal(first, config.NOISE_PRIORS["v0_scale_mps"]))
        sample["sigma_mps"] = numpyro.sample("sigma_mps", dist.HalfNormal(config.NOISE_PRIORS["sigma_mps"]))
    if problem.noise == "integrated":
        # Gamma(2) vanishes at 0: measured inputs are never noise-free, and the boundary-avoiding
        # prior removes the funnel at q -> 0 where the coefficients' posterior narrows
        sample["q_mps_per_sqrt_s"] = numpyro.sample(
            "q_mps_per_sqrt_s", dist.Gamma(2.0, 2.0 / config.NOISE_PRIORS["q_mps_per_sqrt_s"]))
    if problem.robust:
        sample["student_df"] = numpyro.sample("student_df", dist.Gamma(2.0, config.NOISE_PRIORS["student_df_rate"]))
    numpyro.factor("speed_loglik", run_log_likelihood(problem, sample).sum())
