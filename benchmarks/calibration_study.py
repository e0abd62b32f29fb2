"""Interval calibration of the default fit on campaigns of the independent simulator.

Each campaign is ``simulate_independent(seed, pairs=P)`` (``bayes_roadload.simulate.independent``:
its own integrator, wind field, instruments and vehicles, every nuisance effect, the Type B
errors drawn inside the standards' accuracies), P drawn uniformly in ``--pairs MIN MAX`` from the
seed.  Every campaign is fitted with the options ``bayes-roadload fit`` uses by default (the
speed-trace default model of the kind registry for each campaign,
``KINDS["traces"].default_model``, unless
``--model``; the default pooling and noise of :class:`bayes_roadload.inference.kinds.FitOptions`,
the default sampler) through the batch door (:func:`bayes_roadload.analysis.batch.run_batch`).

The rules are frozen before the confirmatory seeds run (``docs/calibration.md``):

* quantities: AD, BD, CD0, KD, F50_N, F0_N, F1_N_per_kph, F2_N_per_kph2;
* pass: the 95 % intervals cover the truth in 92-98 % of the fits that ran, and the sd over
  fits of z = (mean - truth) / sd lies in [0.85, 1.15]; reported by quantity and by campaign
  size (1-2, 3-5, 6-12 pairs);
* design seeds (used while choosing the default analysis): 100-199, and 1000-1059, 2000-2013,
  3000-3032, 4000-4052, 5000-5073 and 6000-6199 (earlier defaults' and a variant's confirmatory
  runs, which informed the current choice), 8000-8015 (MAP probes); confirmatory seeds of the
  current default analysis: from 9000 on (``--seed0 9000``,
  :data:`~bayes_roadload.analysis.calibration.CONFIRMATORY_SEED0`).

Writes every record, with the commit of the code that fitted it (``code``), to ``--records``
(CSV; a ``.partial.csv`` while running, from which an interrupted run resumes: its campaigns are
not fitted again), prints the summary as JSON and, with ``--docs``, regenerates the section of ``docs/calibration.md`` between
its markers.

    python benchmarks/calibration_study.py --n 200 --seed0 9000 --workers 2 --docs

The confirmatory run of the current default (from seed 10000) logs each campaign's track survey:

    python benchmarks/calibration_study.py --n 200 --seed0 10000 --log survey --workers 2 \
        --records docs/calibration/survey_records.csv

A reading for designing a budget (``analysis.calibration.budget_rescaled``): the records' intervals
with one Type B source's uncertainty scaled, printed as a markdown table, nothing fitted:

    python benchmarks/calibration_study.py --from-records --records RECORDS \
        --rescale tyre_quadratic_s2_per_m2=1,0.75,0.54
    python benchmarks/calibration_study.py --from-records --records RECORDS \
        --rescale yaw_levelling_per_rad2=1,0.5 --one-sided above   # records with the signed columns
    python benchmarks/calibration_study.py --from-records --records RECORDS \
        --rescale tyre_quadratic_s2_per_m2=1,0.75,0.54 --with yaw_levelling_per_rad2=1:above
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.analysis.batch import batch_client, passed_first_time, run_batch, successful  # noqa: E402
from bayes_roadload.inference.kinds import FitOptions  # noqa: E402
from bayes_roadload.config import DEFAULT_SAMPLER  # noqa: E402
from doc_sections import replace_section  # noqa: E402
from gradient_cost import commit_of  # noqa: E402
from bayes_roadload.analysis.calibration import (CONFIRMATORY_SEED0, DIAGNOSTIC_SPLIT, QUANTITIES,  # noqa: E402
                                                 budget_rescaled, calibration_jobs, calibration_markdown, calibration_table,
                                                 with_test_mass)

RECORDS = ROOT / "docs" / "calibration" / "independent_records.csv"
DOC = ROOT / "docs" / "calibration.md"
MARK_BEGIN = "<!-- calibration_study:begin -->"
MARK_END = "<!-- calibration_study:end -->"


def comparison_markdown(first: pd.DataFrame, second: pd.DataFrame) -> str:
    """Per quantity, on the campaigns (``name``) both record sets hold: how many 95 % intervals
    hold the truth, the mean relative error (%) and, for ``second``, the rms of
    z = (mean - truth) / sd."""
    names = sorted(set(first["name"]) & set(second["name"]))
    a = first[first["name"].isin(names)]
    b = second[second["name"].isin(names)]
    n = len(names)
    lines = [f"campaigns {', '.join(names)}", "",
             "| quantity | first: held / mean error | second: held / mean error / rms z |",
             "| --- | --- | --- |"]
    held = [0, 0]
    for q in QUANTITIES:
        cells = []
        for k, rec in enumerate((a, b)):
            inside = int(rec[f"{q}_in95"].astype(bool).sum())
            held[k] += inside
            err = 100.0 * (rec[f"{q}_mean"] / rec[f"{q}_truth"] - 1.0)
            cell = f"{inside} / {n}, {err.mean():+.1f} %"
            if k == 1:
                z = (rec[f"{q}_mean"] - rec[f"{q}_truth"]) / rec[f"{q}_sd"]
                cell += f", {float(np.sqrt((z ** 2).mean())):.2f}"
            cells.append(cell)
        lines.append(f"| {q} | {cells[0]} | {cells[1]} |")
    lines.append(f"| all | {held[0]} / {n * len(QUANTITIES)} | {held[1]} / {n * len(QUANTITIES)} |")
    first_time = [int(passed_first_time(rec).sum()) for rec in (a, b)]
    lines.append(f"| every gate first time | {first_time[0]} / {n} | {first_time[1]} / {n} |")
    retried = [", ".join(f"{r['name']} ({r['retry_failed']})" for _, r in rec[rec["retries"] > 0].iterrows()) or "none"
               for rec in (a, b)]
    lines.append(f"| retried (first attempt failed) | {retried[0]} | {retried[1]} |")
    return "\n".join(lines)


ARM_OPTIONS = {"logged": "--log", "withheld": "--withhold"}
"""The record tags of a run's campaign design and the option that sets each."""


def _arm(tags) -> dict[str, str]:
    """A run's design from its jobs' or records' tags: ``--log`` / ``--withhold`` -> the names
    (joined by spaces), the options not given left out."""
    return {opt: str(tags[tag]) for tag, opt in ARM_OPTIONS.items() if tag in tags and isinstance(tags[tag], str) and tags[tag]}


def resume_from(partial: Path, jobs: list) -> tuple[pd.DataFrame, list]:
    """The records of an interrupted run (``partial``, empty when it does not exist) and the
    jobs whose campaign (``name``) they do not hold yet; refused when the partial records were
    fitted with another design (logged channels, withheld effects) than the jobs ask for."""
    before = pd.read_csv(partial) if partial.exists() else pd.DataFrame({"name": []})
    if len(before) and jobs:
        had, asked = _arm(before.iloc[0].to_dict()), _arm(jobs[0].tags)
        if had != asked:
            shown = lambda arm: " ".join(f"{k} {v}" for k, v in arm.items()) or "no --log / --withhold"  # noqa: E731
            raise SystemExit(f"{partial}: its campaigns were fitted with {shown(had)}, this run asks for "
                             f"{shown(asked)}: resume with the same options, or write to other --records")
    finished = set(before["name"])
    return before, [j for j in jobs if j.name not in finished]


def parse_also(specs: list[str] | None) -> dict[str, tuple[float, str | None]]:
    """``--with SOURCE=F[:above|below]`` (repeatable): source -> (factor, side or None)."""
    out: dict[str, tuple[float, str | None]] = {}
    for spec in specs or []:
        source, _, rest = spec.partition("=")
        factor, _, side = rest.partition(":")
        if not source or source in out:
            raise SystemExit(f"--with {spec!r}: " + ("name the source" if not source else f"{source} given twice"))
        try:
            out[source] = (float(factor), side or None)
        except ValueError:
            raise SystemExit(f"--with {spec!r}: give SOURCE=F or SOURCE=F:above|below") from None
        if side and side not in ("above", "below"):
            raise SystemExit(f"--with {spec!r}: the side is above or below")
    return out


def _counts(n: pd.Series) -> str:
    """The campaigns a table's rows count: one number, or their range when rows differ."""
    lo, hi = int(n.min()), int(n.max())
    return f"{hi}" if lo == hi else f"{lo}-{hi}"


def rescaled_markdown(records: pd.DataFrame, spec: str, one_sided: str | None = None,
                      also: dict[str, tuple[float, str | None]] | None = None) -> str:
    """``--rescale SOURCE=F,F,... [--one-sided above|below] [--with OTHER=F[:side] ...]``:
    :func:`budget_rescaled` of the records as a markdown table."""
    source, _, factors = spec.partition("=")
    try:
        values = [float(f) for f in factors.split(",")]
    except ValueError:
        raise SystemExit(f"--rescale {spec!r}: give SOURCE=F,F,... (factors as numbers)") from None
    try:
        table = budget_rescaled(records, source, values, one_sided=one_sided, also=also)
    except ValueError as e:
        raise SystemExit(f"--rescale {spec!r}: {e}") from None
    if table.empty:
        raise SystemExit(f"--rescale: the records carry no budget column for the source {source!r}"
                         + (" with its sign (records written before the signed columns)"
                            if one_sided or any(o for _, o in (also or {}).values()) else ""))
    how = "scaled" if one_sided is None else f"made one-sided ({one_sided} the declared value) and scaled"
    beside = "".join(f"; beside it `{k}` x {f:g}" + (f", one-sided {o}" if o else "") for k, (f, o) in (also or {}).items())
    lines = [f"The records' intervals with the Type B source `{source}` {how}{beside} (a reading in the normal "
             f"approximation, `analysis.calibration.budget_rescaled`; the {_counts(table['n'])} of the "
             f"{len(successful(records))} fits whose records carry the source):", "",
             "| quantity | campaigns | source's median share | factor | 95 % coverage | sd(z) | mean z |",
             "|---|---|---|---|---|---|---|"]
    for r in table.itertuples():
        lines.append(f"| {r.quantity} | {r.n} | {r.median_share:.2f} | {r.factor:g} | {r.coverage95:.2f} | "
                     f"{r.z_sd:.2f} | {r.z_mean:+.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="campaigns (default 200)")
    ap.add_argument("--seed0", type=int, default=CONFIRMATORY_SEED0,
                    help=f"first seed (confirmatory seeds start at {CONFIRMATORY_SEED0})")
    ap.add_argument("--pairs", type=int, nargs=2, default=(1, 12), metavar=("MIN", "MAX"))
    ap.add_argument("--workers", type=int, default=None, help="Dask workers (default: the usable cores)")
    ap.add_argument("--scheduler", default=None, metavar="ADDR", help="a running Dask scheduler")
    ap.add_argument("--records", type=Path, default=RECORDS)
    ap.add_argument("--docs", action="store_true", help="regenerate the section of docs/calibration.md")
    ap.add_argument("--model", default=None, help="model variant (default: fit's for speed traces)")
    ap.add_argument("--model-heavy", default=None, metavar="MODEL",
                    help="with --model: the variant for campaigns above the heavy-duty test mass (3500 kg)")
    ap.add_argument("--withhold", nargs="+", default=(), metavar="EFFECT",
                    help="an ablation: these effects of the independent simulator left out of every campaign")
    ap.add_argument("--log", nargs="+", default=(), metavar="CHANNEL",
                    help="channels of the independent simulator logged beside the default ones (e.g. survey: "
                         "each campaign's level survey of its track, track.csv)")
    ap.add_argument("--noise-scaled-metric", action=argparse.BooleanOptionalAction,
                    default=DEFAULT_SAMPLER.noise_scaled_metric,
                    help="the sampler's coordinates scaled with the integrated noise (SamplerConfig.noise_scaled_metric; "
                         "default: the sampler's, on)")
    ap.add_argument("--compare", type=Path, default=None, metavar="RECORDS",
                    help="with --from-records: a table of --records beside these records on the seeds both hold")
    ap.add_argument("--from-records", action="store_true", help="summarise --records without fitting")
    ap.add_argument("--rescale", default=None, metavar="SOURCE=F,F,...",
                    help="with --from-records: only the intervals with the Type B source's uncertainty scaled by "
                         "each factor (analysis.calibration.budget_rescaled), as a markdown table")
    ap.add_argument("--one-sided", choices=("above", "below"), default=None,
                    help="with --rescale: read the source as a uniform on that side of its declared value (its "
                         "sign from the records' signed budget columns)")
    ap.add_argument("--with", dest="also", action="append", default=None, metavar="SOURCE=F[:above|below]",
                    help="with --rescale: another source changed beside it in every row (repeatable)")
    ap.add_argument("--fill-test-mass", action="store_true",
                    help="with --from-records: add the declared test mass (test_mass_kg) to the records that lack it, "
                         "by simulating those campaigns again, and write it back to --records")
    args = ap.parse_args(argv)
    if args.rescale is not None and not args.from_records:
        ap.error("--rescale reads the records without fitting: give --from-records")
    if (args.one_sided is not None or args.also) and args.rescale is None:
        ap.error("--one-sided and --with read sources beside --rescale: give --rescale SOURCE=F,...")
    t0 = time.perf_counter()
    wall = None
    if args.from_records:
        records = pd.read_csv(args.records)
        if args.fill_test_mass:
            records = with_test_mass(records)
            records.to_csv(args.records, index=False)
    else:
        options = FitOptions(sampler=dataclasses.replace(DEFAULT_SAMPLER, noise_scaled_metric=args.noise_scaled_metric))
        jobs = calibration_jobs(range(args.seed0, args.seed0 + args.n), *args.pairs, options=options,
                                model=args.model, withhold=args.withhold, model_heavy=args.model_heavy, log=args.log)
        args.records.parent.mkdir(parents=True, exist_ok=True)
        partial = args.records.with_suffix(".partial.csv")
        before, jobs = resume_from(partial, jobs)
        done: list[dict] = before.to_dict("records")
        finished = len(before) > 0
        if finished:
            print(f"resuming: {len(before)} campaigns from {partial}, {len(jobs)} to fit", file=sys.stderr)

        code = commit_of(ROOT)

        def progress(rec):
            done.append({**rec, "code": code})
            pd.DataFrame.from_records(done).to_csv(partial, index=False)

        with batch_client(args.workers, args.scheduler) as client:
            new = run_batch(jobs, client, on_record=progress)
        wall = time.perf_counter() - t0
        new["code"] = code
        records = pd.concat([before, new], ignore_index=True) if finished else new
        records.to_csv(args.records, index=False)
        partial.unlink(missing_ok=True)
    if args.compare is not None:
        print(comparison_markdown(pd.read_csv(args.compare), records))
        return 0
    if args.rescale is not None:
        print(rescaled_markdown(records, args.rescale, args.one_sided, parse_also(args.also)))
        return 0
    if "error" not in records:
        records["error"] = np.nan
    table = calibration_table(records)
    text = calibration_markdown(records, table, wall, split=DIAGNOSTIC_SPLIT)
    if args.from_records and args.records.name.endswith(".partial.csv"):
        final = args.records.resolve().with_name(args.records.name.replace(".partial.csv", ".csv"))
        shown = final.relative_to(ROOT) if final.is_relative_to(ROOT) else final
        arm = "".join(f" {k} {v}" for k, v in _arm(records.iloc[0].to_dict()).items())
        text = (f"**Partial run: {len(records)} of the {args.n} campaigns** (stopped, resumable: `python "
                f"benchmarks/calibration_study.py --n {args.n} --seed0 {int(records['seed'].min())}{arm} --records {shown}` "
                "fits only the campaigns the partial file lacks); every verdict below is on these campaigns "
                "alone.\n\n" + text)
    print(text, file=sys.stderr)
    if args.docs:
        replace_section(DOC, MARK_BEGIN, MARK_END, text)
    print(json.dumps({"benchmark": "calibration_independent", "campaigns": len(records),
                      "records": str(args.records), "wall_s": wall,
                      "table": json.loads(table.to_json(orient="records"))}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
