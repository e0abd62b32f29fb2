"""Bayesian fit of distance-time records: every run of a campaign jointly, at any test masses.

The data of a :class:`~bayes_roadload.data.distances.DistanceCampaign` are, per run, the times
at which the vehicle passes known distances (markers, a speed trap: seed 002).  The model
integrates the coastdown equation in distance from each run's first marker
(:func:`~bayes_roadload.physics.distances.segment_times`, the physics core's drag model) with
an unknown speed there, ``v0_mps[run]`` (prior Normal around the speed a quadratic through the
run's first three passing times gives, sd ``config.DISTANCE_V0_PRIOR_SD_MPS``), and compares
the times between consecutive markers with the observed ones.

Likelihood: the interval-time one (:func:`~bayes_roadload.inference.intervals.
run_log_likelihood`, :func:`~bayes_roadload.physics.intervals.band_time_loglik`) with the
segment between two markers as the band: a timing error per marker passing ``sigma_gate_s``
(neighbouring segments share one), scatter ``band_noise_s_per_sqrt_s`` growing with a
segment's duration, and a run-level deceleration offset ``run_decel_sd_mps2`` integrated out.
Gamma priors with the means and shapes of ``config.DISTANCE_NOISE_PRIORS`` /
``DISTANCE_NOISE_PRIOR_SHAPES``.

Several test masses (``mass_kg`` per run): each run's M and M_e (shifted by the same amount) go
into its integration, so the rolling force M g AD scales with the load and the drag does not:
one joint fit of runs at two masses separates them (seed 002's method).  The coefficients and
their priors come from a model variant (``models/*.toml``, air "still" or "wind"; a wind is a
steady one along the track, a head wind for direction +1 and a tail wind for -1).

Sampling, outputs and gates are those of the interval fit (MAP -> Laplace whitening -> NUTS ->
gates, :func:`~bayes_roadload.inference.nuts.sample_problem`; ``posterior.nc`` with the
replicated segment times, ``summary.csv``, ``runs_summary.csv``, ``diagnostics.json``:
:func:`~bayes_roadload.inference.intervals.interval_report`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist

from .. import config
from ..data.distances import DistanceCampaign
from ..data.ambient import air_density
from ..physics.distances import MarkerRuns, segment_times
from ..physics.intervals import check_speed_domain
from ..physics.model import DragModel
from .bayes import default_prior
from .intervals import NOISE_SITES, interval_report, run_log_likelihood, sample_coefficients_and_noise
from .nuts import sample_problem
from .problem import PooledRunProblem
from .spec import ModelSpec, Prior, load_model_spec

DEFAULT_MODEL = "three_term"
"""Model variant of ``bayes-roadload fit`` on a distance-time campaign: AD, BD, CD0 free (a
coastdown through markers from ~30 m/s to a crawl spans the speeds that separate them)."""


@dataclass(frozen=True, eq=False)
class DistanceProblem(PooledRunProblem):
    """Everything a Bayesian fit of distance-time records needs, resolved once.

    Attributes
    ----------
    spec, model, fixed, free, priors : as :class:`~bayes_roadload.inference.bayes.FitProblem`.
    runs : the markers (:class:`~bayes_roadload.physics.distances.MarkerRuns`, [R, K]).
    observed_segments_s : [R, K-1] observed times between consecutive markers (0 on padding).
    mask : [R, K-1] real segments.
    run_ids : run ids (fit order).
    directions : [R] +1 / -1.
    run_masses_kg, effective_mass_kg : [R] each run's test mass and M_e.
    v0_guess_mps : [R] centre of each run's initial-speed prior.
    mass_kg, frontal_area_m2 : the vehicle (derived road load at reference conditions).
    initial : starting values of every sample site.
    """

    spec: ModelSpec
    model: DragModel
    fixed: dict[str, float]
    free: tuple[str, ...]
    priors: dict[str, Prior]
    runs: MarkerRuns
    observed_segments_s: Any
    mask: Any
    run_ids: tuple
    directions: Any
    run_masses_kg: Any
    effective_mass_kg: Any
    v0_guess_mps: Any
    mass_kg: float
    frontal_area_m2: float
    initial: dict[str, Any] = field(default_factory=dict)

    kind = "distances"
    observed_name = "segment_time_s"
    """Name of the observed times in ``posterior.nc`` (dims run, band: the segment after marker k)."""

    noise_model = "distance-time"

    @property
    def n_observations(self) -> int:
        """Padded marker records of every run."""
        return int(np.size(self.runs.mask))

    @property
    def numpyro_model(self):
        return distance_time_model

    @property
    def sites(self) -> tuple[str, ...]:
        return tuple(self.free) + NOISE_SITES + ("v0_mps",)

    @property
    def observed_runs(self):
        return self.observed_segments_s

    def run_columns(self) -> dict[str, Any]:
        """The columns that identify each run in ``runs_summary.csv`` (its test mass)."""
        return {"run": list(self.run_ids), "direction": np.asarray(self.directions).astype(int),
                "mass_kg": np.asarray(self.run_masses_kg)}

    def parameters(self, sample: dict[str, Any]) -> dict[str, Any]:
        """The drag-model parameters of one draw, per run where they depend on it: a steady
        along-track ``head_wind_mps`` is a head wind for direction +1 and a tail wind for -1."""
        params = {k: jnp.asarray(v) for k, v in self.fixed.items()}
        params.update({k: sample[k] for k in self.free})
        if "head_wind_mps" in params:
            params["head_wind_mps"] = params["head_wind_mps"] * self.directions
        return params

    def run_times(self, sample: dict[str, Any]):
        """[R, K-1] model segment times of one draw and their sensitivity to a constant extra
        deceleration of the run (s per m/s^2)."""
        out = segment_times(self.model, self.parameters(sample), self.runs, sample["v0_mps"])
        return out["time_s"], out["dtime_ddecel_s_per_mps2"]


def _v0_guess(x: np.ndarray, t: np.ndarray) -> float:
    """Speed at the first marker from a quadratic x(t) through the first three passings."""
    t3, x3 = t[:3] - t[0], x[:3] - x[0]
    coef = np.polyfit(t3, x3, 2)
    v = float(coef[1])
    return v if np.isfinite(v) and v > 0 else float(x3[1] / t3[1])


def build_distance_problem(campaign: DistanceCampaign, spec: ModelSpec | str = DEFAULT_MODEL,
                           runs=None) -> DistanceProblem:
    """Resolve a model variant against a distance-time campaign (``runs``: the run ids to fit,
    default all)."""
    spec = load_model_spec(spec) if isinstance(spec, str) else spec
    if spec.air == "measured":
        raise ValueError(f"model {spec.name!r} uses measured air; distance-time records carry no anemometer "
                         "channels")
    model, fixed, free = spec.build(campaign)
    check_speed_domain(model)
    priors = {p: spec.priors.get(p) or default_prior(p, model) for p in free}
    runs = list(campaign.run_ids if runs is None else runs)
    if not runs:
        raise ValueError("no runs to fit")
    v = campaign.vehicle
    groups = {r: g for r, g in campaign.markers.groupby("run", sort=False)}
    missing = [r for r in runs if r not in groups]
    if missing:
        raise ValueError(f"runs {missing} are not in the campaign")
    k = max(len(groups[r]) for r in runs)
    n = len(runs)
    dist_m = np.zeros((n, k))
    obs = np.zeros((n, k - 1))
    mask = np.zeros((n, k - 1), bool)
    mass, temp, rho, direction, v0 = (np.zeros(n) for _ in range(5))
    for i, r in enumerate(runs):
        g = groups[r]
        x, t = g["distance_m"].to_numpy(float), g["time_s"].to_numpy(float)
        m = len(x)
        dist_m[i, :m] = x - x[0]
        dist_m[i, m:] = x[-1] - x[0]
        obs[i, :m - 1] = np.diff(t)
        mask[i, :m - 1] = True
        mass[i] = float(g["mass_kg"].iloc[0]) if "mass_kg" in g else v.mass_kg
        temp[i] = float(g["temperature_k"].iloc[0]) if "temperature_k" in g else config.REFERENCE_TEMPERATURE_K
        rho[i] = air_density(g.iloc[:1])[0]   # the ambient columns are constant within a run
        direction[i] = float(g["direction"].iloc[0]) if "direction" in g else 1.0
        v0[i] = _v0_guess(x, t)
    me = v.effective_mass_kg + (mass - v.mass_kg)   # the rotating inertia does not change with the load
    markers = MarkerRuns(
        distance_m=jnp.asarray(dist_m), mask=jnp.asarray(np.concatenate([np.ones((n, 1), bool), mask], axis=1)),
        direction=jnp.asarray(direction), air_density_kgpm3=jnp.asarray(rho),
        temperature_k=jnp.asarray(temp), mass_kg=jnp.asarray(mass), effective_mass_kg=jnp.asarray(me),
        frontal_area_m2=jnp.full(n, v.frontal_area_m2))
    initial = {p: float(spec.initial.get(p, priors[p].center)) for p in free}
    initial.update({name: config.DISTANCE_NOISE_PRIORS[name] for name in NOISE_SITES})
    initial["v0_mps"] = jnp.asarray(v0)
    return DistanceProblem(
        spec=spec, model=model, fixed={kk: float(vv) for kk, vv in fixed.items()}, free=tuple(free), priors=priors,
        runs=markers, observed_segments_s=jnp.asarray(obs), mask=jnp.asarray(mask), run_ids=tuple(runs),
        directions=jnp.asarray(direction), run_masses_kg=jnp.asarray(mass), effective_mass_kg=jnp.asarray(me),
        v0_guess_mps=jnp.asarray(v0), mass_kg=float(v.mass_kg), frontal_area_m2=float(v.frontal_area_m2),
        initial=initial)


def distance_time_model(problem: DistanceProblem) -> None:
    """The numpyro model of distance-time records (module docstring); contract names for the
    coefficients, ``v0_mps`` [run] for the speeds at the first markers."""
    sample = sample_coefficients_and_noise(problem, config.DISTANCE_NOISE_PRIORS, config.DISTANCE_NOISE_PRIOR_SHAPES)
    sample["v0_mps"] = numpyro.sample(
        "v0_mps", dist.Normal(problem.v0_guess_mps, config.DISTANCE_V0_PRIOR_SD_MPS).to_event(1))
    numpyro.factor("segment_loglik", run_log_likelihood(problem, sample).sum())


def fit_distances_nuts(campaign: DistanceCampaign, spec: ModelSpec | str = DEFAULT_MODEL, *,
                       sampler: config.SamplerConfig = config.DEFAULT_SAMPLER, runs=None):
    """MAP, Laplace whitening and NUTS (:mod:`~bayes_roadload.inference.nuts`) on the
    distance-time model.  Returns a :class:`~bayes_roadload.inference.nuts.NutsFit`."""
    problem = build_distance_problem(campaign, spec, runs=runs)
    return sample_problem(problem, problem.initial, sampler, campaign.truth)


distance_report = interval_report
"""The report of a distance-time fit: that of the interval fit
(:func:`~bayes_roadload.inference.intervals.interval_report`; ``posterior.nc`` with observed and
replicated ``segment_time_s`` and per-run ``v0_mps``, ``runs_summary.csv`` with each run's mass,
speed at the first marker and observed total time against its 95 % predictive interval)."""
