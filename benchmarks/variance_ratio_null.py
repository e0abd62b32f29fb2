"""The total-variance ratio of an SBC arm against its own null (``analysis.sbc.variance_ratio_null_p``).

For every parameter of an arm: mean((mean - truth)^2) / mean(sd^2) and its two-sided Monte
Carlo p under exact Gaussian posteriors with the arm's own posterior sds, with the
Bonferroni-adjusted p over the arm's parameters (the study's family-wise level is
``analysis.sbc.SBC_ALPHA``).  Writes a JSON record and prints a markdown table.

    R=benchmarks/records/sbc
    python benchmarks/variance_ratio_null.py --arm exact_calibrated \\
        --records $R/default_exact.partial.csv $R/default_exact_part2.csv \\
        --out $R/variance_ratio_null_default_exact.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.analysis.sbc import (SBC_ALPHA, SBC_PARAMETERS, VARIANCE_RATIO_NULL_DRAWS,  # noqa: E402
                                         variance_ratio_null_p)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", nargs="+", required=True, type=Path)
    ap.add_argument("--arm", required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--draws", type=int, default=VARIANCE_RATIO_NULL_DRAWS)
    args = ap.parse_args(argv)
    records = pd.concat([pd.read_csv(p) for p in args.records], ignore_index=True)
    arm = records[(records["arm"] == args.arm) & records["error"].isna()]
    params = [p for p in SBC_PARAMETERS if f"{p}_truth" in arm and arm[f"{p}_truth"].notna().any()]
    rows = []
    for i, p in enumerate(params):
        a = arm[arm[f"{p}_truth"].notna()]
        ratio, low, two = variance_ratio_null_p((a[f"{p}_mean"] - a[f"{p}_truth"]).to_numpy(float),
                                                a[f"{p}_sd"].to_numpy(float), draws=args.draws, seed=i)
        rows.append({"parameter": p, "n": int(len(a)), "ratio": ratio, "p_low": low, "p_two_sided": two,
                     "p_family": min(1.0, two * len(params))})
    record = {"records": [str(p.relative_to(ROOT)) if p.is_absolute() else str(p) for p in args.records],
              "arm": args.arm, "draws": args.draws, "family_alpha": SBC_ALPHA, "rows": rows}
    args.out.write_text(json.dumps(record, indent=1) + "\n")
    print(f"| parameter | n | MSE / mean var | p (ratio <= observed) | p two-sided | x {len(params)} parameters |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['parameter']} | {r['n']} | {r['ratio']:.2f} | {r['p_low']:.4f} | {r['p_two_sided']:.4f} | "
              f"{r['p_family']:.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
