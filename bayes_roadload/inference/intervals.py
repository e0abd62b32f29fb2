"""Bayesian fit of speed-gate interval times: every run and window of a campaign jointly.

The data of an :class:`~bayes_roadload.data.intervals.IntervalCampaign` are, per run, the
times to coast through consecutive speed bands (a VBOX "Coastdown" export, a speed trap).
Their model time is ``integral M_e / F(v) dv`` over each band
(:func:`~bayes_roadload.physics.intervals.interval_times`, the physics core's drag model), so
the high (95 -> 70 km/h) and low (50 -> 35 km/h) windows of the NBR "split" method are fitted
jointly with one set of coefficients: their different speeds separate the constant (tyre) and
the quadratic (aerodynamic) parts of the road load.

Likelihood (:func:`~bayes_roadload.physics.intervals.band_time_loglik`): the band times of a
run are Gaussian around the model times with covariance ``sigma_gate_s^2 T +
band_noise_s_per_sqrt_s^2 diag(duration) + (M_e run_decel_sd_mps2)^2 s s^T``: gate-crossing
timing errors (neighbouring bands share a crossing), independent scatter that grows with a
band's duration, and a run-level deceleration offset integrated out (each run meets its own
gusts, tyre temperature and driver; ``s`` the bands' sensitivity to a constant extra force).
Priors of the three nuisances: Gamma with the means and shapes of
:data:`bayes_roadload.config.INTERVAL_NOISE_PRIORS` and ``INTERVAL_NOISE_PRIOR_SHAPES`` (vanishing at 0: no
funnel at the boundary).

The coefficients and their priors come from a model variant (``models/*.toml``, air "still"
or "wind"); ``split_f0_f2`` frees AD and CD0 (F = F0 + F2 v^2 with F0 = M g AD, the split
method's form).  In an interval fit ``head_wind_mps`` is a steady wind **along the track axis**:
a head wind for the runs of direction +1, a tail wind for those of -1 (``split_f0_f2_wind``), and
``grade_rad`` (the ``gradient`` term) the track's rise in the + direction
(``split_f0_f2_grade``): the two explanations of a difference between the headings.

Runs whose ``valid`` column is 0 (the operator's Run-Use = Off) are left out, as are runs the
validity checks reject (:mod:`bayes_roadload.analysis.validity`), with their partners.  Sampling
goes through the same MAP -> Laplace whitening -> NUTS -> gates as the trace fits
(:func:`~bayes_roadload.inference.nuts.run_nuts`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import arviz as az
import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist
import pandas as pd

from .. import config
from ..data.intervals import IntervalCampaign
from ..data.ambient import air_density
from ..physics.intervals import (
    IntervalBands,
    band_time_covariance,
    band_time_loglik,
    check_speed_domain,
    interval_times,
)
from ..physics.model import DragModel
from .bayes import default_prior
from .nuts import sample_problem
from .problem import PooledRunProblem
from .results import DERIVED, SUMMARY_COLUMNS, FitReport, _rows, diagnostics, inference_data
from .spec import ModelSpec, Prior, load_model_spec

NOISE_SITES = ("sigma_gate_s", "band_noise_s_per_sqrt_s", "run_decel_sd_mps2")


@dataclass(frozen=True, eq=False)
class IntervalProblem(PooledRunProblem):
    """Everything a Bayesian fit of interval times needs, resolved once.

    Attributes
    ----------
    spec, model, fixed, free, priors : as :class:`~bayes_roadload.inference.bayes.FitProblem`.
    bands : the runs' speed bands, flattened ([B]).
    observed_s : [B] observed band times.
    band_index : [R, K] index into the flattened bands of run r's k-th band (0 on padding).
    mask : [R, K] real bands.
    run_ids : run ids (batch order).
    windows : window label of each run.
    directions : [R] +1 / -1.
    effective_mass_kg : [R] M_e of each run (the campaign's, or shifted by a per-run test mass).
    mass_kg, frontal_area_m2 : the vehicle (derived road load at reference conditions).
    initial : starting values of the free parameters and nuisances.
    """

    spec: ModelSpec
    model: DragModel
    fixed: dict[str, float]
    free: tuple[str, ...]
    priors: dict[str, Prior]
    bands: IntervalBands
    observed_s: Any
    band_index: Any
    mask: Any
    run_ids: tuple
    windows: tuple
    directions: Any
    effective_mass_kg: Any
    mass_kg: float
    frontal_area_m2: float
    initial: dict[str, Any] = field(default_factory=dict)

    kind = "intervals"
    observed_name = "interval_s"
    """Name of the observed times in ``posterior.nc`` (dims run, band)."""

    noise_model = "interval"

    @property
    def n_observations(self) -> int:
        """Padded interval times of every run."""
        return int(np.size(self.mask))

    @property
    def numpyro_model(self):
        return interval_model

    @property
    def sites(self) -> tuple[str, ...]:
        """The sample sites of a draw the likelihood needs."""
        return tuple(self.free) + NOISE_SITES

    @property
    def observed_runs(self):
        """[R, K] observed band times (0 on padding)."""
        return jnp.where(self.mask, _per_run(self, self.observed_s), 0.0)

    def run_columns(self) -> dict[str, Any]:
        """The columns that identify each run in ``runs_summary.csv``."""
        return {"run": list(self.run_ids), "window": list(self.windows),
                "direction": np.asarray(self.directions).astype(int)}

    def run_times(self, sample: dict[str, Any]):
        """[R, K] model band times of one draw and their sensitivity to a constant extra
        deceleration of the run (s per m/s^2), the inputs of :func:`~bayes_roadload.physics.
        intervals.band_time_loglik`."""
        out = model_band_times(self, sample)
        t = _per_run(self, out["time_s"])
        return t, _per_run(self, out["dtime_dforce_s_per_n"]) * self.effective_mass_kg[:, None]


def build_interval_problem(campaign: IntervalCampaign, spec: ModelSpec | str = "split_f0_f2",
                           runs=None) -> IntervalProblem:
    """Resolve a model variant against an interval campaign.

    ``runs``: the run ids to fit (default: every run whose ``valid`` is not 0).
    """
    spec = load_model_spec(spec) if isinstance(spec, str) else spec
    if spec.air in ("measured",):
        raise ValueError(f"model {spec.name!r} uses measured air; interval times carry no anemometer channels")
    model, fixed, free = spec.build(campaign)
    check_speed_domain(model)
    priors = {p: spec.priors.get(p) or default_prior(p, model) for p in free}
    df = campaign.intervals
    if runs is None:
        valid = campaign.run_table()
        runs = [r for r, ok in zip(valid["run"], valid["valid"] if "valid" in valid else [1] * len(valid)) if ok]
    runs = list(runs)
    if not runs:
        raise ValueError("no runs to fit (every run is marked invalid)")
    df = df[df["run"].isin(runs)]
    order = {r: i for i, r in enumerate(runs)}
    df = df.sort_values("run", key=lambda s: s.map(order), kind="stable").reset_index(drop=True)
    v = campaign.vehicle
    n = len(df)
    temp = df["temperature_k"].to_numpy(float) if "temperature_k" in df else np.full(n, config.REFERENCE_TEMPERATURE_K)
    mass = df["mass_kg"].to_numpy(float) if "mass_kg" in df else np.full(n, v.mass_kg)
    me = v.effective_mass_kg + (mass - v.mass_kg)   # the rotating inertia does not change with the load
    direction = df["direction"].to_numpy(float) if "direction" in df else np.ones(n)
    bands = IntervalBands(
        speed_start_mps=jnp.asarray(df["speed_start_mps"].to_numpy(float)),
        speed_end_mps=jnp.asarray(df["speed_end_mps"].to_numpy(float)),
        direction=jnp.asarray(direction),
        air_density_kgpm3=jnp.asarray(air_density(df)),
        temperature_k=jnp.asarray(temp), mass_kg=jnp.asarray(mass), effective_mass_kg=jnp.asarray(me),
        frontal_area_m2=jnp.full(n, v.frontal_area_m2))
    groups = df.groupby("run", sort=False).indices
    k = max(len(ix) for ix in groups.values())
    index = np.zeros((len(runs), k), int)
    mask = np.zeros((len(runs), k), bool)
    for i, r in enumerate(runs):
        ix = groups[r]
        index[i, :len(ix)] = ix
        mask[i, :len(ix)] = True
    first = df.groupby("run", sort=False).first()
    initial = {p: float(spec.initial.get(p, priors[p].center)) for p in free}
    initial.update({name: config.INTERVAL_NOISE_PRIORS[name] for name in NOISE_SITES})
    return IntervalProblem(
        spec=spec, model=model, fixed={kk: float(vv) for kk, vv in fixed.items()}, free=tuple(free),
        priors=priors, bands=bands, observed_s=jnp.asarray(df["interval_s"].to_numpy(float)),
        band_index=jnp.asarray(index), mask=jnp.asarray(mask), run_ids=tuple(runs),
        windows=tuple(str(first.loc[r, "window"]) if "window" in first else "all" for r in runs),
        directions=jnp.asarray(first["direction"].to_numpy(float) if "direction" in first else np.ones(len(runs))),
        effective_mass_kg=jnp.asarray(me[index[:, 0]]), mass_kg=float(v.mass_kg),
        frontal_area_m2=float(v.frontal_area_m2), initial=initial)


def band_parameters(problem: IntervalProblem, sample: dict[str, Any]) -> dict[str, Any]:
    """The drag-model parameters of one draw, per band where they depend on the run: the
    steady along-track wind ``head_wind_mps`` is a head wind for direction +1 and a tail wind
    for -1."""
    params = {k: jnp.asarray(v) for k, v in problem.fixed.items()}
    params.update({k: sample[k] for k in problem.free})
    if "head_wind_mps" in params:
        params["head_wind_mps"] = params["head_wind_mps"] * problem.bands.direction
    return params


def model_band_times(problem: IntervalProblem, sample: dict[str, Any]) -> dict[str, Any]:
    """[B] model time, distance and force sensitivity of every band for one draw."""
    return interval_times(problem.model, band_parameters(problem, sample), problem.bands)


def _per_run(problem: IntervalProblem, x):
    return jnp.asarray(x)[problem.band_index]


def run_log_likelihood(problem: IntervalProblem, sample: dict[str, Any]) -> jnp.ndarray:
    """[R] log-likelihood of each run's band times for one draw (module docstring).  Works for
    any problem with ``run_times``, ``observed_runs`` and ``mask`` (the segments between the
    markers of a distance-time record too: :mod:`.distances`)."""
    t, sens = problem.run_times(sample)
    resid = problem.observed_runs - t
    return band_time_loglik(resid, problem.mask, t, sens, sample["sigma_gate_s"],
                            sample["band_noise_s_per_sqrt_s"], sample["run_decel_sd_mps2"])


def sample_coefficients_and_noise(problem, means=None, shapes=None) -> dict[str, Any]:
    """numpyro sites of the free coefficients (their priors) and of the three timing-noise
    nuisances (Gamma priors with the given means and shapes, default
    ``config.INTERVAL_NOISE_PRIORS`` / ``INTERVAL_NOISE_PRIOR_SHAPES``)."""
    means = config.INTERVAL_NOISE_PRIORS if means is None else means
    shapes = config.INTERVAL_NOISE_PRIOR_SHAPES if shapes is None else shapes
    sample: dict[str, Any] = {}
    for name in problem.free:
        sample[name] = numpyro.sample(name, problem.priors[name].to_numpyro())
    for name in NOISE_SITES:
        sample[name] = numpyro.sample(name, dist.Gamma(shapes[name], shapes[name] / means[name]))
    return sample


def interval_model(problem: IntervalProblem) -> None:
    """The numpyro model of interval times (module docstring); contract names for the sites."""
    sample = sample_coefficients_and_noise(problem)
    numpyro.factor("interval_loglik", run_log_likelihood(problem, sample).sum())


# ----------------------------------------------------------------------------- fitting

def fit_intervals_nuts(campaign: IntervalCampaign, spec: ModelSpec | str = "split_f0_f2", *,
                       sampler: config.SamplerConfig = config.DEFAULT_SAMPLER, runs=None):
    """MAP, Laplace whitening and NUTS (:mod:`~bayes_roadload.inference.nuts`) on the interval
    model.  Returns a :class:`~bayes_roadload.inference.nuts.NutsFit`."""
    problem = build_interval_problem(campaign, spec, runs=runs)
    return sample_problem(problem, problem.initial, sampler, campaign.truth)


def _flat(x):
    x = np.asarray(x)
    return x.reshape((-1,) + x.shape[2:])


def predictive_band_times(problem: IntervalProblem, samples: dict[str, np.ndarray], n_draws: int = 400,
                          seed: int = 1) -> dict[str, np.ndarray]:
    """Replicated band times [draw, R, K] (model time plus a draw of the noise, run effect
    included) and the model times, for ``n_draws`` posterior draws spread over the chains.
    ``problem`` may hold other runs than the fit (held-out runs: leave-one-pair-out)."""
    flat = {k: _flat(v) for k, v in samples.items()}
    total = next(iter(flat.values())).shape[0]
    idx = np.linspace(0, total - 1, min(n_draws, total)).astype(int)

    def one(s):
        t, sens = problem.run_times(s)
        cov = band_time_covariance(problem.mask, t, sens, s["sigma_gate_s"], s["band_noise_s_per_sqrt_s"],
                                   s["run_decel_sd_mps2"])
        return t, cov

    draws = {k: jnp.asarray(v[idx]) for k, v in flat.items() if k in problem.sites}
    t, cov = jax.jit(jax.vmap(one))(draws)
    t, cov = np.asarray(t), np.asarray(cov)
    chol = np.linalg.cholesky(cov)   # numpy, outside the sampler
    z = np.random.default_rng(seed).standard_normal(t.shape)
    rep = t + np.einsum("drij,drj->dri", chol, z)
    mask = np.asarray(problem.mask)
    return {"interval_s": np.where(mask, rep, np.nan), "model_interval_s": np.where(mask, t, np.nan)}


def observed_band_times(problem: IntervalProblem) -> np.ndarray:
    """[R, K] observed band times (NaN on padding)."""
    return np.where(np.asarray(problem.mask), np.asarray(problem.observed_runs), np.nan)


def log_likelihood_per_run(problem: IntervalProblem, samples: dict[str, np.ndarray]) -> np.ndarray:
    chains = next(iter(samples.values())).shape[0]
    flat = {k: jnp.asarray(_flat(v)) for k, v in samples.items() if k in problem.sites}
    ll = np.asarray(jax.jit(jax.vmap(lambda s: run_log_likelihood(problem, s)))(flat))
    return ll.reshape((chains, -1) + ll.shape[1:])


def to_inference_data(fit) -> az.InferenceData:
    """posterior (contract names, derived road load), log_likelihood per run, observed and
    replicated band times (:func:`~bayes_roadload.inference.results.inference_data`)."""
    p = fit.problem
    name = p.observed_name
    pred = predictive_band_times(p, fit.samples, n_draws=fit.sampler.posterior_predictive_draws)
    chains = fit.sampler.num_chains
    per_chain = pred["interval_s"].shape[0] // chains
    rep = pred["interval_s"][:per_chain * chains].reshape((chains, per_chain) + pred["interval_s"].shape[1:])
    runs = [str(r) for r in p.run_ids]
    k = np.asarray(p.mask).shape[1]
    per_run_sites = [s for s in fit.samples if np.ndim(fit.samples[s]) == 3 and np.shape(fit.samples[s])[2] == p.n_runs]
    return inference_data(fit, predictive={name: rep}, log_likelihood={name: log_likelihood_per_run(p, fit.samples)},
                          observed={name: observed_band_times(p)}, coords={"run": runs, "band": np.arange(k)},
                          dims={name: ["run", "band"], **{s: ["run"] for s in per_run_sites}})


def summary_table(fit, idata) -> pd.DataFrame:
    names = list(fit.problem.free) + list(NOISE_SITES) + list(DERIVED)
    return _rows(idata, names)


def run_predictions(fit, idata) -> pd.DataFrame:
    """``runs_summary.csv`` of an interval fit: per run, observed total time, the posterior
    predictive mean and 95 % interval of it, and whether it falls inside."""
    p = fit.problem
    obs = np.nansum(observed_band_times(p), axis=1)
    rep = np.asarray(idata.posterior_predictive[p.observed_name])
    tot = np.nansum(rep, axis=-1).reshape(-1, p.n_runs)
    lo, hi = np.percentile(tot, [2.5, 97.5], axis=0)
    table = p.run_columns()
    if "v0_mps" in fit.samples:   # distance-time problems: each run's speed at the first marker
        draws = np.asarray(fit.samples["v0_mps"]).reshape(-1, p.n_runs)
        table["v0_mps_mean"], table["v0_mps_sd"] = draws.mean(axis=0), draws.std(axis=0, ddof=1)
    table.update({"observed_time_s": obs, "predicted_mean_s": tot.mean(axis=0), "predicted_q2.5": lo,
                  "predicted_q97.5": hi, "inside_95": (obs >= lo) & (obs <= hi)})
    return pd.DataFrame(table)


def interval_report(fit, campaign=None, *, gates: config.Gates = config.DEFAULT_GATES) -> FitReport:
    """The report of an interval (or distance-time) fit: posterior with replicated times,
    summary, ``runs_summary.csv`` rows (:func:`run_predictions`) and the gates of
    :func:`~bayes_roadload.inference.results.diagnostics` over the sampled quantities."""
    idata = to_inference_data(fit)
    summary = summary_table(fit, idata)
    diag = diagnostics(fit, idata, summary, gates, runs=pd.DataFrame(columns=list(SUMMARY_COLUMNS)))
    diag["kind"] = fit.problem.kind
    diag["runs_fitted"] = fit.problem.n_runs
    return FitReport(idata, summary, run_predictions(fit, idata), diag)
