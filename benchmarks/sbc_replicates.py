"""Replicates of one SBC truth: is the spread of the estimates what the intervals claim?

One draw of ``models/four_term_driveline_informative.toml``'s priors (SBC seed ``TRUTH_SEED``,
:func:`bayes_roadload.analysis.sbc.draw_from_prior`) is simulated ``N`` times as the SBC
simulator arm does (:func:`~bayes_roadload.analysis.sbc.sbc_case`, 2 pairs, driveline channel,
simulation seeds 100, 101, ...: new wind, new noise), each fitted by MAP + Laplace (no importance
correction, :func:`~bayes_roadload.inference.laplace.fit_laplace`).  Prints per replicate the z
of AD, BD, CD0, KD ((mean - truth) / sd) and the MAP's q, then per quantity the spread of the
means over the mean sd and sd(z).  ``VARIANT``: ``default`` (table 6.6 noise on every channel),
``no_input_noise`` (no airspeed and yaw noise: the inputs are exact), ``no_airspeed_noise``,
``no_yaw_noise``.  Comparing the variants shows whether the noise on the model's inputs shapes
the calibration.

Run::

    python benchmarks/sbc_replicates.py default 40 0 > benchmarks/records/sbc/replicates_default.log
    python benchmarks/sbc_replicates.py no_input_noise 40 0 > benchmarks/records/sbc/replicates_no_input_noise.log
"""
import json
import sys

import numpy as np

from bayes_roadload.analysis.sbc import SBC_MODEL, draw_from_prior, sbc_case, with_drawn_truth
from bayes_roadload.inference.laplace import fit_laplace
from bayes_roadload.simulate import SimulationSettings, simulate_campaign

QUANTITIES = ("AD", "BD", "CD0", "KD", "F50_N")


def main(variant: str, n: int, truth_seed: int = 0) -> None:
    base = SimulationSettings()
    kw = {"default": {}, "no_input_noise": dict(airspeed_noise_mps=0.0, yaw_noise_rad=0.0),
          "no_airspeed_noise": dict(airspeed_noise_mps=0.0), "no_yaw_noise": dict(yaw_noise_rad=0.0)}[variant]
    drawn = draw_from_prior(SBC_MODEL, truth_seed * 1000)
    settings = with_drawn_truth(base, drawn, **kw)
    rows = []
    for s in range(n):
        c = simulate_campaign(sbc_case(), 2, 100 + s, driveline=True, settings=settings)
        c.meta["pad_to_samples"] = 400
        f = fit_laplace(c, SBC_MODEL, importance=False, draws=2000)
        row = {}
        for p in QUANTITIES:
            x = np.asarray(f.samples[p]).ravel()
            row[p] = (float(x.mean()), float(x.std()), float(c.truth.get(p, np.nan)))
        row["q"] = float(np.asarray(f.samples["q_mps_per_sqrt_s"]).mean())
        rows.append(row)
        print(s, json.dumps({k: (v if k == "q" else round((v[0] - v[2]) / v[1], 2)) for k, v in row.items()}),
              flush=True)
    print("variant", variant)
    for p in QUANTITIES:
        m = np.array([r[p][0] for r in rows])
        sd = np.array([r[p][1] for r in rows])
        t = rows[0][p][2]
        print(p, "spread/sd", round(m.std(ddof=1) / sd.mean(), 2), "mean z", round(((m - t) / sd).mean(), 2),
              "sd(z)", round(((m - t) / sd).std(ddof=1), 2))
    print("q mean", np.mean([r["q"] for r in rows]))


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]) if len(sys.argv) > 3 else 0)
