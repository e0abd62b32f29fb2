"""The speed-trace kind (runs.csv / runs.parquet): round trip, conversions, and every refusal names
file/column/row."""

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.data import Campaign, CampaignError, Vehicle, load_campaign, save_campaign

VEHICLE_TOML = """[vehicle]
mass_kg = 1100.0
effective_mass_kg = 1130.0
frontal_area_m2 = 1.85
rolling_radius_m = 0.28
"""


def runs_frame(n=40, runs=2):
    t = np.arange(n) * 0.25
    return pd.DataFrame({
        "run": np.repeat(np.arange(1, runs + 1), n),
        "time_s": np.tile(t, runs),
        "speed_mps": np.tile(30.0 - 0.3 * t, runs),
        "direction": np.repeat([1 if i % 2 == 0 else -1 for i in range(runs)], n),
    })


def write(tmp_path, df, toml=VEHICLE_TOML):
    d = tmp_path / "camp"
    d.mkdir()
    df.to_csv(d / "runs.csv", index=False)
    (d / "vehicle.toml").write_text(toml)
    return d


def test_round_trip_and_batch(tmp_path):
    c = Campaign(runs_frame(), Vehicle(1100.0, 1130.0, 1.85), truth={"AD": 0.01})
    out = save_campaign(c, tmp_path / "c")
    back = load_campaign(out)
    pd.testing.assert_frame_equal(back.runs, c.runs)
    assert back.truth == {"AD": 0.01}
    assert back.pairs() == [(1, 2)] and back.directions() == {1: 1, 2: -1}
    batch, ids = back.to_batch()
    assert ids == [1, 2] and batch.time_s.shape == (2, 40)
    assert float(batch.air_density_kgpm3[0, 0]) == pytest.approx(1.18818, rel=1e-4)


def test_wheel_torque_and_rotating_inertia(tmp_path):
    df = runs_frame()
    df["wheel_torque_left_nm"] = 3.0
    df["wheel_torque_right_nm"] = 4.0
    toml = VEHICLE_TOML.replace("effective_mass_kg = 1130.0", "rotating_inertia_kgm2 = 2.352")
    c = load_campaign(write(tmp_path, df, toml))
    np.testing.assert_allclose(c.runs["driveline_force_n"], 7.0 / 0.28)
    assert "wheel_torque_left_nm" not in c.runs
    assert c.vehicle.effective_mass_kg == pytest.approx(1100.0 + 2.352 / 0.28**2)


@pytest.mark.parametrize(
    "mutate, expected",
    [
        (lambda d: d.drop(columns="speed_mps"), "column 'speed_mps': required column is missing"),
        (lambda d: d.rename(columns={"speed_mps": "speed"}), "column 'speed': the column name states no unit"),
        (lambda d: d.assign(speed_kph=d["speed_mps"] * 3.6), "column 'speed_kph': two speed columns"),
        (lambda d: d.assign(speed_mps=d["speed_mps"] * 3.6 + 20), "column 'speed_mps', row 1"),
        (lambda d: d.assign(speed_mps=d["speed_mps"].where(d.index != 7, np.nan)), "column 'speed_mps', row 8"),
        (lambda d: d.assign(speed_mps=d["speed_mps"].where(d.index != 3, -1.0)), "row 4"),
        (lambda d: d.assign(speed_mps=d["speed_mps"].where(d.index != 52, 0.0)),
         "column 'speed_mps', row 53: run 2: speed 0 m/s, at or below standstill"),
        (lambda d: d.assign(speed_mps=d["speed_mps"].where(d.index != 12, 0.2)), "row 13: run 1: speed 0.2 m/s"),
        (lambda d: d.assign(time_s=d["time_s"].where(d.index != 5, 0.0)), "column 'time_s', row 6"),
        (lambda d: d.assign(direction=d["direction"].where(d.index != 2, 2)), "column 'direction', row 3"),
        (lambda d: d.assign(direction=d["direction"].where(d.index != 9, -1)), "direction changes within run"),
        (lambda d: d.iloc[:45], "run 2 has 5 samples"),
        (lambda d: d.assign(temperature_k=20.0), "column 'temperature_k', row 1"),
        (lambda d: d.assign(pressure_pa=101.3), "column 'pressure_pa', row 1"),
        (lambda d: d.assign(airspeed_mps=d["speed_mps"], yaw_rad=5.0), "column 'yaw_rad', row 1"),
        (lambda d: d.assign(airspeed_mps=np.inf, yaw_rad=0.0), "not a finite number"),
        (lambda d: d.assign(airspeed_mps=d["speed_mps"]), "column 'yaw_rad': airspeed_mps without yaw_rad"),
        (lambda d: d.assign(yaw_rad=0.0), "column 'airspeed_mps': yaw_rad without airspeed_mps"),
    ],
)
def test_refusals_name_file_column_row(tmp_path, mutate, expected):
    d = write(tmp_path, mutate(runs_frame()))
    with pytest.raises(CampaignError) as e:
        load_campaign(d)
    assert "runs.csv" in str(e.value) and expected in str(e.value)


def test_nothing_written_when_refused(tmp_path):
    df = runs_frame()
    c = Campaign(df, Vehicle(1100.0, 1130.0, 1.85))
    c.runs.loc[3, "speed_mps"] = 250.0  # km/h-like value sneaks in after construction
    with pytest.raises(CampaignError):
        save_campaign(c, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    assert list(tmp_path.iterdir()) == []


def test_both_csv_and_parquet_is_ambiguous(tmp_path):
    d = write(tmp_path, runs_frame())
    (d / "runs.parquet").write_bytes(b"")
    with pytest.raises(CampaignError, match="ambiguous"):
        load_campaign(d)


def test_subset_and_pair_column():
    df = runs_frame(runs=4)
    df["pair"] = np.repeat([10, 10, 11, 11], 40)
    c = Campaign(df, Vehicle(1100.0, 1130.0, 1.85))
    assert c.pairs() == [(1, 2), (3, 4)]
    s = c.subset([4, 3])
    assert s.run_ids == [4, 3] and s.pairs() == [(4, 3)]


def test_parquet_round_trip(tmp_path):
    pytest.importorskip("pyarrow")
    c = Campaign(runs_frame(), Vehicle(1100.0, 1130.0, 1.85))
    out = save_campaign(c, tmp_path / "pq", fmt="parquet")
    assert (out / "runs.parquet").exists() and not (out / "runs.csv").exists()
    pd.testing.assert_frame_equal(load_campaign(out).runs, c.runs)


def test_text_pair_ids_are_ids(tmp_path):
    """``pair`` is an id as in the other kinds: text pair ids load from CSV and parquet, pair the
    runs, survive a subset and a save/load round trip."""
    df = runs_frame(runs=4)
    df["pair"] = np.repeat(["A", "B", "B", "A"], 40)
    c = load_campaign(write(tmp_path, df))
    assert c.pairs() == [(1, 4), (2, 3)]
    assert c.subset([3, 2]).pairs() == [(3, 2)]
    pytest.importorskip("pyarrow")
    for fmt in ("csv", "parquet"):
        back = load_campaign(save_campaign(c, tmp_path / fmt, fmt=fmt))
        assert back.pairs() == [(1, 4), (2, 3)]
        assert list(back.runs["pair"]) == list(c.runs["pair"])


def test_missing_text_pair_id_names_its_row(tmp_path):
    df = runs_frame(runs=2)
    df["pair"] = "A"
    df.loc[45, "pair"] = None
    with pytest.raises(CampaignError, match=r"runs.csv, column 'pair', row 46: missing pair id"):
        load_campaign(write(tmp_path, df))


@pytest.mark.parametrize("as_time", [lambda t: pd.Timestamp("2024-05-01 10:00") + pd.to_timedelta(t, unit="s"),
                                     lambda t: pd.to_timedelta(t, unit="s")], ids=["datetime", "timedelta"])
def test_datetime_or_timedelta_time_is_refused(tmp_path, as_time):
    """A parquet time column of datetimes or timedeltas would be read as integer nanoseconds."""
    pytest.importorskip("pyarrow")
    df = runs_frame().assign(time_s=lambda d: as_time(d["time_s"]))
    d = tmp_path / "camp"
    d.mkdir()
    df.to_parquet(d / "runs.parquet", index=False)
    (d / "vehicle.toml").write_text(VEHICLE_TOML)
    with pytest.raises(CampaignError, match=r"runs.parquet, column 'time_s', row 1: a (datetime|timedelta)64.* column, "
                       r"not a number: give the seconds from the run's start as a number"):
        load_campaign(d)


def coastdown_frame(runs=2, n=160, dt=0.25, c0=0.115, c2=4.2e-4, v0=30.0):
    """Exact coastdowns of -dv/dt = c0 + c2 v^2 (rolling coefficient ~0.012, drag area ~0.8 m^2
    for the 1100 kg car at the reference density)."""
    t = np.arange(n) * dt
    k = np.sqrt(c0 * c2)
    v = np.sqrt(c0 / c2) * np.tan(np.arctan(v0 * np.sqrt(c2 / c0)) - k * t)
    return pd.DataFrame({"run": np.repeat(np.arange(1, runs + 1), n), "time_s": np.tile(t, runs),
                         "speed_mps": np.tile(v, runs),
                         "direction": np.repeat([1 if i % 2 == 0 else -1 for i in range(runs)], n)})


def test_time_in_milliseconds(tmp_path):
    """A ``time_ms`` column is converted to seconds and recorded; milliseconds in ``time_s`` (the
    implied road load 1000-fold too small) and seconds in ``time_ms`` (1000-fold too large) are
    refused naming the column."""
    df = coastdown_frame()
    for name in "abcd":
        (tmp_path / name).mkdir()
    load_campaign(write(tmp_path / "a", df))
    ms = df.rename(columns={"time_s": "time_ms"}).assign(time_ms=lambda d: d["time_ms"] * 1000.0)
    c = load_campaign(write(tmp_path / "b", ms))
    np.testing.assert_allclose(c.runs["time_s"], df["time_s"])
    assert [(x["column"], x["to"], x["scale"]) for x in c.meta["conversions"]] == [("time_ms", "time_s", 0.001)]
    with pytest.raises(CampaignError, match=r"runs.csv, column 'time_s': the times look logged in milliseconds: "
                       r"rename the column time_ms"):
        load_campaign(write(tmp_path / "c", df.assign(time_s=df["time_s"] * 1000.0)))
    with pytest.raises(CampaignError, match=r"runs.csv, column 'time_ms': the times look logged in seconds"):
        load_campaign(write(tmp_path / "d", df.rename(columns={"time_s": "time_ms"})))


@pytest.mark.parametrize("unit, scale", [("kph", 3.6), ("mph", 1.0 / 0.44704)])
def test_airspeed_in_kph_or_mph_below_the_range_check_is_refused(tmp_path, unit, scale):
    """Airspeeds read in km/h or mph exceed the speeds by far more than any wind the standards
    admit (10 m/s peak); in m/s with a 7 m/s head wind in every run (one direction) they pass."""
    df = coastdown_frame()
    df = df[df["speed_mps"] < 25.0].reset_index(drop=True)  # km/h readings stay below 100 "m/s"
    (tmp_path / "ok").mkdir()
    load_campaign(write(tmp_path / "ok", df.assign(airspeed_mps=df["speed_mps"] + 7.0, yaw_rad=0.0)))
    (tmp_path / unit).mkdir()
    with pytest.raises(CampaignError, match=rf"runs.csv, column 'airspeed_mps', row 1: the airspeeds look logged in "
                       rf".*: give --airspeed-unit {unit} or rename the column airspeed_{unit}"):
        load_campaign(write(tmp_path / unit, df.assign(airspeed_mps=(df["speed_mps"] + 2.0) * scale, yaw_rad=0.0)))
