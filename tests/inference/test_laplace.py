"""MAP + Laplace fits compiled once per campaign shape."""

import dataclasses
import warnings

import numpy as np
import pytest

from bayes_roadload import config
from bayes_roadload._jax import compile_seconds
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
    first = compile_seconds()
    fit_laplace(two_campaigns[0], "two_term_tyres", pooling="pooled")
    c1 = compile_seconds() - first
    fit_laplace(two_campaigns[1], "two_term_tyres", pooling="pooled")
    c2 = compile_seconds() - first - c1
    assert c1 > 0
    assert c2 < 0.1 * c1, (c1, c2)


@pytest.mark.slow  # a cross-check kept out of the default run's 10 minutes
def test_the_potential_of_many_draws_goes_in_batches_and_equals_one_by_one(two_campaigns, monkeypatch):
    """``potential_many`` (the importance draws' potential) runs over the draws in batches of
    results.PER_DRAW_BATCH_ELEMENTS / samples (results.draws_at_once); with batches of 3 draws, 7 draws give exactly
    the one-by-one values (a remainder batch included)."""
    from bayes_roadload.inference import laplace, results

    c = two_campaigns[1]
    problem = build_problem(c, "three_term")
    per_draw = int(np.prod(np.shape(problem.batch.speed_mps)))
    monkeypatch.setattr(results, "PER_DRAW_BATCH_ELEMENTS", 3 * per_draw)
    init = initial_values(problem, c)
    comp = laplace.CompiledProblem.build(problem, init)
    y0 = comp.to_scaled(problem, init)
    ys = y0 + 0.01 * np.random.default_rng(0).standard_normal((7, y0.size))
    many = comp.potential_many(problem, ys)
    one = np.array([float(comp.potential(problem, y)[0]) for y in ys])
    assert np.all(np.isfinite(one)) and np.ptp(one) > 0
    np.testing.assert_allclose(many, one, rtol=1e-12, atol=1e-9)


def test_the_proposal_mixture_density_is_normalised():
    """The mixture's components are weighed by their normalised densities (unlike the sequential
    proposals, whose shared constant cancels): in one dimension the mixture's density
    integrates to 1 and equals the share-weighted sum of its components."""
    from scipy import stats

    from bayes_roadload.inference.laplace import _mixture_draws

    rng = np.random.default_rng(0)
    ys, log_q = _mixture_draws(np.zeros(1), np.eye(1), 3001, "t", (1.0, 1.5, 2.0), rng)
    assert ys.shape == (3001, 1) and np.isfinite(log_q).all()
    # the same density on a grid: draws are not needed, so evaluate it through a grid of offsets
    from bayes_roadload.inference.laplace import _proposal_logpdf

    grid = np.linspace(-200.0, 200.0, 400_001)[:, None]
    shares = np.array([1001, 1000, 1000]) / 3001
    dens = sum(w * np.exp(_proposal_logpdf(grid, "t", s)) for w, s in zip(shares, (1.0, 1.5, 2.0)))
    # the t(5) tails beyond +-200 hold ~1e-10 of the mass; the trapezoid's error at this step is smaller
    assert np.trapezoid(dens, grid[:, 0]) == pytest.approx(1.0, abs=1e-6)
    direct = np.log(sum(w * stats.t(df=5, scale=s).pdf(ys[:, 0]) for w, s in zip(shares, (1.0, 1.5, 2.0))))
    np.testing.assert_allclose(log_q, direct, rtol=1e-10)


@pytest.mark.parametrize("combine", ["mixture", "sequential"])
def test_importance_draws_recover_a_posterior_wider_than_the_laplace_one(combine):
    """On a known posterior 1.6 times as wide as the Laplace approximation, with t(4) tails,
    the corrected draws' 97.5 % quantiles match the true ones within four of their Monte
    Carlo standard errors (sqrt(p (1 - p) / ESS) / density, from the reported effective
    sample size), the Pareto k passes the gate, and a mixture costs one set of draws."""
    from types import SimpleNamespace

    from scipy import stats

    from bayes_roadload.inference.laplace import _importance_draws

    d, width, df = 3, 1.6, 4
    target = stats.multivariate_t(loc=np.zeros(d), shape=width**2 * np.eye(d), df=df)
    comp = SimpleNamespace(potential_many=lambda problem, ys: -target.logpdf(np.asarray(ys)))
    problem = None
    draws = 4000
    ys, k, ess, inflation, evaluations = _importance_draws(
        comp, problem, np.zeros(d), np.eye(d), draws, np.random.default_rng(3), "t", (1.0, 1.5, 2.0), combine)
    assert k <= config.LAPLACE_MAX_PARETO_K and 100 < ess <= draws
    if combine == "mixture":
        assert evaluations == draws and np.isnan(inflation)
    else:
        assert evaluations in (draws, 2 * draws, 3 * draws) and inflation in (1.0, 1.5, 2.0)
    marginal = stats.t(df=df, scale=width)
    p = 0.975
    se = np.sqrt(p * (1 - p) / ess) / marginal.pdf(marginal.ppf(p))
    for j in range(d):
        assert abs(np.quantile(ys[:, j], p) - marginal.ppf(p)) < 4 * se, (j, np.quantile(ys[:, j], p), se)


def test_a_start_sets_the_noise_intensity_and_the_spreads():
    """``initial_values``' start may give q and the spreads (positive values only); without
    them they start at 0.002 and at their prior's mode."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        c = simulate_campaign(clean_case(), pairs=2, seed=5)
    problem = build_problem(c, "three_term", pooling="hierarchical")
    assert problem.varying and problem.integrated_noise
    plain = initial_values(problem, c, {"AD": 0.01})
    tau = {f"tau_{n}": 0.3 * config.TAU_PRIOR_SCALES[n] for n in problem.varying}
    warm = initial_values(problem, c, {"AD": 0.01, "q_mps_per_sqrt_s": 0.0011, **tau,
                                       f"tau_{problem.varying[0]}": 0.0})
    assert plain["q_mps_per_sqrt_s"] == 0.002 and warm["q_mps_per_sqrt_s"] == 0.0011
    first, *rest = problem.varying
    assert warm[f"tau_{first}"] == plain[f"tau_{first}"] == 0.5 * config.TAU_PRIOR_SCALES[first]  # 0: not a start
    for n in rest:
        assert warm[f"tau_{n}"] == tau[f"tau_{n}"] != plain[f"tau_{n}"]
