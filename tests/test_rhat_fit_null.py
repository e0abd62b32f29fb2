"""benchmarks/rhat_fit_null.py: the block-bootstrap null of a fit's largest R-hat keeps the
draws, finds chains that agree unremarkable and chains that disagree far outside it."""

import numpy as np
import pytest
import xarray as xr

from .conftest import benchmark_script


@pytest.fixture(scope="module")
def rfn():
    with benchmark_script("rhat_fit_null") as module:
        yield module


def _posterior(x: np.ndarray) -> xr.Dataset:
    """``x[quantity, chain, draw]`` as a posterior with one vector variable and a constant."""
    k, c, n = x.shape
    return xr.Dataset({"theta": (("chain", "draw", "i"), np.moveaxis(x, 0, -1)),
                       "fixed": (("chain", "draw"), np.ones((c, n)))})


def test_quantities_skip_constants_and_name_elements(rfn):
    x = np.random.default_rng(0).normal(size=(3, 2, 50))
    names, draws = rfn.quantities(_posterior(x))
    assert names == ["theta[0]", "theta[1]", "theta[2]"]  # "fixed" never varies: R-hat undefined
    np.testing.assert_array_equal(draws, x)


def test_the_bootstrap_reuses_blocks_of_the_fits_draws(rfn):
    x = np.arange(2 * 2 * 300, dtype=float).reshape(2, 2, 300)  # every draw unique
    y = rfn.block_bootstrap(x, 100, np.random.default_rng(1))
    assert y.shape == x.shape
    assert np.isin(y, x).all()
    # consecutive draws of a block are consecutive draws of one source chain, and the same
    # blocks are taken for every quantity
    assert (np.diff(y[0, :, :100], axis=-1) == 1).all()
    np.testing.assert_array_equal(y[1] - y[0], np.full(y[0].shape, 600.0))


def test_agreeing_chains_sit_inside_their_null_and_disagreeing_ones_outside(rfn):
    rng = np.random.default_rng(2)
    x = rng.normal(size=(20, 2, 1000))
    ok = rfn.fit_null(_posterior(x), gate=1.01, block=50, reps=200, seed=3)
    # iid draws: the observed maximum is one draw of the null's distribution; 200 replicates put
    # a share below 0.01 only if the estimate is off (probability ~0.01 under the null)
    assert ok["null_share_at_or_above_observed"] > 0.01
    assert ok["null_median"] < 1.01 and ok["quantities"] == 20
    x[:, 1] += 0.5  # one chain half an sd off (R-hat ~ 1.04, tests/test_rhat_null.py)
    bad = rfn.fit_null(_posterior(x), gate=1.01, block=50, reps=200, seed=3)
    assert bad["max_r_hat"] > 1.03
    assert bad["null_share_at_or_above_observed"] == 0.0
    assert bad["max_r_hat"] > bad["null_q95"]
