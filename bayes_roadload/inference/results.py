"""From NUTS draws to what a test engineer reads: ArviZ data, summary, diagnostics, gates.

Outputs of ``bayes-roadload fit --method nuts --out DIR``:

``posterior.nc``
    ArviZ InferenceData: ``posterior`` (contract names, per-run sites on a ``run``
    coordinate, derived road-load quantities), ``posterior_predictive`` (replicated speed
    traces: integrated speed + integrated noise + measurement noise, for a thinned subset of
    draws), ``log_likelihood`` (summed per run), ``observed_data`` and ``constant_data``
    (padded samples are NaN; the inputs as the model read them, so with the vehicle's admittance
    the airspeed and yaw of the air the body feels), ``sample_stats`` (divergences, tree depth, energy, ...).
``summary.csv``
    ``parameter, mean, sd, q2.5, q50, q97.5, r_hat, ess_bulk, ess_tail``: the free
    parameters, the noise parameters, ``tau_*`` (hierarchical), and ``F50_N`` with its tyre /
    aero / driveline / undriven parts and ``F0_N, F1_N_per_kph, F2_N_per_kph2`` at reference
    conditions.
``diagnostics.json``
    divergences, max R-hat, min bulk / tail ESS, mean and max tree depth, E-BFMI per chain,
    timings, MAP status, each gate and ``pass``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import arviz as az
import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from .. import config
from ..physics.residuals import integrated_error_draws
from .bayes import NOISE_SITES, FitProblem, integrated_speed, reversion_along, run_log_likelihood
from .nuts import NutsFit
from .problem import ROAD_LOAD_DERIVED, road_load_truth

SUMMARY_COLUMNS = ("parameter", "mean", "sd", "q2.5", "q50", "q97.5", "r_hat", "ess_bulk", "ess_tail")
DERIVED = ROAD_LOAD_DERIVED


def _flat(x: np.ndarray) -> np.ndarray:
    return x.reshape((-1,) + x.shape[2:])


def _unflat(x: np.ndarray, chains: int) -> np.ndarray:
    return x.reshape((chains, -1) + x.shape[1:])


def derived_quantities(fit: NutsFit) -> dict[str, np.ndarray]:
    """The derived quantities of every draw ([chain, draw] arrays): the problem's
    :meth:`~bayes_roadload.inference.problem.Problem.derived` (road load at reference conditions
    for a drag model; the hierarchical model's population-mean coefficients)."""
    return fit.problem.derived(fit.samples)


PER_DRAW_BATCH_ELEMENTS = 2_000_000
"""Samples x draws evaluated at once when a function of every draw runs over the speed traces
(log-likelihood, posterior predictive): the draws go in batches of
``PER_DRAW_BATCH_ELEMENTS // (runs x samples)`` so that memory does not grow with the number of
draws (all 4000 draws of a 108-run campaign at once took more than 20 GB)."""


def draws_at_once(problem) -> int:
    """Draws per batch of a function of every draw over ``problem``'s speed traces
    (:data:`PER_DRAW_BATCH_ELEMENTS` / the batch's samples, at least 1)."""
    per_draw = max(1, int(np.prod(np.shape(problem.batch.speed_mps))))
    return max(1, PER_DRAW_BATCH_ELEMENTS // per_draw)


def _map_draws(fn, xs, problem) -> Any:
    """``jax.vmap(fn)(xs)`` in batches of draws (:func:`draws_at_once`), compiled once."""
    batch = draws_at_once(problem)
    return jax.jit(lambda x: jax.lax.map(fn, x, batch_size=batch))(xs)


def _draw_dicts(fit: NutsFit, idx: np.ndarray) -> dict[str, jnp.ndarray]:
    return {k: jnp.asarray(_flat(v)[idx]) for k, v in fit.samples.items()}


PREDICTIVE_DTYPE = np.float32
"""Storage type of the replicated speed traces (:func:`posterior_predictive`), the bulk of
``posterior.nc`` (two arrays of draws x runs x samples: 59 MB in float64 for 200 draws of 36 runs
padded to 512 samples, against ~2 MB for everything else).  Their rounding, 6e-8 relative
(2.4e-6 m/s at 40 m/s), is 400 times below the likelihood's speed-noise floor
(:data:`~bayes_roadload.config.SPEED_NOISE_FLOOR_MPS`); they are computed in float64."""


PREDICTIVE_PRNG = "rbg"
"""JAX PRNG of the replicated traces' noise: XLA's RngBitGenerator for the bits, Threefry for
the per-draw keys (``jax.random.key(seed, impl="rbg")``).  The predictive of the 36-run
cold-start reference (200 draws, compiled and run) takes 3.4 s of CPU against 5.0 s with
Threefry bits (``benchmarks/predictive_prng.py``, records ``predictive_prng.jsonl``).  The
noise is reproducible for a given seed and installation, not across JAX versions."""


def posterior_predictive(fit: NutsFit, n_draws: int | None = None, seed: int = 1) -> dict[str, np.ndarray]:
    """Replicated speed traces [chain, draw, run, sample] for a thinned set of draws, and the
    integrated speed (noise-free) for the same draws, in float32 (:data:`PREDICTIVE_DTYPE`)."""
    p = fit.problem
    chains, draws = next(iter(fit.samples.values())).shape[:2]
    n_draws = n_draws or fit.sampler.posterior_predictive_draws
    per_chain = max(1, min(draws, n_draws // chains))
    keep = np.linspace(0, draws - 1, per_chain).astype(int)
    idx = (np.arange(chains)[:, None] * draws + keep[None, :]).ravel()
    batch = p.batch
    key = jax.random.key(seed, impl=PREDICTIVE_PRNG)

    def one(sample, k):
        v = integrated_speed(p, sample)
        z = jax.random.normal(k, (2,) + v.shape)
        q = sample.get("q_mps_per_sqrt_s", jnp.zeros(()))
        # a reverting error reverts along this draw's trajectory, as the likelihood scores it
        phi = reversion_along(p, sample, v) if p.noise == "reverting" else None
        walk = integrated_error_draws(batch.time_s, q, z[0], phi)
        sigma = jnp.sqrt(sample["sigma_mps"] ** 2 + config.SPEED_NOISE_FLOOR_MPS**2)  # the likelihood's noise
        noise = sigma[:, None] * z[1]
        return v, v + walk + noise

    draws_dict = _draw_dicts(fit, idx)
    keys = jax.random.split(key, idx.size)
    v, rep = _map_draws(lambda a: one(*a), (draws_dict, keys), p)
    mask = np.asarray(batch.mask)
    v = np.where(mask, np.asarray(v), np.nan).astype(PREDICTIVE_DTYPE)
    rep = np.where(mask, np.asarray(rep), np.nan).astype(PREDICTIVE_DTYPE)
    return {"speed_mps": _unflat(rep, chains), "speed_integrated_mps": _unflat(v, chains)}


def log_likelihood_per_run(fit: NutsFit) -> np.ndarray:
    """[chain, draw, run] log-likelihood of each run's speed trace."""
    p = fit.problem
    chains = next(iter(fit.samples.values())).shape[0]
    flat = {k: jnp.asarray(_flat(v)) for k, v in fit.samples.items()}
    ll = _map_draws(lambda s: run_log_likelihood(p, s), flat, p)
    return _unflat(np.asarray(ll), chains)


def sample_stats(fit: NutsFit) -> dict[str, np.ndarray]:
    """The sampler statistics of ``posterior.nc`` ([chain, draw] each)."""
    return {"diverging": fit.stats["diverging"].astype(bool), "tree_depth": fit.stats["tree_depth"],
            "n_steps": fit.stats["num_steps"], "energy": fit.stats["energy"],
            "acceptance_rate": fit.stats["accept_prob"]}


def inference_data(fit: NutsFit, *, derived: dict[str, np.ndarray] | None = None,
                   observed: dict[str, np.ndarray] | None = None, constant: dict[str, np.ndarray] | None = None,
                   log_likelihood: dict[str, np.ndarray] | None = None,
                   predictive: dict[str, np.ndarray] | None = None,
                   coords: dict | None = None, dims: dict | None = None) -> az.InferenceData:
    """The one builder of a fit's ArviZ InferenceData, for every data kind: ``posterior`` (the
    draws and the ``derived`` quantities, default the problem's
    :meth:`~bayes_roadload.inference.problem.Problem.derived`), ``sample_stats``
    (:func:`sample_stats`) and the optional groups; ``dims`` / ``coords`` name the extra axes
    (dims of absent variables are dropped)."""
    posterior = dict(fit.samples)
    posterior.update(fit.problem.derived(fit.samples) if derived is None else derived)
    groups: dict = {"posterior": posterior, "sample_stats": sample_stats(fit)}
    present = set(posterior)
    for name, group in (("observed_data", observed), ("constant_data", constant),
                        ("log_likelihood", log_likelihood), ("posterior_predictive", predictive)):
        if group is not None:
            groups[name] = group
            present |= set(group)
    dims = {k: v for k, v in (dims or {}).items() if k in present}
    return az.from_dict(**groups, coords=coords or None, dims=dims or None)


def to_inference_data(fit: NutsFit, *, predictive: bool = True) -> az.InferenceData:
    """The fit of speed traces as ArviZ InferenceData (see the module docstring)."""
    p = fit.problem
    runs = [str(r) for r in p.run_ids]
    n = p.batch.time_s.shape[1]
    dims = {k: ["run"] for k, v in fit.samples.items() if v.ndim == 3 and v.shape[2] == p.n_runs}
    mask = np.asarray(p.batch.mask)
    observed = {"speed_mps": np.where(mask, np.asarray(p.batch.speed_mps), np.nan)}
    constant = {
        "time_s": np.where(mask, np.asarray(p.batch.time_s), np.nan),
        "airspeed_mps": np.where(mask, np.asarray(p.batch.airspeed_mps), np.nan),
        "yaw_rad": np.where(mask, np.asarray(p.batch.yaw_rad), np.nan),
        "driveline_force_n": np.where(mask, np.asarray(p.batch.driveline_force_n), np.nan),
        "direction": np.asarray(p.batch.direction),
    }
    trace_dims = ["run", "sample"]
    all_dims = dict(dims, speed_mps=trace_dims, speed_integrated_mps=trace_dims, time_s=trace_dims,
                    airspeed_mps=trace_dims, yaw_rad=trace_dims, driveline_force_n=trace_dims, direction=["run"])
    idata = inference_data(fit, observed=observed, constant=constant,
                           log_likelihood={"speed_mps": log_likelihood_per_run(fit)},
                           predictive=posterior_predictive(fit) if predictive else None,
                           coords={"run": runs, "sample": np.arange(n)}, dims=all_dims)
    idata.log_likelihood["speed_mps"] = idata.log_likelihood["speed_mps"].rename({"speed_mps_dim_0": "run"}) \
        if "speed_mps_dim_0" in idata.log_likelihood.dims else idata.log_likelihood["speed_mps"]
    return idata


def _rows(idata: az.InferenceData, names: list[str]) -> pd.DataFrame:
    post = idata.posterior
    rows = []
    for name in names:
        da = post[name]
        extra = [d for d in da.dims if d not in ("chain", "draw")]
        labels = [(name, {})] if not extra else [
            (f"{name}[{r}]", {extra[0]: r}) for r in da.coords[extra[0]].values]
        for label, sel in labels:
            x = da.sel(sel) if sel else da
            arr = np.asarray(x)
            varies = arr.shape[1] > 3 and np.ptp(arr) > 0  # a constant (e.g. an absent part) has none
            ess_bulk = float(az.ess(arr, method="bulk")) if varies else math.nan
            ess_tail = float(az.ess(arr, method="tail")) if varies else math.nan
            r_hat = float(az.rhat(arr)) if varies and arr.shape[0] > 1 else math.nan
            q = np.percentile(arr, [2.5, 50.0, 97.5])
            rows.append({"parameter": label, "mean": float(arr.mean()), "sd": float(arr.std(ddof=1)),
                         "q2.5": q[0], "q50": q[1], "q97.5": q[2], "r_hat": r_hat,
                         "ess_bulk": ess_bulk, "ess_tail": ess_tail})
    return pd.DataFrame(rows, columns=list(SUMMARY_COLUMNS))


def summary_table(fit: NutsFit, idata: az.InferenceData) -> pd.DataFrame:
    """The rows of ``summary.csv``: free parameters, noise parameters, tau_* and derived."""
    p = fit.problem
    names = list(p.free) + [f"tau_{k}" for k in p.varying]
    names += [k for k in NOISE_SITES if k in idata.posterior]
    names += list(DERIVED)
    return _rows(idata, names)


def run_table(fit: NutsFit, idata: az.InferenceData) -> pd.DataFrame:
    """Per-run rows (initial speed, noise level, run-level coefficients), ``runs_summary.csv``."""
    names = ["v0_mps", "sigma_mps"] + [f"{k}_run" for k in fit.problem.varying]
    return _rows(idata, names)


def gate_failures(fit: NutsFit, gates: config.Gates = config.DEFAULT_GATES) -> list[str]:
    """The gates a fit fails, from its draws alone (for any kind of problem): the checks of
    :func:`diagnostics` over every posterior variable and the problem's derived quantities
    (:func:`inference_data`), without building the kind's full InferenceData."""
    return gate_check(fit, gates)[0]


def _extreme(ds, pick) -> tuple[float, str, int]:
    """The extreme value over every element of every variable of ``ds`` (``pick``: np.argmax or
    np.argmin over the finite ones), its variable and its flat index in that variable
    (nan, "", 0 when there is none)."""
    where = [(str(v), i) for v in ds.data_vars for i in range(ds[v].size)]
    x = np.concatenate([np.ravel(ds[v].values) for v in ds.data_vars]) if where else np.array([])
    ok = np.flatnonzero(np.isfinite(x))
    if not ok.size:
        return math.nan, "", 0
    k = ok[pick(x[ok])]
    return float(x[k]), *where[k]


def _element(ds, var: str, index: int) -> str:
    """``var`` for a scalar variable of ``ds``, ``var[index]`` for an element of a vector."""
    return var if ds[var].size == 1 else f"{var}[{index}]"


def gate_check(fit: NutsFit, gates: config.Gates = config.DEFAULT_GATES) -> tuple[list[str], dict[str, Any]]:
    """:func:`gate_failures` and the extremes they were read from: the largest R-hat and its
    quantity (with that quantity's bulk ESS), the smallest bulk and tail ESS and their
    quantities (recorded with a retry: an R-hat just over the gate on a quantity of low ESS is
    what converged chains show, docs/calibration.md)."""
    idata = inference_data(fit)
    post = idata.posterior
    chains = int(post.sizes["chain"])
    with np.errstate(invalid="ignore", divide="ignore"):
        rhat = az.rhat(post) if chains > 1 else None
        bulk = az.ess(post, method="bulk")
        tail = az.ess(post, method="tail")
    max_rhat, rhat_var, rhat_i = _extreme(rhat, np.argmax) if rhat is not None else (math.nan, "", 0)
    min_bulk, bulk_var, bulk_i = _extreme(bulk, np.argmin)
    min_tail, tail_var, tail_i = _extreme(tail, np.argmin)
    bfmi = np.atleast_1d(az.bfmi(idata))
    hits = float(np.mean(fit.stats["tree_depth"] >= fit.sampler.max_tree_depth))
    checks = {
        "divergences": int(fit.stats["diverging"].sum()) <= gates.max_divergences,
        "r_hat": chains < 2 or not math.isfinite(max_rhat) or max_rhat <= gates.max_r_hat,
        "ess_bulk": not math.isfinite(min_bulk) or min_bulk >= gates.min_ess_bulk_per_chain * chains,
        "ess_tail": not math.isfinite(min_tail) or min_tail >= gates.min_ess_tail_per_chain * chains,
        "bfmi": float(np.min(bfmi)) >= gates.min_bfmi,
        "tree_depth": hits <= gates.max_tree_depth_hits_fraction,
    }
    extremes = {
        "max_r_hat": max_rhat, "max_r_hat_quantity": _element(rhat, rhat_var, rhat_i) if rhat_var else "",
        "its_ess_bulk": float(np.ravel(bulk[rhat_var].values)[rhat_i]) if rhat_var else math.nan,
        "min_ess_bulk": min_bulk, "min_ess_bulk_quantity": _element(bulk, bulk_var, bulk_i) if bulk_var else "",
        "min_ess_tail": min_tail, "min_ess_tail_quantity": _element(tail, tail_var, tail_i) if tail_var else ""}
    return [k for k, ok in checks.items() if not ok], extremes


def diagnostics(fit: NutsFit, idata: az.InferenceData, summary: pd.DataFrame,
                gates: config.Gates = config.DEFAULT_GATES, runs: pd.DataFrame | None = None) -> dict:
    """Sampler diagnostics and the pass/fail of every gate.  ``runs`` is :func:`run_table`'s
    result when the caller already has it (computed here otherwise)."""
    chains = int(idata.posterior.sizes["chain"])
    div = int(fit.stats["diverging"].sum())
    depth = fit.stats["tree_depth"]
    hits = float(np.mean(depth >= fit.sampler.max_tree_depth))
    # every sampled quantity counts (per-run ones too), not only the summary rows
    every = pd.concat([summary, run_table(fit, idata) if runs is None else runs], ignore_index=True)
    max_rhat = float(np.nanmax(every["r_hat"])) if every["r_hat"].notna().any() else math.nan
    min_bulk = float(np.nanmin(every["ess_bulk"])) if every["ess_bulk"].notna().any() else math.nan
    min_tail = float(np.nanmin(every["ess_tail"])) if every["ess_tail"].notna().any() else math.nan
    bfmi = [float(x) for x in np.atleast_1d(az.bfmi(idata))]
    checks = {
        "divergences": div <= gates.max_divergences,
        "r_hat": (chains < 2) or (math.isfinite(max_rhat) and max_rhat <= gates.max_r_hat),
        "ess_bulk": bool(min_bulk >= gates.min_ess_bulk_per_chain * chains),
        "ess_tail": bool(min_tail >= gates.min_ess_tail_per_chain * chains),
        "bfmi": min(bfmi) >= gates.min_bfmi,
        "tree_depth": hits <= gates.max_tree_depth_hits_fraction,
    }
    out = {
        "method": "nuts",
        "model": fit.problem.spec.name,
        **fit.problem.settings(),
        "chains": chains,
        "draws_per_chain": int(idata.posterior.sizes["draw"]),
        "divergences": div,
        "max_r_hat": max_rhat,
        "min_ess_bulk": min_bulk,
        "min_ess_tail": min_tail,
        "mean_tree_depth": float(depth.mean()),
        "max_tree_depth": int(depth.max()),
        "tree_depth_limit_hits_fraction": hits,
        "mean_leapfrog_steps": float(fit.stats["num_steps"].mean()),
        "bfmi": bfmi,
        "timings_s": {k: round(v, 3) for k, v in fit.timings.items()},
        "retries": list(fit.retries),
        "coordinates": fit.coordinates,
        "chain_method": dict(fit.chain_method),
        "precondition": fit.sampler.precondition,
        "noise_scaled_metric": fit.noise_scaled_rates is not None,
        "noise_scaled_rates": None if fit.noise_scaled_rates is None else {
            k: round(v, 4) for k, v in fit.noise_scaled_rates.items()},
        "map": None if fit.map is None else {
            "success": fit.map.success, "iterations": fit.map.n_iter, "message": fit.map.message,
            "grad_max_scaled": fit.map.grad_max,
            "hessian_min_eigenvalue_scaled": fit.map.min_eigenvalue, **fit.map.diagnostics()},
        "map_converged": True if fit.map is None else bool(fit.map.success),
        "gates": {k: bool(v) for k, v in checks.items()},
        "thresholds": {
            "max_r_hat": gates.max_r_hat, "min_ess_bulk": gates.min_ess_bulk_per_chain * chains,
            "min_ess_tail": gates.min_ess_tail_per_chain * chains, "max_divergences": gates.max_divergences,
            "min_bfmi": gates.min_bfmi, "max_tree_depth_hits_fraction": gates.max_tree_depth_hits_fraction},
        "pass": bool(all(checks.values())),
    }
    out["failed"] = [k for k, v in checks.items() if not v]
    return out


def truth_derived(problem, truth: dict | None) -> dict[str, float]:
    """The derived road-load quantities at the true coefficients (simulated campaigns) of a
    problem with a drag model (:func:`~bayes_roadload.inference.problem.road_load_truth`)."""
    curve = problem.driveline_curve if isinstance(problem, FitProblem) else (0.0, 0.0, 0.0)
    return road_load_truth(problem, truth, driveline_curve=curve)


REMEDIES = {
    "divergences": "raise --target-accept (e.g. 0.95), and drop --no-noise-scaled-metric if given: the sampler "
                   "met curvature its step size cannot follow (with few runs, at small integrated-noise levels q)",
    "r_hat": "more draws (--draws) or warm-up (--warmup); if it persists the chains found different modes",
    "ess_bulk": "more draws (--draws)",
    "ess_tail": "more draws (--draws)",
    "tree_depth": "more warm-up (--warmup); check the MAP converged (diagnostics.json)",
    "bfmi": "more warm-up (--warmup); a heavy-tailed noise scale may need a tighter prior",
}
"""What to try when a gate fails (printed under the failure line)."""


def format_posterior_table(summary: pd.DataFrame, diag: dict, truth: dict | None = None) -> str:
    """A table for the terminal, headed by a loud line when the fit failed its gates."""
    lines = []
    if not diag["pass"]:
        lines.append("!! NUTS FIT FAILED ITS DIAGNOSTIC GATES: " + ", ".join(diag["failed"])
                     + " -- the posterior below is NOT reliable !!")
        lines.extend(f"   remedy: {REMEDIES[g]}" for g in diag["failed"] if g in REMEDIES)
    lines.append(f"NUTS, model {diag['model']}, {diag['pooling']}: {diag['chains']} chains x "
                 f"{diag['draws_per_chain']} draws, divergences {diag['divergences']}, max R-hat "
                 f"{diag['max_r_hat']:.3f}, min ESS bulk {diag['min_ess_bulk']:.0f} / tail "
                 f"{diag['min_ess_tail']:.0f}, mean tree depth {diag['mean_tree_depth']:.1f}, "
                 f"E-BFMI {min(diag['bfmi']):.2f}: {'PASS' if diag['pass'] else 'FAIL'}")
    header = f"{'quantity':<16}{'mean':>12}{'sd':>11}{'q2.5':>12}{'q97.5':>12}{'r_hat':>7}{'ess_bulk':>9}"
    if truth:
        header += f"{'truth':>10}{'in 95%':>8}"
    lines.append(header)
    lines.append("-" * len(header))
    for _, r in summary.iterrows():
        line = (f"{r['parameter']:<16}{r['mean']:>12.5g}{r['sd']:>11.3g}{r['q2.5']:>12.5g}{r['q97.5']:>12.5g}"
                f"{r['r_hat']:>7.3f}{r['ess_bulk']:>9.0f}")
        if truth:
            t = truth.get(r["parameter"])
            if isinstance(t, (int, float)):
                line += f"{t:>10.5g}{'yes' if r['q2.5'] <= t <= r['q97.5'] else 'NO':>8}"
        lines.append(line)
    return "\n".join(lines)


@dataclass
class FitReport:
    """Everything a fit directory holds (:func:`bayes_roadload.output.write_fit_dir`).

    Attributes
    ----------
    idata : ``posterior.nc``; None for a fit without draws (least squares).
    summary : ``summary.csv`` (:data:`SUMMARY_COLUMNS`).
    runs : ``runs_summary.csv``; None for a kind without per-run rows.
    diagnostics : ``diagnostics.json`` (:func:`diagnostics`, the gates); None for least squares.
    float_format : number format of the CSV tables (None: full precision).
    """

    idata: az.InferenceData | None
    summary: pd.DataFrame
    runs: pd.DataFrame | None
    diagnostics: dict | None
    float_format: str | None = None


def trace_report(fit: NutsFit, campaign=None, *, gates: config.Gates = config.DEFAULT_GATES) -> FitReport:
    """The report of a fit of speed traces: posterior with replicated traces, summary, per-run
    rows (initial speed, noise, run-level coefficients) and the gates over all of them."""
    idata = to_inference_data(fit)
    summary = summary_table(fit, idata)
    runs = run_table(fit, idata)
    return FitReport(idata, summary, runs, diagnostics(fit, idata, summary, gates, runs=runs))


def channel_inference_data(fit: NutsFit, *, derived: dict[str, np.ndarray] | None = None,
                           observed: dict[str, np.ndarray] | None = None, dims: dict | None = None,
                           coords: dict | None = None) -> az.InferenceData:
    """ArviZ data of a fit that has no speed-trace model (a measured channel, a wheel spin-down,
    steady-state forces): :func:`inference_data` with ``posterior`` (the draws and ``derived``
    [chain, draw, ...] quantities), ``observed_data`` and ``sample_stats``."""
    return inference_data(fit, derived=derived or {}, observed=observed or {}, coords=coords, dims=dims)


def channel_report(fit: NutsFit, names: list[str], *, kind: str, observed: dict[str, np.ndarray] | None = None,
                   run_sites: tuple[str, ...] = (), dims: dict | None = None, coords: dict | None = None,
                   gates: config.Gates = config.DEFAULT_GATES, extra: dict | None = None) -> FitReport:
    """The report of a fit without a speed-trace model: summary rows ``names`` then the
    problem's derived quantities, per-run rows of the ``run_sites`` (None when there are none),
    the gates of :func:`diagnostics` over every sampled quantity; ``kind`` (and ``extra``) are
    recorded in the diagnostics."""
    derived = fit.problem.derived(fit.samples)
    idata = channel_inference_data(fit, derived=derived, observed=observed, dims=dims, coords=coords)
    summary = _rows(idata, list(names) + list(derived))
    runs = _rows(idata, [k for k in run_sites if k in idata.posterior]) if run_sites else \
        pd.DataFrame(columns=list(SUMMARY_COLUMNS))
    diag = diagnostics(fit, idata, summary, gates, runs=runs)
    diag["kind"] = kind
    diag.update(extra or {})
    return FitReport(idata, summary, runs if run_sites else None, diag)
