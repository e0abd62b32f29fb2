"""The thesis' planning tables (studies/thesis_tables.py) and their replay (studies/planning_report.py)."""

import math

import pandas as pd
from scipy import stats

from studies.planning_report import planning_markdown
from studies.thesis_tables import THESIS_PLAN_PAIRS, THESIS_PLAN_TABLES, THESIS_TARGETS_PCT


def test_the_transcribed_tables_follow_the_thesis_formula():
    """Every published half-width is z s / sqrt(n) of its table's spread, as printed: the
    tables give 2-3 significant figures, so the transcription agrees to half a unit in the last
    printed digit (at most 0.05 absolute on the largest entries, 5 % relative on the
    smallest two-figure ones) -- a mistyped digit is off by far more."""
    z = stats.norm.ppf(0.975)
    for table, spec in THESIS_PLAN_TABLES.items():
        for q, published in spec["published"].items():
            assert len(published) == len(THESIS_PLAN_PAIRS), (table, q)
            assert q in THESIS_TARGETS_PCT
            s = spec["spreads_pct"][q]
            for n, pub in zip(THESIS_PLAN_PAIRS, published):
                formula = z * s / math.sqrt(n)
                assert abs(pub - formula) <= max(0.05, 0.05 * formula), (table, q, n, pub, formula)


def test_the_report_writes_the_thesis_section_from_its_table():
    th = pd.DataFrame([{"table": "8.6 (3-term)", "quantity": "AD", "spread_pct": 4.3, "n_pairs": n,
                        "published": 8.5 / math.sqrt(n), "z_formula": 8.43 / math.sqrt(n),
                        "median_half_width": 9.0 / math.sqrt(n), "q10_half_width": 6.0 / math.sqrt(n),
                        "q90_half_width": 14.0 / math.sqrt(n), "assurance_at_published": 0.3,
                        "target_pct": 1.0, "thesis_n_for_target": 72, "n_for_target": 104} for n in (2, 6)])
    md = "\n".join(planning_markdown({"thesis": th}))
    assert "### Table 8.6 (3-term)" in md
    assert "| 8.6 (3-term) | AD | 4.3 | 1 | 72 | 104 |" in md
    # sections whose frames are missing are skipped
    assert "## 2." not in md and "## 3." not in md

