"""The Laplace refits' importance correction against NUTS, proposal by proposal.

`plan` refits every future campaign by MAP + Laplace, corrected by Pareto-smoothed importance
sampling (``bayes_roadload/inference/laplace.py``); the correction is three quarters of a 12-pair
refit's time (docs/planning.md section 7).  This study refits the same future campaigns -- the
planning jobs of ``plan_jobs`` from a source fit, by default the issue's 12-pair reference fit of
``benchmarks/plan_time.py`` (thesis case 14, seed 1, hierarchical four_term) -- by

* each importance-sampling scheme of ``SCHEMES`` (a proposal family and its inflations, tried in
  turn or mixed as ``laplace._importance_draws`` does; ``--schemes`` picks some), the same MAP for
  all, and
* NUTS with the fit's defaults (``method="nuts"`` through the batch door, without the Type B
  draws: the posterior itself, the reference),

and records, per campaign and scheme, the 95 % half-widths of AD, BD, CD0 and F50_N (percent of
the posterior mean, as ``planning.half_widths``), the Pareto k, the effective sample size, the
inflation kept, the posterior evaluations and the time of the correction.  ``--docs`` writes the
summary (half-width ratio to NUTS by size and scheme) into docs/planning.md from the records alone.

    python benchmarks/laplace_proposals.py --pairs 2 6 12 --campaigns 6 [--fit-dir DIR]
    python benchmarks/laplace_proposals.py --docs
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from doc_sections import replace_section  # noqa: E402

RECORDS = ROOT / "benchmarks" / "records" / "performance" / "laplace_proposals.jsonl"
DOC = ROOT / "docs" / "planning.md"
BEGIN, END = "<!-- laplace proposals: begin -->", "<!-- laplace proposals: end -->"
QUANTITIES = ("AD", "BD", "CD0", "F50_N")
SCHEMES = {  # name (as the records call it): (family, inflations, combine)
    "t5 1.0/1.5/2.0": ("t", (1.0, 1.5, 2.0), "sequential"),
    "normal 1.1/1.25/1.5": ("normal", (1.1, 1.25, 1.5), "sequential"),
    "normal 1.1": ("normal", (1.1,), "sequential"),
    "normal 1.35": ("normal", (1.35,), "sequential"),
    "t5 mixture 1.0/1.5/2.0": ("t", (1.0, 1.5, 2.0), "mixture"),
    "t5 1.5/2.0": ("t", (1.5, 2.0), "sequential"),
    "t5 mixture 1.5/2.0": ("t", (1.5, 2.0), "mixture"),
}


def _half_widths(samples) -> dict[str, float]:
    out = {}
    for q in QUANTITIES:
        x = np.asarray(samples[q], float).ravel()
        lo, hi = np.quantile(x, [0.025, 0.975])
        out[q] = float(100.0 * (hi - lo) / 2.0 / abs(x.mean()))
    return out


def run(fit_dir: Path, pairs: list[int], campaigns: int, note: str, schemes: list[str], nuts: bool = True) -> None:
    from bayes_roadload.analysis.batch import run_job
    from bayes_roadload.analysis.planning import half_widths, plan_jobs, population_from_samples
    from bayes_roadload.data import load_campaign
    from bayes_roadload.inference.laplace import fit_laplace
    from bayes_roadload.output import read_fit_dir

    src = read_fit_dir(fit_dir)
    pop = population_from_samples(src.samples, src.record["free"], src.model, load_campaign(src.record["campaign"]),
                                  source=str(fit_dir))
    stamp = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "note": note}
    RECORDS.parent.mkdir(parents=True, exist_ok=True)
    for job in plan_jobs(pop, pairs, simulations=campaigns):
        campaign = job.campaign()
        base = {**stamp, "pairs": job.tags["n_pairs"], "simulation": job.tags["simulation"], "model": job.model,
                "pooling": job.pooling}
        rows = []
        for name in schemes:
            family, inflations, combine = SCHEMES[name]
            fit = fit_laplace(campaign, job.model, pooling=job.pooling, start=job.start, proposal=family,
                              inflations=inflations, combine=combine)
            d = fit.diagnostics
            rows.append({**base, "method": name, "half_width_pct": _half_widths(fit.samples),
                         "pareto_k": d["pareto_k"], "is_ess": d["is_ess"], "inflation": d["proposal_inflation"],
                         "evaluations": d["is_evaluations"], "importance_s": fit.timings["importance_s"],
                         "map_s": fit.timings["map_s"]})
        if not nuts:
            _write(rows, base)
            continue
        # the posterior itself on both sides: no Type B draws added (the Laplace fits above have none)
        rec = run_job(dataclasses.replace(job, method="nuts", type_b=False, name=job.name.replace("laplace", "nuts")))
        frame = pd.DataFrame([rec])
        rows.append({**base, "method": "nuts", "half_width_pct": {q: float(half_widths(frame, q).iloc[0])
                                                                  for q in QUANTITIES},
                     "gate_pass": bool(rec["gate_pass"]), "gates_failed": rec.get("gates_failed", ""),
                     "fit_s": float(rec["time_fit_s"])})
        _write(rows, base)


def _write(rows: list[dict], base: dict) -> None:
    with RECORDS.open("a") as f:
        for r in rows:
            f.write(json.dumps(r) + "\n")
    print(json.dumps({"pairs": base["pairs"], "simulation": base["simulation"],
                      **{r["method"]: {q: round(v, 3) for q, v in r["half_width_pct"].items()} for r in rows}}),
          flush=True)


def summary(records: pd.DataFrame) -> pd.DataFrame:
    """Per refitted model, size and scheme (refits: one per campaign and invocation; invocations
    with the same sizes refit the same campaigns): the median and range of the half-width ratio to NUTS
    over campaigns and quantities (where the invocation ran NUTS: "-" otherwise), the share of
    refits whose Pareto k fails the gate, the median k, effective sample size and posterior
    evaluations."""
    from bayes_roadload.config import LAPLACE_GOOD_PARETO_K, LAPLACE_MAX_PARETO_K

    records = records.assign(refit_model=records["model"].map(lambda m: Path(str(m)).stem))
    key = ["date", "pairs", "simulation"]  # each invocation refits its own campaigns with NUTS
    nuts = records[records["method"] == "nuts"].set_index(key)["half_width_pct"]
    rows = []
    for (model, pairs, method), g in records[records["method"] != "nuts"].groupby(["refit_model", "pairs", "method"],
                                                                                  sort=True):
        ratios = [r["half_width_pct"][q] / nuts.loc[(r["date"], r["pairs"], r["simulation"])][q]
                  for _, r in g.iterrows() if (r["date"], r["pairs"], r["simulation"]) in nuts.index
                  for q in QUANTITIES]
        k = g["pareto_k"].astype(float)
        rows.append({"model": model, "pairs": int(pairs), "scheme": method, "refits": len(g),
                     "median ratio": round(float(np.median(ratios)), 3) if ratios else "-",
                     "ratio 10-90 %": f"{np.quantile(ratios, 0.1):.2f}-{np.quantile(ratios, 0.9):.2f}" if ratios else "-",
                     f"k > {LAPLACE_GOOD_PARETO_K}": f"{int((k > LAPLACE_GOOD_PARETO_K).sum())} / {len(k)}",
                     f"k > {LAPLACE_MAX_PARETO_K} (gate)": f"{int((k > LAPLACE_MAX_PARETO_K).sum())} / {len(k)}",
                     "median k": round(float(k.median()), 2),
                     "median ESS": round(float(g["is_ess"].median())),
                     "mean evaluations": round(float(g["evaluations"].mean())),
                     "mean correction s": round(float(g["importance_s"].mean()), 2)})
    return pd.DataFrame(rows)


def _markdown(table: pd.DataFrame) -> str:
    lines = ["| " + " | ".join(table.columns) + " |", "|" + "---|" * len(table.columns)]
    lines += ["| " + " | ".join(str(v) for v in row) + " |" for row in table.itertuples(index=False)]
    return "\n".join(lines) + "\n"


def docs() -> None:
    records = pd.read_json(RECORDS, lines=True)
    table = summary(records)
    nuts = records[records["method"] == "nuts"]
    text = (f"Generated by `benchmarks/laplace_proposals.py --docs` from `{RECORDS.relative_to(ROOT)}`: future "
            "campaigns of the 12-pair reference fit's population (by refitted model), each refitted by MAP + "
            "Laplace with every importance scheme of its invocation (same MAP) and, except with `--no-nuts`, "
            f"by NUTS with the fit's defaults ({nuts.groupby('pairs').size().to_dict()} NUTS refits by size, "
            f"{int(nuts['gate_pass'].sum())} of {len(nuts)} passed their gates).  Ratio: Laplace / NUTS 95 % "
            "half-width of AD, BD, CD0 and F50_N, over campaigns and quantities ('-': no NUTS refit).  A refit "
            "whose k exceeds the gate fails it.\n\n" + _markdown(table))
    replace_section(DOC, BEGIN, END, text, heading="## 9. The importance correction's proposal against NUTS")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--pairs", type=int, nargs="+", default=[2, 6, 12])
    p.add_argument("--campaigns", type=int, default=6)
    p.add_argument("--fit-dir", type=Path, default=None, help="source fit (default: plan_time's reference fit)")
    p.add_argument("--note", default="")
    p.add_argument("--schemes", nargs="+", default=list(SCHEMES), choices=list(SCHEMES), metavar="SCHEME",
                   help=f"the importance schemes to run (default: all of {list(SCHEMES)})")
    p.add_argument("--no-nuts", action="store_true",
                   help="compare the schemes with each other only (no NUTS refit: no half-width ratio)")
    p.add_argument("--docs", action="store_true", help="only regenerate the docs section from the records")
    a = p.parse_args()
    if a.docs:
        docs()
        return
    if a.fit_dir is None:
        from plan_time import reference_fit

        with tempfile.TemporaryDirectory(prefix="laplace_proposals_") as tmp:
            run(reference_fit(Path(tmp)), a.pairs, a.campaigns, a.note, a.schemes, not a.no_nuts)
    else:
        run(a.fit_dir, a.pairs, a.campaigns, a.note, a.schemes, not a.no_nuts)
    docs()


if __name__ == "__main__":
    main()
