"""Loading and saving any kind of campaign through the registry of data kinds."""

import itertools

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.data import (
    DATA_KINDS,
    Campaign,
    CampaignError,
    DistanceCampaign,
    IntervalCampaign,
    SpindownCampaign,
    SteadyCampaign,
    Vehicle,
    data_kind,
    kind_of,
    load_campaign,
    save_campaign,
)
from bayes_roadload.data.io import DATA_FILES

VEHICLE = Vehicle(1500.0, 1530.0, 2.2)


def traces():
    t = np.arange(20) * 0.5
    return Campaign(pd.DataFrame({"run": np.repeat([1, 2], 20), "time_s": np.tile(t, 2),
                                  "speed_mps": np.tile(30.0 - 0.3 * t, 2), "direction": np.repeat([1, -1], 20)}),
                    VEHICLE, truth={"CD0": 0.4})


def intervals():
    return IntervalCampaign(pd.DataFrame({"run": [1, 1, 2, 2], "speed_start_mps": [30.0, 28.0, 30.0, 28.0],
                                          "speed_end_mps": [28.0, 26.0, 28.0, 26.0],
                                          "interval_s": [3.1, 3.3, 3.0, 3.2], "direction": [1, 1, -1, -1]}),
                            VEHICLE, truth={"CD0": 0.4})


def distances():
    x = 100.0 * np.arange(5)
    return DistanceCampaign(pd.DataFrame({"run": np.repeat([1, 2], 5), "distance_m": np.tile(x, 2),
                                          "time_s": np.tile(x / 25.0 + 0.01 * np.arange(5) ** 2, 2)}),
                            VEHICLE, truth={"CD0": 0.4})


def spindown():
    t = np.arange(12) * 0.5
    return SpindownCampaign(pd.DataFrame({"run": 1, "time_s": t, "wheel_speed_mps": 20.0 - 0.1 * t}),
                            {"wheel": 0.59}, 0.28, truth={"Au": 60.0})


def steady():
    return SteadyCampaign(pd.DataFrame({"run": np.repeat([1, 2], 3), "speed_mps": 20.0,
                                        "tractive_force_n": 300.0, "direction": np.repeat([1, -1], 3)}),
                          VEHICLE, truth={"CD0": 0.4})


CAMPAIGNS = {"traces": traces, "intervals": intervals, "distances": distances, "spindown": spindown,
             "steady": steady}


def test_every_registered_kind_follows_the_protocol():
    assert sorted(k.KIND for k in DATA_KINDS) == sorted(CAMPAIGNS)  # a new kind needs a campaign here
    assert len(DATA_FILES) == len(set(DATA_FILES))  # a file name identifies one kind
    for kind in DATA_KINDS:
        assert isinstance(kind.DESCRIPTION, str) and kind.FILES and isinstance(kind.OPTIONS, tuple)
        assert isinstance(kind.OPTIONAL_FILES, tuple) and not set(kind.OPTIONAL_FILES) & set(DATA_FILES)
        assert callable(kind.load) and callable(kind.files)
        assert data_kind(kind.KIND) is kind and kind_of(CAMPAIGNS[kind.KIND]()) is kind


@pytest.mark.parametrize("kind", DATA_KINDS, ids=lambda k: k.KIND)
def test_every_kind_round_trips_through_save_and_load_campaign(tmp_path, kind):
    c = CAMPAIGNS[kind.KIND]()
    out = save_campaign(c, tmp_path / "c")
    assert sorted(p.name for p in out.iterdir()) == sorted([kind.FILES[0], "vehicle.toml", "truth.json"])
    back = load_campaign(out)
    assert type(back) is type(c) and back.kind == kind.KIND and back.run_ids == c.run_ids
    assert back.truth == c.truth


def test_saving_replaces_every_other_kinds_data(tmp_path):
    root = tmp_path / "c"
    for kind in DATA_KINDS + DATA_KINDS[:1]:
        c = CAMPAIGNS[kind.KIND]()
        c.truth = None
        save_campaign(c, root)
        assert kind_of(load_campaign(root)) is kind
        assert not (root / "truth.json").exists()


@pytest.mark.parametrize("a, b", itertools.combinations(DATA_KINDS, 2), ids=lambda k: k.KIND)
def test_two_kinds_in_one_directory_are_refused(tmp_path, a, b):
    save_campaign(CAMPAIGNS[a.KIND](), tmp_path)
    (tmp_path / b.FILES[0]).write_text("run\n")
    with pytest.raises(CampaignError, match="ambiguous campaign kind") as e:
        load_campaign(tmp_path)
    assert a.FILES[0] in str(e.value) and b.FILES[0] in str(e.value)


def test_a_directory_without_data_names_every_kinds_file(tmp_path):
    with pytest.raises(CampaignError, match="is missing") as e:
        load_campaign(tmp_path)
    assert all(name in str(e.value) for name in DATA_FILES)
    with pytest.raises(CampaignError, match="not a campaign directory"):
        load_campaign(tmp_path / "nowhere")


def test_load_options_reach_their_kind_only(tmp_path):
    sd = tmp_path / "sd"
    save_campaign(spindown(), sd)
    (sd / "vehicle.toml").write_text("[spindown]\nrolling_radius_m = 0.28\n")  # no inertia in the file
    with pytest.raises(CampaignError, match="wheel_inertia_kgm2"):
        load_campaign(sd)
    c = load_campaign(sd, wheel_inertia_kgm2=0.7, rolling_radius_m=None)
    assert c.wheel_inertia_kgm2 == {"wheel": 0.7}
    tr = save_campaign(traces(), tmp_path / "tr")
    assert load_campaign(tr, wheel_inertia_kgm2=None, rolling_radius_m=None).kind == "traces"
    with pytest.raises(ValueError, match=r"^--wheel-inertia-kgm2 / --rolling-radius-m apply to spin-down "
                                         r"campaigns \(spindown.csv\) only$"):
        load_campaign(tr, rolling_radius_m=0.3)
    with pytest.raises(TypeError, match="'colour'"):
        load_campaign(tr, colour="red")


def test_unknown_kinds_and_formats_are_refused(tmp_path):
    with pytest.raises(TypeError, match="not a campaign"):
        save_campaign(object(), tmp_path / "x")
    with pytest.raises(ValueError, match="unknown campaign kind 'wind'"):
        data_kind("wind")
    with pytest.raises(ValueError, match="written as spindown.csv"):
        save_campaign(spindown(), tmp_path / "p", fmt="parquet")
    with pytest.raises(ValueError, match="fmt must be 'csv' or 'parquet'"):
        save_campaign(traces(), tmp_path / "p", fmt="xlsx")
    assert not (tmp_path / "x").exists() and not (tmp_path / "p").exists()
