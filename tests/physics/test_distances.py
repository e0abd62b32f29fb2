"""Passing times of markers by RK4 in distance against appendix D (closed form), against
scipy's solve_ivp (a linear tyre term and a wind), and their deceleration sensitivity against
finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from bayes_roadload import config
from bayes_roadload.physics.distances import MarkerRuns, passing_times
from bayes_roadload.physics.integrate import quadratic_coastdown_time
from bayes_roadload.physics.model import simplified_model

G, RHO, AREA = config.GRAVITY_MPS2, 1.2, 2.2
X = np.arange(0.0, 1201.0, 100.0)
WIND = simplified_model(air="wind")
PASSING = jax.jit(passing_times, static_argnames=("model", "substeps"))
"""Compiled once for the closed-form and the solve_ivp checks (same model and shapes)."""


def runs(masses=(1500.0, 1800.0), directions=(1.0, -1.0), x=X, pad_last=0):
    """Runs past the markers ``x``; the last run padded with ``pad_last`` repeated markers."""
    n = len(masses)
    d = np.tile(np.concatenate([x, np.full(pad_last, x[-1])]), (n, 1))
    mask = np.ones(d.shape, bool)
    if pad_last:
        d[:-1] = np.concatenate([x, x[-1] + 100.0 * np.arange(1, pad_last + 1)])
        mask[-1, x.size:] = False
    m = np.asarray(masses)
    return MarkerRuns(jnp.asarray(d), jnp.asarray(mask), jnp.asarray(directions), jnp.full(n, RHO),
                      jnp.full(n, config.REFERENCE_TEMPERATURE_K), jnp.asarray(m), jnp.asarray(m + 30.0),
                      jnp.full(n, AREA))


def test_passing_times_match_the_closed_form_at_two_masses():
    # F = M g AD + 0.5 rho A CD0 v^2 (no linear term, no wind): v(x)^2 = (v0^2 + a/c)
    # exp(-2 c x / M_e) - a/c, and appendix D's t(v) gives the time; each run at its own M and M_e
    p = {"AD": 0.008, "BD": 0.0, "CD0": 0.3, "KD": 0.0, "KT": 0.0, "cross_wind_mps": 0.0,
         "head_wind_mps": jnp.zeros(2)}
    v0 = jnp.array([30.0, 30.0])
    out = PASSING(WIND, p, runs(pad_last=2), v0, decel_offset_mps2=0.0)
    c = 0.5 * RHO * AREA * 0.3
    for i, m in enumerate((1500.0, 1800.0)):
        a, me = m * G * 0.008, m + 30.0
        x = X if i else np.concatenate([X, X[-1] + [100.0, 200.0]])
        v = np.sqrt((30.0**2 + a / c) * np.exp(-2.0 * c * x / me) - a / c)
        t = np.asarray(quadratic_coastdown_time(v, 30.0, a, 0.0, c, me))
        # 4 RK4 steps per 100 m: measured 1.2e-9 s over 56 s (8 steps: 8e-11 s)
        np.testing.assert_allclose(np.asarray(out["time_s"][i, :x.size]), t, rtol=0, atol=1e-8)
        np.testing.assert_allclose(np.asarray(out["speed_mps"][i, :x.size]), v, rtol=0, atol=1e-8)
    # from the same speed the heavier run decelerates less (its rolling force grows with M, the
    # drag does not): 1.5 m/s faster at its last marker than the light run at the same distance
    assert float(out["speed_mps"][1, X.size - 1]) - float(out["speed_mps"][0, X.size - 1]) > 1.0


def test_passing_times_match_solve_ivp_with_a_linear_term_a_wind_and_padding():
    p = {"AD": 0.009, "BD": 2e-4, "CD0": 0.38, "KD": 0.0, "KT": 0.0, "cross_wind_mps": 0.0,
         "head_wind_mps": jnp.array([2.0, -2.0])}     # per run: a head wind for +, a tail wind for -
    v0 = jnp.array([29.0, 31.0])
    r = runs(pad_last=2)
    out = PASSING(WIND, p, r, v0, decel_offset_mps2=0.0)
    for i, w in enumerate((2.0, -2.0)):
        m, me = float(r.mass_kg[i]), float(r.effective_mass_kg[i])
        xi = np.asarray(r.distance_m[i])[np.asarray(r.mask[i])]

        def rhs(x, y):
            v = y[0]
            force = m * G * (0.009 + 2e-4 * v) + 0.5 * RHO * AREA * 0.38 * (v + w) * abs(v + w)
            return [-force / (me * v), 1.0 / v]

        ref = solve_ivp(rhs, (0.0, xi[-1]), [float(v0[i]), 0.0], t_eval=xi, method="DOP853", rtol=1e-12, atol=1e-12)
        k = xi.size
        # RK4's truncation grows where the run is slow (the head-wind run crawls past its last
        # markers at ~7 m/s): measured 3.9e-7 s at 84 s, 1e-8 m/s
        np.testing.assert_allclose(np.asarray(out["time_s"][i, :k]), ref.y[1], rtol=0, atol=1e-6)
        np.testing.assert_allclose(np.asarray(out["speed_mps"][i, :k]), ref.y[0], rtol=0, atol=1e-7)
    # padding repeats the last marker: nothing moves there
    assert float(out["time_s"][1, -1]) == float(out["time_s"][1, X.size - 1])
    seg_times = np.diff(np.asarray(out["time_s"]), axis=1)
    assert seg_times.shape == (2, X.size + 1) and seg_times[1, -1] == 0.0 and seg_times[0, -1] > 0.0


def test_deceleration_sensitivity_and_parameter_gradients():
    p = {"AD": 0.008, "BD": 1e-4, "CD0": 0.3, "KD": 0.0, "KT": 0.0, "cross_wind_mps": 0.0,
         "head_wind_mps": jnp.zeros(2)}
    r, v0 = runs(pad_last=2), jnp.array([30.0, 28.0])
    out = PASSING(WIND, p, r, v0, decel_offset_mps2=0.0)
    eps = 1e-5
    fd = (np.asarray(PASSING(WIND, p, r, v0, decel_offset_mps2=eps)["time_s"])
          - np.asarray(PASSING(WIND, p, r, v0, decel_offset_mps2=-eps)["time_s"])) / (2 * eps)
    # the forward sensitivity equations integrate with the same RK4 steps: equal to central
    # differences to their truncation (~eps^2 x third derivative, measured 2e-8 of the largest)
    np.testing.assert_allclose(np.asarray(out["dtime_ddecel_s_per_mps2"]), fd, rtol=1e-6, atol=1e-6)
    assert np.all(np.diff(np.asarray(out["dtime_ddecel_s_per_mps2"])[0], axis=0) > 0)

    # reverse-mode gradient of a passing time in CD0 and v0 against central differences
    def last(cd0, v):
        return PASSING(WIND, dict(p, CD0=cd0), r, v, decel_offset_mps2=0.0)["time_s"][0, -1]

    g_cd, g_v = jax.jit(jax.grad(last, argnums=(0, 1)))(0.3, v0)
    h = 1e-6
    assert float(g_cd) == pytest.approx((float(last(0.3 + h, v0)) - float(last(0.3 - h, v0))) / (2 * h), rel=1e-5)
    dv = jnp.array([h, 0.0])
    assert float(g_v[0]) == pytest.approx((float(last(0.3, v0 + dv)) - float(last(0.3, v0 - dv))) / (2 * h), rel=1e-5)
    assert float(g_v[0]) < 0.0 and float(g_v[1]) == 0.0   # faster at the first marker: earlier at the last
