"""Tests of the thesis simulation study (tables 6.8, 6.9): per-pair classical fits of the
table 6.7 cases beside the published recoveries and test-to-test spreads."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from bayes_roadload import thesis
from studies.thesis_study import (
    FREE,
    PARAMETERS,
    PUBLISHED,
    PUBLISHED_CASES,
    PUBLISHED_ROUNDING,
    SPREAD_CASES,
    VALIDATION_CASES,
    Z_NOISY,
    _campaign,
    case_table,
    markdown,
    published_range,
    replicate_index,
    spread_table,
)

TRUTH = thesis.THESIS_COEFFICIENTS


@pytest.fixture(scope="module")
def table():
    # two pairs per case so the markdown shows a per-pair sd and the spread has 2 pairs
    return case_table(cases=(1, 14), seed=0, pairs=2)


def test_published_figures_are_consistent():
    # The per-case values (tables 6.8, 6.9) must give the summary figures of section 4: the
    # cases 1-6 range, the case 9 / 10 rows, and the spreads over 14-19 (sample std, ddof 1)
    # to the printed rounding (half a unit of the last digit).  The 4-term K_D spread of the
    # six printed values is 41.6 % against the printed 40.8 % (the table's "averages" are
    # weighted; its K_D std is not recomputable from the rounded values to better than ~1).
    for p, (low, high) in PUBLISHED["4-term"]["cases_1_6_range"].items():
        values = [PUBLISHED_CASES[("4-term", c)][p] for c in VALIDATION_CASES]
        assert (min(values), max(values)) == pytest.approx((low, high), rel=1e-12)
    for case in (9, 10):
        assert PUBLISHED_CASES[("4-term", case)] == pytest.approx(PUBLISHED["4-term"][f"case_{case}"])
    for analysis, spreads in (("4-term", PUBLISHED["4-term"]["spread_14_19_pct"]),
                              ("3-term", PUBLISHED["3-term"]["spread_14_19_pct"])):
        for p, published in spreads.items():
            x = np.array([PUBLISHED_CASES[(analysis, c)][p] for c in SPREAD_CASES])
            pct = 100 * x.std(ddof=1) / x.mean()
            half_unit = 0.05 if published >= 1 else 0.005
            assert abs(pct - published) <= (1.0 if p == "KD" else half_unit), (analysis, p, pct)
    assert PUBLISHED["3-term"]["KD_fixed"] == TRUTH["KD"]
    assert published_range("4-term", 3, "BD") == (1.985e-4, 2.000e-4)
    assert published_range("3-term", 12, "CD0") == (0.4015, 0.4015)


def test_columns_and_rows(table):
    for col in ("case", "description", "analysis", "model", "initial_speed", "seed", "pair", "runs",
                "published_table", "noisy", "success", "rms_residual_mps", "fit_time_s", "warnings"):
        assert col in table
    for p in PARAMETERS:
        for suffix in ("", "_truth", "_err_pct", "_published", "_published_low", "_published_high",
                       "_outside_pct"):
            assert f"{p}{suffix}" in table
    assert len(table) == 2 * 2 * 2  # cases x analyses x pairs
    assert set(table["analysis"]) == {"4-term", "3-term"}
    assert sorted(table["pair"].unique()) == [1, 2]
    assert table["success"].all()
    three = table[table["analysis"] == "3-term"]
    # three_term fixes K_D from the campaign's [tunnel] K_D, which the simulator sets to its
    # true K_D: the thesis' 0.614
    assert (three["model"] == "three_term").all() and not three["KD_free"].any()
    assert (three["KD"] == PUBLISHED["3-term"]["KD_fixed"]).all()
    four = table[table["analysis"] == "4-term"]
    assert four["KD_free"].all() and (four["model"] == "four_term").all()
    assert (table["published_table"] == table["analysis"].map({"4-term": "6.8", "3-term": "6.9"})).all()
    for p in PARAMETERS:
        assert (table[f"{p}_truth"] == TRUTH[p]).all()
        err = 100 * (table[p] - TRUTH[p]) / TRUTH[p]
        assert np.allclose(table[f"{p}_err_pct"], err, rtol=1e-12, atol=1e-12)


def test_outside_is_zero_exactly_inside_the_printed_range(table):
    for p in PARAMETERS:
        low = table[f"{p}_published_low"] - PUBLISHED_ROUNDING[p]
        high = table[f"{p}_published_high"] + PUBLISHED_ROUNDING[p]
        inside = (table[p] >= low) & (table[p] <= high)
        assert ((table[f"{p}_outside_pct"] == 0) == inside).all(), p
        sign = np.sign(table.loc[~inside, f"{p}_outside_pct"])
        assert (sign == np.where(table.loc[~inside, p] > high[~inside], 1, -1)).all()


def test_noise_free_case_recovers_within_published_accuracy(table):
    # Case 1 has no noise: the thesis' errors (table 6.8 / 6.9, cases 1-6) come from writing
    # the speed to 5 decimals, ours from the analysis seeing the frozen turbulence at 4 Hz;
    # both are discretisation errors of exact data, so the largest published error over the
    # validation cases is the accuracy to meet.  (Ours may lie on the other side of the truth:
    # the thesis' B_D never exceeds 2.000e-4, ours does by ~0.15 %.)
    rows = table[table["case"] == 1]
    assert not rows["noisy"].any()
    for analysis, g in rows.groupby("analysis"):
        for p in FREE[analysis]:
            published = [PUBLISHED_CASES[(analysis, c)][p] for c in VALIDATION_CASES]
            accuracy = max(abs(x - TRUTH[p]) for x in published) + PUBLISHED_ROUNDING[p]
            assert (np.abs(g[p] - TRUTH[p]) <= accuracy).all(), (analysis, p, g[p].tolist(), accuracy)
    # K_D too needs only the 4-term's worst published error, 0.678: 10 %
    kd = rows.loc[rows["analysis"] == "4-term", "KD"]
    assert (np.abs(kd - TRUTH["KD"]) < 0.678 - TRUTH["KD"]).all()


def test_noisy_case_rows_carry_the_published_pair(table):
    rows = table[table["case"] == 14]
    assert rows["noisy"].all()
    for _, r in rows.iterrows():
        pub = PUBLISHED_CASES[(r["analysis"], 14)]
        for p in PARAMETERS:
            assert r[f"{p}_published"] == pub[p]
            assert r[f"{p}_published_low"] == r[f"{p}_published_high"] == pub[p]
        # one pair of case 14 lies within 4 published per-pair spreads of the truth: the
        # thesis' spread over six pairs estimates the per-pair sd (to ~30 %), and 4 of them
        # cover any plausible pair including our C_D0 bias of ~1 % (a broken fit would not)
        for p in FREE[r["analysis"]]:
            if p == "KD":
                continue
            assert abs(r[f"{p}_err_pct"]) < 4 * PUBLISHED[r["analysis"]]["spread_14_19_pct"][p], (r["analysis"], p)


def test_repeated_cases_are_independent_pairs():
    assert [replicate_index(c) for c in range(1, 20)] == [0] * 14 + [1, 0, 1, 0, 1]
    first, second = _campaign(14, 0, 1), _campaign(15, 0, 1)
    assert first.run_ids == [1, 2] and second.run_ids == [3, 4]
    both = _campaign(14, 0, 2)  # the same seed's second pair of the same conditions
    run3 = both.runs[both.runs["run"] == 3]["speed_mps"].to_numpy()
    assert np.array_equal(second.runs[second.runs["run"] == 3]["speed_mps"].to_numpy(), run3)
    assert not np.array_equal(first.runs[first.runs["run"] == 1]["speed_mps"].to_numpy()[:100], run3[:100])


class _RecordingExecutor:
    def __init__(self):
        self.jobs = []

    def map(self, fn, iterable):
        items = list(iterable)
        self.jobs.extend(items)
        return map(fn, items)


def test_executor_maps_pure_case_jobs(table):
    ex = _RecordingExecutor()
    again = case_table(cases=(1,), seed=0, pairs=2, executor=ex)
    assert [(j.case, j.seed, j.pairs, j.analysis) for j in ex.jobs] == [(1, 0, 2, "4-term"), (1, 0, 2, "3-term")]
    before = table[table["case"] == 1].reset_index(drop=True)
    cols = [c for c in before.columns if c not in ("fit_time_s",)]
    pd.testing.assert_frame_equal(again[cols], before[cols])


def _synthetic_fits(rng, seeds, truth=TRUTH):
    rows = []
    for s in seeds:
        for c in SPREAD_CASES:
            for analysis in ("4-term", "3-term"):
                row = {"case": c, "seed": s, "analysis": analysis}
                for p in PARAMETERS:
                    row[p] = truth[p] * (1 + 0.02 * rng.standard_normal())
                    row[f"{p}_truth"] = truth[p]
                rows.append(row)
    return pd.DataFrame(rows)


def test_spread_table_statistics_by_hand():
    seeds = (3, 1, 2, 0)
    fits = _synthetic_fits(np.random.default_rng(5), seeds)
    sp = spread_table(seeds=seeds, fits=fits)
    assert list(zip(sp["analysis"], sp["parameter"])) == [("4-term", p) for p in PARAMETERS] + [
        ("3-term", p) for p in ("AD", "BD", "CD0")]
    for _, r in sp.iterrows():
        sub = fits[fits["analysis"] == r["analysis"]]
        per_seed = {s: 100 * g[r["parameter"]].std(ddof=1) / g[r["parameter"]].mean()
                    for s, g in sub.groupby("seed")}
        x = np.array([per_seed[s] for s in sorted(per_seed)])
        published = PUBLISHED[r["analysis"]]["spread_14_19_pct"][r["parameter"]]
        assert r["first_seed_pct"] == pytest.approx(per_seed[0])
        assert r["mean_pct"] == pytest.approx(x.mean())
        assert r["se_pct"] == pytest.approx(x.std(ddof=1) / 2.0)
        assert (r["min_pct"], r["max_pct"]) == pytest.approx((x.min(), x.max()))
        assert r["published_quantile"] == pytest.approx(np.mean(x < published))
        assert r["published_se_pct"] == pytest.approx(published / math.sqrt(10))
        assert r["ratio"] == pytest.approx(x.mean() / published)
        allx = sub[r["parameter"]]
        assert r["pooled_pct"] == pytest.approx(100 * allx.std(ddof=1) / allx.mean())
        assert r["n_seeds"] == 4 and r["n_pairs"] == 6
        z = (x.mean() - published) / math.hypot(x.std(ddof=1) / 2, published / math.sqrt(10))
        assert r["z"] == pytest.approx(z)


def test_markdown_sets_ours_beside_published(table):
    spread = spread_table(cases=(14,), seeds=(0,), fits=table)
    text = markdown(table, spread)
    lines = text.splitlines()
    row1 = next(line for line in lines if line.startswith("| 1 validation"))
    ours_ad = table.loc[(table["case"] == 1) & (table["analysis"] == "4-term"), "AD"].mean()
    assert f"{ours_ad:.5f}" in row1 and "0.00999-0.01000" in row1 and "1.985-2.000" in row1
    assert "0.4000-0.4005" in row1 and "0.613-0.678" in row1
    row14 = next(line for line in lines if line.startswith("| 14 combined"))
    assert "0.01016" in row14 and "1.960" in row14 and "0.4041" in row14 and "0.244" in row14
    assert "±" in row14  # two pairs: our per-pair sd is shown
    for figure in ("1.5 (6.8)", "5.7 (6.8)", "1.1 (6.8)", "40.8 (6.8)", "0.62 (6.9)", "2.21 (6.9)",
                   "0.57 (6.9)"):
        assert figure in text
    # every noise-free case / coefficient whose mean lies outside the published range is named
    # in the paragraph with its distance; a noisy one when the published pair lies more than
    # Z_NOISY of our per-pair sd from our mean
    g = table.groupby(["analysis", "case"])
    mean, sd = g[list(PARAMETERS)].mean(), g[list(PARAMETERS)].std(ddof=1)
    named = 0
    for (analysis, case), r in mean.iterrows():
        para = next(line for line in lines if line.startswith(f"{analysis} (table"))
        for p in FREE[analysis]:
            low, high = published_range(analysis, case, p)
            if low - PUBLISHED_ROUNDING[p] <= r[p] <= high + PUBLISHED_ROUNDING[p]:
                assert f"case {case} {p} " not in para
                continue
            d = 100 * (r[p] - (high if r[p] > high else low)) / TRUTH[p]
            z = (PUBLISHED_CASES[(analysis, case)][p] - r[p]) / sd.loc[(analysis, case), p]
            if case in VALIDATION_CASES or abs(z) > Z_NOISY:
                assert f"case {case} {p} " in para and f"({d:+.2f} %" in para, (analysis, case, p)
                named += 1
    assert named > 0  # the check above is not vacuous


@pytest.mark.slow
def test_four_term_spreads_of_the_published_order():
    # Cases 14-19, one pair each, over 10 seeds (about 5 minutes).  The published spread is
    # one sample std of six pairs: with sigma the true per-pair spread, s / sigma is
    # distributed as sqrt(chi2_5 / 5), and our mean over seeds estimates c4 sigma = 0.95
    # sigma to ~10 %.  ours / published > 2 then needs s < 0.48 sigma (P = 0.05) and < 0.5
    # needs s > 1.9 sigma (P = 0.003): a factor 2 is the published figure's own ~95 % band.
    sp = spread_table(cases=SPREAD_CASES, seeds=range(10)).set_index(["analysis", "parameter"])
    for p in ("AD", "BD", "CD0"):
        ratio = sp.loc[("4-term", p), "ratio"]
        assert 0.5 < ratio < 2.0, (p, ratio, sp.loc[("4-term", p), "mean_pct"])
