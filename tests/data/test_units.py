"""Units of a speed-trace table: conversion on load (recorded), refusal of what states no unit,
and the implied-road-load check that catches km/h logged in a m/s column."""

import math

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.data import CampaignError, load_campaign, save_campaign
from bayes_roadload.data.units import (
    COASTDOWN_TOP_SPEED_MPS,
    PLAUSIBLE_DRAG_AREA_M2,
    PLAUSIBLE_ROLLING,
    convert_units,
    implied_road_load,
)
from bayes_roadload.simulate import simulate_campaign

MASS, M_E, RHO = 1100.0, 1130.0, 1.2
C0, C2 = 0.11, 3.2e-4  # -dv/dt = c0 + c2 v^2 (m/s^2, 1/m): rolling 0.0115, drag area 0.60 m^2


def coastdown_frame(dt=0.1, v0=33.0, t_end=60.0, runs=2, c0=C0, c2=C2):
    """Exact speeds of -dv/dt = c0 + c2 v^2: v = sqrt(c0/c2) tan(atan(v0 sqrt(c2/c0)) - sqrt(c0 c2) t)."""
    t = np.arange(0.0, t_end, dt)
    v = math.sqrt(c0 / c2) * np.tan(math.atan(v0 * math.sqrt(c2 / c0)) - math.sqrt(c0 * c2) * t)
    return pd.DataFrame({"run": np.repeat(np.arange(1, runs + 1), len(t)), "time_s": np.tile(t, runs),
                         "speed_mps": np.tile(v, runs),
                         "direction": np.repeat([1 if i % 2 == 0 else -1 for i in range(runs)], len(t))})


def write(tmp_path, df, name="camp"):
    d = tmp_path / name
    d.mkdir()
    df.to_csv(d / "runs.csv", index=False)
    (d / "vehicle.toml").write_text(f"[vehicle]\nmass_kg = {MASS}\neffective_mass_kg = {M_E}\n"
                                    "frontal_area_m2 = 2.0\n")
    return d


def test_implied_road_load_recovers_the_closed_form():
    r = implied_road_load(coastdown_frame(), M_E, MASS, RHO)
    # central differences of a smooth trace at dt 0.1 s: error O(dt^2 v''') ~ 1e-5 relative
    assert r["c0"] == pytest.approx(C0, rel=1e-3) and r["c2"] == pytest.approx(C2, rel=1e-3)
    assert r["rolling"] == pytest.approx(C0 * M_E / (MASS * 9.81), rel=1e-3)
    assert r["drag_area_m2"] == pytest.approx(2 * C2 * M_E / RHO, rel=1e-3)


def test_kph_column_is_converted_and_recorded(tmp_path):
    df = coastdown_frame()
    c = load_campaign(write(tmp_path, df.rename(columns={"speed_mps": "speed_kph"}).assign(
        speed_kph=df["speed_mps"] * 3.6)))
    np.testing.assert_allclose(c.runs["speed_mps"], df["speed_mps"], rtol=1e-12)
    (conv,) = c.meta["conversions"]
    assert conv["column"] == "speed_kph" and conv["to"] == "speed_mps" and conv["stated_by"] == "column name"
    assert conv["scale"] == pytest.approx(1 / 3.6) and conv["file"].endswith("runs.csv")


def test_stated_speed_unit_converts_a_bare_or_mislabelled_column(tmp_path):
    df = coastdown_frame()
    mph = df.assign(speed_mps=df["speed_mps"] / 0.44704)
    c = load_campaign(write(tmp_path, mph.rename(columns={"speed_mps": "speed"}), "bare"), speed_unit="mph")
    np.testing.assert_allclose(c.runs["speed_mps"], df["speed_mps"], rtol=1e-12)
    assert c.meta["conversions"][0]["stated_by"] == "--speed-unit"
    kph = df.assign(speed_mps=df["speed_mps"] * 3.6)  # the name says m/s, the user says km/h
    c = load_campaign(write(tmp_path, kph, "mislabelled"), speed_unit="kph")
    np.testing.assert_allclose(c.runs["speed_mps"], df["speed_mps"], rtol=1e-12)


def test_other_unit_suffixed_columns_are_converted():
    df = coastdown_frame().assign(yaw_deg=3.0, temperature_c=15.0, pressure_kpa=98.2, airspeed_kph=90.0)
    out, conversions = convert_units(df, "runs.csv")
    assert out["yaw_rad"].iloc[0] == pytest.approx(3.0 * math.pi / 180)
    assert out["temperature_k"].iloc[0] == pytest.approx(288.15)
    assert out["pressure_pa"].iloc[0] == pytest.approx(98_200.0)
    assert out["airspeed_mps"].iloc[0] == pytest.approx(25.0)
    assert {c.column for c in conversions} == {"yaw_deg", "temperature_c", "pressure_kpa", "airspeed_kph"}
    assert not {"yaw_deg", "temperature_c", "pressure_kpa", "airspeed_kph"} & set(out.columns)


@pytest.mark.parametrize("df, options, expected", [
    (coastdown_frame().rename(columns={"speed_mps": "speed"}), {}, "column 'speed': the column name states no unit"),
    (coastdown_frame().rename(columns={"speed_mps": "speed_kph"}), {"speed_unit": "mph"},
     "column 'speed_kph': the column name says km/h but --speed-unit says mph"),
    (coastdown_frame().assign(yaw_deg=1.0, yaw_rad=0.01), {}, "column 'yaw_deg': both yaw_deg and yaw_rad"),
    (coastdown_frame(), {"airspeed_unit": "kph"}, "--airspeed-unit kph given but the table has no airspeed column"),
])
def test_ambiguous_units_are_refused_naming_file_and_column(df, options, expected):
    with pytest.raises(CampaignError) as e:
        convert_units(df, "runs.csv", **options)
    assert str(e.value).startswith("runs.csv, ") and expected in str(e.value)


def test_kph_logged_as_mps_is_refused_with_the_conversion(tmp_path):
    """A thesis-car campaign (case 14, one pair, wind and noise) with km/h in speed_mps: top
    speed 112 "m/s" passes the channel limit only because it is 100 m/s; scaled to stay below
    it (v0 25 m/s -> 90 "m/s") it is caught by the implied road load."""
    c = simulate_campaign(14, pairs=1, seed=3)
    c.runs = c.runs[c.runs["speed_mps"] < 25.0].reset_index(drop=True)
    good = save_campaign(c, tmp_path / "good")
    implied = implied_road_load(c.runs, c.vehicle.effective_mass_kg, c.vehicle.mass_kg, 1.19)
    assert PLAUSIBLE_ROLLING[0] < implied["rolling"] < PLAUSIBLE_ROLLING[1]
    assert PLAUSIBLE_DRAG_AREA_M2[0] < implied["drag_area_m2"] < PLAUSIBLE_DRAG_AREA_M2[1]
    runs = pd.read_csv(good / "runs.csv")
    bad = tmp_path / "bad"
    save_campaign(c, bad)
    runs.assign(speed_mps=runs["speed_mps"] * 3.6).to_csv(bad / "runs.csv", index=False)
    with pytest.raises(CampaignError) as e:
        load_campaign(bad)
    assert "runs.csv, column 'speed_mps'" in str(e.value) and "--speed-unit kph" in str(e.value)
    back = load_campaign(bad, speed_unit="kph")  # the conversion the message names loads it
    np.testing.assert_allclose(back.runs["speed_mps"], load_campaign(good).runs["speed_mps"], rtol=1e-9)


def test_kph_logged_as_mps_on_a_large_vehicle_is_refused(tmp_path):
    """A van's road load (rolling 0.012, drag area 1.76 m^2) logged in km/h reads as rolling
    0.043 and drag area 0.49 m^2 (x 3.6, / 3.6): the area stays above the plausible minimum,
    so only the top speed (23.4 m/s -> 84 "m/s", above the coastdown limit) with the
    implausible rolling coefficient gives the unit error away."""
    mass, m_e = 2800.0, 2884.0
    c0, c2 = 0.012 * mass * 9.81 / m_e, 1.76 * RHO / (2 * m_e)
    df = coastdown_frame(v0=23.4, t_end=120.0, c0=c0, c2=c2)  # stops at 143 s
    kph = df.assign(speed_mps=df["speed_mps"] * 3.6)
    read = implied_road_load(kph, m_e, mass, RHO)
    assert read["rolling"] > PLAUSIBLE_ROLLING[1] and read["drag_area_m2"] > PLAUSIBLE_DRAG_AREA_M2[0]
    assert read["top_speed"] > COASTDOWN_TOP_SPEED_MPS
    d = write(tmp_path, kph)
    (d / "vehicle.toml").write_text(f"[vehicle]\nmass_kg = {mass}\neffective_mass_kg = {m_e}\n"
                                    "frontal_area_m2 = 3.6\n")
    with pytest.raises(CampaignError) as e:
        load_campaign(d)
    assert "runs.csv, column 'speed_mps'" in str(e.value) and "--speed-unit kph" in str(e.value)
    np.testing.assert_allclose(load_campaign(d, speed_unit="kph").runs["speed_mps"], df["speed_mps"], rtol=1e-12)


@pytest.mark.parametrize("v0, c0, why", [
    (55.0, C0, "a coastdown from 198 km/h with a plausible road load"),
    (30.0, 0.36, "an in-gear coastdown whose rolling coefficient (0.038) no km/h reading explains at 30 m/s"),
])
def test_implausible_alone_or_fast_alone_is_not_a_unit_error(tmp_path, v0, c0, why):
    """Only the two together (or the km/h signature: rolling too high and area too low at once)
    refuse a campaign; each alone loads, whatever the road load."""
    c = load_campaign(write(tmp_path, coastdown_frame(v0=v0, c0=c0, t_end=40.0)))
    assert c.runs["speed_mps"].max() == pytest.approx(v0, rel=1e-9), why


def test_empty_file_and_empty_cell_are_named(tmp_path):
    d = write(tmp_path, coastdown_frame())
    (d / "runs.csv").write_text("")
    with pytest.raises(CampaignError, match=r"runs\.csv: the file is empty"):
        load_campaign(d)
    df = coastdown_frame()
    df.loc[4, "speed_mps"] = np.nan
    (d / "runs.csv").unlink()
    df.to_csv(d / "runs.csv", index=False)
    with pytest.raises(CampaignError) as e:
        load_campaign(d)
    assert "column 'speed_mps', row 5: an empty cell is not a finite number" in str(e.value)
    assert "np.float64" not in str(e.value)


@pytest.mark.parametrize("sep, decimal, name", [(";", ",", "semicolons"), ("\t", ".", "tabs")])
def test_a_table_separated_by_semicolons_or_tabs_is_named(tmp_path, sep, decimal, name):
    """A European spreadsheet's export (semicolons and decimal commas) or a tab-separated table
    reads as one column: refused naming the file and the separator, where the comma-separated
    table of the same samples loads."""
    df = coastdown_frame()
    d = write(tmp_path, df)
    assert len(load_campaign(d).runs) == len(df)
    (d / "runs.csv").unlink()
    df.to_csv(d / "runs.csv", index=False, sep=sep, decimal=decimal)
    with pytest.raises(CampaignError, match=rf"runs\.csv: the columns are separated by {name} .*: save the table "
                       r"comma-separated, with decimal points"):
        load_campaign(d)
    # a first row of whole numbers has fewer decimal commas than the rows after it: pandas
    # cannot tokenise such a file at all, and the header still names the separator
    text = (d / "runs.csv").read_text().splitlines()
    first = sep.join(["1", "0", "31"] + text[1].split(sep)[3:])
    (d / "runs.csv").write_text("\n".join([text[0], first, *text[2:]]) + "\n")
    with pytest.raises(CampaignError, match=rf"separated by {name}"):
        load_campaign(d)
