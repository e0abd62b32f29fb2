"""Wall time of ``bayes-roadload plan`` with its defaults on a 12-pair hierarchical fit (the
issue's reference): thesis case 14, 12 pairs, seed 1 (``simulate --case 14 --pairs 12 --seed 1``),
fitted with ``fit`` and its defaults (hierarchical at 24 runs), then ``plan FIT_DIR --out DIR``
with every default (the sizes that locate each target by bisection among 9, 40 simulations
per size at most, one worker per usable core), timed from before the process starts to its
exit.  The record adds the refits per size, their mean time and the
compile time from ``plan_records.csv``, the recommendation, and each target's assurance and
simulations per size (``assurance``: quantity -> pairs -> [assurance, simulations]).

Records: ``benchmarks/records/performance/plan_time.jsonl`` (one line per run);
``docs/planning.md`` section 7 quotes them.  ``--refits N --pairs P`` instead times N refits of
P pairs in one process (time, compile time, resident memory, caches cleared), from the same
fit: the per-refit record (``plan_refits.jsonl``).

    python benchmarks/plan_time.py [--extra-args "--workers 2"]
    python benchmarks/plan_time.py --from-run DIR --wall-s S --note TEXT   # a run of the same
                                                                            # commands made by hand
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "benchmarks" / "records" / "performance" / "plan_time.jsonl"
REFIT_RECORDS = ROOT / "benchmarks" / "records" / "performance" / "plan_refits.jsonl"

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cli_process import run_cli  # noqa: E402


def reference_fit(tmp: Path) -> Path:
    """The issue's source fit: case 14, 12 pairs, seed 1, ``fit`` with its defaults."""
    run_cli(["simulate", "--case", "14", "--pairs", "12", "--seed", "1", "--out", tmp / "camp"])
    run_cli(["fit", tmp / "camp", "--out", tmp / "fit", "--no-progress", "--no-report"])
    return tmp / "fit"


def time_refits(fit_dir: Path, pairs: int, refits: int) -> list[dict]:
    """``refits`` planning refits of ``pairs`` pairs from ``fit_dir``'s posterior, one after the
    other in this process, as `plan` runs them (``batch.run_job``)."""
    sys.path.insert(0, str(ROOT))
    from bayes_roadload.analysis.batch import run_job
    from bayes_roadload.analysis.planning import plan_jobs, population_from_samples
    from bayes_roadload.data import load_campaign
    from bayes_roadload.output import read_fit_dir

    src = read_fit_dir(fit_dir)
    pop = population_from_samples(src.samples, src.record["free"], src.model, load_campaign(src.record["campaign"]),
                                  source=str(fit_dir))
    out = []
    for job in plan_jobs(pop, [pairs], simulations=refits):
        t0 = time.perf_counter()
        r = run_job(job)
        out.append({"pairs": pairs, "refit": job.tags["simulation"], "wall_s": round(time.perf_counter() - t0, 2),
                    "compile_s": round(float(r["time_compile_s"]), 2), "rss_mb": round(float(r["rss_mb"])),
                    "jax_caches_cleared": bool(r["jax_caches_cleared"]), "pareto_k": round(float(r["pareto_k"]), 3),
                    "error": r.get("error")})
    return out


def summarise(plan_dir: Path, wall_s: float, args: str, note: str = "") -> dict:
    """The record of one plan run from its output directory."""
    try:
        rec = pd.read_csv(plan_dir / "plan_records.csv")
    except pd.errors.EmptyDataError:   # no target reachable: nothing simulated
        rec = pd.DataFrame(columns=["n_pairs", "time_total_s", "time_compile_s", "rss_mb", "jax_caches_cleared",
                                    "error"])
    per_size = rec.groupby("n_pairs").agg(refits=("n_pairs", "size"), mean_s=("time_total_s", "mean"),
                                          compile_s=("time_compile_s", "sum"), max_rss_mb=("rss_mb", "max"),
                                          caches_cleared=("jax_caches_cleared", "sum"))
    recommendation = pd.read_csv(plan_dir / "recommendation.csv")
    return {
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "cpu_count": os.cpu_count(),
        "load_avg_1min_after": round(os.getloadavg()[0], 2), "plan_args": args, "wall_s": round(wall_s, 1),
        "target_s": 180.0, "refits": int(len(rec)), "errors": int(rec["error"].notna().sum()) if "error" in rec else 0,
        "refit_s": round(float(rec["time_total_s"].sum()), 1), "compile_s": round(float(rec["time_compile_s"].sum()), 1),
        "refits_compiling_over_3s": int((rec["time_compile_s"] > 3).sum()),
        "jax_caches_cleared": int(rec["jax_caches_cleared"].sum()),
        "sizes_simulated": sorted(int(n) for n in rec["n_pairs"].unique()),
        "per_size": {int(n): {k: round(float(v), 2) for k, v in r.items()} for n, r in per_size.iterrows()},
        "recommendation": {r["quantity"]: _answer(r) for _, r in recommendation.iterrows()},
        **({"type_b_floors": {r["quantity"]: round(float(r["type_b_half_width"]), 3)
                              for _, r in recommendation.iterrows()}} if "type_b_half_width" in recommendation else {}),
        "assurance": {q: {int(r["n_pairs"]): [round(float(r["assurance"]), 3), int(r["n_sims"])] for _, r in g.iterrows()}
                      for q, g in pd.read_csv(plan_dir / "plan.csv").groupby("quantity")},
        "note": note}


def _answer(row) -> int | str:
    """A recommendation row as the plan prints it: the pairs, "> N" (not reached by the largest
    size simulated) or "none (Type B floor)" (not reachable at any size)."""
    if row["reached"]:
        return int(row["n_pairs"])
    if "reachable" in row and not bool(row["reachable"]):
        return "none (Type B floor)"
    return f"> {int(row['max_pairs_simulated'])}"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--extra-args", default="", help="options added to `plan` (default: none, its defaults)")
    p.add_argument("--from-run", type=Path, default=None, help="summarise a plan output directory instead")
    p.add_argument("--wall-s", type=float, default=None)
    p.add_argument("--note", default="")
    p.add_argument("--refits", type=int, default=None, help="time this many refits of --pairs pairs instead")
    p.add_argument("--pairs", type=int, default=24)
    p.add_argument("--fit-dir", type=Path, default=None, help="the source fit (default: fitted anew)")
    a = p.parse_args()
    if a.refits is not None:
        with tempfile.TemporaryDirectory(prefix="plan_refits_") as tmp:
            rows = time_refits(a.fit_dir or reference_fit(Path(tmp)), a.pairs, a.refits)
        stamp = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "load_avg_1min_after": round(os.getloadavg()[0], 2),
                 "note": a.note}
        REFIT_RECORDS.parent.mkdir(parents=True, exist_ok=True)
        with REFIT_RECORDS.open("a") as f:
            for row in rows:
                f.write(json.dumps({**stamp, **row}) + "\n")
        print(json.dumps(rows, indent=1))
        return
    if a.from_run is not None:
        if a.wall_s is None:
            sys.exit("--from-run needs --wall-s")
        record = summarise(a.from_run, a.wall_s, a.extra_args, a.note)
    else:
        with tempfile.TemporaryDirectory(prefix="plan_time_") as tmp:
            tmp = Path(tmp)
            fit_dir = a.fit_dir or reference_fit(tmp)
            wall, _ = run_cli(["plan", fit_dir, "--out", tmp / "plan", *shlex.split(a.extra_args)])
            record = summarise(tmp / "plan", wall, a.extra_args, a.note)
    RECORDS.parent.mkdir(parents=True, exist_ok=True)
    with RECORDS.open("a") as f:
        f.write(json.dumps(record) + "\n")
    print(json.dumps(record, indent=1))


if __name__ == "__main__":
    main()
