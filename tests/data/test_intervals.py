"""The interval campaign kind and the VBOX importer, on synthetic exports."""

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.data import CampaignError, IntervalCampaign, Vehicle, load_campaign, save_campaign
from bayes_roadload.data.vbox import import_vbox, parse_gates, read_vbox_table, write_vbox_csv

KPH = 1 / 3.6
VEHICLE = Vehicle(1500.0, 1530.0, 2.2)


def split_campaign(window=(95.0, 90.0, 85.0, 80.0, 75.0, 70.0), runs=4, f0=100.0, c=0.4, seed=0):
    """Interval times of F = f0 + c v^2 (closed form per band, small noise)."""
    rng = np.random.default_rng(seed)
    gates = np.asarray(window) * KPH
    k = np.sqrt(f0 * c)
    rows = []
    for r in range(runs):
        for j in range(len(gates) - 1):
            t = 1530.0 / k * (np.arctan(c * gates[j] / k) - np.arctan(c * gates[j + 1] / k))
            rows.append({"run": r + 1, "window": f"{window[0]:g}-{window[-1]:g}kph", "direction": 1 - 2 * (r % 2),
                         "speed_start_mps": gates[j], "speed_end_mps": gates[j + 1],
                         "interval_s": t + rng.normal(0, 0.02)})
    return IntervalCampaign(pd.DataFrame(rows), VEHICLE)


def test_save_and_load_an_interval_campaign(tmp_path):
    c = split_campaign()
    save_campaign(c, tmp_path / "c")
    assert (tmp_path / "c" / "intervals.csv").exists() and not (tmp_path / "c" / "runs.csv").exists()
    back = load_campaign(tmp_path / "c")
    assert isinstance(back, IntervalCampaign)
    pd.testing.assert_frame_equal(back.intervals, c.intervals, check_dtype=False)
    assert back.pairs() == [(1, 2), (3, 4)]


@pytest.mark.parametrize("change, message", [
    (lambda d: d.rename(columns={"interval_s": "time"}), "did you mean interval_s"),
    (lambda d: d.rename(columns={"speed_start_mps": "speed_start_kph"}), "divide km/h by 3.6"),
    (lambda d: d.assign(speed_start_mps=-d["speed_start_mps"]), "outside"),
    (lambda d: d.assign(speed_end_mps=d["speed_start_mps"]), "not below its start speed"),
    (lambda d: d.drop(index=1).reset_index(drop=True), "does not start where the previous one"),
    (lambda d: d.assign(interval_s=-d["interval_s"]), "outside"),
])
def test_interval_table_refusals_name_column_and_row(tmp_path, change, message):
    c = split_campaign()
    root = tmp_path / "c"
    save_campaign(c, root)
    change(pd.read_csv(root / "intervals.csv")).to_csv(root / "intervals.csv", index=False)
    with pytest.raises(CampaignError, match=message):
        load_campaign(root)


def test_both_kinds_in_one_directory_are_refused(tmp_path):
    root = tmp_path / "c"
    save_campaign(split_campaign(), root)
    (root / "runs.csv").write_text("run,time_s,speed_mps\n")
    with pytest.raises(CampaignError, match="ambiguous campaign kind"):
        load_campaign(root)


def test_vbox_round_trip_with_default_gates(tmp_path):
    high = write_vbox_csv(split_campaign(), tmp_path / "high.csv")
    low = write_vbox_csv(split_campaign((50.0, 45.0, 40.0, 35.0), runs=6, seed=1), tmp_path / "low.csv")
    table = read_vbox_table(high)
    assert table.bands_s.shape == (4, 5)
    camp, report = import_vbox([high, low], VEHICLE)
    assert set(camp.windows().values()) == {"95-70kph", "50-35kph"}
    assert len(camp.run_ids) == 10 and len(camp.pairs()) == 5
    assert all(abs(e) < 0.005 for e in report.distance_median_error.values())
    np.testing.assert_allclose(camp.intervals["speed_start_mps"].iloc[0], 95 * KPH)


def test_vbox_wrong_gates_or_units_are_refused(tmp_path):
    high = write_vbox_csv(split_campaign(), tmp_path / "high.csv")
    with pytest.raises(CampaignError, match="do not reproduce the logged distances"):
        import_vbox([high], VEHICLE, gates=["90,86,82,78,74,70"])
    with pytest.raises(CampaignError, match="do not reproduce"):   # m/s given as km/h
        import_vbox([high], VEHICLE, gates=[",".join(f"{x / 3.6:.4f}" for x in (95, 90, 85, 80, 75, 70))])
    with pytest.raises(CampaignError, match="band columns"):
        import_vbox([high], VEHICLE, gates=["50,45,40,35"])
    with pytest.raises(ValueError, match="descending"):
        parse_gates("70,75,80")


def test_vbox_total_time_mismatch_is_refused(tmp_path):
    high = write_vbox_csv(split_campaign(), tmp_path / "high.csv")
    lines = high.read_text(encoding="utf-8-sig").splitlines()
    parts = lines[15].split(",")
    parts[3] = f"{float(parts[3]) + 1.0:.2f}"
    lines[15] = ",".join(parts)
    high.write_text("\n".join(lines) + "\n")
    with pytest.raises(CampaignError, match="line 16: band times add up"):
        import_vbox([high], VEHICLE)


def test_speed_traces_at_several_test_masses(small_campaign):
    """``mass_kg`` per run in runs.csv: each run's M and M_e in the batch (M_e - M unchanged);
    a mass changing within a run is refused."""
    from bayes_roadload.data import Campaign

    runs = small_campaign.runs.copy()
    heavy = runs["run"].isin(small_campaign.run_ids[2:])
    runs["mass_kg"] = np.where(heavy, 1400.0, 1100.0)
    camp = Campaign(runs, small_campaign.vehicle)
    batch, _ = camp.to_batch()
    np.testing.assert_allclose(np.asarray(batch.mass_kg), [1100.0, 1100.0, 1400.0, 1400.0])
    np.testing.assert_allclose(np.asarray(batch.effective_mass_kg) - np.asarray(batch.mass_kg),
                               small_campaign.vehicle.effective_mass_kg - small_campaign.vehicle.mass_kg)
    runs.loc[1, "mass_kg"] = 1200.0
    with pytest.raises(CampaignError, match="mass_kg changes within run"):
        Campaign(runs, small_campaign.vehicle)


KESTREL = """Device Information:,,,
Name:,TEST,,
,,,
Time,Temp,Wet Bulb Temp.,Rel. Hum.,Baro.,Station P.
yyyy-MM-dd hh:mm:ss,Celsius,Celsius,%,mb,mb
{rows}
"""


def test_a_kestrel_log_brings_temperature_pressure_and_humidity_to_each_run(tmp_path):
    """The log's sample nearest each run's start (the exports' 12:00 start, runs 120 s apart)
    gives the run's ``temperature_k``, ``pressure_pa`` and ``relative_humidity_pct``, and the
    fit's density is the moist air's."""
    from bayes_roadload.data.ambient import air_density
    from bayes_roadload.data.vbox import read_kestrel
    from bayes_roadload.physics.atmosphere import air_density_kgpm3

    rows = "\n".join(f"01/01/2026 12:{m:02d},{20 + 0.1 * m:.1f},15.0,{50 + m},1000.0,{950 + m:.1f}" for m in range(0, 20))
    log = tmp_path / "kestrel.csv"
    log.write_text(KESTREL.format(rows=rows), encoding="latin-1")
    w = read_kestrel(log)
    assert list(w.columns) == ["datetime", "temperature_k", "pressure_pa", "relative_humidity_pct"]
    assert w["relative_humidity_pct"].iloc[3] == 53.0 and w["pressure_pa"].iloc[3] == pytest.approx(95_300.0)
    high = write_vbox_csv(split_campaign(), tmp_path / "high.csv")
    camp, report = import_vbox([high], VEHICLE, weather=log)
    assert "nearest sample" in report.weather
    per_run = camp.intervals.groupby("run", sort=False)[["temperature_k", "pressure_pa", "relative_humidity_pct"]].first()
    # runs start at 12:00, 12:02, 12:04, 12:06: the samples of minutes 0, 2, 4, 6
    np.testing.assert_allclose(per_run["relative_humidity_pct"], [50.0, 52.0, 54.0, 56.0])
    np.testing.assert_allclose(per_run["temperature_k"], [293.15, 293.35, 293.55, 293.75])
    rho = air_density(camp.intervals.groupby("run", sort=False).head(1))
    np.testing.assert_allclose(rho, [air_density_kgpm3(95_000.0 + 200.0 * k, 293.15 + 0.2 * k, (50.0 + 2 * k) / 100)
                                     for k in range(4)], rtol=1e-12)
