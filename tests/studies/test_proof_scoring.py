"""Scoring of the proof suite's records (``studies.proof_scoring``): the outcome of a campaign,
the visibility of its true effect, and the summary's invariants on every committed record."""

from pathlib import Path

import pandas as pd
import pytest

from bayes_roadload import config
from studies.proof_scoring import CAUSES, outcome, read_records, summarise, true_distinct, true_rank, true_visible

RECORDS = Path(__file__).resolve().parents[2] / "docs" / "sim_to_real"
THRESHOLD = config.DEFAULT_DIAGNOSIS.support_delta_elpd


def _row(**kw) -> pd.Series:
    base = {"true_effect": "track_gradient", "top": "none", "supported": "", "not_identifiable": "",
            "not_distinguishable": "", "error": None}
    return pd.Series({**base, **kw})


@pytest.mark.parametrize("gain, visible", [(THRESHOLD, True), (THRESHOLD - 1e-9, False), (float("nan"), False),
                                           (10 * THRESHOLD, True)])
def test_an_effect_is_visible_when_its_own_candidate_reaches_the_support_threshold(gain, visible):
    assert true_visible(_row(delta_elpd_track_gradient=gain)) is visible


def test_a_missing_score_is_not_visible():
    assert true_visible(_row()) is False


MARGIN = config.DEFAULT_DIAGNOSIS.ambiguity_margin


@pytest.mark.parametrize("rival, distinct", [(None, True), (20.0 - MARGIN, True), (20.0 - MARGIN + 1e-9, False),
                                             (25.0, False)])
def test_an_effect_is_distinct_when_it_leads_every_rival_by_the_margin(rival, distinct):
    """Visible at 20 and ahead of the rival by at least the ambiguity margin; a rival within it,
    or ahead, leaves nothing any rule with that margin could claim."""
    row = _row(delta_elpd_track_gradient=20.0, **({} if rival is None else {"delta_elpd_spatial_wind": rival}))
    assert true_distinct(row) is distinct
    assert true_distinct(_row(delta_elpd_track_gradient=THRESHOLD - 1e-9)) is False  # not visible


def test_every_claim_of_the_committed_records_was_of_a_distinct_effect():
    """The rules claim nothing within the margin of a rival, so every correct claim of every
    committed records file (earlier rules included) is of a distinct effect, campaign by
    campaign, and the distinct share bounds the claimed share."""
    for path in _committed():
        records = read_records(path)
        ok = records[records["error"].isna()]
        claimed = ok[(ok["true_effect"] != "null") & (ok.apply(outcome, axis=1) == "correct")]
        assert claimed.apply(true_distinct, axis=1).all(), path.name
        s = summarise(records)
        assert s["true_first"] <= s["true_distinct"] <= s["true_visible"], path.name


@pytest.mark.parametrize("kw, expected", [
    (dict(top="track_gradient"), "correct"),
    (dict(top="spatial_wind"), "wrong"),
    (dict(not_identifiable="track_gradient"), "flagged"),
    (dict(not_distinguishable="spatial_wind,track_gradient"), "indistinct"),
    (dict(), "none"),
    (dict(true_effect="null"), "correct"),
    (dict(true_effect="null", top="yaw_calibration"), "wrong"),
])
def test_outcomes(kw, expected):
    assert outcome(_row(**kw)) == expected


FORM = next(name for name, cause in CAUSES.items() if cause != name)  # a candidate that is a form of another


@pytest.mark.parametrize("kw, expected", [
    (dict(top=FORM), "correct"),
    (dict(not_distinguishable=f"spatial_wind,{FORM}"), "indistinct"),
    (dict(not_identifiable=FORM), "flagged"),
])
def test_a_form_of_the_true_effect_counts_as_the_effect(kw, expected):
    assert outcome(_row(**{"true_effect": CAUSES[FORM], **kw})) == expected
    assert outcome(_row(**{"true_effect": "track_gradient", **kw})) in ("wrong", "none")


def test_the_true_effects_rank_and_gain_are_its_best_forms_against_the_other_effects():
    cause = CAUSES[FORM]
    row = _row(true_effect=cause, **{f"delta_elpd_{cause}": -1.0, f"delta_elpd_{FORM}": 30.0,
                                     "delta_elpd_track_gradient": 20.0, "delta_elpd_spatial_wind": 40.0})
    assert true_visible(row) and true_rank(row) == 2.0
    assert true_rank(row.drop("delta_elpd_spatial_wind")) == 1.0


def _committed() -> list[Path]:
    return sorted(RECORDS.glob("records_*.csv")) + sorted((RECORDS / "earlier_rules").glob("records_*.csv"))


@pytest.mark.parametrize("path", _committed(), ids=lambda p: p.name)
def test_a_claim_needs_a_visible_effect_in_every_committed_record(path):
    """Claimed (ranked first and supported) implies the true candidate's own delta_elpd reached
    the support threshold: the share of visible campaigns bounds the share claimed."""
    rec = read_records(path)
    ok = rec[rec["error"].isna() & (rec["true_effect"] != "null")]
    claimed = ok[ok.apply(outcome, axis=1) == "correct"]
    assert claimed.apply(true_visible, axis=1).all()
    s = summarise(rec)
    assert s["true_first"] <= s["true_visible"] <= s["effect_campaigns"]
    assert s["true_first"] <= s["true_ranked_first"]
