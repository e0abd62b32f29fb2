"""Scoring of the sim-to-real proof suite's records (one row per diagnosed campaign, as
:class:`studies.proof_suite.DiagnoseJob` writes them): each campaign's outcome, the true effect's
rank and visibility, the summary figures and the confusion matrices that
``benchmarks/sim_to_real_study.py`` reports in ``docs/sim_to_real.md``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from bayes_roadload import config
from bayes_roadload.analysis import effects as fx
from bayes_roadload.analysis.effects import EFFECT_NAMES

CAUSES = fx.causes(fx.load_library())
"""Candidate -> the physical effect it stands for, from the shipped library (``cause``): a
claim of any form of the injected effect names it.  Candidates of earlier libraries are their
own cause."""


def cause_of(name: str) -> str:
    """The effect candidate ``name`` stands for (:data:`CAUSES`; itself when not a form)."""
    return CAUSES.get(name, name)


def _forms(effect: str) -> list[str]:
    """The candidates that stand for ``effect`` (its own first)."""
    return [effect] + [n for n in EFFECT_NAMES if n != effect and cause_of(n) == effect]


def read_records(path: Path) -> pd.DataFrame:
    """A records file of the proof suite, its claim columns as strings ("" when empty)."""
    records = pd.read_csv(path, keep_default_na=False, na_values=[""])  # "null" is an arm, not NaN
    for col in ("supported", "not_identifiable", "not_distinguishable", "refit_effects"):
        if col not in records:
            records[col] = ""
        records[col] = records[col].fillna("")
    return records


def outcome(row) -> str:
    """``correct`` (a form of the true effect ranked first and supported), ``flagged`` (nothing
    claimed and the true effect reported not identifiable here), ``indistinct`` (nothing claimed
    and the true effect among the candidates reported not distinguishable here), ``none``
    (nothing claimed), ``wrong`` (another effect claimed).  Candidates count by their cause
    (:func:`cause_of`)."""
    truth, top = row["true_effect"], row["top"]
    if truth == "null":
        return "correct" if top == "none" else "wrong"
    if cause_of(top) == truth:
        return "correct"
    if top == "none":
        if truth in {cause_of(c) for c in str(row.get("not_distinguishable") or "").split(",")}:
            return "indistinct"
        flagged = {cause_of(c) for c in str(row.get("not_identifiable") or "").split(",")}
        return "flagged" if truth in flagged else "none"
    return "wrong"


def _scores(row) -> dict[str, float]:
    return {e: float(row.get(f"delta_elpd_{e}", float("nan"))) for e in EFFECT_NAMES}


def true_gain(row) -> float:
    """The true effect's own delta_elpd, the best of its forms' (NaN for nulls and when none
    was scored)."""
    truth = row["true_effect"]
    if truth == "null":
        return float("nan")
    values = [v for e, v in _scores(row).items() if e in _forms(truth) and np.isfinite(v)]
    return max(values) if values else float("nan")


def true_rank(row) -> float:
    """Rank of the true effect (its best form) among the other effects' candidates by
    delta_elpd alone (1 = best), claimed or not; NaN for nulls."""
    mine = true_gain(row)
    if not np.isfinite(mine):
        return float("nan")
    return 1.0 + sum(1 for e, v in _scores(row).items()
                     if cause_of(e) != row["true_effect"] and np.isfinite(v) and v > mine)


def true_visible(row) -> bool:
    """Whether the true effect's own candidate gains the support threshold
    (``delta_elpd >= DiagnosisConfig.support_delta_elpd``): without it no rule on this library
    could claim the effect, so the share of visible campaigns bounds the share claimed."""
    value = true_gain(row)
    return bool(np.isfinite(value) and value >= config.DEFAULT_DIAGNOSIS.support_delta_elpd)


def close_rivals(row) -> list[str]:
    """The other effects' candidates whose delta_elpd comes within
    ``DiagnosisConfig.ambiguity_margin`` of the true effect's best form, or beats it."""
    mine = true_gain(row)
    margin = config.DEFAULT_DIAGNOSIS.ambiguity_margin
    return [e for e, v in _scores(row).items()
            if cause_of(e) != row["true_effect"] and np.isfinite(v) and v > mine - margin]


def true_distinct(row) -> bool:
    """Whether the true effect is visible (:func:`true_visible`) and its best form's delta_elpd
    exceeds every other effect's candidate by ``DiagnosisConfig.ambiguity_margin`` (no
    :func:`close_rivals`): the rules claim nothing within that margin of a rival, so the share
    of such campaigns bounds the share any rule with this margin could claim, however the other
    tests are set."""
    return true_visible(row) and not close_rivals(row)


def rank_one(row) -> str:
    """The candidate at rank 1 of ``diagnosis.json``: the supported top, else the best by
    delta_elpd (supported or not); "none" when no candidate was scored."""
    if row["top"] != "none":
        return str(row["top"])
    scores = {e: v for e, v in _scores(row).items() if np.isfinite(v)}
    return max(scores, key=scores.get) if scores else "none"


def median_of(rows: pd.DataFrame, column: str) -> float | None:
    """Median of a column over rows that have it (records written before it existed lack it)."""
    if column not in rows:
        return None
    vals = pd.to_numeric(rows[column], errors="coerce").dropna()
    return float(vals.median()) if len(vals) else None


def summarise(records: pd.DataFrame) -> dict:
    ok = records[records["error"].isna()].copy()
    ok["outcome"] = ok.apply(outcome, axis=1)
    ok["true_rank"] = ok.apply(true_rank, axis=1)
    effects = ok[ok["true_effect"] != "null"]
    nulls = ok[ok["true_effect"] == "null"]
    shrink = effects.loc[effects["outcome"] == "correct", "shrink_trend_rms_mps"].astype(float)
    visible = effects.apply(true_visible, axis=1) if len(effects) else pd.Series(dtype=bool)
    distinct = effects.apply(true_distinct, axis=1) if len(effects) else pd.Series(dtype=bool)
    first = (effects.apply(lambda r: cause_of(rank_one(r)), axis=1) == effects["true_effect"]) if len(effects) \
        else pd.Series(dtype=bool)
    return {
        "campaigns": int(len(ok)), "failed": int(len(records) - len(ok)),
        "effect_campaigns": int(len(effects)),
        "true_ranked_first": int(first.sum()),
        "true_ranked_first_pct": 100.0 * float(first.mean()) if len(effects) else None,
        "true_first": int((effects["outcome"] == "correct").sum()),
        "true_first_pct": 100.0 * float((effects["outcome"] == "correct").mean()) if len(effects) else None,
        "true_top_by_delta_elpd": int((effects["true_rank"] == 1).sum()),
        "true_visible": int(visible.sum()),
        "true_visible_pct": 100.0 * float(visible.mean()) if len(effects) else None,
        "true_distinct": int(distinct.sum()),
        "true_distinct_pct": 100.0 * float(distinct.mean()) if len(effects) else None,
        "true_first_pct_of_visible": 100.0 * float((effects.loc[visible, "outcome"] == "correct").mean())
        if visible.any() else None,
        "flagged_not_identifiable": int((effects["outcome"] == "flagged").sum()),
        "not_distinguishable": int((effects["outcome"] == "indistinct").sum()),
        "nothing_claimed": int((effects["outcome"] == "none").sum()),
        "wrong_claim": int((effects["outcome"] == "wrong").sum()),
        "extra_claims": int(sum(1 for _, r in effects.iterrows()
                                if {cause_of(c) for c in filter(None, str(r["supported"]).split(","))}
                                - {r["true_effect"]})),
        "null_campaigns": int(len(nulls)), "null_false_claims": int((nulls["top"] != "none").sum()),
        "median_trend_shrink_pct_when_correct": float(shrink.median()) if len(shrink) else None,
        **{f"median_spread_excess_{arm}": median_of(arm_rows, "before_spread_excess")
           for arm, arm_rows in (("nulls", nulls), ("run_to_run", effects[effects["true_effect"] == "run_to_run_variation"]),
                                 ("other_effects", effects[effects["true_effect"] != "run_to_run_variation"]))},
        "median_spread_excess_after_refit_when_correct": median_of(effects[effects["outcome"] == "correct"],
                                                                   "after_spread_excess"),
        "median_time_per_campaign_s": float(ok["time_total_s"].median()) if len(ok) else None,
    }


def confusion(records: pd.DataFrame, by: str = "top") -> pd.DataFrame:
    """True effect (rows) against the top-ranked supported effect (``by="top"``, "none" when
    nothing is claimed) or against the rank-1 candidate of diagnosis.json (``by="rank_one"``)."""
    ok = records[records["error"].isna()].copy()
    if by == "rank_one":
        ok["rank_one"] = ok.apply(rank_one, axis=1) if len(ok) else []
    cols = list(EFFECT_NAMES) + ["none"]
    table = pd.crosstab(ok["true_effect"], ok[by]).reindex(columns=cols, fill_value=0)
    order = [e for e in list(EFFECT_NAMES) + ["null"] if e in table.index]
    return table.reindex(order)
