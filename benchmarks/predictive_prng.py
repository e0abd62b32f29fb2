"""CPU time of the posterior predictive (:func:`bayes_roadload.inference.results.posterior_predictive`:
its program compiled and run once) with each JAX PRNG, on the cold-start reference campaign
(``benchmarks/cold_start.py``: 18 pairs from the independent simulator, seed 2026, 4 Hz).

The campaign is fitted once with ``four_term`` and short chains (50 + 100 draws: the predictive's
cost does not depend on the draws' quality), then for each PRNG (``results.PREDICTIVE_PRNG``
set to it) the predictive of 200 draws is timed ``--repeats`` times with JAX's in-process
caches cleared in between, so that every repeat compiles.  Process CPU time (not wall time): the
compilation is single-threaded, so the figure is little affected by other work on the machine.
Appends one record per PRNG to ``benchmarks/records/performance/predictive_prng.jsonl``.

    python benchmarks/predictive_prng.py
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
import warnings
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "benchmarks" / "records" / "performance" / "predictive_prng.jsonl"
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from cold_start import REFERENCE_SEED, campaign  # noqa: E402
from gradient_cost import commit_of  # noqa: E402

PRNGS = ("threefry2x32", "rbg", "unsafe_rbg")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--draws", type=int, default=200)
    ap.add_argument("--records", type=Path, default=RECORDS)
    args = ap.parse_args(argv)

    import jax

    from bayes_roadload import config
    from bayes_roadload.data import load_campaign
    from bayes_roadload.inference import results
    from bayes_roadload.inference.nuts import fit_nuts

    with tempfile.TemporaryDirectory() as tmp:
        path, _ = campaign(18, Path(tmp), 4.0, REFERENCE_SEED)
        camp = load_campaign(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = fit_nuts(camp, "four_term", sampler=dataclasses.replace(
            config.DEFAULT_SAMPLER, num_warmup=50, num_samples=100, progress_bar=False))
    shipped = results.PREDICTIVE_PRNG
    rows = []
    try:
        for prng in PRNGS:
            results.PREDICTIVE_PRNG = prng
            cpu = []
            for _ in range(args.repeats):
                jax.clear_caches()
                t = time.process_time()
                jax.block_until_ready(results.posterior_predictive(fit, n_draws=args.draws)["speed_mps"])
                cpu.append(round(time.process_time() - t, 3))
            rows.append({"date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"), "commit": commit_of(ROOT),
                         "prng": prng, "shipped": prng == shipped, "draws": args.draws, "runs": fit.problem.n_runs,
                         "cpu_s": cpu, "min_cpu_s": min(cpu)})
            print(json.dumps(rows[-1]))
    finally:
        results.PREDICTIVE_PRNG = shipped
    args.records.parent.mkdir(parents=True, exist_ok=True)
    with args.records.open("a") as f:
        for r in rows:
            f.write(json.dumps(r) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
