"""Campaigns of the same shapes lower to the same compiled programs (bayes_roadload._jax,
physics.integrate.bucket_length): the data are arguments of the programs, not constants."""

import re
import warnings

import jax
import numpy as np
import pytest

from bayes_roadload import config
from bayes_roadload.inference.bayes import build_problem
from bayes_roadload.inference.nuts import initial_values, unconstrained_posterior
from bayes_roadload.physics.integrate import bucket_length
from bayes_roadload.simulate import simulate_campaign

from ..conftest import clean_case


@pytest.mark.parametrize("per_octave", [4, 8, 16])
def test_bucket_length_is_the_next_size_of_the_octave_and_pads_less_than_its_share(per_octave):
    for n in range(1, 5000):
        b = bucket_length(n, per_octave)
        assert b >= n
        assert b == n or (b - n) * per_octave < n  # less than 1/per_octave of padding
        if n > per_octave:  # m * 2**k with per_octave <= m < 2 per_octave
            k = (b // per_octave).bit_length() - 1
            assert b % 2**k == 0 and per_octave <= b // 2**k < 2 * per_octave
        assert bucket_length(b, per_octave) == b  # a bucket's own length is kept
    assert bucket_length(493, 0) == 493


def _potential(campaign):
    problem = build_problem(campaign, "four_term")
    post = unconstrained_posterior(problem, initial_values(problem, campaign))
    return post


def _program_text(post):
    text = jax.jit(post.potential_fn).lower(post.z0).as_text(debug_info=False)
    return re.sub(r"loc\([^)]*\)", "", text)


@pytest.fixture(scope="module")
def campaigns():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return {s: simulate_campaign(clean_case(), pairs=1, seed=s) for s in (1, 2)}


def test_two_campaigns_of_one_bucket_lower_to_one_program(campaigns):
    lengths = {s: c.runs.groupby("run").size().max() for s, c in campaigns.items()}
    assert lengths[1] != lengths[2]  # different data and different run lengths ...
    assert len({bucket_length(n, config.PAD_SIZES_PER_OCTAVE) for n in lengths.values()}) == 1  # ... one bucket
    a, b = (_potential(campaigns[s]) for s in (1, 2))
    assert float(a.potential_fn(a.z0)) != float(b.potential_fn(a.z0))
    assert _program_text(a) == _program_text(b)


def test_padding_to_a_longer_length_leaves_the_density_unchanged(campaigns):
    camp = campaigns[1]
    post = _potential(camp)
    longer = type(camp)(camp.runs, camp.vehicle, camp.anemometer, camp.tunnel, camp.truth,
                        dict(camp.meta, pad_to_samples=1024))
    assert longer.to_batch()[0].time_s.shape[-1] == 1024 != post.problem.batch.time_s.shape[-1]
    padded = _potential(longer)
    z = post.z0
    assert np.isclose(float(padded.potential_fn(z)), float(post.potential_fn(z)), rtol=1e-12, atol=0)
