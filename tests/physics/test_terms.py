"""Each drag term against its equation, the model's implicit pitch solve, the registry."""

import jax.numpy as jnp
import numpy as np
import pytest

from bayes_roadload import config, thesis
from bayes_roadload.physics import TERMS, Conditions, DragModel, air_density_kgpm3, full_model, simplified_model
from bayes_roadload.physics import terms as T

G = config.GRAVITY_MPS2


def conditions(**kw):
    base = dict(speed_mps=25.0, airspeed_mps=27.0, yaw_rad=0.1, driveline_force_n=40.0, position_m=300.0,
                distance_m=300.0, time_s=12.0, accel_mps2=-0.3, direction=1.0,
                air_density_kgpm3=1.2, temperature_k=config.REFERENCE_TEMPERATURE_K, mass_kg=1100.0,
                frontal_area_m2=1.85)
    base.update(kw)
    return Conditions(**{k: jnp.asarray(v, float) for k, v in base.items()})


P = {"AD": 0.01, "BD": 2e-4, "KT": 0.0086, "CD0": 0.4, "KD": 0.614, "CL0": 0.273, "KL": 3.64, "KS": 2.4,
     "Cy": 25000.0, "Kalpha": 0.9, "pitch_gain": 0.01, "At": 21.0, "Bt": 2.09, "Ct": -0.02, "Au": 3.24,
     "Bu": 0.232, "grade_rad": 0.002, "grade_scale": 1.0, "yaw_saturation_per_rad2": 5.0,
     "yaw_levelling_per_rad2": 0.5, "yaw_knee_rad": 0.35}


def test_air_density_reference():
    assert float(air_density_kgpm3()) == pytest.approx(100_000.0 / (287.05 * 293.2), rel=1e-12)
    assert float(air_density_kgpm3(101_325.0, 288.15)) == pytest.approx(1.2250, abs=2e-4)


def test_terms_match_their_equations():
    c = conditions()
    q_a = 0.5 * 1.2 * 27.0**2 * 1.85
    tyre = 1100 * G * (0.01 + 2e-4 * 25.0)
    expected = {
        "tyre_rolling": tyre,
        "lift_unloading": -q_a * (0.273 + 3.64 * 0.01) * (0.01 + 2e-4 * 25.0),
        "aero_drag": q_a * (0.4 + 0.614 * 0.01),
        "aero_drag_saturating": q_a * (0.4 + 0.614 * 0.01 / (1.0 + 5.0 * 0.01)),
        "aero_drag_levelling": q_a * (0.4 + 0.614 * 0.01 - 0.5 * 0.01**2 / (0.35**2 + 0.01)),
        "side_force_slip": (q_a * 2.4 * 0.1) ** 2 / (4 * 25000.0),
        "pitch_attitude": q_a * 0.9 * 0.01 * -0.3,
        "driveline_measured": 40.0,
        "driveline_polynomial": 21.0 + 2.09 * 25 - 0.02 * 625,
        "undriven_wheels": 3.24 + 0.232 * 25,
        "gradient": 1100 * G * np.sin(0.002),
    }
    for name, value in expected.items():
        assert float(TERMS[name]().force_n(P, c)) == pytest.approx(value, rel=1e-12), name


def test_tyre_temperature_correction_eq_2_38():
    hot = conditions(temperature_k=config.REFERENCE_TEMPERATURE_K + 10.0)
    ratio = T.TyreRolling().force_n(P, hot) / T.TyreRolling().force_n(P, conditions())
    assert float(ratio) == pytest.approx(1 - 0.0086 * 10.0)


def test_gradient_reverses_with_direction_and_profile():
    up, down = conditions(direction=1.0), conditions(direction=-1.0)
    g = T.Gradient()
    assert float(g.force_n(P, up)) == pytest.approx(-float(g.force_n(P, down)))
    prof = T.GradientProfile(position_m=(0.0, 1000.0), grade_rad=(0.0, 0.004))
    assert float(prof.force_n(P, up)) == pytest.approx(1100 * G * np.sin(0.0012), rel=1e-9)
    with pytest.raises(ValueError):
        T.GradientProfile(position_m=(0.0, 0.0), grade_rad=(0.0, 1.0))


def test_surveyed_gradient_reads_the_grade_channel():
    """M g sin(d theta) with theta the surveyed grade at the logged position, reversing with the
    direction; integrated over a run, a constant surveyed grade moves the vehicle exactly as the
    constant-grade term."""
    from bayes_roadload.physics.integrate import integrate_run, make_run

    s = T.SurveyedGradient()
    assert s.speed_affine and not s.defaults
    for d in (1.0, -1.0):
        assert float(s.force_n({}, conditions(direction=d, track_grade_rad=0.003))) == pytest.approx(
            1100 * G * np.sin(d * 0.003), rel=1e-12)
    t = np.arange(0.0, 60.0, 0.5)
    v = 30.0 - 0.3 * t
    vehicle = {"mass_kg": 1100.0, "effective_mass_kg": 1130.0, "frontal_area_m2": 1.85}
    p = {"AD": 0.01, "BD": 2e-4, "CD0": 0.4, "KD": 0.6, "grade_rad": 0.004}
    base = (T.TyreRolling(), T.AeroDrag())
    constant, _ = integrate_run(DragModel(base + (T.Gradient(),)), p, make_run(t, v, **vehicle))
    surveyed, _ = integrate_run(DragModel(base + (s,)), p, make_run(t, v, track_grade_rad=0.004, **vehicle))
    np.testing.assert_allclose(np.asarray(surveyed), np.asarray(constant), rtol=1e-12)
    level, _ = integrate_run(DragModel(base), p, make_run(t, v, **vehicle))
    assert float(np.asarray(level)[-1] - np.asarray(surveyed)[-1]) > 0.5   # the grade slows the vehicle


def test_saturating_yaw_drag_keeps_the_zero_yaw_curvature_and_levels_off():
    """c_psi = 0 is the quadratic drag; K_D stays the curvature at zero yaw; the yaw term is
    half its ceiling K_D / c_psi at psi = 1 / sqrt(c_psi)."""
    sat, quad = T.AeroDragSaturating(), T.AeroDrag()
    q_a = 0.5 * 1.2 * 27.0**2 * 1.85
    for yaw in (0.0, 0.05, 0.3):
        c = conditions(yaw_rad=yaw)
        assert float(sat.force_n(dict(P, yaw_saturation_per_rad2=0.0), c)) == pytest.approx(float(quad.force_n(P, c)), rel=1e-14)
    small = 1e-3
    yaw_term = float(sat.force_n(P, conditions(yaw_rad=small))) / q_a - 0.4
    assert yaw_term / small**2 == pytest.approx(0.614, rel=1e-5)
    half = float(sat.force_n(P, conditions(yaw_rad=1.0 / np.sqrt(5.0)))) / q_a - 0.4
    assert half == pytest.approx(0.5 * 0.614 / 5.0, rel=1e-12)


def test_saturating_yaw_shape_fits_the_thesis_tunnel_table_better_than_the_quadratic():
    """The docstring's reading of the thesis tunnel table: the saturating shape fits it with
    an rms under half the quadratic's, c_psi is positive by more than two of its standard
    errors, and the quoted figures are those of the fits."""
    from scipy.optimize import least_squares

    psi = np.deg2rad(thesis.THESIS_TUNNEL_TABLE["yaw_deg"])
    cd = np.asarray(thesis.THESIS_TUNNEL_TABLE["cd"])
    sat = least_squares(lambda x: x[0] + x[1] * psi**2 / (1 + x[2] * psi**2) - cd, [0.4, 0.6, 1.0])
    quad = least_squares(lambda x: x[0] + x[1] * psi**2 - cd, [0.4, 0.6])
    rms = lambda r: float(np.sqrt(np.mean(r.fun**2)))  # noqa: E731
    assert rms(sat) < 0.5 * rms(quad)
    cov = np.linalg.inv(sat.jac.T @ sat.jac) * np.sum(sat.fun**2) / (psi.size - 3)
    assert sat.x[2] > 2.0 * np.sqrt(cov[2, 2])
    # the figures the term's docstring and models/four_term_tyre_lag_saturating.toml quote
    assert (round(sat.x[1], 2), round(sat.x[2], 1), round(np.sqrt(cov[2, 2]), 1)) == (1.16, 7.7, 2.3)
    assert (round(rms(sat), 3), round(rms(quad), 3)) == (0.004, 0.009)
    narrow = np.abs(psi) <= np.deg2rad(15.0) + 1e-12
    kd15 = np.linalg.lstsq(np.c_[np.ones(narrow.sum()), psi[narrow] ** 2], cd[narrow], rcond=None)[0][1]
    assert (round(kd15, 2), round(quad.x[1], 2)) == (0.76, 0.45)


def test_levelling_yaw_drag_spans_the_quadratic_and_the_saturating_form():
    """L_psi = 0 is the quadratic drag and L_psi = K_D the saturating form with c_psi = 1 / psi_k^2;
    K_D stays the curvature at zero yaw and K_D - L_psi is the curvature far beyond the knee."""
    lev, sat, quad = T.AeroDragLevelling(), T.AeroDragSaturating(), T.AeroDrag()
    q_a = 0.5 * 1.2 * 27.0**2 * 1.85
    for yaw in (0.0, 0.05, 0.3, 0.6):
        c = conditions(yaw_rad=yaw)
        assert float(lev.force_n(dict(P, yaw_levelling_per_rad2=0.0), c)) == pytest.approx(float(quad.force_n(P, c)), rel=1e-14)
        full = dict(P, yaw_levelling_per_rad2=P["KD"], yaw_saturation_per_rad2=1.0 / P["yaw_knee_rad"] ** 2)
        assert float(lev.force_n(full, c)) == pytest.approx(float(sat.force_n(full, c)), rel=1e-12)
    small = 1e-3
    assert (float(lev.force_n(P, conditions(yaw_rad=small))) / q_a - 0.4) / small**2 == pytest.approx(0.614, rel=1e-5)
    yaw_term = lambda yaw: float(lev.force_n(P, conditions(yaw_rad=yaw))) / q_a - 0.4  # noqa: E731
    far, step = 30.0, 1e-3
    curvature = (yaw_term(far + step) - 2 * yaw_term(far) + yaw_term(far - step)) / (2 * step**2)
    assert curvature == pytest.approx(0.614 - 0.5, rel=1e-3)


def test_levelling_yaw_shape_fits_the_thesis_tunnel_table_as_its_model_file_says():
    """The figures models/four_term_tyre_lag_levelling.toml and the term's docstring quote: at a
    20 deg knee the thesis tunnel table gives K_D 1.21, L_psi 1.22 (full levelling), rms 0.0042
    against the quadratic's 0.009; knees of 15 and 25 deg fit with rms 0.0046 and 0.0040."""
    psi = np.deg2rad(thesis.THESIS_TUNNEL_TABLE["yaw_deg"])
    cd = np.asarray(thesis.THESIS_TUNNEL_TABLE["cd"])

    def fit(knee_deg):
        X = np.c_[np.ones_like(psi), psi**2, -psi**4 / (np.deg2rad(knee_deg) ** 2 + psi**2)]
        coef = np.linalg.lstsq(X, cd, rcond=None)[0]
        return coef, float(np.sqrt(np.mean((X @ coef - cd) ** 2)))

    coef, rms20 = fit(20.0)
    assert (round(coef[1], 2), round(coef[2], 2), round(rms20, 4)) == (1.21, 1.22, 0.0042)
    assert (round(fit(15.0)[1], 4), round(fit(25.0)[1], 4)) == (0.0046, 0.004)
    assert T.AeroDragLevelling.defaults["yaw_knee_rad"] == pytest.approx(np.deg2rad(20.0), abs=1e-3)


def test_tunnel_table_keeps_cd0_at_zero_yaw():
    t = T.AeroDragTable(yaw_deg=tuple(thesis.THESIS_TUNNEL_TABLE["yaw_deg"]), cd=tuple(thesis.THESIS_TUNNEL_TABLE["cd"]))
    c0 = conditions(yaw_rad=0.0)
    assert float(t.force_n({"CD0": 0.4}, c0)) == pytest.approx(0.5 * 1.2 * 27.0**2 * 1.85 * 0.4)
    c10 = conditions(yaw_rad=np.deg2rad(10.0))
    cd10 = 0.4 + 0.426 - 0.401
    assert float(t.force_n({"CD0": 0.4}, c10)) == pytest.approx(0.5 * 1.2 * 27.0**2 * 1.85 * cd10)


def test_no_term_falls_back_to_the_thesis_vehicle():
    """The tunnel table must be given, and the driveline and undriven-wheel losses are zero
    until given or fitted (not the thesis car's)."""
    with pytest.raises(TypeError):
        T.AeroDragTable()
    assert set(T.DrivelinePolynomial.defaults.values()) == {0.0}
    assert set(T.UndrivenWheels.defaults.values()) == {0.0}
    assert simplified_model(tunnel_table=None).term_names[-1] == "aero_drag"
    table = simplified_model(tunnel_table={"yaw_deg": [-10.0, 0.0, 10.0], "cd": [0.5, 0.4, 0.5]}).terms[-1]
    assert table.yaw_deg == (-10.0, 0.0, 10.0) and table.cd == (0.5, 0.4, 0.5)


def test_pitch_implicit_solve_is_exact():
    """M_e a = -F(a) holds at the returned a, for a term depending on dv/dt."""
    model = full_model()
    c = conditions()
    a = model.acceleration_mps2(P, c, 1130.0)
    residual = 1130.0 * a + model.force_n(P, c._replace(accel_mps2=a))
    assert abs(float(residual)) < 1e-9
    # without the pitch term it is the explicit -F/M_e
    plain = model.without("pitch_attitude")
    assert float(plain.acceleration_mps2(P, c, 1130.0)) == pytest.approx(-float(plain.force_n(P, c)) / 1130.0)


def test_the_pitch_solve_evaluates_the_terms_that_do_not_read_dv_dt_once():
    """The slope of F in dv/dt is taken from the terms that read it; every other term is
    evaluated once per acceleration (the integrator calls it at each RK4 stage)."""
    import dataclasses
    from typing import ClassVar

    calls = []

    @dataclasses.dataclass(frozen=True)
    class Counted(T.Term):
        name: ClassVar[str] = "counted"
        defaults: ClassVar[dict] = {}

        def force_n(self, p, c):
            calls.append(1)
            return 50.0 + 0.0 * c.speed_mps

    model = DragModel((Counted(), T.PitchAttitude()), full_model().air)
    c = conditions()
    a = model.acceleration_mps2(P, c, 1130.0)
    assert len(calls) == 1
    residual = 1130.0 * a + model.force_n(P, c._replace(accel_mps2=a))
    assert abs(float(residual)) < 1e-9


def test_model_composition():
    m = simplified_model(driveline="polynomial", undriven=True, lift=True)
    assert m.term_names == ("tyre_rolling", "lift_unloading", "driveline_polynomial", "undriven_wheels", "aero_drag")
    assert {"AD", "BD", "CD0", "KD", "At", "Bt", "Ct", "Au", "Bu"} <= set(m.parameter_names)
    # one effect in, one effect out, nothing else changes
    m2 = m.with_terms(T.Gradient())
    assert m2.term_names[-1] == "gradient" and m2.without("gradient").term_names == m.term_names
    c = conditions()
    total = m2.force_n(P, c)
    parts = m2.force_components_n(P, c)
    assert float(total) == pytest.approx(sum(float(v) for v in parts.values()))
    with pytest.raises(ValueError):
        DragModel((T.AeroDrag(), T.AeroDrag()))
    with pytest.raises(ValueError):
        simplified_model(driveline="belt")


def test_register_term_refuses_duplicates():
    with pytest.raises(ValueError):
        T.register_term(T.AeroDrag)
