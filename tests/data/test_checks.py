"""The shared checks and file helpers of every data kind."""

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.data.checks import (
    CampaignError,
    check_pair_groups,
    check_wheel_torque_pair,
    pairs_by_column,
    read_truth,
    refuse,
    run_rows,
    truth_files,
    write_atomically,
)


def test_refusal_names_file_column_and_row():
    with pytest.raises(CampaignError, match=r"^runs.csv, column 'speed_mps', row 3: too fast$"):
        refuse("runs.csv", "speed_mps", 3, "too fast")
    with pytest.raises(CampaignError, match=r"^runs.csv: no samples$"):
        refuse("runs.csv", None, None, "no samples")


def test_run_rows_in_file_order_as_python_values():
    df = pd.DataFrame({"run": np.array([7, 7, 3, 3, 3], dtype=np.int64)})
    rows = list(run_rows(df))
    assert [r for r, _ in rows] == [7, 3] and all(type(r) is int for r, _ in rows)
    np.testing.assert_array_equal(rows[1][1], [2, 3, 4])


def test_one_wheel_torque_is_refused_naming_the_other():
    assert check_wheel_torque_pair(["run", "speed_mps"], "f.csv") == []
    with pytest.raises(CampaignError, match="column 'wheel_torque_right_nm'.*both the left and the right"):
        check_wheel_torque_pair(["wheel_torque_left_nm"], "f.csv")


def test_write_atomically_replaces_stale_files_and_keeps_others(tmp_path):
    root = tmp_path / "c"
    root.mkdir()
    (root / "old.csv").write_text("old")
    (root / "notes.txt").write_text("kept")
    write_atomically(root, {"a.csv": "x,y\n", "b.bin": b"\x00\x01"}, stale=("old.csv",))
    assert sorted(p.name for p in root.iterdir()) == ["a.csv", "b.bin", "notes.txt"]
    assert (root / "b.bin").read_bytes() == b"\x00\x01" and (root / "a.csv").read_text() == "x,y\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c"]  # no temporary directory left


def test_write_atomically_changes_nothing_when_a_file_fails(tmp_path):
    root = tmp_path / "c"
    root.mkdir()
    (root / "old.csv").write_text("old")
    with pytest.raises(TypeError):
        write_atomically(root, {"a.csv": "x\n", "b.csv": 3.0}, stale=("old.csv",))  # 3.0 is not text
    assert [p.name for p in root.iterdir()] == ["old.csv"] and (root / "old.csv").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c"]


def test_truth_round_trips_and_is_optional(tmp_path):
    assert truth_files(None) == {} and read_truth(tmp_path) is None
    write_atomically(tmp_path, truth_files({"CD0": 0.4, "AD": 1.5}))
    assert read_truth(tmp_path) == {"CD0": 0.4, "AD": 1.5}


# --------------------------------------------------------------------------- pair ids

def _pair_table(pairs, directions):
    return pd.DataFrame({"run": np.repeat(np.arange(1, len(pairs) + 1), 3), "pair": np.repeat(pairs, 3),
                         "direction": np.repeat(directions, 3)})


def test_pair_id_of_three_runs_is_refused_at_its_third_run():
    with pytest.raises(CampaignError, match=r"^f.csv, column 'pair', row 7: pair id 1 is held by 3 runs \(1, 2, 3\)"):
        check_pair_groups(_pair_table([1, 1, 1, 2], [1, -1, 1, -1]), "f.csv")


def test_pair_of_one_direction_is_refused_naming_both_runs():
    with pytest.raises(CampaignError, match=r"^f.csv, column 'pair', row 7: pair id 'A': runs 1 and 3 both have "
                       r"direction \+1"):
        check_pair_groups(_pair_table(["A", "B", "A", "B"], [1, -1, 1, -1]), "f.csv")


def test_pair_ids_accepted():
    """Opposite-direction pairs; a run alone under its id (left out of the pairs); without a
    direction column only the count is checked; split segments where the kind allows them."""
    check_pair_groups(_pair_table([1, 1, 2, 3], [1, -1, 1, -1]), "f.csv")
    assert pairs_by_column(_pair_table([1, 1, 2, 3], [1, -1, 1, -1])) == [(1, 2)]
    check_pair_groups(_pair_table([1, 1], [1, 1]).drop(columns="direction"), "f.csv")
    split = _pair_table([1, 1, 1, 1], [1, 1, -1, -1])
    check_pair_groups(split, "f.csv", split_segments=True)
    assert pairs_by_column(split) == []
    with pytest.raises(CampaignError, match="row 7: pair id 1 is held by 4 runs"):
        check_pair_groups(split, "f.csv")
    with pytest.raises(CampaignError, match="row 7: pair id 1 is held by 3 runs"):
        check_pair_groups(_pair_table([1, 1, 1], [1, -1, -1]), "f.csv", split_segments=True)


@pytest.mark.parametrize("kind", ["traces", "intervals", "distances", "steady"])
def test_every_kind_with_a_pair_column_checks_its_pairs(kind):
    """The same refusal in every kind that has a ``pair`` column (its validation calls
    :func:`check_pair_groups`)."""
    from bayes_roadload.data.distances import validate_distances
    from bayes_roadload.data.intervals import validate_intervals
    from bayes_roadload.data.steady import validate_steady
    from bayes_roadload.data.traces import validate_runs

    rows = []
    for r, (p, d) in enumerate(zip([1, 2, 1, 2], [1, -1, 1, -1]), start=1):
        for k in range(10):
            rows.append({"run": r, "pair": p, "direction": d, "time_s": 2.0 * k, "speed_mps": 30.0 - k,
                         "distance_m": 60.0 * k, "interval_s": 1.0, "speed_start_mps": 30.0 - k,
                         "speed_end_mps": 29.0 - k, "tractive_force_n": 500.0})
    df = pd.DataFrame(rows)
    validate = {"traces": lambda: validate_runs(df[["run", "pair", "direction", "time_s", "speed_mps"]], "f.csv"),
                "intervals": lambda: validate_intervals(df[["run", "pair", "direction", "interval_s", "speed_start_mps",
                                                            "speed_end_mps"]], "f.csv"),
                "distances": lambda: validate_distances(df[["run", "pair", "direction", "distance_m", "time_s"]],
                                                        "f.csv"),
                "steady": lambda: validate_steady(df[["run", "pair", "direction", "speed_mps", "tractive_force_n"]],
                                                  "f.csv")}[kind]
    with pytest.raises(CampaignError, match=r"f.csv, column 'pair', row 21: pair id 1: runs 1 and 3 both have"):
        validate()


def test_consecutive_pairs_follow_the_directions_when_logged():
    """Without a pair column, runs pair with the next run in file order; when the direction is
    logged only with the next run of the other direction (of two the same way, the first is left
    without a partner); without it (every run +1) consecutive runs as before."""
    from bayes_roadload.data.checks import consecutive_pairs

    ids = [1, 2, 3, 4, 5]
    assert consecutive_pairs(ids) == [(1, 2), (3, 4)]
    assert consecutive_pairs(ids, {1: 1, 2: 1, 3: -1, 4: -1, 5: 1}) == [(2, 3), (4, 5)]
    assert consecutive_pairs([1, 2], {1: 1, 2: 1}) == []


def test_a_campaign_without_a_pair_column_pairs_opposite_directions():
    from bayes_roadload.data import Campaign, Vehicle

    from .test_traces import runs_frame

    df = runs_frame(runs=4)
    df["direction"] = df["run"].map({1: 1, 2: 1, 3: -1, 4: 1})
    c = Campaign(df, Vehicle(1100.0, 1130.0, 1.85))
    assert c.pairs() == [(2, 3)]
    assert Campaign(df.drop(columns="direction"), Vehicle(1100.0, 1130.0, 1.85)).pairs() == [(1, 2), (3, 4)]
