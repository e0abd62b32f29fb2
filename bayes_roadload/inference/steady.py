"""Bayesian fit of steady-state torque tests (thesis sections 5.4, 7.4, eq. 5.5-5.9).

Eq. 5.5 with the corrective terms on the left: the tractive force measured at the driven
wheels, less the inertial term of the speed the driver could not hold, is the road load without
the driveline loss,

    F_T,i - M_e (dv/dt)_i = F_D(v_i, v_r,i, psi_i; AD, BD, CD0, KD, ...),

the same drag function as the coastdown (:class:`~bayes_roadload.physics.model.DragModel` built
from a model variant, ``models/*.toml``; the driveline is left out because the torque is measured
beyond it, section 5.4.1, so the coefficients compare directly with a coastdown whose driveline
loss was measured or modelled).  The thesis fitted eq. 5.6, a least-squares quadratic
A_0 + B_0 v + C_0 v^2 of the corrected force, and read AD = A_0 / (M g), BD = B_0 / (M g),
CD0 = C_0 / (rho A / 2) (eq. 5.7-5.9, reconstructed); :func:`classical_steady` keeps that
analysis on opposite-direction averages (table 7.7).

Likelihood: the samples of run r are Gaussian around the model force with covariance
``sigma_force_n^2 I + run_force_sd_n^2 1 1^T``: sample scatter (torque meter, gusts) and a
constant offset per run (the run's mean gust, tyre temperature, the driver), integrated out in
closed form (:func:`run_offset_log_likelihood`).  The relative air is

* measured (on-board anemometers, calibrated by the ``[anemometer]`` factors), or
* without anemometers a latent steady **along-track wind per opposite-direction pair**
  (``head_wind_mps[pair]``, a head wind for the + run and a tail wind for the - run), the
  Bayesian form of averaging the two directions (section 7.4); averaging itself leaves
  0.5 rho A CD0 w^2 in the fit (:func:`classical_steady`), or
* still air (no directions).

Priors: the coefficients from the model file, the noise and wind from
``config.STEADY_NOISE_PRIORS``.  Sampling goes through MAP -> Laplace whitening -> NUTS -> gates
(:func:`~bayes_roadload.inference.nuts.sample_problem`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist
import pandas as pd

from .. import config
from ..thesis import THESIS_TABLE_7_11
from ..data.ambient import air_density, mean_air_density
from ..physics.model import DragModel, StillAir, WindAir
from ..physics.roadload import road_load_summary
from ..physics.terms import Conditions
from .nuts import sample_problem
from .problem import shifted_constant, road_load_truth
from .results import FitReport, channel_report
from .spec import ModelSpec, Prior, load_model_spec

NOISE_SITES = ("sigma_force_n", "run_force_sd_n")
WIND_OPTIONS = ("auto", "measured", "pair", "still")


@dataclass(frozen=True, eq=False)
class SteadyProblem:
    """Everything the steady-state model needs (one row per sample, flattened over runs)."""

    spec: ModelSpec
    model: DragModel
    fixed: dict[str, float]
    free: tuple[str, ...]
    priors: dict[str, Prior]
    conditions: Conditions
    force_n: Any
    inertial_n: Any
    run_index: Any
    n_run: int
    pair_index: Any
    n_pairs: int
    wind: str
    run_ids: tuple
    pair_ids: tuple
    mass_kg: float
    frontal_area_m2: float
    initial: dict[str, Any] = field(default_factory=dict)

    kind = "steady"

    @property
    def n_observations(self) -> int:
        """Steady-state force readings."""
        return int(np.size(self.force_n))

    @property
    def hessian_runs(self) -> int:
        # 0: the finite-difference Hessian treats every coordinate as shared (the pair winds
        # couple two runs each; the problems are small)
        return 0

    def alternative_coordinates(self, values: dict[str, Any]) -> None:
        """None: one set of coordinates (:class:`~.problem.Problem`)."""
        return None

    def beyond_support(self, z: dict[str, Any], cov: np.ndarray) -> float:
        """0: every sampled coordinate maps into its support (:class:`~.problem.Problem`)."""
        return 0.0

    def shift_constant(self, name: str, delta: float) -> "SteadyProblem | None":
        """The problem with a fixed constant moved (:meth:`~.problem.Problem.shift_constant`)."""
        return shifted_constant(self, name, delta)

    def settings(self) -> dict[str, Any]:
        return {"pooling": "pooled", "noise": "run_offset", "robust": False}

    def postprocess(self, samples: dict[str, Any], seed: int) -> dict[str, Any]:
        return {}

    def derived(self, samples: dict[str, Any]) -> dict[str, Any]:
        return steady_derived(self, samples)

    def truth_values(self, truth: dict | None) -> dict[str, float]:
        """Scalar truths and the road load at the true coefficients."""
        values = {k: v for k, v in (truth or {}).items() if isinstance(v, (int, float))}
        if values:
            values.update(road_load_truth(self, values))
        return values

    @property
    def numpyro_model(self):
        return steady_model


def resolve_wind(campaign, wind: str = "auto") -> str:
    """The relative-air treatment: measured with anemometers, else a latent wind per pair when
    the runs have directions and pairs, else still air."""
    if wind not in WIND_OPTIONS:
        raise ValueError(f"wind must be one of {', '.join(WIND_OPTIONS)}, not {wind!r}")
    has_pairs = "direction" in campaign.runs and len(campaign.pairs()) > 0
    if wind == "auto":
        return "measured" if campaign.has_anemometer else ("pair" if has_pairs else "still")
    if wind == "measured" and not campaign.has_anemometer:
        raise ValueError("wind 'measured' needs airspeed_mps and yaw_rad in steady.csv")
    if wind == "pair" and not has_pairs:
        raise ValueError("wind 'pair' needs a direction column and opposite-direction pairs")
    return wind


def build_steady_problem(campaign, spec: ModelSpec | str = "four_term", *, wind: str = "auto") -> SteadyProblem:
    """The steady-state problem of a campaign under a model variant (module docstring)."""
    spec = load_model_spec(spec) if isinstance(spec, str) else spec
    if spec.driveline == "polynomial" or any(p in spec.free for p in ("At", "Bt", "Ct")):
        raise ValueError(f"model {spec.name!r} models the driveline loss: the steady-state force is measured at "
                         "the driven wheels, beyond the driveline (thesis 5.4.1); use e.g. four_term or three_term")
    wind = resolve_wind(campaign, wind)
    if wind == "pair" and spec.air not in ("auto", "still"):
        raise ValueError(f"model {spec.name!r} sets air = {spec.air!r}; the latent pair wind needs 'auto' or 'still'")
    model, fixed, free = spec.build(campaign)
    if wind == "pair":
        model = DragModel(model.terms, WindAir())
        fixed = {k: v for k, v in fixed.items() if k not in ("airspeed_factor", "yaw_factor")}
        fixed.update({"head_wind_mps": 0.0, "cross_wind_mps": 0.0})
    elif wind == "still" and campaign.has_anemometer:
        model = DragModel(model.terms, StillAir())
        fixed = {k: v for k, v in fixed.items() if k not in ("airspeed_factor", "yaw_factor")}
    runs = campaign.runs
    n = len(runs)
    v = runs["speed_mps"].to_numpy(float)
    yaw_reading = runs["yaw_rad"].to_numpy(float) if campaign.has_anemometer else np.zeros(n)
    air_reading = (campaign.anemometer.yaw_corrected_airspeed(runs["airspeed_mps"].to_numpy(float), yaw_reading)
                   if campaign.has_anemometer else v)
    temp = runs["temperature_k"].to_numpy(float) if "temperature_k" in runs else np.full(n, config.REFERENCE_TEMPERATURE_K)
    direction = runs["direction"].to_numpy(float) if "direction" in runs else np.ones(n)
    z = np.zeros(n)
    vehicle = campaign.vehicle
    c = Conditions(speed_mps=jnp.asarray(v), airspeed_mps=jnp.asarray(air_reading), yaw_rad=jnp.asarray(yaw_reading),
                   driveline_force_n=jnp.asarray(z), position_m=jnp.asarray(z), distance_m=jnp.asarray(z),
                   time_s=jnp.asarray(z), accel_mps2=jnp.asarray(runs["accel_mps2"].to_numpy(float)),
                   direction=jnp.asarray(direction), air_density_kgpm3=jnp.asarray(air_density(runs)),
                   temperature_k=jnp.asarray(temp), mass_kg=jnp.asarray(z + vehicle.mass_kg),
                   frontal_area_m2=jnp.asarray(z + vehicle.frontal_area_m2))
    run_ids = tuple(campaign.run_ids)
    run_of = {r: i for i, r in enumerate(run_ids)}
    run_index = np.array([run_of[r] for r in runs["run"].tolist()])
    pair_ids: tuple = ()
    pair_index = np.zeros(n, int)
    if wind == "pair":
        pairs = campaign.pairs()
        pair_ids = tuple(range(1, len(pairs) + 1))
        pair_of = {r: k for k, pr in enumerate(pairs) for r in pr}
        keep = np.array([r in pair_of for r in runs["run"].tolist()])
        if not keep.all():
            raise ValueError("with a latent pair wind every run needs an opposite-direction partner: "
                             f"{sorted(set(runs['run'][~keep].tolist()))} have none")
        pair_index = np.array([pair_of[r] for r in runs["run"].tolist()])
    force = runs["tractive_force_n"].to_numpy(float)
    inertial = vehicle.effective_mass_kg * runs["accel_mps2"].to_numpy(float)
    problem = SteadyProblem(spec=spec, model=model, fixed=fixed, free=free,
                            priors={k: spec.priors[k] for k in free}, conditions=c, force_n=jnp.asarray(force),
                            inertial_n=jnp.asarray(inertial), run_index=jnp.asarray(run_index), n_run=len(run_ids),
                            pair_index=jnp.asarray(pair_index), n_pairs=len(pair_ids), wind=wind, run_ids=run_ids,
                            pair_ids=pair_ids, mass_kg=float(vehicle.mass_kg),
                            frontal_area_m2=float(vehicle.frontal_area_m2))
    return _with_initial(problem)


def _with_initial(problem: SteadyProblem) -> SteadyProblem:
    """Start values: the free coefficients by linear least squares of the corrected force on
    each free parameter's force per unit (the drag function is affine in AD, BD, CD0, KD at
    fixed lift), the noise levels from its residuals, the pair winds 0."""
    base = dict(problem.fixed, **{k: problem.spec.initial.get(k, problem.priors[k].center) for k in problem.free})
    if problem.wind == "pair":
        base["head_wind_mps"] = jnp.zeros(problem.force_n.shape)

    def force(values):
        return drag_force_n(problem.model, dict(base, **values), problem.conditions)

    f0 = force({})
    columns = [np.asarray(force({k: base[k] + 1.0})) - np.asarray(f0) for k in problem.free]
    y = np.asarray(problem.force_n - problem.inertial_n) - np.asarray(f0)
    design = np.stack(columns, axis=1)
    delta, *_ = np.linalg.lstsq(design, y, rcond=None)
    init: dict[str, Any] = {}
    for k, d in zip(problem.free, delta):
        x = float(base[k] + d)
        prior = problem.priors[k]
        if prior.low is not None:
            x = max(x, prior.low + 1e-3 * config.PARAMETER_SCALES.get(k, 1.0))
        init[k] = x
    resid = y - design @ delta
    init["sigma_force_n"] = max(float(np.std(resid)), 1.0)
    init["run_force_sd_n"] = 0.5 * config.STEADY_NOISE_PRIORS["run_force_sd_n"]
    if problem.wind == "pair":
        init["head_wind_mps"] = jnp.zeros(problem.n_pairs)
    return dataclasses.replace(problem, initial=init)


def drag_force_n(model: DragModel, params: dict[str, Any], c: Conditions) -> jnp.ndarray:
    """F_D of ``model`` under the logged conditions ``c``, the relative air taken from the model's
    air treatment (calibrated readings, a wind, or still air) as the coastdown integrator does."""
    airspeed, yaw = model.air.relative_air(model.complete(params), c.speed_mps, c.airspeed_mps, c.yaw_rad)
    return model.force_n(params, c._replace(airspeed_mps=airspeed, yaw_rad=yaw))


def model_force_n(problem: SteadyProblem, sample: dict[str, Any]) -> jnp.ndarray:
    """The road load F_D at every sample (N) for the parameters of ``sample``."""
    params = dict(problem.fixed, **{k: sample[k] for k in problem.free})
    if problem.wind == "pair":
        params["head_wind_mps"] = problem.conditions.direction * sample["head_wind_mps"][problem.pair_index]
    return drag_force_n(problem.model, params, problem.conditions)


def run_offset_log_likelihood(residual_n, run_index, n_runs: int, sigma, tau) -> jnp.ndarray:
    """Sum over runs of log N(e_r; 0, sigma^2 I + tau^2 1 1^T), the run's constant offset
    integrated out: with n, S1 = sum e, S2 = sum e^2 of a run, by Sherman-Morrison
    -0.5 [S2 / sigma^2 - tau^2 S1^2 / (sigma^2 (sigma^2 + n tau^2)) + (n - 1) log sigma^2
    + log(sigma^2 + n tau^2) + n log 2 pi]."""
    e = jnp.asarray(residual_n)
    count = jax.ops.segment_sum(jnp.ones_like(e), run_index, num_segments=n_runs)
    s1 = jax.ops.segment_sum(e, run_index, num_segments=n_runs)
    s2 = jax.ops.segment_sum(e**2, run_index, num_segments=n_runs)
    s, t = sigma**2, tau**2
    big = s + count * t
    ll = -0.5 * (s2 / s - t * s1**2 / (s * big) + (count - 1.0) * jnp.log(s) + jnp.log(big)
                 + count * math.log(2.0 * math.pi))
    return jnp.sum(ll)


def steady_log_likelihood(problem: SteadyProblem, sample: dict[str, Any]) -> jnp.ndarray:
    """Log-likelihood of the logged tractive forces given a sample (module docstring)."""
    resid = problem.force_n - problem.inertial_n - model_force_n(problem, sample)
    return run_offset_log_likelihood(resid, problem.run_index, problem.n_run, sample["sigma_force_n"],
                                     sample["run_force_sd_n"])


def steady_model(problem: SteadyProblem) -> None:
    """numpyro model of the steady-state forces (module docstring)."""
    sample: dict[str, Any] = {k: numpyro.sample(k, problem.priors[k].to_numpyro()) for k in problem.free}
    priors = config.STEADY_NOISE_PRIORS
    sample["sigma_force_n"] = numpyro.sample("sigma_force_n", dist.HalfNormal(priors["sigma_force_n"]))
    sample["run_force_sd_n"] = numpyro.sample("run_force_sd_n", dist.Gamma(2.0, 2.0 / priors["run_force_sd_n"]))
    if problem.wind == "pair":
        with numpyro.plate("pair", problem.n_pairs):
            sample["head_wind_mps"] = numpyro.sample("head_wind_mps", dist.Normal(0.0, priors["pair_wind_mps"]))
    numpyro.factor("steady_loglik", steady_log_likelihood(problem, sample))


def fit_steady_nuts(campaign, spec: ModelSpec | str = "four_term", *, wind: str = "auto",
                    sampler: config.SamplerConfig = config.DEFAULT_SAMPLER):
    """MAP, Laplace whitening, NUTS and gates on the steady-state model; a
    :class:`~bayes_roadload.inference.nuts.NutsFit`."""
    problem = build_steady_problem(campaign, spec, wind=wind)
    return sample_problem(problem, problem.initial, sampler, campaign.truth)


def steady_derived(problem: SteadyProblem, samples: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Road load at reference conditions (still air, 100 kPa, 293.2 K) per draw: ``F50_N``, its
    tyre / aero parts, ``F0_N``, ``F1_N_per_kph``, ``F2_N_per_kph2``."""
    shape = np.shape(samples[problem.free[0]])[:2]
    flat = {k: jnp.asarray(np.reshape(samples[k], -1)) for k in problem.free}
    model = DragModel(problem.model.terms, WindAir()) if problem.wind == "pair" else problem.model

    def one(values):
        params = dict(problem.fixed, **values)
        if problem.wind == "pair":
            params.update(head_wind_mps=0.0, cross_wind_mps=0.0)
        return road_load_summary(model, params, problem.mass_kg, problem.frontal_area_m2)

    out = jax.jit(jax.vmap(one))(flat)
    names = ("F50_N", "F50_tyre_N", "F50_aero_N", "F0_N", "F1_N_per_kph", "F2_N_per_kph2")
    return {k: np.asarray(out[k]).reshape(shape) for k in names}


def classical_steady(campaign, *, averaged: bool = True) -> pd.DataFrame:
    """The thesis' analysis (eq. 5.6-5.9): per run the mean speed and mean corrected force
    F_T - M_e dv/dt; with ``averaged`` the two runs of each opposite-direction pair averaged
    (table 7.7, no wind correction); a least-squares quadratic A_0 + B_0 v + C_0 v^2 through
    the points; AD = A_0 / (M g), BD = B_0 / (M g), CD0 = C_0 / (rho A / 2) at the campaign's
    mean air density.  Rows ``AD, BD, CD0`` with ``estimate`` and ``se`` (from the fit's
    covariance), and ``points``."""
    runs = campaign.runs.assign(corrected=campaign.runs["tractive_force_n"]
                                - campaign.vehicle.effective_mass_kg * campaign.runs["accel_mps2"])
    per_run = runs.groupby("run", sort=False).agg(v=("speed_mps", "mean"), f=("corrected", "mean"))
    if averaged:
        pairs = campaign.pairs()
        if not pairs:
            raise ValueError("averaging opposite directions needs pairs (direction / pair columns)")
        per_run = pd.DataFrame([per_run.loc[list(p)].mean() for p in pairs])
    rho = mean_air_density(runs)
    (c0, b0, a0), cov = np.polyfit(per_run["v"], per_run["f"], 2, cov=True)
    se = np.sqrt(np.diag(cov))[::-1]
    mg = campaign.vehicle.mass_kg * config.GRAVITY_MPS2
    half_rho_a = 0.5 * rho * campaign.vehicle.frontal_area_m2
    return pd.DataFrame({"parameter": ["AD", "BD", "CD0"], "estimate": [a0 / mg, b0 / mg, c0 / half_rho_a],
                         "se": [se[0] / mg, se[1] / mg, se[2] / half_rho_a], "points": len(per_run)})


def steady_report(fit, campaign=None, *, gates: config.Gates = config.DEFAULT_GATES) -> FitReport:
    """The report of a steady-state fit: summary (free coefficients, noise, derived road
    load), per-run rows of the pair winds (when latent; None otherwise) and the gates."""
    p = fit.problem
    run_sites = ("head_wind_mps",) if p.wind == "pair" else ()
    return channel_report(
        fit, list(p.free) + list(NOISE_SITES), kind="steady",
        observed={"tractive_force_n": np.asarray(p.force_n)}, run_sites=run_sites,
        dims={"head_wind_mps": ["pair"]}, coords={"pair": [str(k) for k in p.pair_ids]} if run_sites else None,
        gates=gates, extra={"wind": p.wind, "runs": len(p.run_ids), "samples": int(np.size(p.force_n)),
                            "accel_source": None if campaign is None else campaign.accel_source})


def steady_extras(fit, campaign, summary: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """``classical.csv`` (:func:`classical_steady`, opposite directions averaged) when the
    campaign has pairs."""
    if "direction" in campaign.runs and campaign.pairs():
        return {"classical.csv": classical_steady(campaign)}
    return {}


def compare_with_coastdown(steady: pd.DataFrame, coastdown: pd.DataFrame,
                           names=("AD", "BD", "CD0", "KD", "F50_N")) -> pd.DataFrame:
    """Steady state against coastdown in the spirit of thesis table 7.11: for each quantity both
    posterior means, sds and 95 % intervals, the difference (steady - coastdown) in % of the
    coastdown and in combined sds, and the thesis' figures (table 7.11: the coastdown "set of
    24" and the steady-state column, ``THESIS_TABLE_7_11``)."""
    s, c = steady.set_index("parameter"), coastdown.set_index("parameter")
    thesis = THESIS_TABLE_7_11
    rows = []
    for k in names:
        if k not in s.index or k not in c.index:
            continue
        diff = s.loc[k, "mean"] - c.loc[k, "mean"]
        sd = math.hypot(s.loc[k, "sd"], c.loc[k, "sd"])
        t_cd, t_ss = thesis["coastdown_set_of_24"].get(k), thesis["steady_state"].get(k)
        rows.append({"parameter": k, "coastdown_mean": c.loc[k, "mean"], "coastdown_sd": c.loc[k, "sd"],
                     "coastdown_q2.5": c.loc[k, "q2.5"], "coastdown_q97.5": c.loc[k, "q97.5"],
                     "steady_mean": s.loc[k, "mean"], "steady_sd": s.loc[k, "sd"],
                     "steady_q2.5": s.loc[k, "q2.5"], "steady_q97.5": s.loc[k, "q97.5"],
                     "difference_pct": 100.0 * diff / c.loc[k, "mean"], "difference_z": diff / sd if sd > 0 else math.nan,
                     "thesis_coastdown": t_cd, "thesis_steady": t_ss,
                     "thesis_difference_pct": (100.0 * (t_ss - t_cd) / t_cd) if t_cd and t_ss else math.nan})
    return pd.DataFrame(rows)
