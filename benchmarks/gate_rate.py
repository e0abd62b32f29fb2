"""How often the default fit passes every diagnostic gate first time, and after its one retry.

Campaigns: the thesis' simulation cases 1-19 (``--cases``) at ``--pairs`` pairs (seeded), and
``--independent`` campaigns of the independent simulator (``bayes_roadload.simulate.independent``,
1-``--max-pairs`` pairs).  Each is fitted with the default options of ``bayes-roadload fit``
(:class:`bayes_roadload.inference.kinds.FitOptions`: the registry's default model for speed
traces unless ``--model`` names another, default sampler with its retry,
:data:`bayes_roadload.config.DEFAULT_SAMPLER`, in its coordinates scaled with the integrated
noise unless ``--no-noise-scaled-metric``) through the batch door.  A fit passes
*first time* when it needed no retry; the records say which gate failed first
(``retry_failed``) and the time of the first attempt (``time_first_attempt_s``).

    python benchmarks/gate_rate.py --cases 1-19 --pairs 1 --independent 10 --workers 2
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.analysis.batch import FitJob, SimulatedCampaign, batch_client, passed_first_time, run_batch  # noqa: E402
from bayes_roadload.config import DEFAULT_SAMPLER  # noqa: E402
from bayes_roadload.inference.kinds import KINDS, FitOptions  # noqa: E402
from bayes_roadload.simulate.independent import simulate_independent  # noqa: E402

RECORDS = ROOT / "benchmarks" / "records" / "gates" / "gate_rate.csv"


def parse_cases(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        out += list(range(int(lo), int(hi or lo) + 1))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="1-19", help="thesis cases, e.g. 1-19 or 1,7,14")
    ap.add_argument("--pairs", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--independent", type=int, default=0, help="campaigns of the independent simulator")
    ap.add_argument("--max-pairs", type=int, default=3, help="pairs of the independent campaigns: 1..MAX")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--records", type=Path, default=RECORDS)
    ap.add_argument("--pooling", choices=("auto", "pooled", "hierarchical"), default="auto",
                    help="pooling of every fit (default: the default of `fit`)")
    ap.add_argument("--model", default=None, help="model variant of every fit (default: fit's for speed traces)")
    ap.add_argument("--noise-scaled-metric", action=argparse.BooleanOptionalAction,
                    default=DEFAULT_SAMPLER.noise_scaled_metric,
                    help="the sampler's coordinates scaled with the integrated noise (SamplerConfig.noise_scaled_metric; "
                         "default: the sampler's, on)")
    args = ap.parse_args(argv)
    o = FitOptions(pooling=args.pooling,
                   sampler=dataclasses.replace(DEFAULT_SAMPLER, noise_scaled_metric=args.noise_scaled_metric))
    common = dict(model=args.model or KINDS["traces"].default_model(None, o), pooling=o.pooling, noise=o.noise,
                  robust=o.robust, sampler=o.sampler)
    jobs = [FitJob(f"case{c}-p{args.pairs}-s{args.seed}", SimulatedCampaign(c, args.pairs, args.seed),
                   tags={"source": "thesis case", "case": c, "pairs": args.pairs}, **common)
            for c in parse_cases(args.cases)]
    for i in range(args.independent):
        seed = 200 + i
        pairs = int(np.random.default_rng([seed, 7]).integers(1, args.max_pairs + 1))
        jobs.append(FitJob(f"ind-{seed}", functools.partial(simulate_independent, seed, pairs=pairs),
                           tags={"source": "independent", "case": seed, "pairs": pairs}, **common))
    args.records.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    done: list[dict] = []

    def keep(rec):
        # each fit's record as it finishes: a run stopped early keeps what it did
        done.append(rec)
        pd.DataFrame.from_records(done).to_csv(args.records, index=False)

    with batch_client(args.workers) as client:
        records = run_batch(jobs, client, on_record=keep)
    wall = time.perf_counter() - t0
    records.to_csv(args.records, index=False)
    ok = records[records["error"].isna()] if "error" in records else records
    first = passed_first_time(ok)
    out = {"benchmark": "gate_rate", "fits": len(records), "errors": len(records) - len(ok),
           "pass_first_time": int(first.sum()), "pass_after_retry": int(ok["gate_pass"].astype(bool).sum()),
           "retried": int(ok["retries"].fillna(0).gt(0).sum()),
           "first_failures": ok.loc[ok["retries"].fillna(0).gt(0), "retry_failed"].value_counts().to_dict(),
           "still_failed": ok.loc[~ok["gate_pass"].astype(bool), "gates_failed"].value_counts().to_dict(),
           "mean_fit_s": float(ok["time_total_s"].mean()), "wall_s": round(wall, 1), "records": str(args.records)}
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
