"""Interval calibration of the default fit on campaigns of the independent simulator.

Each campaign is ``simulate_independent(seed, pairs=P)`` (``bayes_roadload.simulate.independent``:
its own integrator, wind field, instruments and vehicles, every nuisance effect, the Type B
errors drawn inside the standards' accuracies), P drawn uniformly in ``--pairs MIN MAX`` from the
seed.  Every campaign is fitted with the options ``bayes-roadload fit`` uses by default (model
``four_term``, the default pooling and noise of :class:`bayes_roadload.inference.kinds.FitOptions`,
the default sampler) through the batch door (:func:`bayes_roadload.analysis.batch.run_batch`).

The rules are frozen before the confirmatory seeds run (``docs/calibration.md``):

* quantities: AD, BD, CD0, KD, F50_N, F0_N, F1_N_per_kph, F2_N_per_kph2;
* pass: the 95 % intervals cover the truth in 92-98 % of the fits that ran, and the sd over
  fits of z = (mean - truth) / sd lies in [0.85, 1.15]; reported by quantity and by campaign
  size (1-2, 3-5, 6-12 pairs);
* design seeds (used while choosing the default analysis): 100-199; confirmatory seeds: from
  1000 on (``--seed0 1000``).

Writes every record to ``--records`` (CSV; a ``.partial.csv`` while running), prints the
summary as JSON and, with ``--docs``, regenerates the section of ``docs/calibration.md`` between
its markers.

    python benchmarks/calibration_study.py --n 200 --seed0 1000 --workers 2 --docs
"""

from __future__ import annotations

import argparse
import functools
import json
import re
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.analysis.batch import FitJob, batch_client, coverage_summary, run_batch  # noqa: E402
from bayes_roadload.inference.kinds import FitOptions  # noqa: E402
from bayes_roadload.simulate.independent import simulate_independent  # noqa: E402

RECORDS = ROOT / "docs" / "calibration" / "independent_records.csv"
DOC = ROOT / "docs" / "calibration.md"
QUANTITIES = ("AD", "BD", "CD0", "KD", "F50_N", "F0_N", "F1_N_per_kph", "F2_N_per_kph2")
DERIVED = ("F50_N", "F0_N", "F1_N_per_kph", "F2_N_per_kph2")
COVERAGE_TARGET = (0.92, 0.98)
Z_SD_TARGET = (0.85, 1.15)
SIZE_BINS = ((1, 2), (3, 5), (6, 12))
MARK_BEGIN = "<!-- calibration_study:begin -->"
MARK_END = "<!-- calibration_study:end -->"


def pairs_of(seed: int, lo: int, hi: int) -> int:
    """Pairs of campaign ``seed``: uniform in [lo, hi], from the seed alone."""
    return int(np.random.default_rng([seed, 7]).integers(lo, hi + 1))


def jobs_for(seeds, lo: int, hi: int, options: FitOptions) -> list[FitJob]:
    """One fit job per seed with the default fit options."""
    return [FitJob(f"ind-{s}", functools.partial(simulate_independent, s, pairs=pairs_of(s, lo, hi)),
                   pooling=options.pooling, noise=options.noise, robust=options.robust, sampler=options.sampler,
                   derived=DERIVED, tags={"seed": s, "pairs": pairs_of(s, lo, hi)})
            for s in seeds]


def size_bin(pairs: int) -> str:
    for lo, hi in SIZE_BINS:
        if lo <= pairs <= hi:
            return f"{lo}-{hi}"
    return "other"


def summarise(records: pd.DataFrame) -> pd.DataFrame:
    """95 % coverage and sd(z) by quantity, overall and by campaign size, with the verdicts."""
    rec = records.copy()
    rec["size"] = rec["pairs"].map(size_bin)
    rec["all"] = "all"
    rows = []
    for by in ("all", "size"):
        cov = coverage_summary(rec, by=(by,), quantities=list(QUANTITIES), levels=(0.95,))
        for _, c in cov.iterrows():
            rows.append({"group": c[by], "quantity": c["quantity"], "n": int(c["n"]),
                         "coverage95": float(c["coverage"]), "z_sd": float(c["z_sd"])})
    out = pd.DataFrame(rows)
    out["coverage_ok"] = out["coverage95"].between(*COVERAGE_TARGET)
    out["z_sd_ok"] = out["z_sd"].between(*Z_SD_TARGET)
    return out


def markdown(records: pd.DataFrame, table: pd.DataFrame, wall_s: float | None = None) -> str:
    ok = records[records["error"].isna()] if "error" in records else records
    gate = ok["gate_pass"].astype(bool)
    lines = [f"{len(records)} campaigns (seeds {int(records['seed'].min())}-{int(records['seed'].max())}), "
             f"{len(records) - len(ok)} errors, {int(gate.sum())} of {len(ok)} fits passed every gate; "
             f"targets: 95 % coverage in [{COVERAGE_TARGET[0]:.2f}, {COVERAGE_TARGET[1]:.2f}], "
             f"sd(z) in [{Z_SD_TARGET[0]}, {Z_SD_TARGET[1]}].", "",
             "| campaigns | quantity | n | 95 % coverage | sd(z) | verdict |", "|---|---|---|---|---|---|"]
    for _, r in table.iterrows():
        verdict = "pass" if r["coverage_ok"] and r["z_sd_ok"] else "**fail**"
        lines.append(f"| {r['group']} | {r['quantity']} | {r['n']} | {r['coverage95']:.2f} | {r['z_sd']:.2f} | "
                     f"{verdict} |")
    if wall_s is not None:
        lines += ["", f"Mean fit time {ok['time_total_s'].mean():.0f} s; wall time {wall_s / 60:.0f} min."]
    return "\n".join(lines) + "\n"


def write_doc_section(text: str, doc: Path = DOC) -> None:
    body = doc.read_text()
    pattern = re.compile(re.escape(MARK_BEGIN) + ".*?" + re.escape(MARK_END), re.S)
    if not pattern.search(body):
        raise SystemExit(f"{doc}: markers {MARK_BEGIN} ... {MARK_END} not found")
    doc.write_text(pattern.sub(lambda _: f"{MARK_BEGIN}\n{text}{MARK_END}", body))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="campaigns (default 200)")
    ap.add_argument("--seed0", type=int, default=1000, help="first seed (confirmatory seeds start at 1000)")
    ap.add_argument("--pairs", type=int, nargs=2, default=(1, 12), metavar=("MIN", "MAX"))
    ap.add_argument("--workers", type=int, default=None, help="Dask workers (default: the usable cores)")
    ap.add_argument("--scheduler", default=None, metavar="ADDR", help="a running Dask scheduler")
    ap.add_argument("--records", type=Path, default=RECORDS)
    ap.add_argument("--docs", action="store_true", help="regenerate the section of docs/calibration.md")
    ap.add_argument("--from-records", action="store_true", help="summarise --records without fitting")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    wall = None
    if args.from_records:
        records = pd.read_csv(args.records)
    else:
        jobs = jobs_for(range(args.seed0, args.seed0 + args.n), *args.pairs, FitOptions())
        args.records.parent.mkdir(parents=True, exist_ok=True)
        partial = args.records.with_suffix(".partial.csv")
        done: list[dict] = []

        def progress(rec):
            done.append(rec)
            pd.DataFrame.from_records(done).to_csv(partial, index=False)

        with batch_client(args.workers, args.scheduler) as client:
            records = run_batch(jobs, client, on_record=progress)
        wall = time.perf_counter() - t0
        records.to_csv(args.records, index=False)
        partial.unlink(missing_ok=True)
    if "error" not in records:
        records["error"] = np.nan
    table = summarise(records)
    text = markdown(records, table, wall)
    print(text, file=sys.stderr)
    if args.docs:
        write_doc_section(text)
    print(json.dumps({"benchmark": "calibration_independent", "campaigns": len(records),
                      "records": str(args.records), "wall_s": wall,
                      "table": json.loads(table.to_json(orient="records"))}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
