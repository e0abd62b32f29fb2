"""Is a fit's R-hat failure Monte-Carlo noise?  The null distribution of a real fit's largest
R-hat, from the fit's own draws.

``benchmarks/rhat_null.py`` gives the gate's false-alarm rate for stationary AR(1) chains in
which every quantity has one ESS.  A NUTS fit is not like that: its draws are anti-correlated
for a quantity's mean (bulk ESS above the number of draws) and positively correlated for its
spread, and ArviZ's R-hat is the larger of the rank-normalised split R-hat of the draws and of
their folded draws |x - median| (Vehtari et al. 2021, eqs. 14-15), whose ESS is the spread's.  So
a quantity of bulk ESS 4000 can still carry a folded ESS near 1000.

This script builds chains that are exchangeable by construction out of one fit's draws: every
replicate makes ``chains`` pseudo-chains of the fit's length from blocks of ``--block``
consecutive draws, each block taken from a random chain at a random start, the same blocks for
every quantity (a moving-block bootstrap, Kuensch 1989: it keeps the draws' autocorrelation
within a block and their correlation across quantities).  The largest R-hat of such chains over
all the fit's quantities is what the gate reads when the chains have nothing to disagree
about.  Reported per fit: the observed largest R-hat, its quantity with its bulk and folded
ESS, the null's median and 95th percentile, P(null > gate) (the fit's false-alarm rate) and
the share of null replicates at or above the observed value (small: the chains disagree by
more than their draws' scatter allows).

Fits come from the calibration study's campaigns (``--seeds``: the independent simulator's
``ind-SEED``, fitted with ``fit``'s defaults and the retry off, so the first attempt is what is
read) or from fit directories (``--posterior DIR/posterior.nc``).  Records:
``benchmarks/records/gates/rhat_fit_null.csv``.

    python benchmarks/rhat_fit_null.py --seeds 6092 6096 6093 6094
    python benchmarks/rhat_fit_null.py --posterior out/fit_nuts/posterior.nc
    python benchmarks/rhat_fit_null.py --docs     # the table of docs/calibration.md from the records
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from rhat_null import rank_split_rhat  # noqa: E402

RECORDS = ROOT / "benchmarks" / "records" / "gates" / "rhat_fit_null.csv"


def quantities(posterior) -> tuple[list[str], np.ndarray]:
    """Every scalar of ``posterior`` (an ``xarray.Dataset`` with dims ``chain, draw, ...``) that
    varies and is finite, as names ``var`` / ``var[i]`` and draws ``x[quantity, chain, draw]``:
    the quantities the R-hat gate reads (``results.gate_check``)."""
    names, rows = [], []
    for var, da in posterior.data_vars.items():
        a = np.asarray(da.values, float)
        c, n = a.shape[:2]
        flat = a.reshape(c, n, -1)
        for i in range(flat.shape[2]):
            x = flat[:, :, i]
            if not np.all(np.isfinite(x)) or np.ptp(x) == 0.0:
                continue
            names.append(var if flat.shape[2] == 1 else f"{var}[{i}]")
            rows.append(x)
    return names, np.stack(rows)


def block_bootstrap(x: np.ndarray, block: int, rng: np.random.Generator) -> np.ndarray:
    """Pseudo-chains of ``x[quantity, chain, draw]``'s shape, each the concatenation of blocks of
    ``block`` consecutive draws of a random chain from a random start (the last block cut to
    the length), one set of blocks for all quantities."""
    _, c, n = x.shape
    nb = -(-n // block)
    src = rng.integers(0, c, (c, nb))
    start = rng.integers(0, n - block + 1, (c, nb))
    draw = (start[..., None] + np.arange(block)).reshape(c, -1)[:, :n]
    chain = np.repeat(src, block, axis=1)[:, :n]
    return x[:, chain, draw]


def fit_null(posterior, gate: float, block: int = 100, reps: int = 400, seed: int = 0,
             other_blocks: tuple[int, ...] = ()) -> dict:
    """The observed largest R-hat of a fit's ``posterior`` against its block-bootstrap null
    (module docstring); ``other_blocks``: the null's P(> gate) also for these block lengths
    (``null_p_fail_block{L}``), to show how much the answer depends on the block."""
    import arviz as az

    names, x = quantities(posterior)
    observed = rank_split_rhat(x)
    i = int(np.argmax(observed))
    rng = np.random.default_rng(seed)

    def null_of(length: int) -> np.ndarray:
        return np.array([rank_split_rhat(block_bootstrap(x, length, rng)).max() for _ in range(reps)])

    null = null_of(block)
    xi = x[i]
    folded = np.abs(xi - np.median(xi))
    return {"quantities": len(names), "chains": x.shape[1], "draws": x.shape[2],
            "max_r_hat": float(observed[i]), "max_r_hat_quantity": names[i],
            "its_ess_bulk": float(az.ess(xi, method="bulk")), "its_ess_folded": float(az.ess(folded, method="bulk")),
            "median_ess_bulk": float(np.median([az.ess(q, method="bulk") for q in x])),
            "median_ess_folded": float(np.median([az.ess(np.abs(q - np.median(q)), method="bulk") for q in x])),
            "null_block": block, "null_reps": reps, "null_median": float(np.median(null)),
            "null_q95": float(np.quantile(null, 0.95)), "null_p_fail": float(np.mean(null > gate)),
            "null_share_at_or_above_observed": float(np.mean(null >= observed[i])),
            **{f"null_p_fail_block{b}": float(np.mean(null_of(b) > gate)) for b in other_blocks}}


def fit_campaign(seed: int, pairs_range: tuple[int, int] = (1, 12)):
    """The first attempt of ``fit``'s default NUTS fit of the calibration campaign ``ind-SEED``
    (the retry off), with the gates it read: ``(posterior, failed_gates, record)``."""
    from bayes_roadload.analysis.batch import job_model
    from bayes_roadload.analysis.calibration import calibration_jobs
    from bayes_roadload.inference.kinds import KINDS, FitOptions, resolve_pooling
    from bayes_roadload.inference.nuts import fit_nuts
    from bayes_roadload.inference.results import gate_check, inference_data
    from bayes_roadload.inference.spec import load_model_spec

    job = calibration_jobs([seed], *pairs_range)[0]
    campaign = job.campaign()
    options = FitOptions(method="nuts")
    model = job_model(job, campaign, options)
    pooling = job.pooling
    if pooling == "auto":
        pooling = resolve_pooling(KINDS["traces"], campaign, load_model_spec(model), options).pooling
    t0 = time.perf_counter()
    fit = fit_nuts(campaign, model, pooling=pooling, noise=job.noise, robust=job.robust,
                   sampler=dataclasses.replace(job.sampler, retry=False))
    failed, _ = gate_check(fit)
    record = {"fit": job.name, "pairs": job.tags["pairs"], "model": model, "pooling": pooling,
              "gates_failed": " ".join(failed), "time_fit_s": round(time.perf_counter() - t0, 1)}
    return inference_data(fit).posterior, failed, record


def docs_table(records: pd.DataFrame) -> str:
    """Markdown: one row per fit, and the mean false-alarm rate over the fits."""
    extra = sorted((c for c in records.columns if c.startswith("null_p_fail_block")), key=lambda c: int(c[17:]))
    block = int(records["null_block"].iloc[0])
    lines = ["| fit | pairs | quantities | gates failed | largest R-hat (quantity) | its bulk / folded ESS | "
             "median folded ESS | null median / 95th pct. | P(null > 1.01) | null share >= observed |"
             + "".join(f" P(null > 1.01), blocks of {c[17:]} |" for c in extra),
             "|---|---|---|---|---|---|---|---|---|---|" + "---|" * len(extra)]
    for r in records.to_dict("records"):
        failed = r["gates_failed"] if isinstance(r["gates_failed"], str) and r["gates_failed"] else "none"
        lines.append(f"| {r['fit']} | {r['pairs']} | {r['quantities']} | {failed} | {r['max_r_hat']:.4f} "
                     f"(`{r['max_r_hat_quantity']}`) | {r['its_ess_bulk']:.0f} / {r['its_ess_folded']:.0f} | "
                     f"{r['median_ess_folded']:.0f} | {r['null_median']:.4f} / {r['null_q95']:.4f} | "
                     f"{r['null_p_fail']:.3f} | {r['null_share_at_or_above_observed']:.3f} |"
                     + "".join(f" {r[c]:.3f} |" for c in extra))
    means = f"{records['null_p_fail'].mean():.3f} (blocks of {block})" + "".join(
        f", {records[c].mean():.3f} (blocks of {c[17:]})" for c in extra)
    return "\n".join(lines) + f"\n\nMean P(null > 1.01) over the {len(records)} fits: {means}.\n"


def write_docs(records: pd.DataFrame, path: Path) -> None:
    from doc_sections import replace_section

    reps, block = int(records["null_reps"].iloc[0]), int(records["null_block"].iloc[0])
    text = (f"`python benchmarks/rhat_fit_null.py` (record `{path.resolve().relative_to(ROOT)}`, "
            f"{reps} bootstrap replicates per fit, blocks of {block} draws; fitted at `{records['code'].iloc[0]}`):\n\n"
            + docs_table(records))
    replace_section(ROOT / "docs" / "calibration.md", "<!-- rhat_fit_null:begin -->", "<!-- rhat_fit_null:end -->", text)


def main(argv=None) -> int:
    from bayes_roadload import config
    from gradient_cost import commit_of

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="*", default=[], help="calibration campaigns ind-SEED to fit")
    ap.add_argument("--posterior", type=Path, nargs="*", default=[], help="posterior.nc files of fits")
    ap.add_argument("--block", type=int, default=100, help="draws per bootstrap block")
    ap.add_argument("--other-blocks", type=int, nargs="*", default=[25],
                    help="block lengths whose P(null > gate) is also recorded")
    ap.add_argument("--reps", type=int, default=400)
    ap.add_argument("--records", type=Path, default=RECORDS)
    ap.add_argument("--append", action="store_true", help="add to --records instead of replacing them")
    ap.add_argument("--docs", action="store_true", help="no fitting: write the docs table from --records")
    args = ap.parse_args(argv)
    if args.docs:
        write_docs(pd.read_csv(args.records), args.records)
        return 0
    import arviz as az

    gate = config.DEFAULT_GATES.max_r_hat
    rows = []
    for seed in args.seeds:
        posterior, _, record = fit_campaign(seed)
        rows.append({**record, **fit_null(posterior, gate, args.block, args.reps, seed, tuple(args.other_blocks)), "code": commit_of(ROOT)})
        print(rows[-1], file=sys.stderr, flush=True)
    for path in args.posterior:
        posterior = az.from_netcdf(path).posterior
        rows.append({"fit": str(path), "pairs": np.nan, "gates_failed": "",
                     **fit_null(posterior, gate, args.block, args.reps, 0, tuple(args.other_blocks)), "code": commit_of(ROOT)})
        print(rows[-1], file=sys.stderr, flush=True)
    new = pd.DataFrame(rows)
    if args.append and args.records.exists():
        new = pd.concat([pd.read_csv(args.records), new], ignore_index=True)
    args.records.parent.mkdir(parents=True, exist_ok=True)
    new.to_csv(args.records, index=False)
    print(docs_table(new))
    return 0


if __name__ == "__main__":
    sys.exit(main())
