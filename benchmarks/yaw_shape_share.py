"""How much of the yaw drag of the independent simulator's campaigns lies where C_D(psi) is no
longer quadratic: per campaign, over its logged samples, the quartic's share of the yaw force
``sum q K4 psi^4 / sum q K_D psi^2`` (q = airspeed^2, the true K_D and K4 of the vehicle), the
share of the yaw force ``q psi^2`` at |psi| > 15 and > 25 deg, and the mean |psi|.

    python benchmarks/yaw_shape_share.py --seeds 100 101 102 103 104 105 --pairs 3 \
        > benchmarks/records/yaw_shape_share.jsonl
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.simulate.independent import simulate_independent  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[100, 101, 102, 103, 104, 105])
    ap.add_argument("--pairs", type=int, default=3)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    for seed in args.seeds:
        c = simulate_independent(seed, pairs=args.pairs)
        v = c.truth["meta"]["vehicle_true"]
        kd, k4 = v["kd_per_rad2"], v["k4_per_rad4"]
        psi = c.runs["yaw_rad"].to_numpy()
        q = c.runs["airspeed_mps"].to_numpy() ** 2
        yaw_force = q * psi**2
        print(json.dumps({
            "seed": seed, "pairs": args.pairs, "KD": kd, "K4": k4, "K4_over_KD": k4 / kd,
            "mean_abs_yaw_rad": float(np.mean(np.abs(psi))),
            "quartic_share": float(np.sum(q * k4 * psi**4) / np.sum(q * kd * psi**2)),
            "yaw_force_share_above_15deg": float(yaw_force[np.abs(psi) > np.deg2rad(15)].sum() / yaw_force.sum()),
            "yaw_force_share_above_25deg": float(yaw_force[np.abs(psi) > np.deg2rad(25)].sum() / yaw_force.sum()),
        }), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
