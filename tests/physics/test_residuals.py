"""The integrated-noise residual likelihood against a dense multivariate normal."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from bayes_roadload.physics.residuals import local_level_loglik, local_level_loglik_batch, local_level_smooth


def dense_covariance(t, sigma, q):
    # Cov(r_i, r_j) = q^2 min(t_i, t_j) + sigma^2 delta_ij with t measured from the first sample
    tt = t - t[0]
    return q**2 * np.minimum.outer(tt, tt) + sigma**2 * np.eye(t.size)


@pytest.mark.parametrize("q", [0.0, 0.004, 0.03])
def test_kalman_loglik_equals_dense_gaussian(q):
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(0.2, 0.3, 60))
    r = rng.normal(0, 0.05, t.size) + np.cumsum(rng.normal(0, 0.01, t.size))
    sigma = 0.04
    ll = float(local_level_loglik(jnp.asarray(r), jnp.asarray(t), jnp.ones(t.size, bool), sigma, q))
    ref = stats.multivariate_normal(np.zeros(t.size), dense_covariance(t, sigma, q)).logpdf(r)
    assert ll == pytest.approx(ref, rel=1e-10)


def test_masked_samples_add_nothing():
    rng = np.random.default_rng(1)
    t = np.arange(40) * 0.25
    r = rng.normal(0, 0.05, 40)
    full = local_level_loglik(jnp.asarray(r[:30]), jnp.asarray(t[:30]), jnp.ones(30, bool), 0.05, 0.01)
    tp = np.concatenate([t[:30], np.full(10, t[29])])
    rp = np.concatenate([r[:30], rng.normal(0, 5, 10)])  # garbage in the padding
    mask = np.arange(40) < 30
    padded = local_level_loglik(jnp.asarray(rp), jnp.asarray(tp), jnp.asarray(mask), 0.05, 0.01)
    assert float(padded) == pytest.approx(float(full), rel=1e-12)


def test_smoother_matches_dense_conditional_mean():
    rng = np.random.default_rng(2)
    t = np.arange(50) * 0.25
    sigma, q = 0.05, 0.02
    r = rng.normal(0, 0.05, 50) + np.cumsum(rng.normal(0, 0.01, 50))
    m, v = local_level_smooth(jnp.asarray(r), jnp.asarray(t), jnp.ones(50, bool), sigma, q)
    tt = t - t[0]
    c_dd = q**2 * np.minimum.outer(tt, tt)
    c_rr = c_dd + sigma**2 * np.eye(50)
    gain = c_dd @ np.linalg.inv(c_rr)
    np.testing.assert_allclose(m, gain @ r, atol=1e-10)
    np.testing.assert_allclose(v, np.diag(c_dd - gain @ c_dd), atol=1e-10)


def test_student_t_reduces_to_independent_t_without_process_noise():
    rng = np.random.default_rng(4)
    t = np.arange(30) * 0.25
    r = rng.standard_t(4, 30) * 0.05
    ll = local_level_loglik(jnp.asarray(r), jnp.asarray(t), jnp.ones(30, bool), 0.05, 0.0, df=4.0)
    assert float(ll) == pytest.approx(stats.t(4, scale=0.05).logpdf(r).sum(), rel=1e-10)
    # an outlier costs far less under the t than under the normal
    r_out = r.copy()
    r_out[10] = 1.0
    drop_t = float(ll) - float(local_level_loglik(jnp.asarray(r_out), jnp.asarray(t), jnp.ones(30, bool), 0.05, 0.0, df=4.0))
    drop_n = float(local_level_loglik(jnp.asarray(r), jnp.asarray(t), jnp.ones(30, bool), 0.05, 0.0)) - float(
        local_level_loglik(jnp.asarray(r_out), jnp.asarray(t), jnp.ones(30, bool), 0.05, 0.0))
    assert drop_t < 0.1 * drop_n


@pytest.mark.parametrize("q", [0.0, 0.004, 0.03])
def test_batch_loglik_and_its_gradient_equal_the_kalman_filter(q):
    """The banded-solve likelihood with its closed-form gradient equals the Kalman filter
    (value and reverse-mode gradient in residuals, sigma and q) on padded runs of unequal
    length with garbage in the padding."""
    rng = np.random.default_rng(2)
    lengths, n = [60, 47, 31, 2], 60
    t = np.zeros((4, n))
    r = rng.normal(0, 0.05, (4, n)) + np.cumsum(rng.normal(0, 0.01, (4, n)), axis=1)
    mask = np.zeros((4, n), bool)
    for i, length in enumerate(lengths):
        ti = np.cumsum(rng.uniform(0.2, 0.3, length)) - 0.25
        t[i, :length], t[i, length:] = ti, ti[-1]
        mask[i, :length] = True
        r[i, length:] = rng.normal(0, 5, n - length)
    sigma = jnp.asarray([0.03, 0.05, 0.04, 0.02])
    weights = jnp.arange(1.0, 5.0)

    def kalman(res, sig, qq):
        per_run = jax.vmap(lambda a, b, c, d: local_level_loglik(a, b, c, d, qq))(res, jnp.asarray(t), jnp.asarray(mask), sig)
        return per_run @ weights

    def banded(res, sig, qq):
        return local_level_loglik_batch(res, t, mask, sig, qq) @ weights

    args = (jnp.asarray(r), sigma, jnp.asarray(q))
    assert float(banded(*args)) == pytest.approx(float(kalman(*args)), rel=1e-11)
    for g_banded, g_kalman in zip(jax.grad(banded, argnums=(0, 1, 2))(*args), jax.grad(kalman, argnums=(0, 1, 2))(*args)):
        np.testing.assert_allclose(np.asarray(g_banded), np.asarray(g_kalman), rtol=1e-8, atol=1e-9)


@pytest.mark.parametrize("q", [0.0, 1e-7, 5e-4, 0.03, 1.0])
def test_closed_form_log_determinant_on_equally_spaced_samples(q):
    """On an equally spaced grid the log determinant has a closed form; it equals the variance
    recursion (value and derivatives in sigma^2 and q^2) from white noise (q = 0, the series
    branch) to a random walk far above the noise, and the batch likelihood takes it."""
    from bayes_roadload.physics.residuals import _logdet_and_grad, local_level_logdet_uniform, uniform_grid

    n, lengths = 503, np.array([503, 450, 2, 1])
    t = np.tile(np.arange(n) * 0.25, (4, 1))
    mask = np.arange(n)[None, :] < lengths[:, None]
    t = np.where(mask, t, (lengths[:, None] - 1) * 0.25)
    grid = uniform_grid(t, mask)
    assert grid is not None and list(grid[1]) == list(lengths)
    ve = jnp.asarray([0.03, 0.05, 0.02, 0.04]) ** 2
    q2 = jnp.asarray(q**2)
    ref, (ref_ve, ref_q2) = _logdet_and_grad(jnp.asarray(t), jnp.asarray(mask), ve, q2)
    f = jax.vmap(jax.value_and_grad(local_level_logdet_uniform, argnums=(2, 3)), in_axes=(0, 0, 0, None))
    val, (d_ve, d_q2) = f(jnp.asarray(grid[0]), jnp.asarray(grid[1], float), ve, q2)
    np.testing.assert_allclose(val, ref, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(d_ve, ref_ve, rtol=1e-8)
    np.testing.assert_allclose(d_q2, ref_q2, rtol=1e-6, atol=1e-6 * float(np.max(np.abs(ref_q2))))
    # the batch likelihood (closed form here) equals the Kalman filter
    r = np.random.default_rng(3).normal(0, 0.05, (4, n))
    kal = jax.vmap(lambda a, b, c, d: local_level_loglik(a, b, c, d, q))(jnp.asarray(r), jnp.asarray(t), jnp.asarray(mask), jnp.sqrt(ve))
    np.testing.assert_allclose(local_level_loglik_batch(jnp.asarray(r), t, mask, jnp.sqrt(ve), q), kal, rtol=1e-11)
    # a jittered grid falls back to the recursion
    jitter = t + np.where(mask, 1e-4 * np.random.default_rng(4).random(t.shape), 0.0)
    assert uniform_grid(jitter, mask) is None


def test_tridiagonal_solver_equals_lapack():
    """The pure-XLA Thomas solver (used instead of LAPACK's custom call, which deadlocked when
    both chains' devices called it at once) equals jax.lax.linalg.tridiagonal_solve."""
    from bayes_roadload.physics.residuals import tridiagonal_solve

    rng = np.random.default_rng(7)
    r, n, k = 3, 80, 2
    lower = -rng.random((r, n))
    lower[:, 0] = 0.0
    upper = np.concatenate([lower[:, 1:], np.zeros((r, 1))], axis=1)
    diag = 2.2 + rng.random((r, n))
    rhs = rng.normal(size=(r, n, k))
    args = tuple(jnp.asarray(a) for a in (lower, diag, upper, rhs))
    np.testing.assert_allclose(tridiagonal_solve(*args), jax.lax.linalg.tridiagonal_solve(*args), rtol=1e-12, atol=1e-14)


def _reverting_dense_covariance(t, phi, sigma, q):
    """Cov(r) of delta_k = phi_k delta_{k-1} + w_k, Var(w_k) = q^2 dt_k (1 + phi_k^2) / 2,
    delta_0 = 0, r = delta + e: delta = L w with L[k, j] = prod_{i=j+1..k} phi_i."""
    n = t.size
    dt = np.diff(t, prepend=t[0])
    var_w = q**2 * dt * (1.0 + phi**2) / 2.0
    var_w[0] = 0.0
    lower = np.zeros((n, n))
    for k in range(n):
        for j in range(1, k + 1):
            lower[k, j] = np.prod(phi[j + 1:k + 1])
    return lower @ np.diag(var_w) @ lower.T + sigma**2 * np.eye(n)


def test_reverting_loglik_equals_dense_gaussian_and_the_walk_at_phi_one():
    """The quasi-differenced banded likelihood of a reverting error equals the dense normal of
    its covariance (padded samples add nothing), reduces to the random walk's at phi = 1, and
    its run effects' posterior equals the dense Gaussian conditional."""
    from bayes_roadload.physics.residuals import (local_level_effects_posterior, local_level_loglik_effects,
                                                  reversion_factors, reverting_loglik_batch)

    rng = np.random.default_rng(11)
    r_runs, n = 2, 40
    t = np.tile(np.arange(n) * 0.25, (r_runs, 1))
    mask = np.ones((r_runs, n), bool)
    mask[1, 31:] = False
    t[1, 31:] = t[1, 30]
    kappa = rng.uniform(0.05, 0.6, (r_runs, n))
    sigma, q = np.array([0.05, 0.02]), 0.3
    resid = rng.normal(0, 0.1, (r_runs, n))
    phi = np.asarray(reversion_factors(jnp.asarray(t), jnp.asarray(mask), jnp.asarray(kappa)))
    assert np.all(phi[mask] <= 1.0) and np.all(phi[:, 0] == 1.0)
    design = rng.normal(size=(r_runs, n, 2))
    design[~mask] = 0.0
    tau2 = np.array([0.04, 0.09])

    @jax.jit
    def all_three(res, ph):
        args = (res, jnp.asarray(t), jnp.asarray(mask), jnp.asarray(sigma), q)
        return (reverting_loglik_batch(*args, ph),
                local_level_loglik_effects(*args, jnp.asarray(design), jnp.asarray(tau2), ph),
                local_level_effects_posterior(*args, jnp.asarray(design), jnp.asarray(tau2), ph)[0])

    ll, ll_eff, mean = all_three(jnp.asarray(resid), jnp.asarray(phi))
    for i in range(r_runs):
        m = mask[i]
        cov = _reverting_dense_covariance(t[i, m], phi[i, m], sigma[i], q)
        assert float(ll[i]) == pytest.approx(stats.multivariate_normal(np.zeros(m.sum()), cov).logpdf(resid[i, m]),
                                             rel=1e-10)
        j = design[i, m]
        marginal = cov + j @ np.diag(tau2) @ j.T
        assert float(ll_eff[i]) == pytest.approx(
            stats.multivariate_normal(np.zeros(m.sum()), marginal).logpdf(resid[i, m]), rel=1e-10)
        dense_mean = np.diag(tau2) @ j.T @ np.linalg.solve(marginal, resid[i, m])
        np.testing.assert_allclose(np.asarray(mean[i]), dense_mean, rtol=1e-8)
    walk = all_three(jnp.asarray(resid), jnp.ones((r_runs, n)))[0]
    np.testing.assert_allclose(walk, local_level_loglik_batch(jnp.asarray(resid), jnp.asarray(t), jnp.asarray(mask),
                                                               jnp.asarray(sigma), q), rtol=1e-12)


def test_error_draws_have_the_covariance_the_likelihoods_score():
    """The posterior predictive's draws of the integrated error are a linear map of standard
    normals; with the unit vectors as normals its columns give the covariance exactly: the
    random walk's q^2 min(t_i, t_j) and the reverting error's covariance of
    :func:`_reverting_dense_covariance` (without the white noise)."""
    from bayes_roadload.physics.residuals import integrated_error_draws, reversion_factors

    n, q = 25, 0.3
    t = np.cumsum(np.r_[0.0, np.full(n - 1, 0.25)])
    kappa = np.random.default_rng(3).uniform(0.05, 0.6, n)
    phi = np.asarray(reversion_factors(jnp.asarray(t[None]), jnp.ones((1, n), bool), jnp.asarray(kappa[None])))[0]
    eye = jnp.eye(n)                                   # row k: the unit normal vector e_k
    tt = jnp.broadcast_to(jnp.asarray(t), (n, n))
    walk = np.asarray(integrated_error_draws(tt, q, eye)).T          # [sample, normal]
    np.testing.assert_allclose(walk @ walk.T, dense_covariance(t, 0.0, q), atol=1e-12)
    rev = np.asarray(integrated_error_draws(tt, q, eye, jnp.broadcast_to(jnp.asarray(phi), (n, n)))).T
    np.testing.assert_allclose(rev @ rev.T, _reverting_dense_covariance(t, phi, 0.0, q), atol=1e-12)


def test_effect_terms_closed_form_gradient_equals_autodiff_and_dense_values():
    """G = J^T Sigma^-1 J and b = J^T Sigma^-1 r of the random-walk residual equal the dense
    covariance's, and their closed-form reverse-mode gradient (residual, sigma, q, design)
    equals JAX's differentiation through the banded solve's scans (the reverting form at
    phi = 1, the same covariance), on runs of different lengths (padding)."""
    from bayes_roadload.physics.residuals import _effect_terms

    rng = np.random.default_rng(5)
    r_runs, n, k = 3, 30, 3
    t = np.tile(np.arange(n) * 0.2, (r_runs, 1))
    mask = np.ones((r_runs, n), bool)
    mask[1, 22:] = False
    mask[2, 27:] = False
    for i in (1, 2):
        t[i, ~mask[i]] = t[i, mask[i]][-1]
    sigma, q = jnp.asarray([0.04, 0.02, 0.03]), jnp.asarray(0.2)
    resid = jnp.asarray(np.where(mask, rng.normal(0, 0.1, (r_runs, n)), 0.0))
    design = np.where(mask[..., None], rng.normal(size=(r_runs, n, k)), 0.0)
    c_g, c_b = jnp.asarray(rng.normal(size=(r_runs, k, k))), jnp.asarray(rng.normal(size=(r_runs, k)))
    tt, mm = jnp.asarray(t), jnp.asarray(mask)

    def scalar(phi):
        def f(res, s, qq, j):
            g, b = _effect_terms(res, tt, mm, s, qq, j, phi)
            return jnp.sum(c_g * g) + jnp.sum(c_b * b)
        return jax.jit(jax.grad(f, argnums=(0, 1, 2, 3)))

    closed = scalar(None)(resid, sigma, q, jnp.asarray(design))
    through_scans = scalar(jnp.ones((r_runs, n)))(resid, sigma, q, jnp.asarray(design))
    for a, b in zip(closed, through_scans):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-9, atol=1e-12)
    g, b = _effect_terms(resid, tt, mm, sigma, q, jnp.asarray(design))
    for i in range(r_runs):
        m = mask[i]
        ti = t[i, m] - t[i, 0]
        cov = float(q) ** 2 * np.minimum.outer(ti, ti) + float(sigma[i]) ** 2 * np.eye(m.sum())
        j = design[i, m]
        np.testing.assert_allclose(np.asarray(g[i]), j.T @ np.linalg.solve(cov, j), rtol=1e-9)
        np.testing.assert_allclose(np.asarray(b[i]), j.T @ np.linalg.solve(cov, np.asarray(resid[i, m])), rtol=1e-9)
