"""Likelihood of speed residuals with integrated input noise (pure JAX).

The measured inputs (airspeed, yaw, driveline force) carry sensor noise that the equation of
motion integrates, and unmodelled forces (track surface, small gusts: the thesis' "system
noise") do the same.  The speed residual r_k = v_meas,k - v_calc,k is then not white: it is a
random walk (the integrated force error) plus white measurement noise,

    delta_k = delta_{k-1} + w_k,   w_k ~ N(0, q^2 dt_k)        (integrated process noise)
    r_k     = delta_k + e_k,       e_k ~ N(0, sigma^2)          (speed measurement noise)

with delta_0 = 0 (the initial speed is a parameter).  Its exact log-likelihood is given by a
scalar Kalman filter.  With q = 0 it reduces to independent Gaussian residuals.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

Array = jnp.ndarray

_LOG_2PI = jnp.log(2.0 * jnp.pi)


def local_level_loglik(residual: Array, time_s: Array, mask: Array, sigma: Array, q: Array,
                       df: Array | None = None) -> Array:
    """Log-likelihood of one run's residuals under white noise plus integrated noise.

    Parameters
    ----------
    residual : [N] measured minus integrated speed (m/s).
    time_s : [N] sample times (s); padded samples repeat the last time.
    mask : [N] True on real samples; others add nothing.
    sigma : speed measurement noise standard deviation (m/s).
    q : process noise intensity (m/s per sqrt(s)): the speed error wanders by q sqrt(t).
    df : optional Student-t degrees of freedom for outlier-robust fits: each innovation is
        scored by a Student-t of scale sqrt(S) instead of a normal (the filter update stays
        the Gaussian one: an approximation that is exact when q = 0).

    Returns
    -------
    Scalar log-likelihood.
    """
    dt = jnp.diff(time_s, prepend=time_s[:1])
    var_e = sigma**2

    def step(carry, xs):
        m, p, ll = carry
        r, h, ok = xs
        p_pred = p + q**2 * h
        s = p_pred + var_e
        innov = r - m
        k = p_pred / s
        if df is None:
            ll_k = -0.5 * (_LOG_2PI + jnp.log(s) + innov**2 / s)
        else:
            ll_k = _student_t_logpdf(innov, jnp.sqrt(s), df)
        m_new = jnp.where(ok, m + k * innov, m)
        p_new = jnp.where(ok, (1.0 - k) * p_pred, p)
        return (m_new, p_new, ll + jnp.where(ok, ll_k, 0.0)), None

    zero = jnp.zeros((), dtype=residual.dtype)
    (_, _, ll), _ = jax.lax.scan(step, (zero, zero, zero), (residual, dt, mask))
    return ll


def _student_t_logpdf(x, scale, df):
    z = x / scale
    return (jax.scipy.special.gammaln(0.5 * (df + 1.0)) - jax.scipy.special.gammaln(0.5 * df)
            - 0.5 * jnp.log(df * jnp.pi) - jnp.log(scale) - 0.5 * (df + 1.0) * jnp.log1p(z**2 / df))


def local_level_smooth(residual: Array, time_s: Array, mask: Array, sigma: Array, q: Array) -> tuple[Array, Array]:
    """Smoothed estimate (mean, variance) of the integrated error delta_k given all residuals
    (Rauch-Tung-Striebel).  Used to draw posterior-predictive speed traces and to separate the
    slow drift of a run from its measurement noise."""
    dt = jnp.diff(time_s, prepend=time_s[:1])
    var_e = sigma**2

    def fwd(carry, xs):
        m, p = carry
        r, h, ok = xs
        p_pred = p + q**2 * h
        k = jnp.where(ok, p_pred / (p_pred + var_e), 0.0)
        m_new = m + k * (r - m)
        p_new = (1.0 - k) * p_pred
        return (m_new, p_new), (m_new, p_new, m, p_pred)

    zero = jnp.zeros((), dtype=residual.dtype)
    _, (mf, pf, _, pp) = jax.lax.scan(fwd, (zero, zero), (residual, dt, mask))

    def bwd(carry, xs):
        ms, ps = carry
        m_f, p_f, p_pred_next = xs
        g = jnp.where(p_pred_next > 0, p_f / jnp.where(p_pred_next > 0, p_pred_next, 1.0), 0.0)
        m_s = m_f + g * (ms - m_f)
        p_s = p_f + g**2 * (ps - p_pred_next)
        return (m_s, p_s), (m_s, p_s)

    xs = (mf[:-1], pf[:-1], pp[1:])
    _, (ms, ps) = jax.lax.scan(bwd, (mf[-1], pf[-1]), xs, reverse=True)
    return jnp.concatenate([ms, mf[-1:]]), jnp.concatenate([ps, pf[-1:]])
