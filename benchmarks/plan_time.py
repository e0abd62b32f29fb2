"""Wall time of ``bayes-roadload plan`` with its defaults on a 12-pair hierarchical fit (the
issue's reference): thesis case 14, 12 pairs, seed 1 (``simulate --case 14 --pairs 12 --seed 1``),
fitted with ``fit`` and its defaults (hierarchical at 24 runs), then ``plan FIT_DIR --out DIR``
with every default (9 sizes, 40 simulations per size at most, one worker), timed from before
the process starts to its exit.  The record adds the refits per size, their mean time and the
compile time from ``plan_records.csv``, and the recommendation.

Records: ``benchmarks/records/performance/plan_time.jsonl`` (one line per run);
``docs/planning.md`` section 7 quotes them.

    python benchmarks/plan_time.py [--extra-args "--workers 2"]
    python benchmarks/plan_time.py --from-run DIR --wall-s S --note TEXT   # a run of the same
                                                                            # commands made by hand
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "benchmarks" / "records" / "performance" / "plan_time.jsonl"


def summarise(plan_dir: Path, wall_s: float, args: str, note: str = "") -> dict:
    """The record of one plan run from its output directory."""
    rec = pd.read_csv(plan_dir / "plan_records.csv")
    per_size = rec.groupby("n_pairs").agg(refits=("n_pairs", "size"), mean_s=("time_total_s", "mean"),
                                          compile_s=("time_compile_s", "sum"))
    recommendation = pd.read_csv(plan_dir / "recommendation.csv")
    return {
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "cpu_count": os.cpu_count(),
        "load_avg_1min_after": round(os.getloadavg()[0], 2), "plan_args": args, "wall_s": round(wall_s, 1),
        "target_s": 180.0, "refits": int(len(rec)), "errors": int(rec["error"].notna().sum()) if "error" in rec else 0,
        "per_size": {int(n): {k: round(float(v), 2) for k, v in r.items()} for n, r in per_size.iterrows()},
        "recommendation": {r["quantity"]: (int(r["n_pairs"]) if r["reached"] else f"> {int(r['max_pairs_simulated'])}")
                           for _, r in recommendation.iterrows()},
        "note": note}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--extra-args", default="", help="options added to `plan` (default: none, its defaults)")
    p.add_argument("--from-run", type=Path, default=None, help="summarise a plan output directory instead")
    p.add_argument("--wall-s", type=float, default=None)
    p.add_argument("--note", default="")
    a = p.parse_args()
    if a.from_run is not None:
        if a.wall_s is None:
            sys.exit("--from-run needs --wall-s")
        record = summarise(a.from_run, a.wall_s, a.extra_args, a.note)
    else:
        with tempfile.TemporaryDirectory(prefix="plan_time_") as tmp:
            tmp = Path(tmp)
            cli = [sys.executable, "-m", "bayes_roadload"]
            subprocess.run(cli + ["simulate", "--case", "14", "--pairs", "12", "--seed", "1", "--out", str(tmp / "camp")],
                           check=True, capture_output=True)
            subprocess.run(cli + ["fit", str(tmp / "camp"), "--out", str(tmp / "fit"), "--no-progress", "--no-report"],
                           check=True, capture_output=True)
            t0 = time.perf_counter()
            subprocess.run(cli + ["plan", str(tmp / "fit"), "--out", str(tmp / "plan"), *shlex.split(a.extra_args)],
                           check=True, capture_output=True)
            record = summarise(tmp / "plan", time.perf_counter() - t0, a.extra_args, a.note)
    RECORDS.parent.mkdir(parents=True, exist_ok=True)
    with RECORDS.open("a") as f:
        f.write(json.dumps(record) + "\n")
    print(json.dumps(record, indent=1))


if __name__ == "__main__":
    main()
