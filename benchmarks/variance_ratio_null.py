"""The total-variance ratio of an SBC arm against its own null (``analysis.sbc.variance_ratio_null_p``).

For every parameter of an arm: mean((mean - truth)^2) / mean(sd^2) and its two-sided Monte
Carlo p under exact Gaussian posteriors with the arm's own posterior sds, with the
Bonferroni-adjusted p over the arm's parameters (the study's family-wise level is
``analysis.sbc.SBC_ALPHA``).  Also measures how often three tests of the ratio reject an exact
arm at 5 % (``null_calibration``): the percentile-bootstrap interval of
``analysis.sbc.variance_ratio``, a normal approximation of the mean of (error^2 - sd^2), and the
Monte Carlo null, on 400 arms of 200 conjugate draws with skewed posteriors (theta ~ Gamma(a, 1),
y ~ Poisson(theta), posterior Gamma(a + y, 2)).  Writes a JSON record and prints a markdown table.

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

import numpy as np
import pandas as pd
from scipy.stats import norm

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.analysis.sbc import (SBC_ALPHA, SBC_PARAMETERS, VARIANCE_RATIO_NULL_DRAWS,  # noqa: E402
                                         variance_ratio, variance_ratio_null_p)


def null_calibration(arms: int = 400, fits: int = 200, seed: int = 1) -> dict:
    """Rejection rates at 5 % of the three tests of the ratio on exact conjugate arms."""
    rng = np.random.default_rng(seed)
    rejected = {"bootstrap_interval": 0, "normal_mean": 0, "monte_carlo_null": 0}
    for i in range(arms):
        a = 0.7 + rng.uniform(0.0, 2.0, fits)
        theta = rng.gamma(a, 1.0)
        y = rng.poisson(theta)
        error, sd = (a + y) / 2.0 - theta, np.sqrt(a + y) / 2.0
        _, lo, hi = variance_ratio(error, sd, seed=i)
        rejected["bootstrap_interval"] += not lo <= 1.0 <= hi
        d = error**2 - sd**2
        rejected["normal_mean"] += 2 * norm.sf(abs(d.mean()) / (d.std(ddof=1) / np.sqrt(fits))) < 0.05
        rejected["monte_carlo_null"] += variance_ratio_null_p(error, sd, draws=2000, seed=i)[2] < 0.05
    return {"arms": arms, "fits": fits, "level": 0.05, **{k: v / arms for k, v in rejected.items()}}


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
              "arm": args.arm, "draws": args.draws, "family_alpha": SBC_ALPHA, "rows": rows,
              "null_calibration": null_calibration()}
    args.out.write_text(json.dumps(record, indent=1) + "\n")
    print(f"| parameter | n | MSE / mean var | p (ratio <= observed) | p two-sided | x {len(params)} parameters |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['parameter']} | {r['n']} | {r['ratio']:.2f} | {r['p_low']:.4f} | {r['p_two_sided']:.4f} | "
              f"{r['p_family']:.3f} |")
    c = record["null_calibration"]
    print(f"\nExact conjugate arms ({c['arms']} x {c['fits']} fits) rejected at 5 %: bootstrap interval "
          f"{c['bootstrap_interval']:.3f}, normal approximation {c['normal_mean']:.3f}, Monte Carlo null "
          f"{c['monte_carlo_null']:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
