"""The start of the default speed-trace fit on real traces (../shared/data/external, no
licence: read in place; skipped when the folder is absent)."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bayes_roadload import config
from bayes_roadload.data import Campaign, Vehicle

GNSS = (Path(__file__).resolve().parents[3] / "shared" / "data" / "external"
        / "Finding-Rolling-Resistance-for-Electric-Car" / "Data")
pytestmark = [pytest.mark.external, pytest.mark.skipif(not GNSS.is_dir(), reason=f"{GNSS} not present")]


def _eco_car_pair() -> Campaign:
    """One pair of the eco car's 1 Hz GNSS speed traces (km/h), cut at 1.5 m/s, in still air:
    the upstream analysis' 78 kg and 0.4294 m^2 (as benchmarks/real_data.py reads them)."""
    rows = []
    for name, direction in (("Michelin60A1", 1), ("Michelin60B1", -1)):
        v = np.loadtxt(GNSS / f"{name}.csv", delimiter=",", usecols=0) * config.KPH_TO_MPS
        last = int(np.flatnonzero(v < 1.5)[0])
        rows += [{"run": name, "time_s": float(t), "speed_mps": float(x), "direction": direction, "pair": 1}
                 for t, x in enumerate(v[:last])]
    return Campaign(pd.DataFrame(rows), Vehicle(mass_kg=78.0, effective_mass_kg=80.0, frontal_area_m2=0.4294))


def test_the_lag_defaults_start_and_map_on_a_light_cars_traces():
    """Least squares of the lag model put C_D0 at 26 and A_D below zero on these traces; the
    start takes the estimates the prior all but excludes at the prior's centre and refits the
    others, and the MAP from it is the lag-free model's optimum (speed noise ~0.15 m/s), not the
    local optimum with ~2 m/s of noise the prior's centres led to."""
    from bayes_roadload.inference.bayes import build_problem
    from bayes_roadload.inference.nuts import find_map, prepare_problem, unconstrained_posterior

    camp = _eco_car_pair()
    maps = {}
    for model in ("four_term", "four_term_tyre_lag"):
        problem, init = prepare_problem(build_problem(camp, model), camp)
        for k, prior in problem.priors.items():
            if prior.dist == "normal" and k in init:
                assert abs(float(init[k]) - prior.loc) <= 4 * prior.scale, (model, k)
        maps[model] = find_map(problem, {}, posterior=unconstrained_posterior(problem, init)).constrained
    lag, plain = maps["four_term_tyre_lag"], maps["four_term"]
    assert float(np.max(lag["sigma_mps"])) < 0.3
    # the lag's gain sits at its prior here, so the two models' optima nearly coincide
    for k in ("AD", "CD0"):
        assert float(lag[k]) == pytest.approx(float(plain[k]), rel=0.1), k


@pytest.mark.slow  # ~40 s: two MAPs and the sampler compile
def test_a_wall_in_the_apparent_coefficients_is_sampled_directly_from_the_start():
    """On the eco car's traces C_D0 is weakly fixed and kappa = b M g / (rho A / 2) large, so
    C_D0 = C_D0' - kappa B_D G_T leaves its support inside the apparent coefficients' space: the
    first attempt diverged 28-88 times in 2000 draws at any target acceptance.  The MAP's Laplace
    approximation shows the wall (``beyond_support`` >= MAX_BEYOND_SUPPORT_SHARE), the fit samples
    A_D, B_D, C_D0 directly from the start, says so in ``diagnostics.json``, and does not diverge
    (none in 2000 draws of either pair when this was built; 600 here)."""
    import dataclasses

    from bayes_roadload.inference.nuts import fit_nuts
    from bayes_roadload.inference.results import diagnostics, summary_table, to_inference_data

    sampler = dataclasses.replace(config.DEFAULT_SAMPLER, num_warmup=300, num_samples=300, retry=False, seed=7)
    fit = fit_nuts(_eco_car_pair(), "four_term_tyre_lag_admittance_pitch_shapes", sampler=sampler)
    assert fit.problem.apparent is None and "directly" in fit.coordinates and "beyond a support" in fit.coordinates
    idata = to_inference_data(fit)
    diag = diagnostics(fit, idata, summary_table(fit, idata))
    assert diag["coordinates"] == fit.coordinates and not fit.retries
    assert diag["divergences"] == 0
