"""The candidate-effect terms of physics/effects.py: null at zero, linear in their parameter,
and the physics each one states."""

import jax.numpy as jnp
import numpy as np
import pytest

from bayes_roadload import config
from bayes_roadload.physics import TERMS, Conditions, DragModel, MeasuredAir, OffsetAir, simplified_model
from bayes_roadload.physics import effects as fx
from bayes_roadload.physics.terms import AeroDrag, PitchAttitude, SideForceSlip, TyreRolling

RHO = 1.19
VEHICLE = {"mass_kg": 1100.0, "effective_mass_kg": 1130.0, "frontal_area_m2": 1.85}


def conditions(**kw):
    base = dict(speed_mps=jnp.array([10.0, 20.0, 30.0]), airspeed_mps=jnp.array([12.0, 21.0, 29.0]),
                yaw_rad=jnp.array([0.2, -0.1, 0.05]), driveline_force_n=jnp.zeros(3),
                position_m=jnp.array([0.0, 1250.0, 2500.0]), distance_m=jnp.array([100.0, 500.0, 900.0]),
                time_s=jnp.array([0.0, 40.0, 80.0]), accel_mps2=jnp.array([-0.2, -0.3, -0.5]),
                direction=jnp.array(-1.0), air_density_kgpm3=jnp.array(RHO),
                temperature_k=jnp.array(config.REFERENCE_TEMPERATURE_K), mass_kg=jnp.array(1100.0),
                frontal_area_m2=jnp.array(1.85), airspeed_rate_mps2=jnp.array([-0.35, 0.1, -0.6]),
                felt_airspeed_mps=jnp.array([11.5, 21.3, 28.6]), felt_yaw_rad=jnp.array([0.15, -0.08, 0.06]))
    base.update(kw)
    return Conditions(**base)


EFFECT_TERMS = {  # term -> (effect parameter, a non-null value)
    "tyre_temperature_transient": ("tyre_transient", 0.1),
    "tyre_loss_level": ("tyre_level", 0.02),
    "tyre_speed_power": ("tyre_power_coeff", 3e-4),
    "side_slip_drag": ("side_slip_coeff_per_n", 5.76e-5),
    "driveline_quadratic": ("Ct", 0.03),
    "anemometer_lag": ("cup_lag_m", 1.5),
    "admittance_filter": ("admittance_gain", 1.0),
    "mass_error": ("mass_error_kg", 30.0),
    "spatial_wind": ("wind_gradient_mps", 2.0),
}


@pytest.mark.parametrize("name", sorted(EFFECT_TERMS))
def test_effect_terms_are_registered_null_at_zero_and_linear(name):
    term = TERMS[name]()
    param, value = EFFECT_TERMS[name]
    p = {"AD": 0.01, "BD": 2e-4, "KT": 0.0, "CD0": 0.4, "KD": 0.6, **term.defaults}
    c = conditions()
    assert np.allclose(term.force_n({**p, param: 0.0}, c), 0.0)
    f1 = np.asarray(term.force_n({**p, param: value}, c))
    f2 = np.asarray(term.force_n({**p, param: 2 * value}, c))
    assert np.any(np.abs(f1) > 1e-6)
    np.testing.assert_allclose(f2, 2 * f1, rtol=1e-12)  # linear: the diagnosis linearises about 0


def test_tyre_loss_level_is_the_transient_that_never_decays():
    """tyre_level scales the rolling loss like tyre_transient at t = 0, and stays (eq. 2.38 scaled)."""
    c = conditions()
    p = {"AD": 0.01, "BD": 2e-4, "KT": 0.0, "CD0": 0.4, "KD": 0.6}
    level = TERMS["tyre_loss_level"]().force_n({**p, "tyre_level": 0.03}, c)
    start = TERMS["tyre_temperature_transient"]().force_n({**p, "tyre_transient": 0.03, "tyre_time_constant_s": 40.0},
                                                          c._replace(time_s=jnp.zeros(3)))
    np.testing.assert_allclose(level, start, rtol=1e-12)
    rolling = TERMS["tyre_rolling"]().force_n(p, c)
    np.testing.assert_allclose(level, 0.03 * np.asarray(rolling), rtol=1e-12)


def test_side_slip_drag_equals_side_force_slip_with_folded_coefficient():
    c = conditions()
    ks, cy = 2.4, 25_000.0
    expected = SideForceSlip().force_n({"KS": ks, "Cy": cy}, c)
    got = fx.SideSlipDrag().force_n({"side_slip_coeff_per_n": ks**2 / (4 * cy)}, c)
    np.testing.assert_allclose(got, expected, rtol=1e-12)


def test_mass_error_is_the_equation_of_motion_with_the_true_mass():
    """(M_e + dM) dv/dt = -F  <=>  M_e dv/dt = -(F + dM dv/dt): same deceleration."""
    c = conditions()
    params = {"AD": 0.01, "BD": 2e-4, "CD0": 0.4, "KD": 0.6, "mass_error_kg": 40.0}
    base = DragModel((TyreRolling(), AeroDrag()))
    with_error = base.with_terms(fx.EffectiveMassError())
    np.testing.assert_allclose(with_error.acceleration_mps2(params, c, 1130.0),
                               base.acceleration_mps2(params, c, 1170.0), rtol=1e-12)


def test_anemometer_lag_matches_the_drag_at_the_corrected_airspeed():
    """To first order in the lag the term is the drag at a_m + (d / a_m) da_m/dt (the
    reading's own rate, gusts included: not dv/dt) minus that at the reading a_m: check
    against the exact difference for a small lag."""
    c = conditions()
    d = 0.05
    p = {"CD0": 0.4, "KD": 0.6, "cup_lag_m": d}
    corrected = c._replace(airspeed_mps=c.airspeed_mps + d / c.airspeed_mps * c.airspeed_rate_mps2)
    exact = AeroDrag().force_n(p, corrected) - AeroDrag().force_n(p, c)
    lag = fx.AnemometerLag().force_n(p, c)
    # first order: relative error ~ (d a / a_m^2) / 2, below 1e-4 here
    np.testing.assert_allclose(lag, exact, rtol=1e-4)


def _gusty_run(t, v):
    """Readings of a run in gusty wind: airspeed v + 2 m/s head wind with a 7 s gust, yaw
    0.15 rad with a 5 s one."""
    return v + 2.0 + 1.5 * np.sin(2 * np.pi * t / 7.0), 0.15 + 0.1 * np.sin(2 * np.pi * t / 5.0)


def test_admittance_filter_at_full_gain_is_the_model_in_the_felt_air():
    """End to end: a run integrated with the filter term at gain 1 on the readings equals the
    run integrated without it on the air the body feels (physics.admittance.felt_air_readings,
    the integrator's channels); at gain 0 it is the run on the readings."""
    from bayes_roadload.physics.admittance import felt_air_readings
    from bayes_roadload.physics.integrate import integrate_run, make_run

    t = np.arange(0.0, 60.0, 0.25)
    v = 30.0 - 0.35 * t
    a_m, yaw = _gusty_run(t, v)
    base = DragModel((TyreRolling(), AeroDrag()))
    model = base.with_terms(fx.AdmittanceFilter())
    p = {"AD": 0.01, "BD": 2e-4, "CD0": 0.4, "KD": 0.6, "admittance_length_m": 12.0}
    run = make_run(t, v, airspeed_mps=a_m, yaw_rad=yaw, **VEHICLE)
    felt_a, felt_y = felt_air_readings(t, v, a_m, yaw, 1.0, 1.0, 12.0)
    v_felt, _ = integrate_run(base, p, make_run(t, v, airspeed_mps=np.asarray(felt_a), yaw_rad=np.asarray(felt_y),
                                                **VEHICLE), v0_mps=30.0)
    v_read, _ = integrate_run(base, p, run, v0_mps=30.0)
    v_full, _ = integrate_run(model, {**p, "admittance_gain": 1.0}, run, v0_mps=30.0)
    v_none, _ = integrate_run(model, {**p, "admittance_gain": 0.0}, run, v0_mps=30.0)
    assert np.max(np.abs(np.asarray(v_felt) - np.asarray(v_read))) > 1e-3      # the filter matters
    np.testing.assert_allclose(v_full, v_felt, rtol=0, atol=1e-9)
    np.testing.assert_allclose(v_none, v_read, rtol=0, atol=1e-12)


def test_a_short_admittance_filter_delays_the_wind_by_its_length():
    """For a body short against the gusts the filter is a delay of the wind, not of the
    vehicle's own speed: w_f = w - (l / v_r) dw/dt to first order (w_x = v_r cos psi - v,
    w_y = v_r sin psi).  The neglected terms are of second order, tau^2 d^2w/dt^2 and
    tau (dtau/dt) dw/dt (tau = l / v_r varies with the gusts); away from the start, where the
    filter begins at the reading."""
    from bayes_roadload.physics.admittance import felt_air

    t = np.arange(0.0, 60.0, 0.05)
    v = 30.0 - 0.35 * t
    a_m, yaw = _gusty_run(t, v)
    length = 0.5
    felt_a, felt_y = (np.asarray(x) for x in felt_air(t, v, a_m, yaw, length))
    tau = length / a_m
    wx, wy = a_m * np.cos(yaw) - v, a_m * np.sin(yaw)
    delayed_x, delayed_y = wx - tau * np.gradient(wx, t), wy - tau * np.gradient(wy, t)
    fx_, fy_ = felt_a * np.cos(felt_y) - v, felt_a * np.sin(felt_y)
    late = t > 20 * tau.max()
    for w, felt, delayed in ((wx, fx_, delayed_x), (wy, fy_, delayed_y)):
        rate = np.gradient(w, t)
        second = tau**2 * np.gradient(rate, t) + tau * np.gradient(tau, t) * rate
        size = np.max(np.abs(second)[late])
        # the series converges: what the second order leaves is a fraction (third order, ~tau
        # d/dt of the second) of it, so the first order's error is the second order's size
        # plus that fraction
        assert np.max(np.abs(felt - delayed - second)[late]) < 0.5 * size
        assert np.max(np.abs(felt - delayed)[late]) < 1.5 * size
        assert np.max(np.abs(felt - w)[late]) > 5 * size          # the delay itself is resolved


def test_the_integrator_feeds_the_felt_air_to_a_term_naming_its_length():
    """The conditions the integrator builds for a model with the filter term carry the felt
    air of the readings (factors 1, then the model's calibration), sample by sample; without
    such a term they carry none, and the tyre lag's channel keeps its place beside it."""
    from bayes_roadload.physics.admittance import felt_air_readings
    from bayes_roadload.physics.integrate import (_conditions, _inputs, _with_model_channel, lagged_speed_drop, make_run,
                                                  stack_runs)
    from bayes_roadload.physics.terms import TyreThermalLag

    t = np.arange(0.0, 30.0, 0.25)
    v = 30.0 - 0.35 * t
    a_m, yaw = _gusty_run(t, v)
    short = make_run(t[:80], v[:80], airspeed_mps=a_m[:80], yaw_rad=yaw[:80], **VEHICLE)
    batch = stack_runs([make_run(t, v, airspeed_mps=a_m, yaw_rad=yaw, **VEHICLE), short])
    air = OffsetAir()
    for terms in ((TyreRolling(), AeroDrag(), fx.AdmittanceFilter()),
                  (TyreRolling(), AeroDrag(), TyreThermalLag(), fx.AdmittanceFilter())):
        model = DragModel(terms, air)
        p = model.complete({"AD": 0.01, "BD": 2e-4, "CD0": 0.4, "KD": 0.6, "admittance_length_m": 9.0,
                            "airspeed_factor": 1.05, "yaw_factor": 0.9, "tyre_lag_time_constant_s": 300.0})
        for r, n in ((0, t.size), (1, 80)):
            run = batch.run(r)
            u, _ = _with_model_channel(model, p, run, jnp.asarray(_inputs(run)), None)
            c = _conditions(model, p, run, run.speed_mps, jnp.zeros_like(run.speed_mps), run.time_s, jnp.moveaxis(u, -1, 0))
            fa, fy = felt_air_readings(t[:n], v[:n], a_m[:n], yaw[:n], 1.0, 1.0, 9.0)
            np.testing.assert_allclose(np.asarray(c.felt_airspeed_mps)[:n], 1.05 * np.asarray(fa), rtol=1e-12)
            np.testing.assert_allclose(np.asarray(c.felt_yaw_rad)[:n], 0.9 * np.asarray(fy), rtol=1e-12)
            np.testing.assert_allclose(np.asarray(c.airspeed_mps)[:n], 1.05 * a_m[:n], rtol=1e-12)
            lagged = lagged_speed_drop(t[:n], v[:n], 300.0) if model.lag_time_constant else np.zeros(n)
            drop = np.broadcast_to(np.asarray(c.speed_drop_lagged_mps), np.shape(run.speed_mps))
            np.testing.assert_allclose(drop[:n], lagged, rtol=1e-12, atol=1e-12)
    plain = DragModel((TyreRolling(), AeroDrag()), air)
    run = batch.run(0)
    u, _ = _with_model_channel(plain, plain.complete({}), run, jnp.asarray(_inputs(run)), None)
    c = _conditions(plain, plain.complete({}), run, run.speed_mps, jnp.zeros_like(run.speed_mps), run.time_s,
                    jnp.moveaxis(u, -1, 0))
    assert c.felt_airspeed_mps is None and c.felt_yaw_rad is None


def test_tyre_transient_decays_with_its_time_constant():
    c = conditions(time_s=jnp.array([0.0, 40.0, 80.0]), speed_mps=jnp.full(3, 20.0))
    p = {"AD": 0.01, "BD": 2e-4, "KT": 0.0, "tyre_transient": 0.1, "tyre_time_constant_s": 40.0}
    f = np.asarray(fx.TyreTemperatureTransient().force_n(p, c))
    tyre = np.asarray(TyreRolling().force_n(p, c))
    np.testing.assert_allclose(f / tyre, 0.1 * np.exp(-np.array([0.0, 1.0, 2.0])), rtol=1e-12)


def test_spatial_wind_reverses_with_direction_and_vanishes_mid_track():
    c = conditions()
    p = {"CD0": 0.4, "wind_gradient_mps": 2.0}
    f = np.asarray(fx.SpatialWind().force_n(p, c))
    assert f[1] == pytest.approx(0.0, abs=1e-12)  # x = L/2
    g = np.asarray(fx.SpatialWind().force_n(p, c._replace(direction=jnp.array(1.0))))
    np.testing.assert_allclose(g, -f, rtol=1e-12)


def test_offset_air_adds_the_vane_offset_and_keeps_the_measured_air_path():
    air = OffsetAir()
    assert isinstance(air, MeasuredAir)  # the integrator's parallel affine path still applies
    v, psi = air.relative_air({"airspeed_factor": 1.08, "yaw_factor": 0.87, "yaw_offset_rad": 0.02},
                              None, jnp.array(20.0), jnp.array(0.1))
    assert float(v) == pytest.approx(21.6)
    assert float(psi) == pytest.approx(0.087 + 0.02)
    model = DragModel(simplified_model(lift=True).terms, OffsetAir()).with_terms(PitchAttitude())
    assert model.speed_affine and "yaw_offset_rad" in model.defaults


def test_the_integrator_feeds_the_reading_rate_to_the_cup_lag():
    """End to end: a run integrated with the cup-lag term on a gusty airspeed reading a_m(t)
    equals the run integrated without it on the corrected reading a_m + (d / a_m) da_m/dt
    (first order in a small lag d); the rate is the reading's central difference."""
    from bayes_roadload.physics.integrate import integrate_run, make_run, reading_rate

    t = np.arange(0.0, 60.0, 0.1)
    v = 30.0 - 0.35 * t
    gust = 1.5 * np.sin(2 * np.pi * t / 7.0)
    a_m = v + 2.0 + gust
    rate = reading_rate(t, a_m, np.ones(t.size, bool))
    exact = -0.35 + 1.5 * 2 * np.pi / 7.0 * np.cos(2 * np.pi * t / 7.0)
    assert np.max(np.abs(rate[1:-1] - exact[1:-1])) < 2e-3          # central differences, O(h^2)
    d = 0.05
    base = DragModel((TyreRolling(), AeroDrag()))
    p = {"AD": 0.01, "BD": 2e-4, "CD0": 0.4, "KD": 0.6, "cup_lag_m": d}
    with_lag = base.with_terms(fx.AnemometerLag())
    v_lag, _ = integrate_run(with_lag, p, make_run(t, v, airspeed_mps=a_m, **VEHICLE), v0_mps=30.0)
    v_cor, _ = integrate_run(base, p, make_run(t, v, airspeed_mps=a_m + d / a_m * np.asarray(rate), **VEHICLE),
                             v0_mps=30.0)
    v_none, _ = integrate_run(base, p, make_run(t, v, airspeed_mps=a_m, **VEHICLE), v0_mps=30.0)
    effect = np.max(np.abs(np.asarray(v_cor) - np.asarray(v_none)))
    assert effect > 1e-4                                               # the lag matters
    assert np.max(np.abs(np.asarray(v_lag) - np.asarray(v_cor))) < 0.01 * effect


def test_only_speed_traces_take_the_admittance_filter():
    """The filter reads a measured speed trace and its readings: every other kind refuses a
    model with it, naming the term; speed traces take it.  A model carries one felt air."""
    import dataclasses

    from bayes_roadload.inference.kinds import KINDS, check_model
    from bayes_roadload.inference.spec import load_model_spec

    plain = load_model_spec("four_term")
    felt = dataclasses.replace(plain, terms=tuple(plain.terms) + ("admittance_filter",))
    check_model(KINDS["traces"], felt)
    for name, entry in KINDS.items():
        if name != "traces":
            with pytest.raises(ValueError, match="admittance_filter"):
                check_model(entry, felt)

    @dataclasses.dataclass(frozen=True)
    class OtherFilter(fx.AdmittanceFilter):
        name = "other_filter"
        felt_air_length = "other_length_m"

    with pytest.raises(ValueError, match="at most one felt air"):
        DragModel((TyreRolling(), fx.AdmittanceFilter(), OtherFilter()))
