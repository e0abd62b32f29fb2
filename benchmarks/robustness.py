"""Long run of the robustness suite (tests/robustness/draws.py): ``--n`` valid draws and
``--n-invalid`` invalid ones fitted through the command line, one record per draw in
``benchmarks/records/robustness/<name>.csv`` (draw parameters, outcome, exit code, time,
message), written after every draw so an interrupted run keeps its records.

    nice python benchmarks/robustness.py --n 1000 --n-invalid 200 --name long
    nice python benchmarks/robustness.py --budget-s 1200 --draw-timeout-s 300 --name short
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

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


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=1000, help="valid draws")
    p.add_argument("--n-invalid", type=int, default=200, help="invalid draws")
    p.add_argument("--first-seed", type=int, default=10_000)
    p.add_argument("--budget-s", type=float, default=None, help="stop after this much wall time")
    p.add_argument("--name", default="long")
    p.add_argument("--draw-timeout-s", type=float, default=None,
                   help="run each draw in a child process and stop it after this long (outcome 'timeout')")
    a = p.parse_args(argv)
    out = ROOT / "benchmarks" / "records" / "robustness" / f"{a.name}.csv"
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
    with tempfile.TemporaryDirectory() as tmp:
        for d in plan:
            if a.budget_s is not None and time.perf_counter() - t0 > a.budget_s:
                break
            rec = run_with_timeout(d, Path(tmp), a.draw_timeout_s)
            records.append(rec)
            pd.DataFrame(records).to_csv(out, index=False)
            print(f"{len(records):4d} {rec['kind']:9s} {rec['invalid'] or rec['method']:16s} {rec['outcome']:14s} "
                  f"{rec['time_s']:7.1f} s {rec['message'][:80]}", flush=True)
    df = pd.DataFrame(records)
    failures = df["outcome"].str.startswith("FAILURE")
    print(f"\n{len(df)} draws ({(df['invalid'] == '').sum()} valid, {(df['invalid'] != '').sum()} invalid) in "
          f"{time.perf_counter() - t0:.0f} s; failures {int(failures.sum())}; -> {out}")
    return 1 if failures.any() else 0


if __name__ == "__main__":
    sys.exit(main())
