"""Undriven-wheel spin-downs and steady-state torque tests against the coastdown (thesis 7.4-7.7).

1. Spin-downs (table 7.10): 3 tests of each rear wheel of the thesis car (table 7.10 means),
   fitted by NUTS over all runs; the vehicle's Au, Bu against the truth, the classical eq. 5.14
   line and table 7.10, for ``--seeds`` seeds; then tests scattering like table 7.10's (sd 0.1 N,
   0.004 N s/m per test), pooled against ``pooling="hierarchical"``.
2. Steady state against coastdown (table 7.11): per seed a coastdown campaign (``--coast-pairs``
   pairs, four_term) and a steady-state group (20-70 mph, both directions, one pair per speed) in
   the same table 6.7 case's winds, both fitted by NUTS (steady state: with anemometers, four_term;
   without, a latent pair wind, three_term); the comparison table of
   :func:`bayes_roadload.inference.steady.compare_with_coastdown` and the classical averaged analysis.

Prints one JSON object.  Run: ``python benchmarks/undriven_steady_study.py [--seeds 0 1 2] [--case 9]``.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings

from bayes_roadload import config
from bayes_roadload import thesis
from bayes_roadload.inference.nuts import fit_nuts
from bayes_roadload.inference.results import summary_table, to_inference_data
from bayes_roadload.inference.spindown import classical_spindown, fit_spindown_nuts, spindown_derived
from bayes_roadload.inference.results import _rows, channel_inference_data
from bayes_roadload.inference.steady import classical_steady, compare_with_coastdown, fit_steady_nuts, steady_derived
from bayes_roadload.simulate import simulate_campaign
from bayes_roadload.simulate.spindown import simulate_spindown
from bayes_roadload.simulate.steady import simulate_steady


def _summary(fit, names, derived):
    idata = channel_inference_data(fit, derived=derived)
    return _rows(idata, list(names) + list(derived))


def spindown_study(seeds, sampler):
    out = []
    for seed in seeds:
        c = simulate_spindown(tests_per_wheel=3, seed=seed)
        t0 = time.perf_counter()
        fit = fit_spindown_nuts(c, sampler=sampler)
        s = _summary(fit, ["Au", "Bu"], spindown_derived(fit.samples)).set_index("parameter")
        cl = classical_spindown(c).set_index("wheel")
        out.append({"seed": seed, "wall_s": round(time.perf_counter() - t0, 1),
                    "divergences": int(fit.stats["diverging"].sum()),
                    **{f"{k}_{q}": float(s.loc[k, q]) for k in ("Au", "Bu") for q in ("mean", "sd", "q2.5", "q97.5")},
                    "Au_truth": c.truth["Au"], "Bu_truth": c.truth["Bu"],
                    "Au_classical": float(cl.loc["total", "Au"]), "Au_classical_se": float(cl.loc["total", "Au_se"]),
                    "Bu_classical": float(cl.loc["total", "Bu"]), "Bu_classical_se": float(cl.loc["total", "Bu_se"])})
    return out


def spindown_scatter_study(seeds, sampler, test_sd=(0.1, 0.004)):
    """Tests scattering like table 7.10's: pooled against hierarchical (run-level A, B)."""
    out = []
    for seed in seeds:
        c = simulate_spindown(tests_per_wheel=3, seed=seed, test_sd=test_sd)
        row = {"seed": seed, "runs_mean_Au": sum(r["Au"] for r in c.truth["per_run"].values()) / 3.0,
               "Au_truth": c.truth["Au"], "Bu_truth": c.truth["Bu"]}
        for pooling in ("pooled", "hierarchical"):
            t0 = time.perf_counter()
            fit = fit_spindown_nuts(c, pooling=pooling, sampler=sampler)
            s = _summary(fit, ["Au", "Bu"], spindown_derived(fit.samples)).set_index("parameter")
            row[pooling] = {"wall_s": round(time.perf_counter() - t0, 1), "divergences": int(fit.stats["diverging"].sum()),
                            **{f"{k}_{q}": float(s.loc[k, q]) for k in ("Au", "Bu") for q in ("mean", "sd", "q2.5", "q97.5")}}
        out.append(row)
    return out


def steady_study(seeds, case, coast_pairs, sampler):
    out = []
    for seed in seeds:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            coast = simulate_campaign(case, pairs=coast_pairs, seed=seed)
        cfit = fit_nuts(coast, "four_term", sampler=sampler)
        csum = summary_table(cfit, to_inference_data(cfit, predictive=False))
        row = {"seed": seed, "coastdown": csum.set_index("parameter").loc[["AD", "BD", "CD0", "KD", "F50_N"],
                                                                          ["mean", "sd"]].to_dict()}
        for label, anem, model in (("steady_anemometer", True, "four_term"), ("steady_pair_wind", False, "three_term")):
            st = simulate_steady(case, pairs=1, seed=seed, anemometer=anem)
            fit = fit_steady_nuts(st, model, sampler=sampler)
            ssum = _summary(fit, list(fit.problem.free) + ["sigma_force_n", "run_force_sd_n"],
                            steady_derived(fit.problem, fit.samples))
            cmp = compare_with_coastdown(ssum, csum)
            row[label] = {"divergences": int(fit.stats["diverging"].sum()),
                          "comparison": cmp[["parameter", "coastdown_mean", "steady_mean", "steady_sd", "difference_pct",
                                             "difference_z"]].to_dict(orient="records"),
                          "classical_averaged": classical_steady(st).to_dict(orient="records")}
        out.append(row)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--case", type=int, default=9)
    ap.add_argument("--coast-pairs", type=int, default=3)
    args = ap.parse_args()
    sampler = config.SamplerConfig(progress_bar=False, seed=1)
    t0 = time.perf_counter()
    result = {"spindown": spindown_study(args.seeds, sampler),
              "spindown_test_scatter": spindown_scatter_study(args.seeds, sampler),
              "steady_vs_coastdown": steady_study(args.seeds, args.case, args.coast_pairs, sampler),
              "truth": {**thesis.THESIS_COEFFICIENTS}, "case": args.case, "wall_s": round(time.perf_counter() - t0, 1)}
    print(json.dumps(result, indent=1, default=float))


if __name__ == "__main__":
    main()
