"""The cup anemometer's lag in the analysis model when the campaign states its distance constant
(vehicle.toml ``[anemometer] distance_constant_m``, the ``anemometer_lag`` term)."""

from __future__ import annotations

import dataclasses

import pytest

from bayes_roadload.data import load_campaign, save_campaign
from bayes_roadload.data.checks import CampaignError
from bayes_roadload.data.vehicle import vehicle_from_toml
from bayes_roadload.inference.lsq import fit_lsq
from bayes_roadload.inference.spec import load_model_spec
from bayes_roadload.simulate import simulate_campaign
from bayes_roadload.simulate.independent import simulate_independent

DOC = {"vehicle": {"mass_kg": 1000.0, "effective_mass_kg": 1030.0, "frontal_area_m2": 2.0}}


def test_distance_constant_is_read_checked_and_written(tmp_path):
    _, anem, _, _ = vehicle_from_toml(dict(DOC, anemometer={"distance_constant_m": 1.5}), "v.toml")
    assert anem.distance_constant_m == 1.5
    assert vehicle_from_toml(DOC, "v.toml")[1].distance_constant_m == 0.0  # not stated: no lag
    with pytest.raises(CampaignError, match=r"v\.toml.*\[anemometer\] distance_constant_m"):
        vehicle_from_toml(dict(DOC, anemometer={"distance_constant_m": -1.0}), "v.toml")
    c = simulate_campaign(7, pairs=1, seed=0)  # case 7: instrument dynamics on
    assert c.anemometer.distance_constant_m == pytest.approx(1.5)
    save_campaign(c, tmp_path / "c")
    assert load_campaign(tmp_path / "c").anemometer.distance_constant_m == pytest.approx(1.5)
    assert simulate_campaign(2, pairs=1, seed=0).anemometer.distance_constant_m == 0.0  # case 2: none


def test_a_stated_lag_adds_the_anemometer_term_with_its_distance_constant():
    c = simulate_campaign(7, pairs=1, seed=0)
    model, fixed, _ = load_model_spec("four_term").build(c)
    assert "anemometer_lag" in model.term_names and fixed["cup_lag_m"] == pytest.approx(1.5)
    plain = dataclasses.replace(c, anemometer=dataclasses.replace(c.anemometer, distance_constant_m=0.0))
    assert "anemometer_lag" not in load_model_spec("four_term").build(plain)[0].term_names
    still = dataclasses.replace(c, runs=c.runs.drop(columns=["airspeed_mps", "yaw_rad"]))
    assert "anemometer_lag" not in load_model_spec("four_term").build(still)[0].term_names  # no reading


def test_the_lag_correction_shrinks_the_cd0_error_on_the_independent_simulator():
    """Noise-free campaign of the independent simulator with only its anemometer dynamics (cup
    first order with over-speeding: the slow-down distance constant is r x d, r =
    ``overspeed_ratio``; second-order vane).  Undoing the stated d leaves (r - 1) / r of the
    cup's lag during the deceleration, so the C_D0 error must shrink to about that fraction;
    0.25 is added for what the correction cannot reach (the vane, the yaw-K_D trade)."""
    c = simulate_independent(8, pairs=1, effects=["anemometer_dynamics"], type_b=False, run_to_run_sd=0.0,
                             speed_noise_sd_mps=0.0)
    r = c.truth["meta"]["anemometer_dynamics"]["overspeed_ratio"]
    assert c.anemometer.distance_constant_m == pytest.approx(c.truth["meta"]["anemometer_dynamics"]["distance_constant_m"])
    off = dataclasses.replace(c, anemometer=dataclasses.replace(c.anemometer, distance_constant_m=0.0))
    err = {}
    for label, camp in (("stated", c), ("not stated", off)):
        cd0 = fit_lsq(camp, "four_term", grouping="all").weighted_mean["CD0"]
        err[label] = abs(cd0 / c.truth["CD0"] - 1.0)
    assert err["stated"] < ((r - 1.0) / r + 0.25) * err["not stated"], (err, r)
