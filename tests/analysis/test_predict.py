"""predict: cycle work and the trace of a manoeuvre at other conditions or mass."""

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.analysis.predict import format_cycle_work, mass_changed, run_predict


def _draws():
    return {"F0_N": np.full(6, 300.0), "F1_N_per_kph": np.zeros(6), "F2_N_per_kph2": np.zeros(6)}


def test_coastdown_at_other_temperature_and_mass_by_hand(tmp_path):
    """f0 = 300 N at 293.2 K; at 283.2 K the tyre factor is 1 - 0.0086 (283.2 - 293.2) = 1.086 and
    with M_e 1500 + 150 kg, f0 scales by 1650/1500 (tyre load ~ mass): F = 300*1.086*1.1 N,
    decel F/1650 = 0.19548 m/s^2, so from 72 km/h (20 m/s) at t = 50 s: 20 - 9.774 m/s."""
    work, shares, trace, heavier = run_predict(_draws(), "hwfet", effective_mass_kg=1500.0, temperature_k=283.2,
                                               mass_kg_change=150.0, v0_kph=72.0, duration_s=80.0, out_dir=tmp_path)
    decel = 300.0 * 1.086 * 1.1 / 1650.0
    row = trace.loc[np.isclose(trace["time_s"], 50.0)].iloc[0]
    assert row["mean_kph"] == pytest.approx((20.0 - decel * 50.0) * 3.6, abs=1e-6)
    # reference-condition work over HWFET: 300 N x its distance (kJ/km = N)
    assert work.set_index("quantity").loc["road_load_work_per_km", "mean"] == pytest.approx(300.0, rel=1e-12)
    assert (tmp_path / "predicted_trace.csv").is_file()
    assert "hwfet road-load work" in format_cycle_work(work, shares)
    # the heavier vehicle's work, at reference conditions: 300 N x 1650/1500 = 330 N per km
    written = pd.read_csv(tmp_path / "cycle_work_mass_changed.csv").set_index("quantity")
    assert written.loc["road_load_work_per_km", "mean"] == pytest.approx(330.0, rel=1e-12)
    assert (written["mass_change_kg"] == 150.0).all()
    assert heavier.set_index("quantity").loc["road_load_work_per_km", "mean"] == pytest.approx(330.0, rel=1e-12)
    # its inertia is M_e + dM: the energy demand equals that of a 330 N vehicle of 1650 kg and
    # exceeds that of the same forces on the fitted 1500 kg
    from bayes_roadload.analysis.cycles import cycle_work

    forces = dict(_draws(), F0_N=np.full(6, 330.0))
    by_mass = {m: cycle_work(forces, "hwfet", effective_mass_kg=m)[0].set_index("quantity")["mean"]
               for m in (1500.0, 1650.0)}
    got = heavier.set_index("quantity")["mean"]
    for q in ("tractive_work_positive", "cycle_energy_demand"):
        assert got[q] == pytest.approx(by_mass[1650.0][q], rel=1e-12) and got[q] > by_mass[1500.0][q] * 1.01, q
    assert "with the test mass +150 kg" in format_cycle_work(work, shares, heavier)
    unchanged = run_predict(_draws(), "hwfet", effective_mass_kg=1500.0, out_dir=tmp_path / "same")
    assert unchanged.work_mass_changed is None and not (tmp_path / "same" / "cycle_work_mass_changed.csv").exists()
    assert shares["variance_share"].isna().all()  # constant draws: no variance to share


def test_a_heavier_vehicle_adds_rolling_loss_from_the_tyre_coefficients():
    """F0 = 300 N of which A_D M g = 0.01 x 1500 x 9.81 = 147.15 N is rolling and the rest
    driveline: 150 kg more add 0.01 x 150 x 9.81 = 14.715 N to F0 (the driveline unchanged),
    B_D 2e-4 s/m adds 150 x 9.81 x 2e-4 / 3.6 N per km/h to F1, F2 unchanged; scaling the whole
    of F0 by the mass ratio would have added 30 N.  Without A_D and B_D the test mass ratio scales
    F0 and F1."""
    draws = dict(_draws(), AD=np.full(6, 0.01), BD=np.full(6, 2e-4), F2_N_per_kph2=np.full(6, 0.03))
    heavier = mass_changed(draws, 150.0, mass_kg=1500.0, effective_mass_kg=1540.0)
    np.testing.assert_allclose(heavier["F0_N"], 300.0 + 14.715)
    np.testing.assert_allclose(heavier["F1_N_per_kph"], 150.0 * 9.81 * 2e-4 / 3.6)
    np.testing.assert_allclose(heavier["F2_N_per_kph2"], 0.03)
    scaled = mass_changed(_draws(), 150.0, mass_kg=1500.0, effective_mass_kg=1540.0)
    np.testing.assert_allclose(scaled["F0_N"], 300.0 * 1650.0 / 1500.0)
    np.testing.assert_array_equal(mass_changed(draws, 0.0, mass_kg=1500.0, effective_mass_kg=1540.0)["F0_N"],
                                  draws["F0_N"])


def test_the_tyre_v2_coefficient_and_a_fixed_b_d_move_the_heavier_vehicle_s_curve():
    """With C_R (here fixed by the model, as the default holds it) the added rolling loss
    dM g [A_D + B_D v + C_R (v^2 - a - b v)] is the quadratic in V = 3.6 v that F0 + F1 V + F2 V^2
    gains: checked against that loss evaluated at 20-130 km/h.  A model without a sampled B_D
    takes it from ``fixed`` (0 when it has none)."""
    from bayes_roadload.physics.terms import TYRE_QUADRATIC_LINE

    draws = dict(_draws(), AD=np.full(6, 0.01), F2_N_per_kph2=np.full(6, 0.03))
    fixed = {"BD": 2e-4, "tyre_quadratic_s2_per_m2": 1e-6, "CL0": "tunnel"}
    heavier = mass_changed(draws, 300.0, mass_kg=1500.0, effective_mass_kg=1540.0, fixed=fixed)
    V = np.linspace(20.0, 130.0, 12)
    v = V / 3.6
    a, b = TYRE_QUADRATIC_LINE
    added = 300.0 * 9.81 * (0.01 + 2e-4 * v + 1e-6 * (v**2 - a - b * v))
    curve = heavier["F0_N"][0] + heavier["F1_N_per_kph"][0] * V + heavier["F2_N_per_kph2"][0] * V**2
    np.testing.assert_allclose(curve - (300.0 + 0.03 * V**2), added, rtol=1e-12)
    without_bd = mass_changed(draws, 300.0, mass_kg=1500.0, effective_mass_kg=1540.0)
    np.testing.assert_allclose(without_bd["F1_N_per_kph"], 0.0)
