"""Does the tyre-lag arm's C_D0 excess in exact SBC go through the lag gain's identification?

For each ``--seeds`` campaign of the tyre-lag model's exact SBC arm
(:class:`~bayes_roadload.analysis.sbc.ModelDrawnCampaign`, 2 pairs), two MAP + Laplace fits
(:func:`~bayes_roadload.inference.laplace.fit_laplace`, importance-corrected draws): the model as
it is (the gain ``tyre_lag_gain_per_mps`` free) and the same model with the gain fixed at the
campaign's true value.  Records C_D0's z = (mean - truth) / sd and sd of each.  If the excess came
from the gain trading with C_D0, knowing the gain would shrink |z| towards ``four_term``'s on the
same draw (docs/calibration.md, *The same draws without the lag*).

    python benchmarks/sbc_fixed_gain.py --seeds 46 124 24 16 \\
        --records benchmarks/records/sbc/fixed_gain_laplace.jsonl
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

MODEL = "four_term_tyre_lag_driveline_informative"
GAIN = "tyre_lag_gain_per_mps"


def with_gain_fixed(spec, value: float):
    """``spec`` with the lag gain fixed at ``value`` (no prior, no start value)."""
    from bayes_roadload.inference.spec import without_free

    return without_free(spec, (GAIN,), fixed={GAIN: value}, name=spec.name + "_gain_fixed")


def record(seed: int, pairs: int = 2) -> dict:
    """C_D0's z and sd with the gain free and fixed at its truth (module docstring)."""
    from bayes_roadload.analysis.sbc import ModelDrawnCampaign
    from bayes_roadload.inference.laplace import fit_laplace
    from bayes_roadload.inference.spec import load_model_spec

    campaign = ModelDrawnCampaign(seed, pairs=pairs, model=MODEL)()
    truth = campaign.truth
    spec = load_model_spec(MODEL)
    out = {"seed": seed, "pairs": pairs, "model": MODEL, "gain_truth": float(truth[GAIN]),
           "CD0_truth": float(truth["CD0"])}
    for arm, s in (("free", spec), ("fixed", with_gain_fixed(spec, truth[GAIN]))):
        x = np.asarray(fit_laplace(campaign, s).samples["CD0"], float).ravel()
        out[f"CD0_z_gain_{arm}"] = float((x.mean() - truth["CD0"]) / x.std())
        out[f"CD0_sd_gain_{arm}"] = float(x.std())
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", required=True)
    p.add_argument("--records", type=Path, required=True, help="JSON lines, one per seed (appended)")
    a = p.parse_args()
    a.records.parent.mkdir(parents=True, exist_ok=True)
    for seed in a.seeds:
        rec = record(seed)
        rec["date"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
        with a.records.open("a") as f:
            f.write(json.dumps(rec) + "\n")
        print(json.dumps(rec), flush=True)


if __name__ == "__main__":
    main()
