"""Published results of Passmore (1990) that the studies compare with and the package does not use.

The planning tables of chapter 8 (:data:`THESIS_PLAN_TABLES`, replayed by
:func:`studies.planning_report.thesis_replay_table`) and two figures of chapter 7.  Values the
package itself prints or simulates from are in :mod:`bayes_roadload.thesis`.
"""

from __future__ import annotations

from typing import Any

THESIS_PLAN_PAIRS = (1, 2, 3, 4, 5, 6, 12, 24, 48, 96)
"""Numbers of tests (pairs) of the thesis' tables 8.6, 8.8 and 8.10."""

THESIS_PLAN_TABLES: dict[str, dict[str, Any]] = {
    "8.6 (3-term)": {
        "spreads_pct": {"AD": 4.3, "BD": 23.1, "CD0": 4.3, "F50_N": 0.40},  # table 8.3
        "published": {"AD": (8.5, 6.0, 4.9, 4.2, 3.8, 3.5, 2.4, 1.7, 1.2, 0.9),
                      "BD": (45.3, 32.0, 26.1, 22.6, 20.2, 18.5, 13.1, 9.2, 6.5, 4.6),
                      "CD0": (8.5, 6.0, 4.9, 4.2, 3.8, 3.5, 2.4, 1.7, 1.2, 0.9),
                      "F50_N": (0.79, 0.56, 0.45, 0.39, 0.35, 0.32, 0.22, 0.16, 0.11, 0.08)}},
    "8.8 (2-term, CD0 = 0.39)": {
        "spreads_pct": {"AD": 1.97, "BD": 3.77, "F50_tyre_N": 1.24},  # table 8.7
        "published": {"AD": (3.8, 2.7, 2.2, 1.9, 1.7, 1.6, 1.1, 0.78, 0.55, 0.39),
                      "BD": (7.4, 5.2, 4.3, 3.7, 3.3, 3.0, 2.1, 1.5, 1.1, 0.75),
                      "F50_tyre_N": (2.4, 1.7, 1.4, 1.2, 1.1, 1.0, 0.70, 0.50, 0.35, 0.25)}},
    "8.10 (4-term)": {
        "spreads_pct": {"AD": 3.2, "BD": 15.2, "CD0": 3.1, "F50_N": 0.48},  # table 8.9
        "published": {"AD": (6.4, 4.5, 3.7, 3.2, 2.8, 2.6, 1.8, 1.3, 0.92, 0.65),
                      "BD": (29.8, 21.1, 17.2, 14.9, 13.3, 12.2, 8.6, 6.1, 4.3, 3.0),
                      "CD0": (6.0, 4.3, 3.5, 3.0, 2.7, 2.5, 1.7, 1.2, 0.87, 0.62),
                      "F50_N": (0.94, 0.67, 0.56, 0.47, 0.42, 0.39, 0.27, 0.19, 0.14, 0.10)}},
}
"""The thesis' planning tables (95 % half-widths in % of the mean against the number of tests,
from z s / sqrt(n) with the between-pair spreads s of 18 pairs) and those spreads (tables 8.3,
8.7, 8.9).  Table 8.8's 3-term tyre-drag column is left out (its spread is not tabulated)."""

THESIS_PILOT_PAIRS = 18
THESIS_TARGETS_PCT = {"AD": 1.0, "BD": 5.0, "CD0": 1.0, "F50_N": 1.0, "F50_tyre_N": 1.0}
"""The accuracies the thesis plans for (section 8.2-8.4)."""

THESIS_DRIVELINE_OFF_LOAD_LOW_WIND = {"At": 17.03, "Bt": 1.59}
"""Off-load (coastdown) driveline loss of the initial study's low-wind coastdowns, thesis table 7.8."""
THESIS_STEADY_F50_DIFFERENCE_PCT = 4.5
"""Total drag at 50 mph, steady state above coastdown (thesis section 7.7; not in table 7.11)."""
