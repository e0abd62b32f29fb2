"""The spin-down data kind: loading, unit conversion and refusals of ambiguous input."""

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.data import CampaignError, load_campaign
from bayes_roadload.data.spindown import SpindownCampaign, load_spindown, save_spindown
from bayes_roadload.simulate.spindown import simulate_spindown

SETUP = "[spindown]\nwheel_inertia_kgm2 = 0.59\nrolling_radius_m = 0.28\n"


def write(root, df, toml=SETUP):
    root.mkdir(parents=True, exist_ok=True)
    df.to_csv(root / "spindown.csv", index=False)
    (root / "vehicle.toml").write_text(toml)
    return root


def table(**speed):
    t = np.arange(12) * 0.5 + 3.0
    return pd.DataFrame({"run": 1, "time_s": t, **{k: v - 0.1 * t for k, v in speed.items()}})


def test_radps_is_converted_to_tread_speed_and_time_starts_at_zero(tmp_path):
    c = load_campaign(write(tmp_path / "c", table(wheel_speed_radps=100.0)))
    assert isinstance(c, SpindownCampaign) and c.wheels == ["wheel"]
    np.testing.assert_allclose(c.runs["wheel_speed_mps"].iloc[0], (100.0 - 0.3) * 0.28)
    assert c.runs["time_s"].iloc[0] == 0.0 and c.wheel_inertia_kgm2 == {"wheel": 0.59}


@pytest.mark.parametrize("column, hint", [("wheel_speed_rpm", "2 pi / 60"), ("wheel_speed_kph", "3.6"),
                                          ("wheel_speed", "wheel_speed_radps")])
def test_unit_ambiguous_speed_columns_are_refused(tmp_path, column, hint):
    with pytest.raises(CampaignError, match=hint):
        load_campaign(write(tmp_path / "c", table(**{column: 30.0})))


def test_both_speed_columns_are_refused(tmp_path):
    with pytest.raises(CampaignError, match="not both"):
        load_campaign(write(tmp_path / "c", table(wheel_speed_radps=100.0, wheel_speed_mps=28.0)))


def test_missing_inertia_and_conflicting_radius_are_refused(tmp_path):
    with pytest.raises(CampaignError, match="wheel_inertia_kgm2.*missing"):
        load_campaign(write(tmp_path / "a", table(wheel_speed_mps=28.0), "[spindown]\nrolling_radius_m = 0.28\n"))
    both = SETUP + "\n[vehicle]\nrolling_radius_m = 0.30\n"
    with pytest.raises(CampaignError, match="ambiguous"):
        load_campaign(write(tmp_path / "b", table(wheel_speed_mps=28.0), both))
    with pytest.raises(CampaignError, match="ambiguous"):
        load_spindown(write(tmp_path / "c", table(wheel_speed_mps=28.0)), wheel_inertia_kgm2=0.7)
    with pytest.raises(CampaignError, match="outside"):
        load_campaign(write(tmp_path / "d", table(wheel_speed_mps=28.0), SETUP.replace("0.59", "5900.0")))


def test_arguments_stand_in_for_the_file(tmp_path):
    root = tmp_path / "c"
    root.mkdir()
    table(wheel_speed_mps=28.0).to_csv(root / "spindown.csv", index=False)
    c = load_spindown(root, wheel_inertia_kgm2=0.8, rolling_radius_m=0.3)
    assert c.wheel_inertia_kgm2 == {"wheel": 0.8} and c.rolling_radius_m == 0.3


def test_more_wheels_than_undriven_and_stopped_wheel_are_refused(tmp_path):
    df = pd.concat([table(wheel_speed_mps=28.0).assign(wheel="a"),
                    table(wheel_speed_mps=28.0).assign(run=2, wheel="b")])
    with pytest.raises(CampaignError, match="undriven"):
        load_campaign(write(tmp_path / "a", df, SETUP + "undriven_wheels = 1\n"))
    stopped = table(wheel_speed_mps=0.5)  # reaches 0 at t = 8 s
    with pytest.raises(CampaignError, match="stopped wheel"):
        load_campaign(write(tmp_path / "b", stopped))


def test_a_simulated_campaign_round_trips(tmp_path):
    c = simulate_spindown(tests_per_wheel=1, seed=0)
    back = load_campaign(save_spindown(c, tmp_path / "sd"))
    assert back.wheels == ["nearside", "offside"] and back.undriven_wheels == 2
    np.testing.assert_allclose(back.runs["wheel_speed_mps"], c.runs["wheel_speed_mps"], rtol=1e-9)
    assert back.truth["Au"] == pytest.approx(3.24)


def test_a_second_data_file_is_ambiguous(tmp_path):
    root = write(tmp_path / "c", table(wheel_speed_mps=28.0))
    (root / "runs.csv").write_text("run,time_s,speed_mps\n")
    with pytest.raises(CampaignError, match="ambiguous campaign kind"):
        load_campaign(root)
