"""Benchmark of the NUTS fit: Laplace-preconditioned against numpyro's default NUTS.

Reference campaign: 18 pairs (36 runs) at thesis case 14 conditions (basic drag model),
~450 samples per run, model four_term, pooled; also 6 and 54 pairs (12 and 108 runs) for the
scaling.  Prints one JSON object with, for each campaign: compile (first gradient) seconds,
LSQ-start, MAP, warm-up and sampling seconds, wall seconds of the whole fit, min bulk ESS, min
ESS per sampling second, divergences, R-hat, mean tree depth and leapfrog steps per draw.

Unpreconditioned NUTS saturates its trees (1023 leapfrog steps per draw) on this posterior, so
it is run with fewer draws (``--naive-warmup``, ``--naive-draws``): its per-draw cost and ESS
per second are what compare.  Run: ``python benchmarks/bench_fit.py [--pairs 6 18 54] [--skip-naive]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
import warnings

import jax
import numpy as np

from bayes_roadload import config
from bayes_roadload.inference.bayes import build_problem, coastdown_model
from bayes_roadload.inference.nuts import find_map, prepare_problem, run_nuts, unconstrained_posterior
from bayes_roadload.inference.results import diagnostics, summary_table, to_inference_data
from bayes_roadload.simulate import get_case, simulate_campaign


def compile_seconds(problem) -> float:
    from numpyro.infer.util import initialize_model

    info, potential, _, _ = initialize_model(jax.random.PRNGKey(0), coastdown_model, model_args=(problem,))
    t0 = time.perf_counter()
    jax.block_until_ready(jax.jit(jax.grad(potential))(info.z))
    return time.perf_counter() - t0


def report(fit, extra: dict) -> dict:
    idata = to_inference_data(fit, predictive=False)
    summary = summary_table(fit, idata)
    diag = diagnostics(fit, idata, summary)
    core = summary[summary["parameter"].isin(fit.problem.free)]
    min_ess = float(core["ess_bulk"].min())
    return dict(extra, **{
        "warmup_s": round(fit.timings["warmup_s"], 2),
        "sampling_s": round(fit.timings["sampling_s"], 2),
        "draws": int(fit.sampler.num_samples * fit.sampler.num_chains),
        "min_ess_bulk_coefficients": round(min_ess, 1),
        "min_ess_bulk_all": round(diag["min_ess_bulk"], 1),
        "min_ess_per_sampling_s": round(min_ess / fit.timings["sampling_s"], 2),
        "divergences": diag["divergences"],
        "mean_tree_depth": round(diag["mean_tree_depth"], 2),
        "mean_leapfrog_steps": round(diag["mean_leapfrog_steps"], 1),
        "max_r_hat": round(diag["max_r_hat"], 4),
        "gates_pass": diag["pass"],
        "gates_failed": diag["failed"],
    })


def fit_once(campaign, sampler: config.SamplerConfig) -> dict:
    """One fit the way ``fit_nuts`` does it, each stage timed (compilation included)."""
    t0 = time.perf_counter()
    problem, init = prepare_problem(build_problem(campaign, "four_term"), campaign)
    t1 = time.perf_counter()
    post = unconstrained_posterior(problem, init) if sampler.precondition == "laplace" else None
    m = find_map(problem, {}, posterior=post) if post is not None else None
    t2 = time.perf_counter()
    fit = run_nuts(problem, sampler=sampler, map_result=m, posterior=post)
    t3 = time.perf_counter()
    extra = {"runs": problem.n_runs, "unconstrained_dim": int(np.size(post.flat0)) if post is not None else None,
             "lsq_start_s": round(t1 - t0, 2), "map_s": round(t2 - t1, 2),
             "map_converged": None if m is None else m.success, "wall_s": round(t3 - t0, 2)}
    return report(fit, extra)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, nargs="+", default=[6, 18, 54],
                    help="campaign sizes (pairs); the first 18-pair one is the reference")
    ap.add_argument("--warmup", type=int, default=config.DEFAULT_SAMPLER.num_warmup)
    ap.add_argument("--draws", type=int, default=config.DEFAULT_SAMPLER.num_samples)
    ap.add_argument("--target-accept", type=float, default=config.DEFAULT_SAMPLER.target_accept)
    ap.add_argument("--naive-pairs", type=int, default=18)
    ap.add_argument("--naive-warmup", type=int, default=30)
    ap.add_argument("--naive-draws", type=int, default=30)
    ap.add_argument("--skip-naive", action="store_true")
    args = ap.parse_args()
    warnings.simplefilter("ignore")

    case = dataclasses.replace(get_case(14), model="basic")
    out = {"benchmark": "fit", "cpu_devices": jax.local_device_count(), "preconditioned": []}
    for pairs in args.pairs:
        campaign = simulate_campaign(case, pairs=pairs, seed=1)
        problem, _ = prepare_problem(build_problem(campaign, "four_term"), campaign)
        row = {"pairs": pairs, "samples_per_run_mean": round(float(np.asarray(problem.batch.mask).sum(axis=1).mean()), 1),
               "compile_gradient_s": round(compile_seconds(problem), 2)}
        row.update(fit_once(campaign, config.SamplerConfig(num_warmup=args.warmup, num_samples=args.draws,
                                                           target_accept=args.target_accept)))
        out["preconditioned"].append(row)
        print(json.dumps(row), file=sys.stderr, flush=True)
    if not args.skip_naive:
        campaign = simulate_campaign(case, pairs=args.naive_pairs, seed=1)
        naive = fit_once(campaign, config.SamplerConfig(num_warmup=args.naive_warmup, num_samples=args.naive_draws,
                                                        precondition="none"))
        out["naive"] = dict(naive, pairs=args.naive_pairs)
        ref = next((r for r in out["preconditioned"] if r["pairs"] == args.naive_pairs), None)
        if ref is not None:
            out["speedup_ess_per_s"] = round(ref["min_ess_per_sampling_s"] / max(naive["min_ess_per_sampling_s"], 1e-12), 1)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
