"""Where the anemometer's air and the body's differ: paired MAP + Laplace fits of one campaign of
the independent simulator (every effect, Type B errors, 1 % run-to-run spread), the simulator's
random streams untouched, with

* ``raw``: the campaign as simulated, read without the admittance (``admittance = "none"``);
* ``admittance``: the same campaign, the shipped admittance on (``admittance = "auto"``);
* ``felt``: the anemometer reads the air the body feels (its cup and vane states replaced by the
  body's relative air before the instrument's calibration errors and noise), no admittance in
  the analysis: what a perfect account of the air that acts on the body would give;
* ``no_body_admittance``: the simulator's body feels the wind at its centre at once (the
  anemometer as simulated), read without the admittance.

The model is ``four_term_tyre_lag_j2452_typeb`` (pooled) with ``admittance`` set as above
(``--model`` for another); the heavy priors are not used, so that only the air differs.  One
JSON line per seed: each variant's posterior mean over the truth for K_D, C_D0, B_D, F50_N and
K_D's z-score.  The patches act on ``simulate_run``'s returned trace or its ``admittance``
argument, which consume no random numbers, so the variants of a seed share every draw.

    python benchmarks/admittance_ablation.py --seeds 3004 3014 3026 > benchmarks/records/admittance_ablation.jsonl
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import bayes_roadload.simulate.independent.campaign as independent_campaign  # noqa: E402
from bayes_roadload.analysis.calibration import pairs_of  # noqa: E402
from bayes_roadload.inference.laplace import fit_laplace  # noqa: E402
from bayes_roadload.inference.spec import load_model_spec  # noqa: E402
from bayes_roadload.simulate.independent import simulate_independent  # noqa: E402

VARIANTS = ("raw", "admittance", "felt", "no_body_admittance")
QUANTITIES = ("KD", "CD0", "BD", "F50_N")
_SIMULATE_RUN = independent_campaign.simulate_run


def _patched_run(variant: str):
    def run(*args, **kwargs):
        if variant == "no_body_admittance":
            kwargs = dict(kwargs, admittance=False)
        trace = _SIMULATE_RUN(*args, **kwargs)
        if variant == "felt":
            trace = dataclasses.replace(trace, cup_mps=trace.airspeed_mps.copy(), vane_rad=trace.yaw_rad.copy())
        return trace
    return run


def one_seed(seed: int, model: str, draws: int) -> dict:
    base = load_model_spec(model)
    row: dict = {"seed": seed, "pairs": pairs_of(seed, 1, 12), "model": model}
    try:
        for variant in VARIANTS:
            independent_campaign.simulate_run = _patched_run(variant)
            campaign = simulate_independent(seed, pairs=row["pairs"])
            spec = dataclasses.replace(base, admittance="auto" if variant == "admittance" else "none")
            fit = fit_laplace(campaign, spec, pooling="pooled", draws=draws, importance=False)
            for q in QUANTITIES:
                row[f"{variant}_{q}"] = float(np.mean(fit.samples[q])) / campaign.truth[q]
            kd = np.asarray(fit.samples["KD"])
            row[f"{variant}_KD_z"] = float((kd.mean() - campaign.truth["KD"]) / kd.std())
    finally:
        independent_campaign.simulate_run = _SIMULATE_RUN
    meta = campaign.truth["meta"]
    row.update(category=campaign.meta["category"], KD=campaign.truth["KD"],
               length_m=campaign.vehicle.length_m, turbulence_sigma_mps=meta["wind"]["turbulence_sigma_mps"],
               mean_wind_mps=meta["wind"]["mean_speed_mps"])
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", required=True)
    ap.add_argument("--model", default="four_term_tyre_lag_j2452_typeb")
    ap.add_argument("--draws", type=int, default=400, help="Laplace draws per fit")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    for seed in args.seeds:
        print(json.dumps(one_seed(seed, args.model, args.draws)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
