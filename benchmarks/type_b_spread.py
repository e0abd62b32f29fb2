"""The Type B standard uncertainty a speed-trace fit adds to each quantity, from the
least-squares step (:func:`bayes_roadload.inference.lsq.linear_sensitivities`, what ``fit``
uses), on the independent simulator's campaigns.

For each campaign (the calibration study's design seeds, every effect, Type B errors) and
model, ``sqrt(sum_s (c_{x,s} u_s)^2)`` of each quantity, and the truth to read it against; one
JSON line per (seed, pairs, model).  A model with a coefficient the data hardly identify
(least squares has no prior to hold it) shows sensitivities far beyond the quantity itself.

    python benchmarks/type_b_spread.py --seeds 100 101 102 103 104 105 --pairs 3 \
        > benchmarks/records/type_b_spread.jsonl
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.analysis.budget import type_b_shifts  # noqa: E402
from bayes_roadload.inference.lsq import linear_sensitivities  # noqa: E402
from bayes_roadload.inference.spec import load_model_spec  # noqa: E402
from bayes_roadload.simulate.independent import simulate_independent  # noqa: E402

QUANTITIES = ("AD", "BD", "CD0", "KD", "F50_N", "F0_N", "F1_N_per_kph", "F2_N_per_kph2")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[100, 101, 102, 103, 104, 105])
    ap.add_argument("--pairs", type=int, nargs="+", default=[3])
    ap.add_argument("--models", nargs="+", default=["four_term_tyre_lag", "four_term_tyre_lag_saturating"])
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    for pairs in args.pairs:
        for seed in args.seeds:
            campaign = simulate_independent(seed, pairs=pairs)
            for name in args.models:
                spec = load_model_spec(name)
                u, shifts, _ = type_b_shifts(campaign, spec)
                t0 = time.perf_counter()
                _, rows = linear_sensitivities(campaign, spec, shifts)
                sd = {q: float(np.sqrt(sum((row[q] * u[s]) ** 2 for s, row in rows.items() if q in row)))
                      for q in QUANTITIES}
                print(json.dumps({"seed": seed, "pairs": pairs, "model": name,
                                  "truth": {q: campaign.truth.get(q) for q in QUANTITIES},
                                  "type_b_sd": sd, "time_s": time.perf_counter() - t0}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
