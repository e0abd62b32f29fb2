"""Cost of the Type B sensitivities of the MAP-refitting kinds: one compilation per shifted
campaign against one shared compilation (``inference.shift.SharedPotential``), the compile and
evaluation time of the fitted problem's potential gradient (what a MAP spends), and the
largest difference of a contribution c u between the two, relative to its quantity's largest
(quantities the model holds constant, below ``analysis.budget.CONSTANT_SD``, have no budget and
are left out).

    python benchmarks/type_b_cost.py   # appends to benchmarks/records/performance/type_b_cost.jsonl
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload import config  # noqa: E402
from bayes_roadload.analysis.budget import CONSTANT_SD, type_b_sensitivities  # noqa: E402
from bayes_roadload.inference.kinds import FitOptions, kind_of  # noqa: E402
from bayes_roadload.inference.nuts import NutsFit, unconstrained_posterior  # noqa: E402
from bayes_roadload.inference.shift import mode_of  # noqa: E402
from bayes_roadload.inference.spec import load_model_spec  # noqa: E402
from bayes_roadload.simulate import simulate_campaign  # noqa: E402
from bayes_roadload.simulate.distances import distance_campaign_from_traces  # noqa: E402
from bayes_roadload.simulate.intervals import interval_campaign_from_traces  # noqa: E402
from bayes_roadload.simulate.spindown import simulate_spindown  # noqa: E402
from bayes_roadload.simulate.steady import simulate_steady  # noqa: E402

OUT = ROOT / "benchmarks" / "records" / "performance" / "type_b_cost.jsonl"


def gradient_cost(problem, evals: int = 200) -> tuple[float, float]:
    """Seconds to compile (and run once) the jitted gradient of the problem's potential at its
    start, and milliseconds per evaluation after that."""
    import jax
    from jax.flatten_util import ravel_pytree

    post = unconstrained_posterior(problem, problem.initial)
    y0, unravel = ravel_pytree(post.z0)
    g = jax.jit(jax.grad(lambda y: post.potential_fn(unravel(y))))
    t0 = time.perf_counter()
    jax.block_until_ready(g(y0))
    t1 = time.perf_counter()
    for i in range(evals):
        out = g(y0 + 1e-9 * i)
    jax.block_until_ready(out)
    return t1 - t0, (time.perf_counter() - t1) / evals * 1e3


def main() -> int:
    warnings.simplefilter("ignore")
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    traces = simulate_campaign(1, pairs=1, seed=0)
    cases = [("intervals", interval_campaign_from_traces(traces), "split_f0_f2"),
             ("distances", distance_campaign_from_traces(traces), "three_term"),
             ("spindown", simulate_spindown(), "undriven_spindown"),
             ("steady", simulate_steady(9, pairs=1, seed=0), "four_term")]
    with OUT.open("a") as f:
        for kind, campaign, model in cases:
            spec = load_model_spec(model)
            problem = kind_of(campaign).problem(campaign, spec, FitOptions())
            compile_s, eval_ms = gradient_cost(problem)
            fit = NutsFit(problem, {}, {}, mode_of(problem), config.DEFAULT_SAMPLER)
            t0 = time.perf_counter()
            own = type_b_sensitivities(campaign, spec)
            t1 = time.perf_counter()
            shared = type_b_sensitivities(campaign, spec, fit=fit)
            t2 = time.perf_counter()
            # each contribution c u against the largest of its quantity (what a budget reads)
            largest = {q: max((abs(x) * own.u[s] for s, x in row.items()), default=0.0)
                       for q, row in own.sensitivity.items()}
            rel = max((abs(shared.sensitivity[q][k] - c) * own.u[k] / largest[q]
                       for q, row in own.sensitivity.items() if largest[q] > CONSTANT_SD
                       for k, c in row.items()), default=0.0)
            rec = {"commit": commit, "kind": kind, "model": model, "sources": len(own.sources),
                   "own_s": round(t1 - t0, 2), "shared_s": round(t2 - t1, 2), "max_contribution_difference": rel,
                   "gradient_compile_s": round(compile_s, 2), "gradient_eval_ms": round(eval_ms, 3)}
            f.write(json.dumps(rec) + "\n")
            print(json.dumps(rec))
    return 0


if __name__ == "__main__":
    sys.exit(main())
