"""Scoring a test design for a sim-to-real candidate (`plan --identify`): the design
changes, the designed campaign, and that a weighed ballast identifies an effective-mass error
a single-mass campaign cannot."""

import warnings

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.analysis.design_identify import DesignChange, changed_conditions, designed_campaign
from bayes_roadload.cli import main
from bayes_roadload.data import save_campaign
from studies.proof_suite import independent_withheld_campaign


def test_design_changes_parse_and_refuse():
    assert DesignChange.parse("extra_mass_kg=300") == DesignChange(extra_mass_kg=300.0)
    assert DesignChange.parse("add_pairs=2, cross_wind_factor=2") == DesignChange(add_pairs=2, cross_wind_factor=2.0)
    assert DesignChange.parse("") == DesignChange()
    for bad in ("mass=3", "add_pairs", "add_pairs=two", "add_pairs=0", "cross_wind_factor=-1"):
        with pytest.raises(ValueError):
            DesignChange.parse(bad)


@pytest.fixture(scope="module")
def one_pair():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        factory, model = independent_withheld_campaign("mass_error", 2, pairs=1)
        return factory(), model


def test_changed_conditions_shift_the_mass_and_scale_only_the_cross_wind(one_pair):
    c, _ = one_pair
    ch = changed_conditions(c, DesignChange(extra_mass_kg=250.0, cross_wind_factor=2.0))
    np.testing.assert_allclose(ch.runs["mass_kg"], c.vehicle.mass_kg + 250.0)
    a0, p0 = c.runs["airspeed_mps"].to_numpy(), c.runs["yaw_rad"].to_numpy()
    a1, p1 = ch.runs["airspeed_mps"].to_numpy(), ch.runs["yaw_rad"].to_numpy()
    np.testing.assert_allclose(a1 * np.cos(p1), a0 * np.cos(p0), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(a1 * np.sin(p1), 2.0 * a0 * np.sin(p0), rtol=1e-12, atol=1e-12)


def test_designed_campaign_keeps_the_runs_as_tested_and_adds_the_design(one_pair):
    c, model = one_pair
    values = {"AD": 0.01, "BD": 1e-4, "CD0": 0.35, "sigma_mps": 0.02, "q_mps_per_sqrt_s": 0.001}
    d = designed_campaign(c, values, ("AD", "BD", "CD0"), model, DesignChange(add_pairs=2, extra_mass_kg=300.0))
    obs = d.runs[~d.runs["run"].str.startswith("d")]
    added = d.runs[d.runs["run"].str.startswith("d")]
    pd.testing.assert_series_equal(obs["speed_mps"].reset_index(drop=True), c.runs["speed_mps"].reset_index(drop=True))
    assert added["run"].nunique() == 4 and added["pair"].nunique() == 2
    assert set(added["pair"]) .isdisjoint(set(obs["pair"]))
    np.testing.assert_allclose(added["mass_kg"], c.vehicle.mass_kg + 300.0)
    np.testing.assert_allclose(obs["mass_kg"], c.vehicle.mass_kg)


def test_designed_campaign_of_text_pair_ids(one_pair):
    """Text pair ids (accepted as in every kind): the added pairs get ids of their own."""
    import dataclasses

    c, model = one_pair
    c = dataclasses.replace(c, runs=c.runs.assign(pair="P" + c.runs["pair"].astype(str)))
    values = {"AD": 0.01, "BD": 1e-4, "CD0": 0.35, "sigma_mps": 0.02, "q_mps_per_sqrt_s": 0.001}
    d = designed_campaign(c, values, ("AD", "BD", "CD0"), model, DesignChange(add_pairs=2))
    added = d.runs[d.runs["run"].str.startswith("d")]
    assert added["pair"].nunique() == 2 and set(added["pair"]).isdisjoint(set(c.runs["pair"]))
    assert len(d.pairs()) == 3


@pytest.mark.slow  # the outcome of a planning study (refits of designed campaigns), ~30 s
def test_plan_identify_finds_that_a_ballast_identifies_a_mass_error(one_pair, tmp_path):
    """With A_D, B_D, C_D0 free, an effective-mass error dM dv/dt rescales every force alike
    (library `needs`): one test mass leaves it almost all in the coefficients.  Runs at a
    weighed +300 kg separate it: the rolling loss scales with the mass, the air drag does not."""
    c, model = one_pair
    save_campaign(c, tmp_path / "campaign")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        code = main(["-q", "plan", str(tmp_path / "campaign"), "--model", model, "--identify", "mass_error",
                     "--design", "extra_mass_kg=300", "--out", str(tmp_path / "out")])
    assert code == 0
    t = pd.read_csv(tmp_path / "out" / "identify.csv").set_index("design")
    tested, ballast = t.loc["as tested"], t.loc["+ the pairs again, +300 kg"]
    assert tested["runs"] == 2 and ballast["runs"] == 4
    assert ballast["information_ratio"] > 100 * tested["information_ratio"]
    assert ballast["contraction"] >= 0.5 and bool(ballast["identifiable"])
    assert ballast["detectable"] < tested["detectable"] / 10
