"""Cost of one gradient of the sampler's potential, and of its parts, pinned to one core as each
of the two parallel chains runs, on one of two campaigns (``--campaign``):

* ``reference``: the cold-start reference campaign (``benchmarks/cold_start.py``: 18 pairs from
  the independent simulator, seed 2026, 4 Hz), pooled;
* ``small``: the first 2-pair campaign of the independent-simulator coverage study (seed 1001 of
  ``benchmarks/calibration_study.py``: 4 runs of 580-730 samples at 5 Hz) with the default
  pooling for its size (hierarchical: the run effects integrated out, ``local_level_loglik_effects``).

For each model (``four_term`` and the speed-trace default), it times, in milliseconds
(the fastest of ``--repeats`` blocks of 50 calls, compiled first):

* ``potential_grad``: value and gradient of the MAP-whitened potential NUTS evaluates;
* ``integrate`` / ``integrate_grad``: the integrated speed traces of one draw, and the gradient
  of their sum with respect to the draw;
* ``loglik_grad``: the gradient of the speed traces' log-likelihood (integration included).

Each invocation appends one record per model to ``--records`` with the package's commit, so two
commits compare by running the script against each (``PYTHONPATH=<other checkout>``), in turn.
``--hold-ab`` also compiles the potential with and without the stage coefficients' hold
(``physics.integrate._hold``) and times the two in alternating blocks in one process, the
comparison least exposed to the machine's drift.  ``--docs`` regenerates the table in docs/performance.md (*The gradient's cost*) from the records.

    python benchmarks/gradient_cost.py --label "hold"
    python benchmarks/gradient_cost.py --docs
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "benchmarks" / "records" / "performance" / "gradient_cost.jsonl"
DOC = ROOT / "docs" / "performance.md"
BEGIN, END = "<!-- gradient_cost: begin -->", "<!-- gradient_cost: end -->"


def commit_of(path: Path) -> str:
    """The checkout's commit, with ``+dirty`` when its package has uncommitted changes."""
    def git(*a):
        return subprocess.run(["git", "-C", str(path), *a], capture_output=True, text=True).stdout.strip()
    return git("rev-parse", "--short", "HEAD") + ("+dirty" if git("status", "--porcelain", "bayes_roadload") else "")


def block_ms(f, arg) -> float:
    """Mean time of one call of ``f(arg)`` over a block of 50 calls (ms)."""
    import jax

    t0 = time.perf_counter()
    for _ in range(50):
        out = f(arg)
    jax.block_until_ready(out)
    return (time.perf_counter() - t0) / 50 * 1e3


def best_ms(f, arg, repeats: int) -> float:
    import jax

    jax.block_until_ready(f(arg))
    return round(min(block_ms(f, arg) for _ in range(repeats)), 4)


def hold_comparison(held, build, arg, repeats: int) -> dict:
    """The potential's value and gradient ``held`` (compiled with the stage coefficients held,
    ``physics.integrate._hold``) against ``build()`` compiled without (the hold replaced by the
    identity while tracing), timed in alternating blocks of 50 calls in this process: the
    medians over ``repeats`` blocks each, in ms, and the median of the per-block ratios."""
    import jax
    import numpy as np

    from bayes_roadload.physics import integrate

    jax.block_until_ready(held(arg))
    hold, integrate._hold = integrate._hold, lambda stages: stages
    try:
        unheld = build()
        jax.block_until_ready(unheld(arg))
    finally:
        integrate._hold = hold
    times = {"held": [], "unheld": []}
    for _ in range(repeats):
        for name, f in (("held", held), ("unheld", unheld)):
            times[name].append(block_ms(f, arg))
    ratio = np.median(np.asarray(times["held"]) / np.asarray(times["unheld"]))
    return {"ab_held_ms": round(float(np.median(times["held"])), 4),
            "ab_unheld_ms": round(float(np.median(times["unheld"])), 4), "ab_ratio": round(float(ratio), 3)}


def reference_campaign():
    from bayes_roadload.simulate.independent import simulate_independent

    return simulate_independent(2026, pairs=18, category="suv_van", wind="calm", sample_rate_hz=4.0)


def small_campaign():
    from bayes_roadload.analysis.calibration import pairs_of
    from bayes_roadload.simulate.independent import simulate_independent

    return simulate_independent(1001, pairs=pairs_of(1001, 1, 12))


def pooling_of(campaign_name: str, campaign, model: str) -> str:
    """The reference campaign pooled (as its cold-start record); the small one as ``fit``'s
    ``--pooling auto`` resolves it (hierarchical at 4 runs)."""
    if campaign_name == "reference":
        return "pooled"
    from bayes_roadload.inference.kinds import KINDS, FitOptions, resolve_pooling
    from bayes_roadload.inference.spec import load_model_spec

    return resolve_pooling(KINDS["traces"], campaign, load_model_spec(model), FitOptions()).pooling


CAMPAIGNS = {"reference": reference_campaign, "small": small_campaign}


def measure(model: str, repeats: int, hold_ab: bool = False, campaign_name: str = "reference") -> dict:
    from bayes_roadload._jax import configure_jax

    configure_jax()
    import jax
    import jax.numpy as jnp
    from jax.flatten_util import ravel_pytree

    import bayes_roadload
    from bayes_roadload.inference import bayes
    from bayes_roadload.inference.bayes import build_problem
    from bayes_roadload.inference.nuts import prepare_problem, unconstrained_posterior

    campaign = CAMPAIGNS[campaign_name]()
    pooling = pooling_of(campaign_name, campaign, model)
    problem, init = prepare_problem(build_problem(campaign, model, pooling=pooling), campaign)
    post = unconstrained_posterior(problem, init)
    flat0, unravel = ravel_pytree(post.z0)
    def build_potential():
        return jax.jit(jax.value_and_grad(lambda u: post.potential_fn(unravel(flat0 + post.scale * u))))

    potential = build_potential()
    draw = {k: jnp.asarray(v) for k, v in init.items()}
    times = {}
    if hold_ab:
        times.update(hold_comparison(potential, build_potential, jnp.zeros(flat0.size), repeats))
    times |= {
        "potential_grad": best_ms(potential, jnp.zeros(flat0.size), repeats),
        "integrate": best_ms(jax.jit(lambda s: bayes.integrated_speed(problem, s)), draw, repeats),
        "integrate_grad": best_ms(jax.jit(jax.grad(lambda s: bayes.integrated_speed(problem, s).sum())), draw, repeats),
        "loglik_grad": best_ms(jax.jit(jax.grad(lambda s: bayes.run_log_likelihood(problem, s).sum())), draw, repeats),
    }
    return {"model": model, "campaign": campaign_name, "pooling": "hierarchical" if problem.varying else "pooled",
            "runs": int(problem.batch.n_runs), "padded_samples": int(problem.batch.time_s.shape[-1]),
            "dimension": int(flat0.size), "commit": commit_of(Path(bayes_roadload.__file__).resolve().parents[1]),
            **times}


def markdown(records: list[dict]) -> str:
    lines = ["Generated by `python benchmarks/gradient_cost.py --docs` from "
             "`benchmarks/records/performance/gradient_cost.jsonl`: one core, milliseconds per call (the fastest "
             "of the blocks of 50) on the cold-start reference campaign (`reference`: 18 pairs, 36 runs, pooled) "
             "or the coverage study's first 2-pair campaign (`small`: 4 runs of 580-730 samples, hierarchical). "
             "Rows in the order they ran; `load` is the 1-minute load average at the start (the other core "
             "may have been busy).", "",
             "| date (UTC) | label | commit | campaign | model | potential value + gradient | integrate | "
             "integrate, gradient | log-likelihood, gradient | in turn: held / unheld (ratio) | load |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in records:
        ab = (f"{r['ab_held_ms']:.2f} / {r['ab_unheld_ms']:.2f} ({r['ab_ratio']:.2f})" if "ab_ratio" in r else "-")
        where = f"{r.get('campaign', 'reference')}, {r.get('pooling', 'pooled')}"
        lines.append(f"| {r['date']} | {r['label']} | {r['commit']} | {where} | {r['model']} | {r['potential_grad']:.2f} "
                     f"| {r['integrate']:.2f} | {r['integrate_grad']:.2f} | {r['loglik_grad']:.2f} | {ab} | {r['load']:.2f} |")
    return "\n".join(lines) + "\n"


def write_doc(records: list[dict]) -> None:
    text = DOC.read_text()
    head, rest = text.split(BEGIN)
    _, tail = rest.split(END)
    DOC.write_text(head + BEGIN + "\n\n" + markdown(records) + "\n" + END + tail)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", nargs="+", default=None, help="default: four_term and the speed-trace default")
    ap.add_argument("--label", default="", help="what this checkout is (kept in the record)")
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--core", type=int, default=1, help="the core to pin to")
    ap.add_argument("--campaign", choices=sorted(CAMPAIGNS), default="reference")
    ap.add_argument("--records", type=Path, default=RECORDS)
    ap.add_argument("--docs", action="store_true", help="only regenerate the docs table from the records")
    ap.add_argument("--hold-ab", action="store_true",
                    help="also time the potential with and without the stage coefficients' hold, in turn, in this process")
    args = ap.parse_args()
    if args.docs:
        write_doc([json.loads(line) for line in args.records.read_text().splitlines() if line.strip()])
        return
    os.sched_setaffinity(0, {args.core})
    from bayes_roadload.inference.kinds import KINDS, FitOptions

    models = args.models or ["four_term", KINDS["traces"].default_model(None, FitOptions())]
    load = os.getloadavg()[0]
    args.records.parent.mkdir(parents=True, exist_ok=True)
    for model in models:
        rec = {"date": time.strftime("%Y-%m-%d %H:%M", time.gmtime()), "label": args.label,
               "load": round(load, 2), **measure(model, args.repeats, args.hold_ab, args.campaign)}
        print(json.dumps(rec), flush=True)
        with args.records.open("a") as f:
            f.write(json.dumps(rec) + "\n")


if __name__ == "__main__":
    main()
