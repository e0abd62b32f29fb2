"""Long run of the robustness suite (tests/robustness/draws.py): ``--n`` valid draws and
``--n-invalid`` invalid ones fitted through the command line, one record per draw in
``benchmarks/records/robustness/<name>.csv`` (draw parameters, outcome, exit code, time,
message), written after every draw so an interrupted run keeps its records.  The draws go
through the project's batch door (:func:`bayes_roadload.analysis.batch.batch_map`): one after
the other in this process by default, on a Dask ``LocalCluster`` with ``--workers N``, or on a
running cluster with ``--scheduler ADDR``; each draw then runs in a child process of its worker,
stopped after ``--draw-timeout-s``.

    nice python benchmarks/robustness.py --n 1000 --n-invalid 200 --name long
    nice python benchmarks/robustness.py --budget-s 1200 --draw-timeout-s 300 --name short
    nice python benchmarks/robustness.py --budget-s 3600 --draw-timeout-s 600 --workers 2 --name long_f
    python benchmarks/robustness.py --summarise --docs   # every record file -> docs/robustness.md
"""

from __future__ import annotations

import argparse
import functools
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.analysis.batch import batch_client, batch_map  # noqa: E402
from doc_sections import replace_section  # noqa: E402
from tests.robustness.draws import draw, run_draw  # noqa: E402


def run_with_timeout(d: dict, workdir: Path, timeout_s: float | None) -> dict:
    """:func:`run_draw` in a child process, stopped after ``timeout_s`` (outcome "timeout":
    not an exception, but no fit within the limit either)."""
    if timeout_s is None:
        return run_draw(d, workdir)
    code = ("import json, sys; sys.path.insert(0, sys.argv[1]); from tests.robustness.draws import run_draw; "
            "print('RECORD ' + json.dumps(run_draw(json.loads(sys.argv[2]), sys.argv[3])))")
    t0 = time.perf_counter()
    try:
        done = subprocess.run([sys.executable, "-c", code, str(ROOT), json.dumps(d), str(workdir)],
                              capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return dict(d, outcome="timeout", rc=None, time_s=round(time.perf_counter() - t0, 2),
                    message=f"no result within {timeout_s:g} s")
    lines = [x for x in done.stdout.splitlines() if x.startswith("RECORD ")]
    if not lines:
        return dict(d, outcome=f"FAILURE: child exited {done.returncode}", rc=None,
                    time_s=round(time.perf_counter() - t0, 2), message=done.stderr.strip()[-300:])
    return json.loads(lines[-1][len("RECORD "):])


RECORDS = ROOT / "benchmarks" / "records" / "robustness"
DOC = ROOT / "docs" / "robustness.md"
MARK_BEGIN, MARK_END = "<!-- robustness:begin -->", "<!-- robustness:end -->"
OUTCOMES = (("fitted", "fitted (exit 0)"), ("gates_failed", "gates failed, said so (exit 3)"),
            ("refused", "refused (exit 2)"), ("timeout", "timeout"), ("FAILURE", "failure"))


def summarise(records: pd.DataFrame, files: list[str]) -> str:
    """Markdown summary of the records of every run: totals (exceptions and wrong exit codes
    are both failures), outcomes by class and kind, invalid draws by damage, time per draw."""
    df = records.copy()
    df["invalid"] = df["invalid"].fillna("").astype(str)
    df["class"] = (df["invalid"] != "").map({True: "invalid", False: "valid"})
    df["outcome_class"] = df["outcome"].where(~df["outcome"].str.startswith("FAILURE"), "FAILURE")
    failed = df[df["outcome_class"] == "FAILURE"]
    exceptions = failed["message"].fillna("").str.contains("Error|Exception|Traceback", regex=True)
    lines = [f"Records: {', '.join(f'`{f}`' for f in files)}.  **{len(df)} draws, "
             f"{int((df['class'] == 'valid').sum())} valid and {int((df['class'] == 'invalid').sum())} invalid: "
             f"{int(exceptions.sum())} exceptions, {int((~exceptions).sum())} wrong exit codes, "
             f"{int((df['outcome'] == 'timeout').sum())} timeouts**; {df['time_s'].sum() / 60:.0f} min of draw "
             "wall time.", "",
             "| class | kind | " + " | ".join(label for _, label in OUTCOMES) + " |",
             "| --- | --- | " + " | ".join("---:" for _ in OUTCOMES) + " |"]
    for (cls, kind), g in df.groupby(["class", "kind"]):
        counts = g["outcome_class"].value_counts()
        lines.append(f"| {cls} | {kind} | " + " | ".join(str(int(counts.get(k, 0))) for k, _ in OUTCOMES) + " |")
    inv = df[df["class"] == "invalid"]
    if len(inv):
        by = inv.groupby("invalid")["outcome_class"].agg(lambda o: f"{int((o == 'refused').sum())} / {len(o)}")
        lines += ["", "Invalid draws refused, by kind of damage: "
                  + ", ".join(f"{k} {v}" for k, v in by.items()) + "."]
    parts = []
    for label, g in (("lsq", df[(df["class"] == "valid") & (df["method"] == "lsq")]),
                     ("nuts", df[(df["class"] == "valid") & (df["method"] == "nuts")]),
                     ("refusal", inv)):
        if len(g):
            parts.append(f"{label} median {g['time_s'].median():.1f}, max {g['time_s'].max():.1f} ({len(g)} draws)")
    lines += ["", "Time per draw (s, simulation + fit; in a child process, imports included, where a time limit was set): "
              + "; ".join(parts) + "."]
    if len(failed):
        lines += ["", "Failures:", ""] + [f"* seed {int(r.seed)} ({r.kind}, {r.invalid or r.method}): {r.outcome}; "
                                          f"{str(r.message)[:160]}" for r in failed.itertuples()]
    slow = df[df["outcome"] == "timeout"]
    if len(slow):
        lines += ["", "Timeouts (no exception, no fit within the limit): " + "; ".join(
            f"seed {int(r.seed)} {r.kind} {r.vehicle} {r.pairs} pair(s) at {r.rate_hz:g} Hz, {r.model}, "
            f"measurement noise {'on' if r.measurement_noise else 'off'}" for r in slow.itertuples()) + "."]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=1000, help="valid draws")
    p.add_argument("--n-invalid", type=int, default=200, help="invalid draws")
    p.add_argument("--first-seed", type=int, default=10_000)
    p.add_argument("--budget-s", type=float, default=None, help="stop after this much wall time")
    p.add_argument("--name", default="long")
    p.add_argument("--draw-timeout-s", type=float, default=None,
                   help="run each draw in a child process and stop it after this long (outcome 'timeout')")
    p.add_argument("--workers", type=int, default=1,
                   help="draws at once on a local Dask cluster (default 1: one after the other, no cluster)")
    p.add_argument("--scheduler", default=None, help="address of a running Dask scheduler (tcp://host:8786)")
    p.add_argument("--summarise", action="store_true", help="summarise every record file instead of drawing")
    p.add_argument("--docs", action="store_true", help="with --summarise: regenerate docs/robustness.md's section")
    a = p.parse_args(argv)
    if a.summarise:
        files = sorted(RECORDS.glob("*.csv"))
        text = summarise(pd.concat([pd.read_csv(f) for f in files], ignore_index=True),
                         [str(f.relative_to(ROOT)) for f in files])
        print(text)
        if a.docs:
            replace_section(DOC, MARK_BEGIN, MARK_END, text)
        return 0
    out = RECORDS / f"{a.name}.csv"
    out.parent.mkdir(parents=True, exist_ok=True)
    # invalid draws interleaved (one in every (n + n_invalid) / n_invalid) so a budgeted run covers both
    plan = []
    every = max(1, round((a.n + a.n_invalid) / max(a.n_invalid, 1)))
    vi = ii = 0
    while vi < a.n or ii < a.n_invalid:
        if ii < a.n_invalid and (len(plan) % every == every - 1 or vi >= a.n):
            plan.append(draw(a.first_seed + 100_000 + ii, invalid=True))
            ii += 1
        else:
            plan.append(draw(a.first_seed + vi))
            vi += 1
    records, t0 = [], time.perf_counter()
    parallel = a.workers > 1 or a.scheduler is not None
    # on a cluster every draw runs in a child process of its worker (a time limit, and a crash
    # of the fit cannot take the worker down)
    timeout_s = a.draw_timeout_s if a.draw_timeout_s is not None or not parallel else 3600.0

    def record(rec: dict) -> None:
        records.append(rec)
        pd.DataFrame(records).to_csv(out, index=False)
        print(f"{len(records):4d} {rec['seed']:7d} {rec['kind']:9s} {rec['invalid'] or rec['method']:16s} "
              f"{rec['outcome']:14s} {rec['time_s']:7.1f} s {str(rec['message'])[:80]}", flush=True)

    chunk = max(2 * a.workers, 1) if parallel else 1  # the budget is checked between chunks
    with tempfile.TemporaryDirectory() as tmp, batch_client(a.workers, a.scheduler) as client:
        run = functools.partial(run_with_timeout, workdir=Path(tmp), timeout_s=timeout_s)
        for start in range(0, len(plan), chunk):
            if a.budget_s is not None and time.perf_counter() - t0 > a.budget_s:
                break
            batch_map(run, plan[start:start + chunk], client, progress=False, on_result=record,
                      on_error=lambda d, exc, tb: dict(d, outcome=f"FAILURE: {type(exc).__name__}", rc=None,
                                                       time_s=float("nan"), message=str(exc)[:300]))
    df = pd.DataFrame(records)
    failures = df["outcome"].str.startswith("FAILURE")
    print(f"\n{len(df)} draws ({(df['invalid'] == '').sum()} valid, {(df['invalid'] != '').sum()} invalid) in "
          f"{time.perf_counter() - t0:.0f} s; failures {int(failures.sum())}; -> {out}")
    return 1 if failures.any() else 0


if __name__ == "__main__":
    sys.exit(main())
