"""Drive-cycle tables, road-load work over a cycle and predicted speed traces."""

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.analysis.cycles import (COEFFICIENTS, Cycle, cycle_energy_demand_j, cycle_work, load_cycle, predict_speed_trace,
                                            variance_shares, work_coefficients_j)

MILE_KM = 1.609344


@pytest.mark.parametrize("name, duration_s, distance_km, tol_km", [
    # published duration and distance; tolerance = half the last published digit plus the
    # 1e-4 km/h rounding of the tables (< 1 m over a cycle)
    ("wltc3b", 1800.0, 23.266, 0.0015),          # UN GTR 15 Annex 1: 23 266 m
    ("nedc", 1180.0, 11.01, 0.015),              # 11.007 (ECE 4 x 1.013 + EUDC 6.955) to 11.023 km quoted
    ("ftp75", 1874.0, 11.04 * MILE_KM, 0.005 * MILE_KM + 0.001),   # EPA: 11.04 mi
    ("hwfet", 765.0, 10.26 * MILE_KM, 0.005 * MILE_KM + 0.001),    # EPA: 10.26 mi
])
def test_packaged_cycles_match_published_duration_and_distance(name, duration_s, distance_km, tol_km):
    c = load_cycle(name)
    assert c.duration_s == duration_s
    assert c.distance_km == pytest.approx(distance_km, abs=tol_km)
    assert c.speed_kph[0] == 0.0 and c.speed_kph[-1] == 0.0


def test_wltc3b_top_speed_is_131_3_kph():
    assert load_cycle("wltc3b").speed_kph.max() == pytest.approx(131.3)


def _constant(speed_kph=50.0, seconds=100.0):
    t = np.arange(0.0, seconds + 1.0)
    return Cycle("constant", t, np.full(t.size, speed_kph))


def test_work_at_constant_speed_by_hand():
    """50 km/h for 100 s: distance 50/3.6*100 = 1388.9 m; F(50) = 100 + 0.5*50 + 0.03*50^2 = 200 N;
    W = 200 * 1388.9 J = 277.78 kJ, i.e. 200 kJ/km (= the force in N)."""
    draws = {"F0_N": np.full(10, 100.0), "F1_N_per_kph": np.full(10, 0.5), "F2_N_per_kph2": np.full(10, 0.03)}
    draws["F0_N"] = draws["F0_N"] + np.linspace(-1, 1, 10)  # a spread, mean kept
    work, shares = cycle_work(draws, _constant(), effective_mass_kg=1500.0)
    w = work.set_index("quantity")
    assert w.loc["road_load_work", "mean"] == pytest.approx(200.0 * 50 / 3.6 * 100 / 1000, rel=1e-12)
    assert w.loc["road_load_work_per_km", "mean"] == pytest.approx(200.0, rel=1e-12)
    # no acceleration: the positive tractive work is the road-load work
    assert w.loc["tractive_work_positive", "mean"] == pytest.approx(w.loc["road_load_work", "mean"], rel=1e-12)
    assert w.loc["cycle_energy_demand", "mean"] == pytest.approx(w.loc["road_load_work", "mean"], rel=1e-12)
    # only f0 varies: it carries the whole variance
    np.testing.assert_allclose(shares["variance_share"], [1.0, 0.0, 0.0], atol=1e-12)


def test_cycle_energy_demand_by_hand():
    """Trace 0, 36, 36, 18 km/h at 1 s, f = (100, 0.5, 0.03), M_e = 1000 kg.  Steps: mean speeds
    18, 36, 27 km/h (d = 5, 10, 7.5 m), accelerations +10, 0, -5 m/s^2; forces 100 + 9 + 9.72 +
    10000 = 10118.72 N, 100 + 18 + 38.88 = 156.88 N and 100 + 13.5 + 21.87 - 5000 < 0 (left out):
    E = 10118.72 * 5 + 156.88 * 10 = 52162.4 J."""
    c = Cycle("t", np.arange(4.0), np.array([0.0, 36.0, 36.0, 18.0]))
    f = np.array([[100.0, 0.5, 0.03]])
    np.testing.assert_allclose(cycle_energy_demand_j(f, c, 1000.0), [52162.4], rtol=1e-12)
    work, _ = cycle_work({k: f[:, i] for i, k in enumerate(COEFFICIENTS)}, c, effective_mass_kg=1000.0)
    assert work.set_index("quantity").loc["cycle_energy_demand", "mean"] == pytest.approx(52.1624, rel=1e-12)


def test_work_coefficients_by_hand():
    """Trace 0, 36, 36, 0 km/h at 1 s: trapezoid weights 0.5, 1, 1, 0.5 s; v/3.6 = 10 m/s at the
    two moving samples: c0 = 10*1 + 10*1 = 20 m, c1 = 36*20 = 720, c2 = 36^2*20 = 25920."""
    c = Cycle("t", np.arange(4.0), np.array([0.0, 36.0, 36.0, 0.0]))
    np.testing.assert_allclose(work_coefficients_j(c), [20.0, 720.0, 25920.0])


def test_variance_shares_sum_to_one_and_match_a_diagonal_case():
    rng = np.random.default_rng(0)
    draws = rng.normal(size=(20000, 3)) * [2.0, 0.1, 0.002]
    coef = np.array([1.0, 50.0, 2500.0])
    s = variance_shares(coef, draws)
    assert s.sum() == pytest.approx(1.0, abs=1e-12)
    expected = (coef * [2.0, 0.1, 0.002]) ** 2
    expected = expected / expected.sum()
    # independent draws: shares -> c_k^2 var_k / sum; sampling error of a covariance ~ 1/sqrt(n) = 0.007
    np.testing.assert_allclose(s, expected, atol=0.03)


def test_coastdown_prediction_with_constant_force_by_hand():
    """F = 300 N, M_e = 1500 kg: v(t) = v0 - 0.2 t m/s; from 72 km/h (20 m/s), 10 m/s at 50 s = 36 km/h."""
    draws = {"F0_N": np.full(4, 300.0), "F1_N_per_kph": np.zeros(4), "F2_N_per_kph2": np.zeros(4)}
    tr = predict_speed_trace(draws, 1500.0, v0_kph=72.0, duration_s=60.0, dt_s=0.5)
    row = tr.loc[np.isclose(tr["time_s"], 50.0)].iloc[0]
    assert row["mean_kph"] == pytest.approx(36.0, abs=1e-9)
    assert row["q2.5_kph"] == pytest.approx(36.0, abs=1e-9)


def test_constant_power_prediction_reaches_its_balance_speed():
    """P = F v with F = 0.03 V^2 (V km/h) and P = 20 kW: V^3 = 20000 * 3.6 / 0.03 -> 133.9 km/h."""
    draws = {"F0_N": np.zeros(3), "F1_N_per_kph": np.zeros(3), "F2_N_per_kph2": np.full(3, 0.03)}
    tr = predict_speed_trace(draws, 1500.0, v0_kph=20.0, duration_s=1500.0, dt_s=0.5, power_w=20_000.0)
    assert tr["mean_kph"].iloc[-1] == pytest.approx((20000 * 3.6 / 0.03) ** (1 / 3), rel=1e-3)


def test_cycle_csv_refuses_negative_speed(tmp_path):
    p = tmp_path / "c.csv"
    pd.DataFrame({"time_s": [0, 1, 2], "speed_kph": [0, -5, 0]}).to_csv(p, index=False)
    with pytest.raises(ValueError, match="speed_kph is negative at row 2"):
        load_cycle(p)


def test_missing_coefficient_is_refused():
    with pytest.raises(ValueError, match="F2_N_per_kph2"):
        cycle_work({k: np.ones(3) for k in COEFFICIENTS[:2]}, _constant())


def test_variance_shares_of_correlated_coefficients_by_hand():
    """Two correlated coefficients, W = f0 + f1 with Var f0 = 1, Var f1 = 4, Cov = -1.5: the
    covariance split gives f0 (1 - 1.5) / 2 = -0.25 (negative); the Shapley effects, by hand,
    v({0}) = Cov(W, f0)^2 / Var f0 = 0.25, v({1}) = 2.5^2 / 4 = 1.5625, v({0, 1}) = Var W = 2:
    phi_0 = (0.25 + 2 - 1.5625) / 2 = 0.34375, phi_1 = 1.65625; shares / 2."""
    rng = np.random.default_rng(1)
    cov = np.array([[1.0, -1.5], [-1.5, 4.0]])
    draws = rng.multivariate_normal([0.0, 0.0], cov, size=400_000)
    s = variance_shares(np.array([1.0, 1.0]), draws)
    # sample covariances of 4e5 draws: relative error ~ sqrt(2 / 4e5) ~ 0.002 per entry
    np.testing.assert_allclose(s, [0.34375 / 2, 1.65625 / 2], atol=0.01)
    assert (s >= 0).all() and s.sum() == pytest.approx(1.0, abs=1e-12)


def test_a_cycle_table_with_text_is_refused_naming_column_and_row(tmp_path):
    path = tmp_path / "c.csv"
    pd.DataFrame({"time_s": [0.0, 1.0, 2.0], "speed_kph": ["0", "abc", "3"]}).to_csv(path, index=False)
    with pytest.raises(ValueError, match=r"c.csv, column speed_kph, row 2: 'abc' is not a finite number"):
        load_cycle(path)
