"""The steady-state and spin-down simulators against the fitted models' own physics."""

import dataclasses

import numpy as np

from bayes_roadload.inference.steady import build_steady_problem, model_force_n
from bayes_roadload.simulate import DEFAULT_SETTINGS
from bayes_roadload.simulate.spindown import SpindownSettings, simulate_spindown
from bayes_roadload.simulate.steady import SteadySettings, simulate_steady


def test_noise_free_steady_force_is_the_analysis_model_plus_inertia():
    # case 2 (basic model = four_term with tunnel lift), every noise off: the wheel force less
    # M_e dv/dt (dv/dt from the polynomial method) is the analysis model's force at the truth
    quiet = SteadySettings(duration_s=6.0, force_noise_n=0.0, run_force_sd_n=0.0, speed_noise_mps=0.0,
                           driveline_noise_n=0.0)
    sim = dataclasses.replace(DEFAULT_SETTINGS, airspeed_noise_mps=0.0, yaw_noise_rad=0.0)
    c = simulate_steady(2, pairs=1, seed=7, settings=quiet, simulation=sim)
    p = build_steady_problem(c, "four_term")
    truth = {k: c.truth[k] for k in p.free}
    resid = np.asarray(p.force_n - p.inertial_n - model_force_n(p, truth))
    assert np.abs(resid).max() < 1e-8
    assert np.abs(np.asarray(p.inertial_n)).max() > 1.0  # the drift is there and was corrected


def test_noise_free_spindown_follows_the_table_7_10_wheels():
    c = simulate_spindown(tests_per_wheel=1, seed=0, settings=SpindownSettings(speed_noise_mps=0.0))
    m_w = 0.59 / 0.28**2
    for _, g in c.runs.groupby("run"):
        v = g["wheel_speed_mps"].to_numpy()
        a, b = c.truth["Au_wheel"][g["wheel"].iloc[0]], c.truth["Bu_wheel"][g["wheel"].iloc[0]]
        # logged from the release to the end speed: the last sample within one 4 Hz step of 3 m/s
        assert v[0] == 31.0 and 3.0 <= v[-1] < 3.0 + 0.25 * (a + b * 3.0) / m_w
    assert c.truth["Au_wheel"] == {"nearside": 1.66, "offside": 1.58}
