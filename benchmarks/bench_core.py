"""Benchmark of the core: simulation, RK4 integration of a campaign, classical fit.

Prints one JSON object.  Run: ``python benchmarks/bench_core.py [--pairs 18]``.
Times are wall-clock seconds on this machine; "first" includes JIT compilation.
"""

from __future__ import annotations

import argparse
import json
import time

import jax

from bayes_roadload.inference.lsq import fit_lsq
from bayes_roadload.inference.spec import load_model_spec
from bayes_roadload.physics import integrate_batch
from bayes_roadload.simulate import simulate_campaign


def timed(f, repeats=3):
    t0 = time.perf_counter()
    out = f()
    first = time.perf_counter() - t0
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        f()
        best = min(best, time.perf_counter() - t0)
    return out, first, best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=18)
    ap.add_argument("--case", type=int, default=14)
    args = ap.parse_args()

    campaign, sim_first, sim_best = timed(lambda: simulate_campaign(args.case, pairs=args.pairs, seed=1), 1)
    spec = load_model_spec("four_term")
    model, fixed, free = spec.build(campaign)
    batch, _ = campaign.to_batch()
    params = dict(fixed, **{k: campaign.truth[k] for k in free})
    f = jax.jit(lambda p: integrate_batch(model, p, batch)[0])
    _, int_first, int_best = timed(lambda: f(params).block_until_ready(), 5)
    grad = jax.jit(jax.grad(lambda cd: integrate_batch(model, dict(params, CD0=cd), batch)[0].sum()))
    _, grad_first, grad_best = timed(lambda: grad(0.4).block_until_ready(), 5)
    result, fit_first, fit_best = timed(lambda: fit_lsq(campaign, spec, grouping="pair"), 1)

    print(json.dumps({
        "benchmark": "core",
        "case": args.case,
        "pairs": args.pairs,
        "runs": batch.n_runs,
        "samples_padded_per_run": int(batch.time_s.shape[1]),
        "samples_total": int(batch.mask.sum()),
        "simulate_first_s": round(sim_first, 3),
        "simulate_repeat_s": round(sim_best, 3),
        "integrate_batch_first_s": round(int_first, 3),
        "integrate_batch_s": round(int_best, 5),
        "grad_first_s": round(grad_first, 3),
        "grad_s": round(grad_best, 5),
        "lsq_per_pair_first_s": round(fit_first, 3),
        "lsq_per_pair_repeat_s": round(fit_best, 3),
        "lsq_all_converged": bool(all(g.success for g in result.groups)),
        "devices": [str(d) for d in jax.devices()],
    }, indent=2))


if __name__ == "__main__":
    main()
