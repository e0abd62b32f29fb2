"""The tyre-lag model's small campaigns sampled in A_D, B_D, C_D0 directly from the start.

The default samples the tyre-lag model in its apparent coefficients and switches to A_D, B_D,
C_D0 only where the MAP's Laplace approximation reaches a wall (``config.MAX_BEYOND_SUPPORT_SHARE``)
or on the retry after divergences (``inference.nuts.start_coordinates``, ``retry_coordinates``).
On the survey run (``docs/calibration/survey_records.csv``) 7 of 199 fits diverged in their first
attempt in the apparent coefficients, 6 of them at 1-3 pairs, and the retry in the direct
coordinates passed 6 of them; the MAP's wall share of two of them is 0
(``benchmarks/wall_share_probe.py``), so no threshold on it foresees them.

This study refits the campaigns of a calibration study's records (at most ``--max-pairs``
pairs) with the sampler's ``coordinates = "alternative"`` (the same posterior in the direct
coordinates from the start; the default retry) through the batch door, and prints, beside
the records' first attempts in the apparent coefficients: gates passed first time, divergences
of the first attempt, the time, and the posterior means' agreement (C_D0's and F50_N's
difference in posterior sd: the same posterior, so about 0 up to Monte-Carlo error).

    python benchmarks/coordinates_study.py --records docs/calibration/survey_records.csv \
        --max-pairs 3 --out benchmarks/records/gates/coordinates_direct_survey.csv

The refits resume from ``OUT.partial.csv`` when interrupted; ``--from-records`` prints the
comparison of ``--out`` without fitting.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bayes_roadload.analysis.batch import batch_client, passed_first_time, run_batch, successful  # noqa: E402
from bayes_roadload.analysis.calibration import calibration_jobs  # noqa: E402
from bayes_roadload.config import DEFAULT_SAMPLER  # noqa: E402
from bayes_roadload.inference.kinds import FitOptions  # noqa: E402
from calibration_study import resume_from  # noqa: E402
from gradient_cost import commit_of  # noqa: E402


def first_divergences(rec: pd.DataFrame) -> pd.Series:
    """Per record: did the first attempt fail on divergences (a retry for them, or kept)."""
    failed = rec["retry_failed"].fillna("").astype(str).str.contains("divergences")
    kept = rec["retries"].fillna(0).eq(0) & rec["divergences"].fillna(0).gt(0)
    return failed | kept


def comparison(before: pd.DataFrame, after: pd.DataFrame) -> str:
    """Markdown: the campaigns both hold, the records' first attempts against the refits'."""
    before, after = successful(before).set_index("name"), successful(after).set_index("name")
    names = before.index.intersection(after.index)
    before, after = before.loc[names], after.loc[names]
    lines = ["| coordinates | campaigns | first time through every gate | first attempt diverged | "
             "after the retry | median fit time (s) |", "|---|---|---|---|---|---|"]
    for label, r in (("apparent (the records)", before), ("direct from the start", after)):
        lines.append(f"| {label} | {len(r)} | {int(passed_first_time(r).sum())} | {int(first_divergences(r).sum())} | "
                     f"{int(r['gate_pass'].astype(bool).sum())} | {np.median(r['time_fit_s']):.0f} |")
    lines.append("")
    for q in ("CD0", "F50_N"):
        if f"{q}_mean" in before and f"{q}_mean" in after:
            d = (after[f"{q}_mean"] - before[f"{q}_mean"]) / before[f"{q}_sd"]
            lines.append(f"{q}: posterior means differ by {d.abs().median():.3f} sd (median), "
                         f"{d.abs().max():.3f} sd at most ({d.abs().idxmax()})")
    both = first_divergences(before) & first_divergences(after)
    lines.append("first attempt diverged in both: " + (", ".join(both[both].index) or "none"))
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--records", type=Path, required=True, help="a calibration study's records (CSV)")
    ap.add_argument("--max-pairs", type=int, default=3, help="campaigns of at most this many pairs")
    ap.add_argument("--out", type=Path, required=True, help="the refits' records (CSV)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--from-records", action="store_true", help="compare --out with --records without fitting")
    args = ap.parse_args(argv)
    before = pd.read_csv(args.records, low_memory=False)
    before = before[before["error"].isna() & (before["pairs"] <= args.max_pairs)]
    if not args.from_records:
        sampler = dataclasses.replace(DEFAULT_SAMPLER, coordinates="alternative")
        jobs = []
        for _, r in before.iterrows():
            log = tuple(str(r["logged"]).split()) if isinstance(r.get("logged"), str) else ()
            jobs += calibration_jobs([int(r["seed"])], options=FitOptions(sampler=sampler), log=log)
        partial = args.out.with_suffix(".partial.csv")
        args.out.parent.mkdir(parents=True, exist_ok=True)
        done_before, jobs = resume_from(partial, jobs)
        done = done_before.to_dict("records")
        code = commit_of(ROOT)

        def progress(rec):
            done.append({**rec, "code": code})
            pd.DataFrame.from_records(done).to_csv(partial, index=False)

        with batch_client(args.workers) as client:
            run_batch(jobs, client, on_record=progress)
        pd.DataFrame.from_records(done).to_csv(args.out, index=False)
        partial.unlink(missing_ok=True)
    print(comparison(before, pd.read_csv(args.out, low_memory=False)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
