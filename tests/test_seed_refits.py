"""benchmarks/seed_refits.py: thinning a campaign's runs and the paired comparison of two refits."""

import pandas as pd
import pytest

from .conftest import benchmark_script


@pytest.fixture(scope="module")
def refits():
    with benchmark_script("seed_refits") as module:
        yield module


def test_thinning_keeps_every_kth_sample_of_each_run_from_its_first(refits):
    from bayes_roadload.simulate.independent import simulate_independent

    c = simulate_independent(5, pairs=1, sample_rate_hz=20.0, wind="calm")
    t = refits.thinned(c, 5)
    for rid, run in c.runs.groupby("run"):
        kept = t.runs[t.runs["run"] == rid]
        assert kept["time_s"].tolist() == run["time_s"].iloc[::5].tolist()
    assert list(t.runs.columns) == list(c.runs.columns)
    assert refits.thinned(c, 1) is c


def test_compare_reports_each_seed_and_the_paired_change(refits):
    """C_D0 errors -10 / -4 % in the first file and -8 / -4 % in the second: means -7.00 / -6.00,
    paired change +1.00 with SE sd(+2, 0) / sqrt 2 = 1.00."""
    def records(errors):
        rows = []
        for seed, e in zip((1, 2), errors):
            row = {"seed": seed, "pairs": 3, "CD0_truth": 0.5, "CD0_mean": 0.5 * (1 + e / 100), "CD0_sd": 0.02}
            for q in ("KD", "F1_N_per_kph", "F2_N_per_kph2"):
                row.update({f"{q}_truth": 1.0, f"{q}_mean": 1.0})
            rows.append(row)
        return pd.DataFrame(rows)

    table = refits.compare(records([-10.0, -4.0]), records([-8.0, -4.0]))
    seed1 = next(x for x in table.splitlines() if x.startswith("| 1 |"))
    assert "-10.00 / -8.00" in seed1 and "4.00 / 4.00" in seed1
    assert "-7.00 / -6.00" in next(x for x in table.splitlines() if x.startswith("| mean |"))
    assert "+1.00 (1.00)" in next(x for x in table.splitlines() if x.startswith("| paired change"))


def test_by_effect_lists_each_withheld_effect_against_every_effect(refits):
    """Seed 7: C_D0 -10 % with every effect, -4 % without turbulence (change +6.00), -11 %
    without lift (-1.00): turbulence listed first."""
    rows = []
    for withheld, err in (("", -10.0), ("lift", -11.0), ("turbulence", -4.0)):
        row = {"seed": 7, "pairs": 1, "withheld": withheld, "CD0_truth": 0.5, "CD0_mean": 0.5 * (1 + err / 100)}
        for q in ("F2_N_per_kph2", "F1_N_per_kph", "KD"):
            row.update({f"{q}_truth": 1.0, f"{q}_mean": 1.0})
        rows.append(row)
    table = refits.by_effect(pd.DataFrame(rows))
    assert "every effect CD0 -10.00 %" in table
    body = [x for x in table.splitlines() if x.startswith("| ") and not x.startswith("| withheld")]
    assert [x.split("|")[1].strip() for x in body] == ["turbulence", "lift"]
    assert body[0].split("|")[2].strip() == "+6.00"
    assert body[1].split("|")[2].strip() == "-1.00"


def test_by_realisation_sets_the_spread_between_realisations_against_the_posterior_sd(refits):
    """Seed 3001, three realisations with C_D0 errors -2, 0, +2 % and posterior sd 1 % of the
    truth: mean error +0.00, spread sd(-2, 0, 2) = 2.00, ratio 2.00, z -2, 0, 2 so sd(z) 2.00,
    and the +-2 % ones outside the 95 % interval (1 of 3 held); the campaign's conditions first."""
    rows = []
    for r, e in enumerate((-2.0, 0.0, 2.0)):
        row = {"seed": 3001, "pairs": 1, "realisation": r, "mean_abs_yaw_rad": 0.1 * (r + 1)}
        for q in refits.SPREAD_SHOWN:
            err = e if q == "CD0" else 0.0
            row.update({f"{q}_truth": 0.5, f"{q}_mean": 0.5 * (1 + err / 100), f"{q}_sd": 0.005,
                        f"{q}_in95": abs(err) < 1.96})
        rows.append(row)
    table = refits.by_realisation(pd.DataFrame(rows))
    cd0 = next(x for x in table.splitlines() if x.startswith("| 3001 |") and "| CD0 |" in x).split("|")
    assert [c.strip() for c in cd0[5:13]] == ["3", "+0.00", "2.00", "1.00", "2.00", "2.00", "1 / 3", "-2.0 to +2.0"]
    pooled = next(x for x in table.splitlines() if x.startswith("| CD0 |")).split("|")
    assert [c.strip() for c in pooled[2:10]] == ["1", "3", "0.00", "2.00", "1.00", "2.00", "2.00", "1 / 3"]
    # the campaign's conditions: the seed's own draws (as the campaign the study fitted), the
    # records' K_D truth and their mean logged yaw (0.1, 0.2, 0.3)
    from bayes_roadload.simulate.independent import simulate_independent

    meta = simulate_independent(3001, pairs=1).truth["meta"]
    conditions = next(x for x in table.splitlines() if x.startswith("| 3001 |")).split("|")
    assert [c.strip() for c in conditions[2:6]] == [meta["vehicle_true"]["category"], "0.50",
                                                    f"{meta['wind']['turbulence_sigma_mps']:.2f}", "0.200"]


def test_by_effect_over_realisations_pairs_each_realisation_with_its_own_every_effect_arm(refits):
    """Seed 5, two realisations: C_D0 -10 / -6 % with every effect, -7 / -1 % without lift
    (changes +3, +5: mean +4.00, SE sd(3, 5) / sqrt 2 = 1.00, arm's mean error -4.00)."""
    rows = []
    for r, (every, lift) in enumerate(((-10.0, -7.0), (-6.0, -1.0))):
        for withheld, err in (("", every), ("lift", lift)):
            row = {"seed": 5, "pairs": 1, "realisation": r, "withheld": withheld,
                   "CD0_truth": 0.5, "CD0_mean": 0.5 * (1 + err / 100)}
            for q in ("F2_N_per_kph2", "F1_N_per_kph", "KD"):
                row.update({f"{q}_truth": 1.0, f"{q}_mean": 1.0})
            rows.append(row)
    table = refits.by_effect_over_realisations(pd.DataFrame(rows))
    assert "2 realisations): every effect CD0 -8.00 %" in table
    lift = next(x for x in table.splitlines() if x.startswith("| lift |")).split("|")
    assert lift[2].strip() == "+4.00 (1.00)" and lift[6].strip() == "-4.00"
