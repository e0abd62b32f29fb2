"""F50_N of the default's exact SBC arm scored against the draw's own road load.

Until 2026-12-06 the exact draw's truth (``analysis.sbc.ModelDrawnCampaign``) stated the
template simulator's tyre v^2 coefficient (0) where the model, and so the draw, holds its J2452
mean: the road load the fits were scored against was not the draw's.  The records keep each
fit's mean, sd and quantiles but not its draws, so this script recomputes the truth of F50_N for
every calibrated record (the campaign drawn again from its seed: the same draw) and scores the
stored intervals against it: z = (mean - truth) / sd and coverage from the stored quantiles.
Ranks need the draws and are not recomputed.

    python benchmarks/sbc_rescore_truth.py benchmarks/records/sbc/default_exact.partial.csv \\
        benchmarks/records/sbc/default_exact_part2.csv > benchmarks/records/sbc/default_exact_rescored.json
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np
import pandas as pd


def rescore(paths: list[str], quantity: str = "F50_N") -> dict:
    from bayes_roadload.analysis.sbc import ModelDrawnCampaign, z_sd_interval
    from bayes_roadload.inference.bayes import build_problem
    from bayes_roadload.inference.results import truth_derived

    rec = pd.concat([pd.read_csv(p) for p in paths], ignore_index=True)
    rec = rec[rec["arm"] == "exact_calibrated"]
    truths = []
    import jax

    for i, (seed, pairs, model) in enumerate(zip(rec["seed"], rec["pairs"], rec["model"])):
        if i % 10 == 9:  # every campaign compiles programs of its own shape: keep the process's memory maps bounded
            jax.clear_caches()
        campaign = ModelDrawnCampaign(int(seed), pairs=int(pairs), model=model)()
        truths.append(truth_derived(build_problem(campaign, model), campaign.truth)[quantity])
    new = np.asarray(truths)
    mean, sd, old = (rec[f"{quantity}_{c}"].to_numpy(float) for c in ("mean", "sd", "truth"))
    out = {"records": paths, "quantity": quantity, "n": int(len(rec))}
    for label, truth in (("as_recorded", old), ("draws_truth", new)):
        z = (mean - truth) / sd
        low, high = z_sd_interval(z)
        out[label] = {"z_mean": float(z.mean()), "z_sd": float(z.std(ddof=1)), "z_sd_low": float(low),
                      "z_sd_high": float(high),
                      "coverage95": float(np.mean((rec[f"{quantity}_q2.5"] <= truth) & (truth <= rec[f"{quantity}_q97.5"]))),
                      "coverage90": float(np.mean((rec[f"{quantity}_q5"] <= truth) & (truth <= rec[f"{quantity}_q95"]))),
                      "share_truth_above_median": float(np.mean(truth > rec[f"{quantity}_q50"]))}
    out["truth_change_N"] = {"median": float(np.median(new - old)), "min": float(np.min(new - old)),
                             "max": float(np.max(new - old))}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("records", nargs="+")
    a = ap.parse_args(argv)
    print(json.dumps(rescore(a.records), indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
