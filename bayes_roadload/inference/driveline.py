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
from .nuts import sample_problem
from .results import FitReport, channel_report
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
    on_load: bool = False

    kind = "driveline"

    @property
    def n_observations(self) -> int:
        """Logged driveline forces."""
        return int(np.size(self.speed_mps))

    @property
    def hessian_runs(self) -> int:
        return 0   # the samples of all runs are pooled: no per-run sites

    def alternative_coordinates(self, values: dict[str, Any]) -> None:
        """None: one set of coordinates (:class:`~.problem.Problem`)."""
        return None

    def beyond_support(self, z: dict[str, Any], cov: np.ndarray) -> float:
        """0: every sampled coordinate maps into its support (:class:`~.problem.Problem`)."""
        return 0.0

    def shift_constant(self, name: str, delta: float) -> None:
        """None: no fixed drag-model constants (:meth:`~.problem.Problem.shift_constant`)."""
        return None

    def settings(self) -> dict[str, Any]:
        return {"pooling": "pooled", "noise": "driveline", "robust": False}

    def postprocess(self, samples: dict[str, Any], seed: int) -> dict[str, Any]:
        return {}

    def derived(self, samples: dict[str, Any]) -> dict[str, Any]:
        return driveline_derived(samples)

    def truth_values(self, truth: dict | None) -> dict[str, float]:
        """The true A_t, B_t, C_t (a steady-state campaign's on-load ones: ``At_on_load`` ...)
        and ``F50_driveline_N`` at them."""
        truth = dict(truth or {})
        if self.on_load:
            truth = {k[:-len("_on_load")]: v for k, v in truth.items() if k.endswith("_on_load")}
        if all(isinstance(truth.get(k), (int, float)) for k in DRIVELINE_PARAMETERS):
            v = config.SPEED_50MPH_MPS
            truth["F50_driveline_N"] = truth["At"] + truth["Bt"] * v + truth["Ct"] * v**2
        return truth

    @property
    def numpyro_model(self):
        return driveline_model


@dataclass(frozen=True)
class DrivelineChannel:
    """A measured driveline loss: every logged sample's speed (m/s) and loss (N), and whether
    it is the on-load loss of a steady-state test (section 5.5.2) or the off-load loss of a
    coastdown (eq. 5.12)."""

    speed_mps: np.ndarray
    force_n: np.ndarray
    on_load: bool


def off_load_channel(campaign) -> DrivelineChannel:
    """The logged ``driveline_force_n`` of a speed-trace campaign (eq. 5.12)."""
    if not campaign.has_driveline:
        raise ValueError("the campaign logs no driveline_force_n (or wheel torques): nothing to fit")
    return DrivelineChannel(campaign.runs["speed_mps"].to_numpy(float),
                            campaign.runs["driveline_force_n"].to_numpy(float), on_load=False)


def on_load_channel(campaign) -> DrivelineChannel:
    """The on-load loss of a steady-state campaign: gearbox input minus wheel force (5.5.2)."""
    if not campaign.has_driveline_loss:
        raise ValueError("the steady-state campaign logs no gearbox_input_force_n: the on-load driveline loss "
                         "(gearbox input minus wheel force, section 5.5.2) is not measured")
    return DrivelineChannel(campaign.runs["speed_mps"].to_numpy(float), campaign.driveline_loss_n(), on_load=True)


def build_driveline_problem(campaign, spec: ModelSpec | str = "four_term_driveline") -> DrivelineProblem:
    """The logged driveline force of a speed-trace campaign (off-load, eq. 5.12), or the
    on-load loss of a steady-state campaign (gearbox input minus wheel force, section 5.5.2),
    with the priors of ``spec``; the channel of the campaign's kind is that of
    :data:`~bayes_roadload.inference.kinds.KINDS`."""
    from .kinds import kind_of   # kinds imports this module

    channel_of = kind_of(campaign).driveline_channel
    if channel_of is None:
        raise ValueError(f"a {kind_of(campaign).label} campaign has no driveline channel")
    channel = channel_of(campaign)
    spec = load_model_spec(spec) if isinstance(spec, str) else spec
    missing = [p for p in DRIVELINE_PARAMETERS if p not in spec.priors]
    if missing:
        raise ValueError(f"model {spec.name!r} gives no prior for {', '.join(missing)}: use four_term_driveline")
    priors = {p: spec.priors[p] for p in DRIVELINE_PARAMETERS}
    v, f = channel.speed_mps, channel.force_n
    c2, c1, c0 = np.polyfit(v, f, 2)
    initial = {"At": float(c0), "Bt": float(c1), "Ct": float(c2),
               "sigma_driveline_n": max(float(np.std(f - np.polyval([c2, c1, c0], v))), 1e-3)}
    return DrivelineProblem(spec=spec, free=DRIVELINE_PARAMETERS, priors=priors, speed_mps=jnp.asarray(v),
                            force_n=jnp.asarray(f), initial=initial, run_ids=tuple(campaign.run_ids),
                            on_load=channel.on_load)


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
    problem = build_driveline_problem(campaign, spec)
    return sample_problem(problem, problem.initial, sampler, campaign.truth)


def driveline_derived(samples: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The driveline loss at 50 mph, ``F50_driveline_N`` = A_t + B_t v + C_t v^2 per draw."""
    v = config.SPEED_50MPH_MPS
    return {"F50_driveline_N": np.asarray(samples["At"]) + np.asarray(samples["Bt"]) * v
            + np.asarray(samples["Ct"]) * v**2}


def driveline_report(fit, campaign=None, *, gates: config.Gates = config.DEFAULT_GATES) -> FitReport:
    """The report of :func:`fit_driveline_nuts`: summary (At, Bt, Ct, sigma_driveline_n,
    F50_driveline_N) and the gates of the coastdown fits; no per-run rows."""
    p = fit.problem
    return channel_report(
        fit, list(p.free) + ["sigma_driveline_n"], kind="driveline",
        observed={"driveline_force_n": np.asarray(p.force_n)}, gates=gates,
        extra={"samples_fitted": int(np.size(p.force_n)), "runs": [str(r) for r in p.run_ids]})
