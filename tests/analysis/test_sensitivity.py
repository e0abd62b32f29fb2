"""Tests of the coefficient sensitivity study (thesis section 6.3, tables 6.1 and 6.2)."""

from __future__ import annotations

import numpy as np
import pytest

from bayes_roadload.analysis import (
    PUBLISHED_KD_SENSITIVITY_MPS,
    PUBLISHED_SENSITIVITY_MPS,
    coefficient_sensitivity,
    compare_with_thesis,
    format_sensitivity_table,
)

CROSS = (0.0, 1.0, 2.0, 3.0)


@pytest.fixture(scope="module")
def table():
    return coefficient_sensitivity(cross_winds_mps=CROSS, head_winds_mps=(0.0, 2.0))


def _value(df, parameter, cross, head=0.0, side="above"):
    row = df[(df.parameter == parameter) & (df.cross_wind_mps == cross) & (df.head_wind_mps == head)]
    assert len(row) == 1
    return float(row[f"sensitivity_{side}_mps"].iloc[0])


def test_columns(table):
    assert list(table.columns) == ["parameter", "cross_wind_mps", "head_wind_mps", "sensitivity_above_mps",
                                   "sensitivity_below_mps", "normalised"]
    assert len(table) == 4 * len(CROSS) * 2
    assert table["normalised"].max() == pytest.approx(1.0)


def test_ordering_cd0_ad_bd_kd(table):
    # Table 6.1/6.2: C_D0 is the easiest coefficient to determine, then A_D, B_D; K_D is far
    # behind: > 10x below B_D up to 2 m/s cross-wind, > 5x at 3 m/s.  (The thesis' own
    # tables give B_D / K_D = 0.012 / 0.0015 = 8 at 3 m/s, so "10x" cannot hold there; ours
    # is 6.0x: our K_D sensitivity is 1.4x the published, see the next test.)
    for cross in CROSS:
        for head in (0.0, 2.0):
            for side in ("above", "below"):
                s = {p: _value(table, p, cross, head, side) for p in ("AD", "BD", "CD0", "KD")}
                ratio = 10.0 if cross <= 2.0 else 5.0
                assert s["CD0"] > s["AD"] > s["BD"] > ratio * s["KD"], (cross, head, s)


def test_kd_needs_cross_wind(table):
    for head in (0.0, 2.0):
        kd = [_value(table, "KD", x, head) for x in CROSS]
        assert kd[0] < 1e-9  # zero yaw: K_D psi^2 vanishes
        assert all(b > a for a, b in zip(kd, kd[1:])), kd


def test_tyre_and_cd0_sensitivities_barely_depend_on_the_wind(table):
    # "virtually independent of the level of wind input" (thesis section 6.3)
    for p in ("AD", "BD", "CD0"):
        values = [_value(table, p, x, h) for x in CROSS for h in (0.0, 2.0)]
        assert np.ptp(values) < 0.2 * np.mean(values), (p, values)


def test_close_to_the_published_values(table):
    # Within a factor 2 of tables 6.1 / 6.2 (measured: AD 0.035, BD 0.012, CD0 0.051 m/s;
    # KD 0.0002 / 0.0009 / 0.0021 m/s at 1 / 2 / 3 m/s).  They need not agree exactly: the
    # transcript does not give the run length or end speed, and the thesis' "RMS error" may
    # come from its optimiser with the other coefficients re-fitted (its C_D0 0.04 above /
    # 0.07 below nominal is asymmetric, which a 1 % perturbation of the trace is not: ours
    # differ by < 2 %).
    cmp = compare_with_thesis(table[table.head_wind_mps == 0.0])
    published = cmp[cmp.published_above_mps > 0]
    assert len(published) == 3 * len(CROSS) + 3  # AD, BD, CD0 at each wind; KD at 1, 2, 3 m/s
    for col in ("ratio_above", "ratio_below"):
        assert published[col].between(0.5, 2.0).all(), published[["parameter", "cross_wind_mps", col]]
    assert (table.sensitivity_above_mps - table.sensitivity_below_mps).abs().max() < 0.02 * table[
        ["sensitivity_above_mps", "sensitivity_below_mps"]].max().max()
    assert PUBLISHED_SENSITIVITY_MPS["CD0"] == {"above": 0.04, "below": 0.07}
    assert PUBLISHED_KD_SENSITIVITY_MPS == {0.0: 0.0, 1.0: 0.0002, 2.0: 0.0007, 3.0: 0.0015}
    text = format_sensitivity_table(table)
    assert "published_above_mps" in text and "CD0" in text


def test_unknown_coefficient():
    with pytest.raises(ValueError, match="unknown coefficient"):
        coefficient_sensitivity(coefficients=("XD",))
