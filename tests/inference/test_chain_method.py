"""Parallel chains while their projected memory growth fits the machine, sequential above
(:func:`bayes_roadload.inference.nuts.chain_method`, config.PARALLEL_CHAIN_*)."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import pytest

from bayes_roadload import config
from bayes_roadload.inference import nuts

SAMPLER = dataclasses.replace(config.DEFAULT_SAMPLER, num_chains=2, num_warmup=300, num_samples=1000)


@pytest.fixture
def two_devices(monkeypatch):
    monkeypatch.setattr(nuts.jax, "local_device_count", lambda: 2)
    monkeypatch.setattr(nuts, "_physical_memory_bytes", lambda: 24e9)


def _growth(n_obs: int, sampler=SAMPLER) -> float:
    """The projection written out: bytes per observation per chain iteration x observations x
    chains x iterations."""
    return config.PARALLEL_CHAIN_GROWTH_BYTES * n_obs * sampler.num_chains * (sampler.num_warmup + sampler.num_samples)


def test_the_threshold_is_the_projected_growth_against_the_memory_fraction(two_devices):
    limit = config.PARALLEL_CHAIN_MEMORY_FRACTION * 24e9
    n_edge = int(limit / _growth(1))
    assert nuts.chain_method(SAMPLER, SimpleNamespace(n_observations=n_edge))[0] == "parallel"
    method, why = nuts.chain_method(SAMPLER, SimpleNamespace(n_observations=n_edge + 1))
    assert method == "sequential"
    assert f"{_growth(n_edge + 1) / 1e9:.1f} GB" in why and "24.0 GB" in why


def test_the_issue_sizes(two_devices):
    """18 pairs (16,230 samples) and 54 pairs (48,769) stay parallel on 24 GB; a 500-pair
    campaign (~450 samples per run) goes sequential, and so does the R-hat retry's longer run
    of a size that was parallel on its first attempt."""
    assert nuts.chain_method(SAMPLER, SimpleNamespace(n_observations=16_230))[0] == "parallel"
    assert nuts.chain_method(SAMPLER, SimpleNamespace(n_observations=48_769))[0] == "parallel"
    assert nuts.chain_method(SAMPLER, SimpleNamespace(n_observations=1000 * 450))[0] == "sequential"
    n = 70_000
    retry = dataclasses.replace(SAMPLER, num_warmup=600, num_samples=2000)
    assert nuts.chain_method(SAMPLER, SimpleNamespace(n_observations=n))[0] == "parallel"
    assert nuts.chain_method(retry, SimpleNamespace(n_observations=n))[0] == "sequential"


def test_too_few_devices_or_one_chain_is_sequential(monkeypatch):
    monkeypatch.setattr(nuts.jax, "local_device_count", lambda: 1)
    assert nuts.chain_method(SAMPLER, SimpleNamespace(n_observations=10))[0] == "sequential"
    one = dataclasses.replace(SAMPLER, num_chains=1)
    assert nuts.chain_method(one, SimpleNamespace(n_observations=10)) == ("sequential", "one chain")
