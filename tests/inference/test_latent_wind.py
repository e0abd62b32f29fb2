"""Speed-only campaigns: a latent along-track wind per opposite-direction pair."""

import dataclasses
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from bayes_roadload import config
from bayes_roadload.data import Campaign
from bayes_roadload.inference.bayes import build_problem, free_parameters, run_log_likelihood
from bayes_roadload.simulate import get_case, simulate_campaign


def speed_only(c):
    """The campaign without its anemometer channels (GNSS or CAN speed only)."""
    return Campaign(c.runs.drop(columns=["airspeed_mps", "yaw_rad"]), c.vehicle, c.anemometer, c.tunnel,
                    c.truth, dict(c.meta))


@pytest.fixture(scope="module")
def windy_pair():
    """One pair of case 9 (speed noise) with a 3 m/s along-track wind and no cross wind."""
    case = dataclasses.replace(get_case(9), head_wind_mps=3.0, cross_wind_mps=0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return speed_only(simulate_campaign(case, pairs=1, seed=4))


def test_one_wind_per_pair_signed_by_direction(windy_pair):
    p = build_problem(windy_pair, "speed_only_wind")
    assert p.latent_wind and list(p.wind_pair_index) == [0, 0]
    sample = {"AD": 0.01, "BD": 2e-4, "CD0": 0.4, "head_wind_mps": jnp.asarray([2.0])}
    per_run = np.asarray(free_parameters(p, sample)["head_wind_mps"])
    np.testing.assert_allclose(per_run, 2.0 * np.asarray(p.batch.direction))


def test_the_simulated_wind_is_the_likeliest(windy_pair):
    """At the true coefficients the speed traces prefer the simulated along-track wind (+3 m/s,
    a head wind for the + run) to still air and to the opposite sign."""
    p = build_problem(windy_pair, "speed_only_wind", noise="white")
    base = {"AD": 0.01, "BD": 2e-4, "CD0": 0.4, "v0_mps": jnp.asarray(p.batch.speed_mps[:, 0]),
            "sigma_mps": jnp.full(2, 0.05)}
    loglik = jax.jit(lambda w: run_log_likelihood(p, dict(base, head_wind_mps=w)).sum())
    ll = {w: float(loglik(jnp.asarray([w]))) for w in (-3.0, 0.0, 3.0)}
    assert ll[3.0] > ll[0.0] > ll[-3.0]


@pytest.mark.slow
def test_joint_fit_gives_one_set_where_per_run_fits_differ(windy_pair):
    """Seed 001's approach (each run alone, still air) gives two different answers; the joint fit
    with a latent wind per pair gives one set, consistent with the truth (measured: per-run BD
    6.7e-4 +- 0.36e-4 and 1.95e-4 +- 0.19e-4; joint AD 0.0107 +- 0.0008, BD 1.7e-4 +- 1.05e-4,
    CD0 0.400 +- 0.030, wind 2.83 +- 0.29 m/s; ~40 s)."""
    from bayes_roadload.inference.lsq import fit_lsq
    from bayes_roadload.inference.nuts import fit_nuts
    from bayes_roadload.inference.results import diagnostics, summary_table, to_inference_data

    per_run = fit_lsq(windy_pair, "three_term", grouping="run").groups
    bd = [(g.estimate["BD"], g.se["BD"]) for g in per_run]
    assert abs(bd[0][0] - bd[1][0]) > 5 * np.hypot(bd[0][1], bd[1][1])   # the two runs disagree
    fit = fit_nuts(windy_pair, "speed_only_wind", sampler=config.SamplerConfig(seed=1, target_accept=0.95))
    idata = to_inference_data(fit)
    s = summary_table(fit, idata)
    assert diagnostics(fit, idata, s)["pass"]
    s = s.set_index("parameter")
    for name, truth in (("AD", 0.01), ("BD", 2e-4), ("CD0", 0.4), ("head_wind_mps[0]", 3.0)):
        assert abs(s.loc[name, "mean"] - truth) < 3 * s.loc[name, "sd"], name
