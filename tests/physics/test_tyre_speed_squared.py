"""The rolling coefficient's speed-squared part (SAE J2452's speed law): orthogonal to the line
on the road-load speeds, exact v^2 where no trace is logged, and along a speed trace (v^2
linearised about the logged speed) the coastdown of an independent solver (scipy)."""

import jax
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from bayes_roadload import config
from bayes_roadload.physics import DragModel, integrate_run, make_run
from bayes_roadload.physics.roadload import road_load_summary
from bayes_roadload.physics.terms import TYRE_QUADRATIC_LINE, AeroDrag, TyreRolling, TyreSpeedSquared

M, ME, AREA, RHO = 1500.0, 1540.0, 2.2, 1.19
CR = 2.0e-6
P = {"AD": 0.011, "BD": 1.8e-4, "CD0": 0.33, "KD": 0.0, "KT": 0.0, "tyre_quadratic_s2_per_m2": CR}
MODEL = DragModel((TyreRolling(), TyreSpeedSquared(), AeroDrag()))


def test_the_line_is_the_least_squares_line_of_v_squared_on_the_road_load_speeds():
    """The normal equations: the residual v^2 - a - b v sums to zero and has no moment in v on
    the road-load speeds (to rounding, relative to the sums of v^2 and v^3)."""
    v = np.asarray(config.ROADLOAD_FIT_SPEEDS_KPH) / 3.6
    a, b = TYRE_QUADRATIC_LINE
    residual = v**2 - a - b * v
    assert abs(residual.sum()) < 1e-12 * (v**2).sum()
    assert abs((residual * v).sum()) < 1e-12 * (v**3).sum()


def test_the_term_adds_no_line_on_the_road_load_speeds():
    """The term's force on the road-load speeds has no least-squares line (so A_D + B_D v stays
    the least-squares line of the rolling coefficient there, whatever C_R), and it moves the
    road-load quadratic by exactly M g C_R (v^2 - a - b v): F2 by M g C_R per (3.6 m/s)^2, F0
    by -M g C_R a, F1 by -M g C_R b / 3.6; F50 by M g C_R (v50^2 - a - b v50), all of it tyre."""
    v = np.asarray(config.ROADLOAD_FIT_SPEEDS_KPH) / 3.6
    a, b = TYRE_QUADRATIC_LINE
    w = M * config.GRAVITY_MPS2
    line = np.polyfit(v, w * CR * (v**2 - a - b * v), 1)
    assert np.all(np.abs(line * [v.max(), 1.0]) < 1e-12 * w * CR * v.max() ** 2)
    with_term = road_load_summary(MODEL, P, M, AREA)
    without = road_load_summary(MODEL, dict(P, tyre_quadratic_s2_per_m2=0.0), M, AREA)
    shift = {k: float(with_term[k] - without[k]) for k in ("F0_N", "F1_N_per_kph", "F2_N_per_kph2", "F50_N",
                                                          "F50_tyre_N")}
    assert shift["F2_N_per_kph2"] == pytest.approx(w * CR / 3.6**2, rel=1e-9)
    assert shift["F0_N"] == pytest.approx(-w * CR * a, rel=1e-9)
    assert shift["F1_N_per_kph"] == pytest.approx(-w * CR * b / 3.6, rel=1e-9)
    v50 = config.SPEED_50MPH_MPS
    assert shift["F50_N"] == pytest.approx(w * CR * (v50**2 - a - b * v50), rel=1e-9)
    assert shift["F50_tyre_N"] == pytest.approx(shift["F50_N"], rel=1e-12)


def _reference(t_eval, v0):
    """The coastdown with the exact v^2 (scipy, tight tolerance)."""
    a, b = TYRE_QUADRATIC_LINE
    w = M * config.GRAVITY_MPS2

    def rhs(t, y):
        v = y[0]
        f = w * (P["AD"] + P["BD"] * v + CR * (v * v - a - b * v)) + 0.5 * RHO * AREA * P["CD0"] * v**2
        return [-f / ME]

    sol = solve_ivp(rhs, (0.0, t_eval[-1]), [v0], t_eval=t_eval, method="DOP853", rtol=1e-11, atol=1e-11)
    assert sol.success
    return sol.y[0]


def test_along_a_trace_the_model_is_the_exact_coastdown():
    """Integrated along its own (noise-free) trace, the linearised term gives the exact
    coastdown to the integrator's accuracy, far inside the term's own effect; along a trace with
    0.1 m/s of noise the linearisation's error, (v - v_m)^2 ~ 0.01 m^2/s^2 against v^2 of
    25-1000, stays below a thousandth of the effect."""
    t = np.arange(0.0, 240.0, 0.5)
    v_ref = _reference(t, 32.0)
    noisy = v_ref + np.random.default_rng(0).normal(0.0, 0.1, t.size)
    assert MODEL.speed_affine  # measured air: solved in parallel over time (the default integrator)
    for trace in (v_ref, noisy):
        run = make_run(t, trace, airspeed_mps=v_ref, yaw_rad=np.zeros_like(t),
                       air_density_kgpm3=np.full_like(t, RHO), mass_kg=M, effective_mass_kg=ME,
                       frontal_area_m2=AREA)
        speeds = jax.jit(lambda p, r: integrate_run(MODEL, p, r, v0_mps=32.0)[0])
        err = np.max(np.abs(np.asarray(speeds(P, run)) - v_ref))
        effect = np.max(np.abs(np.asarray(speeds(dict(P, tyre_quadratic_s2_per_m2=0.0), run)) - v_ref))
        assert effect > 0.02
        assert err < 1e-3 * effect


def test_the_term_is_affine_in_the_state_along_a_trace():
    """With a logged speed the force is affine in the model's speed (so the integrator may solve
    the motion in parallel), and equals the exact v^2 where the two speeds agree."""
    from bayes_roadload.physics.terms import Conditions

    def conditions(v, vm=None):
        return Conditions(speed_mps=v, airspeed_mps=0.0, yaw_rad=0.0, driveline_force_n=0.0, position_m=0.0,
                          distance_m=0.0, time_s=0.0, accel_mps2=0.0, direction=1.0, air_density_kgpm3=RHO,
                          temperature_k=config.REFERENCE_TEMPERATURE_K, mass_kg=M, frontal_area_m2=AREA,
                          speed_measured_mps=vm)

    def force(v, vm):
        return float(TyreSpeedSquared().force_n(P, conditions(v, vm)))

    second = force(21.0, 20.0) - 2 * force(20.0, 20.0) + force(19.0, 20.0)
    assert abs(second) < 1e-9 * abs(force(20.0, 20.0))
    exact = DragModel((TyreSpeedSquared(),)).force_components_n(dict(P), conditions(20.0))
    assert force(20.0, 20.0) == pytest.approx(float(exact["tyre_speed_squared"]), rel=1e-12)
    assert TyreSpeedSquared.speed_affine
