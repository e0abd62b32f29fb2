"""Why the exact SBC of the tyre-lag default finds C_D0's intervals too narrow: one campaign's
truth, many noise draws, several arms.

The exact SBC of ``four_term_tyre_lag_driveline_informative`` (``sbc_study.py --exact --model
...``) gives C_D0 sd(z) 1.3-1.5 where every other coefficient is calibrated.  This probe holds the
truth and inputs of one exact-SBC campaign (``--seed``) and draws ``--replicates`` new noise
realisations (:class:`~bayes_roadload.analysis.sbc.ModelDrawnCampaign` with ``replicate``), for
each arm ``TEMPLATE:MODEL:NOISE``:

* TEMPLATE, the model whose prior-drawn campaign gives the inputs (time grid, airspeed, yaw)
  and the truth: the lag model's template is simulated with its tyre-lag gain (runs ~10 %
  longer than the four-term model's of the same seed);
* MODEL, the model the speed traces are drawn from and fitted with;
* NOISE, ``both`` (the likelihood's white + integrated noise), ``white`` or ``walk``.

Each fit is the MAP + Laplace fit of the batch door (``method="laplace"``: the Laplace
intervals are narrower than NUTS's, so the arms are compared with each other, not with 1).
Writes the records (CSV) and prints, per arm, the rms and sd of z = (mean - truth) / sd of
every coefficient.

Run (the committed record ``benchmarks/records/sbc/cd0_probe_seed24.csv``; L, F the lag and
four_term SBC models)::

    python benchmarks/sbc_cd0_probe.py --seed 24 --replicates 16 --workers 2 \\
        --arms $L:$L:both $L:$F:both $F:$F:both --records benchmarks/records/sbc/cd0_probe_seed24.csv
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from bayes_roadload.analysis.batch import FitJob, batch_client, coverage_summary, run_batch, successful
from bayes_roadload.analysis.sbc import ModelDrawnCampaign

LAG = "four_term_tyre_lag_driveline_informative"
FOUR = "four_term_driveline_informative"
ARMS = (f"{LAG}:{LAG}:both", f"{LAG}:{FOUR}:both", f"{FOUR}:{FOUR}:both", f"{LAG}:{LAG}:white")
COEFFICIENTS = ("AD", "BD", "CD0", "KD", "At", "Bt", "Ct", "tyre_lag_gain_per_mps")


def probe_jobs(seed: int, replicates: int, arms: list[str], pairs: int = 2) -> list[FitJob]:
    """One Laplace fit job per arm and replicate (tags: arm, template, noise, replicate)."""
    jobs = []
    for arm in arms:
        template, model, noise = arm.split(":")
        for rep in range(1, replicates + 1):
            factory = ModelDrawnCampaign(seed, pairs=pairs, model=model, replicate=rep, noise=noise,
                                         template_model=template)
            jobs.append(FitJob(f"cd0probe-{arm}-{seed}-{rep}", factory, model=model, method="laplace",
                               type_b=False, tags={"arm": arm, "template": template, "noise": noise,
                                                   "replicate": rep}))
    return jobs


def summary(records: pd.DataFrame) -> dict:
    """Per arm: fits, and for every coefficient the arm's model fits sd(z) and 95 % coverage
    (:func:`~bayes_roadload.analysis.batch.coverage_summary`) and the rms of z, which at one
    fixed truth also carries the priors' pull (a bias sd(z) does not see)."""
    ok = successful(records)
    cov = coverage_summary(ok, by=("arm",), quantities=[k for k in COEFFICIENTS if f"{k}_truth" in ok],
                           levels=(0.95,))
    out = {}
    for arm, g in ok.groupby("arm", sort=False):
        row = {"fits": len(g)}
        for _, c in cov[cov["arm"] == arm].iterrows():
            k = c["quantity"]
            if g[f"{k}_mean"].isna().any():
                continue  # a coefficient of another arm's model
            z = (g[f"{k}_mean"] - g[f"{k}_truth"]) / g[f"{k}_sd"]
            row[k] = {"rms_z": round(float(np.sqrt(np.mean(z**2))), 2), "sd_z": round(float(c["z_sd"]), 2),
                      "coverage95": round(float(c["coverage"]), 2)}
        out[arm] = row
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=24)
    ap.add_argument("--replicates", type=int, default=30)
    ap.add_argument("--arms", nargs="+", default=list(ARMS), metavar="TEMPLATE:MODEL:NOISE")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--records", type=Path, required=True)
    ap.add_argument("--summary-only", action="store_true", help="read --records, no fitting")
    args = ap.parse_args(argv)
    if not args.summary_only:
        with batch_client(args.workers) as client:
            records = run_batch(probe_jobs(args.seed, args.replicates, args.arms), client)
        args.records.parent.mkdir(parents=True, exist_ok=True)
        records.to_csv(args.records, index=False)
    records = pd.read_csv(args.records)
    print(json.dumps({"benchmark": "sbc_cd0_probe", "seed": args.seed, "records": str(args.records),
                      "arms": summary(records)}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
