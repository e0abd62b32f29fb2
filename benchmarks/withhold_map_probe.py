"""What one physics effect of the independent simulator does to the estimates, by MAP and Laplace.

For each seed, the independent simulator's campaign (``simulate.independent``, every effect on,
as the calibration study draws it) and a second arm: the same seed with the ``--withhold``
effects switched off (``analysis.calibration.calibration_jobs(withhold=...)``: the same vehicle,
size and Type B errors), or with ``--model`` (``--model-heavy`` above 3500 kg) fitted instead of
the default (``--withhold`` with no names keeps every effect), or with ``--log`` channels logged
beside the default ones (``--log humidity``: the hygrometer's reading, which the analysis then
uses), or with ``--state-yaw-calibration`` the anemometer's airspeed factor against yaw stated in
``vehicle.toml`` (the simulator's own, as a wind-tunnel calibration would give it).  Each campaign is fitted by MAP and
Laplace.  Prints, per quantity, the mean relative error against the truth of both arms and their
paired difference with its standard error: the part of the error the withheld physics causes, or
what the model variant removes of it.  A quick probe of a bias; the NUTS study that confirms it is
``calibration_study.py --withhold`` or ``--model``.

    python benchmarks/withhold_map_probe.py --withhold pitch --seeds 3000 3015 \
        --records benchmarks/records/withhold_map/pitch_withheld_seeds3000_3015.csv
    python benchmarks/withhold_map_probe.py --withhold --model four_term_tyre_lag_admittance_pitch \
        --model-heavy four_term_tyre_lag_admittance_heavy_pitch --seeds 3000 3015 --second-only \
        --records benchmarks/records/withhold_map/pitch_model_seeds3000_3015.csv
    python benchmarks/withhold_map_probe.py --from-records \
        benchmarks/records/withhold_map/pitch_withheld_seeds3000_3015.csv \
        benchmarks/records/withhold_map/pitch_model_seeds3000_3015.csv
    python benchmarks/withhold_map_probe.py --withhold --base-model four_term_tyre_lag_admittance_pitch \
        --base-model-heavy four_term_tyre_lag_admittance_heavy_pitch \
        --model four_term_tyre_lag_admittance_pitch_shapes \
        --model-heavy four_term_tyre_lag_admittance_heavy_pitch_shapes --seeds 3000 3015
    python benchmarks/withhold_map_probe.py --withhold --log humidity --seeds 3000 3015 --second-only \
        --records benchmarks/records/withhold_map/humidity_logged_seeds3000_3015.csv
    python benchmarks/withhold_map_probe.py --withhold --state-yaw-calibration --seeds 3000 3015 --second-only
    python benchmarks/withhold_map_probe.py --withhold turbulence --seeds 3000 3015 --second-only \
        --categories heavy_truck light_truck
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from bayes_roadload.analysis.calibration import QUANTITIES


def run(seeds, withhold, lo, hi, model=None, model_heavy=None, arms=("all", "withheld"),
        base_model=None, base_model_heavy=None, log=(), state_yaw_calibration=False) -> pd.DataFrame:
    """Records of the ``arms`` (column ``arm``: ``all``, every effect and ``base_model``
    (``base_model_heavy`` above the heavy-duty test mass; default: fit's default), or
    ``withheld``, the named effects off, the ``log`` channels logged too and ``model``,
    ``model_heavy``, and with ``state_yaw_calibration`` the anemometer's yaw calibration
    stated in vehicle.toml), one row per seed and
    arm; an arm left out comes from another run's records, which :func:`summary` reads together
    with these."""
    from bayes_roadload.analysis.batch import run_batch
    from bayes_roadload.analysis.calibration import calibration_jobs
    from bayes_roadload.inference.kinds import FitOptions

    options = FitOptions(method="laplace")
    frames = []
    for arm, off, name, heavy, logged, stated in (
            ("all", (), base_model, base_model_heavy, (), False),
            ("withheld", tuple(withhold), model, model_heavy, tuple(log), state_yaw_calibration)):
        if arm in arms:
            df = run_batch(calibration_jobs(seeds, lo, hi, options=options, model=name, withhold=off,
                                            model_heavy=heavy, log=logged, state_yaw_calibration=stated),
                           progress=False)
            frames.append(df.assign(arm=arm, withheld=" ".join(off), arm_model=name or "default",
                                    arm_logged=" ".join(logged), arm_stated="yaw calibration" if stated else ""))
    return pd.concat(frames, ignore_index=True)


def of_categories(seeds, categories=None) -> list[int]:
    """The ``seeds`` whose campaign's vehicle is of one of ``categories`` (all with None), read
    from the simulator's first draw (:func:`~bayes_roadload.simulate.independent.first_draws`)."""
    if not categories:
        return list(seeds)
    from bayes_roadload.simulate.independent import CATEGORIES, first_draws

    unknown = sorted(set(categories) - set(CATEGORIES))
    if unknown:
        raise SystemExit(f"unknown categories {unknown}; the simulator's: {sorted(CATEGORIES)}")
    return [s for s in seeds if first_draws(int(s))[0].category in categories]


def summary(records: pd.DataFrame) -> str:
    """Mean relative error (%) per arm, and the paired difference (second arm - all) with its SE;
    where the records carry intervals, the 95 % intervals of each arm that hold the truth and the
    median ratio of the arms' posterior sd (the Type B budget included): one table per second
    arm (its withheld effects and model) the records hold."""
    records = records.assign(withheld=records["withheld"].astype(object).fillna("") if "withheld" in records else "",
                             arm_model=records["arm_model"].astype(object).fillna("default") if "arm_model" in records else "default",
                             arm_logged=records["arm_logged"].astype(object).fillna("") if "arm_logged" in records else "",
                             arm_stated=records["arm_stated"].astype(object).fillna("") if "arm_stated" in records else "")
    from bayes_roadload.analysis.batch import successful

    records = successful(records)  # a failed fit has no interval: it is left out of the pairs
    first = records[records["arm"] == "all"].drop_duplicates("name").set_index("name")
    tables = []
    for (withheld, model, logged, stated), rows in records[records["arm"] == "withheld"].groupby(
            ["withheld", "arm_model", "arm_logged", "arm_stated"]):
        second = rows.set_index("name")
        common = first.index.intersection(second.index)
        lines = [f"{len(common)} campaigns ({', '.join(common)}); second arm: withheld {withheld or 'none'}, "
                 f"model {model}" + (f", also logged: {logged}" if logged else "")
                 + (f", stated in vehicle.toml: {stated}" if stated else ""), "",
                 "| quantity | mean rel. error %, first arm (every effect) | second arm | paired difference (SE) |",
                 "| --- | --- | --- | --- |"]
        for q in QUANTITIES:
            if f"{q}_mean" not in first:
                continue
            err = [((arm.loc[common, f"{q}_mean"] - arm.loc[common, f"{q}_truth"])
                    / arm.loc[common, f"{q}_truth"].abs() * 100.0) for arm in (first, second)]
            diff = err[1] - err[0]
            se = diff.std(ddof=1) / np.sqrt(len(diff)) if len(diff) > 1 else float("nan")
            lines.append(f"| {q} | {err[0].mean():+.2f} | {err[1].mean():+.2f} | {diff.mean():+.2f} ({se:.2f}) |")
        held = [q for q in QUANTITIES if all(f"{q}_{c}" in arm for arm in (first, second) for c in ("in95", "sd"))]
        if held:
            lines += ["", "| quantity | 95 % intervals holding the truth, first arm (every effect) | second arm "
                      "| median sd ratio (second arm / first) |", "| --- | --- | --- | --- |"]
            totals = [0, 0]
            for q in held:
                counts = [int(arm.loc[common, f"{q}_in95"].astype(bool).sum()) for arm in (first, second)]
                totals = [a + b for a, b in zip(totals, counts)]
                ratio = float(np.median(second.loc[common, f"{q}_sd"] / first.loc[common, f"{q}_sd"]))
                lines.append(f"| {q} | {counts[0]} of {len(common)} | {counts[1]} of {len(common)} | {ratio:.3f} |")
            n = len(common) * len(held)
            lines.append(f"| all | {totals[0]} of {n} | {totals[1]} of {n} | |")
        tables.append("\n".join(lines))
    return "\n\n".join(tables)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--withhold", nargs="*", default=["pitch"], help="independent-simulator effects to switch off in the second arm")
    ap.add_argument("--model", default=None, help="the second arm's analysis model (default: fit's default)")
    ap.add_argument("--model-heavy", default=None, help="with --model: the second arm's model above 3500 kg test mass")
    ap.add_argument("--base-model", default=None, help="the first arm's analysis model (default: fit's default)")
    ap.add_argument("--base-model-heavy", default=None,
                    help="with --base-model: the first arm's model above 3500 kg test mass")
    ap.add_argument("--seeds", type=int, nargs=2, default=(3000, 3015), metavar=("FIRST", "LAST"))
    ap.add_argument("--pairs", type=int, nargs=2, default=(1, 12), metavar=("MIN", "MAX"))
    ap.add_argument("--log", nargs="+", default=(), metavar="CHANNEL",
                    help="channels the second arm's campaigns log beside the default ones (e.g. humidity)")
    ap.add_argument("--state-yaw-calibration", action="store_true",
                    help="the second arm's vehicle.toml states the anemometer's airspeed factor against yaw "
                         "(the simulator's e, as a wind-tunnel calibration would)")
    ap.add_argument("--categories", nargs="+", metavar="CATEGORY",
                    help="only the seeds whose vehicle is of these categories (e.g. heavy_truck light_truck)")
    ap.add_argument("--records", type=Path, help="write the records here (CSV)")
    ap.add_argument("--second-only", action="store_true", help="fit the second arm alone (the first from another run's records)")
    ap.add_argument("--from-records", type=Path, nargs="+", help="only summarise written records (read together)")
    args = ap.parse_args(argv)
    if args.from_records:
        records = pd.concat([pd.read_csv(f) for f in args.from_records], ignore_index=True)
    else:
        seeds = of_categories(range(args.seeds[0], args.seeds[1] + 1), args.categories)
        records = run(seeds, args.withhold, *args.pairs, model=args.model,
                      model_heavy=args.model_heavy, arms=("withheld",) if args.second_only else ("all", "withheld"),
                      base_model=args.base_model, base_model_heavy=args.base_model_heavy, log=args.log,
                      state_yaw_calibration=args.state_yaw_calibration)
        if args.records:
            args.records.parent.mkdir(parents=True, exist_ok=True)
            records.to_csv(args.records, index=False)
    print(summary(records))
    return 0


if __name__ == "__main__":
    sys.exit(main())
