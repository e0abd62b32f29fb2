"""The distance-time campaign kind: load, save and the refusals of distances.csv."""

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.data import CampaignError, DistanceCampaign, Vehicle, load_campaign, save_campaign

VEHICLE = Vehicle(1500.0, 1530.0, 2.2)
VEHICLE_TOML = "[vehicle]\nmass_kg = 1500.0\neffective_mass_kg = 1530.0\nfrontal_area_m2 = 2.2\n"


def markers_table(runs=2, n=6):
    """Markers 100 m apart passed at a steadily falling speed (25 m/s, -0.5 m/s per segment)."""
    rows = []
    for r in range(runs):
        t = 0.0
        for k in range(n):
            rows.append({"run": r + 1, "distance_m": 50.0 + 100.0 * k, "time_s": 1000.0 * r + t,
                         "direction": 1 - 2 * (r % 2), "mass_kg": 1500.0 + 300.0 * r})
            t += 100.0 / (25.0 - 0.5 * k)
    return pd.DataFrame(rows)


def write(tmp_path, df, name="distances.csv"):
    root = tmp_path / "c"
    root.mkdir(exist_ok=True)
    df.to_csv(root / name, index=False)
    (root / "vehicle.toml").write_text(VEHICLE_TOML)
    return root


def test_load_save_round_trip(tmp_path):
    c = load_campaign(write(tmp_path, markers_table()))
    assert isinstance(c, DistanceCampaign) and c.kind == "distances"
    assert c.run_ids == [1, 2] and c.directions() == {1: 1, 2: -1} and c.pairs() == [(1, 2)]
    assert c.masses_kg() == {1: 1500.0, 2: 1800.0}
    table = c.run_table()
    assert table["markers"].tolist() == [6, 6] and table["span_m"].tolist() == [500.0, 500.0]
    back = load_campaign(save_campaign(c, tmp_path / "again"))
    pd.testing.assert_frame_equal(back.markers, c.markers, check_dtype=False, rtol=1e-12)
    assert sorted(p.name for p in (tmp_path / "again").iterdir()) == ["distances.csv", "vehicle.toml"]
    assert c.subset([2]).run_ids == [2]


@pytest.mark.parametrize("edit, column, row, words", [
    (lambda d: d.rename(columns={"time_s": "time_ms"}), "time_ms", None, "divide ms by 1000"),
    (lambda d: d.rename(columns={"distance_m": "distance_km"}), "distance_km", None, "multiply km by 1000"),
    (lambda d: d.assign(speed_mps=20.0), "speed_mps", None, "runs.csv"),
    (lambda d: d.drop(columns="time_s"), "time_s", None, "required column is missing"),
    (lambda d: d.assign(time_s=d["time_s"].where(d.index != 3, np.nan)), "time_s", 4, "not a finite number"),
    (lambda d: d.assign(distance_m=d["distance_m"].where(d.index != 2, 40.0)), "distance_m", 3, "does not increase"),
    (lambda d: d.assign(time_s=d["time_s"].where(d.index != 4, d["time_s"].iloc[3])), "time_s", 5, "does not increase"),
    (lambda d: d.assign(time_s=d["time_s"] * 1000.0), "time_s", 2, "ms in time_s"),
    (lambda d: d.assign(distance_m=d["distance_m"] / 1000.0), "time_s", 2, "km or mm"),
    (lambda d: d.assign(mass_kg=d["mass_kg"].where(d.index != 1, 1600.0)), "mass_kg", 2, "changes within run 1"),
    (lambda d: d.assign(direction=2), "direction", 1, "not +1 or -1"),
    (lambda d: d.assign(temperature_k=20.0), "temperature_k", 1, "Celsius"),
    (lambda d: d[d["run"] == 2].iloc[:2], "run", 1, "at least 3"),
    (lambda d: pd.concat([d.iloc[:3], d[d["run"] == 2], d.iloc[3:6]]), "run", 10, "not contiguous"),
])
def test_refusals_name_file_column_and_row(tmp_path, edit, column, row, words):
    root = write(tmp_path, edit(markers_table()).reset_index(drop=True))
    with pytest.raises(CampaignError) as e:
        load_campaign(root)
    msg = str(e.value)
    assert "distances.csv" in msg and f"column '{column}'" in msg and words in msg, msg
    assert (f"row {row}:" in msg) if row is not None else ("row" not in msg), msg


@pytest.mark.parametrize("other", ["runs.csv", "intervals.csv"])
def test_distances_beside_another_kind_is_ambiguous(tmp_path, other):
    root = write(tmp_path, markers_table())
    (root / other).write_text("run\n1\n")
    with pytest.raises(CampaignError, match="ambiguous campaign kind"):
        load_campaign(root)


def test_construction_validates_and_save_refuses_parquet(tmp_path):
    with pytest.raises(CampaignError, match="does not increase"):
        DistanceCampaign(markers_table().iloc[::-1].reset_index(drop=True), VEHICLE)
    with pytest.raises(ValueError, match="distances.csv"):
        save_campaign(DistanceCampaign(markers_table(), VEHICLE), tmp_path / "p", fmt="parquet")
    assert not (tmp_path / "p").exists()
