"""Design runs of the test-to-test choice: pooled against hierarchical on the same campaigns.

``--source case``: thesis case ``--case`` of the project's simulator; ``--source independent``:
the independent simulator (every effect, Type B errors, 1 % run-to-run spread).  ``--n``
seeds (from ``--seed0``) at ``--pairs`` pairs, each fitted with both poolings (model
``four_term``, 2 chains, ``--warmup`` / ``--draws``) through the batch door.  Writes the
records (CSV) and prints coverage, rms z, mean z and the relative posterior sd per quantity.

The records of docs/calibration.md's pooling table:

    python benchmarks/pooling_design.py --source case --case 14 --pairs 3 --n 4 --seed0 0 \
        --draws 1000 --records docs/calibration/design_case14_3pairs.csv
    python benchmarks/pooling_design.py --source independent --pairs 3 --n 6 --seed0 100 \
        --draws 500 --records docs/calibration/design_independent_3pairs.csv
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import sys
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload import config  # noqa: E402
from bayes_roadload.analysis.batch import FitJob, SimulatedCampaign, batch_client, run_batch  # noqa: E402
from bayes_roadload.simulate.independent import simulate_independent  # noqa: E402

QUANTITIES = ("AD", "BD", "CD0", "KD", "F50_N")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--source", choices=("case", "independent"), required=True)
    ap.add_argument("--case", type=int, default=14)
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--n", type=int, default=4)
    ap.add_argument("--seed0", type=int, default=0)
    ap.add_argument("--warmup", type=int, default=300)
    ap.add_argument("--draws", type=int, default=1000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--records", type=Path, required=True)
    args = ap.parse_args(argv)
    sampler = dataclasses.replace(config.DEFAULT_SAMPLER, num_warmup=args.warmup, num_samples=args.draws,
                                  num_chains=2)
    jobs = []
    for seed in range(args.seed0, args.seed0 + args.n):
        factory = (SimulatedCampaign(args.case, args.pairs, seed) if args.source == "case"
                   else functools.partial(simulate_independent, seed, pairs=args.pairs))
        for pooling in ("pooled", "hierarchical"):
            jobs.append(FitJob(f"{seed}-{pooling}", factory, pooling=pooling, sampler=sampler, tags={"seed": seed}))
    with batch_client(args.workers) as client:
        records = run_batch(jobs, client)
    args.records.parent.mkdir(parents=True, exist_ok=True)
    records.to_csv(args.records, index=False)
    for pooling, g in records.groupby("pooling"):
        print(f"{pooling}: gates passed {g['gate_pass'].mean():.2f}, mean fit {g['time_total_s'].mean():.0f} s")
        for q in QUANTITIES:
            z = (g[f"{q}_mean"] - g[f"{q}_truth"]) / g[f"{q}_sd"]
            print(f"  {q:6s} cover95 {g[f'{q}_in95'].mean():.2f}  rms z {np.sqrt(np.mean(z ** 2)):.2f}  "
                  f"mean z {z.mean():.2f}  sd {100 * (g[f'{q}_sd'] / g[f'{q}_truth'].abs()).mean():.2f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
