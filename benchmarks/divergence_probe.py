"""Where a one-pair fit's divergent draws sit: thesis case C at one pair, the default model and
likelihood, no retry, at a given target acceptance; per coordinate the mean percentile of the
divergent draws among all draws and the share below the 10th percentile.

    python benchmarks/divergence_probe.py --case 9 --target-accept 0.8
    python benchmarks/divergence_probe.py --case 18 --target-accept 0.8 0.9 0.95

Records (JSON lines): ``benchmarks/records/gates/divergence_probe.jsonl``, with the commit.  The
figures of docs/method.md 4.5 and docs/calibration.md's gate section came from this probe: those
"before" the softplus for truncated priors were measured at commit 0fd1b39 (exp transform).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload import config  # noqa: E402
from bayes_roadload.inference.nuts import fit_nuts  # noqa: E402
from bayes_roadload.simulate import simulate_campaign  # noqa: E402

RECORDS = ROOT / "benchmarks" / "records" / "gates" / "divergence_probe.jsonl"


def probe(case: int, target_accept: float, seed: int = 0, noise: str = "integrated") -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        campaign = simulate_campaign(case, pairs=1, seed=seed)
        sampler = dataclasses.replace(config.DEFAULT_SAMPLER, retry=False, target_accept=target_accept,
                                      small_campaign_target_accept=None)
        fit = fit_nuts(campaign, "four_term", sampler=sampler, noise=noise)
    div = np.asarray(fit.stats["diverging"]).reshape(-1)
    where = {}
    for name, value in fit.samples.items():
        a = np.asarray(value)
        a = a.reshape(a.shape[0] * a.shape[1], -1)
        for j in range(a.shape[1]):
            pct = (np.argsort(np.argsort(a[:, j])) + 0.5) / a.shape[0]
            where[f"{name}[{j}]"] = {"mean_pct": float(pct[div].mean()) if div.any() else None,
                                     "below_p10": float(np.mean(pct[div] < 0.1)) if div.any() else None}
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    return {"case": case, "seed": seed, "noise": noise, "target_accept": target_accept, "commit": commit,
            "divergences": int(div.sum()), "steps_per_draw": float(np.mean(fit.stats["num_steps"])),
            "divergent_draws": where}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", type=int, required=True)
    ap.add_argument("--target-accept", type=float, nargs="+", default=[0.8])
    ap.add_argument("--noise", default="integrated", choices=("integrated", "white"))
    a = ap.parse_args(argv)
    RECORDS.parent.mkdir(parents=True, exist_ok=True)
    for ta in a.target_accept:
        rec = probe(a.case, ta, noise=a.noise)
        with RECORDS.open("a") as f:
            f.write(json.dumps(rec) + "\n")
        print(f"case {a.case} at {ta}: {rec['divergences']} divergences, {rec['steps_per_draw']:.1f} steps per draw",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
