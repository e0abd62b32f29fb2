"""benchmarks/cup_overspeeding.py: its tables of the drag read from the anemometer (summary only;
the per-run rows come from the independent simulator, which its own tests cover)."""

import numpy as np
import pandas as pd
import pytest

from .conftest import benchmark_script


@pytest.fixture(scope="module")
def cup():
    with benchmark_script("cup_overspeeding") as module:
        yield module


def _rows(cup, seeds, biases, yaw):
    rows = []
    for seed, bias, y in zip(seeds, biases, yaw):
        row = {"seed": seed, "run": 1, "category": "small_car" if seed % 2 else "heavy_truck", "rms_yaw_deg": y}
        for way in cup.WAYS:
            value = 0.0 if way == "air" else bias
            row.update({f"{way}_pct": value, f"{way}_low_pct": 2 * value, f"{way}_high_pct": value / 2})
        rows.append(row)
    return pd.DataFrame(rows)


def _cells(table, label):
    line = next(x for x in table.splitlines() if x.startswith(f"| {label} |"))
    return [c.strip() for c in line.strip("|").split("|")]


def test_the_means_by_category_and_overall(cup):
    """Seeds 1, 3 (small cars) read +1 and +3 %, seeds 2, 4 (heavy trucks) +2 and +6 %: the cars'
    mean +2.00 (low 2x, high x/2), the trucks' +4.00, all +3.00; the air way reads 0."""
    table = cup.summary(_rows(cup, [1, 2, 3, 4], [1.0, 2.0, 3.0, 6.0], [1.0, 2.0, 3.0, 4.0]))
    assert _cells(table, "small_car")[1:3] == ["2", "+0.00 / +0.00 / +0.00"]
    assert _cells(table, "small_car")[3] == "+2.00 / +4.00 / +1.00"
    assert _cells(table, "heavy_truck")[3] == "+4.00 / +8.00 / +2.00"
    assert _cells(table, "all")[1] == "4"
    assert _cells(table, "all")[3] == "+3.00 / +6.00 / +1.50"


def test_the_yaw_quartiles_hold_every_run_once(cup):
    rows = _rows(cup, range(1, 9), np.arange(1.0, 9.0), np.arange(1.0, 9.0))
    table = cup.summary(rows)
    counts = [int(_cells(table, label)[1]) for label in
              (x.split("|")[1].strip() for x in table.splitlines() if x.startswith("| rms yaw"))]
    assert counts == [2, 2, 2, 2]


def test_the_probe_table_pairs_each_seed_and_correlates_its_change(cup):
    """Seeds whose C_D0 moves by +1, +2, +3 % of the truth when the dynamics are withheld, with
    cup biases (above 20 m/s) 0.5, 1, 1.5: mean change +2.00, correlation +1.00."""
    rows = _rows(cup, [1, 2, 3], [1.0, 2.0, 3.0], [1.0, 2.0, 3.0])
    truth = np.array([0.4, 0.5, 0.6])
    first = pd.DataFrame({"seed": [1, 2, 3], "CD0_truth": truth, "CD0_mean": truth})
    second = first.assign(CD0_mean=truth * (1 + np.array([0.01, 0.02, 0.03])))
    for q in ("KD", "F2_N_per_kph2", "F1_N_per_kph"):
        first[f"{q}_truth"] = first[f"{q}_mean"] = second[f"{q}_truth"] = 1.0
        second[f"{q}_mean"] = [1.0, 1.01, 1.0]
    table = cup.summary(rows, probe=(first, second))
    assert _cells(table, "CD0") == ["CD0", "+2.00", "+1.00"]
