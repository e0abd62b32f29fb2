"""Several test masses in one speed-trace fit: how a second mass separates rolling from drag.

Simulated campaigns of 2 opposite-direction pairs (case 2 winds, 2 m/s head and cross, basic drag
model, measurement noise, anemometers, no dynamics or system noise: the conftest's clean case),
all 4 runs at the vehicle's 1100 kg against pair 1 at 1100 kg and pair 2 at 1400 kg
(``simulate_campaign(masses_kg=...)``, common random numbers: the same wind and noise draws),
each fitted jointly by NUTS with ``three_term``.  Prints JSON per seed: posterior mean and sd of
AD, BD, CD0, the correlations AD-CD0 and AD-BD, the gates and the wall time.

    python benchmarks/trace_masses.py [SEED ...]
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bayes_roadload import config  # noqa: E402
from bayes_roadload import thesis  # noqa: E402
from bayes_roadload.inference.nuts import fit_nuts  # noqa: E402
from bayes_roadload.inference.results import summary_table, to_inference_data, diagnostics  # noqa: E402
from bayes_roadload.simulate import get_case, simulate_campaign  # noqa: E402

CASE = dataclasses.replace(get_case(2), model="basic", dynamics=False, measurement_noise=True, system_noise=False)
SAMPLER = config.SamplerConfig(num_warmup=300, num_samples=800, num_chains=2, seed=3, target_accept=0.95)
MASSES = {"one mass (4 runs at 1100 kg)": None, "two masses (2 runs at 1100 + 2 at 1400 kg)": [1100.0, 1400.0]}


def one(seed: int, masses, model: str = "three_term") -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        camp = simulate_campaign(CASE, pairs=2, seed=seed, masses_kg=masses)
        t0 = time.perf_counter()
        fit = fit_nuts(camp, model, sampler=SAMPLER)
        idata = to_inference_data(fit, predictive=False)
        s = summary_table(fit, idata)
        d = diagnostics(fit, idata, s)
    s = s.set_index("parameter")
    flat = {k: fit.samples[k].ravel() for k in ("AD", "BD", "CD0")}
    out = {k: [float(s.loc[k, "mean"]), float(s.loc[k, "sd"])] for k in ("AD", "BD", "CD0", "F50_N")}
    out.update({"corr_AD_CD0": float(np.corrcoef(flat["AD"], flat["CD0"])[0, 1]),
                "corr_AD_BD": float(np.corrcoef(flat["AD"], flat["BD"])[0, 1]),
                "pass": bool(d["pass"]), "wall_s": round(time.perf_counter() - t0, 1)})
    return out


def main(seeds=(11, 12, 13)):
    out = {"truth": {k: thesis.THESIS_COEFFICIENTS[k] for k in ("AD", "BD", "CD0")}}
    for seed in seeds:
        out[f"seed {seed}"] = {label: one(seed, masses) for label, masses in MASSES.items()}
        print(json.dumps({f"seed {seed}": out[f"seed {seed}"]}), flush=True)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main(tuple(int(a) for a in sys.argv[1:]) or (11, 12, 13))
