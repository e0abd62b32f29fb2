"""Whitened coordinates whose scale follows the integrated noise's intensity
(``inference.nuts.noise_scaled_coordinates``, ``SamplerConfig.noise_scaled_metric``)."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from bayes_roadload.inference.nuts import fit_nuts, noise_scaled_coordinates
from bayes_roadload.inference.results import trace_report

from ..conftest import SMALL_SAMPLER

C = 0.5
"""The toy funnel's conditional sd of x1 is exp(C x0)."""
COV = np.diag([0.25, 1.0, 1.0])
"""The toy's Laplace covariance at its mode (0, 0, 0): x0 ~ N(0, 0.5^2), x1, x2 unit."""


def _toy_potential(x):
    """x0 ~ N(0, 0.5^2); x1 | x0 ~ N(0, exp(C x0)^2); x2 ~ N(0, 1): a funnel in x1 alone."""
    return 2.0 * x[0] ** 2 + 0.5 * x[1] ** 2 * jnp.exp(-2.0 * C * x[0]) + C * x[0] + 0.5 * x[2] ** 2


def _toy_coordinates():
    grad = jax.jit(jax.grad(_toy_potential))
    return noise_scaled_coordinates(np.zeros(3), COV, 0, lambda y: grad(jnp.asarray(y)), np.ones(3),
                                    np.full(3, -1))


def test_the_rates_follow_the_conditional_scale_and_leave_the_rest():
    """x1's conditional sd exp(C x0) is exp(C sd(x0) u0) in whitened units: rate C * 0.5; x2
    does not depend on x0: rate 0."""
    _, _, rates = _toy_coordinates()
    assert rates[0] == pytest.approx(C * 0.5, rel=1e-3)
    assert rates[1] == pytest.approx(0.0, abs=1e-6)


def test_the_log_jacobian_is_the_change_of_coordinates_own():
    """log |det dx/du| (by automatic differentiation) equals the returned log Jacobian plus
    log det L at any u: the potential in u is the posterior's, exactly."""
    to_x, log_jacobian, _ = _toy_coordinates()
    log_det_l = 0.5 * np.log(np.linalg.det(COV))
    for u in np.random.default_rng(0).normal(size=(5, 3)) * 2.0:
        _, logdet = np.linalg.slogdet(np.asarray(jax.jacfwd(to_x)(jnp.asarray(u))))
        assert logdet == pytest.approx(float(log_jacobian(jnp.asarray(u))) + log_det_l, abs=1e-10)
    assert np.allclose(np.asarray(to_x(jnp.zeros(3))), 0.0)  # u = 0 is the mode


def test_the_funnels_draws_in_the_scaled_coordinates_are_the_posterior():
    """Exact draws of u under the potential U(x(u)) - log J(u), pushed through x(u), have
    the funnel's moments: by importance weights from a wide normal (no sampler involved)."""
    to_x, log_jacobian, _ = _toy_coordinates()
    rng = np.random.default_rng(1)
    u = rng.normal(size=(200_000, 3)) * 1.5
    x = np.asarray(jax.vmap(to_x)(jnp.asarray(u)))
    log_w = -(np.asarray(jax.vmap(_toy_potential)(jnp.asarray(x))) - np.asarray(jax.vmap(log_jacobian)(jnp.asarray(u))))
    log_w += 0.5 * np.sum((u / 1.5) ** 2, axis=1)  # divided by the proposal's density
    w = np.exp(log_w - log_w.max())
    w /= w.sum()
    mean_x0 = np.sum(w * x[:, 0])
    var_x0 = np.sum(w * (x[:, 0] - mean_x0) ** 2)
    var_x1 = np.sum(w * x[:, 1] ** 2)
    assert mean_x0 == pytest.approx(0.0, abs=0.01)
    assert var_x0 == pytest.approx(0.25, rel=0.03)
    assert var_x1 == pytest.approx(np.exp(2.0 * C ** 2 * 0.25), rel=0.03)  # E exp(2 C x0), x0 ~ N(0, 0.25)


@pytest.mark.slow  # a cross-check kept out of the default run's 10 minutes
def test_a_fit_in_the_scaled_coordinates_has_the_same_posterior(small_campaign, pooled_fit):
    """The option through fit_nuts: the default fit (in the noise-scaled coordinates) and one in
    the Laplace coordinates alone agree: the latter's posterior medians lie inside the default
    fit's central 50 % intervals."""
    assert SMALL_SAMPLER.noise_scaled_metric and pooled_fit.sampler.noise_scaled_metric
    diag = trace_report(pooled_fit).diagnostics  # what diagnostics.json says
    assert diag["noise_scaled_metric"] is True and int(np.sum(pooled_fit.stats["diverging"])) == 0
    rates = diag["noise_scaled_rates"]  # every coordinate but log q, each clipped to [0, 1]
    assert not any(k.startswith("q_mps_per_sqrt_s") for k in rates) and len(rates) == len(pooled_fit.map.cov) - 1
    assert all(0.0 <= r <= 1.0 for r in rates.values()) and max(rates.values()) > 0.0
    sampler = dataclasses.replace(SMALL_SAMPLER, num_warmup=200, num_samples=300, noise_scaled_metric=False)
    fit = fit_nuts(small_campaign, "four_term", sampler=sampler)
    assert trace_report(fit).diagnostics["noise_scaled_metric"] is False and fit.noise_scaled_rates is None
    for k in ("AD", "BD", "CD0", "q_mps_per_sqrt_s"):
        ref = np.asarray(pooled_fit.samples[k]).reshape(-1)
        new = np.asarray(fit.samples[k]).reshape(-1)
        lo, hi = np.quantile(ref, [0.25, 0.75])
        assert lo < np.median(new) < hi, (k, lo, np.median(new), hi)
