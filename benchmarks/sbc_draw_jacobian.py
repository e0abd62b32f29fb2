"""Is the tyre-lag model's likelihood the density of its exact-SBC draw?  The log-determinant
of the draw's Jacobian.

The lag's force reads the logged speed, so the exact draw solves ``v = v_model(theta; v) +
noise`` (:func:`bayes_roadload.analysis.sbc.drawn_speed`) and the density of the logged speed
is the noise density at ``v - v_model(theta; v)`` times ``|det(I - d v_model / d v)|``.  The
likelihood leaves the determinant out; that is exact only while it does not depend on theta
over the posterior.  This script computes ``log det(I - J)`` at the truth of one exact-SBC
campaign (J by forward-mode autodiff over every real sample) and its derivative with respect
to each coefficient by central differences (5 % of the value).  Multiply a derivative by the
coefficient's posterior sd (the SBC records) for the change of the left-out term over one sd.

Run: ``python benchmarks/sbc_draw_jacobian.py --seed 24 > benchmarks/records/sbc/draw_jacobian_seed24.json``
(docs/calibration.md quotes it).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from bayes_roadload.analysis.sbc import ModelDrawnCampaign, PriorDrawnCampaign
from bayes_roadload.inference.bayes import build_problem, integrated_speed

MODEL = "four_term_tyre_lag_driveline_informative"
COEFFICIENTS = ("AD", "BD", "CD0", "KD", "tyre_lag_gain_per_mps")


def draw_jacobian(seed: int, pairs: int = 2, model: str = MODEL) -> dict:
    campaign = ModelDrawnCampaign(seed, pairs=pairs, model=model)()
    problem = build_problem(campaign, model)
    truth = {k: float(campaign.truth[k]) for k in problem.free}
    template = build_problem(PriorDrawnCampaign(seed, pairs=pairs, model=model)(), model)
    truth["v0_mps"] = np.asarray(template.batch.speed_mps)[:, 0]
    mask = np.asarray(problem.batch.mask, bool).reshape(-1)
    logged = jnp.asarray(problem.batch.speed_mps)

    def v_model(speed, params):  # reverse-mode integrator: forward-mode autodiff runs through it
        p = dataclasses.replace(problem, batch=problem.batch._replace(speed_mps=speed), gradients="autodiff")
        return integrated_speed(p, params)

    def log_det(params) -> tuple[float, float]:
        jac = np.asarray(jax.jacfwd(lambda s: v_model(s, params))(logged)).reshape(mask.size, mask.size)
        jac = jac[np.ix_(mask, mask)]
        return float(np.linalg.slogdet(np.eye(int(mask.sum())) - jac)[1]), float(np.trace(jac))

    v_model(logged, truth)  # fills the problem's caches with concrete values
    value, trace = log_det(truth)
    slopes = {}
    for k in COEFFICIENTS:
        h = 0.05 * abs(truth[k]) + 1e-9
        slopes[k] = (log_det({**truth, k: truth[k] + h})[0] - log_det({**truth, k: truth[k] - h})[0]) / (2 * h)
    return {"seed": seed, "pairs": pairs, "samples": int(mask.sum()), "log_det": value, "trace_J": trace,
            "d_log_det": slopes}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=24)
    ap.add_argument("--pairs", type=int, default=2)
    args = ap.parse_args(argv)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        print(json.dumps(draw_jacobian(args.seed, args.pairs), indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
