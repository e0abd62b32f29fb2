"""The VBOX importer and the validity checks on the real sample exports in
../shared/data/external (no licence: read in place; skipped when the folder is absent)."""

from pathlib import Path

import pytest

from bayes_roadload.analysis.validity import interval_validity
from bayes_roadload.data import Vehicle
from bayes_roadload.data.vbox import import_vbox

SPLIT = (Path(__file__).resolve().parents[3] / "shared" / "data" / "external" / "coastdown-mda-split"
         / "sample_data" / "Split" / "coastdown")
pytestmark = [pytest.mark.external,
              pytest.mark.skipif(not SPLIT.is_dir(), reason=f"{SPLIT} not present")]
VEHICLE = Vehicle(1000.0, 1020.0, 1.0)


@pytest.mark.parametrize("files, runs", [
    (["altas_ioniq.csv", "baixas_ioniq.csv"], 31),
    (["intercalado_ioniq_16012026.csv"], 20),
    (["ford-HighSpeed-ok.csv", "Ford-LowSpeed-ok.csv"], 33),
])
def test_default_gates_reproduce_the_logged_distances(files, runs):
    camp, report = import_vbox([SPLIT / f for f in files], VEHICLE)
    assert len(camp.run_ids) == runs
    # the defaults reproduce the distances to ~0.1 %; the next candidate gates are >= 2.8 % off
    assert all(abs(e) < 0.002 for e in report.distance_median_error.values())


def test_wrong_gates_are_refused_on_real_exports():
    from bayes_roadload.data import CampaignError

    with pytest.raises(CampaignError, match="do not reproduce"):
        import_vbox([SPLIT / "altas_ioniq.csv"], VEHICLE, gates=["90,86,82,78,74,70"])


def test_braked_ford_runs_are_rejected_with_their_partners():
    camp, _ = import_vbox([SPLIT / "ford-HighSpeed-ok.csv", SPLIT / "Ford-LowSpeed-ok.csv"], VEHICLE)
    v = interval_validity(camp).set_index("run")
    short = [f"Ford-LowSpeed-ok-{i}" for i in (1, 4, 9, 12, 17)]   # ~4.6 s through 50 -> 35 km/h
    assert v.loc[short, "rejected"].all()
    assert v.loc[short, "reason"].str.contains("Hampel").all()
    assert v.loc["Ford-LowSpeed-ok-2", "reason"] == "partner of Ford-LowSpeed-ok-1"
    assert not v.loc["ford-HighSpeed-ok-1", "rejected"]


def test_standard_exports_default_gates_and_hourless_start_times():
    standard = SPLIT.parents[1] / "Standard"
    camp, report = import_vbox([standard / "su2b_1388_manha_recalc.csv"], VEHICLE)
    assert len(camp.run_ids) == 10 and camp.intervals.groupby("run").size().eq(14).all()
    assert all(abs(e) < 0.005 for e in report.distance_median_error.values())
    assert "start_time_of_day_s" not in camp.intervals           # mm:ss.s: the hour is not guessed
