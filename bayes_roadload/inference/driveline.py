"""The driveline off-load loss from wheel-torque data on its own (thesis eq. 5.12).

With wheel torque meters the driveline loss is measured directly: every logged sample of
``driveline_force_n`` (or of the two wheel torques over the rolling radius) is the loss at the
logged speed.  :func:`fit_driveline_nuts` fits ``F_i ~ Normal(A_t + B_t v_i + C_t v_i^2,
sigma_driveline_n)`` over all runs with the priors of a model variant (``four_term_driveline``:
A_t ~ N(20, 20) N, B_t ~ N(2, 2) N s/m, C_t ~ N(0, 0.1) N s^2/m^2; ``sigma_driveline_n``
half-normal(10 N)), through the same MAP / Laplace / NUTS / gates as the coastdown fits.  On a
steady-state campaign that logs the gearbox input (``gearbox_input_force_n``) the same model fits
the **on-load** loss, gearbox input minus wheel force (section 5.5.2; thesis table 7.9: A_t 36.3 N,
B_t 0.0 against the off-load 17.0 N, 1.59 N s/m of table 7.8, low wind).  The
joint fit with the coastdown is the ``four_term_driveline`` model of
:mod:`~bayes_roadload.inference.bayes`; this one needs no speed-trace model and gives the
coefficients to compare with it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist

from .. import config
from .spec import ModelSpec, Prior, load_model_spec

DRIVELINE_PARAMETERS = ("At", "Bt", "Ct")


@dataclass(frozen=True, eq=False)
class DrivelineProblem:
    """A driveline-channel fit: the logged loss against the logged speed, all runs pooled."""

    spec: ModelSpec
    free: tuple[str, ...]
    priors: dict[str, Prior]
    speed_mps: Any
    force_n: Any
    initial: dict[str, Any] = field(default_factory=dict)
    run_ids: tuple = ()
    pooling: str = "pooled"
    noise: str = "driveline"
    robust: bool = False
    varying: tuple = ()

    @property
    def n_runs(self) -> int:
        return 0

    @property
    def numpyro_model(self):
        return driveline_model


def build_driveline_problem(campaign, spec: ModelSpec | str = "four_term_driveline") -> DrivelineProblem:
    """The logged driveline force of a speed-trace campaign (off-load, eq. 5.12), or the
    on-load loss of a steady-state campaign (gearbox input minus wheel force, section 5.5.2),
    with the priors of ``spec``."""
    steady = getattr(campaign, "kind", "traces") == "steady"
    if steady and not campaign.has_driveline_loss:
        raise ValueError("the steady-state campaign logs no gearbox_input_force_n: the on-load driveline loss "
                         "(gearbox input minus wheel force, section 5.5.2) is not measured")
    if not steady and not campaign.has_driveline:
        raise ValueError("the campaign logs no driveline_force_n (or wheel torques): nothing to fit")
    spec = load_model_spec(spec) if isinstance(spec, str) else spec
    missing = [p for p in DRIVELINE_PARAMETERS if p not in spec.priors]
    if missing:
        raise ValueError(f"model {spec.name!r} gives no prior for {', '.join(missing)}: use four_term_driveline")
    priors = {p: spec.priors[p] for p in DRIVELINE_PARAMETERS}
    v = campaign.runs["speed_mps"].to_numpy(float)
    f = campaign.driveline_loss_n() if steady else campaign.runs["driveline_force_n"].to_numpy(float)
    c2, c1, c0 = np.polyfit(v, f, 2)
    initial = {"At": float(c0), "Bt": float(c1), "Ct": float(c2),
               "sigma_driveline_n": max(float(np.std(f - np.polyval([c2, c1, c0], v))), 1e-3)}
    return DrivelineProblem(spec=spec, free=DRIVELINE_PARAMETERS, priors=priors, speed_mps=jnp.asarray(v),
                            force_n=jnp.asarray(f), initial=initial, run_ids=tuple(campaign.run_ids))


def driveline_model(problem: DrivelineProblem) -> None:
    """numpyro model of the logged driveline loss (module docstring)."""
    p = {n: numpyro.sample(n, problem.priors[n].to_numpyro()) for n in problem.free}
    sigma = numpyro.sample("sigma_driveline_n", dist.HalfNormal(config.NOISE_PRIORS["sigma_driveline_n"]))
    v = problem.speed_mps
    numpyro.sample("driveline_force_n", dist.Normal(p["At"] + p["Bt"] * v + p["Ct"] * v**2, sigma),
                   obs=problem.force_n)


def fit_driveline_nuts(campaign, spec: ModelSpec | str = "four_term_driveline", *,
                       sampler: config.SamplerConfig = config.DEFAULT_SAMPLER):
    """A_t, B_t, C_t from the driveline channel alone (module docstring); a
    :class:`~bayes_roadload.inference.nuts.NutsFit` (MAP, Laplace whitening, NUTS:
    :func:`~bayes_roadload.inference.nuts.sample_problem`)."""
    from .nuts import sample_problem

    problem = build_driveline_problem(campaign, spec)
    return sample_problem(problem, problem.initial, sampler, campaign.truth)


def driveline_derived(samples: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The driveline loss at 50 mph, ``F50_driveline_N`` = A_t + B_t v + C_t v^2 per draw."""
    v = config.SPEED_50MPH_MPS
    return {"F50_driveline_N": np.asarray(samples["At"]) + np.asarray(samples["Bt"]) * v
            + np.asarray(samples["Ct"]) * v**2}


def write_driveline_outputs(fit, out_dir, *, gates: config.Gates = config.DEFAULT_GATES):
    """``posterior.nc``, ``summary.csv`` (At, Bt, Ct, sigma_driveline_n, F50_driveline_N) and
    ``diagnostics.json`` (the gates of the coastdown fits) of :func:`fit_driveline_nuts`."""
    from .results import write_channel_outputs

    p = fit.problem
    return write_channel_outputs(
        fit, out_dir, list(p.free) + ["sigma_driveline_n"], kind="driveline", derived=driveline_derived(fit.samples),
        observed={"driveline_force_n": np.asarray(p.force_n)}, gates=gates,
        extra={"samples_fitted": int(np.size(p.force_n)), "runs": [str(r) for r in p.run_ids]})
