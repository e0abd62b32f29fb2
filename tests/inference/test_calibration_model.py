"""The paired-run airspeed calibration in the Bayesian model (thesis section 4.7.3).

One small NUTS fit (the conftest's 2-pair clean campaign with its readings 1 % high); the rest
are pair ratios on simulated data, model traces and refusals.
"""

from __future__ import annotations

import dataclasses
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import numpyro.distributions as dist
from numpyro import handlers
from scipy import stats

from bayes_roadload import config
from bayes_roadload.data import Campaign, CampaignError
from bayes_roadload.inference import bayes, load_model_spec
from bayes_roadload.inference.bayes import (
    airspeed_pair_ratios,
    build_problem,
    calibration_pairs,
    coastdown_model,
)
from bayes_roadload.simulate import simulate_campaign

from ..conftest import clean_case

SCALE = 1.01
"""Readings 1 % high: true airspeed = reading / SCALE."""
CAL_SAMPLER = config.SamplerConfig(num_warmup=200, num_samples=300, num_chains=2, seed=7, target_accept=0.95)
"""Small draw counts (the default tests' budget): enough for means and sd to ~5 % of an sd."""


def scaled(campaign: Campaign, scale: float = SCALE) -> Campaign:
    runs = campaign.runs.copy()
    runs["airspeed_mps"] = runs["airspeed_mps"] * scale
    truth = dict(campaign.truth, airspeed_factor=1.0 / scale)
    return Campaign(runs, campaign.vehicle, campaign.anemometer, campaign.tunnel, truth, dict(campaign.meta))


def with_runs(campaign: Campaign, runs) -> Campaign:
    return Campaign(runs.reset_index(drop=True), campaign.vehicle, campaign.anemometer, campaign.tunnel,
                    campaign.truth, dict(campaign.meta))


def trace(problem, seed=0):
    return handlers.trace(handlers.seed(coastdown_model, jax.random.PRNGKey(seed))).get_trace(problem)


@pytest.fixture
def no_speed_likelihood(monkeypatch):
    """Model traces without integrating the speed traces (op by op outside jit they cost
    seconds): for the tests of the sample sites, which the speed likelihood does not change."""
    monkeypatch.setattr(bayes, "run_log_likelihood", lambda problem, sample: jnp.zeros(problem.n_runs))


# ----------------------------------------------------------------------------- the ratio

@pytest.fixture(scope="module")
def twelve_pairs():
    """12 pairs of the clean case (2 m/s head and cross wind with Dryden turbulence, no
    instrument dynamics): every run has its own wind field, so the pairs are independent."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return simulate_campaign(clean_case(), pairs=12, seed=21)


def test_pair_ratio_is_unbiased_on_a_clean_campaign(twelve_pairs):
    batch, run_ids = twelve_pairs.to_batch()
    pairs = calibration_pairs(twelve_pairs, run_ids)
    assert len(pairs) == 12
    r = np.asarray(airspeed_pair_ratios(batch, pairs))
    se = r.std(ddof=1) / np.sqrt(r.size)
    # the simulator logs the true relative airspeed: factor 1.  3 standard errors: a
    # 1-in-370 event for an unbiased ratio (the campaign is seeded).
    assert abs(r.mean() - 1.0) < 3.0 * se, (r.mean(), se)
    # its scatter is the one the prior of airspeed_calibration_sd is centred on (0.01): within
    # the 99 % chi-square interval of 11 degrees of freedom around 0.0085 +- a factor 2
    assert 0.004 < r.std(ddof=1) < 0.02
    # a scaled reading scales the ratio exactly
    scaled_batch = batch._replace(airspeed_mps=batch.airspeed_mps * SCALE)
    np.testing.assert_allclose(np.asarray(airspeed_pair_ratios(scaled_batch, pairs)) * SCALE, r, rtol=1e-12)


def test_plain_airspeed_ratio_is_biased_by_cross_wind(twelve_pairs):
    """Why the yaw cosine: the plain ratio (yaw_factor = 0 gives cos = 1) reads the cross-wind
    as airspeed, v_r = sqrt((v + d w_a)^2 + w_c^2) > v + d w_a, so it is low; the paired
    difference is far beyond its own standard error."""
    batch, run_ids = twelve_pairs.to_batch()
    pairs = calibration_pairs(twelve_pairs, run_ids)
    d = np.asarray(airspeed_pair_ratios(batch, pairs)) - np.asarray(airspeed_pair_ratios(batch, pairs, 0.0))
    assert d.mean() > 5.0 * d.std(ddof=1) / np.sqrt(d.size)
    # second order in the yaw: ~ mean(psi^2) / 2 (2 m/s cross wind at 5-31 m/s: ~1 %)
    psi = np.asarray(batch.yaw_rad)[np.asarray(batch.mask)]
    assert 0.5 * np.mean(psi**2) / 2 < d.mean() < 2.0 * np.mean(psi**2) / 2


# ----------------------------------------------------------------------------- model files

@pytest.mark.parametrize("base", ["three_term", "four_term"])
def test_calibrated_model_file_frees_exactly_the_airspeed_factor(base):
    fixed_spec, free_spec = load_model_spec(base), load_model_spec(f"{base}_calibrated")
    assert free_spec.free == fixed_spec.free + ("airspeed_factor",)
    for attr in ("terms", "driveline", "lift", "air", "fixed", "fallback"):
        assert getattr(free_spec, attr) == getattr(fixed_spec, attr), attr
    assert {k: v for k, v in free_spec.priors.items() if k != "airspeed_factor"} == fixed_spec.priors
    prior = free_spec.priors["airspeed_factor"]
    assert prior.dist == "normal" and prior.loc == 1.0
    # weakly informative: the thesis' track factor 1.0806 is within one prior scale
    assert abs(1.0806 - prior.loc) < prior.scale


# ----------------------------------------------------------------------------- the model

def test_calibration_sites_and_their_density(small_campaign, no_speed_likelihood):
    fixed = build_problem(small_campaign, "three_term")
    assert not fixed.calibrated and fixed.calibration_pairs == ()
    assert not {"airspeed_calibration_sd", "airspeed_pair_ratio"} & set(trace(fixed))  # unchanged

    p = build_problem(small_campaign, "three_term_calibrated")
    assert p.calibrated and p.calibration_pairs == ((0, 1), (2, 3))
    assert p.initial["airspeed_calibration_sd"] == config.NOISE_PRIORS["airspeed_calibration_sd"]
    tr = trace(p)
    site = tr["airspeed_pair_ratio"]
    assert site["is_observed"] and site["value"].shape == (2,)
    expected = airspeed_pair_ratios(p.batch, p.calibration_pairs, p.fixed["yaw_factor"])
    np.testing.assert_allclose(site["value"], expected)
    f, s = float(tr["airspeed_factor"]["value"]), float(tr["airspeed_calibration_sd"]["value"])
    np.testing.assert_allclose(float(site["fn"].log_prob(site["value"]).sum()),
                               stats.norm(f, s).logpdf(np.asarray(expected)).sum(), rtol=1e-10)
    sd_prior = tr["airspeed_calibration_sd"]["fn"]
    np.testing.assert_allclose(float(sd_prior.mean), config.NOISE_PRIORS["airspeed_calibration_sd"])


def test_free_yaw_factor_enters_the_ratio(small_campaign):
    b = small_campaign.to_batch()[0]
    pairs = ((0, 1), (2, 3))
    r1, r2 = (np.asarray(airspeed_pair_ratios(b, pairs, y)) for y in (1.0, 1.5))
    assert np.all(r2 > r1)  # a larger yaw shrinks the along-track reading: a larger ratio


def test_pairs_come_from_the_pair_column(small_campaign, no_speed_likelihood):
    runs = small_campaign.runs
    # a run without a partner (its own pair id) contributes nothing
    lone = runs.copy()
    lone.loc[lone["run"] == 4, "pair"] = 9
    assert calibration_pairs(with_runs(small_campaign, lone)) == ((0, 1),)
    # two runs in the same direction are not a calibration pair: refused by the data layer, and
    # left out here when the table is changed after the campaign was validated
    same = runs.copy()
    same.loc[same["run"] == 2, "direction"] = 1.0
    with pytest.raises(CampaignError, match="pair id 1: runs 1 and 2 both have direction"):
        with_runs(small_campaign, same)
    changed = with_runs(small_campaign, runs)
    changed.runs = same
    with pytest.warns(RuntimeWarning, match="not opposite directions"):
        assert calibration_pairs(changed) == ((2, 3),)
    # no pair column: no calibration observations, and the fit says so
    no_pairs = with_runs(small_campaign, runs.drop(columns="pair"))
    with pytest.warns(RuntimeWarning, match="no opposite-direction pairs"):
        p = build_problem(no_pairs, "three_term_calibrated")
    assert not p.calibrated and "airspeed_pair_ratio" not in trace(p)


def test_free_factor_needs_the_measured_air(small_campaign):
    still = with_runs(small_campaign, small_campaign.runs.drop(columns=["airspeed_mps", "yaw_rad"]))
    with pytest.raises(ValueError, match="frees airspeed_factor.*airspeed_mps and yaw_rad"):
        build_problem(still, "four_term_calibrated")


def test_calibration_with_hierarchical_pooling_and_robust_noise(small_campaign, no_speed_likelihood):
    """One factor for every run (the instrument's): the hierarchical run effects are AD, BD,
    CD0 only, and the calibration observations stay; robust noise keeps them Gaussian."""
    p = build_problem(small_campaign, "three_term_calibrated", pooling="hierarchical")
    assert p.varying == ("AD", "BD", "CD0") and p.calibrated
    tr = trace(p)
    assert {"tau_AD", "tau_BD", "tau_CD0", "airspeed_calibration_sd", "airspeed_pair_ratio"} <= set(tr)
    assert "tau_airspeed_factor" not in tr and tr["airspeed_factor"]["value"].shape == ()
    tr = trace(build_problem(small_campaign, "three_term_calibrated", robust=True))
    assert {"student_df", "airspeed_calibration_sd"} <= set(tr)
    assert isinstance(tr["airspeed_pair_ratio"]["fn"].base_dist, dist.Normal)


# ----------------------------------------------------------------------------- recovery

SLOW_FIT = pytest.mark.slow  # the calibrated NUTS fit they share takes ~40 s; the calibration sites
# and their density stay in the default run (tests above)


@pytest.fixture(scope="module")
def scaled_campaign(small_campaign):
    return scaled(small_campaign)


@pytest.fixture(scope="module")
def calibrated_fit(scaled_campaign):
    from bayes_roadload.inference.nuts import fit_nuts

    return fit_nuts(scaled_campaign, "three_term_calibrated", sampler=CAL_SAMPLER)


@SLOW_FIT
def test_free_factor_recovers_the_scaled_reading(calibrated_fit, scaled_campaign):
    """The readings are 1 % high: the factor's posterior holds 1 / 1.01, and C_D0 is back
    around its truth (the analysis model is correctly specified on this campaign).  |z| < 3:
    a 1-in-370 event per quantity for a calibrated normal posterior (seeded)."""
    truth = scaled_campaign.truth
    for name in ("airspeed_factor", "CD0"):
        x = calibrated_fit.samples[name].ravel()
        z = (x.mean() - truth[name]) / x.std()
        assert abs(z) < 3.0, (name, x.mean(), x.std(), truth[name])
        lo, hi = np.percentile(x, [0.5, 99.5])
        assert lo <= truth[name] <= hi
    assert int(calibrated_fit.stats["diverging"].sum()) == 0
    # two pairs: the factor is known to about the pair scatter / sqrt(2) (prior sd 0.1)
    assert calibrated_fit.samples["airspeed_factor"].std() < 0.03


@SLOW_FIT
def test_wrongly_fixed_factor_puts_cd0_2_percent_low(scaled_campaign, calibrated_fit):
    """With the factor fixed at 1 the aerodynamic force is C_D0 (1.01 x true airspeed)^2:
    C_D0 comes out 1 / 1.01^2 - 1 = -1.97 % off (thesis 6.6: 2 % per 1 %), give or take its
    own estimation error (the joint least-squares standard error, honest with the initial
    speeds fitted), and far outside its interval."""
    from bayes_roadload.inference.lsq import fit_lsq

    g = fit_lsq(scaled_campaign, "three_term", grouping="all").groups[0]
    truth = scaled_campaign.truth["CD0"]
    expected = truth / SCALE**2
    assert abs(g.estimate["CD0"] - expected) < 3.0 * g.se["CD0"], (g.estimate["CD0"], g.se["CD0"])
    assert abs(g.estimate["CD0"] - truth) > 3.0 * g.se["CD0"]
    # the calibrated posterior is wider: it carries the calibration's uncertainty
    assert calibrated_fit.samples["CD0"].std() > 2.0 * g.se["CD0"]


@SLOW_FIT
def test_summary_has_an_airspeed_factor_row(calibrated_fit):
    from bayes_roadload.inference.results import summary_table, to_inference_data

    summary = summary_table(calibrated_fit, to_inference_data(calibrated_fit, predictive=False))
    row = summary.set_index("parameter").loc["airspeed_factor"]
    x = calibrated_fit.samples["airspeed_factor"].ravel()
    assert row["mean"] == pytest.approx(x.mean()) and row["q2.5"] < row["q50"] < row["q97.5"]
    assert np.isfinite(row["r_hat"])
