"""Why K_D is low on the independent simulator's campaigns: the MAP of ``four_term`` (pooled)
with every effect of the independent simulator (Type B errors, 1 % run-to-run spread), and with
every effect but one (``simulate_independent(..., withhold=(effect,))``), 3 pairs, the calibration
study's design seeds.  One JSON line per (seed, variant): the MAP K_D against its truth, the
errors of C_D0 and A_D.

    python benchmarks/kd_ablation.py --seeds 100 102 > benchmarks/records/kd_ablation.jsonl

``--single``: every effect (``all``), no effect with and without the Type B errors and the spread
(``none``, ``none_clean``), and each effect alone without them::

    python benchmarks/kd_ablation.py --single --seeds 100 101 > benchmarks/records/kd_single.jsonl
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.inference.bayes import build_problem  # noqa: E402
from bayes_roadload.inference.nuts import find_map, prepare_problem  # noqa: E402
from bayes_roadload.simulate.independent import simulate_independent  # noqa: E402
from bayes_roadload.simulate.independent.effects import EFFECTS  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[100, 102])
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--single", action="store_true", help="each effect alone instead of every effect but one")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    # (name, effects (None: all), withheld, Type B errors, run-to-run sd)
    if args.single:
        variants = [("all", None, (), True, 0.01), ("none_clean", (), (), False, 0.0), ("none", (), (), True, 0.01)]
        variants += [(e, (e,), (), False, 0.0) for e in EFFECTS]
    else:
        variants = [("all", None, (), True, 0.01)] + [(f"all_but_{e}", None, (e,), True, 0.01) for e in EFFECTS]
    for seed in args.seeds:
        for name, effects, withhold, type_b, spread in variants:
            try:
                c = simulate_independent(seed, pairs=args.pairs, effects=effects, withhold=withhold, type_b=type_b,
                                         run_to_run_sd=spread)
                p, init = prepare_problem(build_problem(c, "four_term", pooling="pooled"), c)
                k = find_map(p, init).constrained
                rec = {"seed": seed, "variant": name, "KD_truth": c.truth["KD"], "KD": float(k["KD"]),
                       "CD0_err_pct": 100 * (float(k["CD0"]) / c.truth["CD0"] - 1),
                       "AD_err_pct": 100 * (float(k["AD"]) / c.truth["AD"] - 1)}
            except Exception as exc:  # noqa: BLE001 - a failed variant is recorded, not fatal
                rec = {"seed": seed, "variant": name, "error": f"{type(exc).__name__}: {exc}"[:200]}
            print(json.dumps(rec), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
