"""Dynamometer coastdown simulator."""

import numpy as np
import pytest

from bayes_roadload.simulate.dyno import simulate_dyno_coastdown


def test_constant_load_decelerates_linearly_by_hand():
    """Set 100 N + parasitic 50 N, inertia 1500 kg: a = -0.1 m/s^2; from 100 km/h (27.78 m/s)
    the speed at t = 100 s is 27.78 - 10 = 17.78 m/s (RK4 exact for a constant force)."""
    cd = simulate_dyno_coastdown((100.0, 0.0, 0.0), (50.0, 0.0, 0.0), 1500.0, v0_kph=100.0, dt_s=0.5)
    v = np.interp(100.0, cd["time_s"], cd["speed_mps"])
    assert v == pytest.approx(100 / 3.6 - 10.0, abs=1e-9)
    assert cd["speed_mps"].iloc[-1] <= 10 / 3.6  # stops at the end speed


def test_noise_is_reproducible_and_has_its_sd():
    a = simulate_dyno_coastdown((100.0, 0.5, 0.03), (30.0, 0.1, 0.003), 1500.0, speed_noise_mps=0.05, seed=4)
    b = simulate_dyno_coastdown((100.0, 0.5, 0.03), (30.0, 0.1, 0.003), 1500.0, speed_noise_mps=0.05, seed=4)
    clean = simulate_dyno_coastdown((100.0, 0.5, 0.03), (30.0, 0.1, 0.003), 1500.0)
    np.testing.assert_array_equal(a["speed_mps"], b["speed_mps"])
    resid = a["speed_mps"] - clean["speed_mps"]
    # sd of n draws of N(0, 0.05): relative standard error 1/sqrt(2n) < 3 % for n > 600; 5 sigma band
    n = resid.size
    assert resid.std() == pytest.approx(0.05, rel=5 / np.sqrt(2 * n))
