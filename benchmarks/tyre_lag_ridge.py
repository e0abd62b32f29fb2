"""The tyre-lag model on campaigns without a tyre lag: where its fits diverge.

Fits ``bayes-roadload demo``'s campaign (thesis case 14, basic drag model, the project's own
simulator: no tyre thermal lag) with ``models/four_term_tyre_lag.toml`` -- and, with
``truncated``, a copy whose gain prior is truncated at zero -- at one pair (seeds 1, 2) and six
pairs (seed 1), each through ``demo`` itself (its options, pooling and sampler with the retry).
Records per fit (``benchmarks/records/tyre_lag_ridge.jsonl``): the gates, the retry, the
posterior of the gain G_T, its correlation with A_D, B_D and the noise intensity q, where the
divergent draws sit (q and G_T), and which 95 % intervals of AD, BD, CD0, KD hold the truth.
docs/calibration.md (*Other campaign sizes, and why the lag is not the default yet*) reads it.

    python benchmarks/tyre_lag_ridge.py
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

RECORDS = ROOT / "benchmarks" / "records" / "tyre_lag_ridge.jsonl"
MODEL = ROOT / "models" / "four_term_tyre_lag.toml"
GAIN = "tyre_lag_gain_per_mps"
RUNS = ((1, 1, "normal"), (1, 2, "normal"), (1, 1, "truncated"), (1, 2, "truncated"), (6, 1, "normal"))


def truncated_model(directory: Path) -> Path:
    """The shipped tyre-lag model file with its gain prior truncated at zero (renamed)."""
    text = MODEL.read_text()
    old = 'prior = { dist = "normal", loc = 0.0057, scale = 0.003 }'
    if old not in text:
        raise SystemExit(f"{MODEL}: the gain prior is no longer {old!r}; update this study")
    text = text.replace(old, old.replace(" }", ", low = 0.0 }")).replace(
        'name = "four_term_tyre_lag"', 'name = "four_term_tyre_lag_truncated"')
    path = directory / "four_term_tyre_lag_truncated.toml"
    path.write_text(text)
    return path


def read_fit(out: Path) -> dict:
    """The record of one demo directory: gates, G_T's posterior, correlations, divergent draws."""
    import arviz as az
    import pandas as pd

    diag = json.loads((out / "fit_nuts" / "diagnostics.json").read_text())
    truth = json.loads((out / "campaign" / "truth.json").read_text())
    summary = pd.read_csv(out / "fit_nuts" / "summary.csv").set_index("parameter")
    idata = az.from_netcdf(out / "fit_nuts" / "posterior.nc")
    post = idata.posterior
    gain = post[GAIN].values.ravel()
    div = idata.sample_stats["diverging"].values.ravel().astype(bool)
    q = post["q_mps_per_sqrt_s"].values.ravel()
    rec = {"pass": bool(diag["pass"]), "failed": diag["failed"], "retries": len(diag.get("retries") or []),
           "first_failed": (diag.get("retries") or [{}])[0].get("failed"),
           "divergences": int(diag["divergences"]), "pooling": diag["pooling"],
           "gain_mean": float(gain.mean()), "gain_sd": float(gain.std(ddof=1)),
           "q_median": float(np.median(q)),
           "corr_gain": {v: float(np.corrcoef(gain, post[v].values.ravel())[0, 1])
                         for v in ("AD", "BD", "q_mps_per_sqrt_s")},
           "divergent_q": [float(q[div].min()), float(q[div].max())] if div.any() else None,
           "divergent_gain": [float(gain[div].min()), float(gain[div].max())] if div.any() else None,
           "in95": {k: bool(summary.loc[k, "q2.5"] <= truth[k] <= summary.loc[k, "q97.5"])
                    for k in ("AD", "BD", "CD0", "KD")}}
    return rec


def main() -> None:
    from bayes_roadload.cli import main as cli

    stamp = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    RECORDS.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="tyre_lag_ridge_") as tmp:
        tmp = Path(tmp)
        models = {"normal": MODEL, "truncated": truncated_model(tmp)}
        for pairs, seed, prior in RUNS:
            out = tmp / f"p{pairs}_s{seed}_{prior}"
            t0 = time.perf_counter()
            cli(["demo", "--pairs", str(pairs), "--seed", str(seed), "--model", str(models[prior]),
                 "--no-progress", "--out", str(out), "-q"])
            rec = {"date": stamp, "case": 14, "pairs": pairs, "seed": seed, "gain_prior": prior,
                   "wall_s": round(time.perf_counter() - t0, 1), **read_fit(out)}
            with RECORDS.open("a") as f:
                f.write(json.dumps(rec) + "\n")
            print(json.dumps(rec), flush=True)


if __name__ == "__main__":
    main()
