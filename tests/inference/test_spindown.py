"""The spin-down fit: likelihood against scipy and the classical baseline (NUTS recovery: the CLI test)."""

import numpy as np
import pytest
import scipy.stats

from bayes_roadload.inference.spindown import (
    build_spindown_problem,
    classical_spindown,
    spindown_log_likelihood,
)
from bayes_roadload.physics.spindown import equivalent_mass_kg
from bayes_roadload.simulate.spindown import SpindownSettings, simulate_spindown

FAST = SpindownSettings(sample_rate_hz=1.0)


@pytest.fixture(scope="module")
def campaign():
    return simulate_spindown(tests_per_wheel=2, seed=4, settings=FAST)


def test_log_likelihood_equals_scipy(campaign):
    p = build_spindown_problem(campaign)
    sample = {"Au_wheel": np.array([1.7, 1.5]), "Bu_wheel": np.array([0.12, 0.11]),
              "v0_mps": np.asarray(p.first_speed_mps) + 0.01, "sigma_mps": np.array([0.02, 0.03, 0.025, 0.04])}
    expected = 0.0
    m = float(equivalent_mass_kg(0.59, 0.28))
    for i, (_, g) in enumerate(campaign.runs.groupby("run", sort=False)):
        w = campaign.wheels.index(g["wheel"].iloc[0])
        a, b, t = sample["Au_wheel"][w], sample["Bu_wheel"][w], g["time_s"].to_numpy()
        c = a / b  # closed form written independently: (v + A/B) decays as exp(-B t / m)
        model = (sample["v0_mps"][i] + c) * np.exp(-b * t / m) - c
        expected += scipy.stats.norm.logpdf(g["wheel_speed_mps"], model, sample["sigma_mps"][i]).sum()
    assert float(spindown_log_likelihood(p, sample)) == pytest.approx(expected, rel=1e-10)


def test_classical_baseline_recovers_the_wheels(campaign):
    # eq. 5.14 differencing at 1 Hz with 0.02 m/s noise: SE of A_w ~0.1 N; 4 SE tolerance
    c = classical_spindown(campaign).set_index("wheel")
    for w, a, b in (("nearside", 1.66, 0.121), ("offside", 1.58, 0.114)):
        assert abs(c.loc[w, "Au"] - a) < 4 * c.loc[w, "Au_se"] and abs(c.loc[w, "Bu"] - b) < 4 * c.loc[w, "Bu_se"]
    assert c.loc["total", "Au"] == pytest.approx(c.loc["nearside", "Au"] + c.loc["offside", "Au"])


def test_a_spindown_result_becomes_a_fixed_undriven_term(small_campaign):
    from bayes_roadload.inference.spec import ModelSpecError, load_model_spec, with_undriven_wheels
    from bayes_roadload.physics.roadload import road_load_parts_n

    spec = with_undriven_wheels(load_model_spec("three_term"), 3.24, 0.232)
    model, fixed, free = spec.build(small_campaign)
    assert "undriven_wheels" in model.term_names and fixed["Au"] == 3.24 and free == ("AD", "BD", "CD0")
    v = np.array([10.0, 22.352])
    parts = road_load_parts_n(model, dict(fixed, AD=0.01, BD=2e-4, CD0=0.4), v, 1100.0, 1.85)
    np.testing.assert_allclose(np.asarray(parts["undriven"]), 3.24 + 0.232 * v, rtol=1e-12)
    with pytest.raises(ModelSpecError, match="already"):
        with_undriven_wheels(spec, 1.0, 0.1)


@pytest.mark.slow
def test_undriven_values_move_from_the_tyre_terms_into_their_own(small_campaign):
    """A spin-down result fed into a coastdown model (the thesis' practice): the undriven loss
    Au + Bu v leaves the tyre terms, AD by Au / (M g) and BD by Bu / (M g): the least-squares fits
    of the same pair differ by that within 1 % of the shift (lift unloads the tyre terms, not the
    wheel bearings, by q A C_L / (M g) ~ 0.5-1 %)."""
    from bayes_roadload import config
    from bayes_roadload.inference.lsq import fit_lsq
    from bayes_roadload.inference.spec import load_model_spec, with_undriven_wheels

    spec = with_undriven_wheels(load_model_spec("three_term"), 3.24, 0.232)
    pair = small_campaign.subset(small_campaign.run_ids[:2])
    base = fit_lsq(pair, "three_term", grouping="all").groups[0].estimate
    moved = fit_lsq(pair, spec, grouping="all").groups[0].estimate
    mg = small_campaign.vehicle.mass_kg * config.GRAVITY_MPS2
    assert base["AD"] - moved["AD"] == pytest.approx(3.24 / mg, rel=1e-2)
    assert base["BD"] - moved["BD"] == pytest.approx(0.232 / mg, rel=1e-2)
    assert moved["CD0"] == pytest.approx(base["CD0"], rel=1e-3)  # measured 5e-4 (lift coupling)


def test_hierarchical_model_gives_every_run_its_own_coefficients(campaign):
    """The centred run level: Au_run, Bu_run around their wheel's, started from each run's own
    eq. 5.14 line; the vehicle totals still sum the wheels."""
    import jax
    from numpyro import handlers

    from bayes_roadload.inference.spindown import spindown_model

    p = build_spindown_problem(campaign, pooling="hierarchical")
    assert p.initial["Au_run"].shape == (4,) and float(p.initial["tau_Au_wheel"]) == 0.1
    tr = handlers.trace(handlers.seed(spindown_model, jax.random.PRNGKey(0))).get_trace(p)
    assert tr["Au_run"]["value"].shape == (4,) and tr["Au_run"]["fn"].loc.shape == (4,)
    np.testing.assert_allclose(np.asarray(tr["Au_run"]["fn"].loc),
                               np.asarray(tr["Au_wheel"]["value"])[np.asarray(p.wheel_index)])
    assert float(tr["Au"]["value"]) == pytest.approx(float(np.sum(tr["Au_wheel"]["value"])))
    with pytest.raises(ValueError, match="pooling"):
        build_spindown_problem(campaign, pooling="partial")
