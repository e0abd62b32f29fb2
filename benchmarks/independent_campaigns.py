"""Write seeded campaigns of the independent simulator (``bayes_roadload.simulate.independent``)
to a directory, for the calibration, sim-to-real and robustness studies.

Campaign ``i`` is ``simulate_independent(seed + i, ...)`` saved as ``OUT/ind_<seed+i>/``
(runs.csv, vehicle.toml with the declared values, truth.json with the true parameters and
every draw); an ``index.csv`` lists them with their vehicle, pairs, truth F50_N and effects.
Prints a JSON summary.

    python benchmarks/independent_campaigns.py --n 20 --pairs 1 12 --seed 100 --out runs/ind
    python benchmarks/independent_campaigns.py --n 5 --withhold turbulence --withhold tyre_warmup --out runs/ind_wo
    python benchmarks/independent_campaigns.py --n 5 --effects none --perfect --out runs/ind_clean
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.data import save_campaign  # noqa: E402
from bayes_roadload.simulate.independent import CATEGORIES, EFFECTS, simulate_independent  # noqa: E402


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10, help="number of campaigns")
    ap.add_argument("--pairs", type=int, nargs=2, default=(1, 12), metavar=("MIN", "MAX"),
                    help="pairs per campaign, drawn uniformly in [MIN, MAX] (default 1 12)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the first campaign")
    ap.add_argument("--withhold", action="append", default=[], choices=sorted(EFFECTS),
                    help="leave an effect out (repeatable)")
    ap.add_argument("--effects", nargs="*", default=None,
                    help="inject only these effects ('none' for none; default all)")
    ap.add_argument("--category", choices=sorted(CATEGORIES), default=None, help="vehicle category (default random)")
    ap.add_argument("--wind", choices=("random", "calm"), default="random")
    ap.add_argument("--perfect", action="store_true", help="perfect instruments (white speed noise only, no Type B)")
    ap.add_argument("--no-type-b", action="store_true", help="declared values equal the true ones")
    ap.add_argument("--run-to-run-sd", type=float, default=0.01)
    ap.add_argument("--sample-rate-hz", type=float, default=None, help="logging rate (default drawn from 1-20 Hz)")
    ap.add_argument("--out", type=Path, required=True, help="output directory")
    args = ap.parse_args(argv)
    effects = None if args.effects is None else [e for e in args.effects if e != "none"]
    if effects is not None and set(effects) - set(EFFECTS):
        ap.error(f"unknown effect(s) {sorted(set(effects) - set(EFFECTS))}; known: {sorted(EFFECTS)}")
    lo, hi = args.pairs
    if not 1 <= lo <= hi:
        ap.error("--pairs MIN MAX needs 1 <= MIN <= MAX")
    args.out.mkdir(parents=True, exist_ok=True)
    rows, t0 = [], time.time()
    for i in range(args.n):
        seed = args.seed + i
        pairs = int(np.random.default_rng([seed, 7]).integers(lo, hi + 1))
        t1 = time.time()
        c = simulate_independent(seed, pairs=pairs, category=args.category, wind=args.wind, effects=effects,
                                 withhold=args.withhold, type_b=not args.no_type_b,
                                 run_to_run_sd=args.run_to_run_sd, sample_rate_hz=args.sample_rate_hz,
                                 perfect_instruments=args.perfect)
        path = save_campaign(c, args.out / f"ind_{seed}")
        rows.append({"campaign": path.name, "seed": seed, "category": c.meta["category"], "pairs": pairs,
                     "sample_rate_hz": c.meta["sample_rate_hz"], "F50_N": c.truth["F50_N"],
                     "AD": c.truth["AD"], "BD": c.truth["BD"], "CD0": c.truth["CD0"], "KD": c.truth["KD"],
                     "effects": " ".join(c.truth["meta"]["effects"]), "seconds": round(time.time() - t1, 1)})
        print(f"{path}: {rows[-1]['category']}, {pairs} pairs, F50 {rows[-1]['F50_N']:.1f} N "
              f"({rows[-1]['seconds']} s)", file=sys.stderr)
    pd.DataFrame(rows).to_csv(args.out / "index.csv", index=False)
    summary = {"out": str(args.out), "campaigns": len(rows), "seconds": round(time.time() - t0, 1),
               "withheld": sorted(args.withhold), "perfect": args.perfect,
               "categories": sorted({r["category"] for r in rows})}
    print(json.dumps(summary, indent=2))
    return summary


if __name__ == "__main__":
    main()
