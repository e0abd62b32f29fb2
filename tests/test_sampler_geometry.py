"""benchmarks/sampler_geometry.py: a variant changes the fit's softness at the bound only while
it runs, and the docs table shows each record's settings and results."""

import pytest

from .conftest import benchmark_script


@pytest.fixture(scope="module")
def geometry():
    with benchmark_script("sampler_geometry") as module:
        yield module


def test_a_variant_restores_the_softness_and_the_sampler_class_even_when_the_fit_fails(geometry, monkeypatch):
    import bayes_roadload.inference.nuts as nuts

    before = (nuts.SOFTPLUS_FRACTION_AT_BOUND, nuts.MCMC)
    seen = {}

    def failing(problem, campaign):
        seen["softness"] = nuts.SOFTPLUS_FRACTION_AT_BOUND
        raise RuntimeError("stop")

    monkeypatch.setattr(nuts, "prepare_problem", failing)
    monkeypatch.setattr(nuts, "build_problem", lambda *a, **k: None)
    with pytest.raises(RuntimeError, match="stop"):
        geometry.run_variant(None, 0.7, "identity")
    assert seen["softness"] == 0.7
    assert (nuts.SOFTPLUS_FRACTION_AT_BOUND, nuts.MCMC) == before


def test_the_table_shows_each_records_settings_and_results(geometry):
    row = {"date": "2026-12-05 02:00", "commit": "abc1234", "softness_at_bound": 0.3, "widened": ["KD"],
           "mass_matrix": "identity", "steps_per_draw": 7.04, "step_size": [0.51, 0.49],
           "inverse_mass_range": [1.0, 1.0], "divergences": 0, "min_ess_bulk": 2328.6,
           "ess_per_1000_gradients": 164.3, "max_r_hat": 1.0068, "warmup_s": 13.4, "sampling_s": 24.3}
    text = geometry.markdown([row, dict(row, widened=[], softness_at_bound=0.05, mass_matrix="diag")])
    lines = [line for line in text.splitlines() if line.startswith("| 2026")]
    assert lines[0] == ("| 2026-12-05 02:00 | abc1234 | 0.3 | KD | identity | 7.0 | 0.51/0.49 | 1.00-1.00 | 0 | "
                        "2329 | 164 | 1.0068 | 38 |")
    assert "| 0.05 | - | diag |" in lines[1]
    header = next(line for line in text.splitlines() if line.startswith("| date"))
    assert header.count("|") == lines[0].count("|")
