"""Fast subset of the robustness suite (tests/robustness/draws.py; the long run is
benchmarks/robustness.py): a few valid draws fitted through the command line end in a written
fit, invalid ones in a clean refusal."""

import pytest

from .draws import INVALID, draw, run_draw, write_campaign

# draws picked for speed: least squares on one pair (four_term stopping at 12 m/s; three_term
# without anemometer coasting down to 0.5 m/s); the NUTS fit of a two-pair interval campaign of a
# truck (speed-gate times at 2 Hz) is slow: interval NUTS fits through the command line are also
# in tests/output/test_report.py and tests/test_cli.py
VALID_SEEDS = (26, pytest.param(30, marks=pytest.mark.slow), pytest.param(10018, marks=pytest.mark.slow))  # benchmarks/robustness.py draws the rest


@pytest.mark.parametrize("seed", VALID_SEEDS)
def test_a_valid_draw_ends_in_a_written_fit(seed, tmp_path):
    d = draw(seed)
    rec = run_draw(d, tmp_path)
    assert rec["outcome"] in ("fitted", "gates_failed"), rec


@pytest.mark.parametrize("how", INVALID)
def test_an_invalid_draw_is_refused_cleanly(how, tmp_path):
    # start 31 m/s: km/h read as m/s then exceeds the 100 m/s channel limit (below 27.8 m/s the
    # implied road load refuses it: test_kph_in_a_mps_column_below_the_speed_limit_is_refused_...)
    d = dict(draw(1000, invalid=True), invalid=how, pairs=1, method="lsq", model="three_term", rate_hz=2.0,
             start_speed_mps=31.0)
    rec = run_draw(d, tmp_path)
    assert rec["outcome"] == "refused", rec
    assert "runs.csv" in rec["message"] or how == "missing_time", rec  # the message names the file


def test_kph_in_a_mps_column_below_the_speed_limit_is_refused_with_the_conversion(tmp_path):
    """A 97 km/h start read as 97 m/s stays under the 100 m/s channel limit; the implied road
    load (rolling coefficient x 3.6, drag area / 3.6) refuses it and names --speed-unit kph."""
    d = dict(draw(1000, invalid=True), invalid="kph_in_mps", pairs=1, method="lsq", model="three_term",
             rate_hz=2.0, start_speed_mps=27.0)
    rec = run_draw(d, tmp_path)
    assert rec["outcome"] == "refused", rec
    assert "runs.csv" in rec["message"] and "--speed-unit kph" in rec["message"], rec


@pytest.mark.slow
def test_speed_only_suv_campaign_with_driveline_channel_fits(tmp_path):
    """The reported case: a 1950 kg SUV, 0.5 m/s cross wind, driveline channel logged, 6 pairs,
    airspeed and yaw removed, ``fit --method nuts --model three_term``: a written fit."""
    d = dict(draw(0), kind="traces", vehicle="suv", pairs=6, head_wind_mps=0.0, cross_wind_mps=0.5,
             rate_hz=4.0, start_speed_mps=31.3, stop_speed_mps=5.0, dynamics=True, measurement_noise=True,
             system_noise=True, drop_anemometer=True, driveline=True, model="three_term", method="nuts")
    rec = run_draw(d, tmp_path)
    assert rec["outcome"] in ("fitted", "gates_failed"), rec


def test_a_tail_wind_above_the_stop_speed_simulates_a_valid_campaign(tmp_path):
    """Robustness seed 60073 (a small car stopping at 2 m/s in a 2.81 m/s wind, measurement
    noise on): the relative airspeed of the tail-wind runs nears 0 at the end, and the noisy
    reading went negative, a campaign the loader refuses.  Readings of magnitudes are clipped
    at 0, as a sensor's are; the campaign is written and loads."""
    from bayes_roadload.data import load_campaign

    d = dict(draw(60073), drop_anemometer=False)  # the draw drops the anemometer after simulating
    assert d["head_wind_mps"] > d["stop_speed_mps"] and d["measurement_noise"]
    c = load_campaign(write_campaign(d, tmp_path / "c"))
    assert (c.runs["airspeed_mps"] >= 0).all() and (c.runs["speed_mps"] >= 0).all()
    assert c.runs["airspeed_mps"].min() < 0.5  # the tail-wind runs do reach a near-zero airspeed
