"""Tests of the pooling study (:mod:`bayes_roadload.analysis.pooling`): the combined campaign,
the per-pair classical fits and the tables, on real simulated campaigns (least squares only)
and on synthetic records (the NUTS side; the batch door's own test runs a real fit)."""

from __future__ import annotations

import dataclasses
import math
import pickle

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.analysis.batch import SimulatedCampaign
from bayes_roadload.analysis.pooling import (CombinedCampaign, combined_cases, per_pair_fits, pooling_jobs,
                                             pooling_markdown, pooling_table, yaw_jobs, yaw_table)


@pytest.fixture(scope="module")
def combined():
    return combined_cases(0, 1, cases=(14, 18))()


def test_combined_campaign_renumbers_runs_and_pairs(combined):
    assert combined.run_ids == [1, 2, 3, 4]
    assert combined.pairs() == [(1, 2), (3, 4)]
    assert combined.meta["cases"] == [14, 18] and combined.meta["pairs"] == 2
    assert {k: combined.truth[k] for k in ("AD", "BD", "CD0", "KD")} == {"AD": 0.01, "BD": 2e-4, "CD0": 0.4,
                                                                          "KD": 0.614}
    # every run keeps its own (system-noise) coefficients under its new id
    part = SimulatedCampaign(18, pairs=1, seed=1)()
    assert combined.truth["per_run"]["3"] == part.truth["per_run"]["1"]
    # case 18 has no head wind: its runs' yaw is the cross wind's, both directions alike
    assert len(combined.runs) == sum(len(SimulatedCampaign(c, 1, seed=s)().runs) for c, s in ((14, 0), (18, 1)))
    recipe = combined_cases(0, 1, cases=(14, 18))
    assert pickle.loads(pickle.dumps(recipe)) == recipe


def test_combined_campaign_refuses_different_vehicles(combined):
    other = dataclasses.replace(combined.vehicle, mass_kg=combined.vehicle.mass_kg + 10.0)
    from bayes_roadload.data.campaign import Campaign

    heavy = Campaign(combined.runs, other, combined.anemometer, combined.tunnel, combined.truth, combined.meta)
    with pytest.raises(ValueError, match="share the vehicle"):
        CombinedCampaign((combined, heavy))()


def test_per_pair_fits_one_row_per_pair():
    df = per_pair_fits([0], 1, cases=(14, 18))
    assert list(df["case"]) == [14, 18] and list(df["pair"]) == [1, 2]
    assert df["success"].all()
    # cases 14-19: the thesis' per-pair spreads are AD 1.5 %, CD0 1.1 %; a single pair is within
    # 5 % of the truth in AD and CD0 (3+ spreads)
    assert (abs(df["AD"] / 0.01 - 1) < 0.05).all() and (abs(df["CD0"] / 0.4 - 1) < 0.05).all()
    assert (df["KD_se"] > 0).all()


def _records():
    rng = np.random.default_rng(1)
    rows = []
    for k, sd in ((1, 0.02), (4, 0.01)):
        for s in range(8):
            rec = {"error": None, "pairs_per_case": k, "campaign_seed": s}
            for p, t in (("AD", 0.01), ("BD", 2e-4), ("CD0", 0.4), ("KD", 0.614)):
                m = t * (1 + sd * rng.standard_normal())
                rec.update({f"{p}_truth": t, f"{p}_mean": m, f"{p}_q2.5": m - 2 * sd * t,
                            f"{p}_q97.5": m + 2 * sd * t, f"{p}_in95": abs(m - t) <= 2 * sd * t})
            rows.append(rec)
    return pd.DataFrame(rows)


def test_pooling_table_spreads_and_expectation():
    per_pair = pd.DataFrame({"success": True, "AD": [0.0099, 0.0101, 0.0100, 0.0102], "AD_se": 1e-4,
                             "BD": 2e-4, "BD_se": 1e-5, "CD0": 0.4, "CD0_se": 0.002, "KD": 0.6,
                             "KD_se": [0.1, 0.2, np.inf, 0.3]})
    table = pooling_table(_records(), per_pair)
    one = table[(table["analysis"] == "one pair (LSQ)")].set_index("parameter")
    ad = np.array([0.0099, 0.0101, 0.0100, 0.0102])
    assert one.loc["AD", "spread_pct"] == pytest.approx(100 * ad.std(ddof=1) / ad.mean())
    assert one.loc["KD", "unidentified_pairs"] == 1
    assert one.loc["KD", "half_width_95"] == pytest.approx(1.959964 * 0.2)  # median of the identified
    joint = table[table["pairs"] == 24].set_index("parameter")
    assert joint.loc["AD", "expected_spread_pct"] == pytest.approx(one.loc["AD", "spread_pct"] / math.sqrt(24))
    # the 8 synthetic campaigns scatter with sd 1 % (4 pairs per case): measured within 3 SE of it
    assert joint.loc["CD0", "spread_pct"] == pytest.approx(1.0, abs=3 * 1.0 / math.sqrt(2 * 7))
    assert "joint NUTS, 6 pairs" in pooling_markdown(table)


def test_yaw_table_contraction():
    rec = pd.DataFrame({"error": None, "cross_wind_mps": [0.0, 0.0, 3.0], "mean_abs_yaw_rad": [0.01, 0.01, 0.1],
                        "KD_mean": 0.6, "KD_sd": [1.0, 1.0, 0.1], "KD_q2.5": 0.0, "KD_q97.5": 1.0,
                        "KD_in95": True})
    table = yaw_table(rec, model="four_term").set_index("cross_wind_mps")
    # models/four_term.toml: KD ~ normal(0.6, 1.0) truncated > 0, whose sd is 0.7196 (scipy)
    from scipy.stats import truncnorm

    prior_sd = truncnorm(-0.6, np.inf, loc=0.6, scale=1.0).std()
    # the table samples the prior (200 000 draws: the sd is within 0.5 % of the exact value)
    assert table.loc[0.0, "contraction"] == pytest.approx(1 - 1.0 / prior_sd**2, rel=0.02)
    assert table.loc[3.0, "contraction"] == pytest.approx(1 - 0.01 / prior_sd**2, rel=0.02)
    assert table.loc[3.0, "mean_abs_yaw_deg"] == pytest.approx(np.degrees(0.1))


def test_jobs_are_tagged_and_pickle():
    jobs = pooling_jobs([0, 1], (1, 4)) + yaw_jobs((0.0, 3.0), seeds=(0,))
    assert [j.tags.get("pairs_per_case") for j in jobs[:4]] == [1, 1, 4, 4]
    assert [j.tags.get("cross_wind_mps") for j in jobs[4:]] == [0.0, 3.0]
    assert jobs[5].campaign_factory.case.cross_wind_mps == 3.0 and jobs[5].campaign_factory.case.head_wind_mps == 0
    for j in jobs:
        assert pickle.loads(pickle.dumps(j)) == j
