"""Benchmark of the NUTS fit: Laplace-preconditioned against numpyro's default NUTS.

Reference campaign: 18 pairs (36 runs) at thesis case 14 conditions (basic drag model),
~400-500 samples per run, model four_term, pooled.  Prints one JSON object with, for each
sampler: compile (first gradient) seconds, MAP seconds, warm-up and sampling seconds, min bulk
ESS, min ESS per sampling second, divergences, mean tree depth and leapfrog steps per draw.

Unpreconditioned NUTS saturates its trees (1023 leapfrog steps per draw) on this posterior, so
it is run with fewer draws (``--naive-warmup``, ``--naive-draws``): its per-draw cost and ESS
per second are what compare.  Run: ``python benchmarks/bench_fit.py [--pairs 18]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
import warnings

import jax
import numpy as np

from bayes_roadload import config
from bayes_roadload.inference.bayes import build_problem, coastdown_model
from bayes_roadload.inference.nuts import find_map, initial_values, run_nuts
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
    })


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=18)
    ap.add_argument("--warmup", type=int, default=500)
    ap.add_argument("--draws", type=int, default=1000)
    ap.add_argument("--naive-warmup", type=int, default=100)
    ap.add_argument("--naive-draws", type=int, default=100)
    ap.add_argument("--skip-naive", action="store_true")
    args = ap.parse_args()
    warnings.simplefilter("ignore")

    case = dataclasses.replace(get_case(14), model="basic")
    campaign = simulate_campaign(case, pairs=args.pairs, seed=1)
    problem = build_problem(campaign, "four_term")
    out = {"benchmark": "fit", "pairs": args.pairs, "runs": problem.n_runs,
           "samples_per_run_mean": float(np.asarray(problem.batch.mask).sum(axis=1).mean()),
           "compile_gradient_s": round(compile_seconds(problem), 2)}

    t0 = time.perf_counter()
    m = find_map(problem, initial_values(problem, campaign))
    map_s = time.perf_counter() - t0
    pre = run_nuts(problem, sampler=config.SamplerConfig(num_warmup=args.warmup, num_samples=args.draws),
                   map_result=m)
    out["preconditioned"] = report(pre, {"map_s": round(map_s, 2), "map_converged": m.success})
    if not args.skip_naive:
        naive = run_nuts(problem, sampler=config.SamplerConfig(num_warmup=args.naive_warmup,
                                                               num_samples=args.naive_draws, precondition="none"))
        out["naive"] = report(naive, {})
        out["speedup_ess_per_s"] = round(out["preconditioned"]["min_ess_per_sampling_s"]
                                         / max(out["naive"]["min_ess_per_sampling_s"], 1e-12), 1)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
