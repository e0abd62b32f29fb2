"""EEC and GTR 15 precision criteria."""

import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from bayes_roadload.analysis.regulation import GTR_PRECISION_PCT, _band_time, coastdown_times, gtr15_precision, pairs_needed
from bayes_roadload.data.campaign import Campaign, Vehicle


def _linear_run(run, pair, decel, v0=30.0, dt=0.5):
    t = np.arange(0.0, (v0 - 4.0) / decel, dt)
    return pd.DataFrame({"run": run, "pair": pair, "time_s": t, "speed_mps": v0 - decel * t})


def _campaign(decels):
    runs = pd.concat([_linear_run(i + 1, i // 2 + 1, d) for i, d in enumerate(decels)], ignore_index=True)
    return Campaign(runs, Vehicle(mass_kg=1500.0, frontal_area_m2=2.0, effective_mass_kg=1540.0))


def test_band_time_is_exact_for_constant_deceleration():
    t = np.arange(0.0, 50.0, 0.1)
    v = 30.0 - 0.5 * t
    assert _band_time(t, v, 20.0, 10.0) == pytest.approx(20.0, abs=1e-9)
    assert math.isnan(_band_time(t, v, 40.0, 10.0))  # started below the upper speed


def test_gtr_precision_follows_the_formula():
    """Pairs of runs decelerating at 0.50/0.52, 0.49/0.51, 0.50/0.50 m/s^2: the band time is
    (10 km/h) / a, a pair's time the harmonic mean, p = t(0.975, n-1) s / (sqrt n mean)."""
    decels = [0.50, 0.52, 0.49, 0.51, 0.50, 0.50]
    c = _campaign(decels)
    times = coastdown_times(c, speeds_kph=(50.0,))
    np.testing.assert_allclose(times[50.0], (10.0 / 3.6) / np.asarray(decels), rtol=1e-9)
    row = gtr15_precision(c, speeds_kph=(50.0,)).iloc[0]
    pair_t = [2.0 / (decels[i] / (10 / 3.6) + decels[i + 1] / (10 / 3.6)) for i in (0, 2, 4)]
    expected = stats.t.ppf(0.975, 2) * np.std(pair_t, ddof=1) / math.sqrt(3) / np.mean(pair_t) * 100
    assert row["n_pairs"] == 3 and row["precision_pct"] == pytest.approx(expected, rel=1e-9)
    assert row["pass"] == (expected <= GTR_PRECISION_PCT)


def test_failing_criterion_asks_for_more_pairs():
    c = _campaign([0.40, 0.60, 0.45, 0.62, 0.38, 0.58])  # pairs differ by ~3 %
    row = gtr15_precision(c, speeds_kph=(50.0,)).iloc[0]
    if row["pass"]:
        pytest.fail(f"expected a failure, precision {row['precision_pct']}")
    n = row["n_pairs"] + row["extra_pairs"]
    spread = 100 * row["sd"] / row["mean"]
    assert stats.t.ppf(0.975, n - 1) * spread / math.sqrt(n) <= GTR_PRECISION_PCT
    assert stats.t.ppf(0.975, n - 2) * spread / math.sqrt(n - 1) > GTR_PRECISION_PCT
    # keeping the spread's uncertainty asks for at least as many
    assert row["extra_pairs_assured"] >= row["extra_pairs"]


def test_pairs_needed_plug_in_and_assured():
    assert pairs_needed(1.0, 3, 3.0) == 3  # t(2) 1 / sqrt 3 = 2.48 <= 3
    n = pairs_needed(4.0, 3, 2.0)
    assert stats.t.ppf(0.975, n - 1) * 4.0 / math.sqrt(n) <= 2.0 < stats.t.ppf(0.975, n - 2) * 4.0 / math.sqrt(n - 1)
    assured = pairs_needed(4.0, 5, 2.0, assured=0.8)
    assert assured is not None and assured > n
    assert pairs_needed(100.0, 3, 0.01) is None
