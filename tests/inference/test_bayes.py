"""The numpyro models: sites, shapes, the likelihood against its parts."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpyro import handlers

from scipy import stats

from bayes_roadload import config
from bayes_roadload.inference.bayes import (
    build_problem,
    coastdown_model,
    integrated_speed,
    linearise_run_effects,
    run_log_likelihood,
    speed_noise,
    speed_residuals,
)
from bayes_roadload.inference.nuts import initial_values
from bayes_roadload.physics.residuals import local_level_loglik


def trace(problem, seed=0):
    return handlers.trace(handlers.seed(coastdown_model, jax.random.PRNGKey(seed))).get_trace(problem)


def test_pooled_sites_use_contract_names(small_campaign):
    p = build_problem(small_campaign, "four_term")
    tr = trace(p)
    assert {"AD", "BD", "CD0", "KD", "v0_mps", "sigma_mps", "q_mps_per_sqrt_s", "speed_loglik"} <= set(tr)
    assert tr["v0_mps"]["value"].shape == (4,) and tr["sigma_mps"]["value"].shape == (4,)
    assert not any(k.startswith("tau_") for k in tr)


def test_hierarchical_sites(small_campaign):
    p = build_problem(small_campaign, "three_term", pooling="hierarchical")
    assert p.varying == ("AD", "BD", "CD0")
    with pytest.raises(ValueError, match="linearise_run_effects"):
        trace(p)  # the run sensitivities are needed first
    p = linearise_run_effects(p, initial_values(p, small_campaign))
    assert p.run_jacobian.shape == p.batch.time_s.shape + (3,)
    tr = trace(p)
    for k in ("AD", "BD", "CD0"):
        assert tr[f"tau_{k}"]["value"].shape == ()
        assert f"{k}_run" not in tr and f"{k}_z" not in tr  # integrated out, drawn afterwards
    with pytest.raises(ValueError, match="robust"):
        build_problem(small_campaign, "three_term", pooling="hierarchical", robust=True)


def test_hierarchical_likelihood_is_the_first_order_marginal(small_campaign):
    """Each run's hierarchical likelihood equals the dense Gaussian with the run effects
    J diag(tau^2) J^T added to the residual covariance, J the finite-difference response of
    the run's speed to AD, BD, CD0 (an independent check of the sensitivities too)."""
    p = build_problem(small_campaign, "three_term", pooling="hierarchical")
    init = initial_values(p, small_campaign)
    p = linearise_run_effects(p, init)
    sample = {k: jnp.asarray(init[k]) for k in ("AD", "BD", "CD0", "v0_mps", "sigma_mps", "q_mps_per_sqrt_s")}
    sample.update(tau_AD=jnp.asarray(5e-4), tau_BD=jnp.asarray(3e-5), tau_CD0=jnp.asarray(0.01))
    per_run = np.asarray(run_log_likelihood(p, sample))
    b = p.batch
    base = np.asarray(b.speed_mps - integrated_speed(p, sample))
    for r in (0, 3):
        n = int(np.asarray(b.mask[r]).sum())
        cols = []
        for k in ("AD", "BD", "CD0"):
            h = 1e-6 * abs(float(init[k]))
            up = np.asarray(integrated_speed(p, dict(sample, **{k: sample[k] + h})))
            dn = np.asarray(integrated_speed(p, dict(sample, **{k: sample[k] - h})))
            cols.append((up[r, :n] - dn[r, :n]) / (2 * h))
        jac = np.stack(cols, axis=1)
        np.testing.assert_allclose(jac, np.asarray(p.run_jacobian)[r, :n], rtol=1e-5, atol=1e-9)
        t = np.asarray(b.time_s[r, :n]) - float(b.time_s[r, 0])
        q, sig = float(sample["q_mps_per_sqrt_s"]), float(speed_noise(sample)[r])  # sigma with the floor
        tau2 = np.array([5e-4, 3e-5, 0.01]) ** 2
        cov = q**2 * np.minimum.outer(t, t) + sig**2 * np.eye(n) + jac @ np.diag(tau2) @ jac.T
        ref = stats.multivariate_normal(np.zeros(n), cov).logpdf(base[r, :n])
        assert per_run[r] == pytest.approx(ref, rel=1e-9)


def test_factor_is_the_sum_of_run_likelihoods(small_campaign):
    p = build_problem(small_campaign, "four_term")
    tr = trace(p, seed=2)
    sample = {k: v["value"] for k, v in tr.items() if v["type"] == "sample" and not v.get("is_observed")}
    per_run = run_log_likelihood(p, sample)
    assert per_run.shape == (4,)
    np.testing.assert_allclose(tr["speed_loglik"]["fn"].log_factor, per_run.sum(), rtol=1e-12)
    # each run's term is the Kalman likelihood of its residual
    resid = speed_residuals(p, sample)
    b = p.batch
    sigma = np.sqrt(float(sample["sigma_mps"][1]) ** 2 + config.SPEED_NOISE_FLOOR_MPS**2)
    one = local_level_loglik(resid[1], b.time_s[1], b.mask[1], sigma, sample["q_mps_per_sqrt_s"])
    # sigma rounded once in numpy, once in JAX: an ulp in sigma^2 over ~10^3 terms of a
    # log likelihood of ~10^6 is ~10^-12 relative
    assert float(per_run[1]) == pytest.approx(float(one), rel=1e-10)
    assert float(speed_noise(sample)[1]) == pytest.approx(sigma, rel=1e-15)


def test_white_and_robust_variants(small_campaign):
    white = trace(build_problem(small_campaign, "three_term", noise="white"))
    assert "q_mps_per_sqrt_s" not in white
    robust = trace(build_problem(small_campaign, "three_term", robust=True))
    assert "student_df" in robust
    with pytest.raises(ValueError):
        build_problem(small_campaign, "three_term", pooling="partial")


@pytest.mark.slow  # 20-30 s; the integrator's forward and reverse gradients agree in tests/physics
def test_forward_and_reverse_gradients_of_the_potential_agree(small_campaign):
    import dataclasses

    from numpyro.infer.util import initialize_model

    p = build_problem(small_campaign, "four_term")
    grads = []
    for mode in ("forward", "reverse"):
        q = dataclasses.replace(p, gradients=mode)
        info, pot, _, _ = initialize_model(jax.random.PRNGKey(1), coastdown_model, model_args=(q,))
        grads.append(jax.grad(pot)(info.z))
    for k in grads[0]:
        np.testing.assert_allclose(grads[0][k], grads[1][k], rtol=1e-8, atol=1e-10)


def _driveline_campaign():
    import warnings

    from bayes_roadload.simulate import simulate_campaign

    from ..conftest import clean_case

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return simulate_campaign(clean_case(), pairs=1, seed=2, driveline=True)


def test_driveline_channel_enters_the_likelihood(monkeypatch):
    """four_term_driveline on a campaign that logs the driveline force: the logged force enters
    the likelihood, Normal around A_t + B_t v + C_t v^2 at the logged speed."""
    from bayes_roadload.inference import bayes
    from bayes_roadload.inference.bayes import driveline_log_likelihood

    campaign = _driveline_campaign()
    p = build_problem(campaign, "four_term_driveline")
    assert p.driveline_channel and "sigma_driveline_n" in p.initial
    assert not build_problem(campaign, "four_term").driveline_channel  # measured driveline: an input
    with monkeypatch.context() as m:  # the sites and prior draws only: no speed integration op by op
        m.setattr(bayes, "run_log_likelihood", lambda problem, sample: jnp.zeros(problem.n_runs))
        tr = trace(p)
    assert "sigma_driveline_n" in tr and "driveline_loglik" in tr
    sample = {k: tr[k]["value"] for k in p.free}
    b = p.batch
    v, f = np.asarray(b.speed_mps)[np.asarray(b.mask)], np.asarray(b.driveline_force_n)[np.asarray(b.mask)]
    expected = stats.norm(sample["At"] + sample["Bt"] * v + sample["Ct"] * v**2, 3.0).logpdf(f).sum()
    assert float(driveline_log_likelihood(p, sample, 3.0)) == pytest.approx(expected, rel=1e-10)


@pytest.mark.slow  # ~15 s: the MAP of the driveline model compiles
def test_driveline_channel_measures_the_polynomial():
    """With the logged force in the likelihood A_t is measured by that channel instead of
    trading with M g A_D: its Laplace sd at the MAP is far below the prior's 20 N and the MAP is
    within 4 of those sd of the truth."""
    import jax.flatten_util

    from bayes_roadload.inference.nuts import find_map, unconstrained_posterior

    campaign = _driveline_campaign()
    p = build_problem(campaign, "four_term_driveline")
    post = unconstrained_posterior(p, initial_values(p, campaign))
    m = find_map(p, {}, posterior=post)
    flat, _ = jax.flatten_util.ravel_pytree(m.z)
    assert flat.size == m.cov.shape[0]
    unit = {k: jnp.zeros_like(v) + (1.0 if k == "At" else 0.0) for k, v in m.z.items()}
    i = int(np.argmax(np.asarray(jax.flatten_util.ravel_pytree(unit)[0])))
    sd_at = float(np.sqrt(m.cov[i, i]))  # At is unbounded: its unconstrained coordinate is At itself
    assert sd_at < 2.0
    assert abs(float(m.constrained["At"]) - campaign.truth["At"]) < 4 * sd_at


@pytest.mark.parametrize("pooling", ["pooled", pytest.param("hierarchical", marks=pytest.mark.slow)])
def test_reverting_noise_scores_the_reverting_residual(small_campaign, pooling):
    """``noise="reverting"`` samples q as the integrated noise does, and each run's term is
    the reverting likelihood (:func:`~bayes_roadload.physics.residuals.reverting_loglik_batch`,
    tested against the dense normal) of the residual, with the factors of the model's own
    d(dv/dt)/dv along its trajectory (hierarchical, ``slow``: the hierarchical residuals, at
    each run's reference coefficients).  Robust noise has no reverting form and is refused."""
    from bayes_roadload.inference.bayes import _residuals_and_reversion, effect_residuals, run_parameters
    from bayes_roadload.physics.integrate import reversion_rate
    from bayes_roadload.physics.residuals import reversion_factors, reverting_loglik_batch

    p = build_problem(small_campaign, "four_term", noise="reverting", pooling=pooling)
    if pooling == "hierarchical":
        p = linearise_run_effects(p, initial_values(p, small_campaign))
    assert p.integrated_noise          # q is sampled as for the random walk
    truth = small_campaign.truth
    sample = {**{k: jnp.asarray(float(truth[k])) for k in p.free}, "v0_mps": jnp.asarray(p.batch.speed_mps)[:, 0],
              "sigma_mps": jnp.full(p.n_runs, 0.05), "q_mps_per_sqrt_s": jnp.asarray(0.003)}
    sample.update({f"tau_{n}": jnp.asarray(0.1 * abs(float(truth[n]))) for n in p.varying})
    if pooling == "pooled":
        def parts(s):  # compiled once each (eager dispatch of the integrator's scans is slow)
            speed = integrated_speed(p, s)
            phi = reversion_factors(p.batch.time_s, p.batch.mask,
                                    reversion_rate(p.model, run_parameters(p, s), p.batch, speed))
            return phi, reverting_loglik_batch(p.batch.speed_mps - speed, p.batch.time_s, p.batch.mask,
                                               speed_noise(s), s["q_mps_per_sqrt_s"], phi)

        per_run = jax.jit(lambda s: run_log_likelihood(p, s))(sample)
        phi, ref = jax.jit(parts)(sample)
        later = np.asarray(p.batch.mask)[:, 1:]
        assert np.all(np.asarray(phi)[:, 1:][later] < 1.0)    # B_D > 0: a speed error decays
        np.testing.assert_allclose(per_run, ref, rtol=1e-12)
    else:
        resid, phi = _residuals_and_reversion(p, sample)
        np.testing.assert_allclose(resid, effect_residuals(p, sample), rtol=1e-12, atol=1e-12)
        later = np.asarray(p.batch.mask)[:, 1:]
        assert np.all(np.asarray(phi)[:, 1:][later] < 1.0)
        assert np.all(np.isfinite(np.asarray(run_log_likelihood(p, sample))))
    with pytest.raises(ValueError, match="reverting"):
        build_problem(small_campaign, "four_term", noise="reverting", robust=True)


def test_the_least_squares_start_keeps_the_measured_speeds_above_its_jacobian_budget(small_campaign, monkeypatch):
    """``initial_values`` fits every run's initial speed with the coefficients while the dense
    Jacobian (8 bytes x padded samples x (free + runs)) fits config.LSQ_START_MAX_JACOBIAN_BYTES;
    with a budget one byte below it the start keeps the measured first speeds and still fits
    the coefficients (the same estimates to the least-squares fit with measured speeds)."""
    from bayes_roadload.inference.lsq import fit_lsq
    from bayes_roadload.inference.nuts import start_lsq_settings

    p = build_problem(small_campaign, "three_term")
    need = 8.0 * np.size(p.batch.speed_mps) * (len(p.free) + p.n_runs)
    monkeypatch.setattr(config, "LSQ_START_MAX_JACOBIAN_BYTES", need)
    assert start_lsq_settings(p).initial_speed == "fitted"
    fitted = initial_values(p, small_campaign)
    monkeypatch.setattr(config, "LSQ_START_MAX_JACOBIAN_BYTES", need - 1)
    settings = start_lsq_settings(p)
    assert settings.initial_speed == "measured"
    measured = initial_values(p, small_campaign)
    first = np.asarray(p.batch.speed_mps[:, 0])
    np.testing.assert_array_equal(np.asarray(measured["v0_mps"]), first)
    assert not np.array_equal(np.asarray(fitted["v0_mps"]), first)
    g = fit_lsq(small_campaign, p.spec, grouping="all", settings=settings).groups[0]
    for k in p.free:
        assert measured[k] == pytest.approx(g.estimate[k], rel=1e-12)
