"""Which R-hat the 36-run cold-start reference misses: the default NUTS fit of that campaign
(``benchmarks/cold_start.py``'s reference: the independent simulator, seed 2026, 18 pairs, SUV or
van, calm wind, 4 Hz; four-term, pooled; in memory, the retry off), and for the five runs' initial
speeds of largest R-hat: ArviZ's rank R-hat (the gate's: the larger of the bulk split R-hat and
the folded one), the split, folded and z-scale R-hats, bulk and tail ESS, the chains' means and
sd and the halves' means.  Record: ``benchmarks/records/gates/rhat_probe.log``.

    python benchmarks/rhat_probe.py > benchmarks/records/gates/rhat_probe.log
"""
import dataclasses, numpy as np, arviz as az, warnings
warnings.simplefilter("ignore")
from bayes_roadload import config
from bayes_roadload.simulate.independent import simulate_independent
from bayes_roadload.inference.nuts import fit_nuts
c = simulate_independent(2026, pairs=18, category="suv_van", wind="calm", sample_rate_hz=4.0)
sampler = dataclasses.replace(config.DEFAULT_SAMPLER, retry=False)
fit = fit_nuts(c, "four_term", pooling="pooled", sampler=sampler)
v0 = fit.samples["v0_mps"]  # chains x draws x runs
print("v0 shape", v0.shape)
idata = az.from_dict(posterior={"v0": v0})
rh_rank = az.rhat(idata, method="rank")["v0"].values
rh_split = az.rhat(idata, method="split")["v0"].values
rh_folded = az.rhat(idata, method="folded")["v0"].values
rh_z = az.rhat(idata, method="z_scale")["v0"].values
ess_b = az.ess(idata, method="bulk")["v0"].values; ess_t = az.ess(idata, method="tail")["v0"].values
for i in np.argsort(-rh_rank)[:5]:
    print(f"v0[{i}] rank {rh_rank[i]:.5f} split {rh_split[i]:.5f} folded {rh_folded[i]:.5f} z {rh_z[i]:.5f} ess bulk {ess_b[i]:.0f} tail {ess_t[i]:.0f}",
          "chain means", np.round(v0[:, :, i].mean(1), 5), "chain sd", np.round(v0[:, :, i].std(1), 5),
          "half means", np.round([v0[ch, :500, i].mean() for ch in range(2)] + [v0[ch, 500:, i].mean() for ch in range(2)], 5))
