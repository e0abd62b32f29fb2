# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     name: python3
# ---

# %% [markdown]
# # Validation: the plots behind `docs/validation.md`
#
# `benchmarks/validation_report.py` (and `benchmarks/sbc_study.py`) run the validation studies
# and save their tables in `docs/validation/*.csv`; this notebook plots them:
#
# 1. the thesis simulation study (tables 6.8 / 6.9): our per-pair recoveries of the 19 cases;
# 2. pooling: the spread of one-pair-at-a-time estimates against the joint NUTS fit, and K_D's
#    posterior contraction against the mean |yaw|;
# 3. simulation-based calibration: rank histograms and interval coverage, calibrated analysis
#    against the wrong-mass negative control;
# 4. anemometer calibration: C_D0's error with the airspeed factor fixed wrongly and estimated.
#
# It reads results; it fits nothing (the studies take tens of minutes).  `BR_VALIDATION_DIR`
# points it at another directory of study tables, `BR_OUT` is where the figures go.
#
# **Your own fit:** with `FIT_DIR` (or `BR_FIT_DIR`) set to a `bayes-roadload fit` directory,
# a last section checks that fit: its intervals beside the classical least-squares fit of the
# same campaign, and beside the truth when the campaign was simulated.

# %% tags=["parameters"]
import os

FIT_DIR = os.environ.get("BR_FIT_DIR") or None  # a `bayes-roadload fit` output directory, or None

# %%
import os
from pathlib import Path

import matplotlib

matplotlib.use(os.environ.get("MPLBACKEND", "Agg"))
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from bayes_roadload.analysis.sbc import SBC_BINS, SBC_PARAMETERS, rank_fractions, sbc_tests

HERE = Path.cwd() if "__file__" not in globals() else Path(__file__).resolve().parent
DATA = Path(os.environ.get("BR_VALIDATION_DIR", HERE.parent / "docs" / "validation"))
OUT = Path(os.environ.get("BR_OUT", "."))
tables = {p.stem: pd.read_csv(p) for p in sorted(DATA.glob("*.csv"))}
print("study tables:", ", ".join(tables) or "none (run benchmarks/validation_report.py)")

# %% [markdown]
# ## 1. Thesis tables 6.8 / 6.9
# Error of each case's per-pair estimate against the nominal truth, 4-term and 3-term analyses.

# %%
cases = tables.get("thesis_cases")
if cases is not None:
    err_cols = [c for c in cases.columns if c.endswith("_err_pct")]
    fig, axes = plt.subplots(1, len(err_cols), figsize=(3.2 * len(err_cols), 3.2), sharex=True)
    for ax, col in zip(np.atleast_1d(axes), err_cols):
        for analysis, g in cases.groupby("analysis"):
            ax.plot(g["case"], g[col], "o", label=analysis, alpha=0.8)
        ax.axhline(0, color="k", lw=0.5)
        ax.set_title(col.replace("_err_pct", "") + " error (%)")
        ax.set_xlabel("case (table 6.7)")
    np.atleast_1d(axes)[0].legend()
    fig.tight_layout()
    fig.savefig(OUT / "validation_thesis_cases.png", dpi=80)

# %% [markdown]
# ## 2. Pooling
# Left: spread of the estimates (std in % of the mean) one pair at a time, and of the joint
# NUTS estimate over independent campaigns of 6 and 24 pairs, beside what averaging n
# independent pairs would give (dashed).  Right: K_D's posterior contraction (1 - posterior
# variance / prior variance) against the mean |yaw| the cross wind produces.

# %%
pool, yaw = tables.get("pooling_table"), tables.get("yaw_table")
if pool is not None and yaw is not None:
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.6))
    params = list(dict.fromkeys(pool["parameter"]))
    analyses = list(dict.fromkeys(pool["analysis"]))
    width = 0.8 / len(analyses)
    for i, a in enumerate(analyses):
        g = pool[pool["analysis"] == a].set_index("parameter").loc[params]
        x = np.arange(len(params)) + i * width
        ax1.bar(x, g["spread_pct"], width, label=a)
        ax1.plot(x, g["expected_spread_pct"], "k_", ms=12)
    ax1.set_xticks(np.arange(len(params)) + 0.4 - width / 2, params)
    ax1.set_yscale("log")
    ax1.set_ylabel("spread (std, % of mean)")
    ax1.legend(fontsize=7)
    ax2.plot(yaw["mean_abs_yaw_deg"], yaw["contraction"], "o-")
    for _, r in yaw.iterrows():
        ax2.annotate(f"{r['cross_wind_mps']:g} m/s", (r["mean_abs_yaw_deg"], r["contraction"]), fontsize=7)
    ax2.set_xlabel("mean |yaw| (deg)")
    ax2.set_ylabel("K_D posterior contraction")
    ax2.set_ylim(-0.05, 1.05)
    fig.tight_layout()
    fig.savefig(OUT / "validation_pooling.png", dpi=80)

# %% [markdown]
# ## 3. Simulation-based calibration
# Histograms of the normalised rank of the truth among the posterior draws: flat under
# calibration (grey band: the 99 % range of a bin count for uniform ranks), piled at one end when
# the analysis is mis-specified (the vehicle's effective mass stated 5 % high).

# %%
sbc = tables.get("sbc_records")
if sbc is not None:
    u = rank_fractions(sbc)
    arms = list(dict.fromkeys(u["arm"]))
    fig, axes = plt.subplots(len(arms), len(SBC_PARAMETERS), figsize=(2.2 * len(SBC_PARAMETERS), 2.2 * len(arms)),
                             squeeze=False)
    for i, arm in enumerate(arms):
        for j, p in enumerate(SBC_PARAMETERS):
            x = u[(u["arm"] == arm) & (u["parameter"] == p)]["u"]
            n = len(x)
            ax = axes[i, j]
            lo, hi = np.clip(n / SBC_BINS + np.array([-2.58, 2.58]) * np.sqrt(n / SBC_BINS * (1 - 1 / SBC_BINS)), 0, None)
            ax.axhspan(lo, hi, color="0.85")
            ax.hist(x, bins=SBC_BINS, range=(0, 1), color="C0" if arm == "calibrated" else "C3")
            ax.set_title(f"{arm}: {p}", fontsize=8)
            ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(OUT / "validation_sbc_ranks.png", dpi=80)
    print(sbc_tests(sbc)[["arm", "parameter", "n", "p_value", "coverage50", "coverage90", "coverage95"]].round(3))

# %% [markdown]
# ## 4. Anemometer calibration
# C_D0's error (%) when the logged airspeed reads 1 % high: the factor fixed at 1 (classical and
# Bayesian fits) against the factor estimated jointly from the paired runs.

# %%
cal = tables.get("calibration")
if cal is not None and "CD0_err_pct" in cal:
    g = cal.groupby(["analysis", "model"], sort=False)["CD0_err_pct"].agg(["mean", "std", "count"]).reset_index()
    fig, ax = plt.subplots(figsize=(7, 3))
    labels = [f"{a}\n{m}" for a, m in zip(g["analysis"], g["model"])]
    ax.bar(range(len(g)), g["mean"], yerr=g["std"].fillna(0), color="C1")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xticks(range(len(g)), labels, fontsize=7)
    ax.set_ylabel("C_D0 error (%)")
    fig.tight_layout()
    fig.savefig(OUT / "validation_calibration.png", dpi=80)


# %% [markdown]
# ## 5. Your fit (`FIT_DIR`): posterior beside classical least squares and the truth
# The classical joint least-squares fit (thesis chapter 5, one group) of the campaign the fit
# recorded; a posterior interval far from it, or a simulated truth outside the 95 % interval,
# is worth a look.

# %%
if FIT_DIR:
    import json

    from bayes_roadload.data import load_campaign
    from bayes_roadload.inference.lsq import fit_lsq

    record = json.loads((Path(FIT_DIR) / "fit.json").read_text())
    campaign = load_campaign(record["campaign"])
    posterior = pd.read_csv(Path(FIT_DIR) / "summary.csv").set_index("parameter")
    classical = fit_lsq(campaign, record.get("model_file") or record["model"], grouping="all")
    mine = pd.DataFrame({q: {"posterior mean": posterior.loc[q, "mean"], "q2.5": posterior.loc[q, "q2.5"],
                             "q97.5": posterior.loc[q, "q97.5"], "least squares": classical.weighted_mean.get(q),
                             "truth": (campaign.truth or {}).get(q)}
                         for q in ("AD", "BD", "CD0", "KD", "F50_N", "F0_N") if q in posterior.index}).T
    mine["truth inside"] = [(lo <= t <= hi) if t == t and t is not None else None
                            for lo, hi, t in zip(mine["q2.5"], mine["q97.5"], mine["truth"])]
    print(mine.to_string(float_format=lambda x: f"{x:.6g}"))
    fig, ax = plt.subplots(figsize=(6, 3))
    rel = [(mine.loc[q, "least squares"] / mine.loc[q, "posterior mean"] - 1) * 100 for q in mine.index]
    half = [(mine.loc[q, "q97.5"] - mine.loc[q, "q2.5"]) / 2 / abs(mine.loc[q, "posterior mean"]) * 100
            for q in mine.index]
    ax.errorbar(range(len(mine)), np.zeros(len(mine)), yerr=half, fmt="o", label="posterior 95 %")
    ax.plot(range(len(mine)), rel, "rx", label="least squares")
    ax.set_xticks(range(len(mine)), mine.index)
    ax.set_ylabel("% of the posterior mean")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / "validation_your_fit.png", dpi=80)
