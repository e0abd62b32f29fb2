"""Shared fixtures: small simulated campaigns and one NUTS fit reused by many tests."""

import dataclasses
import warnings

import pytest

from bayes_roadload import config
from bayes_roadload.simulate import get_case, simulate_campaign

SMALL_SAMPLER = config.SamplerConfig(num_warmup=300, num_samples=400, num_chains=2, seed=3)
"""Small draw counts for tests: enough for the gates' R-hat and ESS on this posterior."""


def clean_case():
    """Case 2 winds (2/2 m/s), basic drag model, no instrument dynamics, measurement noise on,
    system noise off: the analysis model is correctly specified but for the input noise."""
    return dataclasses.replace(get_case(2), model="basic", dynamics=False, measurement_noise=True,
                               system_noise=False)


@pytest.fixture(scope="session")
def small_campaign():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return simulate_campaign(clean_case(), pairs=2, seed=11)


@pytest.fixture(scope="session")
def pooled_fit(small_campaign):
    from bayes_roadload.inference.nuts import fit_nuts

    return fit_nuts(small_campaign, "four_term", sampler=SMALL_SAMPLER)
