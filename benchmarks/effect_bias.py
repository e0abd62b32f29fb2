"""Bias of the default analysis model from each nuisance effect of the independent simulator alone.

For every effect of :data:`bayes_roadload.simulate.independent.EFFECTS` (and "none"), ``--seeds``
campaigns of the independent simulator with only that effect, no Type B errors, no run-to-run
spread and perfect instruments except the effect itself (white speed noise only), fitted by
joint least squares (``four_term``, one group) -- the estimate the posterior centres on -- and
compared with the simulator's truth: the relative error of AD, BD, CD0, KD and F50_N.  The
effects whose bias exceeds the posterior's sd are what the analysis leaves unmodelled.

    python benchmarks/effect_bias.py --seeds 3 --pairs 3 --out benchmarks/records/effect_bias.csv

``--leave-one-out`` asks the converse: every effect together (the calibration study's campaign:
``all + Type B + spread``; then without Type B errors and run-to-run spread: ``all``), and
every effect but one (``all but X``, no Type B, no spread), to show how the errors of the
campaigns the calibration study fits add up:

    python benchmarks/effect_bias.py --leave-one-out --seed0 100 --seeds 3 \
        --out benchmarks/records/effect_bias_leave_one_out.csv --docs
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.inference.lsq import fit_lsq  # noqa: E402
from bayes_roadload.simulate.independent import EFFECTS, simulate_independent  # noqa: E402

QUANTITIES = ("AD", "BD", "CD0", "KD", "F50_N")
DOC = ROOT / "docs" / "calibration.md"
MARKS = ("<!-- effect_bias:begin -->", "<!-- effect_bias:end -->")
LOO_MARKS = ("<!-- effect_ablation:begin -->", "<!-- effect_ablation:end -->")


def markdown(df: pd.DataFrame) -> str:
    """Per effect: the seeds' vehicles and the relative error of each quantity, seed by seed."""
    ok = df[df.get("error", pd.Series(index=df.index, dtype=object)).isna()]
    seeds = sorted(ok["seed"].unique())
    lines = [f"Least-squares error (%) of the default model, one effect at a time, {ok['pairs'].iloc[0]} pairs, "
             f"seeds {', '.join(str(s) for s in seeds)} (vehicles: {', '.join(ok.drop_duplicates('seed')['vehicle'])}); "
             "per cell the seeds' values in that order.", "",
             "| effect | " + " | ".join(QUANTITIES) + " |", "|---|" + "---|" * len(QUANTITIES)]
    for effect, g in ok.groupby("effect", sort=False):
        g = g.sort_values("seed")
        cells = [" / ".join(f"{x:+.1f}" for x in g[f"{q}_err_pct"]) for q in QUANTITIES]
        lines.append(f"| {effect} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def configurations(leave_one_out: bool, effects: list[str] | None) -> list[tuple[str, dict]]:
    """(label, simulate_independent keywords) of the study: one effect at a time (perfect
    instruments but for an instrument effect), or every effect and every effect but one."""
    if not leave_one_out:
        out = []
        for e in effects or ["none"] + sorted(EFFECTS):
            instrument = e != "none" and EFFECTS[e].instrument
            out.append((e, dict(effects=[] if e == "none" else [e], type_b=False, run_to_run_sd=0.0,
                                perfect_instruments=not instrument)))
        return out
    every = sorted(EFFECTS)
    out = [("all + Type B + spread", {}), ("all", dict(type_b=False, run_to_run_sd=0.0))]
    return out + [(f"all but {e}", dict(effects=[x for x in every if x != e], type_b=False, run_to_run_sd=0.0))
                  for e in effects or every]


def one(effect: str, seed: int, pairs: int, model: str, simulate: dict | None = None) -> dict:
    if simulate is None:
        simulate = configurations(False, [effect])[0][1]
    campaign = simulate_independent(seed, pairs=pairs, **simulate)
    t0 = time.perf_counter()
    fit = fit_lsq(campaign, model, grouping="all")
    row = {"effect": effect, "seed": seed, "pairs": pairs, "fit_s": time.perf_counter() - t0,
           "vehicle": campaign.truth["meta"]["vehicle_true"]["category"]}
    for q in QUANTITIES:
        est, truth = fit.weighted_mean.get(q, np.nan), campaign.truth.get(q, np.nan)
        row[f"{q}_err_pct"] = 100.0 * (est / truth - 1.0)
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--seed0", type=int, default=300)
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--model", default="four_term")
    ap.add_argument("--effects", nargs="*", default=None, help="default: none and every effect")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "records" / "effect_bias.csv")
    ap.add_argument("--docs", action="store_true", help="regenerate the section of docs/calibration.md")
    ap.add_argument("--from-records", action="store_true", help="summarise --out without fitting")
    ap.add_argument("--leave-one-out", action="store_true",
                    help="every effect together, and every effect but one (docs section effect_ablation)")
    args = ap.parse_args(argv)
    if args.from_records:
        df = pd.read_csv(args.out)
        if "vehicle" not in df:  # the vehicle is drawn from the seed alone
            category = {int(s): simulate_independent(int(s), pairs=1, effects=[], type_b=False, run_to_run_sd=0.0,
                                                     perfect_instruments=True).truth["meta"]["vehicle_true"]["category"]
                        for s in df["seed"].unique()}
            df["vehicle"] = df["seed"].map(category)
        return _report(df, args)
    rows = []
    for e, simulate in configurations(args.leave_one_out, args.effects):
        for s in range(args.seed0, args.seed0 + args.seeds):
            try:
                rows.append(one(e, s, args.pairs, args.model, simulate))
            except Exception as exc:  # a record, not the end of the study
                rows.append({"effect": e, "seed": s, "error": f"{type(exc).__name__}: {exc}"})
            args.out.parent.mkdir(parents=True, exist_ok=True)
            pd.DataFrame(rows).to_csv(args.out, index=False)
    return _report(pd.DataFrame(rows), args)


def _report(df: pd.DataFrame, args) -> int:
    if args.docs:
        marks = LOO_MARKS if args.leave_one_out else MARKS
        text = markdown(df)
        if args.leave_one_out:
            text = text.replace("one effect at a time", "every effect together and every effect but one")
        body = DOC.read_text()
        pattern = re.compile(re.escape(marks[0]) + ".*?" + re.escape(marks[1]), re.S)
        if not pattern.search(body):
            raise SystemExit(f"{DOC}: markers {marks[0]} ... {marks[1]} not found")
        DOC.write_text(pattern.sub(lambda _: f"{marks[0]}\n{text}{marks[1]}", body))
    cols = [f"{q}_err_pct" for q in QUANTITIES]
    table = df.groupby("effect")[cols].agg(["mean", "std"]).round(2)
    print(table.to_string(), file=sys.stderr)
    print(json.dumps({"benchmark": "effect_bias", "records": str(args.out),
                      "mean_error_pct": json.loads(df.groupby("effect")[cols].mean().round(3).to_json())}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
