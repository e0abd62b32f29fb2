"""vehicle.toml: reading refuses with the file and the key, writing reads back the same vehicle."""

import json
import tomllib

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.data import Campaign, CampaignError, Vehicle, load_campaign
from bayes_roadload.data.vehicle import Anemometer, read_vehicle_file, vehicle_from_toml, vehicle_toml

VEHICLE_TOML = """[vehicle]
mass_kg = 1100.0
effective_mass_kg = 1130.0
frontal_area_m2 = 1.85
rolling_radius_m = 0.28
"""


def runs_frame(n=40, runs=2):
    t = np.arange(n) * 0.25
    return pd.DataFrame({"run": np.repeat(np.arange(1, runs + 1), n), "time_s": np.tile(t, runs),
                         "speed_mps": np.tile(30.0 - 0.3 * t, runs)})


@pytest.mark.parametrize(
    "toml, expected",
    [
        (VEHICLE_TOML.replace("1100.0", "0.0"), "[vehicle] mass_kg"),
        (VEHICLE_TOML.replace("1.85", "185.0"), "[vehicle] frontal_area_m2"),
        (VEHICLE_TOML.replace("effective_mass_kg = 1130.0", ""), "[vehicle] effective_mass_kg"),
        (VEHICLE_TOML.replace("1130.0", "1000.0"), "less than the test mass"),
        (VEHICLE_TOML + "colour = 'red'\n", "[vehicle] colour"),
        (VEHICLE_TOML + "mass_in_running_order_kg = 1200.0\n", "the test mass includes the mass in running order"),
        (VEHICLE_TOML + "[anemometer]\nairspeed_factor = 10.8\n", "[anemometer] airspeed_factor"),
        (VEHICLE_TOML + "[anemometer]\nairspeed_yaw_coefficient_per_rad2 = 1.5\n",
         "[anemometer] airspeed_yaw_coefficient_per_rad2"),
        (VEHICLE_TOML + "[anemometer]\nyaw_factor = 'one'\n", "[anemometer] yaw_factor"),
        ("[vehicle\n", "not valid TOML"),
        (VEHICLE_TOML.replace("1100.0", '"1100 kg"'), "column '[vehicle] mass_kg': '1100 kg' is not a number"),
        (VEHICLE_TOML.replace("1100.0", '"1100"'), "column '[vehicle] mass_kg': '1100' is not a number"),
        (VEHICLE_TOML.replace("1.85", '"1,85"'), "column '[vehicle] frontal_area_m2': '1,85' is not a number"),
        (VEHICLE_TOML.replace("0.28", "true"), "column '[vehicle] rolling_radius_m': True is not a number"),
        ("vehicle = 3\n", "column '[vehicle]': is 3, not a table"),
        (VEHICLE_TOML.replace("[vehicle]", "anemometer = 2\n[vehicle]"), "column '[anemometer]': is 2, not a table"),
    ],
)
def test_vehicle_refusals(tmp_path, toml, expected):
    f = tmp_path / "vehicle.toml"
    f.write_text(toml)
    with pytest.raises(CampaignError) as e:
        read_vehicle_file(f)
    assert "vehicle.toml" in str(e.value) and expected in str(e.value)


def test_a_campaign_refuses_its_bad_vehicle_file(tmp_path):
    root = tmp_path / "c"
    root.mkdir()
    runs_frame().to_csv(root / "runs.csv", index=False)
    (root / "vehicle.toml").write_text(VEHICLE_TOML.replace("1.85", "185.0"))
    with pytest.raises(CampaignError, match=r"vehicle.toml, column '\[vehicle\] frontal_area_m2'"):
        load_campaign(root)
    (root / "vehicle.toml").unlink()
    with pytest.raises(CampaignError, match="vehicle.toml: missing"):
        load_campaign(root)


def test_vehicle_toml_reads_back_and_carries_tunnel():
    c = Campaign(runs_frame(), Vehicle(1100.0, 1130.0, 1.85, 0.3, 4.2), Anemometer(1.05, 0.95),
                 tunnel={"KD": 0.614, "yaw_deg": [-5.0, 0.0, 5.0], "cd": [0.41, 0.40, 0.41]}, meta={"case": 14})
    doc = tomllib.loads(vehicle_toml(c))
    assert doc["tunnel"]["yaw_deg"] == [-5.0, 0.0, 5.0] and doc["meta"]["case"] == 14
    assert json.dumps(doc)  # plain data
    assert vehicle_from_toml(doc, "vehicle.toml") == (c.vehicle, c.anemometer, c.tunnel, c.meta)


def test_rotating_inertia_gives_the_effective_mass():
    doc = tomllib.loads(VEHICLE_TOML.replace("effective_mass_kg = 1130.0", "rotating_inertia_kgm2 = 2.352"))
    vehicle, *_ = vehicle_from_toml(doc, "vehicle.toml")
    assert vehicle.effective_mass_kg == pytest.approx(1100.0 + 2.352 / 0.28**2)  # eq. 2.2


def test_mass_in_running_order_reads_back():
    doc = tomllib.loads(VEHICLE_TOML + "mass_in_running_order_kg = 1020.0\n")
    vehicle, anem, tunnel, meta = vehicle_from_toml(doc, "vehicle.toml")
    assert vehicle.mass_in_running_order_kg == 1020.0
    c = Campaign(runs_frame(), vehicle, anem, tunnel, meta=meta)
    assert vehicle_from_toml(tomllib.loads(vehicle_toml(c)), "vehicle.toml")[0] == vehicle


def test_a_stated_yaw_calibration_reads_back_and_corrects_the_airspeed_as_it_enters_a_fit():
    """``airspeed_yaw_coefficient_per_rad2`` e: the batch's airspeed is reading x (1 + e psi^2),
    psi = yaw_factor x yaw reading; the table keeps the readings; absent, nothing changes."""
    runs = runs_frame().assign(airspeed_mps=lambda d: d["speed_mps"] + 2.0, yaw_rad=np.tile(np.linspace(-0.3, 0.3, 40), 2))
    doc = tomllib.loads(VEHICLE_TOML + "[anemometer]\nairspeed_factor = 1.05\nyaw_factor = 0.9\n"
                        "airspeed_yaw_coefficient_per_rad2 = -0.18\n")
    vehicle, anem, tunnel, meta = vehicle_from_toml(doc, "vehicle.toml")
    assert anem.airspeed_yaw_coefficient_per_rad2 == -0.18
    c = Campaign(runs, vehicle, anem, tunnel, meta=meta)
    assert vehicle_from_toml(tomllib.loads(vehicle_toml(c)), "vehicle.toml")[1] == anem
    batch, ids = c.to_batch()
    psi = 0.9 * runs["yaw_rad"].to_numpy().reshape(2, 40)
    want = runs["airspeed_mps"].to_numpy().reshape(2, 40) * (1.0 - 0.18 * psi**2)
    np.testing.assert_allclose(np.asarray(batch.airspeed_mps)[:, :40], want, rtol=1e-12)
    back = anem.yaw_uncorrected_airspeed(want.ravel(), runs["yaw_rad"].to_numpy())
    np.testing.assert_allclose(back, runs["airspeed_mps"].to_numpy(), rtol=1e-12)  # the inverse, for written-back data
    vr, yaw = anem.calibrated_air(runs["airspeed_mps"], runs["yaw_rad"])
    np.testing.assert_allclose(vr, 1.05 * want.ravel(), rtol=1e-12)
    np.testing.assert_allclose(yaw, psi.ravel(), rtol=1e-12)
    plain = Campaign(runs, vehicle, Anemometer(1.05, 0.9), tunnel, meta=meta)
    assert "airspeed_yaw_coefficient" not in vehicle_toml(plain)
    np.testing.assert_array_equal(np.asarray(plain.to_batch()[0].airspeed_mps)[:, :40],
                                  runs["airspeed_mps"].to_numpy().reshape(2, 40))


def test_a_byte_order_mark_is_skipped_in_toml_and_json_and_bad_json_names_its_file(tmp_path):
    """TOML and JSON written with a UTF-8 byte-order mark read as the CSV files do; a
    truth.json that is not JSON, or holds no object, is refused naming it."""
    root = tmp_path / "c"
    root.mkdir()
    runs_frame().to_csv(root / "runs.csv", index=False)
    (root / "vehicle.toml").write_text("\ufeff" + VEHICLE_TOML, encoding="utf-8")
    (root / "truth.json").write_text("\ufeff" + json.dumps({"AD": 0.01}), encoding="utf-8")
    c = load_campaign(root)
    assert c.vehicle.mass_kg == 1100.0 and c.truth == {"AD": 0.01}
    for text, expected in (("{'AD': 0.01}", r"truth.json: not valid JSON \(Expecting property name"),
                           ("[0.01]", "truth.json: holds a JSON list, not an object")):
        (root / "truth.json").write_text(text)
        with pytest.raises(CampaignError, match=expected):
            load_campaign(root)
