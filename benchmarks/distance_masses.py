"""Distance-time records at one and at two test masses: one joint fit each, same number of runs.

Simulated speed traces (case 9 without its wind: measurement noise, the thesis' system noise as
one offset per run) of 2 opposite-direction pairs, all at 1100 kg against pair 1 at 1100 kg and
pair 2 at 1400 kg (``simulate_campaign(masses_kg=...)``, common random numbers), timed past 13
markers 100 m apart (100 -> 1300 m from the start of the coast) with 0.02 s of timing error per
passing (:func:`~bayes_roadload.simulate.distances.distance_campaign_from_traces`), fitted by
NUTS with ``three_term`` (2 x 1000 draws, target acceptance 0.95).  Prints JSON per seed: posterior mean and sd of AD, BD, CD0, F50_N,
the correlation AD-CD0, the gates and the wall time.

    python benchmarks/distance_masses.py [SEED ...]
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bayes_roadload import config  # noqa: E402
from bayes_roadload.inference.distances import fit_distances_nuts  # noqa: E402
from bayes_roadload.inference.intervals import summary_table, to_inference_data  # noqa: E402
from bayes_roadload.inference.results import SUMMARY_COLUMNS, diagnostics, truth_derived  # noqa: E402
from bayes_roadload.simulate import SimulationSettings, get_case, simulate_campaign  # noqa: E402
from bayes_roadload.simulate.distances import distance_campaign_from_traces  # noqa: E402

CASE = dataclasses.replace(get_case(9), head_wind_mps=0.0, cross_wind_mps=0.0, system_noise=True)
SETTINGS = SimulationSettings(system_noise_mode="per_run")
SAMPLER = config.SamplerConfig(seed=1, target_accept=0.95, progress_bar=False)
"""2 x 1000 draws at target acceptance 0.95 (as tests/inference/test_distances.py's slow test)."""
MASSES = {"one mass (4 runs at 1100 kg)": None, "two masses (2 runs at 1100 + 2 at 1400 kg)": [1100.0, 1400.0]}


def campaign(seed: int, masses):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        traces = simulate_campaign(CASE, pairs=2, seed=seed, masses_kg=masses, settings=SETTINGS)
    return distance_campaign_from_traces(traces, timing_sd_s=0.02, seed=seed)


def one(seed: int, masses, model: str = "three_term", sampler: config.SamplerConfig = SAMPLER) -> dict:
    camp = campaign(seed, masses)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = fit_distances_nuts(camp, model, sampler=sampler)
        idata = to_inference_data(fit)
        s = summary_table(fit, idata)
        d = diagnostics(fit, idata, s, runs=pd.DataFrame(columns=list(SUMMARY_COLUMNS)))
    s = s.set_index("parameter")
    truth = dict(camp.truth, **truth_derived(fit.problem, camp.truth))
    out = {k: [float(s.loc[k, "mean"]), float(s.loc[k, "sd"]), float(truth[k])] for k in ("AD", "BD", "CD0", "F50_N")}
    out.update({"corr_AD_CD0": float(np.corrcoef(fit.samples["AD"].ravel(), fit.samples["CD0"].ravel())[0, 1]),
                "pass": bool(d["pass"]), "failed": d["failed"], "divergences": int(d["divergences"]),
                "max_r_hat": float(d["max_r_hat"]), "wall_s": round(time.perf_counter() - t0, 1)})
    return out


def main(seeds=(5, 6, 7)):
    out = {}
    for seed in seeds:
        out[f"seed {seed}"] = {label: one(seed, masses) for label, masses in MASSES.items()}
        print(json.dumps({f"seed {seed}": out[f"seed {seed}"]}), flush=True)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main(tuple(int(a) for a in sys.argv[1:]) or (5, 6, 7))
