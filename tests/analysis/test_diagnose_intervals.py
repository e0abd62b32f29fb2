"""Sim-to-real diagnosis of interval-time campaigns: candidates as model variants, statements
for the effects gate times cannot carry, residual localisation, and (slow) a withheld track
grade found, estimated and its heading difference removed through the CLI."""

import dataclasses
import json
import warnings
from types import SimpleNamespace

import numpy as np
import pytest

from bayes_roadload.analysis import diagnose_intervals as di
from bayes_roadload.analysis.effects import EFFECT_NAMES, load_library
from bayes_roadload.inference.spec import load_model_spec


def test_every_effect_is_scored_or_stated():
    assert set(di.SCORED) | set(di.STATEMENTS) == set(EFFECT_NAMES)
    assert not set(di.SCORED) & set(di.STATEMENTS)


def test_candidates_are_model_variants_with_the_library_priors():
    lib = load_library()
    base = load_model_spec("split_f0_f2")
    grade = di.candidate_spec(base, "track_gradient", lib)
    assert "gradient" in grade.terms and grade.free == base.free + ("grade_rad",)
    assert grade.priors["grade_rad"].scale == lib["track_gradient"].prior_sd["grade_rad"]
    wind = di.candidate_spec(base, "spatial_wind", lib)
    assert wind.air == "wind" and "head_wind_mps" in wind.free and wind.fixed["cross_wind_mps"] == 0.0
    tyre = di.candidate_spec(base, "tyre_speed_exponent", lib)
    assert tyre.fixed["tyre_speed_exponent"] == lib["tyre_speed_exponent"].fixed["tyre_speed_exponent"]
    # a model that has the effect already is not offered it again
    assert di.candidate_spec(load_model_spec("split_f0_f2_grade"), "track_gradient", lib) is None
    assert di.candidate_spec(load_model_spec("split_f0_f2_wind"), "spatial_wind", lib) is None
    with pytest.raises(ValueError, match="not scored"):
        di.candidate_spec(base, "aero_lift", lib)


def test_localise_finds_a_heading_offset():
    rng = np.random.default_rng(3)
    runs, bands = 8, 5
    directions = np.array([1.0, -1.0] * 4)
    z = rng.standard_normal((runs, bands)) + 2.0 * directions[:, None]
    speeds = np.linspace(26.0, 20.0, bands + 1)
    problem = SimpleNamespace(
        mask=np.ones((runs, bands), bool), band_index=np.arange(runs * bands).reshape(runs, bands),
        bands=SimpleNamespace(speed_start_mps=np.tile(speeds[:-1], runs), speed_end_mps=np.tile(speeds[1:], runs)),
        directions=directions, windows=("95-70kph",) * runs, run_ids=tuple(range(1, runs + 1)))
    loc = di.localise(problem, z)
    assert loc["where"][0] in ("direction", "run")
    # the direction explains ~4 / (4 + 1) of the variance
    assert loc["direction"]["eta2"] == pytest.approx(0.8, abs=0.1)
    assert loc["speed_mps"]["eta2"] < 0.2
    plus = next(b for b in loc["direction"]["bins"] if b["value"] == 1.0)
    assert plus["mean_z"] == pytest.approx(2.0, abs=0.5)


@pytest.mark.slow
def test_a_withheld_grade_is_found_in_interval_times(tmp_path):
    from bayes_roadload.cli import main
    from bayes_roadload.data import save_campaign
    from bayes_roadload.physics.terms import Gradient
    from bayes_roadload.simulate import SimulationSettings, get_case, simulate_campaign
    from bayes_roadload.simulate.intervals import interval_campaign_from_traces

    case = dataclasses.replace(get_case(9), head_wind_mps=0.0, cross_wind_mps=0.0)
    settings = SimulationSettings(extra_terms=(Gradient(),), extra_params={"grade_rad": 0.002})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        camp = interval_campaign_from_traces(simulate_campaign(case, pairs=4, seed=5, settings=settings))
        save_campaign(camp, tmp_path / "campaign")
        code = main(["diagnose", str(tmp_path / "campaign"), "--out", str(tmp_path / "out"), "--no-progress"])
    assert code == 0
    d = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert set(d) == {"gap", "localisation", "candidates", "rules"}  # the rules' fingerprints as the traces'
    assert {"library_sha256", "thresholds_sha256"} <= set(d["rules"])
    top = d["candidates"][0]
    assert top["effect"] == "track_gradient" and top["supported"]
    est = top["estimates"]["grade_rad"]
    assert abs(est["mean"] - 0.002) < 4 * est["sd"]
    # the +/- heading difference of the residuals is most of what the grade removes
    assert top["shrink_pct"]["heading_z_diff"] > 80.0
    assert not any(c["supported"] for c in d["candidates"][1:])
    assert (tmp_path / "out" / "report.md").exists() and (tmp_path / "out" / "localisation.png").exists()


@pytest.mark.slow
def test_a_withheld_grade_is_ranked_first_in_distance_time_records(tmp_path):
    """The same on markers every 100 m (3 pairs): the grade leads the ranking and is estimated;
    with so few runs the distance-time fits may miss a gate, and a failed fit is never claimed."""
    from bayes_roadload.cli import main
    from bayes_roadload.data import save_campaign
    from bayes_roadload.physics.terms import Gradient
    from bayes_roadload.simulate import SimulationSettings, get_case, simulate_campaign
    from bayes_roadload.simulate.distances import distance_campaign_from_traces

    case = dataclasses.replace(get_case(9), head_wind_mps=0.0, cross_wind_mps=0.0)
    settings = SimulationSettings(extra_terms=(Gradient(),), extra_params={"grade_rad": 0.002})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        camp = distance_campaign_from_traces(simulate_campaign(case, pairs=3, seed=5, settings=settings))
        save_campaign(camp, tmp_path / "campaign")
        code = main(["diagnose", str(tmp_path / "campaign"), "--out", str(tmp_path / "out"), "--no-progress",
                     "--target-accept", "0.95"])
    assert code == 0
    d = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    top = d["candidates"][0]
    assert top["effect"] == "track_gradient" and top["delta_elpd"] > 5.0
    est = top["estimates"]["grade_rad"]
    assert abs(est["mean"] - 0.002) < 4 * est["sd"]
    assert top["supported"] == bool(top["gap_after"]["gates_pass"]) or "gates" in top["statement"]
    assert "segment" in d["localisation"]
