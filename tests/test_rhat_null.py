"""benchmarks/rhat_null.py: its vectorised R-hat is ArviZ's, and it tells converged chains from
chains that sample different distributions."""

import numpy as np
import pytest

from .conftest import benchmark_script


@pytest.fixture(scope="module")
def rhat_null():
    with benchmark_script("rhat_null") as module:
        yield module


def test_the_vectorised_rhat_is_arviz(rhat_null):
    # both compute the same floating-point sums in another order: equal to rounding
    assert rhat_null.check_against_arviz(np.random.default_rng(1), reps=3) < 1e-9


def test_a_shifted_chain_fails_and_iid_chains_pass(rhat_null):
    rng = np.random.default_rng(2)
    x = rhat_null.ar1(rng, 0.0, (3, 2), 2000)
    # iid draws, ESS 4000: R-hat - 1 is of order 1 / ESS, far below the gate's 0.01
    assert rhat_null.rank_split_rhat(x).max() < 1.005
    # one chain's mean off by half an sd: the four split chains' means 0, 0, 0.5, 0.5 have
    # variance 1/12, so R-hat^2 - 1 ~ 0.08 (R-hat ~ 1.04), well above the gate
    x[:, 1] += 0.5
    assert (rhat_null.rank_split_rhat(x) > 1.01).all()


def test_the_ar1_draws_have_the_stationary_variance(rhat_null):
    x = rhat_null.ar1(np.random.default_rng(3), 0.5, (4, 4), 4000)
    # variance 1 / (1 - phi^2) = 4 / 3; 16 chains of ESS ~1300 each: sd of the estimate ~0.02
    assert x.var() == pytest.approx(4.0 / 3.0, abs=0.1)
