"""Dynamometer coastdown directory: round trip and refusals."""

import pytest

from bayes_roadload.data.dyno import load_dyno, save_dyno
from bayes_roadload.simulate.dyno import simulate_dyno


def test_round_trip_keeps_setup_and_truth(tmp_path):
    d = simulate_dyno((100.0, 0.8, 0.025), (35.0, 0.25, 0.003), 1150.0)
    save_dyno(d, tmp_path / "dyno")
    back = load_dyno(tmp_path / "dyno")
    assert back.inertia_kg == 1150.0
    assert back.set_coefficients == (100.0, 0.8, 0.025)
    assert back.parasitic_truth == (35.0, 0.25, 0.003)
    assert back.runs["speed_mps"].to_numpy() == pytest.approx(d.runs["speed_mps"].to_numpy(), rel=1e-9)


def test_missing_set_coefficients_are_refused(tmp_path):
    d = simulate_dyno((100.0, 0.8, 0.025), (35.0, 0.25, 0.003), 1150.0)
    save_dyno(d, tmp_path)
    (tmp_path / "dyno.toml").write_text("[dyno]\ninertia_kg = 1150.0\n")
    with pytest.raises(ValueError, match="set_coefficients"):
        load_dyno(tmp_path)


def test_dyno_toml_with_a_byte_order_mark_reads_and_bad_toml_names_the_file(tmp_path):
    from bayes_roadload.data import CampaignError

    d = simulate_dyno((100.0, 0.8, 0.025), (35.0, 0.25, 0.003), 1150.0)
    save_dyno(d, tmp_path)
    text = (tmp_path / "dyno.toml").read_text()
    (tmp_path / "dyno.toml").write_text("\ufeff" + text, encoding="utf-8")
    assert load_dyno(tmp_path).inertia_kg == 1150.0
    (tmp_path / "dyno.toml").write_text("[dyno\n")
    with pytest.raises(CampaignError, match="dyno.toml: not valid TOML"):
        load_dyno(tmp_path)


def test_dyno_table_gets_the_speed_traces_checks(tmp_path):
    """km/h in speed_mps (implied road load), time running backwards, a km/h column converted."""
    from bayes_roadload.data import CampaignError

    d = simulate_dyno((100.0, 0.8, 0.025), (35.0, 0.25, 0.003), 1150.0)
    save_dyno(d, tmp_path)
    f = tmp_path / "dyno_coastdown.csv"
    runs = d.runs.copy()
    runs.assign(speed_mps=runs["speed_mps"] * 3.6).pipe(lambda r: r[r["speed_mps"] < 100]).to_csv(f, index=False)
    with pytest.raises(CampaignError, match=r"dyno_coastdown.csv, column 'speed_mps': the speeds look logged in km/h"):
        load_dyno(tmp_path)
    runs.assign(time_s=runs["time_s"].where(runs.index != 4, 0.0)).to_csv(f, index=False)
    with pytest.raises(CampaignError, match=r"dyno_coastdown.csv, column 'time_s', row 5: time does not increase"):
        load_dyno(tmp_path)
    runs.assign(speed_kph=runs.pop("speed_mps") * 3.6).to_csv(f, index=False)
    back = load_dyno(tmp_path)
    assert back.runs["speed_mps"].to_numpy() == pytest.approx(d.runs["speed_mps"].to_numpy(), rel=1e-9)
    assert back.conversions[0]["column"] == "speed_kph"
