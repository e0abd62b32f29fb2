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
# # Sim-to-real: the withheld-effect proof suite
#
# `benchmarks/sim_to_real_study.py` simulates campaigns with one candidate effect present,
# analyses each with a model that withholds it (`three_term`), and runs the diagnosis
# (`bayes-roadload diagnose`); null controls add no effect.  Two designs: `standard` (thesis
# case 9 conditions, the effect at a plausible size) and `identifying` (the campaign the
# effects' *needs* ask for: `[proof.identifying]` in `models/effects/library.toml`).  Its
# records are in `docs/sim_to_real/records_DESIGN.csv`; this notebook plots them:
#
# 1. per design, the confusion matrix, true effect against the top-ranked supported effect
#    ("none" when nothing is claimed);
# 2. each campaign's delta_elpd of the true effect, against the support threshold, and the
#    largest delta_elpd of any candidate on the null controls;
# 3. the shrink of the residual trend after the refit;
# 4. the between-run spread (`spread_excess`, the Birge ratio of the runs' coefficients) on the
#    nulls, the run-to-run campaigns and the other effects.
#
# It reads results; it fits nothing.  `BR_SIM_TO_REAL_DIR` points it at another records
# directory, `BR_OUT` is where the figures go.
#
# **Your own fit:** with `FIT_DIR` (or `BR_FIT_DIR`) set to a `bayes-roadload fit` directory of
# speed traces, section 5 diagnoses the fit's campaign with the fit's model, as
# `bayes-roadload diagnose CAMPAIGN --model MODEL` does (one MAP fit, candidates linearised).

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

from bayes_roadload import config
from bayes_roadload.analysis.effects import EFFECT_NAMES

ROOT = Path.cwd() if (Path.cwd() / "docs").is_dir() else Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("BR_SIM_TO_REAL_DIR", ROOT / "docs" / "sim_to_real"))
OUT = Path(os.environ.get("BR_OUT", "."))
frames = []
for path in sorted(DATA.glob("records_*.csv")):
    frame = pd.read_csv(path, keep_default_na=False, na_values=[""])  # "null" is an arm
    frame["design"] = path.stem.removeprefix("records_")
    frames.append(frame)
records = pd.concat(frames, ignore_index=True)
records = records[records["error"].isna()]
records["name"] = records["design"] + ":" + records["name"]
designs = list(dict.fromkeys(records["design"]))
threshold = config.DEFAULT_DIAGNOSIS.support_delta_elpd
print(f"{len(records)} campaigns, designs {designs}, {records['true_effect'].nunique()} arms")

# %% [markdown]
# ## 1. Confusion matrix

# %%
cols = list(EFFECT_NAMES) + ["none"]
fig, axes = plt.subplots(1, len(designs), figsize=(9 * len(designs), 6), squeeze=False)
for ax, design in zip(axes[0], designs):
    part = records[records["design"] == design]
    rows = [e for e in list(EFFECT_NAMES) + ["null"] if e in set(part["true_effect"])]
    cm = pd.crosstab(part["true_effect"], part["top"]).reindex(index=rows, columns=cols, fill_value=0)
    ax.imshow(cm.to_numpy(), cmap="Blues")
    ax.set_xticks(range(len(cols)), cols, rotation=60, ha="right", fontsize=7)
    ax.set_yticks(range(len(rows)), rows, fontsize=7)
    for (i, j), v in np.ndenumerate(cm.to_numpy()):
        if v:
            ax.text(j, i, str(v), ha="center", va="center", fontsize=8)
    ax.set_title(f"design {design}")
    ax.set_xlabel("top-ranked supported effect")
    ax.set_ylabel("true (withheld) effect")
    correct = sum(cm.loc[e, e] for e in rows if e in cm.columns)
    print(f"{design}: true effect ranked first and claimed:", correct, "of",
          int(cm.drop(index="null", errors="ignore").to_numpy().sum()))
fig.tight_layout()
fig.savefig(OUT / "sim_to_real_confusion.png", dpi=90)

# %% [markdown]
# ## 2. Evidence for the true effect, and the null controls

# %%
effects = records[records["true_effect"] != "null"]
true_delta = [effects.iloc[i][f"delta_elpd_{e}"] for i, e in enumerate(effects["true_effect"])]
nulls = records[records["true_effect"] == "null"]
null_max = nulls[[f"delta_elpd_{e}" for e in EFFECT_NAMES]].max(axis=1)
fig, ax = plt.subplots(figsize=(8, 4))
y = np.arange(len(effects))
ax.barh(y, np.sign(true_delta) * np.log10(1 + np.abs(true_delta)), color="tab:blue", label="true effect")
ax.barh(len(effects) + np.arange(len(nulls)), np.sign(null_max) * np.log10(1 + np.abs(null_max)), color="tab:gray",
        label="nulls: largest candidate")
ax.axvline(np.log10(1 + threshold), color="k", ls="--", lw=0.8)
ax.set_yticks(list(y) + list(len(effects) + np.arange(len(nulls))), list(effects["name"]) + list(nulls["name"]),
              fontsize=7)
ax.set_xlabel("sign x log10(1 + |delta_elpd|)  (dashed: support threshold)")
ax.legend(fontsize=7)
fig.tight_layout()
fig.savefig(OUT / "sim_to_real_evidence.png", dpi=90)

# %% [markdown]
# ## 3. Shrink of the residual trend after the refit

# %%
shrink = records.loc[records["refit_effects"].notna(), ["name", "shrink_trend_rms_mps"]].dropna()
fig, ax = plt.subplots(figsize=(6, 3))
ax.hist(shrink["shrink_trend_rms_mps"].clip(-50, 100), bins=np.linspace(-50, 100, 16), color="tab:green")
ax.set_xlabel("shrink of the trend's excess over its floor (%)")
ax.set_ylabel("campaigns")
fig.tight_layout()
fig.savefig(OUT / "sim_to_real_shrink.png", dpi=90)
print("median shrink of the refitted campaigns:", float(shrink["shrink_trend_rms_mps"].median()) if len(shrink) else None)

# %% [markdown]
# ## 4. Between-run spread of the coefficients
#
# `spread_excess` is ~1 when the runs differ by their noise only; run-to-run changes of the
# vehicle (the thesis' track spreads) lift it.  Records written before the metric existed lack it.

# %%
if "before_spread_excess" in records:
    arms = {"nulls": records["true_effect"] == "null",
            "run_to_run_variation": records["true_effect"] == "run_to_run_variation"}
    arms["other effects"] = ~(arms["nulls"] | arms["run_to_run_variation"])
    fig, ax = plt.subplots(figsize=(6, 3))
    values = [pd.to_numeric(records.loc[m, "before_spread_excess"], errors="coerce").dropna() for m in arms.values()]
    ax.boxplot([v for v in values if len(v)], tick_labels=[k for k, v in zip(arms, values) if len(v)])
    ax.axhline(1.0, color="k", ls="--", lw=0.8)
    ax.set_ylabel("spread_excess (Birge ratio)")
    fig.tight_layout()
    fig.savefig(OUT / "sim_to_real_spread.png", dpi=90)
    for k, v in zip(arms, values):
        print(f"spread_excess, {k}: median", float(v.median()) if len(v) else None, "over", len(v))


# %% [markdown]
# ## 5. Your campaign (`FIT_DIR`): the gap of your model and the candidate effects

# %%
if FIT_DIR:
    import json

    from bayes_roadload.analysis.diagnose import diagnose
    from bayes_roadload.data import load_campaign
    from bayes_roadload.inference.kinds import kind_of

    record = json.loads((Path(FIT_DIR) / "fit.json").read_text())
    campaign = load_campaign(record["campaign"])
    if kind_of(campaign).diagnosis != "traces":
        print(f"{record['kind']} campaigns are diagnosed by `bayes-roadload diagnose` (NUTS refits); not run here")
    else:
        model_file = record.get("model_file")
        mine = diagnose(campaign, model_file if model_file and Path(model_file).is_file() else record["model"])
        gap = mine.result["gap"]
        print(f"residual trend {gap['trend_rms_mps']:.4f} m/s (white-noise floor {gap['trend_floor_mps']:.4f}); "
              f"residuals concentrate by {mine.result['localisation']['where'][0]}")
        table = pd.DataFrame(mine.candidates)[["rank", "effect", "delta_elpd", "statement"]]
        print(table.to_string(index=False))
        fig, ax = plt.subplots(figsize=(6, 3))
        d = pd.to_numeric(table["delta_elpd"], errors="coerce").fillna(0.0)
        ax.barh(table["effect"], d)
        ax.axvline(threshold, color="r", ls="--", lw=0.8, label="support threshold")
        ax.set_xlabel("delta_elpd")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(OUT / "sim_to_real_your_campaign.png", dpi=90)
