"""Run validity: wind limits, Hampel outliers, partner rejection."""

import numpy as np
import pandas as pd

from bayes_roadload.analysis.validity import (
    format_validity,
    hampel_filter,
    hampel_scores,
    interval_validity,
    reject_with_partners,
    trace_validity,
)
from bayes_roadload.data import IntervalCampaign, Vehicle


def test_hampel_filter_finds_a_spike_and_leaves_a_smooth_trace():
    t = np.arange(200) * 0.25
    v = 30.0 - 0.3 * t + np.random.default_rng(0).normal(0, 0.02, t.size)
    flags, _ = hampel_filter(v)
    assert flags.mean() < 0.05                   # measured ~1.3 % false alarms on Gaussian noise
    v[100] += 1.0
    flags, cleaned = hampel_filter(v)
    assert flags[100] and abs(cleaned[100] - (30.0 - 0.3 * t[100])) < 0.15


def test_scores_floor_and_partner_rejection():
    times = [35.2, 35.22, 35.25, 35.18, 37.0]
    assert abs(hampel_scores(times, min_relative_spread=0.02)[-1]) < 3   # 5 % slower: ordinary with the floor
    assert abs(hampel_scores(times)[-1]) > 3                              # an outlier without it
    table = pd.DataFrame({"run": [1, 2, 3, 4], "rejected": [False, True, False, False], "reason": ["", "x", "", ""]})
    out = reject_with_partners(table, [(1, 2), (3, 4)])
    assert list(out["rejected"]) == [True, True, False, False] and out.loc[0, "reason"] == "partner of 2"


def test_interval_outlier_and_operator_flag():
    rows = []
    for r, total in enumerate([20.0, 20.2, 19.9, 20.1, 20.0, 5.0, 20.1, 19.8]):
        rows.append({"run": r + 1, "direction": 1 - 2 * (r % 2), "valid": 0 if r == 6 else 1,
                     "speed_start_mps": 26.0, "speed_end_mps": 20.0, "interval_s": total})
    v = interval_validity(IntervalCampaign(pd.DataFrame(rows), Vehicle(1500.0, 1530.0, 2.2))).set_index("run")
    assert v.loc[6, "rejected"] and "Hampel" in v.loc[6, "reason"]
    assert v.loc[5, "reason"] == "partner of 6"
    assert v.loc[7, "reason"].startswith("operator") and v.loc[8, "reason"] == "partner of 7"
    assert not v.loc[[1, 2, 3, 4], "rejected"].any()
    assert "4 rejected" in format_validity(v.reset_index())


def test_wind_limits_on_a_windy_campaign(small_campaign):
    """Case 2 winds (2 m/s head and cross, Dryden turbulence): beyond the EEC limits (mean 3,
    gusts 5, cross 2 m/s) at least in the gusts, within GTR 15's on-board ones (7, 10, 4)."""
    eec = trace_validity(small_campaign, "eec")
    gtr = trace_validity(small_campaign, "gtr_onboard")
    assert eec["rejected"].all() and "(eec)" in eec["reason"].iloc[0]
    assert not gtr["rejected"].any()
    np.testing.assert_allclose(gtr["mean_wind_mps"], 2 * np.sqrt(2), atol=0.5)


def test_the_yaw_readings_resolution_is_reported_and_a_reading_that_misses_the_gusts_is_noted(small_campaign):
    """Each run's yaw sample rate and the lag-1 autocorrelation of its gusts; the summary line
    notes a reading whose gusts change from one sample to the next (white noise in place of the
    yaw's fluctuations: autocorrelation ~0), never a rejection."""
    import dataclasses

    from bayes_roadload import config

    table = trace_validity(small_campaign, "gtr_onboard")
    t = small_campaign.runs.groupby("run", sort=False)["time_s"].apply(lambda s: 1.0 / np.median(np.diff(s)))
    np.testing.assert_allclose(table["yaw_sample_rate_hz"], t.to_numpy())
    assert table["yaw_lag1_autocorr"].between(-1.0, 1.0).all()
    noted = table["yaw_lag1_autocorr"].median() < config.DEFAULT_DIAGNOSIS.min_input_lag1
    assert ("does not follow its gusts" in format_validity(table)) == noted
    runs = small_campaign.runs.copy()
    rng = np.random.default_rng(0)
    runs["yaw_rad"] = runs.groupby("run")["yaw_rad"].transform("mean") + 0.05 * rng.standard_normal(len(runs))
    white = trace_validity(dataclasses.replace(small_campaign, runs=runs), "gtr_onboard")
    assert (white["yaw_lag1_autocorr"].abs() < 4.0 / np.sqrt(white["samples"])).all()
    assert "does not follow its gusts" in format_validity(white)
    assert not white["reason"].str.contains("gust").any()   # its noise may raise the peak wind; not itself a reason
