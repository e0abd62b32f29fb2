"""The calibration study's rules (:mod:`bayes_roadload.analysis.calibration`) on synthetic
records, and a smoke run of its whole path on one small independent-simulator campaign."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy.stats import norm

from bayes_roadload import config
from bayes_roadload.analysis.batch import run_batch
from bayes_roadload.analysis.calibration import (COVERAGE_TARGET, QUANTITIES, budget_attribution, budget_rescaled,
                                                  calibration_jobs,
                                                 calibration_markdown, calibration_table, mass_class, mass_class_table,
                                                 pairs_of, size_bin, with_test_mass)
from bayes_roadload.inference.kinds import KINDS, FitOptions


def _records(scale: float, n: int = 400, seed: int = 0) -> pd.DataFrame:
    """Posteriors N(truth + scale * e, 1) with e ~ N(0, 1): calibrated for scale 1."""
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(n):
        rec = {"seed": i, "pairs": 1 + i % 12, "error": np.nan, "gate_pass": True}
        for q in QUANTITIES:
            mean = scale * rng.standard_normal()
            half = norm.ppf(0.975)
            rec.update({f"{q}_truth": 0.0, f"{q}_mean": mean, f"{q}_sd": 1.0,
                        f"{q}_q2.5": mean - half, f"{q}_q97.5": mean + half,
                        f"{q}_in95": bool(abs(mean) <= half)})
        rows.append(rec)
    return pd.DataFrame(rows)


def test_the_rules_pass_calibrated_and_fail_overconfident_posteriors():
    good = calibration_table(_records(1.0))
    overall = good[good["group"] == "all"]
    assert set(overall["quantity"]) == set(QUANTITIES) and (overall["n"] == 400).all()
    # 400 fits: the coverage's binomial sd is 0.011, sd(z)'s ~0.035: far inside the targets
    assert overall["coverage_ok"].all() and overall["z_sd_ok"].all()
    assert set(good["group"]) == {"all", "1-2", "3-5", "6-12"}
    bad = calibration_table(_records(2.0))
    b = bad[bad["group"] == "all"]
    # errors twice the posterior sd: coverage P(|2 e| < 1.96) = 0.67, sd(z) = 2
    assert not b["coverage_ok"].any() and not b["z_sd_ok"].any()
    assert b["coverage95"].mean() == pytest.approx(0.67, abs=0.05)
    assert COVERAGE_TARGET[0] < 0.95 < COVERAGE_TARGET[1]
    text = calibration_markdown(_records(2.0), bad)
    assert "**fail**" in text and "400 campaigns" in text


def test_a_bias_shows_in_the_mean_z_and_the_coverage_not_in_sd_z():
    """Estimates one posterior sd too high everywhere: sd(z) stays ~1 (it passes), the mean z
    is ~1 and the coverage P(|e + 1| < 1.96) = 0.83 fails; the section shows the mean z."""
    rec = _records(1.0)
    for q in QUANTITIES:
        rec[f"{q}_mean"] += 1.0
        rec[f"{q}_in95"] = (rec[f"{q}_mean"] - rec[f"{q}_truth"]).abs() <= norm.ppf(0.975)
    table = calibration_table(rec)
    overall = table[table["group"] == "all"]
    # 400 fits: the mean z's standard error is 0.05, sd(z)'s 0.035, the coverage's 0.019
    assert overall["z_mean"].between(0.85, 1.15).all() and overall["z_sd_ok"].all()
    assert not overall["coverage_ok"].any() and overall["coverage95"].mean() == pytest.approx(0.83, abs=0.05)
    text = calibration_markdown(rec, table)
    assert "| mean z |" in text and f"| all | {QUANTITIES[0]} | 400 |" in text
    row = next(line for line in text.splitlines() if line.startswith(f"| all | {QUANTITIES[0]} |"))
    assert float(row.split("|")[5]) == pytest.approx(overall["z_mean"].iloc[0], abs=0.005)


def test_the_budget_attribution_finds_the_source_that_widens_the_intervals():
    """Errors N(0, 1) from the data plus N(0, 1) from a real source; the interval also carries a
    spurious source (sd 1.5) and a humidity-like source that shifts the mean by +0.6 without
    moving the truth (sd 0.3).  With every source: sd(z) = sqrt(2) / sqrt(1 + 1 + 2.25 + 0.09)
    = 0.68; without the spurious one sqrt(2 / 2.09) = 0.98; the shift's removal takes the mean z
    to 0.  4000 campaigns: sd(z)'s standard error ~0.011, the coverage's ~0.004 (5 SE allowed)."""
    rng = np.random.default_rng(7)
    n = 4000
    err = rng.standard_normal(n) + rng.standard_normal(n)
    sd = np.sqrt(1 + 1 + 1.5**2 + 0.3**2)
    rec = pd.DataFrame({"seed": np.arange(n), "pairs": 3, "error": np.nan, "gate_pass": True,
                        "CD0_truth": 0.0, "CD0_mean": err + 0.6, "CD0_sd": sd, "CD0_sd_data": 1.0,
                        "CD0_sd_typeb_real": 1.0, "CD0_sd_typeb_spurious": 1.5, "CD0_sd_typeb_humid": 0.3,
                        "CD0_mean_shift_humid": 0.6})
    rec["CD0_in95"] = (rec["CD0_mean"] / sd).abs() <= norm.ppf(0.975)
    a = budget_attribution(rec, quantities=("CD0",)).set_index("source")
    assert list(a.index) == ["spurious", "real", "humid", "data only"]  # by median share, data only last
    assert a.loc["spurious", "median_share"] == pytest.approx(1.5**2 / sd**2)
    assert a.loc["spurious", "z_sd"] == pytest.approx(np.sqrt(2) / sd, abs=0.06)
    assert a.loc["spurious", "z_sd_without"] == pytest.approx(np.sqrt(2 / 2.09), abs=0.06)
    assert a.loc["real", "z_sd_without"] == pytest.approx(np.sqrt(2 / 3.34), abs=0.06)
    assert a.loc["data only", "z_sd_without"] == pytest.approx(np.sqrt(2), abs=0.06)
    assert a.loc["humid", "z_mean_without"] == pytest.approx(0.0, abs=0.06)
    assert a.loc["real", "z_mean_without"] == pytest.approx(0.6 / np.sqrt(sd**2 - 1), abs=0.06)
    cover = 2 * norm.cdf(norm.ppf(0.975) * np.sqrt(2.09 / 2)) - 1  # without the spurious source: 0.955
    assert a.loc["spurious", "coverage95_without"] == pytest.approx(cover, abs=0.02)
    full = _records(1.0, n=40)  # the section reads the attribution where the records carry the columns
    full["CD0_sd_data"], full["CD0_sd_typeb_spurious"] = 0.5, 0.8
    text = calibration_markdown(full, calibration_table(full))
    assert "| CD0 | 40 | spurious | 0.64 |" in text and "| CD0 | 40 | data only | 0.64 |" in text
    assert budget_attribution(rec.drop(columns=[c for c in rec if "_typeb_" in c or "_sd_data" in c])).empty
    # sources whose first-order sds add up beyond the interval's variance (correlated, or the
    # interval narrower than the sum): data only reads the posterior's own sd, not a difference
    over = rec.assign(CD0_sd_typeb_spurious=10.0)
    assert over.pipe(budget_attribution, quantities=("CD0",)).set_index("source").loc[
        "data only", "z_sd_without"] == pytest.approx(np.sqrt(2), abs=0.06)


def test_a_source_scaled_to_its_true_size_brings_sd_z_to_one():
    """Errors N(0, 1) from the data plus N(0, 0.5^2) from a Type B source whose budget states sd
    1: the intervals are too wide (sd(z) sqrt(1.25 / 2) = 0.79); at factor 0.5 the budget is
    the truth's and sd(z) is 1 and the coverage 95 %; at factor 1 the reading equals the
    records' own z.  4000 campaigns: sd(z)'s standard error ~0.011, the coverage's ~0.004."""
    rng = np.random.default_rng(11)
    n = 4000
    err = rng.standard_normal(n) + 0.5 * rng.standard_normal(n)
    rec = pd.DataFrame({"seed": np.arange(n), "pairs": 3, "error": np.nan, "gate_pass": True,
                        "CD0_truth": 1.0, "CD0_mean": 1.0 + err, "CD0_sd": np.sqrt(2.0), "CD0_sd_data": 1.0,
                        "CD0_sd_typeb_tyre": 1.0, "AD_truth": 0.0, "AD_mean": err, "AD_sd": 1.0})
    r = budget_rescaled(rec, "tyre", (1.0, 0.5), quantities=("CD0", "AD")).set_index("factor")
    assert list(r["quantity"].unique()) == ["CD0"]  # AD's records carry no such source
    assert r.loc[1.0, "z_sd"] == pytest.approx(np.std(err / np.sqrt(2.0), ddof=1))
    assert r.loc[1.0, "z_sd"] == pytest.approx(np.sqrt(1.25 / 2.0), abs=0.05)
    assert r.loc[0.5, "z_sd"] == pytest.approx(1.0, abs=0.05)
    assert r.loc[0.5, "coverage95"] == pytest.approx(0.95, abs=0.02)
    assert r.loc[1.0, "median_share"] == pytest.approx(0.5)
    # a one-sided source shifts the mean by +0.6 without moving the truth: scaled to 0 it takes
    # its shift with it (mean z 0), at factor 1 the mean z is 0.6 / sqrt(2)
    shifted = rec.assign(CD0_mean=rec["CD0_mean"] + 0.6, CD0_mean_shift_tyre=0.6)
    r = budget_rescaled(shifted, "tyre", (1.0, 0.0), quantities=("CD0",)).set_index("factor")
    assert r.loc[1.0, "z_mean"] == pytest.approx(0.6 / np.sqrt(2.0), abs=0.04)
    assert r.loc[0.0, "z_mean"] == pytest.approx(0.0, abs=0.04)


def test_a_normal_source_read_as_one_sided_moves_the_mean_by_its_sign():
    """A quantity of truth 1 whose fit misses it by its data's error N(0, 1) and by -c delta, the
    true value delta of a source of standard uncertainty 1 lying above the declared one (uniform
    over [0, sqrt(12)], mean sqrt(3)), sensitivity c = -0.5, the source fitted as a normal about
    the declared value (interval sd sqrt(1.25)): mean z -c sqrt(3) / sqrt(1.25) = +0.77.  Read
    one-sided above, the mean moves by sqrt(3) c u as the truth did: mean z 0 and sd(z) 1 (the
    uniform's variance is the normal's); read below, it moves the other way (mean z +1.55).
    Records without the signed column give no row; a source one-sided in the fits already is
    refused.  4000 campaigns: mean z's standard error ~0.016, sd(z)'s ~0.011 (3 SE allowed)."""
    rng = np.random.default_rng(12)
    n = 4000
    c = -0.5
    sd = np.sqrt(1.0 + c * c)
    err = rng.standard_normal(n) + c * rng.uniform(0.0, np.sqrt(12.0), n)
    rec = pd.DataFrame({"seed": np.arange(n), "pairs": 3, "error": np.nan, "gate_pass": True,
                        "CD0_truth": 1.0, "CD0_mean": 1.0 - err, "CD0_sd": sd, "CD0_sd_data": 1.0,
                        "CD0_sd_typeb_lev": abs(c), "CD0_signed_typeb_lev": c})
    shift = -c * np.sqrt(3.0) / sd
    as_fitted = budget_rescaled(rec, "lev", (1.0,), quantities=("CD0",)).iloc[0]
    assert as_fitted["z_mean"] == pytest.approx(shift, abs=0.05)
    above = budget_rescaled(rec, "lev", (1.0,), quantities=("CD0",), one_sided="above").iloc[0]
    assert above["z_mean"] == pytest.approx(0.0, abs=0.05)
    assert above["z_sd"] == pytest.approx(1.0, abs=0.035)
    below = budget_rescaled(rec, "lev", (1.0,), quantities=("CD0",), one_sided="below").iloc[0]
    assert below["z_mean"] == pytest.approx(2.0 * shift, abs=0.05)
    assert budget_rescaled(rec.drop(columns="CD0_signed_typeb_lev"), "lev", (1.0,), quantities=("CD0",),
                           one_sided="above").empty
    with pytest.raises(ValueError, match="one-sided in these fits already"):
        budget_rescaled(rec.assign(CD0_mean_shift_lev=0.3), "lev", (1.0,), quantities=("CD0",), one_sided="above")
    # campaigns fitted before the signed column (a resumed run's older rows) are left out, not read as 0
    mixed = rec.assign(CD0_signed_typeb_lev=np.where(np.arange(n) < n // 2, np.nan, c))
    assert budget_rescaled(mixed, "lev", (1.0,), quantities=("CD0",), one_sided="above").iloc[0]["n"] == n - n // 2
    # another source changed beside the one scanned: a second source of sd 0.5 whose true value is
    # always its declared one, fitted as a normal, read at factor 0 (left out) brings sd(z) back to
    # what the first alone gives; the changes add
    two = rec.assign(CD0_sd=np.sqrt(1.0 + c * c + 0.25), CD0_sd_typeb_tyre=0.5, CD0_signed_typeb_tyre=0.5)
    both = budget_rescaled(two, "lev", (1.0,), quantities=("CD0",), one_sided="above",
                           also={"tyre": (0.0, None)}).iloc[0]
    assert both["z_sd"] == pytest.approx(above["z_sd"], rel=1e-9) and both["z_mean"] == pytest.approx(above["z_mean"])
    # the other source read one-sided moves the mean by its own sqrt(3) c u; campaigns without
    # that source at all are kept, those with it but without its sign left out
    shifted = budget_rescaled(two, "lev", (1.0,), quantities=("CD0",), one_sided="above",
                              also={"tyre": (1.0, "above")}).iloc[0]
    assert shifted["z_mean"] == pytest.approx(above["z_mean"] * sd / np.sqrt(1.25 + 0.25)
                                              + np.sqrt(3.0) * 0.5 / np.sqrt(1.25 + 0.25), abs=1e-9)
    partly = two.assign(CD0_sd_typeb_tyre=np.where(np.arange(n) < 100, np.nan, 0.5),
                        CD0_signed_typeb_tyre=np.where(np.arange(n) < 200, np.nan, 0.5))
    kept = budget_rescaled(partly, "lev", (1.0,), quantities=("CD0",), one_sided="above", also={"tyre": (1.0, "above")})
    assert kept.iloc[0]["n"] == n - 100
    with pytest.raises(ValueError, match="the source scanned"):
        budget_rescaled(two, "lev", (1.0,), quantities=("CD0",), also={"lev": (0.5, None)})


def test_a_one_sided_reading_is_what_the_budget_draws_for_a_source_stated_above():
    """The same source, sensitivity c, standard uncertainty u: records of a fit that took it as a
    normal (``budget_record``: its signed column c u) read one-sided above give the z of records
    of a fit whose model file states it "above" (``budget_record``: the mean shift c sqrt(3) u
    that ``add_type_b``'s draws add, the same sd): the reading and the budget agree on the sign
    and size of the move, to rounding."""
    from bayes_roadload.analysis.budget import TypeB, budget_record

    rng = np.random.default_rng(3)
    n, c, u = 500, -0.4, 0.8
    normal = TypeB(u={"lev": u}, sensitivity={"CD0": {"lev": c}})
    above = TypeB(u={"lev": u}, sensitivity={"CD0": {"lev": c}}, distribution={"lev": "above"})
    rec_n, rec_a = budget_record(normal, {"CD0": 1.0}), budget_record(above, {"CD0": 1.0})
    assert rec_a["CD0_mean_shift_lev"] == pytest.approx(np.sqrt(3.0) * rec_n["CD0_signed_typeb_lev"])
    assert rec_a["CD0_sd_typeb_lev"] == rec_n["CD0_sd_typeb_lev"] == pytest.approx(abs(c) * u)
    sd = np.sqrt(1.0 + (c * u) ** 2)
    base = pd.DataFrame({"seed": np.arange(n), "pairs": 3, "error": np.nan, "gate_pass": True,
                         "CD0_truth": 0.0, "CD0_mean": rng.standard_normal(n) * sd, "CD0_sd": sd})
    fitted_normal = base.assign(**rec_n)
    fitted_above = base.assign(**rec_a, CD0_mean=base["CD0_mean"] + rec_a["CD0_mean_shift_lev"])
    read = budget_rescaled(fitted_normal, "lev", (1.0,), quantities=("CD0",), one_sided="above").iloc[0]
    as_fitted = budget_rescaled(fitted_above, "lev", (1.0,), quantities=("CD0",)).iloc[0]
    assert read["z_mean"] == pytest.approx(as_fitted["z_mean"], abs=1e-12)
    assert read["z_sd"] == pytest.approx(as_fitted["z_sd"], abs=1e-12)
    assert read["z_mean"] - budget_rescaled(fitted_normal, "lev", (1.0,), quantities=("CD0",)).iloc[0]["z_mean"] \
        == pytest.approx(np.sqrt(3.0) * c * u / sd)


def test_a_source_holding_nearly_all_of_a_budget_larger_than_the_interval_is_read_in_proportion():
    """Records whose first-order budget B = sd_data^2 + (c u)^2 = 1 + 1.1^2 exceeds the interval's
    recorded variance 2 (correlated sources, Monte Carlo error): the source left out (factor 0)
    leaves the interval sd sqrt(2 / 2.21) (its part of B removed), not sqrt(2 - 1.21), less than
    the posterior's own sd 1; a source of 99.99 % of B leaves a finite, positive sd.  Factors that
    are not finite numbers >= 0 and a misspelt ``also`` source are refused."""
    rng = np.random.default_rng(5)
    n = 400
    err = rng.standard_normal(n)
    rec = pd.DataFrame({"seed": np.arange(n), "pairs": 3, "error": np.nan, "gate_pass": True,
                        "CD0_truth": 0.0, "CD0_mean": err, "CD0_sd": np.sqrt(2.0), "CD0_sd_data": 1.0,
                        "CD0_sd_typeb_tyre": 1.1, "CD0_signed_typeb_tyre": 1.1})
    r = budget_rescaled(rec, "tyre", (0.0, 1.0), quantities=("CD0",)).set_index("factor")
    assert r.loc[0.0, "z_sd"] == pytest.approx(np.std(err / np.sqrt(2.0 / 2.21), ddof=1))
    assert r.loc[1.0, "z_sd"] == pytest.approx(np.std(err / np.sqrt(2.0), ddof=1))
    a = budget_attribution(rec, quantities=("CD0",)).set_index("source")
    assert a.loc["tyre", "z_sd_without"] == pytest.approx(r.loc[0.0, "z_sd"])
    nearly_all = rec.assign(CD0_sd_data=0.01, CD0_sd=1.0, CD0_sd_typeb_tyre=1.0)
    z = budget_rescaled(nearly_all, "tyre", (0.0,), quantities=("CD0",)).iloc[0]
    assert np.isfinite(z["z_sd"]) and z["z_sd"] == pytest.approx(np.std(err / np.sqrt(1e-4 / (1e-4 + 1.0)), ddof=1))
    # a row without the posterior's own sd (records of an older commit) is read against sd^2
    older = rec.assign(CD0_sd_data=np.where(np.arange(n) < 10, np.nan, 1.0))
    z_older = budget_rescaled(older, "tyre", (0.0,), quantities=("CD0",)).iloc[0]["z_sd"]
    expected = np.where(np.arange(n) < 10, np.sqrt(2.0 - 1.21), np.sqrt(2.0 / 2.21))
    assert z_older == pytest.approx(np.std(err / expected, ddof=1))
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="finite number >= 0"):
            budget_rescaled(rec, "tyre", (bad,), quantities=("CD0",))
    with pytest.raises(ValueError, match="tyres: no quantity's records carry"):
        budget_rescaled(rec.assign(CD0_sd_typeb_lev=0.1), "lev", (1.0,), quantities=("CD0",), also={"tyres": (0.0, None)})


def test_the_gates_are_read_apart_by_the_code_that_fitted_them():
    """Records fitted by two commits (column ``code``): the section counts each commit's gates
    and first-time passes on its own campaigns; one commit adds no such lines."""
    rec = _records(1.0, n=10)
    rec["retries"] = 0
    rec["code"] = ["old"] * 6 + ["new"] * 4
    rec.loc[[0, 1], "gate_pass"] = False
    rec.loc[7, "retries"] = 1
    text = calibration_markdown(rec, calibration_table(rec))
    assert "- `old`: 4 of 6 passed every gate, 4 first time." in text
    assert "- `new`: 4 of 4 passed every gate, 3 first time." in text
    rec["code"] = "old"
    assert "Gates by the code" not in calibration_markdown(rec, calibration_table(rec))


def test_the_truth_split_reads_coverage_on_either_side():
    """The reading by a true value (``DIAGNOSTIC_SPLIT``): campaigns above the threshold whose
    intervals all miss show coverage 0 there, those below keep theirs, and the section says it
    is a reading."""
    from bayes_roadload.analysis.calibration import DIAGNOSTIC_SPLIT, truth_split_table

    rec = _records(1.0, n=200)
    quantity, threshold = DIAGNOSTIC_SPLIT
    above = np.arange(200) % 4 == 0
    rec.loc[above, f"{quantity}_truth"] = threshold + 1.0
    rec.loc[~above, f"{quantity}_truth"] = threshold - 1.0
    for q in QUANTITIES:
        rec.loc[above, f"{q}_in95"] = False
    st = truth_split_table(rec, quantity, threshold)
    hi = st[st["group"] == f"{quantity} > {threshold:g}"]
    lo = st[st["group"] == f"{quantity} <= {threshold:g}"]
    assert (hi["n"] == 50).all() and (hi["coverage95"] == 0.0).all()
    assert (lo["n"] == 150).all()
    for q in QUANTITIES:
        assert lo.loc[lo["quantity"] == q, "coverage95"].item() == pytest.approx(rec.loc[~above, f"{q}_in95"].mean())
    text = calibration_markdown(rec, calibration_table(rec), split=DIAGNOSTIC_SPLIT)
    assert "A reading, not a rule" in text and f"| {quantity} > {threshold:g} | 50 | 0.00 |" in text


def test_the_header_counts_held_intervals_and_first_time_gates_and_the_mass_classes_read_apart():
    """The section's first line counts the 95 % intervals that hold over all quantities and the
    fits that passed every gate without a retry; with a declared test mass per record it reads
    the coverage of light and heavy campaigns apart (the heavy-duty limit itself is light, as
    ``fit`` routes its default)."""
    rec = _records(1.0, n=40)
    rec["retries"] = np.where(np.arange(40) % 10 == 0, 1, 0)
    heavy = np.arange(40) % 4 == 0
    rec["test_mass_kg"] = np.where(heavy, config.HEAVY_DUTY_MASS_KG + 500.0, config.HEAVY_DUTY_MASS_KG)
    for q in QUANTITIES:
        rec.loc[heavy, f"{q}_in95"] = False
    text = calibration_markdown(rec, calibration_table(rec))
    held = int(rec[[f"{q}_in95" for q in QUANTITIES]].to_numpy().sum())
    assert f"40 of 40 fits passed every gate (36 first time, without a retry); {held} of 320 95 % intervals" in text
    light_label, heavy_label = mass_class(config.HEAVY_DUTY_MASS_KG), mass_class(config.HEAVY_DUTY_MASS_KG + 1.0)
    assert light_label != heavy_label
    table = mass_class_table(rec)
    hi, lo = table[table["group"] == heavy_label], table[table["group"] == light_label]
    assert (hi["n"] == 10).all() and (hi["coverage95"] == 0.0).all() and (lo["n"] == 30).all()
    for q in QUANTITIES:
        assert lo.loc[lo["quantity"] == q, "coverage95"].item() == pytest.approx(rec.loc[~heavy, f"{q}_in95"].mean())
    assert f"| {heavy_label} | 10 | 0.00 |" in text and "by the declared test mass" in text
    # records without the mass (written before it was recorded) show no such reading
    assert "by the declared test mass" not in calibration_markdown(rec.drop(columns="test_mass_kg"), calibration_table(rec))


def test_the_yaw_classes_read_coverage_and_bias_apart():
    """Quartiles of the mean absolute yaw: a shift of the estimates in the gustiest quarter shows
    there (its coverage and mean z) and nowhere else; the section prints the table."""
    from bayes_roadload.analysis.calibration import yaw_class_table

    rec = _records(1.0, n=40)
    rec["mean_abs_yaw_rad"] = np.radians(np.arange(40) * 0.3 + 1.0)   # 1.0-12.7 deg, increasing
    top = np.arange(40) >= 30
    for q in QUANTITIES:
        rec.loc[top, f"{q}_mean"] -= 5.0
        rec.loc[top, f"{q}_in95"] = False
    t = yaw_class_table(rec)
    groups = list(dict.fromkeys(t["group"]))
    assert len(groups) == 4 and (t["n"] == 10).all()
    last = t[t["group"] == groups[-1]]
    assert (last["coverage95"] == 0.0).all() and (last["z_mean"] < -3.0).all()
    rest = t[t["group"] != groups[-1]]
    assert (rest["z_mean"].abs() < 1.5).all()      # 10 unit-normal z: |mean| < 1.5 is 4.7 sd
    text = calibration_markdown(rec, calibration_table(rec))
    assert "by the campaign's mean absolute logged yaw" in text and f"| {groups[-1]} | 10 | 0.00 (" in text


def test_the_fitted_nuisance_classes_read_coverage_and_bias_apart():
    """Quartiles of a fitted nuisance parameter (the tyre-lag gain's posterior mean): misses where
    it is largest show in that class alone, whatever the order of the records; the section
    prints the table only when every fit records the parameter."""
    from bayes_roadload.analysis.calibration import estimate_class_table

    rec = _records(1.0, n=40)
    rng = np.random.default_rng(3)
    gain = rng.permutation(np.linspace(0.001, 0.010, 40))
    rec["tyre_lag_gain_per_mps_mean"] = gain
    top = gain > np.quantile(gain, 0.75)
    for q in QUANTITIES:
        rec.loc[top, f"{q}_mean"] -= 5.0
        rec.loc[top, f"{q}_in95"] = False
    t = estimate_class_table(rec, "tyre_lag_gain_per_mps")
    groups = list(dict.fromkeys(t["group"]))
    assert len(groups) == 4 and (t["n"] == 10).all()
    last = t[t["group"] == groups[-1]]
    assert (last["coverage95"] == 0.0).all() and (last["z_mean"] < -3.0).all()
    assert (t[t["group"] != groups[-1]]["z_mean"].abs() < 1.5).all()
    text = calibration_markdown(rec, calibration_table(rec))
    assert "by the fitted tyre-lag gain" in text and f"| {groups[-1]} | 10 | 0.00 (" in text
    assert "by the fitted tyre-lag gain" not in calibration_markdown(
        rec.drop(columns="tyre_lag_gain_per_mps_mean"), calibration_table(rec))


def test_jobs_carry_the_model_asked_for():
    """The study fits fit's default model for each campaign unless told otherwise (``--model``):
    "auto", which the batch job resolves for each campaign as ``fit`` does."""
    assert {j.model for j in calibration_jobs([1, 2], 1, 3)} == {"auto"}
    assert {j.model for j in calibration_jobs([1], 1, 3, options=FitOptions(method="laplace"))} == {"auto"}
    assert {j.model for j in calibration_jobs([1, 2], 1, 3, model="four_term")} == {"four_term"}



def test_an_ablation_withholds_the_effect_from_every_campaign_and_keeps_the_names():
    """``--withhold``: each job's campaign is the simulator's with that physics off (here the
    quartic of C_D(psi)), of the same vehicle and size, under the same name, tagged with what was
    withheld; an effect the simulator does not have is refused with the list of those it has."""
    plain = calibration_jobs([3001], 1, 1)
    ablated = calibration_jobs([3001], 1, 1, withhold=["cd_yaw_shape"])
    assert ablated[0].name == plain[0].name == "ind-3001" and ablated[0].tags["withheld"] == "cd_yaw_shape"
    assert "withheld" not in plain[0].tags
    on, off = plain[0].campaign(), ablated[0].campaign()
    shape_on = on.truth["meta"]["vehicle_simulated"]
    shape_off = off.truth["meta"]["vehicle_simulated"]
    assert shape_on["k4_per_rad4"] != 0.0 and shape_off["k4_per_rad4"] == 0.0
    assert {k: v for k, v in shape_on.items() if k != "k4_per_rad4"} == {k: v for k, v in shape_off.items() if k != "k4_per_rad4"}
    assert "cd_yaw_shape" in on.truth["meta"]["effects"] and "cd_yaw_shape" not in off.truth["meta"]["effects"]
    with pytest.raises(ValueError, match="cd_yaw_shape"):
        calibration_jobs([1], 1, 1, withhold=["cd_yaw_shap"])

def test_a_study_can_log_the_humidity_too():
    """``log=("humidity",)``: the same campaign under the same name with the hygrometer's column
    added (tagged ``logged``); a channel the simulator does not have is refused."""
    plain, logged = calibration_jobs([3001], 1, 1)[0], calibration_jobs([3001], 1, 1, log=["humidity"])[0]
    assert logged.name == plain.name and logged.tags["logged"] == "humidity" and "logged" not in plain.tags
    a, b = plain.campaign().runs, logged.campaign().runs
    assert "relative_humidity_pct" in b and b.drop(columns="relative_humidity_pct").equals(a)
    with pytest.raises(ValueError, match="humidity"):
        calibration_jobs([1], 1, 1, log=["humidty"])


@pytest.mark.slow  # a cross-check kept out of the default run's 10 minutes
def test_a_study_can_state_the_anemometers_yaw_calibration():
    """``state_yaw_calibration``: the same runs under the same name, whose vehicle.toml states
    the simulator's own airspeed factor against yaw (0 where the effect is withheld)."""
    plain = calibration_jobs([3001], 1, 1)[0].campaign()
    stated = calibration_jobs([3001], 1, 1, state_yaw_calibration=True)[0]
    c = stated.campaign()
    assert stated.tags["stated"] == "yaw calibration" and c.runs.equals(plain.runs)
    e = c.truth["meta"]["instruments"]["airspeed_factor_yaw"]
    assert e > 0.0 and c.anemometer.airspeed_yaw_coefficient_per_rad2 == e
    assert plain.anemometer.airspeed_yaw_coefficient_per_rad2 == 0.0
    off = calibration_jobs([3001], 1, 1, withhold=["anemometer_yaw_factor"], state_yaw_calibration=True)[0].campaign()
    assert off.anemometer.airspeed_yaw_coefficient_per_rad2 == 0.0


def test_a_study_can_fit_realisations_and_campaigns_of_chosen_effects():
    """``realisation``: the seed's vehicle and Type B errors, each run drawn anew (tagged);
    ``effects=()``: the campaign with no effect injected (tagged ``none``); an unknown effect is
    refused with the simulator's list."""
    plain = calibration_jobs([3001], 1, 1)[0]
    again = calibration_jobs([3001], 1, 1, realisation=2)[0]
    bare = calibration_jobs([3001], 1, 1, effects=())[0]
    assert again.tags["realisation"] == 2 and "realisation" not in plain.tags and bare.tags["effects"] == "none"
    p, r, b = plain.campaign(), again.campaign(), bare.campaign()
    assert r.truth["meta"]["type_b_errors"] == p.truth["meta"]["type_b_errors"] and r.meta["realisation"] == 2
    assert r.truth["meta"]["runs"][0]["v0_mps"] != p.truth["meta"]["runs"][0]["v0_mps"]
    assert b.truth["meta"]["effects"] == [] and p.truth["meta"]["effects"]
    with pytest.raises(ValueError, match="cd_yaw_shape"):
        calibration_jobs([1], 1, 1, effects=["cd_yaw_shap"])


def test_campaign_sizes_come_from_the_seed():
    assert [pairs_of(s, 1, 12) for s in range(50)] == [pairs_of(s, 1, 12) for s in range(50)]
    assert {pairs_of(s, 1, 12) for s in range(200)} == set(range(1, 13))
    assert [size_bin(p) for p in (1, 2, 3, 5, 6, 12)] == ["1-2", "1-2", "3-5", "3-5", "6-12", "6-12"]


def test_smoke_one_independent_campaign_through_the_study():
    """The study's path end to end on one 1-pair campaign: the record carries the simulator's
    own truth of every quantity, and the table has a row per quantity.  The fit is the cheap
    MAP + Laplace one (the study passes the options through; a NUTS fit through the same batch
    door: tests/analysis/test_batch.py)."""
    # seed 8: a small car logged at 2 Hz; pooled
    jobs = calibration_jobs([8], 1, 1, FitOptions(method="laplace", pooling="pooled"))
    assert jobs[0].pooling == "pooled" and jobs[0].method == "laplace" and jobs[0].tags["pairs"] == 1
    records = run_batch(jobs, progress=False)
    assert records["error"].isna().all(), records.get("traceback")
    campaign = jobs[0].campaign()
    # "auto" is recorded as the model fit takes for this campaign
    assert records.loc[0, "model"] == KINDS["traces"].default_model(campaign, FitOptions())
    for q in QUANTITIES:
        assert records.loc[0, f"{q}_truth"] == pytest.approx(campaign.truth[q], rel=1e-12), q
    # the declared test mass, which the reading by test mass groups on, as filled for old records
    assert records.loc[0, "test_mass_kg"] == campaign.vehicle.mass_kg
    assert with_test_mass(records.drop(columns="test_mass_kg"))["test_mass_kg"].tolist() == [campaign.vehicle.mass_kg]
    table = calibration_table(records)
    assert set(table.loc[table["group"] == "all", "quantity"]) == set(QUANTITIES)


def test_the_study_resumes_from_its_partial_records(tmp_path):
    """An interrupted study (``benchmarks/calibration_study.py``) keeps the records it wrote and
    fits only the campaigns they do not hold."""
    from ..conftest import benchmark_script

    with benchmark_script("calibration_study") as study:
        jobs = calibration_jobs([1000, 1001, 1002], 1, 3)
        partial = tmp_path / "records.partial.csv"
        before, pending = study.resume_from(partial, jobs)
        assert before.empty and [j.name for j in pending] == ["ind-1000", "ind-1001", "ind-1002"]
        pd.DataFrame({"name": ["ind-1001"], "AD_mean": [0.01]}).to_csv(partial, index=False)
        before, pending = study.resume_from(partial, jobs)
        assert list(before["name"]) == ["ind-1001"] and [j.name for j in pending] == ["ind-1000", "ind-1002"]
        # records of another design (here a logged survey) are not resumed by a run without it
        pd.DataFrame({"name": ["ind-1001"], "logged": ["survey"]}).to_csv(partial, index=False)
        with pytest.raises(SystemExit, match="fitted with --log survey, this run asks for no --log"):
            study.resume_from(partial, jobs)
        before, pending = study.resume_from(partial, calibration_jobs([1000, 1001, 1002], 1, 3, log=("survey",)))
        assert [j.name for j in pending] == ["ind-1000", "ind-1002"]


def test_the_comparison_counts_held_intervals_and_first_time_gates():
    """``calibration_study.py --compare``: on the campaigns both record sets hold, the held
    intervals of each and which fits passed every gate first time (a retried fit did not)."""
    from ..conftest import benchmark_script

    first = _records(1.0, n=4, seed=1).assign(retries=[0, 1, 0, 0], retry_failed=[None, "divergences", None, None])
    second = _records(1.0, n=3, seed=2).assign(retries=0, retry_failed=None)
    for rec in (first, second):
        rec["name"] = [f"ind-{s}" for s in rec["seed"]]
        for q in QUANTITIES:  # truths away from zero: the table states relative errors
            rec[[f"{q}_truth", f"{q}_mean"]] += 1.0
    with benchmark_script("calibration_study") as study:
        text = study.comparison_markdown(first, second)
    rows = {line.split(" | ")[0].strip("| "): line.split(" | ")[1:] for line in text.splitlines() if line.startswith("| ")}
    held = [int(first.loc[:2, [f"{q}_in95" for q in QUANTITIES]].to_numpy().sum()),
            int(second[[f"{q}_in95" for q in QUANTITIES]].to_numpy().sum())]
    assert rows["all"][0].strip() == f"{held[0]} / {3 * len(QUANTITIES)}"
    assert rows["all"][1].strip(" |") == f"{held[1]} / {3 * len(QUANTITIES)}"
    assert [c.strip(" |") for c in rows["every gate first time"]] == ["2 / 3", "3 / 3"]
    assert [c.strip(" |") for c in rows["retried (first attempt failed)"]] == ["ind-1 (divergences)", "none"]


def test_a_candidate_defaults_heavy_file_takes_the_campaigns_above_the_heavy_duty_mass():
    """``model_heavy`` routes a campaign by its test mass as ``fit`` routes its default
    (``config.HEAVY_DUTY_MASS_KG``); ``"auto"`` is ``fit``'s own choice; without it the job's
    model fits every campaign."""
    import dataclasses

    from bayes_roadload import config
    from bayes_roadload.analysis.batch import job_model
    from bayes_roadload.data import Campaign, Vehicle

    def campaign(mass_kg):
        t = np.arange(12.0)
        runs = pd.DataFrame({"run": 1, "direction": 1.0, "time_s": t, "speed_mps": 30.0 - 0.5 * t})
        return Campaign(runs, Vehicle(mass_kg, mass_kg * 1.03, 2.0))

    light, heavy = campaign(config.HEAVY_DUTY_MASS_KG), campaign(config.HEAVY_DUTY_MASS_KG + 1.0)
    (job,) = calibration_jobs([1], 1, 1, model="four_term_tyre_lag_admittance_pitch",
                              model_heavy="four_term_tyre_lag_admittance_heavy_pitch")
    options = FitOptions()
    assert job_model(job, light, options) == "four_term_tyre_lag_admittance_pitch"
    assert job_model(job, heavy, options) == "four_term_tyre_lag_admittance_heavy_pitch"
    assert job_model(dataclasses.replace(job, model_heavy=None), heavy, options) == "four_term_tyre_lag_admittance_pitch"
    auto = dataclasses.replace(job, model="auto")
    for c in (light, heavy):
        assert job_model(auto, c, options) == KINDS["traces"].default_model(c, options)


def test_a_partial_records_summary_names_the_command_that_resumes_it(tmp_path, capsys):
    """``--from-records`` on a ``.partial.csv``: the header's resume command starts at the
    records' first seed (an earlier run's records, not the current confirmatory seed)."""
    from ..conftest import benchmark_script

    rec = _records(1.0, n=20)
    rec["seed"] += 4000
    partial = tmp_path / "records.partial.csv"
    rec.to_csv(partial, index=False)
    with benchmark_script("calibration_study") as study:
        assert study.main(["--from-records", "--records", str(partial)]) == 0
    err = capsys.readouterr().err
    assert "**Partial run: 20 of the 200 campaigns**" in err and "--seed0 4000 " in err
    assert "20 campaigns (seeds 4000-4019)" in err and "| mean z |" in err
    rec.assign(logged="survey").to_csv(partial, index=False)   # a run that logged the track survey
    with benchmark_script("calibration_study") as study:
        assert study.main(["--from-records", "--records", str(partial)]) == 0
    assert "--seed0 4000 --log survey --records" in capsys.readouterr().err


def test_fill_test_mass_writes_the_campaigns_masses_back_and_the_section_reads_them(tmp_path, capsys):
    """``--from-records --fill-test-mass``: records written before the mass was recorded get each
    campaign's declared test mass (the campaign simulated again from its seed and size), written
    back to the file, and the section shows the reading by test mass."""
    from bayes_roadload.simulate.independent import simulate_independent

    from ..conftest import benchmark_script

    rec = _records(1.0, n=2)
    rec["seed"], rec["pairs"] = [8, 9], [1, 1]
    records = tmp_path / "records.csv"
    rec.to_csv(records, index=False)
    with benchmark_script("calibration_study") as study:
        assert study.main(["--from-records", "--fill-test-mass", "--records", str(records)]) == 0
    filled = pd.read_csv(records)
    assert filled["test_mass_kg"].tolist() == [simulate_independent(s, pairs=1).vehicle.mass_kg for s in (8, 9)]
    assert "by the declared test mass" in capsys.readouterr().err
