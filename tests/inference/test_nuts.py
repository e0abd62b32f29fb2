"""MAP + Laplace-preconditioned NUTS on a small, correctly specified campaign."""

import dataclasses
import logging

import numpy as np
import pytest

from bayes_roadload import config
from bayes_roadload.inference.results import diagnostics, summary_table, to_inference_data
from bayes_roadload.inference.nuts import MAP_NEWTON_DECREMENT

FREE = ("AD", "BD", "CD0", "KD")


def test_fit_passes_its_gates(pooled_fit):
    idata = to_inference_data(pooled_fit, predictive=False)
    diag = diagnostics(pooled_fit, idata, summary_table(pooled_fit, idata))
    assert diag["pass"], (diag["failed"], diag["max_r_hat"], diag["min_ess_bulk"], diag["min_ess_tail"])
    assert diag["divergences"] == 0 and diag["max_r_hat"] <= 1.01
    # The Laplace mass matrix makes the posterior nearly isotropic: short trees.  Unpreconditioned
    # NUTS on this posterior (AD-BD-CD0 correlations beyond 0.99) saturates depth 10
    # (benchmarks/bench_fit.py); here the mean depth is ~3.
    assert diag["mean_tree_depth"] <= 5.0
    assert pooled_fit.map.success
    # a well-posed campaign needs none of the MAP's guards, and says so
    guards = pooled_fit.map.diagnostics()
    assert 0.0 <= guards.pop("newton_decrement") < MAP_NEWTON_DECREMENT
    assert guards == {"map_method": "trust-exact", "map_fallback": "", "hessian_regularised": False,
                      "n_eigenvalues_clipped": 0, "hessian_step": 1e-4}


def test_truth_within_the_posterior(pooled_fit, small_campaign):
    """The analysis model is correctly specified here (basic physics, no instrument dynamics),
    so each true coefficient lies within 3.5 posterior sd of the mean (a 1-in-2000 event per
    parameter for a calibrated normal posterior; the campaign is seeded)."""
    for k in FREE:
        x = pooled_fit.samples[k].ravel()
        z = (x.mean() - small_campaign.truth[k]) / x.std()
        assert abs(z) < 3.5, (k, z)


def test_map_agrees_with_the_posterior(pooled_fit):
    for k in ("AD", "BD", "CD0"):
        x = pooled_fit.samples[k].ravel()
        assert abs(float(pooled_fit.map.constrained[k]) - x.mean()) < 1.0 * x.std(), k


def test_posterior_correlation_of_ad_bd_cd0(pooled_fit):
    """The reason preconditioning matters: B_D trades off against A_D and C_D0 (on this
    2-pair campaign corr(BD, CD0) ~ -0.93, corr(AD, BD) ~ -0.8)."""
    x = np.stack([pooled_fit.samples[k].ravel() for k in ("AD", "BD", "CD0")])
    corr = np.corrcoef(x)
    assert corr[1, 2] < -0.85 and corr[0, 1] < -0.6


def test_gates_fail_loudly_on_too_few_draws(pooled_fit):
    from bayes_roadload.inference.results import format_posterior_table

    short = dataclasses.replace(
        pooled_fit,
        samples={k: v[:, :12] for k, v in pooled_fit.samples.items()},
        stats={k: v[:, :12] for k, v in pooled_fit.stats.items()},
    )
    idata = to_inference_data(short, predictive=False)
    summary = summary_table(short, idata)
    diag = diagnostics(short, idata, summary)
    assert not diag["pass"] and "ess_bulk" in diag["failed"]
    table = format_posterior_table(summary, diag)
    assert table.startswith("!! NUTS FIT FAILED ITS DIAGNOSTIC GATES")
    assert "remedy: more draws" in table


def test_sampler_config_is_validated():
    with pytest.raises(ValueError):
        config.SamplerConfig(precondition="whitened")
    with pytest.raises(ValueError):
        config.SamplerConfig(num_samples=0)
    with pytest.raises(ValueError):
        config.SamplerConfig(heartbeat_s=-1.0)


def test_heartbeat_logs_while_its_block_runs_and_stops_with_it(caplog):
    import threading
    import time

    from bayes_roadload.inference.nuts import heartbeat

    caplog.set_level(logging.INFO, logger="bayes_roadload")
    with heartbeat("work", 0.05, expected_s=100.0):
        time.sleep(0.4)
    lines = [r.getMessage() for r in caplog.records if "still running" in r.getMessage()]
    # a line every 0.05 s of a 0.4 s block: about 8, at least 2 on a loaded machine
    assert len(lines) >= 2 and all(m.startswith("work: still running after") and "s left" in m for m in lines)
    assert not any(t.name == "bayes-roadload-heartbeat" for t in threading.enumerate())
    caplog.clear()
    with heartbeat("work", 0.0):
        time.sleep(0.1)
    caplog.set_level(logging.WARNING, logger="bayes_roadload")
    with heartbeat("work", 0.01):
        time.sleep(0.1)
    assert not caplog.records  # off, or INFO not shown: nothing


def test_the_heartbeats_bar_shows_the_time_so_far_and_the_time_left(caplog, capsys):
    import time

    from bayes_roadload.inference.nuts import heartbeat

    caplog.set_level(logging.INFO, logger="bayes_roadload")
    with heartbeat("work", 0.0, bar=True):
        time.sleep(1.8)
    with heartbeat("more", 0.0, expected_s=100.0, bar=True):
        time.sleep(1.8)
    err = capsys.readouterr().err
    # redrawn every 0.5 s: the draw at ~1.5 s shows one whole second, 1 % of the 100 s expected
    assert "work: 00:01" in err
    assert "more:   1%|" in err and "left" in err
    assert not caplog.records  # a bar, not log lines


def test_a_terminal_fit_draws_the_time_bar_not_numpyros_iteration_bars(caplog, capsys):
    from bayes_roadload.inference.steady import fit_steady_nuts

    caplog.set_level(logging.INFO, logger="bayes_roadload")
    fit_steady_nuts(_steady_campaign(), "four_term", sampler=dataclasses.replace(TINY, progress_bar=True))
    err = capsys.readouterr().err
    # numpyro's bars come from host callbacks that keep the program out of the compilation cache
    assert "NUTS (warm-up and sampling)" in err
    assert "Running chain" not in err and "sample:" not in err and "warmup:" not in err


def test_a_fit_without_a_progress_bar_logs_its_heartbeat(caplog):
    from bayes_roadload.inference.steady import fit_steady_nuts

    caplog.set_level(logging.INFO, logger="bayes_roadload")
    # the warm-up and sampling program of even this small fit compiles and runs for seconds
    fit_steady_nuts(_steady_campaign(), "four_term", sampler=dataclasses.replace(TINY, heartbeat_s=0.05))
    assert any(r.getMessage().startswith("NUTS (warm-up and sampling): still running") for r in caplog.records)


@pytest.mark.slow  # a second numerical check: the exact Hessian by reverse mode through the ODE, ~25 s
def test_fd_hessian_matches_the_exact_hessian(small_campaign):
    """The run-structured finite-difference Hessian (2 x (shared + per-run-of-one-run)
    gradients) equals JAX's exact Hessian (reverse mode through the ODE) at the MAP."""
    import jax
    import jax.numpy as jnp

    from bayes_roadload.inference.bayes import build_problem
    from bayes_roadload.inference.nuts import fd_hessian, find_map, initial_values, unconstrained_posterior

    problem = build_problem(small_campaign, "three_term")
    post = unconstrained_posterior(problem, initial_values(problem, small_campaign))
    m = find_map(problem, {}, posterior=post)
    assert m.success and m.min_eigenvalue > 0
    # a well-posed campaign needs none of the guards, and says so
    guards = m.diagnostics()
    assert 0.0 <= guards.pop("newton_decrement") < MAP_NEWTON_DECREMENT
    assert guards == {"map_method": "trust-exact", "map_fallback": "", "hessian_regularised": False,
                      "n_eigenvalues_clipped": 0, "hessian_step": 1e-4}
    exact_post = unconstrained_posterior(dataclasses.replace(problem, gradients="reverse"), m.constrained)
    y = np.asarray(jax.flatten_util.ravel_pytree(m.z)[0]) / post.scale

    def objective(yy):
        return exact_post.potential_fn(exact_post.unravel(yy * post.scale))

    exact = np.asarray(jax.jit(jax.hessian(objective))(jnp.asarray(y)))
    approx = fd_hessian(jax.jit(jax.grad(objective)), y, post.run_index)
    assert np.abs(approx - exact).max() < 1e-5 * np.abs(exact).max()
    # the structure it relies on: coordinates of different runs do not interact
    other_run = post.run_index[:, None] != post.run_index[None, :]
    both_per_run = (post.run_index[:, None] >= 0) & (post.run_index[None, :] >= 0)
    assert np.abs(exact[other_run & both_per_run]).max() < 1e-9 * np.abs(exact).max()


def test_mass_matrix_option_is_validated():
    assert config.SamplerConfig().mass_matrix == "auto"
    with pytest.raises(ValueError):
        config.SamplerConfig(mass_matrix="full")


def test_auto_metric_is_dense_for_few_dimensions_and_above_the_laplace_whitening_or_diagonal():
    from bayes_roadload.inference.nuts import mass_matrix

    auto = config.SamplerConfig()
    assert mass_matrix(auto, config.DENSE_MASS_MAX_DIM) == "dense"
    assert mass_matrix(auto, config.DENSE_MASS_MAX_DIM, hierarchical=True) == "dense"
    assert mass_matrix(auto, config.DENSE_MASS_MAX_DIM + 1) == "identity"
    assert mass_matrix(auto, config.DENSE_MASS_MAX_DIM + 1, hierarchical=True) == "diag"
    for chosen in ("dense", "diag", "identity"):
        assert mass_matrix(config.SamplerConfig(mass_matrix=chosen), 77, hierarchical=True) == chosen


def test_nuts_and_least_squares_agree(pooled_fit, small_campaign):
    """On a clean campaign the joint least-squares estimate and the posterior mean differ by
    less than two posterior sd for every coefficient (priors are weak against 4 runs)."""
    from bayes_roadload.inference.lsq import fit_lsq

    g = fit_lsq(small_campaign, "four_term", grouping="all").groups[0]
    for k in FREE:
        x = pooled_fit.samples[k].ravel()
        assert abs(g.estimate[k] - x.mean()) < 2.0 * x.std(), (k, g.estimate[k], x.mean(), x.std())


@pytest.mark.slow  # ~20 s (numpyro initialises the unwhitened model op by op); the gates' failure
# path and the failure printed first are checked fast by test_gates_fail_loudly_on_too_few_draws
def test_gates_fail_on_a_deliberately_bad_configuration(small_campaign):
    """10 warm-up draws without the Laplace preconditioning (and trees capped at depth 6 to
    bound the test's cost): the sampler cannot adapt to the AD-BD-CD0 correlation, and the
    gates say so (R-hat far above 1.01, trees at their limit), with the failure first in the
    printed table."""
    from bayes_roadload.inference.nuts import fit_nuts
    from bayes_roadload.inference.results import format_posterior_table

    bad = config.SamplerConfig(num_warmup=10, num_samples=40, num_chains=2, seed=5, precondition="none",
                               max_tree_depth=6)
    fit = fit_nuts(small_campaign, "four_term", sampler=bad)
    idata = to_inference_data(fit, predictive=False)
    summary = summary_table(fit, idata)
    diag = diagnostics(fit, idata, summary)
    assert not diag["pass"]
    assert "r_hat" in diag["failed"] and diag["max_r_hat"] > 1.1
    assert format_posterior_table(summary, diag).startswith("!! NUTS FIT FAILED ITS DIAGNOSTIC GATES")


def test_one_program_keeps_only_the_post_warmup_draws(pooled_fit):
    """Warm-up and sampling run as one compiled program: the fit keeps exactly num_samples draws
    per chain (the warm-up draws, collected to split the time, are dropped) and both phase
    times are positive."""
    s = pooled_fit.sampler
    for k in FREE:
        assert pooled_fit.samples[k].shape[:2] == (s.num_chains, s.num_samples)
    assert pooled_fit.stats["num_steps"].shape == (s.num_chains, s.num_samples)
    assert pooled_fit.timings["warmup_s"] > 0 and pooled_fit.timings["sampling_s"] > 0


def _wall_quadratic(distance):
    """A quadratic objective with its optimum ``distance`` inside a wall beyond which value
    and gradient are NaN (the integrated speed of a still-air model overflows past some
    coefficient values): the Hessian by central differences at the optimum steps over the
    wall when the difference step exceeds ``distance``."""
    c = np.array([1.0 - distance, 0.5, -0.3])
    a = np.array([[2.0, 0.3, 0.0], [0.3, 1.0, 0.1], [0.0, 0.1, 0.5]])

    def f(y):
        return 0.5 * (y - c) @ a @ (y - c) + (np.nan if y[0] >= 1.0 else 0.0)

    def g(y):
        return a @ (y - c) + (np.nan if y[0] >= 1.0 else 0.0)

    return f, g, c, a


def test_newton_map_survives_a_non_finite_hessian_next_to_the_optimum():
    """With the optimum 5e-5 from the wall, the default difference step (1e-4) gives a NaN
    Hessian at an accepted iterate: scipy's trust-exact then stops with "array must not
    contain infs or NaNs".  The guarded MAP retries a smaller step and reaches the optimum."""
    from bayes_roadload.inference.nuts import newton_map

    f, g, c, a = _wall_quadratic(5e-5)
    res = newton_map(lambda y: (f(y), g(y)), np.zeros(3), np.full(3, -1), np.ones(3))
    assert res["success"] and res["map_method"] == "trust-exact"
    assert res["hessian_step"] < 5e-5  # the step had to be smaller than the distance to the wall
    np.testing.assert_allclose(res["y"], c, atol=1e-8)
    # a quadratic's central differences are exact up to rounding (|g| ~ 1, step 1e-6: ~1e-10)
    np.testing.assert_allclose(np.linalg.inv(res["cov"]), a, atol=1e-6)


def test_newton_map_falls_back_to_lbfgs_and_records_it():
    """With the optimum 5e-7 from the wall no difference step works: trust-exact is
    abandoned for L-BFGS-B, the Laplace covariance comes from its inverse-Hessian estimate,
    and both are recorded."""
    from bayes_roadload.inference.nuts import newton_map

    f, g, c, a = _wall_quadratic(5e-7)
    res = newton_map(lambda y: (f(y), g(y)), np.zeros(3), np.full(3, -1), np.ones(3))
    assert res["map_method"] == "L-BFGS-B" and "trust-exact failed" in res["map_fallback"]
    assert res["hessian_regularised"] and res["hessian_step"] == 0.0
    np.testing.assert_allclose(res["y"], c, atol=1e-6)
    cov = res["cov"]
    assert np.all(np.isfinite(cov)) and np.all(np.linalg.eigvalsh(cov) > 0)
    # L-BFGS-B's estimate of a 3-d quadratic after ~10 steps: within 5 % of the true Hessian
    assert np.abs(np.linalg.inv(cov) - a).max() < 0.05 * np.abs(a).max()


def test_newton_map_is_converged_by_its_newton_decrement_when_one_direction_is_stiff():
    """A potential of 1000 nats whose first coordinate is 1e10 times stiffer than the second
    (a campaign of little noise fixes one combination of A_D, B_D, C_D0 that tightly),
    started 5e-13 from that coordinate's optimum: its gradient there is 5e-3, above the
    1e-3 threshold, but stepping to the optimum gains 1.25e-15 nats, below the rounding of
    1000, so trust-exact cannot see the gain and stops.  The MAP is converged (its Newton
    decrement g' H^-1 g is 2.5e-15) and says so; a start 1e-6 away (decrement 1e-2 nats, a
    gain rounding can show) still converges by iterating, not by the criterion."""
    from bayes_roadload.inference.nuts import MAP_NEWTON_DECREMENT, newton_map

    stiff = 1e10

    def fg(y):
        return 1000.0 + 0.5 * stiff * y[0] ** 2 + 0.5 * y[1] ** 2, np.array([stiff * y[0], y[1]])

    res = newton_map(fg, np.array([5e-13, 0.0]), np.full(2, -1), np.ones(2))
    assert res["grad_max"] > 1e-3          # the old criterion alone would call it unconverged
    assert res["newton_decrement"] < MAP_NEWTON_DECREMENT and res["success"]
    np.testing.assert_allclose(res["newton_decrement"], res["grad_max"] ** 2 / stiff, rtol=1e-3)
    far = newton_map(fg, np.array([1e-6, 1.0]), np.full(2, -1), np.ones(2))
    assert far["success"] and abs(far["y"][0]) < 1e-12 and abs(far["y"][1]) < 1e-8


def test_newton_map_names_the_coordinate_with_a_non_finite_gradient_at_the_start():
    from bayes_roadload.errors import FitStageError
    from bayes_roadload.inference.nuts import newton_map

    def f(y):
        return float(np.sum(y**2))

    def g(y):
        d = 2.0 * y
        d[3] = np.nan
        return d

    with pytest.raises(FitStageError) as err:
        newton_map(lambda y: (f(y), g(y)), np.ones(4), np.array([-1, -1, 0, 1]), np.ones(4),
                   names=["AD", "BD", "v0_mps[0]", "v0_mps[1]"])
    assert err.value.stage == "map" and err.value.parameter == "v0_mps[1]" and err.value.run == 1
    assert "remedy" in str(err.value)


def test_laplace_covariance_clips_non_positive_eigenvalues():
    from bayes_roadload.inference.nuts import laplace_covariance

    h = np.diag([4.0, 1.0, -2.0])
    cov, min_eig, n_clipped = laplace_covariance(h)
    assert min_eig == -2.0 and n_clipped == 1
    # the clipped direction gets variance 1 / (1e-8 x largest eigenvalue)
    np.testing.assert_allclose(np.diag(cov), [0.25, 1.0, 1.0 / (1e-8 * 4.0)])


def test_laplace_cholesky_whitens_coordinates_of_very_different_scales():
    """Variances from 1e-10 (B_D) to 4e2 (a softplus coordinate), two of them correlated
    0.9999: the whitened covariance L^-1 C L^-T must be the identity.  A jitter of 1e-14 x the
    largest variance on every diagonal element (4e-12 here) is 4 % of B_D's variance and more
    than half the conditional variance of the correlated pair's difference, so it fails this."""
    from bayes_roadload.inference.nuts import laplace_cholesky

    sd = np.array([1.5e-1, 1e-5, 3.8e-1, 2.0e1, 1.8e-2])
    corr = np.eye(5)
    corr[1, 2] = corr[2, 1] = 0.9999
    cov = corr * np.outer(sd, sd)
    chol = laplace_cholesky(cov)
    assert np.allclose(np.triu(chol, 1), 0.0)
    inv = np.linalg.inv(chol)
    eig = np.linalg.eigvalsh(inv @ cov @ inv.T)
    np.testing.assert_allclose(eig, 1.0, atol=1e-8)
    # a correlation matrix that is singular to rounding is still factorised (with the jitter)
    singular = np.outer(sd, sd)
    assert np.all(np.isfinite(laplace_cholesky(singular)))


def test_soften_bounds_widens_the_coordinate_only_where_the_posterior_reaches_the_bound(small_campaign):
    """The least-squares start decides: K_D within 3 standard errors of its bound 0, without a
    finite standard error, or held at its prior's centre gets the softness for a posterior at
    its bound; estimates far from their bounds, B_D (no bound) and a failed start change
    nothing.  The priors' densities are untouched (only ``softness``)."""
    import dataclasses as dc
    from types import SimpleNamespace

    from bayes_roadload.inference.nuts import build_problem, soften_bounds
    from bayes_roadload.inference.spec import SOFTPLUS_FRACTION_AT_BOUND

    problem = build_problem(small_campaign, "four_term")
    far = {"AD": (0.01, 1e-4), "BD": (2e-4, float("nan")), "CD0": (0.35, 0.01), "KD": (0.6, 0.05)}

    def start(values, centres=()):
        g = SimpleNamespace(estimate={k: v[0] for k, v in values.items()}, se={k: v[1] for k, v in values.items()})
        return g, {k: 0.6 for k in centres}

    assert soften_bounds(problem, start(far)) is problem
    assert soften_bounds(problem, None) is problem
    for values, centres in (({**far, "KD": (0.2, 0.1)}, ()), ({**far, "KD": (0.6, float("nan"))}, ()),
                            (far, ("KD",))):
        softened = soften_bounds(problem, start(values, centres))
        assert softened.priors["KD"] == dc.replace(problem.priors["KD"], softness=SOFTPLUS_FRACTION_AT_BOUND)
        assert {k: v for k, v in softened.priors.items() if k != "KD"} == \
            {k: v for k, v in problem.priors.items() if k != "KD"}


def test_coordinate_names_follow_the_ravel_order():
    import jax.numpy as jnp
    from jax.flatten_util import ravel_pytree

    from bayes_roadload.inference.nuts import _coordinate_names

    z = {"sigma_mps": jnp.array([1.0, 2.0]), "AD": jnp.array(3.0), "v0_mps": jnp.array([4.0, 5.0])}
    flat = np.asarray(ravel_pytree(z)[0])
    names = _coordinate_names(z)
    lookup = {"AD": 3.0, "sigma_mps[0]": 1.0, "sigma_mps[1]": 2.0, "v0_mps[0]": 4.0, "v0_mps[1]": 5.0}
    assert [lookup[n] for n in names] == list(flat)
def test_collect_warmup_keeps_every_draw():
    """``nuts.collect_warmup`` is the one use of numpyro's private ``_set_collection_params``:
    this fails on a numpyro upgrade that renames it, changes its parameters or stops it from
    keeping the warm-up draws (then ``run_nuts`` would misreport the warm-up / sampling split
    and drop real draws)."""
    import inspect

    import jax
    import numpyro
    import numpyro.distributions as dist
    from numpyro.infer import MCMC, NUTS

    from bayes_roadload.inference.nuts import collect_warmup

    params = list(inspect.signature(MCMC._set_collection_params).parameters)
    assert params == ["self", "lower", "upper", "collection_size", "phase"], params

    def model():
        numpyro.sample("x", dist.Normal(0.0, 1.0))

    mcmc = MCMC(NUTS(model), num_warmup=7, num_samples=5, num_chains=1, progress_bar=False)
    collect_warmup(mcmc)
    mcmc.run(jax.random.PRNGKey(0), extra_fields=("num_steps",))
    assert mcmc.get_samples()["x"].shape == (12,)
    assert mcmc.get_extra_fields()["num_steps"].shape == (12,)


def test_small_campaigns_are_sampled_at_the_small_campaign_acceptance():
    """At most ``small_campaign_runs`` runs: target acceptance raised to the small-campaign
    value, never lowered; more runs, or no small-campaign value: unchanged."""
    from types import SimpleNamespace

    from bayes_roadload.inference.nuts import campaign_sampler

    base = config.SamplerConfig()
    runs = lambda n: SimpleNamespace(run_ids=tuple(range(n)))  # noqa: E731
    assert campaign_sampler(base, runs(base.small_campaign_runs)).target_accept == base.small_campaign_target_accept
    assert campaign_sampler(base, runs(base.small_campaign_runs + 1)) is base
    high = dataclasses.replace(base, target_accept=0.99)
    assert campaign_sampler(high, runs(2)).target_accept == 0.99
    off = dataclasses.replace(base, small_campaign_target_accept=None)
    assert campaign_sampler(off, runs(2)) is off


def test_quiet_traces_are_sampled_at_the_quiet_trace_acceptance():
    """The median run's MAP speed noise below the likelihood's floor: target acceptance raised
    to the quiet-trace value, never lowered; at or above the floor, without a speed-noise site,
    without a MAP or without a quiet-trace value: unchanged."""
    from types import SimpleNamespace

    from bayes_roadload.inference.nuts import quiet_trace_sampler

    floor = config.SPEED_NOISE_FLOOR_MPS
    base = config.SamplerConfig()
    at = lambda *sigma: SimpleNamespace(constrained={"sigma_mps": np.array(sigma)})  # noqa: E731
    assert quiet_trace_sampler(base, at(5e-5, 6e-5, 0.05)).target_accept == base.quiet_trace_target_accept
    assert quiet_trace_sampler(base, at(5e-5, floor, 0.05)) is base      # the median run at the floor
    assert quiet_trace_sampler(base, at(0.02, 0.05)) is base
    assert quiet_trace_sampler(base, SimpleNamespace(constrained={"CD0": 0.4})) is base
    assert quiet_trace_sampler(base, None) is base
    high = dataclasses.replace(base, target_accept=0.99)
    assert quiet_trace_sampler(high, at(5e-5)).target_accept == 0.99
    off = dataclasses.replace(base, quiet_trace_target_accept=None)
    assert quiet_trace_sampler(off, at(5e-5)) is off


def test_remedy_answers_each_failed_gate():
    from bayes_roadload.inference.nuts import remedy

    base = config.SamplerConfig()
    assert remedy(base, []) is None
    div = remedy(base, ["divergences"])
    assert div.target_accept == 0.99 and div.num_samples == 2 * base.num_samples and div.seed == base.seed + 1
    assert remedy(dataclasses.replace(base, target_accept=0.995), ["divergences"]).target_accept == 0.995
    for gate in ("r_hat", "ess_bulk", "ess_tail", "bfmi", "tree_depth"):
        more = remedy(base, [gate])
        assert (more.num_warmup, more.num_samples) == (2 * base.num_warmup, 2 * base.num_samples)
        assert more.target_accept == base.target_accept
    both = remedy(base, ["divergences", "r_hat"])
    assert both.target_accept == 0.99 and both.num_samples == 2 * base.num_samples
    assert not both.retry  # one retry only


def test_gate_failures_agree_with_the_diagnostics(pooled_fit):
    from bayes_roadload.inference.results import gate_failures

    idata = to_inference_data(pooled_fit, predictive=False)
    assert gate_failures(pooled_fit) == diagnostics(pooled_fit, idata, summary_table(pooled_fit, idata))["failed"]
    short = dataclasses.replace(pooled_fit, samples={k: v[:, :12] for k, v in pooled_fit.samples.items()},
                                stats={k: v[:, :12] for k, v in pooled_fit.stats.items()})
    assert {"ess_bulk", "ess_tail"} <= set(gate_failures(short))


def _steady_campaign():
    """A short steady-state campaign: the retry is
    :func:`~bayes_roadload.inference.nuts.sample_problem`'s, the same for every kind of campaign,
    and this potential (no ODE) compiles in a fraction of a speed trace's."""
    from bayes_roadload.simulate.steady import SteadySettings, simulate_steady

    return simulate_steady(9, pairs=1, seed=3, settings=SteadySettings(duration_s=8.0))


TINY = config.SamplerConfig(num_warmup=20, num_samples=20, num_chains=2, seed=3)
"""Made the default in these tests (a fit retries only at the default draws or more)."""


def _first_gates_read_as(monkeypatch, failed):
    """The first gate check of a fit reports ``failed`` (with the extremes it really read); later
    checks are the real ones.  Returns the list of (fit checked, what the check really found)."""
    from bayes_roadload.inference import results

    real, found = results.gate_check, []

    def gate_check(fit, *args, **kwargs):
        got, extremes = real(fit, *args, **kwargs)
        found.append((fit, got))
        return (failed if len(found) == 1 else got), extremes

    monkeypatch.setattr(results, "gate_check", gate_check)
    return found


def test_a_failed_r_hat_or_ess_continues_the_same_chains(monkeypatch, caplog):
    """When only R-hat or ESS failed, the chains go on for as many draws again: the fit holds the
    first attempt's draws unchanged followed by the new ones, warm-up is not repeated, and
    ``retries`` says so with what the first attempt's gates read."""
    from bayes_roadload.inference.nuts import CONTINUED_GATES
    from bayes_roadload.inference.steady import fit_steady_nuts, steady_report

    campaign = _steady_campaign()
    monkeypatch.setattr(config, "DEFAULT_SAMPLER", TINY)
    found = _first_gates_read_as(monkeypatch, ["r_hat", "ess_bulk"])
    fit = fit_steady_nuts(campaign, "four_term", sampler=TINY)
    assert {"r_hat", "ess_bulk"} <= CONTINUED_GATES and len(found) == 1  # no second check
    alone = found[0][0]  # the first attempt, as its gates were read
    assert alone.samples["CD0"].shape == (2, 20)
    (retry,) = fit.retries
    assert retry["continued"] and retry["failed"] == ["r_hat", "ess_bulk"]
    assert (retry["num_warmup"], retry["num_samples"], retry["seed"]) == (20, 40, TINY.seed)
    assert fit.sampler.num_samples == 40
    for name in ("CD0", "AD"):
        assert fit.samples[name].shape == (2, 40)
        np.testing.assert_array_equal(fit.samples[name][:, :20], alone.samples[name])
        assert not np.array_equal(fit.samples[name][:, 20:], fit.samples[name][:, :20])
    for k, v in fit.stats.items():
        assert v.shape == (2, 40), k
    np.testing.assert_array_equal(fit.stats["num_steps"][:, :20], alone.stats["num_steps"])
    assert 0 < fit.timings["extension_s"] <= fit.timings["sampling_s"] and "first_attempt_s" not in fit.timings
    # what the first attempt's gates read: the smallest ESS names a reported quantity; the
    # largest R-hat comes with its quantity's own ESS
    first = retry["first_attempt"]
    report = steady_report(fit, campaign)
    assert first["min_ess_bulk_quantity"].split("[")[0] in report.idata.posterior
    assert first["max_r_hat"] > 1.0 and first["its_ess_bulk"] >= first["min_ess_bulk"]
    # the warning names what R-hat read, and that converged chains do that by chance
    (warned,) = [r.getMessage() for r in caplog.records if r.getMessage().startswith("gates failed (r_hat, ess_bulk")]
    assert f" on {first['max_r_hat_quantity']}," in warned
    value = float(warned.split("largest R-hat ")[1].split(" ")[0])
    assert value == pytest.approx(first["max_r_hat"], abs=1e-4)  # first's is rounded to 1e-5
    assert "by chance" in warned
    diag = report.diagnostics
    assert diag["retries"] == fit.retries and diag["draws_per_chain"] == 40
    # a batch record (the studies' tables) says the retry continued the chains
    from bayes_roadload.analysis.batch import retry_fields

    record = retry_fields(fit.retries)
    assert (record["retries"], record["retry_failed"], record["retry_continued"]) == (1, "r_hat,ess_bulk", True)
    assert record["first_max_r_hat"] == first["max_r_hat"] and retry_fields([])["retry_continued"] is None
    # the chain method of the run that produced the draws, with its reason
    assert diag["chain_method"]["method"] in ("parallel", "sequential") and diag["chain_method"]["reason"]


def test_another_failed_gate_samples_anew_with_the_remedy(monkeypatch):
    """Divergences (also beside an R-hat miss), E-BFMI or tree depth need another adaptation: a
    new run with twice the warm-up and draws (0.99 after divergences) and a new seed, once,
    recorded.  After divergences the retry samples the problem that ``alternative_coordinates``
    returns, from a MAP of its own started at the values it returns, and records what changed
    and the MAP time of both (a steady-state problem standing in for one with other
    coordinates, e.g. the lag model's apparent coefficients: the retry is the same for every
    kind)."""
    from bayes_roadload.analysis.batch import retry_fields
    from bayes_roadload.inference.nuts import retry_coordinates
    from bayes_roadload.inference.steady import SteadyProblem, fit_steady_nuts

    offered = []
    own = SteadyProblem.alternative_coordinates

    def alternative(self, values):
        other = dataclasses.replace(self)
        offered.append((self, other, dict(values)))
        return other, values, "other coordinates"

    campaign = _steady_campaign()
    monkeypatch.setattr(config, "DEFAULT_SAMPLER", TINY)
    monkeypatch.setattr(SteadyProblem, "alternative_coordinates", alternative)
    failed = ["r_hat", "divergences"]
    found = _first_gates_read_as(monkeypatch, failed)
    fit = fit_steady_nuts(campaign, "four_term", sampler=TINY)
    (retry,) = fit.retries
    assert not retry["continued"] and retry["failed"] == failed
    assert (retry["num_warmup"], retry["num_samples"], retry["seed"]) == (40, 40, TINY.seed + 1)
    assert (fit.sampler.num_warmup, fit.sampler.num_samples, fit.sampler.seed) == (40, 40, TINY.seed + 1)
    assert retry["target_accept"] == fit.sampler.target_accept == 0.99
    assert fit.samples["CD0"].shape == (2, 40) and fit.timings["first_attempt_s"] > 0
    assert "extension_s" not in fit.timings
    assert retry_fields(fit.retries)["retry_continued"] is False
    # the other coordinates: the returned problem, from its own MAP started at the first one
    first = found[0][0]
    ((asked, other, values),) = offered
    assert asked is first.problem and fit.problem is other and other is not first.problem
    assert values == dict(first.map.constrained)
    assert retry["coordinates"] == "other coordinates" == retry_fields(fit.retries)["retry_coordinates"]
    assert fit.map is not first.map and fit.timings["map_s"] == pytest.approx(first.map.time_s + fit.map.time_s)
    # other gates than divergences, no MAP to start from, or a problem with one set of
    # coordinates (the steady-state problem's own): the retry keeps the coordinates
    assert retry_coordinates(first.problem, first.map, ["r_hat", "tree_depth", "e_bfmi"]) is None
    assert retry_coordinates(first.problem, None, ["divergences"]) is None and len(offered) == 1
    monkeypatch.setattr(SteadyProblem, "alternative_coordinates", own)
    assert retry_coordinates(first.problem, first.map, ["divergences"]) is None


@pytest.mark.slow  # ~60 s alone: the lag model's two MAPs and samplers compile
def test_divergences_in_the_apparent_coefficients_are_retried_in_the_direct_ones(monkeypatch, small_campaign):
    """The tyre-lag model samples its apparent coefficients; after divergences the retry samples
    A_D, B_D, C_D0 directly (the same posterior), from a MAP of its own started at the first
    attempt's, with the remedy's sampler, and says so in ``retries``."""
    from bayes_roadload.analysis.batch import retry_fields
    from bayes_roadload.inference.bayes import APPARENT_SITES
    from bayes_roadload.inference.nuts import fit_nuts

    monkeypatch.setattr(config, "DEFAULT_SAMPLER", TINY)
    found = _first_gates_read_as(monkeypatch, ["divergences"])
    fit = fit_nuts(small_campaign, "four_term_tyre_lag", sampler=TINY)
    first = found[0][0]
    assert first.problem.apparent is not None and set(APPARENT_SITES.values()) <= set(first.samples)
    (retry,) = fit.retries
    assert retry["failed"] == ["divergences"] and not retry["continued"] and retry["target_accept"] == 0.99
    assert "directly" in retry["coordinates"] and retry_fields(fit.retries)["retry_coordinates"] == retry["coordinates"]
    assert fit.problem.apparent is None and not set(APPARENT_SITES.values()) & set(fit.samples)
    for name in ("AD", "BD", "CD0", "tyre_lag_gain_per_mps"):
        assert fit.samples[name].shape == (2, 40) and np.isfinite(fit.samples[name]).all(), name
    # the retry's own MAP is in the direct coordinates, and its time is counted with the first one's
    assert set(APPARENT_SITES) <= set(fit.map.z) and not set(APPARENT_SITES.values()) & set(fit.map.z)
    assert fit.timings["map_s"] > first.map.time_s > 0



def test_the_most_implausible_least_squares_estimate_is_named():
    """Only normal priors are read; an estimate more than START_PRIOR_Z prior scales from the
    location (or not finite) is implausible, and the furthest one is named first."""
    from bayes_roadload.inference.nuts import START_PRIOR_Z, most_implausible_estimate
    from bayes_roadload.inference.spec import Prior

    priors = {"a": Prior("normal", loc=0.0, scale=1.0), "b": Prior("normal", loc=10.0, scale=2.0, low=0.0),
              "c": Prior("lognormal", loc=0.0, scale=1.0)}
    z = START_PRIOR_Z
    assert most_implausible_estimate(priors, {"a": z - 0.1, "b": 10.0 + 2 * (z - 0.1), "c": 1e9}) is None
    assert most_implausible_estimate(priors, {"a": z + 0.1, "b": 10.0}) == "a"
    assert most_implausible_estimate(priors, {"a": z + 0.1, "b": 10.0 - 2 * (z + 1)}) == "b"   # further out
    assert most_implausible_estimate(priors, {"a": float("nan"), "b": 10.0 + 2 * (z + 5)}) == "a"
    assert most_implausible_estimate(priors, {}) is None


@pytest.mark.slow  # ~30 s alone, ~60 s in the default run (the lag model's exact draw and refitted start);
# the rule itself: test_the_most_implausible_least_squares_estimate_is_named above
def test_a_two_pair_campaign_whose_least_squares_leave_the_support_starts_inside_it():
    """The exact-SBC campaign of seed 1 (2 pairs, the lag model with the driveline channel):
    least squares put the tyre-lag gain at -0.30 /(m/s) (prior 0.0057 +- 0.003), A_t, B_t, C_t
    far off, and the apparent C_D0 of that start below zero, where the posterior has no mass and
    numpyro found no valid initial parameters.  The start now takes those at their priors'
    centres and has a finite posterior density."""
    from bayes_roadload.analysis.sbc import ModelDrawnCampaign
    from bayes_roadload.inference.bayes import build_problem
    from bayes_roadload.inference.nuts import initial_values, unconstrained_posterior

    model = "four_term_tyre_lag_driveline_informative"
    campaign = ModelDrawnCampaign(1, pairs=2, model=model)()
    problem = build_problem(campaign, model)
    init = initial_values(problem, campaign)
    prior = problem.priors["tyre_lag_gain_per_mps"]
    assert init["tyre_lag_gain_per_mps"] == prior.center
    assert init["CD0_apparent"] > 0
    post = unconstrained_posterior(problem, init)
    assert np.isfinite(float(post.potential_fn(post.z0)))


def test_an_estimate_its_prior_excludes_starts_at_the_prior_centre_and_the_others_are_refitted(small_campaign):
    """C_D0's prior moved 50 of its scales (0.001) from where least squares puts it: the start
    holds C_D0 at the prior's centre and the least-squares fit of the others with C_D0 fixed
    there (they trade along the ridge: the drag the fixed C_D0 adds comes off A_D and B_D)."""
    from bayes_roadload.inference.bayes import build_problem
    from bayes_roadload.inference.lsq import fit_lsq
    from bayes_roadload.inference.nuts import initial_values

    from ..conftest import with_fixed
    from bayes_roadload.inference.spec import Prior

    problem = build_problem(small_campaign, "three_term")
    free = initial_values(problem, small_campaign)
    far = free["CD0"] + 50 * 0.001
    moved = dataclasses.replace(problem, priors={**problem.priors, "CD0": Prior("normal", loc=far, scale=0.001)})
    init = initial_values(moved, small_campaign)
    assert init["CD0"] == far
    refit = fit_lsq(small_campaign, with_fixed(problem.spec, {"CD0": far}), grouping="all").groups[0].estimate
    for k in ("AD", "BD"):
        assert init[k] == pytest.approx(refit[k], rel=1e-9) and init[k] != pytest.approx(free[k], rel=1e-3), k


def test_the_map_is_the_same_with_the_data_as_arguments_or_as_constants(small_campaign, monkeypatch):
    """``find_map`` evaluates the potential compiled with the campaign's data as arguments
    (``shift.potential_program``, which the Type B step reuses); where that program cannot be
    built it compiles the potential with the data as constants.  Both take the same Newton
    iterations on the same function, so they differ only by the rounding of two compilations
    (~1e-12 relative, measured 2e-11 apart in the O(1)-scaled coordinates); 1e-8 leaves that
    rounding a factor 500 for the Hessian's conditioning, and fails for any difference in the
    potential itself (the optimiser's own tolerance, scaled gradients below 1e-3, is far
    larger)."""
    from jax.flatten_util import ravel_pytree

    from bayes_roadload.inference import shift
    from bayes_roadload.inference.bayes import build_problem
    from bayes_roadload.inference.nuts import find_map, prepare_problem, site_layout

    problem, init = prepare_problem(build_problem(small_campaign, "three_term"), small_campaign)
    with_arguments = find_map(problem, init)
    assert any(p.accepts(problem) for p in shift._RECENT_PROGRAMS)

    def unavailable(*args, **kwargs):
        raise TypeError("data cannot be arguments")

    monkeypatch.setattr(shift, "potential_program", unavailable)
    with_constants = find_map(problem, init)
    assert with_arguments.success and with_constants.success
    assert with_arguments.n_iter == with_constants.n_iter
    scale = site_layout(problem, with_arguments.z)[1]
    y = [np.asarray(ravel_pytree(m.z)[0]) / scale for m in (with_arguments, with_constants)]
    np.testing.assert_allclose(y[0], y[1], rtol=0, atol=1e-8)
    assert with_arguments.neg_log_posterior == pytest.approx(with_constants.neg_log_posterior, abs=1e-8)
