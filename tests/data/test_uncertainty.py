"""Type B sources (:mod:`bayes_roadload.data.uncertainty`) and vehicle.toml's ``[uncertainty]``."""

from __future__ import annotations

import dataclasses
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


def test_the_unlogged_humidity_is_set_above_dry_air_only_where_the_density_is_measured(campaign):
    """Relative humidity not logged: the source adds the column at 50 % + delta (clipped to
    0-100 %) where temperature and pressure are logged; where the humidity is logged its
    hygrometer is the source instead, and without temperature or pressure (the reference air)
    nothing is measured to correct.  Its error lies above the dry air the analysis takes: a
    rectangle of 0-100 % is u = 100 / sqrt(12)."""
    source = SOURCES["relative_humidity_unlogged_pct"]
    assert source.distribution == "above" and source.default == pytest.approx(100.0 / math.sqrt(12.0))
    assert all(s.distribution == "normal" for k, s in SOURCES.items() if k != "relative_humidity_unlogged_pct")
    assert source.apply(campaign, 10.0) is None  # no temperature or pressure column
    runs = campaign.runs.assign(temperature_k=295.0, pressure_pa=99000.0)
    logged_tp = dataclasses.replace(campaign, runs=runs)
    up, down = source.apply(logged_tp, 28.9), source.apply(logged_tp, -28.9)
    assert up.runs["relative_humidity_pct"].to_numpy() == pytest.approx(50.0 + 28.9)
    assert down.runs["relative_humidity_pct"].to_numpy() == pytest.approx(50.0 - 28.9)
    assert source.apply(logged_tp, 80.0).runs["relative_humidity_pct"].max() == 100.0
    assert "relative_humidity_pct" not in logged_tp.runs
    assert source.apply(dataclasses.replace(campaign, runs=runs.assign(relative_humidity_pct=40.0)), 10.0) is None
    with pytest.raises(ValueError, match="distribution"):
        dataclasses.replace(source, distribution="lognormal")


def test_the_yaw_dependent_airspeed_factor_scales_the_airspeed_by_the_calibrated_yaw_squared(campaign):
    """``airspeed_yaw_coefficient_per_rad2``: readings x (1 + delta psi^2), psi the calibrated
    yaw (yaw factor x reading); its bound is the thesis' 1.069-1.107 over +-25 deg (3.5 % of
    1.092 at 0.436 rad), read as a rectangle."""
    source = SOURCES["airspeed_yaw_coefficient_per_rad2"]
    bound = (1.107 - 1.069) / 1.092 / math.radians(25.0) ** 2
    assert 0.17 < bound < 0.19 and source.default == pytest.approx(bound / math.sqrt(3.0))
    anem = dataclasses.replace(campaign.anemometer, yaw_factor=0.9)
    c = dataclasses.replace(campaign, anemometer=anem)
    shifted = source.apply(c, 0.2)
    psi = 0.9 * c.runs["yaw_rad"].to_numpy()
    assert (shifted.runs["airspeed_mps"] / c.runs["airspeed_mps"]).to_numpy() == pytest.approx(1 + 0.2 * psi**2)
    assert (shifted.runs.drop(columns="airspeed_mps")).equals(c.runs.drop(columns="airspeed_mps"))
    assert source.apply(dataclasses.replace(c, runs=c.runs.drop(columns=["airspeed_mps", "yaw_rad"])), 0.2) is None


def test_every_kind_declares_what_its_sources_act_on():
    """The data contract: each registered campaign class names its measured table, and its
    speed-sensor and transducer columns are columns the kind knows."""
    import dataclasses

    from bayes_roadload.data import distances, intervals, spindown, steady, traces
    from bayes_roadload.data.uncertainty import TypeBChannels
    from bayes_roadload.inference.kinds import KINDS

    known = {"traces": traces.KNOWN_COLUMNS, "intervals": intervals.INTERVAL_COLUMNS,
             "distances": distances.DISTANCE_COLUMNS, "spindown": spindown.KNOWN_COLUMNS,
             "steady": steady.KNOWN_COLUMNS}
    for name, entry in KINDS.items():
        ch = entry.campaign_type.type_b_channels
        assert isinstance(ch, TypeBChannels), name
        assert ch.table in {f.name for f in dataclasses.fields(entry.campaign_type)}, name
        assert set(ch.speed + ch.force) <= set(known[name]), name


def test_sources_act_on_each_kinds_own_channels():
    """Interval band speeds come from the speed sensor; distance markers are surveyed (no speed
    sensor); a spin-down has wheel inertias and no vehicle; a steady-state force is a
    transducer reading."""
    from bayes_roadload.simulate.distances import distance_campaign_from_traces
    from bayes_roadload.simulate.intervals import interval_campaign_from_traces
    from bayes_roadload.simulate.spindown import simulate_spindown
    from bayes_roadload.simulate.steady import simulate_steady

    d = 0.01
    traces = simulate_campaign(1, pairs=1, seed=0)
    iv = interval_campaign_from_traces(traces)
    s = SOURCES["speed_scale_rel"].apply(iv, d)
    for col in ("speed_start_mps", "speed_end_mps"):
        assert (s.intervals[col] / iv.intervals[col]).to_numpy() == pytest.approx(1 + d)
    assert s.intervals["interval_s"].equals(iv.intervals["interval_s"])
    assert SOURCES["airspeed_factor_rel"].apply(iv, d) is None

    dc = distance_campaign_from_traces(traces)
    assert SOURCES["speed_scale_rel"].apply(dc, d) is None
    m = SOURCES["mass_kg"].apply(dc, 3.0)
    assert m.vehicle.mass_kg == dc.vehicle.mass_kg + 3.0
    if "mass_kg" in dc.markers:
        assert (m.markers["mass_kg"] - dc.markers["mass_kg"]).to_numpy() == pytest.approx(3.0)

    sd = simulate_spindown()
    assert SOURCES["mass_kg"].apply(sd, 3.0) is None and SOURCES["airspeed_factor_rel"].apply(sd, d) is None
    ri = SOURCES["rotating_inertia_rel"].apply(sd, 0.1)
    assert ri.wheel_inertia_kgm2 == pytest.approx({w: 1.1 * i for w, i in sd.wheel_inertia_kgm2.items()})
    w = SOURCES["speed_scale_rel"].apply(sd, d)
    assert (w.runs["wheel_speed_mps"] / sd.runs["wheel_speed_mps"]).to_numpy() == pytest.approx(1 + d)

    st = simulate_steady(9, pairs=1, seed=0)
    f = SOURCES["driveline_scale_rel"].apply(st, d)
    assert (f.runs["tractive_force_n"] / st.runs["tractive_force_n"]).to_numpy() == pytest.approx(1 + d)
    assert f.runs["speed_mps"].equals(st.runs["speed_mps"])


def test_spindown_uncertainty_round_trips_through_its_vehicle_toml(tmp_path):
    from bayes_roadload.data.spindown import load_spindown, save_spindown
    from bayes_roadload.simulate.spindown import simulate_spindown

    sd = simulate_spindown()
    sd.meta["uncertainty"] = {"rotating_inertia_rel": 0.02}
    save_spindown(sd, tmp_path / "sd")
    back = load_spindown(tmp_path / "sd")
    assert back.meta["uncertainty"] == {"rotating_inertia_rel": 0.02}
    assert standard_uncertainties(back)["rotating_inertia_rel"] == 0.02
    (tmp_path / "sd" / "vehicle.toml").write_text((tmp_path / "sd" / "vehicle.toml").read_text()
                                                  .replace("rotating_inertia_rel", "inertia_rel"))
    with pytest.raises(CampaignError, match=r"\[uncertainty\] inertia_rel"):
        load_spindown(tmp_path / "sd")
