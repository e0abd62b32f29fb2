"""The proof suite of the sim-to-real diagnosis: its campaign designs (the independent one
with the admittance it revealed), the distorted campaigns of calibration and mass errors, and
(slow) null controls and confounded effects through the batch door."""

import math
import warnings

import numpy as np
import pandas as pd
import pytest

from bayes_roadload import config
from bayes_roadload.analysis import effects as fx
from bayes_roadload.analysis.batch import run_batch
from bayes_roadload.analysis.diagnose import diagnose
from bayes_roadload.analysis.pooling import CombinedCampaign
from bayes_roadload.data import Campaign, Vehicle
from studies.proof_suite import DiagnoseJob, Distorted, proof_design, withheld_campaign



@pytest.mark.slow
def test_null_controls_and_a_confounded_effect_through_the_batch_door():
    jobs = []
    for effect, seed in ((None, 1001), (None, 1002), ("aero_lift", 1), ("mass_error", 1)):
        factory, model = withheld_campaign(effect, seed, pairs=3)
        jobs.append(DiagnoseJob(f"{effect}-{seed}", factory, model, tags={"true_effect": str(effect)}))
    rec = run_batch(jobs).set_index("name")
    assert rec["error"].isna().all()
    # nulls: nothing may be claimed at the stated threshold
    assert (rec.loc[["None-1001", "None-1002"], "top"] == "none").all()
    # lift unloading looks like a C_D0 change, an effective-mass error like a rescaling of the
    # coefficients: neither may be claimed as another effect
    for name, effect in (("aero_lift-1", "aero_lift"), ("mass_error-1", "mass_error")):
        assert rec.loc[name, "top"] in ("none", effect)


def test_the_identifying_design_is_the_library_table():
    plan = proof_design("identifying")
    assert proof_design("standard") == {}
    factory, model = withheld_campaign("side_force_slip", seed=3, design="identifying")
    assert model == "three_term" and isinstance(factory, CombinedCampaign)
    parts = factory.parts
    # the pairs split over the start speeds, every part at the design's masses and winds
    assert sum(p.pairs for p in parts) == plan["pairs"]
    assert [p.settings.start_speed_mps for p in parts] == plan["start_speeds_mps"]
    assert all(p.masses_kg == tuple(plan["masses_kg"]) for p in parts)
    assert all(p.case.cross_wind_mps == plan["cross_wind_mps"] for p in parts)
    assert len({p.seed for p in parts}) == len(parts)
    # the effect at its size factor times the plausible size of the standard design
    std, _ = withheld_campaign("side_force_slip", seed=3)
    ratio = parts[0].settings.extra_params["side_slip_coeff_per_n"] / std.settings.extra_params["side_slip_coeff_per_n"]
    assert ratio == pytest.approx(plan["size_factor"]["side_force_slip"])
    mass, _ = withheld_campaign("mass_error", seed=3, design="identifying")
    assert isinstance(mass, Distorted) and mass.effective_mass_factor == pytest.approx(1.03)


def test_proof_design_refuses_unknown_keys_and_effects(tmp_path):
    bad = tmp_path / "lib.toml"
    bad.write_text("[proof.identifying]\npairs = 4\nsun_angle_deg = 3\n")
    with pytest.raises(ValueError, match="sun_angle_deg"):
        proof_design("identifying", bad)
    bad.write_text("[proof.identifying.size_factor]\nwarp_drive = 2\n")
    with pytest.raises(ValueError, match="warp_drive"):
        proof_design("identifying", bad)
    with pytest.raises(ValueError, match="unknown proof design"):
        proof_design("lavish")


def test_a_distorted_yaw_reading_ends_the_run_at_the_logged_limit():
    t = np.arange(0.0, 10.0, 0.25)
    yaw = np.linspace(0.0, 1.45, t.size)          # within the limit as logged
    runs = pd.DataFrame({"run": np.repeat([1, 2], t.size), "time_s": np.tile(t, 2),
                         "speed_mps": np.tile(30.0 - t, 2), "direction": np.repeat([1, -1], t.size),
                         "airspeed_mps": np.tile(31.0 - t, 2), "yaw_rad": np.concatenate([yaw, -yaw / 2])})
    c = Campaign(runs, Vehicle(mass_kg=1100.0, effective_mass_kg=1130.0, frontal_area_m2=1.85))
    d = Distorted(lambda: c, yaw_factor=0.869)()
    r1 = d.runs[d.runs["run"] == 1]
    # true = 0.869 x reading: readings grow by 1 / 0.869 and run 1 stops before the limit
    assert r1["yaw_rad"].abs().max() <= config.MAX_LOGGED_YAW_RAD
    assert len(r1) == int(np.sum(yaw / 0.869 <= config.MAX_LOGGED_YAW_RAD))
    assert len(d.runs[d.runs["run"] == 2]) == t.size

def test_the_independent_design_injects_one_effect_at_its_stated_size():
    """The ``independent`` design: the independent simulator with the base effects, one
    injection per candidate drawn inside its stated range, what the campaign must not state
    stripped, nulls with nothing injected; the factories pickle (the batch door)."""
    import pickle

    from studies.proof_suite import (INDEPENDENT_BASE_EFFECTS, INDEPENDENT_EFFECTS, INDEPENDENT_INJECTIONS,
                                     IndependentWithheld, design_effects, independent_withheld_campaign,
                                     withheld_effect_jobs)
    assert set(design_effects("independent")) == set(INDEPENDENT_EFFECTS) == set(INDEPENDENT_INJECTIONS)
    from bayes_roadload.analysis.effects import EFFECT_NAMES, load_library
    assert set(INDEPENDENT_EFFECTS) <= set(EFFECT_NAMES) and "aero_admittance" in INDEPENDENT_EFFECTS
    # the same-formula designs inject every effect once: a form of another's effect has no arm of its own
    forms = {n for n, e in load_library().items() if e.cause != n}
    assert forms and set(design_effects("standard")) == set(EFFECT_NAMES) - {"aero_admittance"} - forms
    for seed in range(1, 7):
        mass = IndependentWithheld("mass_error", seed).arm()
        rel = mass["errors"]["mass_kg"] / mass["vehicle"].mass_kg
        assert 0.015 <= abs(rel) <= 0.03
        air = IndependentWithheld("airspeed_calibration", seed).arm()["errors"]["airspeed_factor_rel"]
        assert 0.015 <= abs(air) <= 0.04
        yaw = IndependentWithheld("yaw_calibration", seed).arm()["errors"]
        assert math.radians(1) <= abs(yaw["yaw_offset_rad"]) <= math.radians(3) and 0.05 <= abs(yaw["yaw_factor_rel"]) <= 0.13
        grade = IndependentWithheld("track_gradient", seed).arm()["errors"]["track_mean_grade"]
        assert 0.0002 <= abs(grade) <= 0.001
        assert 0.02 <= IndependentWithheld("run_to_run_variation", seed).arm()["run_to_run_sd"] <= 0.045
    # the same seed draws the same vehicle in every arm (a null is the arm's control)
    assert IndependentWithheld(None, 4).arm()["vehicle"] == IndependentWithheld("aero_lift", 4).arm()["vehicle"]
    lift, model = independent_withheld_campaign("aero_lift", 2, pairs=1)
    assert model == "three_term"
    c = pickle.loads(pickle.dumps(lift))()
    assert "lift" in c.truth["meta"]["effects"] and not {"CL0", "KL"} & set(c.tunnel)
    assert c.truth["injected"]["effect"] == "aero_lift"
    cup = independent_withheld_campaign("anemometer_dynamics", 2, pairs=1)[0]()
    assert cup.truth["meta"]["anemometer_dynamics"]["distance_constant_m"] >= 1.5
    assert cup.anemometer.distance_constant_m == 0.0
    null = independent_withheld_campaign(None, 2, pairs=1)[0]()
    assert set(null.truth["meta"]["effects"]) == set(INDEPENDENT_BASE_EFFECTS)
    lead = independent_withheld_campaign("aero_admittance", 2, pairs=1)[0]()
    assert {"admittance", "anemometer_position"} <= set(lead.truth["meta"]["effects"])
    assert all(v == 0.0 for v in null.truth["meta"]["type_b_errors"].values())
    assert null.truth["meta"]["run_to_run_sd"] == 0.0
    with pytest.raises(ValueError, match="no injection"):
        independent_withheld_campaign("driveline_quadratic", 1)
    jobs = withheld_effect_jobs(seeds=(5,), pairs=2, nulls=2, design="independent", null_seed0=3000,
                                tags={"phase": "design"})
    assert [j.name for j in jobs] == [f"{e}-s5" for e in INDEPENDENT_EFFECTS] + ["null-s3000", "null-s3001"]
    assert all(j.tags["phase"] == "design" and j.tags["pairs"] == 2 for j in jobs)


@pytest.mark.slow  # one seed's diagnosis outcome: a study result, ~30 s
def test_a_lead_of_the_reading_is_the_admittance_not_a_cup_lag():
    """The independent simulator's body feels the wind through its admittance and the
    anemometer samples the air ahead of the nose: the reading leads the force.  The admittance
    candidate, a family over the filter's length, fits a positive gain and carries the
    likelihood; the cup-lag candidate's rate term, whose physical distance is positive, fits a
    negative one, is scored at its null (delta_elpd = -1 parameter) and says why."""
    from studies.proof_suite import independent_withheld_campaign

    factory, model = independent_withheld_campaign("aero_admittance", 3, pairs=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = diagnose(factory(), model)
    by = {c["effect"]: c for c in d.candidates}
    cup, adm = by["anemometer_dynamics"], by["aero_admittance"]
    assert adm["estimates"]["admittance_gain"] > 0.0 and not adm["against_sign"]
    assert adm["shape"]["values"]["admittance_length_m"] in fx.load_library()["aero_admittance"].shape["admittance_length_m"]
    assert cup["against_sign"] and cup["against_sign"]["cup_lag_m"] < 0.0
    assert cup["delta_elpd"] == -1.0 and not cup["supported"] and "sign" in cup["statement"]
    assert adm["delta_elpd"] >= config.DEFAULT_DIAGNOSIS.support_delta_elpd


@pytest.mark.slow
def test_a_yaw_reading_that_misses_the_gusts_claims_no_vane_factor():
    """Null 2001 of the independent design: a heavy truck logged at 1 Hz in gusty 2 m/s wind,
    no injected effect.  Under the rules before ``min_input_lag1`` it claimed a vane factor
    (delta_elpd 25.3; docs/sim_to_real/earlier_rules).  Its yaw reading's gusts change from one
    sample to the next (lag-1 autocorrelation under the threshold), so the yaw-term candidates
    are not identifiable here and nothing is claimed."""
    from studies.proof_suite import IndependentWithheld

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = diagnose(IndependentWithheld(None, 2001, 6)(), "three_term")
    yaw_in = d.result["inputs"]["yaw_rad"]
    assert yaw_in["sample_rate_hz"] == pytest.approx(1.0)
    assert yaw_in["lag1_autocorr"] < config.DEFAULT_DIAGNOSIS.min_input_lag1
    vane = next(c for c in d.candidates if c["effect"] == "yaw_calibration")
    assert not vane["identifiable"] and "does not resolve" in vane["statement"]
    assert d.top is None


def test_the_same_formula_designs_refuse_an_effect_they_have_no_arm_for():
    """aero_admittance has no arm of its own in the project's simulator: asking for it is a
    clear error, not a campaign without the effect."""
    from studies.proof_suite import withheld_campaign

    with pytest.raises(ValueError, match="anemometer_dynamics arm"):
        withheld_campaign("aero_admittance", 1, design="standard")
