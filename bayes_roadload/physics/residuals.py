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
import numpy as np

Array = jnp.ndarray

_LOG_2PI = jnp.log(2.0 * jnp.pi)


def _steps(time_s: Array) -> Array:
    """The sample intervals along the last axis, 0 before the first sample: dt_k = t_k - t_{k-1}."""
    return jnp.diff(time_s, axis=-1, prepend=time_s[..., :1])


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
    dt = _steps(time_s)
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
    dt = _steps(time_s)
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


def uniform_grid(time_s, mask) -> tuple | None:
    """(step [R], samples [R]) when every run's real samples are equally spaced (to 1e-9
    relative) and the data are concrete; else None."""
    if any(isinstance(x, jax.core.Tracer) for x in (time_s, mask)):
        return None
    t, m = np.asarray(time_s, float), np.asarray(mask, bool)
    if t.ndim != 2:
        return None
    n = m.sum(axis=1)
    if np.any(n < 1) or np.any(m != (np.arange(t.shape[1])[None, :] < n[:, None])):
        return None  # not a prefix mask
    h = np.zeros(t.shape[0])
    for r in range(t.shape[0]):
        dt = np.diff(t[r, : n[r]])
        if dt.size:
            if np.any(np.abs(dt - dt[0]) > 1e-9 * abs(dt[0])):
                return None
            h[r] = dt[0]
    return h, n


def local_level_logdet_uniform(step_s, n_samples, var_e, q2):
    """Closed form, on an equally spaced grid, of the log determinant of a run's residual
    covariance ``var_e I + q2 K`` (the Kalman variance recursion of :func:`_logdet_and_grad`).

    In units of var_e the filtered variance follows x -> (x + rho) / (x + rho + 1),
    rho = q2 h / var_e: a Moebius map of matrix [[1, rho], [1, 1 + rho]] (determinant 1,
    eigenvalues lambda, 1/lambda), and the innovation variances telescope to the (2, 2)
    element of its (n - 1)-th power:  log det = n log var_e + (n - 1) log lambda
    + log(a + lambda^(-2(n-1)) b) - log s,  s = sqrt(rho^2 + 4 rho), a = (rho + s) / 2,
    b = 2 rho / (rho + s), lambda = 1 + a.  Small rho (n^2 rho < 1e-8): the series
    rho (n - 1) n / 2.
    """
    m = jnp.asarray(n_samples, float) - 1.0
    rho = q2 * step_s / var_e
    small = rho * (m + 1.0) ** 2 < 1e-8
    r = jnp.where(small, 1.0, rho)
    s = jnp.sqrt(r * r + 4.0 * r)
    a = 0.5 * (r + s)
    b = 2.0 * r / (r + s)
    log_lam = jnp.log1p(a)
    exact = m * log_lam + jnp.log(a + jnp.exp(-2.0 * m * log_lam) * b) - jnp.log(s)
    series = rho * m * (m + 1.0) / 2.0
    return (m + 1.0) * jnp.log(var_e) + jnp.where(small, series, exact)


def _logdet_and_grad(time_s, mask, var_e, q2):
    """[R] log det of each run's residual covariance ``var_e I + q2 K`` (K the integrated-noise
    kernel) and its derivatives with respect to var_e ([R]) and q2 (shared): the sum of the
    log innovation variances of the Kalman filter (they do not depend on the data; masked
    samples add nothing), with the two tangents carried forward by hand, all runs at once
    (one pass, no backward pass)."""
    dt = _steps(time_s)

    def step(carry, xs):
        p, dp_ve, dp_q2, ld, dld_ve, dld_q2 = carry
        h, ok = xs
        p_pred, dpp_q2 = p + q2 * h, dp_q2 + h
        s = p_pred + var_e
        ds_ve, ds_q2 = dp_ve + 1.0, dpp_q2
        gain = var_e / s
        p_new = p_pred * gain
        # d(p_pred var_e / s) = (dp_pred var_e + p_pred dvar_e) / s - p_pred var_e ds / s^2
        dpn_ve = (dp_ve * var_e + p_pred) / s - p_new * ds_ve / s
        dpn_q2 = dpp_q2 * gain - p_new * ds_q2 / s
        keep = lambda new, old: jnp.where(ok, new, old)  # noqa: E731
        return (keep(p_new, p), keep(dpn_ve, dp_ve), keep(dpn_q2, dp_q2),
                ld + jnp.where(ok, jnp.log(s), 0.0), dld_ve + jnp.where(ok, ds_ve / s, 0.0),
                dld_q2 + jnp.where(ok, ds_q2 / s, 0.0)), None

    zero = jnp.zeros(time_s.shape[:1], dtype=time_s.dtype)
    (_, _, _, ld, dld_ve, dld_q2), _ = jax.lax.scan(step, (zero,) * 6, (dt.T, mask.T))
    return ld, (dld_ve, dld_q2)


def tridiagonal_solve(lower: Array, diag: Array, upper: Array, rhs: Array) -> Array:
    """Solve T x = rhs for symmetric positive-definite tridiagonal T, batched: ``lower``,
    ``diag``, ``upper`` [R, N] (``lower[:, 0]`` and ``upper[:, -1]`` unused), ``rhs``
    [R, N, K].  The Thomas algorithm (no pivoting needed for a positive-definite T) in pure
    XLA: one ``lax.scan`` over N for the pivots c_i = u_i / (m_i - l_i c_{i-1}) (they do not
    depend on the right-hand sides), then the forward and back substitutions as two scans over
    the K columns of every run flattened into one vector, so that each loop body is element-wise
    on flat vectors (a body that broadcasts [R] pivots over [R, K] columns ran ~6 times slower
    on the CPU backend); for K = 1 the pivots come in the forward substitution's pass.
    ``jax.lax.linalg.tridiagonal_solve`` (a LAPACK custom call) is not used: called from the two
    chains' devices at once on campaigns of ~100 runs it deadlocked (0 % CPU, reproduced twice
    on 54 pairs; the same fit with this solver or sequential chains completes)."""
    r, n, k = rhs.shape
    lo, dg, up = (jnp.swapaxes(x, 0, 1) for x in (lower, diag, upper))     # [N, R]
    lo = lo.at[0].set(0.0)
    b = jnp.swapaxes(rhs, 0, 1).reshape(n, r * k)                          # [N, R K]
    if k == 1:  # pivots and forward substitution in one pass
        def forward_one(carry, xs):
            c_prev, d_prev = carry
            l_i, m_i, u_i, b_i = xs
            inv = 1.0 / (m_i - l_i * c_prev)
            c_i, d_i = u_i * inv, (b_i - l_i * d_prev) * inv
            return (c_i, d_i), (c_i, d_i)

        _, (c, d) = jax.lax.scan(forward_one, (jnp.zeros_like(dg[0]), jnp.zeros_like(b[0])), (lo, dg, up, b))
        flat = lambda x: x                                                 # noqa: E731
    else:
        def pivots(c_prev, xs):
            l_i, m_i, u_i = xs
            inv = 1.0 / (m_i - l_i * c_prev)
            return u_i * inv, (u_i * inv, inv)

        _, (c, inv) = jax.lax.scan(pivots, jnp.zeros_like(dg[0]), (lo, dg, up))
        flat = lambda x: jnp.repeat(x, k, axis=1)                          # noqa: E731  [N, R] -> [N, R K]

        def forward(d_prev, xs):
            l_i, inv_i, b_i = xs
            d_i = (b_i - l_i * d_prev) * inv_i
            return d_i, d_i

        _, d = jax.lax.scan(forward, jnp.zeros_like(b[0]), (flat(lo), flat(inv), b))

    def backward(x_next, xs):
        c_i, d_i = xs
        x_i = d_i - c_i * x_next
        return x_i, x_i

    _, x = jax.lax.scan(backward, jnp.zeros_like(b[0]), (flat(c), d), reverse=True)
    return jnp.swapaxes(x.reshape(n, r, k), 0, 1)


def _difference(x: Array, mask: Array, phi: Array | None = None) -> Array:
    """D x along the samples (axis 1: x_0, x_1 - x_0, ...), zero on padding; with ``phi``
    ([R, N]) the quasi-difference x_0, x_1 - phi_1 x_0, ... of a mean-reverting residual."""
    prev = jnp.concatenate([jnp.zeros_like(x[:, :1]), x[:, :-1]], axis=1)
    if phi is not None:
        prev = prev * phi.reshape(phi.shape + (1,) * (x.ndim - 2))
    return jnp.where(mask.reshape(mask.shape + (1,) * (x.ndim - 2)), x - prev, 0.0)


def _tridiagonal(time_s, mask, var_e, q2, phi=None):
    """Covariance of the differenced residuals (r_0, r_1 - r_0, ...): tridiagonal, with
    identity rows on padded samples.  With ``phi`` ([R, N], :func:`reversion_factors`) that of
    the quasi-differenced residuals r_k - phi_k r_{k-1} = w_k + e_k - phi_k e_{k-1}: diagonal
    Var(w_k) + var_e (1 + phi_k^2), Var(w_k) = q2 dt_k (1 + phi_k^2) / 2 (the trapezoid of
    q2 int exp(2 int_s^t -kappa) ds over the step), below it -phi_k var_e."""
    dt = _steps(time_s)
    ve = var_e[:, None]
    first = jnp.arange(time_s.shape[-1]) == 0
    if phi is None:
        step_var, lag = q2 * dt + 2.0 * ve, -ve
    else:
        both = 1.0 + phi**2
        step_var, lag = 0.5 * q2 * dt * both + ve * both, -phi * ve
    diag = jnp.where(mask, jnp.where(first, ve, step_var), 1.0)
    prev_ok = jnp.concatenate([jnp.zeros_like(mask[:, :1]), mask[:, :-1]], axis=1)
    lower = jnp.where(mask & prev_ok, jnp.broadcast_to(lag, mask.shape), 0.0)   # T[k, k-1]; T[0, -1] is not used
    upper = jnp.concatenate([lower[:, 1:], jnp.zeros_like(lower[:, :1])], axis=1)
    return lower, diag, upper


def tridiagonal_logdet(lower: Array, diag: Array, upper: Array) -> Array:
    """[R] log det of symmetric positive-definite tridiagonal matrices (the Thomas pivots
    d_i = diag_i - lower_i upper_{i-1} / d_{i-1}, one ``lax.scan`` over N)."""
    lo, dg, up = (jnp.swapaxes(x, 0, 1) for x in (lower, diag, upper))     # [N, R]
    up_prev = jnp.concatenate([jnp.zeros_like(up[:1]), up[:-1]], axis=0)

    def step(d_prev, xs):
        l_i, m_i, u_prev = xs
        d = m_i - l_i * u_prev / d_prev
        return d, jnp.log(d)

    lo = lo.at[0].set(0.0)
    _, logs = jax.lax.scan(step, jnp.ones_like(dg[0]), (lo, dg, up_prev))
    return jnp.sum(logs, axis=0)


def reversion_factors(time_s: Array, mask: Array, kappa: Array) -> Array:
    """[R, N] phi_k = exp(-(kappa_{k-1} + kappa_k) dt_k / 2): how much of the residual's
    integrated error survives the step to sample k when the error reverts at the rate
    ``kappa`` ([R, N], 1/s; :func:`bayes_roadload.physics.integrate.reversion_rate`); 1 at the
    first sample and on padding."""
    dt = _steps(time_s)
    k_prev = jnp.concatenate([kappa[:, :1], kappa[:, :-1]], axis=1)
    return jnp.where(mask, jnp.exp(-0.5 * (k_prev + kappa) * dt), 1.0)


def integrated_error_draws(time_s: Array, q: Array, normals: Array, phi: Array | None = None) -> Array:
    """[R, N] draws of the residual's integrated error delta from standard normals [R, N]:
    the random walk delta_k = delta_{k-1} + q sqrt(dt_k) z_k, or with ``phi``
    (:func:`reversion_factors`) the reverting delta_k = phi_k delta_{k-1} + w_k,
    Var(w_k) = q^2 dt_k (1 + phi_k^2) / 2 -- the processes the two likelihoods score
    (delta_0 = 0: dt_0 = 0)."""
    dt = _steps(time_s)
    if phi is None:
        return jnp.cumsum(q * jnp.sqrt(dt) * normals, axis=-1)
    w = q * jnp.sqrt(0.5 * dt * (1.0 + phi**2)) * normals

    def step(prev, xs):
        ph, wk = xs
        cur = ph * prev + wk
        return cur, cur

    _, out = jax.lax.scan(step, jnp.zeros_like(w[..., 0]), (jnp.moveaxis(phi, -1, 0), jnp.moveaxis(w, -1, 0)))
    return jnp.moveaxis(out, 0, -1)


def reverting_loglik_batch(residual: Array, time_s: Array, mask: Array, sigma: Array, q: Array,
                           phi: Array) -> Array:
    """[R] log-likelihoods of R runs' residuals when the integrated error reverts to zero:

        delta_k = phi_k delta_{k-1} + w_k,   r_k = delta_k + e_k,   delta_0 = 0,

    the linearisation of the equation of motion about the model's trajectory (a force error
    that moves the true speed also moves the truth's speed-dependent losses, which the model
    evaluates at its own speed).  ``phi`` from :func:`reversion_factors`; phi = 1 is
    :func:`local_level_loglik_batch`.  The quasi-differenced residuals have a tridiagonal
    covariance (:func:`_tridiagonal`): one banded solve and its pivots' log determinant,
    differentiated by JAX through the scans (phi depends on the coefficients)."""
    sigma = jnp.broadcast_to(jnp.asarray(sigma, residual.dtype), residual.shape[:1])
    time_s, mask = jnp.asarray(time_s, residual.dtype), jnp.asarray(mask, bool)
    q = jnp.asarray(q, residual.dtype)
    lower, diag, upper = _tridiagonal(time_s, mask, sigma**2, q**2, phi)
    y = _difference(residual, mask, phi)
    w = tridiagonal_solve(lower, diag, upper, y[..., None])[..., 0]
    n = mask.sum(axis=1)
    return -0.5 * (n * _LOG_2PI + tridiagonal_logdet(lower, diag, upper) + jnp.sum(y * w, axis=1))


def _batch_loglik(residual, time_s, mask, var_e, q2, grid):
    """The custom-gradient likelihood; ``grid`` (:func:`uniform_grid`) selects the closed-form
    log determinant, else the variance recursion."""

    def logdet_and_grad(ve, qq):
        if grid is None:
            return _logdet_and_grad(time_s, mask, ve, qq)
        h, n = (jnp.asarray(x, float) for x in grid)
        f = jax.vmap(jax.value_and_grad(local_level_logdet_uniform, argnums=(2, 3)), in_axes=(0, 0, 0, None))
        return f(h, n, ve, qq)

    def fwd(residual, var_e, q2):
        y = _difference(residual, mask)
        lower, diag, upper = _tridiagonal(time_s, mask, var_e, q2)
        w = tridiagonal_solve(lower, diag, upper, y[..., None])[..., 0]   # T^-1 D r
        alpha = _difference_transpose(w, mask)                             # D^T T^-1 D r
        logdet, (dld_ve, dld_q2) = logdet_and_grad(var_e, q2)
        n = mask.sum(axis=1)
        ll = -0.5 * (n * _LOG_2PI + logdet + jnp.sum(y * w, axis=1))
        dt = _steps(time_s)
        tail = jnp.cumsum(alpha[:, ::-1], axis=1)[:, ::-1]                 # sum_{j >= k} alpha_j
        g_ve = -0.5 * dld_ve + 0.5 * jnp.sum(alpha**2, axis=1)
        g_q2 = -0.5 * dld_q2 + 0.5 * jnp.sum(dt * tail**2, axis=1)
        return ll, (alpha, g_ve, g_q2)

    def bwd(res, ct):
        alpha, g_ve, g_q2 = res
        return (-ct[:, None] * alpha, ct * g_ve, jnp.sum(ct * g_q2))

    f = jax.custom_vjp(lambda r, ve, qq: fwd(r, ve, qq)[0])
    f.defvjp(fwd, bwd)
    return f(residual, var_e, q2)


def local_level_loglik_batch(residual: Array, time_s: Array, mask: Array, sigma: Array, q: Array) -> Array:
    """[R] log-likelihoods of R runs' residuals, equal to :func:`local_level_loglik` per run,
    computed without a sequential pass over the data.

    The differenced residuals ``(r_0, r_1 - r_0, ...)`` have a tridiagonal covariance ``T``
    (white noise differenced plus the independent increments ``q^2 dt`` of the integrated
    error), so the quadratic form is one banded solve (:func:`tridiagonal_solve`), and its reverse-mode gradient
    is closed-form: d/dr = -Sigma^-1 r, d/dsigma^2 = (-tr Sigma^-1 + |Sigma^-1 r|^2) / 2,
    d/dq^2 = (-tr(Sigma^-1 K) + sum_k dt_k (sum_{j>=k} (Sigma^-1 r)_j)^2) / 2; the log
    determinant and its derivatives come from the data-free Kalman variance recursion
    (:func:`_logdet_and_grad`), in closed form when the grid is equally spaced
    (:func:`local_level_logdet_uniform`).  ``mask`` must mark a prefix of each row (padding
    at the end, as :func:`~bayes_roadload.physics.integrate.stack_runs` builds it).
    """
    grid = uniform_grid(time_s, mask)
    sigma = jnp.broadcast_to(jnp.asarray(sigma, residual.dtype), residual.shape[:1])
    q = jnp.asarray(q, residual.dtype)
    return _batch_loglik(residual, jnp.asarray(time_s, residual.dtype), jnp.asarray(mask, bool), sigma**2, q**2, grid)


def _effect_terms(residual, time_s, mask, sigma, q, design, phi=None):
    """G = J^T Sigma^-1 J ([R, k, k]) and b = J^T Sigma^-1 r ([R, k]) for the residual
    covariance Sigma of each run, through the same banded form (differentiable); ``phi`` as
    in :func:`reverting_loglik_batch`.  Without ``phi`` the reverse-mode gradient is closed
    form (:func:`_effect_terms_walk`); with it JAX differentiates through the scans."""
    sigma = jnp.broadcast_to(jnp.asarray(sigma, residual.dtype), residual.shape[:1])
    time_s, mask = jnp.asarray(time_s, residual.dtype), jnp.asarray(mask, bool)
    q2 = jnp.asarray(q, residual.dtype) ** 2
    design = jnp.asarray(design, residual.dtype)
    if phi is None:
        return _effect_terms_walk(residual, time_s, mask, sigma**2, q2, design)
    lower, diag, upper = _tridiagonal(time_s, mask, sigma**2, q2, phi)
    dj = _difference(design, mask, phi)                                    # [R, N, k]
    w = tridiagonal_solve(lower, diag, upper, dj)                          # T^-1 D J
    g = jnp.einsum("rnk,rnl->rkl", dj, w)
    b = jnp.einsum("rnk,rn->rk", w, _difference(residual, mask, phi))
    return g, b


def _difference_transpose(x: Array, mask: Array) -> Array:
    """D^T x for the masked difference D of :func:`_difference` (no ``phi``):
    (D^T x)_n = m_n x_n - m_{n+1} x_{n+1} along axis 1."""
    m = mask.reshape(mask.shape + (1,) * (x.ndim - 2))
    mx = jnp.where(m, x, 0.0)
    return mx - jnp.concatenate([mx[:, 1:], jnp.zeros_like(mx[:, :1])], axis=1)


def _effect_terms_walk(residual, time_s, mask, var_e, q2, design):
    """G = (D J)^T T^-1 (D J) and b = (D J)^T T^-1 D r of the random-walk residual (T the
    tridiagonal covariance of the differenced residual, :func:`_tridiagonal`), with a
    closed-form reverse-mode gradient: one banded solve of k + 1 right-hand sides, W = T^-1 D J
    and w = T^-1 D r, serves both passes.  T depends on var_e and q2 through
    dT/dvar_e = D D^T and dT/dq2 = diag(dt) on the real samples, so with dT^-1 = -T^-1 dT T^-1
    and cotangents (C_G, c_b):  d/dvar_e = -sum_n [P_n^T C_G P_n + (P_n . c_b) p_n] with
    P = D^T W, p = D^T w;  d/dq2 = -sum_r sum_n dt_n [W_n^T C_G W_n + (W_n . c_b) w_n];
    d/dr = D^T (W c_b);  d/dJ = D^T [W (C_G + C_G^T) + w c_b^T]."""

    def solve(residual, var_e, q2, design):
        dj = _difference(design, mask)                                     # [R, N, k]
        y = _difference(residual, mask)                                    # [R, N]
        lower, diag, upper = _tridiagonal(time_s, mask, var_e, q2)
        both = tridiagonal_solve(lower, diag, upper, jnp.concatenate([dj, y[..., None]], axis=-1))
        w_j, w_y = both[..., :-1], both[..., -1]
        g = jnp.einsum("rnk,rnl->rkl", dj, w_j)
        b = jnp.einsum("rnk,rn->rk", w_j, y)
        return (g, b), (w_j, w_y)

    def bwd(res, ct):
        w_j, w_y = res
        c_g, c_b = ct
        p_j = _difference_transpose(w_j, mask)                             # D^T W
        p_y = _difference_transpose(w_y, mask)                             # D^T w
        pj_cb = jnp.einsum("rnk,rk->rn", p_j, c_b)
        d_ve = -(jnp.einsum("rnk,rkl,rnl->r", p_j, c_g, p_j) + jnp.sum(pj_cb * p_y, axis=1))
        dt = jnp.where(mask, _steps(time_s), 0.0)
        wj_cb = jnp.einsum("rnk,rk->rn", w_j, c_b)
        d_q2 = -jnp.sum(dt * (jnp.einsum("rnk,rkl,rnl->rn", w_j, c_g, w_j) + wj_cb * w_y))
        d_r = _difference_transpose(wj_cb, mask)
        d_j = _difference_transpose(jnp.einsum("rnk,rkl->rnl", w_j, c_g + jnp.swapaxes(c_g, 1, 2))
                                    + w_y[..., None] * c_b[:, None, :], mask)
        return d_r, d_ve, d_q2, d_j

    f = jax.custom_vjp(lambda r, ve, qq, j: solve(r, ve, qq, j)[0])
    f.defvjp(solve, bwd)
    return f(residual, var_e, q2, design)


def _effect_posterior(g, b, effect_var):
    """Gaussian posterior of the run effects delta ~ N(0, diag(effect_var)) given
    G and b: mean, covariance, and the log-likelihood correction of marginalising them."""
    s = jnp.sqrt(jnp.asarray(effect_var))                                 # [k]
    k = s.shape[0]
    m = jnp.eye(k) + s[:, None] * g * s[None, :]                           # I + S G S
    chol = jnp.linalg.cholesky(m)
    sb = s * b
    x = jax.scipy.linalg.cho_solve((chol, True), sb[..., None])[..., 0]   # M^-1 S b
    correction = 0.5 * jnp.sum(sb * x, axis=-1) - jnp.sum(jnp.log(jnp.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
    cov = s[:, None] * jax.scipy.linalg.cho_solve((chol, True), jnp.broadcast_to(jnp.eye(k), m.shape)) * s[None, :]
    return s * x, cov, correction


def local_level_loglik_effects(residual: Array, time_s: Array, mask: Array, sigma: Array, q: Array,
                               design: Array, effect_var: Array, phi: Array | None = None) -> Array:
    """[R] log-likelihoods of R runs' residuals when each run also carries its own effect
    ``J_r delta_r`` with ``delta_r ~ N(0, diag(effect_var))`` integrated out:
    ``r_r ~ N(0, Sigma_r + J_r diag(effect_var) J_r^T)``.

    ``design`` [R, N, k] is J_r (how the run's speed trace responds to the k effects); by
    Woodbury the likelihood is :func:`local_level_loglik_batch` plus
    ``b^T (T^-1 + G)^-1 b / 2 - log det(I + T^1/2 G T^1/2) / 2`` with ``G = J^T Sigma^-1 J``,
    ``b = J^T Sigma^-1 r``, ``T = diag(effect_var)``: k extra banded solves per run.  With
    ``phi`` the residual's error reverts (:func:`reverting_loglik_batch`).
    """
    g, b = _effect_terms(residual, time_s, mask, sigma, q, design, phi)
    _, _, correction = _effect_posterior(g, b, effect_var)
    if phi is not None:
        return reverting_loglik_batch(residual, time_s, mask, sigma, q, phi) + correction
    return local_level_loglik_batch(residual, time_s, mask, sigma, q) + correction


def local_level_effects_posterior(residual: Array, time_s: Array, mask: Array, sigma: Array, q: Array,
                                  design: Array, effect_var: Array, phi: Array | None = None) -> tuple[Array, Array]:
    """Conditional posterior mean [R, k] and covariance [R, k, k] of the run effects of
    :func:`local_level_loglik_effects` given the residuals."""
    g, b = _effect_terms(residual, time_s, mask, sigma, q, design, phi)
    mean, cov, _ = _effect_posterior(g, b, effect_var)
    return mean, cov
