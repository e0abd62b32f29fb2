"""The tyre thermal lag term: its channel against the first-order tyre temperature it stands
for, integrated as an extra ODE state by an independent solver (scipy)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from bayes_roadload import config
from bayes_roadload.physics import DragModel, integrate_batch, integrate_run, make_run, stack_runs
from bayes_roadload.physics.integrate import lagged_speed_drop
from bayes_roadload.physics.terms import AeroDrag, TyreRolling, TyreThermalLag

M, ME, AREA, RHO = 1500.0, 1540.0, 2.2, 1.19
P = {"AD": 0.011, "BD": 1.8e-4, "CD0": 0.33, "KD": 0.0, "KT": 0.0,
     "tyre_lag_gain_per_mps": 0.006, "tyre_lag_time_constant_s": 300.0}
MODEL = DragModel((TyreRolling(), AeroDrag(), TyreThermalLag()))


def test_lagged_speed_drop_is_exact_on_a_linear_speed():
    """v = v0 - c t: L(t) = c tau (1 - exp(-t / tau)) exactly, on an uneven grid; padding
    (repeated last sample) leaves it unchanged."""
    t = np.sort(np.concatenate([[0.0], np.random.default_rng(0).uniform(0, 120, 300)]))
    c, tau = 0.12, 250.0
    lag = np.asarray(lagged_speed_drop(t, 30.0 - c * t, tau))
    np.testing.assert_allclose(lag, c * tau * -np.expm1(-t / tau), rtol=1e-12, atol=1e-12)
    padded = np.asarray(lagged_speed_drop(np.r_[t, t[-1], t[-1]], np.r_[30.0 - c * t, 30.0 - c * t[-1], 30.0 - c * t[-1]], tau))
    assert padded[-1] == pytest.approx(lag[-1], abs=1e-12)
    # tau -> infinity: the whole drop; tau -> 0: nothing left
    assert float(lagged_speed_drop(t, 30.0 - c * t, 1e9)[-1]) == pytest.approx(c * t[-1], rel=1e-6)
    assert float(lagged_speed_drop(t, 30.0 - c * t, 1e-3)[-1]) == pytest.approx(c * 1e-3, rel=1e-3)


def _reference(t_eval, v0):
    """The coastdown with the tyre temperature excess as a state (scipy, tight tolerance):
    dv/dt = -F / M_e, F = M g (AD + BD v)(1 - k dT) + q A CD0, d(dT)/dt = -dT / tau - r dv/dt,
    with k r = the term's gain (r = 0.5 K per m/s here)."""
    r = 0.5
    k = P["tyre_lag_gain_per_mps"] / r
    w = M * config.GRAVITY_MPS2

    def rhs(t, y):
        v, dT = y
        f = w * (P["AD"] + P["BD"] * v) * (1.0 - k * dT) + 0.5 * RHO * AREA * P["CD0"] * v**2
        a = -f / ME
        return [a, -dT / P["tyre_lag_time_constant_s"] - r * a]

    sol = solve_ivp(rhs, (0.0, t_eval[-1]), [v0, 0.0], t_eval=t_eval, method="DOP853", rtol=1e-11, atol=1e-11)
    assert sol.success and sol.y.shape == (2, t_eval.size)
    return sol.y[0], sol.y[1] / r


@pytest.mark.slow  # the optional term against the simulator's tyre state, ~14 s
def test_the_term_reproduces_the_tyre_temperature_state():
    """The model integrated with the lagged speed drop of its own speed trace (the measured
    speed, here noise-free) matches the two-state reference; without the term the speeds
    differ by far more than that agreement."""
    t = np.arange(0.0, 240.0, 0.5)
    v_ref, lag_ref = _reference(t, 32.0)
    run = make_run(t, v_ref, air_density_kgpm3=np.full_like(t, RHO), mass_kg=M, effective_mass_kg=ME,
                   frontal_area_m2=AREA)
    np.testing.assert_allclose(np.asarray(lagged_speed_drop(t, v_ref, P["tyre_lag_time_constant_s"])), lag_ref,
                               atol=2e-5 * np.ptp(v_ref))
    for integrator in (config.DEFAULT_INTEGRATOR, config.IntegratorConfig(substeps=2, stride=1)):
        speeds = jax.jit(lambda p, r: integrate_run(MODEL, p, r, integrator=integrator)[0])
        err = np.max(np.abs(np.asarray(speeds(P, run)) - v_ref))
        v_no = speeds(dict(P, tyre_lag_gain_per_mps=0.0), run)
        effect = np.max(np.abs(np.asarray(v_no) - v_ref))
        assert effect > 0.05  # the lag changes the trace by centimetres per second
        assert err < 1e-3 * effect
    # batched and padded as the fits run it, with a gradient with respect to tau
    batch = stack_runs([run, make_run(t[:300], v_ref[:300], air_density_kgpm3=np.full(300, RHO), mass_kg=M,
                                      effective_mass_kg=ME, frontal_area_m2=AREA)])
    total = jax.jit(lambda tau: integrate_batch(MODEL, dict(P, tyre_lag_time_constant_s=tau), batch)[0])
    vb = total(300.0)
    np.testing.assert_allclose(np.asarray(vb[1, :300]), np.asarray(vb[0, :300]), atol=1e-9)
    g = jax.grad(lambda tau: jnp.sum(total(tau)))(300.0)
    assert np.isfinite(float(g)) and float(g) != 0.0


def test_one_lag_per_model():
    class Other(TyreThermalLag):
        name = "other_lag"
        lag_time_constant = "other_time_constant_s"

    with pytest.raises(ValueError, match="at most one lagged speed drop"):
        DragModel((TyreRolling(), TyreThermalLag(), Other()))


def test_only_speed_traces_take_the_term():
    """Kinds without a measured speed trace refuse the model, naming the term; speed traces and
    models without the term pass."""
    from bayes_roadload.inference.kinds import KINDS, check_model
    from bayes_roadload.inference.spec import load_model_spec

    lag, plain = load_model_spec("four_term_tyre_lag"), load_model_spec("four_term")
    check_model(KINDS["traces"], lag)
    for name, entry in KINDS.items():
        check_model(entry, plain)
        if name != "traces":
            with pytest.raises(ValueError, match="tyre_thermal_lag"):
                check_model(entry, lag)
