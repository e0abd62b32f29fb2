"""How much of each fit's MAP Laplace approximation lies beyond a coefficient's support in the
sampled coordinates (``Problem.beyond_support``), for the campaigns of a calibration study's
records: does the share separate the fits whose first NUTS attempt diverged in the tyre-lag
model's apparent coefficients (record column ``retry_failed`` = ``divergences``) from those that
did not?

``sample_problem`` samples a fit in the direct coordinates (A_D, B_D, C_D0) from the start when
the share reaches ``config.MAX_BEYOND_SUPPORT_SHARE``; a lower share leaves the wall inside the
sampled space, which a first attempt may meet.  Each campaign is rebuilt as the study built it
(``coordinates_study.record_jobs``: ``calibration_jobs`` with the records' logged channels; the
model ``fit`` takes for it), its start and MAP computed as ``fit_nuts`` computes them; nothing
is sampled.

    python benchmarks/wall_share_probe.py --records docs/calibration/survey_records.csv \
        --max-pairs 3 --out benchmarks/records/gates/wall_share_survey.csv

Prints one line per campaign (pairs, pooling, model, the share, whether its first attempt
diverged) and, at the end, the share's range in each group.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from gradient_cost import commit_of  # noqa: E402


def wall_share(job) -> dict:
    """The MAP's Laplace share beyond a support for the campaign and model of ``job``."""
    from bayes_roadload.analysis.batch import job_model
    from bayes_roadload.inference.bayes import build_problem
    from bayes_roadload.inference.kinds import KINDS, FitOptions, resolve_pooling
    from bayes_roadload.inference.nuts import find_map, prepare_problem, unconstrained_posterior
    from bayes_roadload.inference.spec import load_model_spec

    t0 = time.perf_counter()
    campaign = job.campaign()
    options = FitOptions(method="nuts")
    model = job_model(job, campaign, options)
    pooling = resolve_pooling(KINDS["traces"], campaign, load_model_spec(model), options).pooling \
        if job.pooling == "auto" else job.pooling
    problem, init = prepare_problem(build_problem(campaign, model, pooling=pooling, noise=job.noise), campaign)
    post = unconstrained_posterior(problem, init)
    map_result = find_map(problem, {}, posterior=post)
    return {"name": job.name, "model": model, "pooling": pooling, "map_converged": bool(map_result.success),
            "beyond_support": problem.beyond_support(map_result.z, map_result.cov),
            "time_s": time.perf_counter() - t0}


def main(argv=None) -> int:
    from coordinates_study import record_jobs

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--records", type=Path, required=True, help="a calibration study's records (CSV)")
    ap.add_argument("--max-pairs", type=int, default=3, help="campaigns of at most this many pairs")
    ap.add_argument("--names", nargs="+", help="only these campaigns (e.g. ind-10017)")
    ap.add_argument("--out", type=Path, help="write the probe's records here (CSV)")
    args = ap.parse_args(argv)
    rec = pd.read_csv(args.records, low_memory=False)
    rec = rec[rec["error"].isna() & (rec["pairs"] <= args.max_pairs)]
    if args.names:
        rec = rec[rec["name"].isin(args.names)]
    rows = []
    code = commit_of(ROOT)
    for job, (_, r) in zip(record_jobs(rec), rec.iterrows()):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            row = wall_share(job)
        row.update(pairs=int(r["pairs"]), diverged_first="divergences" in str(r.get("retry_failed")),
                   record_model=r["model"], code=code)
        rows.append(row)
        print(f"{row['name']}: {row['pairs']} pairs, {row['pooling']}, {row['model']}: "
              f"{100 * row['beyond_support']:.3f} % beyond a support; first attempt diverged: "
              f"{row['diverged_first']} ({row['time_s']:.0f} s)", flush=True)
        if args.out:
            pd.DataFrame(rows).to_csv(args.out, index=False)
    table = pd.DataFrame(rows)
    for diverged, g in table.groupby("diverged_first"):
        print(f"first attempt diverged {diverged}: {len(g)} campaigns, share {100 * g['beyond_support'].min():.3f}"
              f"-{100 * g['beyond_support'].max():.3f} %, median {100 * g['beyond_support'].median():.3f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
