"""benchmarks/ablation_compare.py: an ablation's records read beside the full study's."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.analysis.calibration import QUANTITIES

from .conftest import benchmark_script


def _records(names, yaw, z, held):
    """Records with every quantity at truth 1, sd 0.1 and mean 1 + 0.1 z (so its z is z)."""
    rec = {"name": names, "mean_abs_yaw_rad": yaw, "error": [np.nan] * len(names)}
    for q in QUANTITIES:
        rec[f"{q}_truth"] = np.ones(len(names))
        rec[f"{q}_sd"] = np.full(len(names), 0.1)
        rec[f"{q}_mean"] = 1.0 + 0.1 * np.asarray(z, float)
        rec[f"{q}_in95"] = held
    return pd.DataFrame(rec)


def test_the_common_campaigns_are_compared_with_the_full_studys_yaw_halves():
    with benchmark_script("ablation_compare") as m:
        full = _records(["a", "b", "c", "d", "e"], [0.05, 0.10, 0.20, 0.30, 0.9], [0.0, 1.0, 2.0, 3.0, 9.0],
                        [True, True, False, False, True])
        # the ablation lacks "e" and saw other yaws: the halves are the full study's on a-d
        ablated = _records(["d", "c", "b", "a"], [0.3, 0.3, 0.0, 0.0], [-1.0, 0.5, 0.0, 0.5],
                           [True, True, True, False])
        table, names = m.compare(full, ablated)
        assert names == ["a", "b", "c", "d"]
        row = table.set_index("quantity").loc["KD"]
        assert row["all effects: held"] == 2 and row["ablated: held"] == 3
        assert row["all effects: mean z"] == pytest.approx(1.5)
        assert row["all effects: mean z gusty"] == pytest.approx(2.5)  # c, d: yaw above the median 0.15
        assert row["all effects: mean z calm"] == pytest.approx(0.5)
        assert row["ablated: mean z gusty"] == pytest.approx(-0.25)  # c 0.5, d -1.0
        assert row["ablated: mean z calm"] == pytest.approx(0.25)
        text = m.markdown(table, len(names), "no quartic")
        assert "| KD | 2, +1.50 (+2.50 / +0.50) | 3, +0.00 (-0.25 / +0.25) |" in text
        assert f"| all | {2 * len(QUANTITIES)} of {4 * len(QUANTITIES)} | {3 * len(QUANTITIES)} of" in text
