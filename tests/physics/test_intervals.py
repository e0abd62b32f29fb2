"""Interval times by Gauss-Legendre quadrature against appendix D, their gradients, and the
band-time likelihood against the dense multivariate normal."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.stats import multivariate_normal

from bayes_roadload.physics.integrate import quadratic_coastdown_time
from bayes_roadload.physics.intervals import (
    IntervalBands,
    band_time_covariance,
    band_time_loglik,
    check_speed_domain,
    interval_times,
)
from bayes_roadload.physics.model import model_from_names, simplified_model

KPH = 1 / 3.6


def bands(start_kph, end_kph, direction=1.0, rho=1.2, me=1550.0):
    n = len(start_kph)
    return IntervalBands(jnp.asarray(start_kph) * KPH, jnp.asarray(end_kph) * KPH, jnp.full(n, direction),
                         jnp.full(n, rho), jnp.full(n, 293.2), jnp.full(n, 1500.0), jnp.full(n, me), jnp.full(n, 2.2))


def test_interval_time_and_distance_match_the_closed_form():
    model = simplified_model(air="still")
    b = bands([95.0, 50.0, 30.0], [90.0, 35.0, 10.0])
    p = {"AD": 0.008, "BD": 1e-4, "CD0": 0.3, "KD": 0.0, "KT": 0.0}
    out = interval_times(model, p, b)
    a, bb, c = 1500 * 9.81 * 0.008, 1500 * 9.81 * 1e-4, 0.5 * 1.2 * 2.2 * 0.3
    ref = quadratic_coastdown_time(b.speed_end_mps, b.speed_start_mps, a, bb, c, 1550.0)
    np.testing.assert_allclose(out["time_s"], ref, rtol=1e-12)
    # distance: integral of v dt by a fine trapezoid over the closed-form speed
    for i in range(3):
        v = np.linspace(float(b.speed_end_mps[i]), float(b.speed_start_mps[i]), 20001)
        integrand = 1550.0 * v / (a + bb * v + c * v**2)
        np.testing.assert_allclose(float(out["distance_m"][i]), np.trapezoid(integrand, v), rtol=1e-7)


def test_force_sensitivity_and_parameter_gradients():
    model = simplified_model(air="still")
    b = bands([95.0, 50.0], [90.0, 45.0])
    p = {"AD": 0.008, "BD": 0.0, "CD0": 0.3, "KD": 0.0}
    out = interval_times(model, p, b)
    # a constant extra force dF = M g dAD: dt/dAD = M g x dt/dF
    g = jax.jacfwd(lambda ad: interval_times(model, dict(p, AD=ad), b)["time_s"])(0.008)
    np.testing.assert_allclose(np.asarray(g), 1500 * 9.81 * np.asarray(out["dtime_dforce_s_per_n"]), rtol=1e-10)
    # reverse-mode gradient against central differences
    f = lambda cd0: interval_times(model, dict(p, CD0=cd0), b)["time_s"].sum()  # noqa: E731
    h = 1e-6
    np.testing.assert_allclose(float(jax.grad(f)(0.3)), (float(f(0.3 + h)) - float(f(0.3 - h))) / (2 * h), rtol=1e-6)


def test_grade_and_wind_act_by_direction():
    grade = model_from_names(["tyre_rolling", "aero_drag", "gradient"], air="still")
    p = {"AD": 0.008, "BD": 0.0, "CD0": 0.3, "KD": 0.0, "grade_rad": 0.002}
    up, down = (interval_times(grade, p, bands([95.0], [70.0], direction=d))["time_s"] for d in (1.0, -1.0))
    assert float(up[0]) < float(down[0])  # climbing in the + direction decelerates faster
    wind = model_from_names(["tyre_rolling", "aero_drag"], air="wind")
    head = interval_times(wind, dict(p, head_wind_mps=jnp.asarray([2.0])), bands([95.0], [70.0]))["time_s"]
    still = interval_times(wind, dict(p, head_wind_mps=jnp.asarray([0.0])), bands([95.0], [70.0]))["time_s"]
    assert float(head[0]) < float(still[0])


def test_models_needing_position_or_anemometers_are_refused():
    with pytest.raises(ValueError, match="position"):
        check_speed_domain(model_from_names(["tyre_rolling", "aero_drag", "gradient_profile"], air="still"))
    with pytest.raises(ValueError, match="anemometer"):
        check_speed_domain(simplified_model(air="measured"))


def test_band_time_loglik_equals_the_dense_normal():
    rng = np.random.default_rng(0)
    r, k = 4, 5
    mask = np.ones((r, k), bool)
    mask[1, 3:] = False
    mask[3, 1:] = False
    res = rng.normal(size=(r, k)) * 0.2
    dur = rng.uniform(4, 9, (r, k))
    sens = -rng.uniform(0.01, 0.05, (r, k))
    ll = np.asarray(band_time_loglik(res, mask, dur, sens, 0.05, 0.03, 5.0))
    cov = np.asarray(band_time_covariance(mask, dur, sens, 0.05, 0.03, 5.0))
    ref = [multivariate_normal(np.zeros(mask[i].sum()), cov[i][np.ix_(mask[i], mask[i])]).logpdf(res[i][mask[i]])
           for i in range(r)]
    np.testing.assert_allclose(ll, ref, rtol=1e-12)
