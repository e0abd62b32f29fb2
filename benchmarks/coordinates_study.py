"""The tyre-lag model's small campaigns sampled in A_D, B_D, C_D0 directly from the start.

The default samples the tyre-lag model in its apparent coefficients and switches to A_D, B_D,
C_D0 only where the MAP's Laplace approximation reaches a wall (``config.MAX_BEYOND_SUPPORT_SHARE``)
or on the retry after divergences (``inference.nuts.start_coordinates``, ``retry_coordinates``).
On the survey run (``docs/calibration/survey_records.csv``) 7 of 199 fits diverged in their first
attempt in the apparent coefficients, 6 of them at 1-3 pairs, and the retry in the direct
coordinates passed 6 of them; the MAP's wall share of all seven is 0
(``benchmarks/wall_share_probe.py``), so no threshold on it foresees them.

This study refits the campaigns of a calibration study's records (at most ``--max-pairs``
pairs) through the batch door, one arm per run at the same code: ``--coordinates auto`` (the
default) and ``--coordinates alternative`` (the same posterior in the direct coordinates from
the start, from their own MAP after the first one; the default retry).  With ``--baseline`` (the
other arm's records) it prints both arms side by side: gates passed first time, first attempts
that diverged, the time of the MAPs and of the whole fit, and the posterior means' agreement
(C_D0's and F50_N's difference in posterior sd: the same posterior, so about 0 up to Monte-Carlo
error); it refuses an ``alternative`` arm whose lag-model fits did not sample directly.

    python benchmarks/coordinates_study.py --records docs/calibration/survey_records.csv --max-pairs 3 \
        --coordinates auto --out benchmarks/records/gates/coordinates_auto_survey.csv
    python benchmarks/coordinates_study.py --records docs/calibration/survey_records.csv --max-pairs 3 \
        --coordinates alternative --out benchmarks/records/gates/coordinates_direct_survey.csv \
        --baseline benchmarks/records/gates/coordinates_auto_survey.csv

Each arm resumes from ``OUT.partial.csv`` when interrupted; ``--from-records`` prints the
comparison of ``--out`` with ``--baseline`` without fitting.
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


def record_jobs(records: pd.DataFrame, options: FitOptions | None = None) -> list:
    """One fit job per record, its campaign built as the study built it (``calibration_jobs``
    with the record's seed and logged channels), fitted with ``options``."""
    jobs = []
    for _, r in records.iterrows():
        log = tuple(str(r["logged"]).split()) if isinstance(r.get("logged"), str) else ()
        jobs += calibration_jobs([int(r["seed"])], options=options, log=log)
    return jobs


def first_divergences(rec: pd.DataFrame) -> pd.Series:
    """Per record: did the first attempt fail on divergences (a retry for them, or kept)."""
    failed = rec["retry_failed"].fillna("").astype(str).str.contains("divergences")
    kept = rec["retries"].fillna(0).eq(0) & rec["divergences"].fillna(0).gt(0)
    return failed | kept


def direct_from_the_start(rec: pd.DataFrame) -> pd.Series:
    """Per record: the first attempt sampled A_D, B_D, C_D0 directly (``coordinates`` says so)."""
    return rec["coordinates"].fillna("").astype(str).str.contains("directly")


def comparison(before: pd.DataFrame, after: pd.DataFrame) -> str:
    """Markdown: the campaigns both arms hold, arm by arm (labelled by ``sampler_coordinates``)."""
    before, after = successful(before).set_index("name"), successful(after).set_index("name")
    names = before.index.intersection(after.index)
    before, after = before.loc[names], after.loc[names]
    lines = ["| sampler coordinates | campaigns | sampled directly from the start | first time through every gate | "
             "first attempt diverged | after the retry | median MAP time (s) | median fit time (s) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in (before, after):
        label = str(r["sampler_coordinates"].iloc[0]) if "sampler_coordinates" in r else "auto (records before the option)"
        lines.append(f"| {label} | {len(r)} | {int(direct_from_the_start(r).sum()) if 'coordinates' in r else 'n/a'} | "
                     f"{int(passed_first_time(r).sum())} | {int(first_divergences(r).sum())} | "
                     f"{int(r['gate_pass'].astype(bool).sum())} | {np.median(r['time_map_s']):.1f} | "
                     f"{np.median(r['time_fit_s']):.0f} |")
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
    ap.add_argument("--coordinates", choices=("auto", "alternative"), default="alternative",
                    help="the sampler's coordinates of this arm (SamplerConfig.coordinates)")
    ap.add_argument("--out", type=Path, required=True, help="this arm's records (CSV)")
    ap.add_argument("--baseline", type=Path, help="the other arm's records, to compare with (default: --records)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--from-records", action="store_true", help="compare --out with --records without fitting")
    args = ap.parse_args(argv)
    before = pd.read_csv(args.records, low_memory=False)
    before = before[before["error"].isna() & (before["pairs"] <= args.max_pairs)]
    if not args.from_records:
        sampler = dataclasses.replace(DEFAULT_SAMPLER, coordinates=args.coordinates)
        jobs = record_jobs(before, FitOptions(sampler=sampler))
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
    after = pd.read_csv(args.out, low_memory=False)
    lag = successful(after)["model"].astype(str).str.contains("tyre_lag")
    if str(after["sampler_coordinates"].iloc[0]) == "alternative" and not direct_from_the_start(successful(after)[lag]).all():
        raise SystemExit(f"{args.out}: a lag-model fit of the 'alternative' arm did not sample A_D, B_D, C_D0 directly")
    if args.baseline is not None:
        before = pd.read_csv(args.baseline, low_memory=False)
    print(comparison(before, after))
    return 0


if __name__ == "__main__":
    sys.exit(main())
