"""MAP + Laplace fits compiled once per campaign shape."""

import dataclasses
import warnings

import numpy as np
import pytest

from bayes_roadload import config
from bayes_roadload.analysis.batch import _compile_clock
from bayes_roadload.inference.bayes import build_problem
from bayes_roadload.inference.laplace import fit_laplace
from bayes_roadload.inference.nuts import find_map, initial_values, unconstrained_posterior
from bayes_roadload.simulate import simulate_campaign

from ..conftest import clean_case


def _padded(campaign, n):
    return dataclasses.replace(campaign, meta=dict(campaign.meta, pad_to_samples=n))


@pytest.fixture(scope="module")
def two_campaigns():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        cs = [simulate_campaign(clean_case(), pairs=1, seed=s) for s in (31, 32)]
    n = max(int(c.runs.groupby("run").size().max()) for c in cs)
    return [_padded(c, n) for c in cs]


@pytest.mark.slow  # a numerical cross-check of two compiled potentials, ~15 s
def test_same_map_and_covariance_as_find_map(two_campaigns):
    """The data-as-argument potential is numpyro's potential: same MAP and Laplace covariance
    as find_map (which compiles the data in)."""
    c = two_campaigns[0]
    lf = fit_laplace(c, "three_term", draws=1000, seed=1, importance=False)
    problem = build_problem(c, "three_term")
    ref = find_map(problem, {}, posterior=unconstrained_posterior(problem, initial_values(problem, c)))
    assert lf.map.success and ref.success
    for k in ("AD", "BD", "CD0"):
        assert float(lf.map.constrained[k]) == pytest.approx(float(ref.constrained[k]), rel=1e-6)
    assert np.abs(lf.map.cov - ref.cov).max() <= 1e-6 * np.abs(ref.cov).max()
    assert lf.samples["AD"].shape == (1, 1000) and np.isfinite(lf.samples["F50_N"]).all()


@pytest.mark.slow  # ~12 s; the correction's batching (below) and the planning refits that use it
# (tests/analysis/test_planning.py, Pareto k) stay in the default run
def test_importance_sampling_widens_the_one_pair_laplace_intervals(two_campaigns):
    """On one pair the Gaussian at the mode is too narrow (the coefficients widen with the noise
    scales); PSIS with a widened t proposal has usable weights and widens the intervals, and the
    batch record's gate reads the Pareto k."""
    c = two_campaigns[0]
    plain = fit_laplace(c, "three_term", draws=1000, seed=1, importance=False)
    corrected = fit_laplace(c, "three_term", draws=1000, seed=1)
    assert plain.map.success and np.isfinite(plain.samples["F50_N"]).all()
    d = corrected.diagnostics
    assert d["pareto_k"] <= config.LAPLACE_MAX_PARETO_K and 0 < d["is_ess"] < 1000
    assert d["proposal_inflation"] in config.LAPLACE_PROPOSAL_INFLATION
    for k in ("AD", "CD0", "F50_N"):
        assert corrected.samples[k].std() > plain.samples[k].std(), k


@pytest.mark.slow  # a compile-time ratio (speed), ~18 s
def test_same_shaped_campaigns_share_one_compilation(two_campaigns):
    """The second campaign of the same shape compiles (almost) nothing: < 10 % of the first's
    compile time."""
    first = _compile_clock()
    fit_laplace(two_campaigns[0], "two_term_tyres", pooling="pooled")
    c1 = _compile_clock() - first
    fit_laplace(two_campaigns[1], "two_term_tyres", pooling="pooled")
    c2 = _compile_clock() - first - c1
    assert c1 > 0
    assert c2 < 0.1 * c1, (c1, c2)


def test_the_potential_of_many_draws_goes_in_batches_and_equals_one_by_one(two_campaigns, monkeypatch):
    """``f_many`` (the importance draws' potential) runs over the draws in batches of
    results.PER_DRAW_BATCH_ELEMENTS / samples (results.draws_at_once); with batches of 3 draws, 7 draws give exactly
    the one-by-one values (a remainder batch included)."""
    import jax.numpy as jnp

    from bayes_roadload.inference import laplace, results

    c = two_campaigns[1]
    problem = build_problem(c, "three_term")
    per_draw = int(np.prod(np.shape(problem.batch.speed_mps)))
    monkeypatch.setattr(results, "PER_DRAW_BATCH_ELEMENTS", 3 * per_draw)
    init = initial_values(problem, c)
    comp = laplace.CompiledProblem.build(problem, init)
    y0 = np.asarray(comp._fns["to_scaled"]({k: jnp.asarray(v) for k, v in init.items()},
                                           laplace._data(problem)))
    ys = y0 + 0.01 * np.random.default_rng(0).standard_normal((7, y0.size))
    many = np.asarray(comp._fns["f_many"](jnp.asarray(ys), laplace._data(problem)))
    one = np.array([float(comp._fns["fg"](jnp.asarray(y), laplace._data(problem))[0]) for y in ys])
    assert np.all(np.isfinite(one)) and np.ptp(one) > 0
    np.testing.assert_allclose(many, one, rtol=1e-12, atol=1e-9)
