"""Tests of fleet fitting (:mod:`bayes_roadload.analysis.fleet`): every campaign under a
directory fitted on a 2-worker Dask ``LocalCluster`` by least squares (a few seconds per fit),
resumed through the ``batch`` command connected to that cluster by its address, and a
refused campaign recorded while the others finish.
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings

import pandas as pd
import pytest

from bayes_roadload import cli
from bayes_roadload.analysis.batch import batch_client
from bayes_roadload.analysis.fleet import (FIT_STATUS, LOG_FILE, MARKER_FILE, TABLE_COLUMNS, TABLE_FILE,
                                           add_batch_parser, find_campaigns, fit_fleet)
from bayes_roadload.data import save_campaign
from bayes_roadload.simulate import simulate_campaign

from ..conftest import clean_case

LSQ = ("--method", "lsq", "--model", "three_term", "--no-report", "--no-progress")
"""The fit options of the fleet: what the batch command passes for ``--method lsq --model
three_term`` (it adds ``--no-progress``), so that its run resumes the fixture's."""


def batch_parser() -> argparse.ArgumentParser:
    """The command line with ``batch`` wired in as the command-line module wires it."""
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    if "batch" not in sub.choices:
        add_batch_parser(sub, fit_command=cli.main, fit_parser=sub.choices["fit"])
    return parser


@pytest.fixture(scope="module")
def fleet_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("fleet")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        save_campaign(simulate_campaign(clean_case(), pairs=1, seed=1), root / "carA" / "day1")
        save_campaign(simulate_campaign(clean_case(), pairs=1, seed=2), root / "carB")
        save_campaign(simulate_campaign(clean_case(), pairs=1, seed=3), root / "bad")
    (root / "bad" / "vehicle.toml").unlink()  # refused by the loader: the vehicle is missing
    (root / "notes").mkdir()
    (root / "notes" / "readme.txt").write_text("not a campaign\n")
    return root


@pytest.fixture(scope="module")
def client():
    with batch_client(workers=2) as c:
        yield c


@pytest.fixture(scope="module")
def first(fleet_root, client, tmp_path_factory):
    out = tmp_path_factory.mktemp("fits")
    return fit_fleet(fleet_root, out, LSQ, fit_command=cli.main, client=client, progress=False), out


def test_find_campaigns(fleet_root, tmp_path):
    found = find_campaigns(fleet_root)
    assert [p.relative_to(fleet_root).as_posix() for p in found] == ["bad", "carA/day1", "carB"]
    # an output directory inside the root is not searched, nor is anything below a campaign
    (fleet_root / "carB" / "old").mkdir(exist_ok=True)
    (tmp_path / "out" / "x").mkdir(parents=True)
    (tmp_path / "out" / "x" / "runs.csv").write_text("")
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "steady.csv").write_text("")
    assert find_campaigns(tmp_path, exclude=[tmp_path / "out"]) == [tmp_path / "c"]


def test_table_rows_and_statuses(first):
    table, out = first
    assert list(table.columns[: len(TABLE_COLUMNS)]) == list(TABLE_COLUMNS)
    rows = table.set_index("campaign")
    assert list(rows.index) == ["bad", "carA/day1", "carB"]
    assert list(rows["status"]) == ["refused", "passed", "passed"]
    assert list(rows["rc"]) == [2, 0, 0]
    assert "vehicle.toml" in rows.loc["bad", "error"]
    assert (rows["kind"] == "traces").all()
    for q in ("AD", "BD", "CD0", "F50_N"):
        ok = rows.loc[["carA/day1", "carB"]]
        assert (ok[f"{q}_q2.5"] <= ok[f"{q}_mean"]).all() and (ok[f"{q}_mean"] <= ok[f"{q}_q97.5"]).all(), q
        assert rows.loc["bad", [f"{q}_mean"]].isna().all()
    assert "KD_mean" not in rows  # not a parameter of three_term
    written = pd.read_csv(out / TABLE_FILE)
    assert list(written["campaign"]) == list(table["campaign"])
    assert (out / "bad" / LOG_FILE).read_text().strip().endswith(rows.loc["bad", "error"])


def test_outputs_identical_to_a_single_fit(first, fleet_root, tmp_path):
    _, out = first
    rc = cli.main(["fit", str(fleet_root / "carB"), "--out", str(tmp_path / "single"), *LSQ])
    assert rc == 0
    assert (tmp_path / "single" / "summary.csv").read_bytes() == (out / "carB" / "summary.csv").read_bytes()
    # the per-pair fits too, but for their wall time
    single, fleet = (pd.read_csv(d / "per_group.csv").drop(columns="fit_time_s") for d in (tmp_path / "single",
                                                                                          out / "carB"))
    pd.testing.assert_frame_equal(single, fleet, check_exact=True)


def test_resume_through_the_command_and_a_scheduler_address(first, fleet_root, client, capsys):
    _, out = first
    address = client.scheduler_info()["address"]
    stamps = {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file() and p.name != TABLE_FILE}
    before = (out / TABLE_FILE).read_bytes()
    args = batch_parser().parse_args(["batch", str(fleet_root), "--out", str(out), "--method", "lsq", "--model",
                                      "three_term", "--no-report", "--scheduler", address])
    assert args.fit_args == ["--method", "lsq", "--model", "three_term", "--no-report"]
    rc = args.func(args)
    assert rc == 2  # the one failure was refused: the fit command's exit code
    printed = capsys.readouterr().out
    assert address in printed and "2 passed, 1 refused" in printed
    # nothing was fitted again: every file but the table is untouched, and the table is the same
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps
    assert (out / TABLE_FILE).read_bytes() == before
    marker = json.loads((out / "carB" / MARKER_FILE).read_text())
    assert marker["fit_args"] == list(LSQ) and marker["rc"] == 0


def _cache_dir_of_worker():
    import jax

    return jax.config.jax_compilation_cache_dir


def test_local_workers_share_this_process_s_compilation_cache(client):
    """The suite turns the persistent cache on in this process (conftest); every local worker
    uses the same directory, so what one compiles the others load."""
    from bayes_roadload.analysis.batch import compilation_cache_dir

    assert compilation_cache_dir()
    per_worker = client.run(_cache_dir_of_worker)
    assert len(per_worker) == 2 and set(per_worker.values()) == {compilation_cache_dir()}


def _malloc_trim_of_worker():
    import os

    return os.environ.get("MALLOC_TRIM_THRESHOLD_")


def test_local_workers_keep_glibc_s_dynamic_mmap_threshold(client):
    """Dask's nanny sets ``MALLOC_TRIM_THRESHOLD_`` in its workers, which turns off glibc's
    dynamic mmap threshold; the batch door's local workers are started without it
    (``batch.NANNY_ENVIRON_UNSET``)."""
    assert set(client.run(_malloc_trim_of_worker).values()) == {None}


def _timed(item):
    import time

    start = time.time()
    time.sleep(0.3)
    return item, start, time.time()


def test_lead_runs_each_key_s_first_item_before_the_others(client):
    """``batch_map(..., lead=key)``: the first item of each key finishes before any other item
    of that key starts (its programs compiled once, then loaded from the persistent cache),
    the keys' first items run side by side, and the results keep the items' order."""
    from bayes_roadload.analysis.batch import batch_map

    items = [("a", 0), ("b", 0), ("a", 1), ("a", 2), ("b", 1)]
    out = batch_map(_timed, items, client, progress=False, lead=lambda item: item[0])
    assert [r[0] for r in out] == items
    by = {item: (start, end) for item, start, end in out}
    for key in ("a", "b"):
        leader_end = by[(key, 0)][1]
        assert all(by[i][0] >= leader_end for i in items if i[0] == key and i[1] > 0)
    assert by[("a", 0)][0] < by[("b", 0)][1] and by[("b", 0)][0] < by[("a", 0)][1]  # side by side


def test_options_are_checked_and_passed_through():
    parser = batch_parser()
    args = parser.parse_args(["batch", "d", "--out", "o", "--workers", "2", "--chains", "2", "--robust",
                              "--warmup", "200"])
    assert args.fit_args == ["--chains", "2", "--robust", "--warmup", "200"] and args.workers == 2
    with pytest.raises(SystemExit):
        parser.parse_args(["batch", "d", "--out", "o", "--method", "bayes"])  # not a choice of fit
    with pytest.raises(SystemExit):
        parser.parse_args(["batch", "d", "--out", "o", "--draws", "many"])  # not an int


def test_status_follows_the_fit_commands_exit_codes():
    assert FIT_STATUS == {0: "passed", cli.EXIT_REFUSED: "refused", cli.EXIT_GATES_FAILED: "gates failed"}


def _fake_fit(argv):
    """A fit command whose outcome is the campaign directory's name."""
    name = argv[1].rsplit("/", 1)[-1]
    print(f"fitting {name}")
    if name == "crash":
        raise RuntimeError("boom")
    if name == "gates":
        sys.exit(3)
    return 0


def test_failures_recorded_and_only_finished_campaigns_skipped(tmp_path):
    root = tmp_path / "root"
    for name in ("crash", "gates", "ok"):
        (root / name).mkdir(parents=True)
        (root / name / "runs.csv").write_text("")
    out = tmp_path / "out"
    table = fit_fleet(root, out, ["--x"], fit_command=_fake_fit, progress=False).set_index("campaign")
    assert list(table["status"]) == ["error", "gates failed", "passed"]
    assert table.loc["crash", "error"] == "RuntimeError: boom" and pd.isna(table.loc["crash", "rc"])
    assert "fitting crash" in (out / "crash" / LOG_FILE).read_text()
    assert not (out / "crash" / MARKER_FILE).exists() and (out / "gates" / MARKER_FILE).exists()
    # a rerun retries the crashed campaign only; other options refit everything
    (out / "ok" / LOG_FILE).unlink()
    fit_fleet(root, out, ["--x"], fit_command=_fake_fit, progress=False)
    assert (out / "crash" / LOG_FILE).exists() and not (out / "ok" / LOG_FILE).exists()
    fit_fleet(root, out, ["--y"], fit_command=_fake_fit, progress=False)
    assert (out / "ok" / LOG_FILE).exists()
