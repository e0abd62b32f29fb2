"""Steady-state fit: the run-offset likelihood against scipy, the model force against the
coastdown's drag function, the classical analysis (eq. 5.6-5.9) and the comparison table."""

import numpy as np
import pandas as pd
import pytest
import scipy.stats

from bayes_roadload import thesis
from bayes_roadload.inference.steady import (
    build_steady_problem,
    classical_steady,
    compare_with_coastdown,
    model_force_n,
    run_offset_log_likelihood,
    steady_log_likelihood,
)
from bayes_roadload.simulate.steady import SteadySettings, simulate_steady

SHORT = SteadySettings(duration_s=8.0)


def test_run_offset_likelihood_equals_the_dense_gaussian():
    rng = np.random.default_rng(0)
    e = rng.normal(0.0, 10.0, 9)
    runs = np.array([0, 0, 0, 1, 1, 2, 2, 2, 2])
    expected = sum(scipy.stats.multivariate_normal(np.zeros(k), 12.0**2 * np.eye(k) + 7.0**2 * np.ones((k, k)))
                   .logpdf(e[runs == r]) for r, k in ((0, 3), (1, 2), (2, 4)))
    assert float(run_offset_log_likelihood(e, runs, 3, 12.0, 7.0)) == pytest.approx(expected, rel=1e-12)


def test_pair_wind_enters_as_head_wind_of_the_plus_run_and_tail_wind_of_the_minus_run():
    c = simulate_steady(9, pairs=1, seed=2, anemometer=False, settings=SHORT)
    p = build_steady_problem(c, "three_term")
    assert p.wind == "pair" and p.n_pairs == 6
    sample = {k: p.initial[k] for k in p.free}
    w = np.arange(1.0, 7.0)
    f_wind = np.asarray(model_force_n(p, dict(sample, head_wind_mps=w)))
    f_still = np.asarray(model_force_n(p, dict(sample, head_wind_mps=np.zeros(6))))
    runs = c.runs
    v, d = runs["speed_mps"].to_numpy(), runs["direction"].to_numpy()
    wind = w[runs["pair"].to_numpy().astype(int) - 1]
    # aero part only changes: 0.5 rho A CD0 ((v + d w)^2 - v^2) (KD has no yaw to act on, lift
    # unloading follows q_r too): check the sign and size against the aero term alone
    rho_a = 0.5 * float(p.conditions.air_density_kgpm3[0]) * 1.85
    aero = rho_a * sample["CD0"] * ((v + d * wind) ** 2 - v**2)
    lift = -rho_a * 0.273 * ((v + d * wind) ** 2 - v**2) * (sample["AD"] + sample["BD"] * v)
    np.testing.assert_allclose(f_wind - f_still, aero + lift, rtol=1e-9)


def test_steady_log_likelihood_uses_the_corrected_force():
    c = simulate_steady(9, pairs=1, seed=3, settings=SHORT)
    p = build_steady_problem(c, "four_term")
    sample = dict(p.initial)
    resid = (c.runs["tractive_force_n"] - 1130.0 * c.runs["accel_mps2"]).to_numpy() - np.asarray(model_force_n(p, sample))
    expected = float(run_offset_log_likelihood(resid, np.asarray(p.run_index), p.n_run,
                                               sample["sigma_force_n"], sample["run_force_sd_n"]))
    assert float(steady_log_likelihood(p, sample)) == pytest.approx(expected, rel=1e-12)


def test_classical_analysis_recovers_still_air_coefficients():
    # still air, no lift difference between directions: the averaged quadratic is the truth's
    # A0 + B0 v + C0 v^2 except for the lift unloading's small v^3 part; 4 SE tolerance
    c = simulate_steady(None, pairs=2, seed=5, settings=SteadySettings(duration_s=10.0))
    cl = classical_steady(c).set_index("parameter")
    assert int(cl.loc["AD", "points"]) == 12
    for k in ("AD", "BD", "CD0"):
        assert abs(cl.loc[k, "estimate"] - c.truth[k]) < 4 * cl.loc[k, "se"], k


def test_comparison_table_follows_table_7_11():
    cols = ["parameter", "mean", "sd", "q2.5", "q97.5"]
    coast = pd.DataFrame([["AD", 0.0098, 0.0002, 0.0094, 0.0102], ["CD0", 0.391, 0.004, 0.383, 0.399],
                          ["F50_N", 436.0, 2.0, 432.0, 440.0]], columns=cols)
    steady = pd.DataFrame([["AD", 0.0110, 0.0008, 0.0094, 0.0126], ["CD0", 0.410, 0.013, 0.385, 0.435],
                           ["F50_N", 455.6, 5.0, 445.6, 465.6]], columns=cols)
    t = compare_with_coastdown(steady, coast).set_index("parameter")
    assert list(t.index) == ["AD", "CD0", "F50_N"]
    assert t.loc["AD", "difference_pct"] == pytest.approx(100 * 0.0012 / 0.0098)
    assert t.loc["CD0", "difference_z"] == pytest.approx(0.019 / np.hypot(0.004, 0.013))
    assert t.loc["CD0", "thesis_steady"] == 0.410 and t.loc["CD0", "thesis_coastdown"] == 0.391
    assert t.loc["AD", "thesis_difference_pct"] == pytest.approx(100 * (0.0110 - 0.0098) / 0.0098)
    assert np.isnan(t.loc["F50_N", "thesis_difference_pct"])
    assert thesis.THESIS_TABLE_7_11["std_pct"]["steady_state"]["BD"] == 131.7


def test_a_driveline_model_is_refused():
    c = simulate_steady(9, pairs=1, seed=3, settings=SHORT)
    with pytest.raises(ValueError, match="beyond the driveline"):
        build_steady_problem(c, "four_term_driveline")


def test_measured_air_is_calibrated_by_the_anemometer_factors():
    from bayes_roadload.data import Anemometer

    c = simulate_steady(9, pairs=1, seed=3, settings=SHORT)
    p1 = build_steady_problem(c, "four_term")
    c.anemometer = Anemometer(airspeed_factor=1.05, yaw_factor=1.0)
    p2 = build_steady_problem(c, "four_term")
    sample = {k: p1.initial[k] for k in p1.free}
    df = np.asarray(model_force_n(p2, sample)) - np.asarray(model_force_n(p1, sample))
    q_a = 0.5 * np.asarray(p1.conditions.air_density_kgpm3) * 1.85 * c.runs["airspeed_mps"].to_numpy() ** 2
    psi = c.runs["yaw_rad"].to_numpy()
    aero = q_a * (sample["CD0"] + sample["KD"] * psi**2)
    lift = -q_a * (0.273 + 3.64 * psi**2) * (sample["AD"] + sample["BD"] * c.runs["speed_mps"].to_numpy())
    np.testing.assert_allclose(df, (1.05**2 - 1.0) * (aero + lift), rtol=1e-9)
    # a stated yaw calibration scales each point's airspeed by (1 + e psi^2): force terms in v_r^2
    c.anemometer = Anemometer(airspeed_factor=1.0, yaw_factor=1.0, airspeed_yaw_coefficient_per_rad2=0.5)
    p3 = build_steady_problem(c, "four_term")
    df = np.asarray(model_force_n(p3, sample)) - np.asarray(model_force_n(p1, sample))
    np.testing.assert_allclose(df, ((1.0 + 0.5 * psi**2) ** 2 - 1.0) * (aero + lift), rtol=1e-9)
