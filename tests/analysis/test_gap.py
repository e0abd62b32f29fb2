"""Gap metrics and localisation on residuals whose structure is known."""

import math

import numpy as np
import pytest

from bayes_roadload.analysis.gap import (TREND_WINDOW_S, localise, plot_localisation, plot_residuals,
                                         residual_structure)


def grid(runs=4, n=400, dt=0.25):
    t = np.tile(np.arange(n) * dt, (runs, 1))
    return t, np.ones((runs, n), bool)


def test_white_noise_sits_at_its_floor_with_no_autocorrelation():
    t, m = grid()
    rng = np.random.default_rng(0)
    sigma = 0.05
    r = sigma * rng.standard_normal(t.shape)
    s = residual_structure(r, m, t, sigma)
    # floor: sigma / sqrt(window samples) = 0.05 / sqrt(80)
    assert s["trend_floor_mps"] == pytest.approx(sigma / math.sqrt(TREND_WINDOW_S / 0.25), rel=1e-9)
    # the moving average of white noise has that rms; over 4 runs x 5 independent windows its
    # estimate scatters by ~1/sqrt(2 x 20) = 16 %: 3 standard errors
    assert abs(s["trend_rms_mps"] / s["trend_floor_mps"] - 1.0) < 0.5
    # lag-1 autocorrelation of white noise: sd 1/sqrt(N) per run, mean of 4 runs: 1/sqrt(1600)
    assert abs(s["lag1_autocorr"]) < 4.0 / math.sqrt(1600)


def test_a_slow_trend_is_measured_and_autocorrelated():
    t, m = grid()
    trend = 0.2 * np.sin(2 * np.pi * t / 100.0)  # 100 s period, passes the 20 s window nearly whole
    s = residual_structure(trend, m, t, 0.05)
    assert s["trend_rms_mps"] == pytest.approx(0.2 / math.sqrt(2), rel=0.1)
    assert s["lag1_autocorr"] > 0.99


def test_padded_samples_are_ignored():
    t, m = grid(runs=2, n=200)
    r = np.zeros_like(t)
    m[1, 150:] = False
    r[1, 150:] = 100.0  # padding garbage must not count
    s = residual_structure(r, m, t, 0.05)
    assert s["trend_rms_mps"] == 0.0


def test_localise_finds_the_variable_that_carries_the_misfit(tmp_path):
    t, m = grid(runs=4, n=300)
    rng = np.random.default_rng(1)
    speed = 30.0 - 0.08 * t
    direction = np.repeat(np.array([1.0, -1.0, 1.0, -1.0])[:, None], t.shape[1], axis=1)
    yaw = 0.1 * rng.standard_normal(t.shape)
    resid = 0.02 * direction + 0.005 * rng.standard_normal(t.shape)  # a direction offset (a gradient)
    run = np.repeat(np.arange(1.0, 5.0)[:, None], t.shape[1], axis=1)
    loc = localise(resid, m, {"time_s": t, "speed_mps": speed, "yaw_rad": yaw, "direction": direction, "run": run})
    # the direction offset explains 0.02^2 / (0.02^2 + 0.005^2) = 94 % of the variance
    assert loc["direction"]["eta2"] == pytest.approx(0.0004 / 0.000425, abs=0.02)
    assert loc["where"][0] in ("direction", "run")  # run bins nest direction: equal eta2
    assert loc["yaw_rad"]["eta2"] < 0.05
    assert loc["direction"]["mean_residual_mps"][0] == pytest.approx(-0.02, abs=0.002)
    assert sum(loc["speed_mps"]["n"]) == m.sum()
    assert plot_localisation(loc, tmp_path / "loc.png").stat().st_size > 1000
    assert plot_residuals(t, resid, m, tmp_path / "res.png", after=0 * resid).stat().st_size > 1000
