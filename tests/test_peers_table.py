"""The peers table of docs/performance.md (benchmarks/peers.py ``render``): ESS per second
against ours, and the bound for a sampler stopped at the time limit."""

import pytest

from .conftest import benchmark_script


@pytest.fixture(scope="module")
def peers():
    with benchmark_script("peers") as module:
        yield module


def _finished(name, ess_per_s, load):
    return {"sampler": name, "warmup": 300, "wall_s": 10.0, "cpu_s": 12.0, "compile_s": None,
            "min_ess_bulk": 10.0 * ess_per_s, "min_ess_per_s": ess_per_s, "max_r_hat": 1.004,
            "divergences": 0, "mean_leapfrog_steps": 7.0, "load_average_1min_at_start": load}


def _row(table, name):
    return next(line for line in table.splitlines() if line.startswith(f"| {name} |")).split("|")[1:-1]


def test_ratios_and_bounds(peers):
    meta = {"date": "d", "pairs": 18, "chains": 2, "draws": 1000, "meads_chains": 8, "timeout_s": 400.0,
            "machine": {"cpu_count": 2, "platform": "p"}, "load_before": [0.5], "load_after": [1.0]}
    records = [_finished("ours", 40.0, 0.5), _finished("nutpie", 8.0, 1.2),
               {"sampler": "stan_default", "error": "did not finish within 400 s", "min_ess_per_s_upper_bound": 5.0},
               # an ensemble sampler's bound counts all its chains' draws: 8 x 1000 / 400 s
               {"sampler": "blackjax_chees", "error": "did not finish within 400 s", "min_ess_per_s_upper_bound": 5.0}]
    table = peers.render(records, meta)
    nutpie = [c.strip() for c in _row(table, "nutpie")]
    assert nutpie[7] == "5.0x" and nutpie[-1] == "1.2"  # 40 / 8, and the load at its start
    stan = [c.strip() for c in _row(table, "stan_default")]
    assert stan[6] == "<= 5.0" and stan[7] == ">= 8.0x"
    chees = [c.strip() for c in _row(table, "blackjax_chees")]
    assert chees[6] == "<= 20.0" and chees[7] == ">= 2.0x"
    assert "measured under load" not in table
    loaded = peers.render([dict(records[0], load_average_1min_at_start=2.5)], meta)
    assert "measured under load" in loaded
