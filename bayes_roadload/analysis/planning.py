"""Test planning: how many pairs of coastdowns until a quantity is known to a target.

The question of a test engineer -- "how many more pairs until C_D0 is known to 1 % and the road
load at 50 mph to 0.5 %, at 95 %?" -- is answered from the posterior by simulation, not by a
normal-theory formula:

1. **A population.**  From a fitted campaign (:func:`population_from_fit`): draws of the
   population-mean coefficients, of the run-to-run spreads ``tau`` of the hierarchical model
   and of the noise levels.  Or from a pilot given as summary numbers
   (:func:`population_from_pilot`: means and between-pair spreads of ``n0`` pairs, the
   thesis' table 8.3): the spreads' own uncertainty is kept (sigma^2 = (n0 - 1) s^2 / chi^2
   with n0 - 1 degrees of freedom, the Jeffreys posterior), where the thesis took the sample
   spread for the population's (section 8.2).
2. **Future campaigns** of n pairs (:class:`FutureCampaign`): one population draw, each run's
   coefficients around its means with the spreads ``tau``, the measured conditions of a pair of
   observed runs resampled (time grid, wind reconstructed from the logged airspeed and yaw,
   density, direction), the coastdown integrated through that wind, speed noise (white
   ``sigma`` plus the integrated random walk ``q`` of the model) added.
3. **Cheap refits.**  Each future campaign is fitted with MAP + Laplace
   (:func:`~bayes_roadload.inference.laplace.fit_laplace`: one compilation per campaign size)
   through the batch door (:func:`~bayes_roadload.analysis.batch.run_batch`, ``method=
   "laplace"``), with the model the engineer will use (e.g. a constrained one).  The Laplace
   intervals are checked against NUTS on the same campaigns at two sizes
   (:func:`nuts_check_jobs`, ``benchmarks/planning_study.py``).
4. **Assurance.**  For each target quantity and n: the distribution of the 95 % interval
   half-width over the future campaigns, and the assurance P(half-width <= target)
   (:func:`plan_table`); the recommendation is the smallest n with assurance >= 0.8
   (:func:`recommend`, configurable).

Half-widths are half the equal-tailed interval, in the target's units: percent of the
posterior mean for relative targets (``CD0=1%``), SI units otherwise (``F50_N=2``).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import re
from dataclasses import dataclass
from pathlib import PurePath
from typing import Any, Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from .. import config
from ..data.campaign import Campaign
from ..physics import integrate_batch
from .batch import FitJob, interval_key, quantile_key, successful

log = logging.getLogger(__name__)

QUANTITY_UNITS: dict[str, str] = {**config.PARAMETER_UNITS, "F50_N": "N", "F50_tyre_N": "N", "F0_N": "N",
                                  "F2_N_per_kph2": "N/(km/h)^2"}
"""Units of the quantities a planning target may name (absolute targets are in these units)."""

PLAN_QUANTITIES = ("AD", "BD", "CD0", "KD", "At", "Bt", "Ct", "F50_N", "F50_tyre_N", "F0_N", "F2_N_per_kph2")
"""Quantities a target may name: coefficients (when the fitted model frees them) and road-load
figures at reference conditions (:data:`~bayes_roadload.inference.results.DERIVED`)."""

PLAN_DERIVED = ("F50_N", "F50_tyre_N", "F0_N", "F2_N_per_kph2")


# --------------------------------------------------------------------------- targets

@dataclass(frozen=True)
class Target:
    """A precision target: the half-width of the ``confidence`` interval of ``quantity`` at most
    ``value`` -- percent of the posterior mean when ``relative``, else in the quantity's SI
    unit."""

    quantity: str
    value: float
    relative: bool = True

    @classmethod
    def parse(cls, text: str) -> "Target":
        """``"CD0=1%"`` (relative) or ``"F50_N=2"`` (absolute, SI units)."""
        m = re.fullmatch(r"\s*([A-Za-z0-9_]+)\s*=\s*([0-9.eE+-]+)\s*(%?)\s*", text)
        if not m:
            raise ValueError(f"target {text!r}: write QUANTITY=VALUE% (relative) or QUANTITY=VALUE (SI units), "
                             "e.g. CD0=1% or F50_N=2")
        name, value, pct = m.group(1), float(m.group(2)), bool(m.group(3))
        if name not in PLAN_QUANTITIES:
            raise ValueError(f"target {text!r}: unknown quantity {name!r}; one of {', '.join(PLAN_QUANTITIES)}")
        if not value > 0:
            raise ValueError(f"target {text!r}: the half-width must be positive")
        return cls(name, value, pct)

    @property
    def unit(self) -> str:
        return "%" if self.relative else QUANTITY_UNITS.get(self.quantity, "SI")

    def __str__(self) -> str:
        return f"{self.quantity}={self.value:g}{'%' if self.relative else ''}"


# --------------------------------------------------------------------------- population

@dataclass(frozen=True, eq=False)
class Population:
    """What a future campaign is drawn from.

    Attributes
    ----------
    model : model variant (``models/*.toml`` name or path) whose drag model generates the runs;
        its free parameters are those of ``means``.
    means : free parameter -> [S] draws of the population mean (SI).
    tau : coefficient -> [S] draws of its run-to-run spread (hierarchical; empty for none).
    sigma_mps, q_mps_per_sqrt_s : [S] draws of the white speed noise and of the integrated noise.
    conditions : the observed campaign whose pairs' conditions are resampled.
    source : a description (for reports).
    """

    model: str
    means: Mapping[str, np.ndarray]
    tau: Mapping[str, np.ndarray]
    sigma_mps: np.ndarray
    q_mps_per_sqrt_s: np.ndarray
    conditions: Campaign
    source: str = ""

    @property
    def n_draws(self) -> int:
        return int(np.size(self.sigma_mps))

    def mean_values(self) -> dict[str, float]:
        """Posterior means of the population means."""
        return {k: float(np.mean(v)) for k, v in self.means.items()}

    def start_values(self) -> dict[str, float]:
        """The refits' start (:func:`~bayes_roadload.inference.nuts.initial_values`): the
        posterior means of the population means, and the medians of the integrated noise's
        intensity and of the run-to-run spreads where positive."""
        start = self.mean_values()
        noise = {"q_mps_per_sqrt_s": self.q_mps_per_sqrt_s, **{f"tau_{k}": v for k, v in self.tau.items()}}
        start.update({k: float(np.median(v)) for k, v in noise.items() if float(np.median(v)) > 0.0})
        return start

    @property
    def pooling(self) -> str:
        """How future campaigns are refitted: hierarchical when runs vary."""
        return "hierarchical" if self.tau else "pooled"


def _flat(x) -> np.ndarray:
    x = np.asarray(x, float)
    return x.reshape((-1,) + x.shape[2:])


def _thin(n: int, max_draws: int) -> np.ndarray:
    return np.unique(np.linspace(0, n - 1, min(n, max_draws)).astype(int))


def population_from_samples(samples: Mapping[str, Any], free: Sequence[str], model: str, conditions: Campaign, *,
                            max_draws: int = 1000, source: str = "") -> Population:
    """A population from posterior draws ([chain, draw, ...] arrays by site name): population
    means of ``free``, spreads ``tau_*`` when present, ``sigma_mps`` averaged over runs,
    ``q_mps_per_sqrt_s`` (zero when the fit had white noise)."""
    n = _flat(samples[free[0]]).shape[0]
    keep = _thin(n, max_draws)
    means = {k: _flat(samples[k])[keep] for k in free}
    tau = {k[4:]: _flat(v)[keep] for k, v in samples.items() if k.startswith("tau_")}
    sigma = _flat(samples["sigma_mps"])
    sigma = (sigma.mean(axis=1) if sigma.ndim > 1 else sigma)[keep]
    q = _flat(samples["q_mps_per_sqrt_s"])[keep] if "q_mps_per_sqrt_s" in samples else np.zeros(keep.size)
    return Population(model=model, means=means, tau=tau, sigma_mps=sigma, q_mps_per_sqrt_s=q,
                      conditions=conditions, source=source)


def population_from_fit(fit, campaign: Campaign, *, max_draws: int = 1000) -> Population:
    """A population from a NUTS fit (:class:`~bayes_roadload.inference.nuts.NutsFit`) of
    ``campaign``; hierarchical fits give the run-to-run spreads."""
    p = fit.problem
    return population_from_samples(fit.samples, p.free, p.spec.name, campaign, max_draws=max_draws,
                                   source=f"{p.pooling} {p.spec.name} fit of {p.n_runs} runs")


def population_from_pilot(means: Mapping[str, float], spreads_pct: Mapping[str, float], pilot_pairs: int,
                          conditions: Campaign, model: str = "three_term", *, draws: int = 1000, seed: int = 0,
                          noise: Mapping[str, float] | None = None) -> Population:
    """A population from a pilot given as summary numbers.

    Parameters
    ----------
    means : free parameter -> pilot mean (SI), e.g. table 8.3's A_D, B_D, C_D0.
    spreads_pct : coefficient -> between-pair standard deviation in % of its mean (table 8.3:
        4.3, 23.1, 4.3).  Coefficients of :data:`~bayes_roadload.inference.bayes.
        HIERARCHICAL_PARAMETERS` vary from run to run; others (K_D) are not given a spread:
        their scatter between pairs is estimation noise, which the simulation reproduces from
        the conditions.
    pilot_pairs : the pilot's number of pairs n0.
    conditions : campaign whose pairs' conditions (wind, speeds, density) are resampled.
    model : model variant generating the runs (its free parameters must be in ``means``).
    noise : ``sigma_mps`` and ``q_mps_per_sqrt_s`` of the future speed traces; default: the
        MAP of a pooled Laplace fit of ``conditions``.

    The population standard deviation of a pair's coefficient is drawn from its posterior given
    the pilot, sigma^2 = (n0 - 1) s^2 / chi^2_{n0 - 1} (Jeffreys prior); a run's spread is
    sqrt(2) sigma (a pair averages two runs).  The population means are drawn around the pilot
    means with standard deviation sigma / sqrt(n0).
    """
    from ..inference.bayes import HIERARCHICAL_PARAMETERS
    from ..inference.spec import load_model_spec

    spec = load_model_spec(model)
    missing = [k for k in spec.free if k not in means]
    if missing:
        raise ValueError(f"model {model!r} frees {missing}: give their pilot means")
    if pilot_pairs < 2:
        raise ValueError("a pilot of one pair has no between-pair spread: give at least two pairs")
    rng = np.random.default_rng(seed)
    out_means, tau = {}, {}
    for k in spec.free:
        m = float(means[k])
        s_pct = spreads_pct.get(k) if k in HIERARCHICAL_PARAMETERS else None
        if s_pct is None:
            out_means[k] = np.full(draws, m)
            continue
        sigma_pair = abs(m) * s_pct / 100.0 * np.sqrt((pilot_pairs - 1) / rng.chisquare(pilot_pairs - 1, draws))
        out_means[k] = m + sigma_pair / math.sqrt(pilot_pairs) * rng.standard_normal(draws)
        tau[k] = math.sqrt(2.0) * sigma_pair
    if noise is None:
        from ..inference.laplace import fit_laplace

        ref = fit_laplace(conditions, model, pooling="pooled", draws=10).map.constrained
        noise = {"sigma_mps": float(np.mean(ref["sigma_mps"])),
                 "q_mps_per_sqrt_s": float(ref.get("q_mps_per_sqrt_s", 0.0))}
    return Population(model=model, means=out_means, tau=tau, sigma_mps=np.full(draws, noise["sigma_mps"]),
                      q_mps_per_sqrt_s=np.full(draws, noise["q_mps_per_sqrt_s"]), conditions=conditions,
                      source=f"pilot of {pilot_pairs} pairs ({', '.join(f'{k} {v:g} %' for k, v in spreads_pct.items())})")


# --------------------------------------------------------------------------- future campaigns

@functools.partial(jax.jit, static_argnums=0)
def _integrated_speed(model, params, batch, v0_mps):
    """:func:`~bayes_roadload.physics.integrate_batch`'s speeds as one compiled program per
    model and batch shape.  Called eagerly, the vmapped integration runs (and compiles) its
    operations one by one: about 100 small programs, 15 s, for the first campaign of a size, and
    again for later ones whenever JAX's caches had let them go (docs/planning.md section 7)."""
    return integrate_batch(model, params, batch, v0_mps)[0]


def _pad_length(c: Campaign) -> int:
    return int(c.runs.groupby("run", sort=False).size().max())


def simulate_future(population: Population, pairs: int, seed: int) -> Campaign:
    """One future campaign of ``pairs`` opposite-direction pairs drawn from ``population``
    (module docstring, step 2).

    Every run is integrated (:func:`~bayes_roadload.physics.integrate_batch`) on the time grid
    of the observed run whose conditions it takes, from that run's first speed, through the
    observed wind: along-track ``a cos(psi) - v`` and cross ``a sin(psi)`` from the logged
    airspeed ``a``, yaw ``psi`` and speed ``v`` of the observed run; the airspeed and yaw
    channels are recomputed from the simulated speed (three fixed-point passes; the yaw held
    within +-``config.MAX_LOGGED_YAW_RAD``, the simulator's vane limit: a strong tail wind near
    the stop speed can turn the relative air round).  The campaign's
    ``truth`` is the population draw's means; ``meta["pad_to_samples"]`` is the longest observed
    run, so that every future campaign of ``pairs`` pairs has one shape.
    """
    from ..inference.spec import load_model_spec

    if pairs < 1:
        raise ValueError("a future campaign needs at least one pair")
    obs = population.conditions
    obs_pairs = obs.pairs()
    if not obs_pairs:
        raise ValueError("the conditions campaign has no opposite-direction pairs (`pair` column)")
    rng = np.random.default_rng(seed)
    s = int(rng.integers(population.n_draws))
    chosen = rng.integers(len(obs_pairs), size=pairs)
    frames, params = [], []
    spec = load_model_spec(population.model)
    model, fixed, free = spec.build(obs)
    for k, idx in enumerate(chosen):
        for rid in obs_pairs[idx]:
            g = obs.runs[obs.runs["run"] == rid].copy()
            g["run"] = f"{k + 1}{'ab'[len(frames) % 2]}"
            g["pair"] = k + 1
            frames.append(g)
            p = {n: float(population.means[n][s]) for n in free}
            for n, t in population.tau.items():
                p[n] = p[n] + float(t[s]) * rng.standard_normal()
            params.append(p)
    runs = pd.concat(frames, ignore_index=True)
    pad = _pad_length(obs)
    future = dataclasses.replace(obs, runs=runs, truth={n: float(population.means[n][s]) for n in free},
                                 meta={"pad_to_samples": pad, "pairs": pairs, "seed": seed, "population_draw": s})
    batch, run_ids = future.to_batch()
    stacked = {n: jnp.asarray([p[n] for p in params]) for n in free}
    v_obs = np.asarray(batch.speed_mps)
    has_air = "airspeed_mps" in runs and "yaw_rad" in runs
    if has_air:
        a, psi = np.asarray(batch.airspeed_mps), np.asarray(batch.yaw_rad)
        along, cross = a * np.cos(psi) - v_obs, a * np.sin(psi)
    v = v_obs
    for _ in range(3 if has_air else 1):
        if has_air:
            rel = v + along
            yaw = np.clip(np.arctan2(cross, rel), -config.MAX_LOGGED_YAW_RAD, config.MAX_LOGGED_YAW_RAD)
            batch = batch._replace(airspeed_mps=jnp.asarray(np.hypot(rel, cross)), yaw_rad=jnp.asarray(yaw))
        v = np.asarray(_integrated_speed(model, dict(fixed, **stacked), batch, jnp.asarray(v_obs[:, 0])))
    t = np.asarray(batch.time_s)
    dt = np.diff(t, axis=1, prepend=t[:, :1])
    walk = np.cumsum(population.q_mps_per_sqrt_s[s] * np.sqrt(dt) * rng.standard_normal(v.shape), axis=1)
    speed = v + walk + population.sigma_mps[s] * rng.standard_normal(v.shape)
    mask = np.asarray(batch.mask)
    for i, rid in enumerate(run_ids):
        rows = runs.index[runs["run"] == rid]
        runs.loc[rows, "speed_mps"] = speed[i][mask[i]]
        if has_air:
            yaw_i = np.asarray(batch.yaw_rad)[i][mask[i]]
            # the batch's airspeed carries the stated yaw calibration (Campaign.to_batch): undone,
            # so that the readings written back are corrected once when fitted
            runs.loc[rows, "airspeed_mps"] = future.anemometer.yaw_uncorrected_airspeed(
                np.asarray(batch.airspeed_mps)[i][mask[i]], yaw_i)
            runs.loc[rows, "yaw_rad"] = yaw_i
    return dataclasses.replace(future, runs=runs)


@dataclass(frozen=True)
class FutureCampaign:
    """Picklable recipe of a future campaign for the batch door (:func:`simulate_future`)."""

    population: Population
    pairs: int
    seed: int

    def __call__(self) -> Campaign:
        return simulate_future(self.population, self.pairs, self.seed)


# --------------------------------------------------------------------------- jobs and tables

def plan_jobs(population: Population, pairs: Sequence[int] = config.PLAN_PAIRS, *,
              simulations: int = config.PLAN_SIMULATIONS,
              model: str | None = None, confidence: float = config.PLAN_CONFIDENCE, seed: int = 0,
              method: str = "laplace", type_b: bool = True,
              tags: Mapping[str, Any] | None = None, first: int = 0) -> list[FitJob]:
    """One fit job per future campaign: simulations ``first`` .. ``simulations - 1`` of each size
    in ``pairs``, refitted with ``model`` (default: the population's) by ``method`` ("laplace",
    or "nuts" to confirm the Laplace intervals).  Campaign seeds depend on the size and the
    simulation's index only, so arms (methods, models) compare the same campaigns and a top-up
    (``first`` > 0, :func:`undecided_sizes`) adds new ones.  With ``type_b`` (default, as
    ``fit``) the refits' intervals carry the Type B uncertainty of the declared values and
    instruments (:mod:`.budget`): the intervals the engineer's own fit will report."""
    model = model or population.model
    label = PurePath(str(model)).stem  # a model file's path labels the jobs by the file's name
    start = population.start_values()
    jobs = []
    for n in pairs:
        for k in range(first, simulations):
            cseed = seed * 1_000_003 + 1009 * int(n) + k
            jobs.append(FitJob(f"plan-{label}-{method}-n{n}-{k}", FutureCampaign(population, int(n), cseed),
                               model=model, pooling=population.pooling, method=method,
                               levels=(confidence,), derived=PLAN_DERIVED, start=start, type_b=type_b,
                               tags={"n_pairs": int(n), "simulation": k, "fit_model": model, **(tags or {})}))
    return jobs


def half_widths(records: pd.DataFrame, quantity: str, confidence: float = 0.95, relative: bool = True) -> pd.Series:
    """Half-width of each record's central ``confidence`` interval of ``quantity``: percent of the
    posterior mean when ``relative``, else in the quantity's units."""
    lo = records[f"{quantity}_{quantile_key((1 - confidence) / 2)}"].astype(float)
    hi = records[f"{quantity}_{quantile_key((1 + confidence) / 2)}"].astype(float)
    half = (hi - lo) / 2.0
    return 100.0 * half / records[f"{quantity}_mean"].astype(float).abs() if relative else half


def plan_table(records: pd.DataFrame, targets: Sequence[Target], confidence: float = config.PLAN_CONFIDENCE,
               by: Sequence[str] = ()) -> pd.DataFrame:
    """Half-width distribution and assurance against the number of pairs.

    Returns one row per (``by`` groups,) target quantity and ``n_pairs``: ``quantity,
    n_pairs, median_half_width, assurance`` (the contract columns of ``plan.csv``), then
    ``target, unit, q10_half_width, q90_half_width, n_sims`` (refits without an error),
    ``bias`` and ``bias_pct`` (mean of posterior mean minus truth over the simulations: what a
    constrained model costs), ``rmse_pct``, ``gate_pass_frac`` (refits passing their gate: the
    MAP converged and the importance weights are usable; the others are kept, their intervals
    being the best available, and the fraction says how far to trust the row) and
    ``coverage`` (of the truth by the intervals)."""
    ok = successful(records)
    rows = []
    groups = ok.groupby(list(by) + ["n_pairs"], sort=True) if by else ok.groupby("n_pairs", sort=True)
    for key, g in groups:
        key = key if isinstance(key, tuple) else (key,)
        for t in targets:
            if f"{t.quantity}_mean" not in g:
                continue
            hw = half_widths(g, t.quantity, confidence, t.relative).dropna()
            if hw.empty:
                continue
            err = g[f"{t.quantity}_mean"].astype(float) - g[f"{t.quantity}_truth"].astype(float)
            truth = g[f"{t.quantity}_truth"].astype(float).abs()
            rows.append({**dict(zip(list(by) + ["n_pairs"], key)), "quantity": t.quantity,
                         "median_half_width": float(hw.median()), "assurance": float((hw <= t.value).mean()),
                         "target": t.value, "unit": t.unit, "q10_half_width": float(hw.quantile(0.1)),
                         "q90_half_width": float(hw.quantile(0.9)), "n_sims": int(hw.size),
                         "bias": float(err.mean()), "bias_pct": float(100.0 * (err / truth).mean()),
                         "rmse_pct": float(100.0 * np.sqrt(((err / truth) ** 2).mean())),
                         "gate_pass_frac": float(g["gate_pass"].astype(bool).mean()) if "gate_pass" in g else math.nan,
                         "coverage": float(g[f"{t.quantity}_{interval_key(confidence)}"].astype(bool).mean())
                         if f"{t.quantity}_{interval_key(confidence)}" in g else math.nan})
    cols = list(by) + ["quantity", "n_pairs", "median_half_width", "assurance"]
    out = pd.DataFrame(rows)
    if out.empty:
        return out
    return out[cols + [c for c in out.columns if c not in cols]]


FLOOR_FIT_DRAWS = 2
"""Draws of the Gaussian approximation of the floor's MAP fit (:func:`type_b_floors` reads its
mode only)."""


def type_b_floors(population: Population, targets: Sequence[Target], confidence: float = config.PLAN_CONFIDENCE,
                  model: str | None = None) -> pd.DataFrame:
    """The half-width that the Type B uncertainty alone gives each target's quantity, whatever
    the number of pairs: the declared values' and instruments' standard uncertainties u_s
    (``[uncertainty]``; SAE J1263 / J2263 defaults) do not shrink with more runs, so the
    ``confidence`` interval of a fit carrying them (:mod:`.budget`: ``sum_s c_s delta_s``
    added to every draw, delta_s ~ N(0, u_s^2)) is never narrower than
    z sqrt(sum_s (c_s u_s)^2), z the normal quantile of (1 + confidence) / 2.  The
    sources and sensitivities c_s are those a refit carries (:func:`plan_jobs`, ``type_b``): of
    the conditions campaign fitted with ``model`` (default: the population's; the refits'
    model) as the refits are, MAP + Laplace from the population's start
    (:func:`~bayes_roadload.inference.laplace.fit_laplace`, no importance draws), taken at that
    fit's posterior mode (:func:`~bayes_roadload.analysis.budget.type_b_sensitivities` with
    ``fit``), so that the model file's constants with an ``uncertainty`` (a shape's time
    constant, the yaw drag's levelling) count as they do in every refit; should that fit fail
    (logged), the least-squares step, which has no model constants.  A relative target divides
    by the quantity at the population's mean coefficients.

    Returns one row per target: ``quantity, target, unit, type_b_half_width`` (the target's
    unit), ``reachable`` (the floor is below the target), ``main_source`` and
    ``main_source_share`` (of the Type B variance)."""
    from statistics import NormalDist

    from ..inference.bayes import build_problem
    from ..inference.laplace import fit_laplace
    from ..inference.results import truth_derived
    from .budget import BUDGET_QUANTITIES, type_b_sensitivities

    model = model or population.model
    quantities = [t.quantity for t in targets if t.quantity in BUDGET_QUANTITIES]
    try:
        fit = fit_laplace(population.conditions, model, pooling=population.pooling, importance=False,
                          draws=FLOOR_FIT_DRAWS, start=population.start_values())
    except Exception as e:  # noqa: BLE001 - the floor falls back to the least-squares step, the plan goes on
        log.warning("Type B floor: the MAP of the conditions campaign failed (%s: %s); the least-squares step "
                    "instead, without the model's constants", type(e).__name__, e)
        fit = None
    typeb = type_b_sensitivities(population.conditions, model, quantities, fit=fit)
    values = population.mean_values()
    values.update(truth_derived(build_problem(population.conditions, population.model, pooling="pooled"), values))
    z = NormalDist().inv_cdf((1.0 + confidence) / 2.0)
    rows = []
    for t in targets:
        parts = typeb.variances(t.quantity)
        var = float(sum(parts.values()))
        half = z * math.sqrt(var)
        value = values.get(t.quantity, math.nan)
        floor = 100.0 * half / abs(value) if t.relative else half
        main = max(parts, key=parts.get) if var > 0 else ""
        rows.append({"quantity": t.quantity, "target": t.value, "unit": t.unit, "type_b_half_width": floor,
                     "reachable": not floor >= t.value, "main_source": main,
                     "main_source_share": parts[main] / var if var > 0 else math.nan})
    return pd.DataFrame(rows)


def floor_hint(floors: pd.DataFrame, model_constants: Sequence[str]) -> str:
    """What lowers the floors of the unreachable targets in ``floors`` (:func:`type_b_floors`):
    the standard uncertainty of each one's main source, in ``vehicle.toml`` ``[uncertainty]``
    for a campaign's source, in the model file for one of ``model_constants`` (the sources the
    model file gives an ``uncertainty``)."""
    mains = set(floors.loc[~floors["reachable"].astype(bool), "main_source"].dropna()) - {""}
    constants = mains & set(model_constants)
    where = []
    if mains - constants:
        where.append(f"vehicle.toml [uncertainty] for {', '.join(sorted(mains - constants))} (e.g. a fresh calibration)")
    if constants:
        where.append(f"the model file's [parameters.NAME] uncertainty for {', '.join(sorted(constants))} (a constant "
                     "of the model's physics: a measurement of it, or a model that fits it)")
    return ("a smaller standard uncertainty of the main source lowers the floor"
            + (f": {'; '.join(where)}" if where else "") + "; `plan --no-type-b` plans the data's share alone")


def refit_work(job: FitJob) -> float:
    """A planning refit's share of the work, for the time left of its progress bar: one unit
    plus one per pair (measured on a 12-pair hierarchical population, one worker: 2 s at 1 pair,
    12 s at 12, 30 s at 24; docs/planning.md section 7)."""
    return 1.0 + float(job.tags.get("n_pairs", 0))


def refit_size(job: FitJob) -> int:
    """A planning refit's campaign size (pairs): the refits of one size share their compiled
    programs (:func:`~bayes_roadload.analysis.batch.batch_map`'s ``lead``)."""
    return int(job.tags["n_pairs"])


def undecided_sizes(table: pd.DataFrame, assurance: float = config.PLAN_ASSURANCE) -> list[int]:
    """The sizes (``n_pairs``) at which some target is still undecided: the Wilson 95 % interval
    of its assurance (``assurance`` x ``n_sims`` refits meeting the target) contains the required
    ``assurance``.  At a decided size more simulations cannot change whether the target is
    reached there, beyond the interval's 5 %; ``plan`` tops up only the undecided ones."""
    from .batch import _wilson

    out = set()
    for _, r in table.iterrows():
        n = int(r["n_sims"])
        lo, hi = _wilson(int(round(float(r["assurance"]) * n)), n)
        if n == 0 or lo < assurance <= hi:
            out.add(int(r["n_pairs"]))
    return sorted(out)


def sizes_to_fit(table: pd.DataFrame, pairs: Sequence[int], quantities: Sequence[str],
                 assurance: float = config.PLAN_ASSURANCE, simulated: Sequence[int] = ()) -> list[int]:
    """The sizes (of ``pairs``) to simulate next so that each quantity's smallest size meeting
    its target is located by bisection, taking the assurance as increasing with the number of
    pairs.  ``table`` (:func:`plan_table`, possibly empty) holds the sizes simulated so far.

    For each quantity, P is the smallest simulated size whose assurance reaches ``assurance``
    (none: beyond the largest size) and F the largest simulated size below P that does not;
    the answer lies in (F, P].  While sizes lie strictly between F and P, the middle one of
    them (the lower of two: a refit costs more the more pairs it has) is returned, so that
    both outcomes at it leave at most half of them; when none do, the quantity is located:
    its answer is P, the size :func:`recommend` reads (or "not reached", the largest size
    having been simulated).  Sizes
    above P and below F are never needed: at 9 sizes a quantity takes at most 4 of them
    instead of 9.  A quantity absent from the table so far (nothing simulated, or not a
    quantity of the model) starts from the whole range.  Sizes in ``simulated`` are not
    returned again (a size whose refits all raised has no row), so the sequence ends.  Returns
    the union, sorted."""
    sizes = sorted(set(int(n) for n in pairs))
    out = set()
    for q in quantities:
        rows = table[table["quantity"] == q] if not table.empty else table
        reached = {int(n): float(a) >= assurance for n, a in zip(rows.get("n_pairs", []), rows.get("assurance", []))}
        passing = [i for i, n in enumerate(sizes) if reached.get(n) is True]
        hi = passing[0] if passing else len(sizes)          # index of P (len: beyond the range)
        failing = [i for i, n in enumerate(sizes[:hi]) if reached.get(n) is False]
        lo = failing[-1] + 1 if failing else 0              # first index above F
        if lo < hi:
            out.add(sizes[(lo + hi - 1) // 2])
    return sorted(out - {int(n) for n in simulated})


def confirm_table(laplace: pd.DataFrame, nuts: pd.DataFrame, targets: Sequence[Target],
                  confidence: float = config.PLAN_CONFIDENCE,
                  assurance: float = config.PLAN_ASSURANCE) -> pd.DataFrame:
    """The MAP + Laplace refits checked by NUTS refits of the same future campaigns (the same
    ``n_pairs`` and ``simulation``, hence the same seed: :func:`plan_jobs`).

    Returns one row per target quantity and ``n_pairs`` of ``nuts``: ``campaigns`` (refitted
    without error by both), ``median_ratio`` (NUTS / Laplace half-width of each campaign, the
    median), ``laplace_assurance`` and ``nuts_assurance`` over those campaigns (the share whose
    half-width meets the target), the Wilson 95 % interval of the latter (``nuts_assurance_low``,
    ``nuts_assurance_high``), ``nuts_gate_pass_frac`` and ``optimistic``: the interval lies
    below ``assurance``, so by the posterior itself the size does not meet the target."""
    from .batch import _wilson

    lap, nut = successful(laplace), successful(nuts)
    rows = []
    for n, g in nut.groupby("n_pairs", sort=True):
        g = g.drop_duplicates("simulation").set_index("simulation")
        ref = lap[lap["n_pairs"] == n].drop_duplicates("simulation").set_index("simulation")
        common = g.index.intersection(ref.index)
        for t in targets:
            if f"{t.quantity}_mean" not in g or f"{t.quantity}_mean" not in ref:
                continue
            hn = half_widths(g.loc[common], t.quantity, confidence, t.relative)
            hl = half_widths(ref.loc[common], t.quantity, confidence, t.relative)
            ok = (hn.notna() & hl.notna()).to_numpy()
            m = int(ok.sum())
            if m == 0:
                continue
            met = int((hn[ok] <= t.value).sum())
            lo, hi = _wilson(met, m)
            rows.append({"quantity": t.quantity, "n_pairs": int(n), "campaigns": m,
                         "median_ratio": float(np.median(hn[ok].to_numpy() / hl[ok].to_numpy())),
                         "laplace_assurance": float((hl[ok] <= t.value).mean()), "nuts_assurance": met / m,
                         "nuts_assurance_low": lo, "nuts_assurance_high": hi,
                         "nuts_gate_pass_frac": float(g.loc[common, "gate_pass"].astype(bool).mean())
                         if "gate_pass" in g else math.nan,
                         "optimistic": bool(hi < assurance)})
    return pd.DataFrame(rows, columns=["quantity", "n_pairs", "campaigns", "median_ratio", "laplace_assurance",
                                       "nuts_assurance", "nuts_assurance_low", "nuts_assurance_high",
                                       "nuts_gate_pass_frac", "optimistic"])


def recommend(table: pd.DataFrame, assurance: float = config.PLAN_ASSURANCE, by: Sequence[str] = (),
              floors: pd.DataFrame | None = None) -> pd.DataFrame:
    """The smallest ``n_pairs`` whose assurance reaches ``assurance``, per (group and) quantity;
    ``n_pairs`` is None (and ``reached`` False) when no simulated size reaches it.  With
    ``floors`` (:func:`type_b_floors`): the columns ``type_b_half_width`` and ``reachable``,
    and a target whose floor is not below it is not reached at any size (also when it was not
    simulated: ``max_pairs_simulated`` 0)."""
    rows = []
    keys = list(by) + ["quantity"]
    for key, g in (table.groupby(keys, sort=False) if not table.empty else []):
        key = key if isinstance(key, tuple) else (key,)
        g = g.sort_values("n_pairs")
        hit = g[g["assurance"] >= assurance]
        n = int(hit["n_pairs"].iloc[0]) if len(hit) else None
        rows.append({**dict(zip(keys, key)), "target": float(g["target"].iloc[0]), "unit": g["unit"].iloc[0],
                     "n_pairs": n, "reached": n is not None, "assurance_required": assurance,
                     "max_pairs_simulated": int(g["n_pairs"].max())})
    out = pd.DataFrame(rows, columns=keys + ["target", "unit", "n_pairs", "reached", "assurance_required",
                                             "max_pairs_simulated"])
    if floors is None or by:
        return out
    missing = floors[~floors["quantity"].isin(out["quantity"])]
    out = pd.concat([out, pd.DataFrame({"quantity": missing["quantity"], "target": missing["target"],
                                        "unit": missing["unit"], "n_pairs": None, "reached": False,
                                        "assurance_required": assurance, "max_pairs_simulated": 0})],
                    ignore_index=True) if len(missing) else out
    out = out.merge(floors[["quantity", "type_b_half_width", "reachable"]], on="quantity", how="left")
    blocked = out["reachable"].eq(False)
    out.loc[blocked, "n_pairs"] = None
    out.loc[blocked, "reached"] = False
    return out


def small_size_caveat(recommendation: pd.DataFrame, pooling: str) -> str:
    """The warning `plan` prints when a hierarchical population's recommendation has answers of
    at most :data:`~bayes_roadload.config.PLAN_SMALL_SIZE_CAVEAT_PAIRS` pairs ("" otherwise)."""
    if pooling != "hierarchical" or recommendation.empty:
        return ""
    small = recommendation[recommendation["reached"].astype(bool)
                           & (recommendation["n_pairs"].astype(float) <= config.PLAN_SMALL_SIZE_CAVEAT_PAIRS)]
    if small.empty:
        return ""
    names = ", ".join(f"{r['quantity']} {int(r['n_pairs'])}" for _, r in small.iterrows())
    return (f"!! optimistic at small sizes ({names} pairs): with run-to-run spreads the MAP + Laplace refits' "
            f"intervals at {config.PLAN_SMALL_SIZE_CAVEAT_PAIRS} pairs or fewer are narrower than NUTS' "
            "(median 0.75 of its half-width at 2 pairs, docs/planning.md section 9); confirm with NUTS refits "
            "or plan one pair more")


def plot_plan(table: pd.DataFrame, targets: Sequence[Target], path, *, assurance: float = config.PLAN_ASSURANCE):
    """Two panels against the number of pairs: the median half-width with its 10-90 % band over
    the simulated campaigns (one line per target, each divided by its target so that 1 is the
    target), and the assurance with the required level."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    for t in targets:
        g = table[table["quantity"] == t.quantity].sort_values("n_pairs")
        if g.empty:
            continue
        line, = ax1.plot(g["n_pairs"], g["median_half_width"] / t.value, "o-", label=str(t))
        ax1.fill_between(g["n_pairs"], g["q10_half_width"] / t.value, g["q90_half_width"] / t.value,
                         color=line.get_color(), alpha=0.15)
        ax2.plot(g["n_pairs"], g["assurance"], "o-", color=line.get_color(), label=str(t))
    ax1.axhline(1.0, color="k", lw=0.8)
    ax1.set(xscale="log", yscale="log", xlabel="pairs of runs", ylabel="half-width / target",
            title="interval half-width (median, 10-90 %)")
    ax2.axhline(assurance, color="k", lw=0.8, ls="--")
    ax2.set(xscale="log", ylim=(-0.02, 1.02), xlabel="pairs of runs", ylabel="P(half-width <= target)",
            title="assurance")
    ticks = sorted(table["n_pairs"].unique()) if not table.empty else []
    for ax in (ax1, ax2):
        ax.set_xticks(ticks)
        ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax1.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------- summary-number replay

def predictive_half_widths(spread_pct: float, pilot_pairs: int, n: int, *, confidence: float = 0.95,
                           simulations: int = 20000, seed: int = 0) -> np.ndarray:
    """[simulations] draws of the half-width (percent) of the ``confidence`` interval of a mean
    from ``n`` future pair estimates, given a pilot's between-pair spread ``spread_pct`` from
    ``pilot_pairs`` pairs (:func:`pilot_summary_half_widths`); infinite for n = 1."""
    from scipy import stats

    rng = np.random.default_rng(seed)
    sigma = spread_pct * np.sqrt((pilot_pairs - 1) / rng.chisquare(pilot_pairs - 1, simulations))
    if n < 2:
        return np.full(simulations, np.inf)
    s_n = sigma * np.sqrt(rng.chisquare(n - 1, simulations) / (n - 1))
    return stats.t.ppf((1 + confidence) / 2, n - 1) * s_n / math.sqrt(n)


def pilot_summary_half_widths(spread_pct: float, pilot_pairs: int, pairs: Sequence[int], *, confidence: float = 0.95,
                              simulations: int = 20000, seed: int = 0) -> pd.DataFrame:
    """Predictive distribution of the half-width (percent) of the ``confidence`` interval of a
    mean from n pair estimates, given a pilot's between-pair spread ``spread_pct`` from
    ``pilot_pairs`` pairs -- at the level of pair estimates only (no campaign simulation).

    sigma^2 is drawn from its Jeffreys posterior given the pilot, a future sample of n pair
    estimates gives s_n, and the interval is t_{n-1} s_n / sqrt(n) (the posterior interval of
    the mean under the Jeffreys prior).  For n = 1 there is no spread to estimate: the
    half-width is infinite.  The thesis' figure (eq. 8.2) is z s / sqrt(n): sample spread taken
    for the population's, normal quantile.  Returns ``n_pairs, thesis_half_width,
    median_half_width, q10_half_width, q90_half_width`` and ``assurance_at_thesis`` (P(half-width
    <= the thesis' figure))."""
    from scipy import stats

    z = stats.norm.ppf((1 + confidence) / 2)
    rows = []
    for n in pairs:
        thesis = z * spread_pct / math.sqrt(n)
        hw = predictive_half_widths(spread_pct, pilot_pairs, int(n), confidence=confidence, simulations=simulations,
                                    seed=seed)
        finite = bool(np.isfinite(hw).all())
        rows.append({"n_pairs": int(n), "thesis_half_width": thesis, "median_half_width": float(np.median(hw)),
                     "q10_half_width": float(np.quantile(hw, 0.1)) if finite else math.inf,
                     "q90_half_width": float(np.quantile(hw, 0.9)) if finite else math.inf,
                     "assurance_at_thesis": float((hw <= thesis).mean())})
    return pd.DataFrame(rows)
