"""How often the R-hat gate fails on chains that have converged: the null distribution of the
largest rank-normalised split R-hat over many quantities.

Each replicate draws ``k`` independent quantities, each sampled by ``m`` chains of ``n`` draws
from the same stationary AR(1) process x_t = phi x_{t-1} + e_t (so every chain is in
equilibrium from its first draw: any R-hat above 1 is Monte-Carlo noise), computes ArviZ's
R-hat (``az.rhat``'s rank-normalised split R-hat, the larger of the bulk and the folded
statistic, vectorised over the quantities and checked against ``az.rhat`` to 1e-9 at the
start) and the bulk ESS of one quantity, and records whether the largest R-hat exceeds the
gate (:data:`bayes_roadload.config.DEFAULT_GATES` ``max_r_hat``).  The AR(1) coefficient sets
the ESS: about m n (1 - phi) / (1 + phi).

A fit's gate reads the largest R-hat over all its quantities (coefficients, run offsets, noise
scales: ~20 at one pair, ~80 at 18 pairs), so its false-alarm rate grows with their number and
falls with their ESS.  Records: ``benchmarks/records/gates/rhat_null.json``.

    python benchmarks/rhat_null.py [--reps 200] [--quantities 20 80]
    python benchmarks/rhat_null.py --docs     # the table of docs/calibration.md from the records
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "benchmarks" / "records" / "gates" / "rhat_null.json"


def ar1(rng: np.random.Generator, phi: float, shape: tuple[int, ...], n: int) -> np.ndarray:
    """Stationary AR(1) draws of unit innovation variance, ``shape + (n,)``."""
    from scipy.signal import lfilter

    e = rng.normal(size=shape + (n,))
    e[..., 0] /= np.sqrt(1.0 - phi**2)  # the first draw from the stationary distribution
    return lfilter([1.0], [1.0, -phi], e, axis=-1)


def _rhat(y: np.ndarray) -> np.ndarray:
    """Potential scale reduction of chains ``y[..., chain, draw]`` (BDA3 eq. 11.4)."""
    n = y.shape[-1]
    w = y.var(axis=-1, ddof=1).mean(axis=-1)
    b = n * y.mean(axis=-1).var(axis=-1, ddof=1)
    return np.sqrt(((n - 1) / n * w + b / n) / w)


def _z_scale(y: np.ndarray) -> np.ndarray:
    """Rank-normalise every quantity over all its chains and draws (Vehtari et al. 2021, eq. 14)."""
    from scipy.special import ndtri
    from scipy.stats import rankdata

    k = y.shape[0]
    flat = y.reshape(k, -1)
    r = rankdata(flat, method="average", axis=1)
    return ndtri((r - 0.375) / (flat.shape[1] + 0.25)).reshape(y.shape)


def rank_split_rhat(x: np.ndarray) -> np.ndarray:
    """ArviZ's ``az.rhat`` (method "rank") of every quantity of ``x[quantity, chain, draw]`` at
    once: the larger of the split R-hat of the rank-normalised draws and of their folded
    (|x - median|) rank-normalised draws."""
    half = x.shape[-1] // 2
    xs = np.concatenate([x[..., :half], x[..., -half:]], axis=1)
    folded = np.abs(xs - np.median(xs.reshape(xs.shape[0], -1), axis=1)[:, None, None])
    return np.maximum(_rhat(_z_scale(xs)), _rhat(_z_scale(folded)))


def replicate(rng, phi: float, k: int, m: int, n: int, gate: float) -> dict[str, float]:
    """One fit's worth of converged chains: the largest R-hat of ``k`` quantities, and the bulk
    ESS (``az.ess``) of the first."""
    import arviz as az

    x = ar1(rng, phi, (k, m), n)
    r = rank_split_rhat(x)
    return {"max_rhat": float(r.max()), "ess": float(az.ess(x[0], method="bulk")), "fail": bool(r.max() > gate)}


def check_against_arviz(rng, reps: int = 5) -> float:
    """Largest difference between :func:`rank_split_rhat` and ``az.rhat`` on random chains."""
    import arviz as az

    worst = 0.0
    for _ in range(reps):
        x = ar1(rng, 0.5, (4, 2), 300)
        ours = rank_split_rhat(x)
        theirs = np.asarray([float(az.rhat(x[i])) for i in range(x.shape[0])])
        worst = max(worst, float(np.abs(ours - theirs).max()))
    return worst


def main(argv=None) -> int:
    from bayes_roadload import config

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=200)
    ap.add_argument("--quantities", type=int, nargs="+", default=[20, 80])
    ap.add_argument("--phi", type=float, nargs="+", default=[0.0, 0.3, 0.5, 0.7])
    ap.add_argument("--chains", default="2x1000,4x500,2x2000", help="comma-separated MxN: M chains of N draws")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--records", type=Path, default=RECORDS)
    ap.add_argument("--docs", action="store_true", help="no simulation: write the docs table from --records")
    args = ap.parse_args(argv)
    if args.docs:
        write_docs(json.loads(args.records.read_text()), args.records)
        return 0

    gate = config.DEFAULT_GATES.max_r_hat
    rng = np.random.default_rng(args.seed)
    agreement = check_against_arviz(rng)
    if agreement > 1e-9:
        raise SystemExit(f"the vectorised R-hat differs from az.rhat by {agreement:.3g}")
    rows = []
    t0 = time.perf_counter()
    for spec in args.chains.split(","):
        m, n = (int(v) for v in spec.split("x"))
        for phi in args.phi:
            for k in args.quantities:
                reps = [replicate(rng, phi, k, m, n, gate) for _ in range(args.reps)]
                fails = sum(r["fail"] for r in reps)
                p = fails / args.reps
                row = {"chains": m, "draws": n, "phi": phi, "quantities": k, "reps": args.reps,
                       "ess_bulk_median": round(float(np.median([r["ess"] for r in reps])), 1),
                       "max_rhat_median": round(float(np.median([r["max_rhat"] for r in reps])), 5),
                       "p_fail": p, "p_fail_se": round(float(np.sqrt(p * (1 - p) / args.reps)), 4)}
                rows.append(row)
                print(json.dumps(row), file=sys.stderr)
    out = {"benchmark": "rhat_null", "gate_max_r_hat": gate, "seed": args.seed, "agreement_with_arviz": agreement,
           "wall_s": round(time.perf_counter() - t0, 1), "rows": rows}
    args.records.parent.mkdir(parents=True, exist_ok=True)
    args.records.write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps(out, indent=1))
    return 0


def docs_table(record: dict) -> str:
    """Markdown: the false-alarm rate of the gate by chains x draws, ESS and number of quantities."""
    rows = record["rows"]
    ks = sorted({r["quantities"] for r in rows})
    lines = [f"| chains x draws | AR(1) phi | bulk ESS (median) | "
             + " | ".join(f"P(max R-hat > {record['gate_max_r_hat']}), {k} quantities" for k in ks) + " |",
             "|---|---|---|" + "---|" * len(ks)]
    keyed = {(r["chains"], r["draws"], r["phi"], r["quantities"]): r for r in rows}
    for m, n, phi in dict.fromkeys((r["chains"], r["draws"], r["phi"]) for r in rows):
        cells = []
        for k in ks:
            r = keyed.get((m, n, phi, k))
            cells.append("-" if r is None else f"{r['p_fail']:.3f} +- {r['p_fail_se']:.3f}")
        ess = next(r["ess_bulk_median"] for r in rows if (r["chains"], r["draws"], r["phi"]) == (m, n, phi))
        lines.append(f"| {m} x {n} | {phi:g} | {ess:.0f} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def write_docs(record: dict, path: Path) -> None:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from doc_sections import replace_section

    text = (f"`python benchmarks/rhat_null.py` (record `{path.resolve().relative_to(ROOT)}`, "
            f"{record['rows'][0]['reps']} replicates per row, seed {record['seed']}):\n\n" + docs_table(record))
    replace_section(ROOT / "docs" / "calibration.md", "<!-- rhat_null:begin -->", "<!-- rhat_null:end -->", text)


if __name__ == "__main__":
    sys.exit(main())
