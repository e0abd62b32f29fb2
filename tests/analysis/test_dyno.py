"""Chassis-dynamometer set coefficients: recovery of known parasitic losses, hand-checked steps."""

import numpy as np
import pandas as pd
import pytest
from scipy.signal import savgol_coeffs

from bayes_roadload.analysis.dyno import (adjust_dyno, measured_load_coefficients, run_dyno, set_from_coastdown,
                                          tolerance_checks)
from bayes_roadload.data.dyno import save_dyno
from bayes_roadload.simulate.dyno import simulate_dyno, simulate_dyno_coastdown

PARASITIC = (40.0, 0.3, 0.004)   # N, N/(km/h), N/(km/h)^2
TARGET = (120.0, 0.6, 0.035)
INERTIA = 1500.0
DT = 0.1


def _truncation_bound_n(total, v_max_kph=130.0):
    """Central-difference error of -M dv/dt: M dt^2/6 max|v'''|, with v' = -F/M,
    v'' = -F'(v) v'/M, v''' = -(F''(v) v'^2 + F'(v) v'')/M (v in m/s; F' in N/(m/s))."""
    a, b, c = total
    v = np.linspace(0.0, v_max_kph / 3.6, 500)
    vk = v * 3.6
    f = a + b * vk + c * vk**2
    f1 = (b + 2 * c * vk) * 3.6
    f2 = 2 * c * 3.6**2
    d1 = -f / INERTIA
    d2 = -f1 * d1 / INERTIA
    d3 = -(f2 * d1**2 + f1 * d2) / INERTIA
    return INERTIA * DT**2 / 6 * np.abs(d3).max()


def test_measured_load_recovers_a_known_total():
    total = np.add(TARGET, PARASITIC)
    cd = simulate_dyno_coastdown((0.0, 0.0, 0.0), total, INERTIA, dt_s=DT)
    meas = measured_load_coefficients(cd, INERTIA)
    speeds = np.arange(20.0, 121.0, 10.0)
    err = (meas[0] - total[0]) + (meas[1] - total[1]) * speeds + (meas[2] - total[2]) * speeds**2
    # RK4 error (dt^4) is far below the finite-difference truncation bound
    assert np.abs(err).max() <= _truncation_bound_n(total)


def test_iterative_adjustment_recovers_the_parasitic_losses():
    res = adjust_dyno(TARGET, lambda s: simulate_dyno_coastdown(s, PARASITIC, INERTIA, dt_s=DT), INERTIA,
                      tolerance_n=1.0)
    assert res.converged
    speeds = np.arange(20.0, 121.0, 10.0)
    bound = _truncation_bound_n(np.add(TARGET, PARASITIC))
    got = res.parasitic_coefficients
    load_err = (got[0] - PARASITIC[0]) + (got[1] - PARASITIC[1]) * speeds + (got[2] - PARASITIC[2]) * speeds**2
    assert np.abs(load_err).max() <= 2 * bound  # two coastdowns' truncation errors
    # first pass runs with set = target (no losses assumed): error = the parasitic load itself
    assert res.iterations["max_abs_error_n"].iloc[0] == pytest.approx(40 + 0.3 * 120 + 0.004 * 120**2, abs=bound)
    # the loss does not depend on the set load: one correction suffices; the corrected setting is
    # accepted on the regression of two consecutive coastdowns (GTR 15 8.1.3.4.2)
    assert len(res.iterations) == 2 and list(res.iterations["coastdowns"]) == [1, 2]
    assert res.accepted and res.coastdowns == 2
    np.testing.assert_allclose(res.set_coefficients, np.subtract(TARGET, PARASITIC), atol=1e-3)


@pytest.mark.parametrize("iterations", [0, 1])
def test_an_adjustment_that_stops_unconverged_reports_the_loss_at_the_setting_it_measured(iterations):
    """Stopped before the tolerance is met (here after ``iterations`` corrections of a
    tolerance no rig meets), the parasitic loss is the last coastdown's load less the setting
    it ran at (not less the next setting), the returned setting is the next one to run,
    target - parasitic, and the set draws carried from the target agree with it."""
    draws = {k: np.full(50, v) for k, v in zip(("F0_N", "F1_N_per_kph", "F2_N_per_kph2"), TARGET)}
    res = adjust_dyno(draws, lambda s: simulate_dyno_coastdown(s, PARASITIC, INERTIA, dt_s=DT), INERTIA,
                      tolerance_n=1e-9, max_iterations=iterations)
    assert not res.converged and len(res.iterations) == iterations + 1
    speeds = np.arange(20.0, 121.0, 10.0)
    got = res.parasitic_coefficients
    load_err = (got[0] - PARASITIC[0]) + (got[1] - PARASITIC[1]) * speeds + (got[2] - PARASITIC[2]) * speeds**2
    assert np.abs(load_err).max() <= _truncation_bound_n(np.add(TARGET, PARASITIC))
    np.testing.assert_allclose(res.set_coefficients, np.subtract(TARGET, got), rtol=1e-12)
    summary = res.summary().set_index("quantity")
    np.testing.assert_allclose(summary.loc[["set_a", "set_b", "set_c"], "mean"], res.set_coefficients, rtol=1e-12)


def test_one_step_from_a_measured_coastdown_and_posterior_carried():
    """Run with set = (50, 0.2, 0.02): measured = set + losses; new set = target - losses."""
    used = (50.0, 0.2, 0.02)
    cd = simulate_dyno_coastdown(used, PARASITIC, INERTIA, dt_s=DT)
    rng = np.random.default_rng(3)
    draws = {"F0_N": rng.normal(120.0, 4.0, 2000), "F1_N_per_kph": rng.normal(0.6, 0.05, 2000),
             "F2_N_per_kph2": rng.normal(0.035, 0.001, 2000)}
    res = set_from_coastdown(draws, cd, used, INERTIA)
    np.testing.assert_allclose(res.parasitic_coefficients, PARASITIC, rtol=1e-3, atol=1e-3)
    summary = res.summary().set_index("quantity")
    # the set coefficients are the target draws shifted by the parasitic losses: same sd
    assert summary.loc["set_a", "sd"] == pytest.approx(draws["F0_N"].std(ddof=1), rel=1e-12)
    assert summary.loc["set_a", "mean"] == pytest.approx(draws["F0_N"].mean() - res.parasitic_coefficients[0],
                                                         rel=1e-12)
    assert summary.loc["set_c", "q97.5"] == pytest.approx(
        np.quantile(draws["F2_N_per_kph2"], 0.975) - res.parasitic_coefficients[2], rel=1e-12)


def test_tolerance_checks_by_hand():
    """Measured a = 10 N above a zero target: error 10 N at every speed, passes a 10 N tolerance."""
    ok = tolerance_checks((10.0, 0.0, 0.0), (0.0, 0.0, 0.0), tolerance_n=10.0)
    assert ok["pass"].all() and np.allclose(ok["error_n"], 10.0)
    # a quadratic error 0.001 V^2 exceeds 10 N above 100 km/h
    q = tolerance_checks((0.0, 0.0, 0.001), (0.0, 0.0, 0.0), tolerance_n=10.0)
    assert list(q.loc[~q["pass"], "speed_kph"]) == [110.0, 120.0]


def test_coastdown_table_needs_its_columns():
    with pytest.raises(ValueError, match="speed_mps"):
        measured_load_coefficients(pd.DataFrame({"time_s": [0.0, 1.0]}), INERTIA)


def test_run_dyno_from_files_recovers_the_recorded_truth(tmp_path):
    used = (100.0, 0.8, 0.025)
    save_dyno(simulate_dyno(used, PARASITIC, INERTIA, dt_s=DT), tmp_path / "dyno")
    draws = {"F0_N": np.full(5, TARGET[0]), "F1_N_per_kph": np.full(5, TARGET[1]),
             "F2_N_per_kph2": np.full(5, TARGET[2])}
    res = run_dyno(draws, tmp_path / "dyno", out_dir=tmp_path / "out")
    speeds = np.arange(20.0, 121.0, 10.0)
    got = res.parasitic_coefficients
    err = (got[0] - PARASITIC[0]) + (got[1] - PARASITIC[1]) * speeds + (got[2] - PARASITIC[2]) * speeds**2
    assert np.abs(err).max() <= _truncation_bound_n(np.add(used, PARASITIC))
    assert (tmp_path / "out" / "dyno_set.csv").is_file() and (tmp_path / "out" / "dyno.json").is_file()


def test_smoothed_derivative_recovers_losses_from_a_noisy_coastdown():
    """Speed noise 0.02 m/s at 10 Hz, 5 s cubic Savitzky-Golay window: the derivative's noise sd is
    sigma * ||h|| (h the filter's derivative coefficients); a load error at one speed is at most
    ~ M sd_deriv / sqrt(n / window) (about n / window independent windows), 5 such sds allowed."""
    total = np.add(TARGET, PARASITIC)
    cd = simulate_dyno_coastdown((0.0, 0.0, 0.0), total, INERTIA, dt_s=DT, speed_noise_mps=0.02, seed=11)
    meas = measured_load_coefficients(cd, INERTIA, smoothing_s=5.0)
    window = 2 * round(5.0 / DT / 2) + 1
    sd_deriv = 0.02 * np.linalg.norm(savgol_coeffs(window, 3, deriv=1, delta=DT))
    bound = 5 * INERTIA * sd_deriv / np.sqrt(len(cd) / window)
    speeds = np.arange(20.0, 121.0, 10.0)
    err = (meas[0] - total[0]) + (meas[1] - total[1]) * speeds + (meas[2] - total[2]) * speeds**2
    assert np.abs(err).max() <= bound
    # and it is a real improvement over central differences on the same noisy trace
    raw = measured_load_coefficients(cd, INERTIA)
    err_raw = (raw[0] - total[0]) + (raw[1] - total[1]) * speeds + (raw[2] - total[2]) * speeds**2
    assert np.abs(err).max() < np.abs(err_raw).max()


def test_two_consecutive_coastdowns_are_regressed_together(tmp_path):
    """Two coastdowns at one setting (speed noise of their own): the pooled regression is the
    least squares over both coastdowns' samples, by hand; the setting is accepted (GTR 15
    8.1.3.4.2) only on two; coastdowns at different settings are refused."""
    used = (100.0, 0.8, 0.025)
    first = simulate_dyno(used, PARASITIC, INERTIA, dt_s=DT, speed_noise_mps=0.01, seed=1)
    second = simulate_dyno(used, PARASITIC, INERTIA, dt_s=DT, speed_noise_mps=0.01, seed=2)
    pooled = measured_load_coefficients([first.runs, second.runs], INERTIA)
    rows = []
    for c in (first, second):
        t, v = c.runs["time_s"].to_numpy(), c.runs["speed_mps"].to_numpy()
        f, vk = -INERTIA * np.gradient(v, t), v * 3.6
        keep = (vk >= 10.0) & (vk <= 130.0)
        keep[0] = keep[-1] = False
        rows.append(np.column_stack([np.ones(keep.sum()), vk[keep], vk[keep] ** 2, f[keep]]))
    x = np.vstack(rows)
    np.testing.assert_allclose(pooled, np.linalg.lstsq(x[:, :3], x[:, 3], rcond=None)[0], rtol=1e-12)
    target = np.add(used, PARASITIC)   # the setting already gives the target: within tolerance
    draws = {k: np.full(4, v) for k, v in zip(("F0_N", "F1_N_per_kph", "F2_N_per_kph2"), target)}
    for i, c in enumerate((first, second)):
        save_dyno(c, tmp_path / f"d{i}")
    one = run_dyno(draws, tmp_path / "d0")
    assert one.converged and not one.accepted
    two = run_dyno(draws, [tmp_path / "d0", tmp_path / "d1"], out_dir=tmp_path / "out")
    assert two.accepted and two.coastdowns == 2
    import json
    record = json.loads((tmp_path / "out" / "dyno.json").read_text())
    assert record["coastdowns"] == 2 and record["accepted"] is True
    save_dyno(simulate_dyno((90.0, 0.8, 0.025), PARASITIC, INERTIA, dt_s=DT), tmp_path / "other")
    with pytest.raises(ValueError, match="at one setting"):
        run_dyno(draws, [tmp_path / "d0", tmp_path / "other"])
