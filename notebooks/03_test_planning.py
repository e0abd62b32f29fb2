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
# # Test planning: how many pairs, from the posterior
#
# "How many more pairs of coastdowns until C_D0 is known to 1 % and the road load at 50 mph to
# 0.5 %, at 95 %?"  `bayes-roadload plan` answers it by simulating future campaigns from a fitted
# posterior (or from a pilot's summary numbers) and refitting each one cheaply (MAP + Laplace,
# checked against NUTS).  This notebook
#
# 1. replays the thesis' planning table 8.6 from its summary numbers, beside the predictive
#    distribution of the half-width a future campaign will actually get;
# 2. shows what a simulated future campaign is: observed conditions resampled, coefficients
#    drawn from the population, noise added;
# 3. plots the study behind `docs/planning.md` (`benchmarks/planning_study.py`, tables in
#    `docs/planning/`): assurance curves, Laplace against NUTS, K_D against the yaw, and what a
#    constrained model buys and costs.
#
# It fits nothing itself (the study takes tens of minutes).  `BR_PLANNING_DIR` points it at
# another directory of study tables, `BR_OUT` is where the figures go.
#
# **Your own fit:** with `FIT_DIR` (or `BR_FIT_DIR`) set to a `bayes-roadload fit` directory,
# section 2 draws the future campaign from that fit's posterior and campaign, and section 5 plans
# from it as `bayes-roadload plan FIT_DIR` does (`BR_PLAN_SIMULATIONS` campaigns per size).

# %% tags=["parameters"]
import os

FIT_DIR = os.environ.get("BR_FIT_DIR") or None  # a `bayes-roadload fit` output directory, or None

# %%
import os
import sys
import warnings
from pathlib import Path

import matplotlib

matplotlib.use(os.environ.get("MPLBACKEND", "Agg"))
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

HERE = Path.cwd() if "__file__" not in globals() else Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))  # the studies package sits beside bayes_roadload, outside the wheel

from bayes_roadload.analysis import planning as pl  # noqa: E402
from bayes_roadload.simulate import simulate_campaign  # noqa: E402
from studies.planning_report import thesis_replay_table  # noqa: E402
from studies.thesis_tables import THESIS_TARGETS_PCT  # noqa: E402

DATA = Path(os.environ.get("BR_PLANNING_DIR", HERE.parent / "docs" / "planning"))
OUT = Path(os.environ.get("BR_OUT", "."))
tables = {p.stem: pd.read_csv(p) for p in sorted(DATA.glob("*.csv"))}
print("study tables:", ", ".join(tables) or "none (run benchmarks/planning_study.py)")

# %% [markdown]
# ## 1. Table 8.6 replayed
# The thesis: half-width = 1.96 s / sqrt(n), s the spread of its 18 pairs taken as the
# population's.  Ours: the spread's uncertainty kept, and the future campaign's own t-interval.

# %%
replay = thesis_replay_table(simulations=4000)
t86 = replay[replay["table"].str.startswith("8.6")]
fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
for ax, q in zip(axes, ("AD", "F50_N")):
    g = t86[(t86["quantity"] == q) & (t86["n_pairs"] > 1)]
    ax.plot(g["n_pairs"], g["published"], "ks--", label="thesis table 8.6")
    ax.plot(g["n_pairs"], g["median_half_width"], "o-", label="ours: median")
    ax.fill_between(g["n_pairs"], g["q10_half_width"], g["q90_half_width"], alpha=0.2, label="ours: 10-90 %")
    ax.axhline(THESIS_TARGETS_PCT[q], color="r", lw=0.8)
    ax.set(xscale="log", yscale="log", xlabel="pairs", ylabel="95 % half-width (% of mean)", title=q)
    ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(OUT / "planning_thesis_replay.png", dpi=100)
need = t86.groupby("quantity")[["thesis_n_for_target", "n_for_target"]].first()
print(need)
assert (need["n_for_target"] >= need["thesis_n_for_target"]).all()

# %% [markdown]
# ## 2. One simulated future campaign
# Conditions of an observed campaign (here a simulated one), coefficients from the pilot's
# population, the coastdown integrated through the reconstructed wind, speed noise added.

# %%
if FIT_DIR:  # the population of your fit: its posterior draws and its campaign's conditions
    from bayes_roadload.data import load_campaign
    from bayes_roadload.output.fitdir import read_fit_dir

    source = read_fit_dir(FIT_DIR)
    observed = load_campaign(source.record["campaign"])
    pilot = pl.population_from_samples(source.samples, source.record["free"], source.model, observed,
                                       source=f"fit {FIT_DIR}")
else:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        observed = simulate_campaign(14, pairs=int(os.environ.get("BR_PAIRS", "2")), seed=0)
    pilot = pl.population_from_pilot({"AD": 0.0095, "BD": 0.214e-3, "CD0": 0.393},
                                     {"AD": 4.3, "BD": 23.1, "CD0": 4.3}, 18, observed, "three_term",
                                     noise={"sigma_mps": 0.05, "q_mps_per_sqrt_s": 0.002})
future = pl.simulate_future(pilot, pairs=2, seed=7)
fig, ax = plt.subplots(figsize=(6, 3.5))
for rid, g in observed.runs.groupby("run"):
    ax.plot(g["time_s"] - g["time_s"].iloc[0], g["speed_mps"], color="0.6", lw=1)
for rid, g in future.runs.groupby("run"):
    ax.plot(g["time_s"] - g["time_s"].iloc[0], g["speed_mps"], lw=1, label=f"future run {rid}")
ax.set(xlabel="time into run (s)", ylabel="speed (m/s)", title="observed (grey) and simulated future runs")
ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(OUT / "planning_future_campaign.png", dpi=100)
print("population draw:", future.meta["population_draw"], {k: round(v, 6) for k, v in future.truth.items()})

# %% [markdown]
# ## 3. The study: assurance against pairs (section 2 of docs/planning.md)

# %%
sim = tables.get("simulated_records")
if sim is not None:
    targets = [pl.Target("AD", 1.0), pl.Target("CD0", 1.0), pl.Target("F50_N", 1.0)]
    tab = pl.plan_table(sim, targets)
    pl.plot_plan(tab, targets, OUT / "planning_assurance.png")
    print(tab[["quantity", "n_pairs", "median_half_width", "assurance"]].to_string(index=False))

# %% [markdown]
# ## 4. Laplace against NUTS, K_D against the yaw, constrained models

# %%
fig, axes = plt.subplots(1, 3, figsize=(14, 3.8))
nuts = tables.get("nuts_check_records")
if nuts is not None:
    ok = nuts[nuts["error"].isna()]
    lap = ok[ok["method"] == "laplace"].set_index(["n_pairs", "simulation"])
    nu = ok[ok["method"] == "nuts"].set_index(["n_pairs", "simulation"])
    both = lap.index.intersection(nu.index)
    for q in ("AD", "BD", "CD0", "F50_N"):
        axes[0].plot(pl.half_widths(nu.loc[both], q), pl.half_widths(lap.loc[both], q), "o", label=q)
    lim = axes[0].get_xlim()
    axes[0].plot(lim, lim, "k-", lw=0.8)
    axes[0].set(xscale="log", yscale="log", xlabel="NUTS half-width (%)", ylabel="Laplace half-width (%)")
    axes[0].legend(fontsize=8)
yaw = tables.get("yaw_records")
if yaw is not None:
    for w, g in yaw[yaw["error"].isna()].groupby("cross_wind_mps"):
        t = pl.plan_table(g, [pl.Target("KD", 20.0)])
        axes[1].plot(t["n_pairs"], t["median_half_width"], "o-",
                     label=f"{np.degrees(g['mean_abs_yaw_rad'].mean()):.1f} deg mean |yaw|")
    axes[1].set(xscale="log", yscale="log", xlabel="pairs", ylabel="K_D half-width (%)")
    axes[1].legend(fontsize=8)
con = tables.get("constrained_records")
if con is not None:
    ok = con[con["error"].isna()]
    for i, (model, g) in enumerate(ok.groupby("fit_model", sort=False)):
        t = pl.plan_table(g, [pl.Target(q, 1.0) for q in ("AD", "CD0", "F50_N", "F50_tyre_N")])
        bias = t.groupby("quantity")["bias_pct"].mean()
        axes[2].bar(np.arange(len(bias)) + 0.25 * i, bias.to_numpy(), width=0.25, label=model)
        axes[2].set_xticks(np.arange(len(bias)) + 0.25, bias.index)
    axes[2].axhline(0, color="k", lw=0.8)
    axes[2].set(ylabel="bias (% of truth)")
    axes[2].legend(fontsize=8)
fig.tight_layout()
fig.savefig(OUT / "planning_study.png", dpi=100)


# %% [markdown]
# ## 5. Your plan (`FIT_DIR`): pairs needed for the default targets, from your fit
# The same refits as `bayes-roadload plan FIT_DIR` (MAP + Laplace of simulated future
# campaigns, in this process), with few campaigns per size unless `BR_PLAN_SIMULATIONS` says more
# (sizes: `BR_PLAN_PAIRS`, default "1 2 4").

# %%
if FIT_DIR:
    from bayes_roadload import config
    from bayes_roadload.analysis.batch import run_batch

    targets = [pl.Target.parse(t) for t in config.PLAN_TARGETS]
    sims = int(os.environ.get("BR_PLAN_SIMULATIONS", "10"))
    sizes = [int(n) for n in os.environ.get("BR_PLAN_PAIRS", "1 2 4").split()]
    jobs = pl.plan_jobs(pilot, sizes, simulations=sims, model=pilot.model, confidence=0.95, seed=0)
    plan_records = run_batch(jobs, None, progress=False)
    mine = pl.plan_table(plan_records, targets, 0.95)
    print(mine[["quantity", "n_pairs", "median_half_width", "assurance"]].to_string(index=False))
    # the Type B uncertainty (vehicle.toml [uncertainty]) does not shrink with pairs: a target
    # below its floor is not reachable at any size (`plan` reports it and does not simulate it)
    floors = pl.type_b_floors(pilot, targets, 0.95)
    print(floors[["quantity", "target", "type_b_half_width", "reachable", "main_source"]].to_string(index=False))
    print(pl.recommend(mine, floors=floors)[["quantity", "n_pairs", "reached", "reachable"]].to_string(index=False))
    pl.plot_plan(mine, targets, OUT / "planning_your_fit.png")
