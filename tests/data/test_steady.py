"""The steady-state data kind: conversion, the inertial correction's source, refusals."""

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.data import CampaignError, load_campaign
from bayes_roadload.data.steady import SteadyCampaign, polynomial_acceleration, save_steady
from bayes_roadload.simulate.steady import SteadySettings, simulate_steady

VEHICLE = "[vehicle]\nmass_kg = 1100.0\neffective_mass_kg = 1130.0\nfrontal_area_m2 = 1.85\nrolling_radius_m = 0.3\n"


def write(root, df):
    root.mkdir(parents=True, exist_ok=True)
    df.to_csv(root / "steady.csv", index=False)
    (root / "vehicle.toml").write_text(VEHICLE)
    return root


def table(**extra):
    t = np.arange(6.0)
    return pd.DataFrame({"run": 1, "time_s": t, "speed_mps": 20.0 + 0.01 * t, **extra})


def test_wheel_torques_become_the_tractive_force_and_time_gives_the_acceleration(tmp_path):
    c = load_campaign(write(tmp_path / "c", table(wheel_torque_left_nm=30.0, wheel_torque_right_nm=33.0)))
    assert isinstance(c, SteadyCampaign) and c.accel_source == "polynomial (time_s)"
    np.testing.assert_allclose(c.runs["tractive_force_n"], 63.0 / 0.3)
    np.testing.assert_allclose(c.runs["accel_mps2"], 0.01, atol=1e-12)
    assert not c.has_driveline and not c.has_anemometer


def test_polynomial_acceleration_is_the_derivative_of_a_quadratic():
    t = np.linspace(0.0, 20.0, 41)
    np.testing.assert_allclose(polynomial_acceleration(t, 25.0 + 0.02 * t - 0.001 * t**2), 0.02 - 0.002 * t, atol=1e-12)


@pytest.mark.parametrize("extra, match", [
    ({"tractive_force_n": 200.0, "wheel_torque_left_nm": 30.0, "wheel_torque_right_nm": 30.0}, "not both"),
    ({"wheel_torque_left_nm": 30.0}, "both the left and the right"),
    ({"torque": 60.0}, "wheel_torque_left_nm"),
    ({"tractive_force_kn": 0.2}, "multiply kN by 1000"),
    ({"tractive_force_n": 200.0, "accel_mps2": 2.0}, "not a steady-speed run"),
    ({"speed_kph": 72.0}, "divide km/h by 3.6"),
])
def test_ambiguous_or_unsteady_input_is_refused(tmp_path, extra, match):
    df = table(**extra)
    if "speed_kph" in extra:
        df = df.assign(tractive_force_n=200.0)
    with pytest.raises(CampaignError, match=match):
        load_campaign(write(tmp_path / "c", df))


def test_a_simulated_campaign_round_trips(tmp_path):
    c = simulate_steady(9, pairs=1, seed=0, settings=SteadySettings(duration_s=5.0))
    assert len(c.run_ids) == 12 and len(c.pairs()) == 6 and c.has_anemometer
    back = load_campaign(save_steady(c, tmp_path / "ss"))
    np.testing.assert_allclose(back.runs["tractive_force_n"], c.runs["tractive_force_n"], rtol=1e-9)
    assert back.truth["CD0"] == 0.4 and back.tunnel["CL0"] == pytest.approx(0.273)


@pytest.mark.parametrize("unit, scale", [("kph", 3.6), ("mph", 1.0 / 0.44704)])
def test_airspeed_in_kph_or_mph_is_refused_as_for_coastdowns(tmp_path, unit, scale):
    """A steady-state table's airspeeds are the vehicle's speed plus at most the wind: read in
    km/h or mph they exceed the speeds by far more than the 10 m/s peak wind the standards admit
    (a simulated campaign's own airspeeds load)."""
    c = simulate_steady(9, pairs=1, seed=0, settings=SteadySettings(duration_s=5.0))
    df = c.runs[c.runs["speed_mps"] < 25.0].reset_index(drop=True)  # km/h readings stay below 100 "m/s"
    (tmp_path / "ok").mkdir()
    df.to_csv(tmp_path / "ok" / "steady.csv", index=False)
    (tmp_path / "ok" / "vehicle.toml").write_text(VEHICLE)
    assert load_campaign(tmp_path / "ok").has_anemometer
    with pytest.raises(CampaignError, match=rf"steady.csv, column 'airspeed_mps', row 1: the airspeeds look logged in "
                       rf".*: convert them to m/s \(multiply .* by {1.0 / scale:.6g}\)"):
        load_campaign(write(tmp_path / unit, df.assign(airspeed_mps=df["airspeed_mps"] * scale)))
