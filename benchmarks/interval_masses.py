"""Several test masses in one interval fit: how a second mass separates rolling from drag.

Synthetic high-window runs (95 -> 70 km/h, five 5 km/h bands, F = M g AD + c v^2 in closed form,
0.05 s of timing noise per band), 12 runs at one test mass against 6 + 6 at two masses
(``mass_kg`` per run: the rolling force scales with the mass, the drag does not), fitted with
``split_f0_f2`` by NUTS.  Prints JSON: posterior mean and sd of AD and CD0, their correlation,
gates, wall time.

    python benchmarks/interval_masses.py
"""

from __future__ import annotations

import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bayes_roadload import config  # noqa: E402
from bayes_roadload.data import IntervalCampaign, Vehicle  # noqa: E402
from bayes_roadload.inference.intervals import fit_intervals_nuts, summary_table, to_inference_data  # noqa: E402
from bayes_roadload.inference.results import SUMMARY_COLUMNS, diagnostics  # noqa: E402
from bayes_roadload.physics.atmosphere import REFERENCE_AIR_DENSITY_KGPM3  # noqa: E402
from bayes_roadload.physics.integrate import quadratic_coastdown_time  # noqa: E402

AD, CD0, AREA = 0.008, 0.30, 2.2
GATES = np.array([95.0, 90.0, 85.0, 80.0, 75.0, 70.0]) * config.KPH_TO_MPS


def campaign(masses, seed=3, timing_sd_s=0.05):
    rng = np.random.default_rng(seed)
    c = 0.5 * REFERENCE_AIR_DENSITY_KGPM3 * AREA * CD0
    rows = []
    for r, m in enumerate(masses):
        me = 1530.0 + (m - 1500.0)
        for j in range(len(GATES) - 1):
            t = float(quadratic_coastdown_time(GATES[j + 1], GATES[j], m * config.GRAVITY_MPS2 * AD, 0.0, c, me))
            rows.append({"run": r + 1, "direction": 1 - 2 * (r % 2), "mass_kg": m, "speed_start_mps": GATES[j],
                         "speed_end_mps": GATES[j + 1], "interval_s": t + rng.normal(0.0, timing_sd_s)})
    return IntervalCampaign(pd.DataFrame(rows), Vehicle(1500.0, 1530.0, AREA))


def main():
    out = {"truth": {"AD": AD, "CD0": CD0}}
    for label, masses in (("one mass (12 x 1500 kg)", [1500.0] * 12),
                          ("two masses (6 x 1500 + 6 x 1900 kg)", [1500.0] * 6 + [1900.0] * 6)):
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = fit_intervals_nuts(campaign(masses), "split_f0_f2",
                                     sampler=config.SamplerConfig(seed=1, target_accept=0.9))
        idata = to_inference_data(fit)
        s = summary_table(fit, idata)
        d = diagnostics(fit, idata, s, runs=pd.DataFrame(columns=list(SUMMARY_COLUMNS)))
        s = s.set_index("parameter")
        out[label] = {"AD": [float(s.loc["AD", "mean"]), float(s.loc["AD", "sd"])],
                      "CD0": [float(s.loc["CD0", "mean"]), float(s.loc["CD0", "sd"])],
                      "corr_AD_CD0": float(np.corrcoef(fit.samples["AD"].ravel(), fit.samples["CD0"].ravel())[0, 1]),
                      "pass": d["pass"], "wall_s": round(time.perf_counter() - t0, 1)}
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
