"""The shared checks and file helpers of every data kind."""

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.data.checks import (
    CampaignError,
    check_wheel_torque_pair,
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
