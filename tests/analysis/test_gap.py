"""Gap metrics and localisation on residuals whose structure is known."""

import math

import numpy as np
import pytest

from bayes_roadload.analysis.gap import (TREND_WINDOW_S, input_resolution, localise, plot_localisation,
                                         plot_residuals, residual_structure)


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


def test_input_resolution_of_a_gust_that_the_samples_follow_and_of_one_they_do_not():
    """A 5 s gust on a steady reading: over the 20 s moving average (four whole periods) the
    deviation is the gust itself, whose lag-1 autocorrelation is cos(2 pi dt / 5 s) --
    0.998 at 20 Hz, cos(0.4 pi) = 0.31 at 1 Hz less the end effects of a finite run; white
    noise reads 0 within 4 / sqrt(samples).  A constant reading has no fluctuation: None."""
    for rate, expect, tol in ((20.0, math.cos(2 * math.pi / 100), 0.01), (1.0, math.cos(0.4 * math.pi), 0.1)):
        t = np.tile(np.arange(0.0, 200.0, 1.0 / rate), (3, 1))
        yaw = 0.1 + 0.03 * np.sin(2 * np.pi * t / 5.0)
        r = input_resolution(t, yaw, np.ones_like(t, bool))
        assert r["sample_rate_hz"] == pytest.approx(rate)
        assert r["lag1_autocorr"] == pytest.approx(expect, abs=tol)
    t, m = grid(runs=3, n=2000)
    white = np.random.default_rng(1).standard_normal(t.shape)
    assert abs(input_resolution(t, white, m)["lag1_autocorr"]) < 4.0 / math.sqrt(2000)
    assert input_resolution(t, np.full(t.shape, 0.2), m) is None
    # padded samples are not read: a run padded with garbage keeps its value
    pad = np.concatenate([m, np.zeros((3, 500), bool)], axis=1)
    tt = np.concatenate([t, t[:, -1:] + 0.25 * np.arange(1, 501)], axis=1)
    wp = np.concatenate([white, np.full((3, 500), 1e6)], axis=1)
    assert input_resolution(tt, wp, pad) == input_resolution(t, white, m)
