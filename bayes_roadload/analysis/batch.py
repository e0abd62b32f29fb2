"""The one door for studies that fit many campaigns: campaigns in, summaries out.

A study (coverage, planning, sim-to-real) describes each fit as a :class:`FitJob` -- a
picklable recipe for a campaign plus the fit settings -- and hands the list to
:func:`run_batch`.  Every job is run by :func:`run_fit_job`, which returns a small, flat,
picklable record (no draws): posterior mean, sd and equal-tailed interval ends of every free
parameter and of the road load at 50 mph, the truth and whether each interval covers it (for
simulated campaigns), the diagnostic gates and the timings.  :func:`coverage_summary` turns
the records of a simulation study into interval coverage with binomial errors.

Where the jobs run is chosen by one object, the Dask client of :func:`batch_client`:

* ``batch_client(workers=N)``: a ``dask.distributed.LocalCluster`` of ``N`` single-threaded
  worker processes on this machine (``N`` = the usable cores when not given);
* ``batch_client(scheduler="tcp://host:8786")``: any running Dask cluster (its workers must
  have ``bayes_roadload`` installed);
* ``batch_client(workers=1)``: no cluster, the jobs run one after the other in this process
  (the client is ``None``), as :func:`run_batch` does without a client.

:func:`run_batch` (fit jobs, a DataFrame of records) and :func:`batch_map` (any picklable
function over any picklable items) submit every item, show one progress bar with the time
left, and collect the results as they complete; a job that raises becomes a record with
``error`` set and never stops the others.

Example
-------
>>> jobs = [FitJob(f"seed{s}-{noise}", SimulatedCampaign(2, pairs=1, seed=s), model="three_term",
...                noise=noise) for s in range(20) for noise in ("white", "integrated")]  # doctest: +SKIP
>>> with batch_client(workers=2) as client:          # doctest: +SKIP
...     records = run_batch(jobs, client)
>>> coverage_summary(records, by=("noise",))          # doctest: +SKIP

.. note::
   Every :func:`~bayes_roadload.inference.nuts.fit_nuts` call compiles its MAP, warm-up and
   sampling functions afresh (the campaign's data are constants of the compiled code): the
   records' ``time_compile_s`` was 70-90 % of a one-pair fit's wall time while the MAP compiled
   an exact Hessian (before :func:`~bayes_roadload.inference.nuts.fd_hessian`; not re-measured since).  The compiled code
   of finished fits stays in JAX's in-process caches (about 85-165 MB per fit), so
   :func:`run_fit_job` clears those caches once the process holds more than
   :data:`CLEAR_JAX_CACHES_ABOVE_MB`, or more memory mappings than
   :data:`CLEAR_JAX_CACHES_ABOVE_MAP_SHARE` of the kernel's limit.  Jobs are independent: parallelise across processes, not
   threads (``time_compile_s`` is counted per process); the workers of :func:`batch_client`
   are single-threaded processes for that reason.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import sys
import time
import traceback
import warnings
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Hashable, Iterable, Iterator, Mapping, Sequence

import numpy as np
import pandas as pd
from tqdm import tqdm

from .. import config
from .._jax import compile_seconds
from ..data.campaign import Campaign

if TYPE_CHECKING:
    from ..inference.kinds import FitOptions

COVERAGE_LEVELS = (0.5, 0.9, 0.95)
"""Central posterior interval levels recorded for every quantity (and checked for coverage)."""

CLEAR_JAX_CACHES_ABOVE_MB = 4096.0
"""Resident memory (MB) above which :func:`run_fit_job` clears JAX's compilation caches after a
job.  Clearing after every job would bound the memory at ~1.2 GB but costs 5-8 s per later fit
(the shared pieces are recompiled); never clearing grows by 85-165 MB per fit."""


CLEAR_JAX_CACHES_ABOVE_MAP_SHARE = 0.5
"""Share of the kernel's limit on a process's memory mappings (``vm.max_map_count``, 65530 by
default) above which :func:`run_fit_job` clears JAX's compilation caches after a job.  Every
compiled program keeps its machine code in mappings of its own, about 1300 per fit of a new
shape: a batch worker that had fitted 27 SBC campaigns of different lengths reached the limit,
and LLVM aborted the process ("Unable to allocate section memory") with 21 GB free.  Clearing
the caches returns the mappings (measured: 6194 after four fits, 1217 after clearing)."""


def _map_count() -> tuple[int, int] | None:
    """This process's memory mappings and the kernel's limit on them, or None where /proc is
    not available."""
    try:
        with open("/proc/self/maps") as f:
            n = sum(1 for _ in f)
        with open("/proc/sys/vm/max_map_count") as f:
            return n, int(f.read())
    except (OSError, ValueError):
        return None


def _rss_mb() -> float | None:
    """Resident memory of this process (MB), or None where /proc is not available."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError, AttributeError):
        return None


FIT_METHODS = ("nuts", "laplace")

DERIVED_QUANTITIES = ("F50_N",)
"""Derived road-load quantities recorded next to the free parameters (total road load at
50 mph and reference conditions, N; :func:`bayes_roadload.inference.results.derived_quantities`)."""


def quantile_key(q: float) -> str:
    """Record key suffix of the ``q`` quantile (a fraction): 0.025 -> ``"q2.5"``."""
    return f"q{100.0 * q:g}"


def interval_key(level: float) -> str:
    """Record key suffix of the in-interval flag of a central interval: 0.95 -> ``"in95"``."""
    return f"in{100.0 * level:g}"


@dataclass(frozen=True)
class SimulatedCampaign:
    """A picklable recipe for a simulated campaign: calling it runs
    :func:`bayes_roadload.simulate.simulate_campaign` ``(case, pairs, seed, driveline=...,
    settings=...)``.

    Parameters
    ----------
    case : int or bayes_roadload.simulate.SimulationCase
        A thesis case number (table 6.7) or a custom case.
    pairs : int
        Opposite-direction pairs of runs.
    seed : int
        Seed of every random draw of the simulation.
    settings : bayes_roadload.simulate.SimulationSettings, optional
        Noise levels, speeds, vehicle, ... (default: thesis chapter 6).
    driveline : bool
        Simulate and log the driveline force channel ``driveline_force_n``.
    masses_kg : tuple of float, optional
        Test masses assigned to the pairs in turn (``simulate_campaign(masses_kg=...)``).
    """

    case: Any
    pairs: int = 1
    seed: int = 0
    settings: Any = None
    driveline: bool = False
    masses_kg: tuple | None = None

    def __call__(self) -> Campaign:
        from ..simulate import simulate_campaign

        return simulate_campaign(self.case, self.pairs, self.seed, driveline=self.driveline,
                                 settings=self.settings, masses_kg=self.masses_kg)


@dataclass(frozen=True)
class FitJob:
    """One fit of one campaign, described so that it can be sent to another process.

    Parameters
    ----------
    name : str
        Identifies the job in the records.
    campaign_factory : callable or Campaign
        A picklable zero-argument callable returning the :class:`~bayes_roadload.data.Campaign`
        (e.g. :class:`SimulatedCampaign`, or ``functools.partial(load_campaign, path)``), or a
        campaign itself.  A factory keeps the job small when it travels to a worker.
    model : str
        Model variant (``models/*.toml`` name) passed to
        :func:`~bayes_roadload.inference.nuts.fit_nuts`; ``"auto"``: ``fit``'s default for
        each campaign (the speed-trace kind's ``default_model`` of that campaign), recorded as
        the model it resolved to.
    model_heavy : str, optional
        The model for a campaign whose test mass is above
        :data:`~bayes_roadload.config.HEAVY_DUTY_MASS_KG` (a candidate default's heavy-vehicle
        file beside ``model``, as ``fit`` routes its own default), recorded as the model used.
    pooling : {"pooled", "hierarchical"}
    noise : {"integrated", "white"}
        Likelihood of the speed residuals (:mod:`bayes_roadload.inference.bayes`).
    robust : bool
        Student-t innovations.
    sampler : bayes_roadload.config.SamplerConfig
        Draw counts, chains, target acceptance, seed.
    levels : tuple of float
        Central interval levels to record (fractions).
    tags : mapping
        Free-form scalars copied into the record (e.g. the study arm), for grouping.
    method : {"nuts", "laplace"}
        ``"nuts"``: :func:`~bayes_roadload.inference.nuts.fit_nuts` with the gates;
        ``"laplace"``: the cheap MAP + Laplace fit
        (:func:`~bayes_roadload.inference.laplace.fit_laplace`; same-shaped campaigns share
        one compilation in a worker), whose gate is the MAP's convergence.
    derived : tuple of str
        Road-load quantities recorded besides the free parameters
        (:data:`~bayes_roadload.inference.results.DERIVED` names).
    type_b : bool
        Add the Type B uncertainty of the declared values and instruments to the draws before
        the intervals are read, as ``fit`` does (:mod:`.budget`), for NUTS and Laplace fits.
    start : mapping, optional
        Laplace only: starting values of the free parameters instead of the least-squares
        start.
    """

    name: str
    campaign_factory: Callable[[], Campaign] | Campaign
    model: str = "four_term"
    pooling: str = "pooled"
    noise: str = "integrated"
    robust: bool = False
    sampler: config.SamplerConfig = config.DEFAULT_SAMPLER
    levels: tuple[float, ...] = COVERAGE_LEVELS
    tags: Mapping[str, Any] = field(default_factory=dict)
    method: str = "nuts"
    derived: tuple[str, ...] = DERIVED_QUANTITIES
    start: Mapping[str, float] | None = None
    type_b: bool = True
    model_heavy: str | None = None

    def __post_init__(self):
        if not all(0.0 < lv < 1.0 for lv in self.levels):
            raise ValueError("interval levels must be fractions in (0, 1)")
        if self.method not in FIT_METHODS:
            raise ValueError(f"method must be one of {FIT_METHODS}, not {self.method!r}")

    def campaign(self) -> Campaign:
        """Build (or return) the job's campaign."""
        if isinstance(self.campaign_factory, Campaign):
            return self.campaign_factory
        return self.campaign_factory()


def job_model(job: FitJob, campaign: Campaign, options: FitOptions) -> str:
    """The model ``job`` fits ``campaign`` with: ``"auto"`` resolved as ``fit`` without
    ``--model`` (the speed-trace kind's ``default_model``), ``job.model_heavy`` for a test mass
    above :data:`~bayes_roadload.config.HEAVY_DUTY_MASS_KG`, else ``job.model``."""
    from ..inference.kinds import KINDS

    if job.model == "auto":
        return KINDS["traces"].default_model(campaign, options)
    if job.model_heavy and campaign.vehicle.mass_kg > config.HEAVY_DUTY_MASS_KG:
        return job.model_heavy
    return job.model


def _job_fields(job: FitJob) -> dict[str, Any]:
    out = {"name": job.name, "method": job.method, "model": job.model, "pooling": job.pooling, "noise": job.noise,
           "robust": bool(job.robust), "num_warmup": job.sampler.num_warmup,
           "num_samples": job.sampler.num_samples, "num_chains": job.sampler.num_chains,
           "target_accept": job.sampler.target_accept, "noise_scaled_metric": bool(job.sampler.noise_scaled_metric),
           "sampler_coordinates": job.sampler.coordinates}
    out.update({str(k): v for k, v in job.tags.items()})
    return out


def _interval_fields(name: str, draws: np.ndarray, truth: float | None,
                     levels: Sequence[float]) -> dict[str, Any]:
    """Mean, sd, median and the ends of each central interval of one quantity's draws, and
    (with a truth) whether each interval covers it."""
    x = np.asarray(draws, float).ravel()
    qs = sorted({0.5} | {(1.0 - lv) / 2.0 for lv in levels} | {(1.0 + lv) / 2.0 for lv in levels})
    values = np.quantile(x, qs)  # same (linear) definition as np.percentile in results.summary_table
    out: dict[str, Any] = {f"{name}_mean": float(x.mean()), f"{name}_sd": float(x.std(ddof=1))}
    out.update({f"{name}_{quantile_key(q)}": float(v) for q, v in zip(qs, values)})
    t = math.nan if truth is None else float(truth)
    out[f"{name}_truth"] = t
    # SBC rank: how many draws fall below the truth (of out["rank_draws"] draws)
    out[f"{name}_rank"] = int(np.count_nonzero(x < t)) if math.isfinite(t) else None
    for lv in levels:
        lo, hi = out[f"{name}_{quantile_key((1.0 - lv) / 2.0)}"], out[f"{name}_{quantile_key((1.0 + lv) / 2.0)}"]
        out[f"{name}_{interval_key(lv)}"] = bool(lo <= t <= hi) if math.isfinite(t) else None
    return out


def retry_fields(retries: list[dict[str, Any]]) -> dict[str, Any]:
    """A batch record's account of a fit's retry (``NutsFit.retries``,
    :func:`~bayes_roadload.inference.nuts.sample_problem`): how many, which gates failed, whether
    the chains were continued (not sampled anew), in which coordinates the retry sampled ("":
    the first attempt's), and what the first attempt's R-hat and ESS gates read."""
    first = retries[0] if retries else {}
    return {"retries": len(retries),
            "retry_failed": ",".join(first.get("failed", [])),
            "retry_continued": bool(first.get("continued")) if retries else None,
            "retry_coordinates": first.get("coordinates", "") if retries else None,
            **{f"first_{k}": (first.get("first_attempt") or {}).get(k) if retries else None
               for k in ("max_r_hat", "max_r_hat_quantity", "its_ess_bulk", "min_ess_bulk")}}


def _fit_record(job: FitJob, campaign: Campaign, fit) -> dict[str, Any]:
    from ..inference.results import diagnostics, summary_table, to_inference_data, truth_derived

    from .budget import BUDGET_QUANTITIES, add_type_b_to_idata, budget_record, type_b_sensitivities

    problem = fit.problem
    truth = campaign.truth or {}
    idata = to_inference_data(fit, predictive=False)
    summary = summary_table(fit, idata)
    diag = diagnostics(fit, idata, summary)
    rows = summary.set_index("parameter")
    rec: dict[str, Any] = {"parameters": ",".join(problem.free),
                           "rank_draws": int(np.asarray(fit.samples[problem.free[0]]).size), "type_b": job.type_b}
    if job.type_b:  # the draws every interval below is read from get the Type B uncertainty (analysis.budget)
        typeb = type_b_sensitivities(campaign, problem.spec,
                                     [q for q in BUDGET_QUANTITIES if q in idata.posterior], fit=fit)
        recorded = [q for q in (*problem.free, *job.derived) if q in typeb.sensitivity and q in idata.posterior]
        rec.update(budget_record(typeb, {q: float(np.std(idata.posterior[q].values)) for q in recorded}))
        add_type_b_to_idata(idata, typeb, seed=job.sampler.seed)
        rec["time_type_b_s"] = typeb.time_s
    for name in problem.free:
        t = truth.get(name)
        rec.update(_interval_fields(name, idata.posterior[name].values, t if isinstance(t, (int, float)) else None,
                                    job.levels))
        rec[f"{name}_r_hat"] = float(rows.loc[name, "r_hat"])
        rec[f"{name}_ess_bulk"] = float(rows.loc[name, "ess_bulk"])
    derived = idata.posterior  # the road load of every draw, computed once by to_inference_data
    derived_truth = truth_derived(problem, truth)
    for name in job.derived:
        rec.update(_interval_fields(name, derived[name].values, derived_truth.get(name), job.levels))
    for name in ("q_mps_per_sqrt_s", "student_df"):
        if name in fit.samples:
            rec[f"{name}_mean"] = float(np.mean(fit.samples[name]))
            rec[f"{name}_q50"] = float(np.median(fit.samples[name]))
            if isinstance(truth.get(name), (int, float)):
                rec[f"{name}_truth"] = float(truth[name])
    rec["sigma_mps_mean"] = float(np.mean(fit.samples["sigma_mps"]))
    rec.update({
        "gate_pass": bool(diag["pass"]),
        "gates_failed": ",".join(diag["failed"]),
        "divergences": int(diag["divergences"]),
        "max_r_hat": float(diag["max_r_hat"]),
        "min_ess_bulk": float(diag["min_ess_bulk"]),
        "min_ess_tail": float(diag["min_ess_tail"]),
        "mean_tree_depth": float(diag["mean_tree_depth"]),
        "map_converged": bool(fit.map.success) if fit.map is not None else None,
        **retry_fields(fit.retries),
        # the first attempt's coordinates when not the problem's own ("": its own)
        "coordinates": fit.coordinates,
        # the acceptance of the reported run: the job's, or the small-campaign / quiet-trace
        # value (nuts.campaign_sampler, nuts.quiet_trace_sampler), or the retry's
        "target_accept_sampled": float(fit.sampler.target_accept),
        # the largest rate of the noise-scaled coordinates (NaN: sampled in the Laplace ones)
        "noise_scaled_max_rate": max(fit.noise_scaled_rates.values(), default=0.0)
        if fit.noise_scaled_rates is not None else math.nan,
    })
    rec.update({f"time_{k}": float(v) for k, v in fit.timings.items()})
    return rec


def _laplace_record(job: FitJob, campaign: Campaign, fit) -> dict[str, Any]:
    from ..inference.results import truth_derived

    problem = fit.problem
    truth = campaign.truth or {}
    rec: dict[str, Any] = {"parameters": ",".join(problem.free),
                           "rank_draws": int(np.asarray(fit.samples[problem.free[0]]).size), "type_b": job.type_b}
    draws = fit.samples
    if job.type_b:  # as the NUTS record (_fit_record) and `fit`: the intervals carry the Type B uncertainty
        from .budget import BUDGET_QUANTITIES, add_type_b, budget_record, type_b_sensitivities

        typeb = type_b_sensitivities(campaign, problem.spec, [q for q in BUDGET_QUANTITIES if q in draws], fit=fit)
        recorded = [q for q in (*problem.free, *job.derived) if q in typeb.sensitivity and q in draws]
        rec.update(budget_record(typeb, {q: float(np.std(draws[q])) for q in recorded}))
        draws = {**draws, **add_type_b({q: draws[q] for q in typeb.sensitivity}, typeb, seed=job.sampler.seed)}
        rec["time_type_b_s"] = typeb.time_s
    for name in problem.free:
        t = truth.get(name)
        rec.update(_interval_fields(name, draws[name], t if isinstance(t, (int, float)) else None, job.levels))
    derived_truth = truth_derived(problem, truth)
    for name in job.derived:
        rec.update(_interval_fields(name, draws[name], derived_truth.get(name), job.levels))
    for name in ("q_mps_per_sqrt_s",) + tuple(f"tau_{n}" for n in problem.varying):
        if name in fit.samples:
            rec[f"{name}_mean"] = float(np.mean(fit.samples[name]))
            rec[f"{name}_q50"] = float(np.median(fit.samples[name]))
    rec["sigma_mps_mean"] = float(np.mean(fit.samples["sigma_mps"]))
    k = float(fit.diagnostics.get("pareto_k", math.nan))
    failed = [name for name, bad in (("map", not (fit.map.success and fit.map.min_eigenvalue > 0.0)),
                                     ("pareto_k", k > config.LAPLACE_MAX_PARETO_K)) if bad]
    rec.update({"gate_pass": not failed, "gates_failed": ",".join(failed),
                "map_converged": bool(fit.map.success), "map_min_eigenvalue": float(fit.map.min_eigenvalue),
                "map_iterations": int(fit.map.n_iter), "pareto_k": k,
                "is_ess": float(fit.diagnostics.get("is_ess", math.nan)),
                "proposal_inflation": float(fit.diagnostics.get("proposal_inflation", math.nan)),
                "is_evaluations": int(fit.diagnostics.get("is_evaluations", 0))})
    rec.update({f"time_{k}": float(v) for k, v in fit.timings.items()})
    return rec


def run_fit_job(job: FitJob) -> dict[str, Any]:
    """Run one job: build the campaign, fit it (NUTS or MAP + Laplace), summarise.

    Never raises for a failure inside the job: the record then has ``error`` set to the
    exception's type and message (and ``traceback``), with the job fields and the timings
    up to the failure.

    Parameters
    ----------
    job : FitJob

    Returns
    -------
    dict
        A flat record of plain Python scalars and strings (picklable, one DataFrame row):

        * job fields: ``name, model, pooling, noise, robust, num_warmup, num_samples,
          num_chains, target_accept`` and the ``tags``;
        * campaign: ``n_runs, n_samples`` (real samples), ``test_mass_kg`` (the declared
          test mass), and ``case, seed, pairs,
          prior_draws, effective_mass_factor`` from the campaign's meta when it has them; ``parameters`` (the free ones, comma-separated);
        * ``mean_abs_yaw_rad``: mean |logged yaw| over all samples (when logged);
        * for every free parameter ``P`` and for ``F50_N``: ``P_mean, P_sd``, quantiles
          ``P_q50`` and ``P_q{lower}``, ``P_q{upper}`` of every level (``P_q2.5``,
          ``P_q97.5`` for 95 %), ``P_truth`` (NaN when unknown), ``P_in{level}`` (True /
          False / None) and ``P_rank``, the number of posterior draws below the truth (None
          when unknown; out of ``rank_draws``, all chains' draws: the rank statistic of
          simulation-based calibration); ``P_r_hat, P_ess_bulk`` for the free parameters;
        * noise: ``sigma_mps_mean`` and, when sampled, ``q_mps_per_sqrt_s_mean`` / ``_q50``
          (NUTS: and ``q_mps_per_sqrt_s_truth`` when the campaign's truth states it);
        * gates: ``gate_pass, gates_failed, divergences, max_r_hat, min_ess_bulk,
          min_ess_tail, mean_tree_depth, map_converged``, ``noise_scaled_max_rate`` (the
          largest rate of the noise-scaled coordinates, NaN when not sampled in them),
          ``coordinates`` (the first attempt's coordinates when not the problem's own, with
          why: :func:`~bayes_roadload.inference.nuts.start_coordinates`; "" its own); for
          ``method="laplace"`` only
          ``gate_pass`` (the MAP converged, its Hessian is positive definite and the
          importance weights' Pareto k is at most ``config.LAPLACE_MAX_PARETO_K``),
          ``gates_failed`` ("map", "pareto_k"), ``map_converged, map_min_eigenvalue,
          map_iterations, pareto_k, is_ess, proposal_inflation, is_evaluations`` (posterior
          evaluations of the importance correction), and no ``P_r_hat, P_ess_bulk``;
          ``tau_P_mean / _q50`` of the hierarchical spreads;
        * timings (s): ``time_simulate_s``, ``time_map_s``, ``time_importance_s`` (Laplace),
          ``time_warmup_s``,
          ``time_sampling_s`` (from the fit, compilation included), ``time_fit_s`` (the whole
          ``fit_nuts`` call), ``time_summary_s``, ``time_total_s`` and ``time_compile_s`` (JAX
          tracing, lowering and compilation during the job);
        * memory: ``rss_mb`` and ``memory_maps`` after the job and ``jax_caches_cleared`` (see
          :data:`CLEAR_JAX_CACHES_ABOVE_MB`, :data:`CLEAR_JAX_CACHES_ABOVE_MAP_SHARE`);
        * ``warnings`` (distinct messages, ``"; "``-joined) and ``error`` (None on success).
    """
    from ..inference.laplace import fit_laplace
    from ..inference.nuts import fit_nuts
    from ..inference.kinds import KINDS, FitOptions, resolve_pooling
    from ..inference.spec import load_model_spec

    rec = _job_fields(job)
    rec["error"] = None
    compile_start = compile_seconds()
    t_start = time.perf_counter()
    caught: list[warnings.WarningMessage] = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            t0 = time.perf_counter()
            campaign = job.campaign()
            rec["time_simulate_s"] = time.perf_counter() - t0
            rec["n_runs"] = len(campaign.run_ids)
            rec["n_samples"] = int(len(campaign.runs))
            rec["test_mass_kg"] = float(campaign.vehicle.mass_kg)
            if "yaw_rad" in campaign.runs:
                rec["mean_abs_yaw_rad"] = float(np.abs(campaign.runs["yaw_rad"].to_numpy(float)).mean())
            for key in ("case", "seed", "pairs", "prior_draws", "effective_mass_factor"):
                if key in campaign.meta and key not in rec:
                    rec[key] = campaign.meta[key]
            t0 = time.perf_counter()
            options = FitOptions(method="nuts", robust=job.robust)
            model, pooling = job_model(job, campaign, options), job.pooling
            rec["model"] = model  # "auto" or a heavy vehicle's file: the model the fit took
            if pooling == "auto":  # as `fit`: the speed-trace kind's default for this campaign and model
                pooling = resolve_pooling(KINDS["traces"], campaign, load_model_spec(model), options).pooling
                rec["pooling"] = pooling
            if job.method == "laplace":
                fit = fit_laplace(campaign, model, pooling=pooling, noise=job.noise, robust=job.robust,
                                  seed=job.sampler.seed, start=None if job.start is None else dict(job.start))
            else:
                fit = fit_nuts(campaign, model, pooling=pooling, noise=job.noise, robust=job.robust,
                               sampler=job.sampler)
            rec["time_fit_s"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            rec.update((_laplace_record if job.method == "laplace" else _fit_record)(job, campaign, fit))
            rec["time_summary_s"] = time.perf_counter() - t0
    except Exception as exc:  # noqa: BLE001 - one failed job must not end the batch
        rec["error"] = f"{type(exc).__name__}: {exc}"
        rec["traceback"] = traceback.format_exc(limit=8)
    rec["warnings"] = "; ".join(dict.fromkeys(
        f"{w.category.__name__}: {w.message}" for w in caught
        if not issubclass(w.category, DeprecationWarning)))[:2000]
    rec["time_total_s"] = time.perf_counter() - t_start
    rec["time_compile_s"] = compile_seconds() - compile_start
    rss, maps = _rss_mb(), _map_count()
    rec["rss_mb"] = math.nan if rss is None else rss
    rec["memory_maps"] = math.nan if maps is None else maps[0]
    rec["jax_caches_cleared"] = bool((rss is not None and rss > CLEAR_JAX_CACHES_ABOVE_MB)
                                     or (maps is not None and maps[0] > CLEAR_JAX_CACHES_ABOVE_MAP_SHARE * maps[1]))
    if rec["jax_caches_cleared"]:
        import jax

        jax.clear_caches()
    return rec


def run_job(job: Any) -> dict[str, Any]:
    """Run one job of any kind: a :class:`FitJob` through :func:`run_fit_job`, any other job
    (e.g. the proof suite's ``studies.proof_suite.DiagnoseJob``) by its ``run()`` method,
    which must return a flat, picklable record and never raise for a failure inside the job."""
    if isinstance(job, FitJob):
        return run_fit_job(job)
    return job.run()


def usable_cores() -> int:
    """Cores this process may run on (its CPU affinity where the platform reports it)."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # not on Linux
        return max(os.cpu_count() or 1, 1)


NANNY_ENVIRON_UNSET = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
"""Dask settings of a local cluster's workers that this package removes: Dask's nanny sets
``MALLOC_TRIM_THRESHOLD_=65536`` in every worker (its "automatically trim memory"), and a set
trim threshold turns off glibc's dynamic mmap threshold, so every block of 128 KiB or more that
XLA allocates is a fresh ``mmap`` whose pages fault in again on each refit."""


def worker_environment(workers: int, cores: int | None = None) -> dict[str, str]:
    """Environment of the worker processes of a local cluster of ``workers`` processes.

    Each worker's XLA runs single-threaded operations (``--xla_cpu_multi_thread_eigen=false
    intra_op_parallelism_threads=1``) on ``max(cores // workers, 1)`` host devices (the
    chains of a NUTS fit run in parallel on them), so the workers together use the machine's
    ``cores`` once rather than each of them all of it.  Other flags of this process's
    ``XLA_FLAGS`` are kept.
    """
    cores = usable_cores() if cores is None else cores
    keep = [f for f in os.environ.get("XLA_FLAGS", "").split()
            if not f.startswith(("--xla_force_host_platform_device_count", "--xla_cpu_multi_thread_eigen",
                                 "intra_op_parallelism_threads"))]
    flags = keep + [f"--xla_force_host_platform_device_count={max(cores // max(workers, 1), 1)}",
                    "--xla_cpu_multi_thread_eigen=false", "intra_op_parallelism_threads=1"]
    return {"XLA_FLAGS": " ".join(flags), "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
            "OPENBLAS_NUM_THREADS": "1"}


@contextlib.contextmanager
def batch_client(workers: int | None = None, scheduler: str | None = None, *,
                 memory_limit: str | float | None = "auto") -> Iterator[Any]:
    """Where a batch runs, as a context manager yielding a ``dask.distributed.Client`` (or
    ``None``) for :func:`run_batch` and :func:`batch_map`.

    Parameters
    ----------
    workers : int, optional
        Without ``scheduler``: the number of single-threaded worker processes of a
        ``LocalCluster`` started here and closed on exit (default: :func:`usable_cores`);
        ``workers <= 1`` starts no cluster and yields ``None``: the jobs then run one after
        the other in this process, with the same results and no worker start-up cost.
        With ``scheduler``: ignored (the cluster has its own workers).
    scheduler : str, optional
        Address of a running Dask scheduler, e.g. ``"tcp://10.0.0.5:8786"``; the client
        connects to it and disconnects on exit, leaving the cluster running.  Its workers
        must have ``bayes_roadload`` (the same version) installed.
    memory_limit : str, float or None
        Memory limit of each local worker, passed to ``LocalCluster`` (``"auto"``: the
        machine's memory shared equally between the workers; ``None``: no limit).

    Yields
    ------
    distributed.Client or None

    Notes
    -----
    Local workers are spawned processes (JAX is multithreaded and does not survive
    ``fork``) started with the environment of :func:`worker_environment` (set in this
    process while they start: a spawned process imports this program's main module, and
    with it JAX, before Dask applies a worker's own environment); they import
    ``bayes_roadload`` to unpickle their first job, which enables 64-bit floats in JAX.  When
    this process has JAX's persistent compilation cache on (the command line turns it on,
    :func:`~bayes_roadload._jax.enable_compilation_cache`), every local worker uses the same
    directory (:class:`~bayes_roadload.analysis._worker_plugins.CompilationCachePlugin`), so
    a program one worker compiled is loaded by the others and by later batches of the same
    shapes.  The dashboard is off and the cluster logs only errors.
    """
    from distributed import Client, LocalCluster  # deferred: the command line starts without Dask

    if scheduler is not None:
        with Client(scheduler) as client:
            yield client
        return
    workers = usable_cores() if workers is None else int(workers)
    if workers <= 1:
        yield None
        return
    import dask

    env = worker_environment(workers)
    with _environ(env), dask.config.set(NANNY_ENVIRON_UNSET):  # XLA reads its flags when the worker imports JAX
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                               memory_limit=memory_limit, silence_logs=logging.ERROR, env=env)
    with cluster, Client(cluster) as client:
        cache = compilation_cache_dir()
        if cache:
            from ._worker_plugins import CompilationCachePlugin

            client.register_plugin(CompilationCachePlugin(cache))
        yield client


def compilation_cache_dir() -> str | None:
    """The directory of this process's persistent compilation cache, or None when it is off
    (or JAX was not imported, so nothing turned it on)."""
    jax = sys.modules.get("jax")
    return (jax.config.jax_compilation_cache_dir or None) if jax is not None else None


@contextlib.contextmanager
def _environ(values: Mapping[str, str]) -> Iterator[None]:
    """This process's environment with ``values`` set, restored on exit (the environment that
    processes spawned meanwhile inherit)."""
    saved = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _format_seconds(seconds: float) -> str:
    return tqdm.format_interval(max(seconds, 0.0))


class _Progress:
    """One progress bar over a batch: tqdm on a terminal, else a plain line per finished item
    with the elapsed time and the time left: elapsed / work done x work left, the work of an
    item being its ``weight`` (1 each by default; e.g. the pairs of a planning refit, whose
    cost grows with them)."""

    def __init__(self, total: int, enabled: bool, desc: str, stream=None, weights: Sequence[float] | None = None):
        self.total, self.done, self.enabled, self.desc = total, 0, enabled, desc
        self.weights = [1.0] * total if weights is None else [float(w) for w in weights]
        self.work_total, self.work_done = sum(self.weights), 0.0
        self.stream = sys.stderr if stream is None else stream
        self.t0 = time.perf_counter()
        self.bar = None
        if enabled and total and getattr(self.stream, "isatty", lambda: False)():
            self.bar = tqdm(total=total, desc=desc, unit="job", file=self.stream, dynamic_ncols=True)

    def update(self, label: str, index: int, failed: bool = False) -> None:
        self.done += 1
        self.work_done += self.weights[index]
        if not self.enabled:
            return
        elapsed = time.perf_counter() - self.t0
        left = elapsed / max(self.work_done, 1e-12) * max(self.work_total - self.work_done, 0.0)
        if self.bar is not None:
            self.bar.set_postfix_str(f"last: {label}{' (failed)' if failed else ''}; about {_format_seconds(left)} left",
                                     refresh=False)
            self.bar.update(1)
            return
        print(f"{self.desc} {self.done}/{self.total} {label}{': failed' if failed else ''} "
              f"[{_format_seconds(elapsed)} elapsed, about {_format_seconds(left)} left]",
              file=self.stream, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _label(item: Any, index: int) -> str:
    name = getattr(item, "name", None)
    return str(name) if name is not None else f"#{index}"


def batch_map(fn: Callable[[Any], Any], items: Iterable[Any], client: Any | None = None, *,
              progress: bool = True, desc: str = "batch",
              on_result: Callable[[Any], None] | None = None,
              on_error: Callable[[Any, BaseException, str], Any] | None = None,
              weight: Callable[[Any], float] | None = None,
              lead: Callable[[Any], Hashable] | None = None) -> list[Any]:
    """``[fn(item) for item in items]`` through the batch door, in item order.

    Parameters
    ----------
    fn : callable
        A picklable (module-level) function of one item.
    items : iterable
        Picklable items (e.g. :class:`FitJob`).
    client : distributed.Client, object with ``map(fn, iterable)``, or None
        ``None`` runs the items one after the other in this process; a Dask client (from
        :func:`batch_client`) submits them all and collects the results as they complete;
        anything else with an ``Executor.map``-like method (a
        ``concurrent.futures.ProcessPoolExecutor``, ``Client.get_executor()``) maps them.
    progress : bool
        Show one progress bar with the time left (a line per finished item on stderr when it
        is not a terminal).
    desc : str
        Label of the progress bar.
    on_result : callable, optional
        Called with every result as it arrives (partial results, checkpoints).
    on_error : callable, optional
        ``on_error(item, exception, traceback_text)`` returns the result that stands for a
        failed item, and the batch goes on.  Without it the first failure is raised once the
        items already submitted have finished (Dask) or at once (in this process, executor).
    weight : callable, optional
        ``weight(item)``: the item's share of the work, for the time left (default: equal).
    lead : callable, optional
        ``lead(item)``: a key shared by the items that run the same compiled programs (e.g. the
        campaign size of planning refits).  With a Dask client the first item of each key is
        submitted alone and the key's other items when it has finished, so that the other
        workers load its programs from the persistent compilation cache
        (:func:`~bayes_roadload._jax.enable_compilation_cache`) instead of compiling them at
        the same time (the items of other keys run meanwhile).  Useful only with that cache
        on; ignored without a Dask client.

    Returns
    -------
    list
        The results, in the order of ``items``.
    """
    items = list(items)
    bar = _Progress(len(items), progress, desc, weights=None if weight is None else [weight(x) for x in items])
    results: list[Any] = [None] * len(items)
    first_error: list[BaseException] = []

    def settle(i: int, result: Any = None, exc: BaseException | None = None, tb: str = "") -> None:
        if exc is not None:
            if on_error is None:
                first_error.append(exc)
                bar.update(_label(items[i], i), failed=True, index=i)
                return
            result = on_error(items[i], exc, tb)
        results[i] = result
        failed = exc is not None or (isinstance(result, Mapping) and result.get("error") is not None)
        bar.update(_label(items[i], i), failed=failed, index=i)
        if on_result is not None:
            on_result(result)

    try:
        if _is_dask_client(client):
            from distributed import as_completed

            waiting: dict[int, list[int]] = {}  # a key's first item -> the key's other items
            if lead is not None:
                groups: dict[Hashable, list[int]] = {}
                for i, item in enumerate(items):
                    groups.setdefault(lead(item), []).append(i)
                waiting = {g[0]: g[1:] for g in groups.values()}
            index: dict[Any, int] = {}

            def submit(indices: list[int]) -> list[Any]:
                futures = client.map(fn, [items[i] for i in indices], pure=False)
                index.update({f.key: i for f, i in zip(futures, indices)})
                return futures

            pending = as_completed(submit(list(waiting) if lead is not None else list(range(len(items)))))
            for future in pending:
                i = index[future.key]
                if waiting.get(i):  # a key's first item has finished: its programs are compiled
                    pending.update(submit(waiting.pop(i)))
                if future.status == "finished":
                    settle(i, future.result())
                else:  # the job raised, its worker died, or it was cancelled
                    try:
                        exc, tb = future.exception(), future.traceback()
                    except Exception as lost:  # noqa: BLE001 - a cancelled future has no exception to give
                        exc, tb = lost, None
                    text = "".join(traceback.format_tb(tb)) if tb is not None else ""
                    settle(i, exc=exc, tb=f"{text}{type(exc).__name__}: {exc}")
                future.release()
        elif client is None:
            for i, item in enumerate(items):
                try:
                    result = fn(item)
                except Exception as exc:  # noqa: BLE001 - recorded by on_error, or re-raised below
                    if on_error is None:
                        raise
                    settle(i, exc=exc, tb=traceback.format_exc(limit=8))
                else:
                    settle(i, result)
        else:
            for i, result in enumerate(client.map(fn, items)):
                settle(i, result)
    finally:
        bar.close()
    if first_error:
        raise first_error[0]
    return results


def _is_dask_client(client: Any) -> bool:
    """Whether ``client`` is a ``distributed.Client`` (without importing Dask for None or an
    executor)."""
    if client is None or "distributed" not in sys.modules:
        return False
    from distributed import Client

    return isinstance(client, Client)


def _error_record(job: Any, exc: BaseException, tb: str) -> dict[str, Any]:
    """The record of a job whose run raised (or whose worker died)."""
    rec = _job_fields(job) if isinstance(job, FitJob) else {"name": getattr(job, "name", None)}
    rec.update({"error": f"{type(exc).__name__}: {exc}", "traceback": tb[-4000:]})
    return rec


def run_batch(jobs: Iterable[FitJob], client: Any | None = None, *, progress: bool = True,
              on_record: Callable[[dict[str, Any]], None] | None = None,
              executor: Any | None = None, weight: Callable[[Any], float] | None = None,
              lead: Callable[[Any], Hashable] | None = None) -> pd.DataFrame:
    """Run many fit jobs and collect their records, one row per job, in job order.

    Parameters
    ----------
    jobs : iterable of FitJob, or of other jobs with a ``run()`` method (:func:`run_job`)
    client : distributed.Client, object with ``map(fn, iterable)``, or None
        Where the jobs run (:func:`batch_map`): ``None`` one after the other in this process,
        a Dask client of :func:`batch_client` on its workers.  Jobs and records must then
        pickle; :class:`FitJob` with a :class:`SimulatedCampaign` does.
    progress : bool
        One progress bar with the time left.
    on_record : callable, optional
        Called with every record as it arrives (progress, partial results).
    executor : optional
        Same as ``client`` (the keyword of callers written for ``concurrent.futures``).
    weight : callable, optional
        A job's share of the work for the progress bar's time left (:func:`batch_map`).
    lead : callable, optional
        A key of the jobs that share compiled programs: the first of each runs before the
        others start (:func:`batch_map`).

    Returns
    -------
    pandas.DataFrame
        The records of :func:`run_fit_job`.  A job that failed, raised, or whose worker died
        has ``error`` set (and ``traceback``); the other jobs' records are complete.
    """
    if client is not None and executor is not None:
        raise TypeError("give client or executor, not both")
    records = batch_map(run_job, jobs, client if client is not None else executor, progress=progress,
                        desc="fits", on_result=on_record, on_error=_error_record, weight=weight, lead=lead)
    return pd.DataFrame.from_records(records)


def successful(records: pd.DataFrame) -> pd.DataFrame:
    """The records of :func:`run_batch` whose job ended without an error."""
    return records[records["error"].isna()] if "error" in records else records


def passed_first_time(records: pd.DataFrame) -> pd.Series:
    """Per record: every gate passed without a retry (``gate_pass`` and ``retries`` 0; a record
    without a retry count had none)."""
    return records["gate_pass"].astype(bool) & records["retries"].fillna(0).eq(0)


# --------------------------------------------------------------------------- coverage

def _wilson(k: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score 95 % interval of a binomial proportion k / n."""
    if n == 0:
        return math.nan, math.nan
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def record_z(records: pd.DataFrame, quantity: str) -> pd.Series:
    """z = (posterior mean - truth) / posterior sd of ``quantity`` in each fit record (its
    ``{quantity}_mean``, ``_truth`` and ``_sd`` columns)."""
    return ((records[f"{quantity}_mean"].astype(float) - records[f"{quantity}_truth"].astype(float))
            / records[f"{quantity}_sd"].astype(float))


def coverage_summary(records: pd.DataFrame, by: Sequence[str] = ("model", "noise"),
                     quantities: Sequence[str] | None = None,
                     levels: Sequence[float] = COVERAGE_LEVELS) -> pd.DataFrame:
    """Frequentist coverage of the posterior intervals of a simulation study.

    Parameters
    ----------
    records : DataFrame of :func:`run_batch` records with known truths.  Records with an
        ``error`` are left out (count them separately).
    by : record columns that define the study arms.
    quantities : names to check (default: every ``X`` with ``X_truth`` and ``X_in{level}``
        columns).
    levels : interval levels (fractions).

    Returns
    -------
    pandas.DataFrame
        One row per arm, quantity and level: ``n`` fits, ``covered``, ``coverage`` (the
        fraction), ``se_nominal`` = sqrt(level (1 - level) / n) (the binomial standard error
        *if* the intervals had nominal coverage: an observed coverage more than ~2 of them from
        the level is evidence against calibration), ``wilson_low``, ``wilson_high`` (95 % score
        interval of the observed proportion), and ``z_sd``: the standard deviation over fits of
        ``(mean - truth) / sd``, ~1 for calibrated posteriors (its own standard error is about
        1 / sqrt(2 n) for normal errors) and > 1 when the posterior sd is too small; ``z_mean``
        its mean, ~0 (standard error 1 / sqrt(n)) unless the estimates are biased.
    """
    ok = successful(records)
    if quantities is None:
        quantities = [c[: -len("_truth")] for c in ok.columns if c.endswith("_truth")
                      and all(f"{c[:-len('_truth')]}_{interval_key(lv)}" in ok for lv in levels)]
    by = [b for b in by if b in ok.columns]
    groups = ok.groupby(by, sort=True, dropna=False) if by else [((), ok)]
    rows = []
    for key, g in groups:
        key = key if isinstance(key, tuple) else (key,)
        for q in quantities:
            truth = g[f"{q}_truth"].astype(float)
            known = g[truth.notna()]
            if known.empty:
                continue
            z = record_z(known, q)
            for lv in levels:
                flags = known[f"{q}_{interval_key(lv)}"].astype(bool)
                n, k = int(flags.size), int(flags.sum())
                lo, hi = _wilson(k, n)
                rows.append({**dict(zip(by, key)), "quantity": q, "level": lv, "n": n, "covered": k,
                             "coverage": k / n, "se_nominal": math.sqrt(lv * (1 - lv) / n),
                             "wilson_low": lo, "wilson_high": hi,
                             "z_sd": float(z.std(ddof=1)) if n > 1 else math.nan, "z_mean": float(z.mean())})
    return pd.DataFrame(rows)
