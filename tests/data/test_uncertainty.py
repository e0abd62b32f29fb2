"""Type B sources (:mod:`bayes_roadload.data.uncertainty`) and vehicle.toml's ``[uncertainty]``."""

from __future__ import annotations

import math

import pytest

from bayes_roadload.data import load_campaign, save_campaign
from bayes_roadload.data.checks import CampaignError
from bayes_roadload.data.uncertainty import SOURCES, standard_uncertainties, uncertainty_from_toml
from bayes_roadload.data.vehicle import vehicle_from_toml
from bayes_roadload.simulate import simulate_campaign

DOC = {"vehicle": {"mass_kg": 1000.0, "effective_mass_kg": 1030.0, "frontal_area_m2": 2.0}}


@pytest.fixture(scope="module")
def campaign():
    return simulate_campaign(1, pairs=1, seed=0)


def test_defaults_are_the_standards_accuracies_as_rectangular_distributions():
    # GUM 4.3.7: a limit +-a read as a rectangular distribution has u = a / sqrt(3)
    assert SOURCES["airspeed_factor_rel"].default == pytest.approx(0.0093 / math.sqrt(3))
    assert SOURCES["temperature_k"].default == pytest.approx(1.0 / math.sqrt(3))
    assert SOURCES["pressure_pa"].default == pytest.approx(700.0 / math.sqrt(3))
    # two axles, each +-5 kg and independent: u = sqrt(2) x 5 / sqrt(3)
    assert SOURCES["mass_kg"].default == pytest.approx(math.sqrt(2.0) * 5.0 / math.sqrt(3))
    assert all(s.default > 0 and s.accuracy for s in SOURCES.values())


def test_uncertainty_table_is_validated_naming_file_and_key():
    assert uncertainty_from_toml({"mass_kg": 2.0, "yaw_offset_rad": 0}, "v.toml") == {"mass_kg": 2.0,
                                                                                      "yaw_offset_rad": 0.0}
    with pytest.raises(CampaignError, match=r"v\.toml.*\[uncertainty\] mass_lb.*unknown key"):
        uncertainty_from_toml({"mass_lb": 2.0}, "v.toml")
    with pytest.raises(CampaignError, match=r"v\.toml.*\[uncertainty\] mass_kg.*negative"):
        uncertainty_from_toml({"mass_kg": -1.0}, "v.toml")
    with pytest.raises(CampaignError, match=r"\[uncertainty\] mass_kg.*not a number"):
        uncertainty_from_toml({"mass_kg": "five"}, "v.toml")
    *_, meta = vehicle_from_toml(dict(DOC, uncertainty={"mass_kg": 2.5}), "v.toml")
    assert meta["uncertainty"] == {"mass_kg": 2.5}


def test_uncertainty_round_trips_through_vehicle_toml(campaign, tmp_path):
    campaign.meta["uncertainty"] = {"mass_kg": 2.5, "temperature_k": 0.0}
    try:
        save_campaign(campaign, tmp_path / "c")
    finally:
        del campaign.meta["uncertainty"]
    assert "[uncertainty]" in (tmp_path / "c" / "vehicle.toml").read_text()
    back = load_campaign(tmp_path / "c")
    u = standard_uncertainties(back)
    assert u["mass_kg"] == 2.5 and u["temperature_k"] == 0.0
    assert u["pressure_pa"] == SOURCES["pressure_pa"].default  # not stated: the default


def test_each_source_shifts_what_it_names(campaign):
    d = 0.01
    before = campaign.runs.copy()
    m = SOURCES["mass_kg"].apply(campaign, 3.0)
    assert m.vehicle.mass_kg == campaign.vehicle.mass_kg + 3.0
    assert m.vehicle.effective_mass_kg == campaign.vehicle.effective_mass_kg + 3.0
    ri = SOURCES["rotating_inertia_rel"].apply(campaign, 0.1)
    rotating = campaign.vehicle.effective_mass_kg - campaign.vehicle.mass_kg
    assert ri.vehicle.effective_mass_kg == pytest.approx(campaign.vehicle.mass_kg + 1.1 * rotating)
    a = SOURCES["airspeed_factor_rel"].apply(campaign, d)
    assert a.anemometer.airspeed_factor == pytest.approx(campaign.anemometer.airspeed_factor * (1 + d))
    y = SOURCES["yaw_offset_rad"].apply(campaign, d)
    assert (y.runs["yaw_rad"] - campaign.runs["yaw_rad"]).to_numpy() == pytest.approx(d)
    s = SOURCES["speed_scale_rel"].apply(campaign, d)
    assert (s.runs["speed_mps"] / campaign.runs["speed_mps"]).to_numpy() == pytest.approx(1 + d)
    assert campaign.runs.equals(before)  # the sources return new campaigns
    # the campaign logs no temperature or driveline channel: nothing for those sources to act on
    assert SOURCES["temperature_k"].apply(campaign, 1.0) is None
    assert SOURCES["driveline_scale_rel"].apply(campaign, d) is None

