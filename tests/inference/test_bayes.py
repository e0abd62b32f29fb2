"""The numpyro models: sites, shapes, the likelihood against its parts."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpyro import handlers

from bayes_roadload.inference.bayes import build_problem, coastdown_model, run_log_likelihood, speed_residuals
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
    tr = trace(p)
    for k in ("AD", "BD", "CD0"):
        assert tr[f"tau_{k}"]["value"].shape == ()
        assert tr[f"{k}_run"]["value"].shape == (4,)
        # non-centred: run values = mean + tau * z
        np.testing.assert_allclose(tr[f"{k}_run"]["value"],
                                   tr[k]["value"] + tr[f"tau_{k}"]["value"] * tr[f"{k}_z"]["value"])
    assert p.varying == ("AD", "BD", "CD0")


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
    one = local_level_loglik(resid[1], b.time_s[1], b.mask[1], sample["sigma_mps"][1], sample["q_mps_per_sqrt_s"])
    assert float(per_run[1]) == pytest.approx(float(one), rel=1e-12)


def test_white_and_robust_variants(small_campaign):
    white = trace(build_problem(small_campaign, "three_term", noise="white"))
    assert "q_mps_per_sqrt_s" not in white
    robust = trace(build_problem(small_campaign, "three_term", robust=True))
    assert "student_df" in robust
    with pytest.raises(ValueError):
        build_problem(small_campaign, "three_term", pooling="partial")


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
