"""Simulation-based calibration of the NUTS fit, with its negative control.

``--campaigns`` campaigns drawn from the priors of ``models/four_term_driveline_informative.toml``
(``--model``: another model's, e.g. the tyre-lag default's ``four_term_tyre_lag_driveline_informative``)
(:mod:`bayes_roadload.analysis.sbc`), simulated with the table 6.6 measurement noise on speed,
airspeed, yaw and driveline force and a random force whose intensity is drawn from the prior of
the integrated noise q (arms ``sim_calibrated``, ``sim_wrong_mass``; ``--sensor-noise-only``
leaves it out: arms ``calibrated``, ``wrong_mass``; ``--exact`` draws the speed traces from the
model's likelihood: arms ``exact_*``), fitted with NUTS through the batch door; ``--control``
more campaigns fitted with the effective mass mis-stated by ``--mass-factor`` (the negative
control).  Writes every record to ``--records`` (CSV, read by
``benchmarks/validation_report.py``) and prints one JSON object: the chi-square uniformity
test and the 50 / 90 / 95 % coverage of A_D, B_D, C_D0, K_D, A_t, B_t per arm, gate pass rate,
time per fit.

Run::

    python benchmarks/sbc_study.py --campaigns 100 --control 40 --workers 2

An interrupted study resumes from its ``.partial.csv`` (the finished fits are not run again).
An arm may be run in parts (``--seed0`` 0, 100, ... with their own ``--records``); ``--docs
CSV [CSV ...]`` then reads the parts' records together (no fitting) and writes the tables into
the ``sbc`` section of ``docs/calibration.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import pandas as pd

from bayes_roadload.analysis.batch import batch_client, run_batch
from bayes_roadload.analysis.sbc import SBC_MODEL, SBC_SAMPLER, rank_histograms, sbc_jobs, sbc_markdown, sbc_tests

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "docs" / "validation" / "sbc_records.csv"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaigns", type=int, default=100)
    ap.add_argument("--control", type=int, default=40, help="campaigns of the negative control")
    ap.add_argument("--mass-factor", type=float, default=1.05)
    ap.add_argument("--pairs", type=int, default=2)
    ap.add_argument("--model", default=SBC_MODEL,
                    help="the model whose priors draw the truths and which fits them (default %(default)s; the "
                         "tyre-lag default's: four_term_tyre_lag_driveline_informative)")
    ap.add_argument("--warmup", type=int, default=SBC_SAMPLER.num_warmup)
    ap.add_argument("--draws", type=int, default=SBC_SAMPLER.num_samples)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--scheduler", default=None, metavar="ADDR",
                    help="address of a running Dask scheduler (default: a local cluster of --workers processes)")
    ap.add_argument("--seed0", type=int, default=0)
    ap.add_argument("--exact", action="store_true",
                    help="exact SBC: speed traces drawn from the model's own likelihood (ModelDrawnCampaign)")
    ap.add_argument("--sensor-noise-only", action="store_true",
                    help="simulator arm without the random force drawn from the prior of q (arms 'calibrated', "
                         "'wrong_mass'): the integrated noise is the sensors' alone")
    ap.add_argument("--records", type=Path, default=RECORDS)
    ap.add_argument("--docs", type=Path, nargs="+", metavar="CSV",
                    help="no fitting: read these record files together and write the tables into docs/calibration.md")
    args = ap.parse_args(argv)
    if args.docs:
        write_docs(args.docs)
        return 0

    sampler = dataclasses.replace(SBC_SAMPLER, num_warmup=args.warmup, num_samples=args.draws)
    force = not (args.exact or args.sensor_noise_only)
    jobs = (sbc_jobs(args.campaigns, seed0=args.seed0, pairs=args.pairs, model=args.model, sampler=sampler,
                     exact=args.exact, random_force=force)
            + sbc_jobs(args.control, seed0=args.seed0 + 10_000, pairs=args.pairs, model=args.model, sampler=sampler,
                       control_factor=args.mass_factor, exact=args.exact, random_force=force))
    if args.control:  # interleave the arms, so that a study cut short still has both
        step = max(args.campaigns // args.control, 1)
        cal, ctl = jobs[:args.campaigns], jobs[args.campaigns:]
        jobs = []
        for i in range(0, max(len(cal), step * len(ctl)), step):
            jobs += cal[i:i + step] + ctl[i // step:i // step + 1]
    t0 = time.perf_counter()
    args.records.parent.mkdir(parents=True, exist_ok=True)
    partial = args.records.with_suffix(".partial.csv")
    done: list[dict] = pd.read_csv(partial).to_dict("records") if partial.is_file() else []
    if done:  # resume an interrupted study: its finished fits are kept, not run again
        finished = {r["name"] for r in done}
        jobs = [j for j in jobs if j.name not in finished]
        print(f"resuming {partial}: {len(done)} fits done, {len(jobs)} to run", file=sys.stderr)

    def progress(rec):
        done.append(rec)
        pd.DataFrame.from_records(done).to_csv(partial, index=False)  # survives an interrupted study

    with batch_client(args.workers, args.scheduler) as client:
        run_batch(jobs, client, on_record=progress)
    records = pd.DataFrame.from_records(done)
    wall = time.perf_counter() - t0
    records.to_csv(args.records, index=False)
    partial.unlink(missing_ok=True)
    tests = sbc_tests(records)
    print(sbc_markdown(records, tests), file=sys.stderr)
    ok = records[records["error"].isna()]
    out = {"benchmark": "sbc", "campaigns": args.campaigns, "control": args.control, "pairs": args.pairs,
           "mass_factor": args.mass_factor, "errors": int(records["error"].notna().sum()),
           "gate_pass_rate": float(ok["gate_pass"].astype(bool).mean()) if len(ok) else None,
           "mean_fit_s": float(ok["time_total_s"].mean()) if len(ok) else None, "wall_s": round(wall, 1),
           "workers": args.workers, "records": str(args.records),
           "tests": json.loads(tests.to_json(orient="records"))}
    print(json.dumps(out, indent=2))
    return 0


def write_docs(paths: list[Path]) -> str:
    """The ``sbc`` section of ``docs/calibration.md`` from the record files ``paths`` (read
    together): the files, the fit count, pairs and mean time, then
    :func:`~bayes_roadload.analysis.sbc.sbc_markdown` with every two exact arms compared on
    their shared draws."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from doc_sections import replace_section

    records = pd.concat([pd.read_csv(p) for p in paths], ignore_index=True)
    ok = records[records["error"].isna()] if "error" in records else records
    names = ", ".join(f"`{p.resolve().relative_to(ROOT)}`" for p in paths)
    head = ""
    if len(ok):
        pairs = int(ok["pairs"].iloc[0]) if "pairs" in ok else "?"
        head = f"Records {names}: {len(records)} fits, {pairs} pairs each, mean {ok['time_total_s'].mean():.0f} s per fit.\n\n"
    # the exact arms draw truth and noise from the seed (ModelDrawnCampaign): any two are paired
    exact = [arm for arm in rank_histograms(records)["arm"].unique() if str(arm).startswith("exact_calibrated")]
    text = head + sbc_markdown(records, paired=[(x, y) for i, x in enumerate(exact) for y in exact[i + 1:]])
    replace_section(ROOT / "docs" / "calibration.md", "<!-- sbc:begin -->", "<!-- sbc:end -->", text)
    return text


if __name__ == "__main__":
    sys.exit(main())
