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
# # Posterior analysis of a coastdown campaign
#
# A simulated campaign at thesis case 14 conditions (head and cross wind 2 m/s, instrument
# dynamics, measurement and system noise) is fitted with NUTS over all runs jointly, and the
# posterior is examined: the A_D-B_D-C_D0 correlation, posterior-predictive bands over the
# speed traces, residuals, and the road-load curve with its band.
#
# **Your own fit:** set `FIT_DIR` (below, or the environment variable `BR_FIT_DIR`) to a
# directory written by `bayes-roadload fit` (speed traces, NUTS) and the same analysis runs on
# it; left empty, the notebook simulates and fits its example.  Draw counts of the example are
# set by environment variables so that the test suite can run this notebook quickly
# (`BR_PAIRS`, `BR_WARMUP`, `BR_DRAWS`); the defaults are a full analysis.

# %% tags=["parameters"]
import os

FIT_DIR = os.environ.get("BR_FIT_DIR") or None  # a `bayes-roadload fit` output directory, or None

# %%
import dataclasses
import json

import matplotlib

matplotlib.use(os.environ.get("MPLBACKEND", "Agg"))
import arviz as az
import jax
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from bayes_roadload import config
from bayes_roadload.data import load_campaign
from bayes_roadload.inference.bayes import build_problem
from bayes_roadload.inference.nuts import fit_nuts
from bayes_roadload.inference.results import diagnostics, format_posterior_table, summary_table, to_inference_data
from bayes_roadload.inference.spec import load_model_spec
from bayes_roadload.physics.roadload import road_load_parts_n
from bayes_roadload.simulate import get_case, simulate_campaign

PAIRS = int(os.environ.get("BR_PAIRS", 6))
WARMUP = int(os.environ.get("BR_WARMUP", 500))
DRAWS = int(os.environ.get("BR_DRAWS", 1000))
OUT = os.environ.get("BR_OUT", ".")

# %% [markdown]
# ## The fit: yours, or simulate and fit the example
# With `FIT_DIR` the posterior, summary and gates are read from the fit directory and the
# campaign from the path its `fit.json` records.  Without it, the basic drag model (thesis
# eq. 6.1) is used to simulate, so the analysis model is the true physics up to the instrument
# dynamics and the noise.

# %%
if FIT_DIR:
    record = json.loads(open(os.path.join(FIT_DIR, "fit.json")).read())
    campaign = load_campaign(record["campaign"])
    model_file = record.get("model_file")
    spec = load_model_spec(model_file if model_file and os.path.isfile(model_file) else record["model"])
    problem = build_problem(campaign, spec, pooling=record["pooling"], noise=record["noise"], robust=record["robust"])
    idata = az.from_netcdf(os.path.join(FIT_DIR, "posterior.nc"))
    summary = pd.read_csv(os.path.join(FIT_DIR, "summary.csv"))
    diag = json.loads(open(os.path.join(FIT_DIR, "diagnostics.json")).read())
else:
    case = dataclasses.replace(get_case(14), model="basic")
    campaign = simulate_campaign(case, pairs=PAIRS, seed=1)
    fit = fit_nuts(campaign, "four_term", sampler=config.SamplerConfig(num_warmup=WARMUP, num_samples=DRAWS))
    problem = fit.problem
    idata = to_inference_data(fit)
    summary = summary_table(fit, idata)
    diag = diagnostics(fit, idata, summary)
samples = {k: idata.posterior[k].values for k in problem.free if k in idata.posterior}
print(format_posterior_table(summary, diag, campaign.truth))

# %% [markdown]
# ## Posterior pairs: A_D, B_D and C_D0 trade off
# A higher B_D (speed-dependent tyre loss) is compensated by a lower A_D and C_D0: the reason
# the sampler needs the Laplace preconditioning, and why single pairs give scattered
# coefficients while the total road load is well determined.

# %%
coefficients = [k for k in ("AD", "BD", "CD0", "KD") if k in samples]
corr = np.corrcoef(np.stack([samples[k].ravel() for k in coefficients]))
print(f"posterior correlation ({', '.join(coefficients)}):\n", np.round(corr, 3))
axes = az.plot_pair(idata, var_names=coefficients, kind="kde", marginals=True)
plt.savefig(os.path.join(OUT, "posterior_pairs.png"), dpi=80)

# %% [markdown]
# ## Posterior-predictive bands over the speed traces, and residuals

# %%
obs = idata.observed_data["speed_mps"]
t = idata.constant_data["time_s"]
pp = idata.posterior_predictive["speed_mps"].stack(s=("chain", "draw"))
fitted = idata.posterior_predictive["speed_integrated_mps"].stack(s=("chain", "draw"))
runs = list(idata.posterior.coords["run"].values)[:2]
fig, ax = plt.subplots(2, len(runs), figsize=(11, 6), sharex="col")
inside = []
for j, r in enumerate(runs):
    lo, hi = pp.sel(run=r).quantile([0.025, 0.975], dim="s")
    mid = fitted.sel(run=r).median(dim="s")
    ax[0, j].fill_between(t.sel(run=r), lo, hi, alpha=0.4, label="95 % predictive band")
    ax[0, j].plot(t.sel(run=r), obs.sel(run=r), "k.", ms=1, label="measured")
    ax[0, j].set_title(f"run {r}")
    ax[1, j].plot(t.sel(run=r), obs.sel(run=r) - mid, ".", ms=1)
    ax[1, j].set_ylabel("measured - fitted (m/s)")
    ax[1, j].set_xlabel("time (s)")
    ok = np.isfinite(obs.sel(run=r).values)
    inside.append(float(((obs.sel(run=r) >= lo) & (obs.sel(run=r) <= hi)).values[ok].mean()))
ax[0, 0].legend()
plt.savefig(os.path.join(OUT, "predictive_bands.png"), dpi=80)
print("fraction of measured speeds inside the 95 % predictive band:", np.round(inside, 3))

# %% [markdown]
# ## The road-load curve and its band
# Road load at reference conditions (100 kPa, 293.2 K, still air) for every posterior draw.

# %%
speeds = np.linspace(5.0, 31.3, 60)
n_draws = samples["CD0"].size
every = max(1, n_draws // 200)  # about 200 draws
draws = {k: v.reshape(-1)[::every] for k, v in samples.items() if v.size == n_draws}


@jax.jit
@jax.vmap
def road_load_n(p):
    """Total road load at ``speeds`` for one draw ``p`` (vectorised over the draws)."""
    parts = road_load_parts_n(problem.model, dict(problem.fixed, **p), speeds, problem.mass_kg,
                              problem.frontal_area_m2)
    return sum(parts.values())


curves = np.asarray(road_load_n(draws))
lo, mid, hi = np.percentile(curves, [2.5, 50, 97.5], axis=0)
plt.figure(figsize=(6, 4))
plt.fill_between(speeds * 3.6, lo, hi, alpha=0.4, label="95 % band")
plt.plot(speeds * 3.6, mid, label="posterior median")
plt.xlabel("speed (km/h)")
plt.ylabel("road load (N)")
plt.legend()
plt.savefig(os.path.join(OUT, "road_load.png"), dpi=80)
f50 = summary.set_index("parameter").loc["F50_N"]
print(f"F50 = {f50['mean']:.1f} N, 95 % interval [{f50['q2.5']:.1f}, {f50['q97.5']:.1f}] N "
      f"({100 * (f50['q97.5'] - f50['q2.5']) / 2 / f50['mean']:.2f} % half-width)")
