"""Bayesian fit of distance-time records: the likelihood against an independent computation
(appendix D's closed form and a dense multivariate normal), and, slow, truth recovery and the
separation of rolling resistance from drag by a second test mass."""

import dataclasses
import warnings

import jax
import numpy as np
import pandas as pd
import pytest
from numpyro.infer.util import log_density
from scipy.stats import gamma, multivariate_normal, norm, truncnorm

from bayes_roadload import config
from bayes_roadload.data import DistanceCampaign, Vehicle
from bayes_roadload.inference.distances import build_distance_problem, distance_time_model, fit_distances_nuts
from bayes_roadload.inference.intervals import run_log_likelihood, summary_table, to_inference_data
from bayes_roadload.inference.results import SUMMARY_COLUMNS, diagnostics, truth_derived
from bayes_roadload.physics.atmosphere import REFERENCE_AIR_DENSITY_KGPM3
from bayes_roadload.physics.integrate import quadratic_coastdown_time
from bayes_roadload.simulate import SimulationSettings, get_case, simulate_campaign
from bayes_roadload.simulate.distances import distance_campaign_from_traces

AD, CD0, AREA, G = 0.008, 0.30, 2.2, config.GRAVITY_MPS2


def closed_form_times(x, v0, mass, ad=AD, cd0=CD0, extra_decel=0.0):
    """Passing times of F = M g AD + c v^2 (c = 0.5 rho A CD0) from v0 at x = 0: appendix D's
    t(v) with v(x) in closed form; a constant extra deceleration d adds M_e d to the constant
    force."""
    me = mass + 30.0
    a = mass * G * ad + me * extra_decel
    c = 0.5 * REFERENCE_AIR_DENSITY_KGPM3 * AREA * cd0
    v = np.sqrt((v0**2 + a / c) * np.exp(-2.0 * c * np.asarray(x) / me) - a / c)
    return np.asarray(quadratic_coastdown_time(v, v0, a, 0.0, c, me))


def marker_campaign(masses=(1500.0, 1800.0), n_markers=(7, 5), seed=0, sd=0.02):
    """Runs at their own masses past markers 100 m apart (unequal counts: padding), times
    from the closed form with a time origin of each run's own and Gaussian timing noise."""
    rng = np.random.default_rng(seed)
    rows = []
    for r, (m, k) in enumerate(zip(masses, n_markers)):
        x = 100.0 * np.arange(k)
        t = closed_form_times(x, 29.0 - r, m) + rng.normal(0.0, sd, k) + 600.0 * r + 12.0
        rows += [{"run": r + 1, "distance_m": 250.0 + xx, "time_s": tt, "mass_kg": m} for xx, tt in zip(x, t)]
    return DistanceCampaign(pd.DataFrame(rows), Vehicle(1500.0, 1530.0, AREA))


def test_likelihood_equals_the_dense_normal_of_closed_form_segment_times():
    camp = marker_campaign()
    problem = build_distance_problem(camp, "split_f0_f2")
    assert problem.free == ("AD", "CD0") and np.asarray(problem.mask).sum() == 6 + 4
    sample = {"AD": 0.0085, "CD0": 0.31, "v0_mps": np.array([29.1, 27.8]), "sigma_gate_s": 0.03,
              "band_noise_s_per_sqrt_s": 0.01, "run_decel_sd_mps2": 0.004}
    # one compiled program for the per-run likelihood and the numpyro model's log density
    both = jax.jit(lambda smp: (run_log_likelihood(problem, smp), log_density(distance_time_model, (problem,), {}, smp)[0]))
    ll, total = both(sample)
    ll = np.asarray(ll)
    for i, (run, g) in enumerate(camp.markers.groupby("run")):
        x = g["distance_m"].to_numpy() - g["distance_m"].iloc[0]
        obs = np.diff(g["time_s"].to_numpy())
        m, v0 = float(g["mass_kg"].iloc[0]), sample["v0_mps"][i]
        model_seg = np.diff(closed_form_times(x, v0, m, 0.0085, 0.31))
        h = 1e-6
        sens = (np.diff(closed_form_times(x, v0, m, 0.0085, 0.31, h))
                - np.diff(closed_form_times(x, v0, m, 0.0085, 0.31, -h))) / (2 * h)
        k = obs.size
        tri = 2.0 * np.eye(k) - np.eye(k, k=1) - np.eye(k, k=-1)
        cov = (sample["sigma_gate_s"] ** 2 * tri + sample["band_noise_s_per_sqrt_s"] ** 2 * np.diag(model_seg)
               + sample["run_decel_sd_mps2"] ** 2 * np.outer(sens, sens))
        ref = multivariate_normal(model_seg, cov).logpdf(obs)
        # RK4 (4 steps per 100 m, ~1e-9 s) and the finite-difference sensitivity: to 1e-6
        assert ll[i] == pytest.approx(ref, abs=1e-6)
    # the numpyro model: that likelihood plus the priors of the coefficients (truncated normals
    # of split_f0_f2), of the nuisances (Gamma, config.DISTANCE_NOISE_PRIORS) and of each run's
    # speed at its first marker (normal around the quadratic through its first three passings)
    prior = truncnorm.logpdf(0.0085, -1.0, np.inf, 0.01, 0.01) + truncnorm.logpdf(0.31, -0.4 / 0.15, np.inf, 0.4, 0.15)
    for name, mean in config.DISTANCE_NOISE_PRIORS.items():
        shape = config.DISTANCE_NOISE_PRIOR_SHAPES[name]
        prior += gamma.logpdf(sample[name], shape, scale=mean / shape)
    guess = np.asarray(problem.v0_guess_mps)
    assert np.all(np.abs(guess - [29.0, 28.0]) < 0.5)   # 0.02 s timing noise on 3.4 s segments
    prior += norm.logpdf(sample["v0_mps"], guess, config.DISTANCE_V0_PRIOR_SD_MPS).sum()
    assert float(total) == pytest.approx(float(ll.sum()) + prior, abs=1e-8)


SLOW_CASE = dataclasses.replace(get_case(9), head_wind_mps=0.0, cross_wind_mps=0.0, system_noise=True)
"""Case 9 without its wind (still air, as the model), measurement noise, and the thesis' system
noise as one offset per run: the runs differ from the nominal coefficients."""
SLOW_SAMPLER = config.SamplerConfig(seed=1, target_accept=0.95)
"""2 x 1000 draws at target acceptance 0.95: with 2 x 500 at 0.9 the two-mass fit of seed 5 had
divergences (the run-effect and segment-noise scales near 0), at 0.95 an R-hat of the noise
scales above the gate."""


def _distance_fit(masses):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        traces = simulate_campaign(SLOW_CASE, pairs=2, seed=5, masses_kg=masses,
                                   settings=SimulationSettings(system_noise_mode="per_run"))
        camp = distance_campaign_from_traces(traces, timing_sd_s=0.02, seed=5)
        fit = fit_distances_nuts(camp, "three_term", sampler=SLOW_SAMPLER)
        idata = to_inference_data(fit)
        summary = summary_table(fit, idata)
        diag = diagnostics(fit, idata, summary, runs=pd.DataFrame(columns=list(SUMMARY_COLUMNS)))
    corr = float(np.corrcoef(fit.samples["AD"].ravel(), fit.samples["CD0"].ravel())[0, 1])
    return camp, fit, summary.set_index("parameter"), diag, corr


@pytest.mark.slow
def test_two_masses_one_joint_distance_time_fit_recovers_and_separates():
    """~5 min (two NUTS fits).  2 pairs timed past 13 markers 100 m apart (0.02 s timing error):
    all at 1100 kg, against pair 2 at 1400 kg (the same wind, noise and timing draws)."""
    one_camp, one_fit, one, one_diag, one_corr = _distance_fit(None)
    camp, fit, two, diag, corr = _distance_fit([1100.0, 1400.0])
    assert camp.masses_kg() == {1: 1100.0, 2: 1100.0, 3: 1400.0, 4: 1400.0}
    # 4 runs barely identify the run effect's sd: the sampler still meets its funnel near 0 (7
    # divergences in 2000 draws measured for the two-mass fit, every other gate passed); the
    # one-mass fit, whose sds are compared, must have mixed (R-hat) though its gates fail
    assert set(diag["failed"]) <= {"divergences"} and diag["divergences"] <= 10, diag
    assert one_diag["max_r_hat"] < 1.05, one_diag
    truth = dict(camp.truth, **truth_derived(fit.problem, camp.truth))
    for name in ("AD", "BD", "CD0", "F50_N"):
        # within 3 posterior sd of the nominal truth (the runs' own coefficients scatter about it
        # by the system noise, 1 % in AD and CD0, well inside the posterior's 10 %)
        z = (two.loc[name, "mean"] - truth[name]) / two.loc[name, "sd"]
        assert abs(z) < 3.0, (name, z)
    # the second mass: AD's and CD0's sd fall by 32 % and 37 % (measured, seed 5) and the AD-CD0
    # correlation from 0.95 to 0.82; the Monte Carlo error of an sd from ~400 effective draws is
    # ~4 %, of the correlation ~0.01
    assert two.loc["AD", "sd"] < 0.8 * one.loc["AD", "sd"]
    assert two.loc["CD0", "sd"] < 0.8 * one.loc["CD0", "sd"]
    assert corr < one_corr - 0.08
