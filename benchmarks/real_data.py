"""Real speed-gate data: fit the VBOX split exports and write docs/real_data.md.

Reads the external sample exports (``../shared/data/external/coastdown-mda-split``, no licence:
read in place, never copied into the repository), imports them with the VBOX importer (default
gates, checked against every run's time and distance), applies the validity checks (operator
flag, Hampel outliers, partner rejection), fits the interval-time model (``split_f0_f2``) of
every campaign with NUTS, measures the leave-one-pair-out predictive coverage of the held-out
runs' band times, and compares a track grade with an along-track wind as explanations of the
difference between the + and - headings (``split_f0_f2_grade``, ``_wind``, ``_grade_wind``;
PSIS-LOO over runs, and the force difference between headings in the high and the low window).

The exports do not record the vehicle: the fits use a nominal vehicle of test mass 1000 kg,
effective mass 1020 kg and frontal area 1 m^2, so ``AD`` is the rolling-resistance coefficient
Crr (mass-free up to the assumed M_e / M), ``CD0`` reads as C_D A in m^2 per tonne of test
mass, and ``F0_N``, ``F2_N_per_kph2`` are per tonne (scale them by the real test mass).

    python benchmarks/real_data.py [--data DIR] [--out docs/real_data.md] [--skip-lopo]
    python benchmarks/real_data.py --extras-only     # drift tables and GNSS fits onto saved records
    python benchmarks/real_data.py --markdown-only   # rewrite docs/real_data.md from docs/real_data.json
    python benchmarks/real_data.py --gnss-lopo-only  # the eco-car traces' leave-one-pair-out coverage onto them
    python benchmarks/real_data.py --only "MrLee (vehicle not named), 2024-04-22, Kestrel weather"
        # fit, LOPO, drift tables and diagnosis of the named campaigns again, onto the saved records

Prints a JSON record of every figure on stdout.
"""

from __future__ import annotations

import argparse
import functools
import json
import re
import sys
import time
import warnings
from pathlib import Path

import arviz as az
import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload import config  # noqa: E402
from bayes_roadload.analysis.validity import interval_validity  # noqa: E402
from bayes_roadload.data import Vehicle  # noqa: E402
from bayes_roadload.data.vbox import import_vbox  # noqa: E402
from bayes_roadload.inference.intervals import (  # noqa: E402
    build_interval_problem,
    fit_intervals_nuts,
    observed_band_times,
    predictive_band_times,
    summary_table,
    to_inference_data,
)
from bayes_roadload.inference.results import SUMMARY_COLUMNS, diagnostics  # noqa: E402

DEFAULT_DATA = ROOT.parent / "shared" / "data" / "external" / "coastdown-mda-split" / "sample_data" / "Split"
VEHICLE = Vehicle(mass_kg=1000.0, effective_mass_kg=1020.0, frontal_area_m2=1.0)
DATASETS = {
    "Hyundai Ioniq, 2026-01-15": (["altas_ioniq.csv", "baixas_ioniq.csv"], False),
    "Hyundai Ioniq, 2026-01-16": (["altas_ioniq_16012026.csv", "baixas_ioniq_16012026.csv",
                                   "intercalado_ioniq_16012026.csv"], False),
    "Ford, 2024-04-23": (["ford-HighSpeed-ok.csv", "Ford-LowSpeed-ok.csv"], False),
    "MrLee (vehicle not named), 2024-04-22, Kestrel weather": (["split_MrLee_HighSpd_ctvi.csv",
                                                                 "spli_MrLee_LowSpd_ctvi.csv"], True),
}
HEADING_MODELS = ("split_f0_f2", "split_f0_f2_grade", "split_f0_f2_wind", "split_f0_f2_grade_wind")
LEVELS = (0.5, 0.9, 0.95)
LOPO_SAMPLER = config.SamplerConfig(num_warmup=300, num_samples=500, seed=7, target_accept=0.9)
FIT_SAMPLER = config.SamplerConfig(seed=3, target_accept=0.9)


def _diag(fit, idata, summary):
    return diagnostics(fit, idata, summary, runs=pd.DataFrame(columns=list(SUMMARY_COLUMNS)))


def fit_campaign(camp, runs, model, sampler=FIT_SAMPLER):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = fit_intervals_nuts(camp, model, sampler=sampler, runs=runs)
    idata = to_inference_data(fit)
    summary = summary_table(fit, idata)
    return fit, idata, summary, _diag(fit, idata, summary)


def lopo_coverage(camp, runs, model="split_f0_f2"):
    """Leave each accepted pair out, fit the rest, predict the pair's band times."""
    pairs = [p for p in camp.pairs() if all(r in runs for r in p)]
    hits = {lv: [] for lv in LEVELS}
    total_hits = {lv: [] for lv in LEVELS}
    pit, gates_failed, failed_gates = [], 0, {}
    for pair in pairs:
        keep = [r for r in runs if r not in pair]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = fit_intervals_nuts(camp, model, sampler=LOPO_SAMPLER, runs=keep)
        idata = to_inference_data(fit)
        diag = _diag(fit, idata, summary_table(fit, idata))
        if not diag["pass"]:
            gates_failed += 1
            for gate in diag.get("failed", []):
                failed_gates[gate] = failed_gates.get(gate, 0) + 1
        held = build_interval_problem(camp, model, runs=list(pair))
        pred = predictive_band_times(held, fit.samples, n_draws=1000)["interval_s"]
        obs = observed_band_times(held)
        m = np.isfinite(obs)
        pit.extend(np.mean(pred <= obs[None], axis=0)[m])
        tot_pred, tot_obs = np.nansum(pred, axis=2), np.nansum(obs, axis=1)
        for lv in LEVELS:
            lo, hi = np.nanpercentile(pred, [50 * (1 - lv), 50 * (1 + lv)], axis=0)
            hits[lv].extend(((obs >= lo) & (obs <= hi))[m])
            tlo, thi = np.percentile(tot_pred, [50 * (1 - lv), 50 * (1 + lv)], axis=0)
            total_hits[lv].extend((tot_obs >= tlo) & (tot_obs <= thi))
    return {"pairs": len(pairs), "bands": len(hits[LEVELS[0]]), "lopo_fits_failing_gates": gates_failed,
            "lopo_failed_gates": failed_gates, "band_coverage": {str(lv): float(np.mean(hits[lv])) for lv in LEVELS},
            "run_total_coverage": {str(lv): float(np.mean(total_hits[lv])) for lv in LEVELS},
            "pit_mean": float(np.mean(pit)), "pit_sd": float(np.std(pit))}


def heading_forces(camp, runs):
    """Model-free: mean resisting force per tonne over each window, M_e (v1 - v2) / T, by
    heading; the + minus - difference in the high and the low window (a grade gives the same
    difference in both, an along-track wind one that grows with the speed, ~4 rho C_D A v w / 2)."""
    rt = camp.run_table().set_index("run").loc[runs]
    rt["force_n"] = VEHICLE.effective_mass_kg * (rt["speed_start_mps"] - rt["speed_end_mps"]) / rt["total_time_s"]
    rt["mid_kph"] = 1.8 * (rt["speed_start_mps"] + rt["speed_end_mps"])
    rt["session"] = [str(r).rsplit("-", 1)[0] for r in rt.index]
    out = []
    for (session, window), g in rt.groupby(["session", "window"]):
        plus, minus = g[g["direction"] > 0]["force_n"], g[g["direction"] < 0]["force_n"]
        se = float(np.sqrt(plus.var(ddof=1) / len(plus) + minus.var(ddof=1) / len(minus)))
        out.append({"session": session, "window": window, "mid_kph": float(g["mid_kph"].iloc[0]), "runs_plus": len(plus),
                    "runs_minus": len(minus), "force_plus_n": float(plus.mean()), "force_minus_n": float(minus.mean()),
                    "difference_n": float(plus.mean() - minus.mean()), "difference_se_n": se})
    return out


def heading_trends(camp, runs):
    """Per window and heading: the drift of the resisting force per tonne over the session (N/t
    per hour, least squares on the runs' start times).  A grade cannot drift; a wind can."""
    rt = camp.run_table().set_index("run").loc[runs]
    rt["force_n"] = VEHICLE.effective_mass_kg * (rt["speed_start_mps"] - rt["speed_end_mps"]) / rt["total_time_s"]
    rt["session"] = [str(r).rsplit("-", 1)[0] for r in rt.index]
    out = []
    for (session, window, direction), g in rt.groupby(["session", "window", "direction"]):
        if len(g) < 3:
            continue
        hours = (g["start_time_of_day_s"].to_numpy() - g["start_time_of_day_s"].min()) / 3600.0
        coef, cov = np.polyfit(hours, g["force_n"].to_numpy(), 1, cov=True)
        out.append({"session": session, "window": window, "direction": int(direction), "runs": len(g),
                    "span_h": float(hours.max()),
                    "slope_n_per_h": float(coef[0]), "slope_se": float(np.sqrt(cov[0, 0]))})
    return out


def heading_models(camp, runs):
    rows = {}
    loos = {}
    for model in HEADING_MODELS:
        fit, idata, summary, diag = fit_campaign(camp, runs, model)
        s = summary.set_index("parameter")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            loos[model] = az.loo(idata, var_name="interval_s")
        rows[model] = {"pass": diag["pass"], "failed": diag["failed"],
                       "elpd_loo": float(loos[model].elpd_loo), "elpd_se": float(loos[model].se),
                       "pareto_k_max": float(np.max(loos[model].pareto_k)),
                       **{f"{k}_{c}": float(s.loc[k, c]) for k in ("AD", "CD0", "grade_rad", "head_wind_mps")
                          if k in s.index for c in ("mean", "sd", "q2.5", "q97.5")}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cmp = az.compare(loos)
    for model in HEADING_MODELS:
        rows[model]["elpd_diff"] = float(cmp.loc[model, "elpd_diff"])
        rows[model]["dse"] = float(cmp.loc[model, "dse"])
    return rows


def heading_diagnosis(camp) -> dict:
    """``diagnose_intervals`` on the accepted runs: the gap and the scored candidates."""
    from bayes_roadload.analysis.diagnose_intervals import diagnose_intervals

    validity = interval_validity(camp)
    runs = list(validity.loc[~validity["rejected"], "run"])
    t0 = time.perf_counter()
    d = diagnose_intervals(camp, "split_f0_f2", sampler=FIT_SAMPLER, runs=runs)
    scored = [{k: c.get(k) for k in ("effect", "rank", "supported", "delta_elpd", "delta_elpd_se", "estimates",
                                     "shrink_pct", "statement")}
              for c in d.candidates if c["delta_elpd"] is not None]
    return {"gap": d.result["gap"], "where": d.result["localisation"]["where"], "candidates": scored,
            "top": d.top, "wall_s": round(time.perf_counter() - t0, 1)}


@functools.cache
def _import(data: Path, name: str, weather: bool = True):
    """The interval campaign ``name`` of :data:`DATASETS` and its import report, with its
    Kestrel log when it has one and ``weather``; imported once per process (the fit, the drift
    tables and the diagnosis read the same campaign, which none of them changes)."""
    files, use_weather = DATASETS[name]
    log = data / "meteo" / "AGRICULTR_SPLIT.csv" if use_weather and weather else None
    return import_vbox([data / "coastdown" / f for f in files], VEHICLE, weather=log)


def drift_tables(data: Path, name: str) -> dict:
    """``heading_trends`` and ``heading_forces`` of campaign ``name`` over its accepted runs,
    imported without its weather log."""
    camp, _ = _import(data, name, weather=False)
    validity = interval_validity(camp)
    accepted = list(validity.loc[~validity["rejected"], "run"])
    return {"heading_trends": heading_trends(camp, accepted), "heading_forces": heading_forces(camp, accepted)}


def run(data: Path, skip_lopo: bool, only=None):
    """Fit (and with LOPO score) every interval campaign of :data:`DATASETS`, or those named in
    ``only``."""
    records = {}
    for name, (files, _) in DATASETS.items():
        if only is not None and name not in only:
            continue
        t0 = time.perf_counter()
        camp, report = _import(data, name)
        validity = interval_validity(camp)
        runs = list(validity.loc[~validity["rejected"], "run"])
        fit, idata, summary, diag = fit_campaign(camp, runs, "split_f0_f2")
        s = summary.set_index("parameter")
        rec = {"files": files, "import": report.lines(), "runs": len(camp.run_ids), "accepted": len(runs),
               # no run's own logged time in the docs (the exports are not ours to publish)
               "rejected": [f"{r}: {re.sub(r'total time [0-9.]+ s, ', '', why)}"
                            for r, why in zip(validity["run"], validity["reason"])
                            if validity.set_index("run").loc[r, "rejected"]],
               "diagnostics": {k: diag[k] for k in ("pass", "failed", "divergences", "max_r_hat", "min_ess_bulk",
                                                    "min_ess_tail")},
               "timings_s": {k: round(float(v), 1) for k, v in fit.timings.items()},
               "posterior": {k: {c: float(s.loc[k, c]) for c in ("mean", "sd", "q2.5", "q97.5")}
                             for k in ("AD", "CD0", "F0_N", "F2_N_per_kph2", "F50_N", "sigma_gate_s",
                                       "band_noise_s_per_sqrt_s", "run_decel_sd_mps2")},
               "heading_forces": heading_forces(camp, runs)}
        if "Ioniq" in name or "MrLee" in name:
            rec["heading_models"] = heading_models(camp, runs)
        if not skip_lopo:
            rec["lopo"] = lopo_coverage(camp, runs)
        rec["wall_s"] = round(time.perf_counter() - t0, 1)
        records[name] = rec
        print(f"{name}: done in {rec['wall_s']} s", file=sys.stderr)
    return records


GNSS_DIR = ROOT.parent / "shared" / "data" / "external" / "Finding-Rolling-Resistance-for-Electric-Car" / "Data"
GNSS_RUNS = (("Michelin60A", 1, 1), ("Michelin60B", -1, 1), ("Michelin60A1", 1, 2), ("Michelin60B1", -1, 2))
"""The eco-car GNSS coastdowns: (file, direction, pair); A / B read as the two directions."""
GNSS_VEHICLE = Vehicle(mass_kg=78.0, effective_mass_kg=80.0, frontal_area_m2=0.4294)
"""The upstream analysis' mass and frontal area; the effective mass adds an assumed 2.5 %."""
GNSS_MIN_SPEED_MPS = 1.5


def gnss_campaign(folder: Path = GNSS_DIR):
    """The eco-car speed traces (1 Hz, km/h, one column) as a speed-only campaign in memory, cut
    where the speed first falls below ``GNSS_MIN_SPEED_MPS`` (the stop)."""
    from bayes_roadload.data import Campaign

    rows = []
    for name, direction, pair in GNSS_RUNS:
        v = np.loadtxt(folder / f"{name}.csv", delimiter=",", usecols=0) * config.KPH_TO_MPS
        below = np.flatnonzero(v < GNSS_MIN_SPEED_MPS)
        last = below[0] if below.size else v.size
        rows += [{"run": name, "time_s": float(t), "speed_mps": float(x), "direction": direction, "pair": pair}
                 for t, x in zip(range(last), v[:last])]
    return Campaign(pd.DataFrame(rows), GNSS_VEHICLE)


def gnss_record(folder: Path = GNSS_DIR):
    from bayes_roadload.inference.nuts import fit_nuts
    from bayes_roadload.inference.results import diagnostics as trace_diagnostics
    from bayes_roadload.inference.results import summary_table as trace_summary
    from bayes_roadload.inference.results import to_inference_data as trace_idata

    camp = gnss_campaign(folder)
    out = {"runs": {r: int(n) for r, n in camp.runs.groupby("run").size().items()}, "models": {}}
    for model in ("split_f0_f2", "split_f0_f2_wind"):
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = fit_nuts(camp, model, sampler=config.SamplerConfig(seed=1, target_accept=0.95))
        idata = trace_idata(fit)
        summary = trace_summary(fit, idata)
        diag = trace_diagnostics(fit, idata, summary)
        s = summary.set_index("parameter")
        names = [n for n in s.index if n in ("AD", "CD0", "F0_N", "F2_N_per_kph2", "q_mps_per_sqrt_s")
                 or n.startswith("head_wind_mps")]
        out["models"][model] = {"pass": diag["pass"], "failed": diag["failed"], "max_r_hat": diag["max_r_hat"],
                                "divergences": diag["divergences"], "wall_s": round(time.perf_counter() - t0, 1),
                                "posterior": {n: {c: float(s.loc[n, c]) for c in ("mean", "sd", "q2.5", "q97.5")}
                                              for n in names}}
    return out


GNSS_LOPO_DRAWS = 400
"""Predictive speed traces per held-out pair (one posterior draw each)."""
GNSS_LOPO_SAMPLER = config.SamplerConfig(seed=7)
"""The default sampler (with its retry): a fit of one speed-trace pair with LOPO_SAMPLER's
300 + 500 draws failed its R-hat, ESS and tree-depth gates."""


def gnss_lopo(folder: Path = GNSS_DIR, model: str = "split_f0_f2", draws: int = GNSS_LOPO_DRAWS, seed: int = 0) -> dict:
    """Leave-one-pair-out predictive coverage of the eco-car speed traces: fit the other pair
    (``fit_nuts``, ``GNSS_LOPO_SAMPLER``), and draw the held-out pair's speed traces from that
    posterior, as ``plan`` draws future runs (:mod:`bayes_roadload.analysis.planning`, step 2):
    the drag model of a posterior draw integrated on the held-out run's time grid from its first
    speed (:func:`~bayes_roadload.physics.integrate_batch`, still air: the traces log no
    airspeed), plus the integrated noise ``q`` as a random walk and the white noise ``sigma``
    of the same draw.  Every held-out sample after the first (the start) is scored against the
    central intervals of the draws at its time."""
    import jax
    import jax.numpy as jnp

    from bayes_roadload.analysis.planning import population_from_fit
    from bayes_roadload.inference.nuts import fit_nuts
    from bayes_roadload.inference.results import diagnostics as trace_diagnostics
    from bayes_roadload.inference.results import summary_table as trace_summary
    from bayes_roadload.inference.results import to_inference_data as trace_idata
    from bayes_roadload.inference.spec import load_model_spec
    from bayes_roadload.physics import integrate_batch

    camp = gnss_campaign(folder)
    rng = np.random.default_rng(seed)
    hits = {lv: [] for lv in LEVELS}
    pit, gates_failed, per_pair, retried = [], [], [], []
    for pair in camp.pairs():
        keep = [str(r) for r in camp.run_ids if r not in pair]
        train, held = camp.subset(keep), camp.subset(list(pair))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = fit_nuts(train, model, sampler=GNSS_LOPO_SAMPLER)
        idata = trace_idata(fit)
        diag = trace_diagnostics(fit, idata, trace_summary(fit, idata))
        if not diag["pass"]:
            gates_failed.append({"fitted": keep, "failed": diag["failed"]})
        retried += [{"fitted": keep, "failed_first": r["failed"]} for r in fit.retries]
        pop = population_from_fit(fit, train, max_draws=draws)
        dm, fixed, free = load_model_spec(model).build(held)
        batch, run_ids = held.to_batch()
        v_obs = np.asarray(batch.speed_mps)
        speed = jax.jit(lambda params: integrate_batch(dm, params, batch, jnp.asarray(v_obs[:, 0]))[0])
        pred = np.stack([np.asarray(speed(dict(fixed, **{n: jnp.full(len(run_ids), float(pop.means[n][s]))
                                                           for n in free})))
                         for s in range(pop.n_draws)])            # [S, R, T]
        t = np.asarray(batch.time_s)
        dt = np.diff(t, axis=1, prepend=t[:, :1])
        walk = np.cumsum(pop.q_mps_per_sqrt_s[:, None, None] * np.sqrt(dt)[None] * rng.standard_normal(pred.shape),
                         axis=2)
        pred = pred + walk + pop.sigma_mps[:, None, None] * rng.standard_normal(pred.shape)
        mask = np.array(batch.mask, bool)
        mask[:, 0] = False
        obs, pr = v_obs[mask], pred[:, mask]
        pit.extend(np.mean(pr <= obs[None], axis=0))
        for lv in LEVELS:
            lo, hi = np.percentile(pr, [50 * (1 - lv), 50 * (1 + lv)], axis=0)
            hits[lv].extend((obs >= lo) & (obs <= hi))
        lo, hi = np.percentile(pr, [2.5, 97.5], axis=0)
        per_pair.append({"held_out": [str(r) for r in pair], "samples": int(obs.size),
                         "coverage_95": float(np.mean((obs >= lo) & (obs <= hi)))})
    return {"model": model, "pairs": len(per_pair), "samples": len(hits[LEVELS[0]]), "draws": draws,
            "lopo_fits_failing_gates": gates_failed, "retried": retried, "per_pair": per_pair, "sampler": {
                "num_warmup": GNSS_LOPO_SAMPLER.num_warmup, "num_samples": GNSS_LOPO_SAMPLER.num_samples},
            "sample_coverage": {str(lv): float(np.mean(hits[lv])) for lv in LEVELS},
            "pit_mean": float(np.mean(pit)), "pit_sd": float(np.std(pit))}


def gnss_diagnosis(folder: Path = GNSS_DIR) -> dict:
    """``diagnose`` (speed traces: one MAP fit, the candidates scored about it) of the eco-car
    campaign with ``split_f0_f2``: the gap, where it lies, every candidate's statement."""
    from bayes_roadload.analysis.diagnose import diagnose

    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = diagnose(gnss_campaign(folder), "split_f0_f2")
    keep = ("trend_rms_mps", "trend_floor_mps", "lag1_autocorr", "spread_excess", "spread_p_value")
    return {"gap": {k: d.result["gap"].get(k) for k in keep}, "where": d.result["localisation"]["where"],
            "top": d.top, "rules": d.result["rules"], "wall_s": round(time.perf_counter() - t0, 1),
            "candidates": [{k: c.get(k) for k in ("effect", "rank", "supported", "identifiable", "delta_elpd",
                                                  "statement")} for c in d.candidates]}


def gnss_markdown(rec) -> list[str]:
    lines = ["## Eco-car GNSS coastdowns (speed only)", "",
             "`Finding-Rolling-Resistance-for-Electric-Car/Data/Michelin60{A,A1,B,B1}.csv`: speed in km/h at 1 Hz from",
             "a GNSS logger, a very light electric car coasting from ~29 km/h to a stop (read in place; no licence).",
             "A and B are read as the two directions, (A, B) and (A1, B1) as pairs; each trace is cut where the speed",
             f"first falls below {GNSS_MIN_SPEED_MPS} m/s. Vehicle: the upstream analysis' 78 kg and 0.4294 m^2, effective",
             "mass 80 kg (assumed). Fitted as speed traces (`fit_nuts`, integrated-noise residuals), in still air",
             "(`split_f0_f2`: Crr = AD and C_D = CD0) and with a latent along-track wind per pair (`split_f0_f2_wind`).",
             f"Samples per run: {rec['runs']}.", "",
             "| model | Crr = AD | C_D (A = 0.4294 m^2) | along-track wind per pair (m/s) | gates | wall |",
             "|---|---|---|---|---|---|"]
    for model, m in rec["models"].items():
        p = m["posterior"]
        winds = ", ".join(_fmt(p, k, 2) for k in p if k.startswith("head_wind_mps")) or "-"
        gate = "pass" if m["pass"] else "FAIL " + ",".join(m["failed"])
        lines.append(f"| {model} | {_fmt(p, 'AD', 3)} | {_fmt(p, 'CD0', 3)} | {winds} | {gate} (R-hat "
                     f"{m['max_r_hat']:.3f}, div {m['divergences']}) | {m['wall_s']} s |")
    lines.append("")
    dg = rec.get("diagnosis")
    if dg:
        g = dg["gap"]
        lines += [f"`bayes-roadload diagnose --model split_f0_f2` on the same runs ({dg['wall_s']} s; rules: library "
                  f"`{dg['rules']['library_sha256'][:16]}`, thresholds `{dg['rules']['thresholds_sha256'][:16]}`): "
                  f"residual trend {g['trend_rms_mps']:.3g} m/s against a white-noise floor of "
                  f"{g['trend_floor_mps']:.3g} m/s, lag-1 autocorrelation {g['lag1_autocorr']:.2f}, residuals "
                  f"concentrated by {dg['where'][0]}; "
                  + (f"**{dg['top']}** supported." if dg["top"] else "no candidate supported."), "",
                  "| rank | candidate | delta_elpd | statement |", "|---|---|---|---|"]
        for c in dg["candidates"]:
            d = c["delta_elpd"]
            lines.append(f"| {c['rank']} | {c['effect']} | {'-' if d is None else f'{d:.1f}'} | {c['statement']} |")
    for lo in [rec.get("lopo"), *rec.get("lopo_models", {}).values()]:
        lines += _lopo_lines(lo)
    return lines


def _lopo_lines(lo) -> list[str]:
    """The paragraph of one model's leave-one-pair-out coverage (:func:`gnss_lopo`)."""
    lines = []
    if lo:
        cov = lo["sample_coverage"]
        failing = "; ".join(f"the fit of {', '.join(f['fitted'])} failed {', '.join(f['failed'])}"
                            for f in lo["lopo_fits_failing_gates"]) or "every fit passed its gates"
        failing += "".join(f" (the fit of {', '.join(r['fitted'])} after its logged retry: its first attempt failed "
                           f"{', '.join(r['failed_first'])})" for r in lo.get("retried", []))
        lines += ["", f"**Leave-one-pair-out predictive coverage** (`{lo['model']}`; fit one pair with "
                  f"{lo['sampler']['num_warmup']} + {lo['sampler']['num_samples']} draws per chain, draw the other "
                  f"pair's speed traces {lo['draws']} times from that posterior: the drag model integrated from the "
                  "held-out run's first speed, the integrated noise as a random walk and the white noise; "
                  f"{lo['samples']} held-out samples after the start): central 50 / 90 / 95 % intervals hold "
                  f"{cov['0.5']:.2f} / {cov['0.9']:.2f} / {cov['0.95']:.2f} of them (per held-out pair at 95 %: "
                  + ", ".join(f"{p['coverage_95']:.2f}" for p in lo["per_pair"])
                  + f"); PIT mean {lo['pit_mean']:.2f}, sd {lo['pit_sd']:.2f} (uniform: 0.5, 0.29); {failing}. "
                  "The samples of a trace are strongly correlated (the random walk), so two held-out pairs are "
                  "few independent checks."]
    return lines


def _fmt(p, k, digits=4):
    r = p[k]
    return f"{r['mean']:.{digits}g} [{r['q2.5']:.{digits}g}, {r['q97.5']:.{digits}g}]"


def _datasets(records):
    return [(k, v) for k, v in records.items() if not k.startswith("_")]


def markdown(records) -> str:
    lines = ["# Real data: VBOX split exports", "",
             "Generated by `python benchmarks/real_data.py` (do not edit by hand). The exports (Racelogic VBOX",
             "\"Coastdown\", NBR 10312 split method: a high window 95 -> 70 km/h in five 5 km/h bands and a low",
             "window 50 -> 35 km/h in three, interleaved low runs 55 -> 30 km/h in five) are read in place from",
             "`../shared/data/external/coastdown-mda-split`; they carry no licence and are not in this repository.",
             "", "## What was fitted", "",
             "- Import: `import_vbox` with the default gates, checked against every run (band times add up to the",
             "  logged time; band time x band mid-speed against the logged distance, median error per file below).",
             "- Validity: the operator's Run-Use flag, a Hampel identifier on each run's window time within its",
             "  window and heading (scale floored at 2 % of the median), a rejected run takes its partner along.",
             "- Model `split_f0_f2` (F = F0 + F2 v^2, still air), interval-time likelihood (gate timing error, band",
             "  noise, run-level deceleration offset integrated out), MAP + Laplace-whitened NUTS, 2 x 1000 draws,",
             "  target acceptance 0.9, with the project's gates.",
             "- **The exports do not record the vehicle.** The fits use a nominal vehicle of 1000 kg test mass,",
             "  1020 kg effective mass and 1 m^2 frontal area: `AD` is the rolling-resistance coefficient Crr",
             "  (independent of the mass up to the assumed 2 % rotating inertia), `CD0` reads as C_D A (m^2) per",
             "  tonne of test mass, and F0, F2 are per tonne: multiply by the test mass in tonnes. Band times",
             "  identify only F / M_e. No temperature correction where no weather covers the runs (reference",
             "  conditions assumed): the Kestrel log covers only 2024-04-22.", ""]
    lines += ["## Road load", "",
              "| campaign | runs (accepted) | Crr = AD | C_D A per tonne (m^2) | F0 per tonne (N) | F2 per tonne (N/(km/h)^2) | gates |",
              "|---|---|---|---|---|---|---|"]
    for name, r in _datasets(records):
        p = r["posterior"]
        d = r["diagnostics"]
        gate = "pass" if d["pass"] else "FAIL: " + ", ".join(d["failed"])
        lines.append(f"| {name} | {r['runs']} ({r['accepted']}) | {_fmt(p, 'AD')} | {_fmt(p, 'CD0')} | "
                     f"{_fmt(p, 'F0_N')} | {_fmt(p, 'F2_N_per_kph2')} | {gate} (R-hat {d['max_r_hat']:.3f}, "
                     f"min ESS {d['min_ess_bulk']:.0f}/{d['min_ess_tail']:.0f}, div {d['divergences']}) |")
    lines += ["", "Posterior means with 95 % intervals. Noise: gate-crossing error, band noise, run deceleration sd:", ""]
    for name, r in _datasets(records):
        p = r["posterior"]
        lines.append(f"- {name}: sigma_gate_s {_fmt(p, 'sigma_gate_s', 2)}, band noise "
                     f"{_fmt(p, 'band_noise_s_per_sqrt_s', 2)} s/sqrt(s), run decel sd "
                     f"{_fmt(p, 'run_decel_sd_mps2', 2)} m/s^2; fit {r['timings_s']}")
    lines += ["", "## Import checks and rejected runs", ""]
    for name, r in _datasets(records):
        lines.append(f"**{name}**")
        lines.append("")
        lines += [f"- {x}" for x in r["import"]]
        lines += [f"- rejected {x}" for x in r["rejected"]] or ["- no run rejected"]
        lines.append("")
    if any("lopo" in r for _, r in _datasets(records)):
        lines += ["## Leave-one-pair-out predictive coverage", "",
                  "Each accepted opposite-direction pair is left out in turn, the rest refitted (2 x (300 + 500)",
                  "draws), and the held-out runs' band times drawn from the posterior predictive (model time +",
                  "gate error + band noise + a new run effect). Coverage of the central intervals:", "",
                  "| campaign | pairs | bands | 50 % | 90 % | 95 % | run totals 50 / 90 / 95 % | PIT mean (sd) | LOPO fits failing gates |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for name, r in _datasets(records):
            if "lopo" not in r:
                continue
            lo = r["lopo"]
            bc, tc = lo["band_coverage"], lo["run_total_coverage"]
            lines.append(f"| {name} | {lo['pairs']} | {lo['bands']} | {bc['0.5']:.2f} | {bc['0.9']:.2f} | "
                         f"{bc['0.95']:.2f} | {tc['0.5']:.2f} / {tc['0.9']:.2f} / {tc['0.95']:.2f} | "
                         f"{lo['pit_mean']:.2f} ({lo['pit_sd']:.2f}) | {lo['lopo_fits_failing_gates']}"
                         + (" (" + ", ".join(f"{g} {n}" for g, n in lo["lopo_failed_gates"].items()) + ")"
                            if lo.get("lopo_failed_gates") else "") + " |")
        lines += ["", "A calibrated predictive gives coverage near the nominal level and PIT values uniform "
                      "(mean 0.5, sd 0.29).", ""]
    lines += ["## The + / - heading difference", "",
              "Mean resisting force per tonne over each window, M_e (v_start - v_end) / T, by heading (model-free).",
              "A constant grade adds the same force difference in both windows; an along-track wind adds",
              "rho C_D A v w x 2 per heading, so its difference grows with the speed (about 1.9 x from the low",
              "window to the high one).", "",
              "| campaign | file (session) | window | + runs | - runs | F+ (N/t) | F- (N/t) | F+ - F- (N/t) |",
              "|---|---|---|---|---|---|---|---|"]
    for name, r in _datasets(records):
        for h in r["heading_forces"]:
            lines.append(f"| {name} | {h.get('session', '')} | {h['window']} | {h['runs_plus']} | {h['runs_minus']} | {h['force_plus_n']:.1f} | "
                         f"{h['force_minus_n']:.1f} | {h['difference_n']:+.1f} +- {h['difference_se_n']:.1f} |")
    lines += ["", "Drift of the resisting force over each session, by window and heading (least squares on the",
              "runs' start times; N per tonne per hour):", "",
              "| campaign | file (session) | window | heading | runs | span (h) | drift (N/t per h) |",
              "|---|---|---|---|---|---|---|"]
    for name, r in _datasets(records):
        for h in r.get("heading_trends", []):
            lines.append(f"| {name} | {h['session']} | {h['window']} | {'+' if h['direction'] > 0 else '-'} | {h['runs']} | "
                         f"{h['span_h']:.2f} | {h['slope_n_per_h']:+.1f} +- {h['slope_se']:.1f} |")
    lines += ["", "Model comparison (PSIS-LOO over runs; `elpd_diff` from the best):", "",
              "| campaign | model | elpd_loo (se) | elpd_diff (dse) | grade (mrad) | head wind for + runs (m/s) | gates |",
              "|---|---|---|---|---|---|---|"]
    for name, r in _datasets(records):
        for model, m in r.get("heading_models", {}).items():
            grade = (f"{1e3 * m['grade_rad_mean']:.2f} [{1e3 * m['grade_rad_q2.5']:.2f}, {1e3 * m['grade_rad_q97.5']:.2f}]"
                     if "grade_rad_mean" in m else "-")
            wind = (f"{m['head_wind_mps_mean']:.2f} [{m['head_wind_mps_q2.5']:.2f}, {m['head_wind_mps_q97.5']:.2f}]"
                    if "head_wind_mps_mean" in m else "-")
            lines.append(f"| {name} | {model} | {m['elpd_loo']:.1f} ({m['elpd_se']:.1f}) | {m['elpd_diff']:.1f} "
                         f"({m['dse']:.1f}) | {grade} | {wind} | {'pass' if m['pass'] else 'FAIL ' + ','.join(m['failed'])} |")
    if any("diagnosis" in r for _, r in _datasets(records)):
        lines += ["", "## `bayes-roadload diagnose` on the interval campaigns", "",
                  "The sim-to-real diagnosis of interval times (`analysis/diagnose_intervals.py`): `split_f0_f2` fitted, "
                  "then each candidate an interval campaign can carry added and refitted with NUTS, compared by "
                  "PSIS-LOO over runs (supported: delta_elpd_loo >= 5, > 2 se, 2 ahead of the others, its fit "
                  "passing the gates).", "",
                  "| campaign | residual RMS (sd) | +/- difference (sd) | 90 % coverage | candidate | delta_elpd_loo (se) "
                  "| estimate | heading shrink % | verdict |", "|---|---|---|---|---|---|---|---|---|"]
        for name, r in _datasets(records):
            dg = r.get("diagnosis")
            if not dg:
                continue
            g = dg["gap"]
            for c in dg["candidates"]:
                est = ", ".join(f"{k} {v['mean']:.4g} +- {v['sd']:.2g}" for k, v in c.get("estimates", {}).items()) or "-"
                sh = c.get("shrink_pct", {}).get("heading_z_diff")
                lines.append(f"| {name} | {g['band_z_rms']:.2f} | {g['heading_z_diff']:.2f} | {g['coverage_90']:.2f} | "
                             f"{c['effect']} | {c['delta_elpd']:.1f} ({c['delta_elpd_se']:.1f}) | {est} | "
                             f"{'-' if sh is None else f'{sh:.0f}'} | {c['statement']} |")
    if "gnss" in records.get("_extra", {}):
        lines += [""] + gnss_markdown(records["_extra"]["gnss"])
    lines += ["", "<!-- reading -->", ""]
    return "\n".join(lines)


def _write_markdown(records, out: Path) -> None:
    text = markdown(records)
    reading = ROOT / "docs" / "real_data_reading.md"
    if reading.exists():   # the hand-written reading of the figures, kept across regenerations
        text = text.replace("<!-- reading -->", reading.read_text())
    out.write_text(text)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "real_data.md")
    ap.add_argument("--json", type=Path, default=ROOT / "docs" / "real_data.json")
    ap.add_argument("--skip-lopo", action="store_true")
    ap.add_argument("--extras-only", action="store_true",
                    help="read the records in --json, add the drift table and the eco-car GNSS fits, rewrite the markdown")
    ap.add_argument("--markdown-only", action="store_true", help="rewrite the markdown from the records in --json")
    ap.add_argument("--gnss-lopo-only", action="store_true",
                    help="read the records in --json, add the eco-car traces' leave-one-pair-out coverage, rewrite "
                         "the markdown")
    ap.add_argument("--gnss-lopo-model", default="split_f0_f2",
                    help="the model of --gnss-lopo-only (default %(default)s; four_term_tyre_lag: the speed-trace "
                         "default of `fit`)")
    ap.add_argument("--only", nargs="+", metavar="CAMPAIGN",
                    help="fit (with LOPO unless --skip-lopo), drift tables and diagnosis of these campaigns again "
                         "(names as in the tables), onto the records in --json; the others' records are kept")
    ap.add_argument("--diagnose-only", action="store_true",
                    help="read the records in --json, run `diagnose` on every interval campaign and on the "
                         "eco-car speed traces, rewrite the markdown")
    args = ap.parse_args(argv)
    if args.markdown_only:
        _write_markdown(json.loads(args.json.read_text()), args.out)
        return 0
    if args.only:
        unknown = sorted(set(args.only) - set(DATASETS))
        if unknown:
            ap.error(f"--only: unknown campaign(s) {unknown}; known: {sorted(DATASETS)}")
        if not (args.data / "coastdown").is_dir():
            print(json.dumps({"skipped": f"{args.data} not found"}))
            return 0
        records = json.loads(args.json.read_text())
        fresh = run(args.data, args.skip_lopo, only=set(args.only))
        for name, rec in fresh.items():
            rec.update(drift_tables(args.data, name))
            rec["diagnosis"] = heading_diagnosis(_import(args.data, name)[0])
            if args.skip_lopo and "lopo" in records.get(name, {}):
                rec["lopo"] = records[name]["lopo"]
            records[name] = rec
        args.json.write_text(json.dumps(records, indent=2) + "\n")
        _write_markdown(records, args.out)
        return 0
    if args.gnss_lopo_only:
        records = json.loads(args.json.read_text())
        if GNSS_DIR.is_dir() and "gnss" in records.get("_extra", {}):
            gnss = records["_extra"]["gnss"]
            if args.gnss_lopo_model == "split_f0_f2":
                gnss["lopo"] = gnss_lopo()
            else:
                gnss.setdefault("lopo_models", {})[args.gnss_lopo_model] = gnss_lopo(model=args.gnss_lopo_model)
            args.json.write_text(json.dumps(records, indent=2) + "\n")
            _write_markdown(records, args.out)
        return 0
    if args.diagnose_only:
        if not (args.data / "coastdown").is_dir():
            print(json.dumps({"skipped": f"{args.data} not found"}))
            return 0
        records = json.loads(args.json.read_text())
        for name in DATASETS:  # every interval campaign
            if name in records:
                records[name]["diagnosis"] = heading_diagnosis(_import(args.data, name)[0])
                print(f"{name}: diagnosed", file=sys.stderr)
        if GNSS_DIR.is_dir() and "gnss" in records.get("_extra", {}):
            records["_extra"]["gnss"]["diagnosis"] = gnss_diagnosis()
            print("eco-car GNSS: diagnosed", file=sys.stderr)
        args.json.write_text(json.dumps(records, indent=2) + "\n")
        _write_markdown(records, args.out)
        return 0
    if args.extras_only:
        records = json.loads(args.json.read_text())
    else:
        if not (args.data / "coastdown").is_dir():
            print(json.dumps({"skipped": f"{args.data} not found"}))
            return 0
        records = run(args.data, args.skip_lopo)
    for name in DATASETS:
        if name in records:
            records[name].update(drift_tables(args.data, name))
    if GNSS_DIR.is_dir():
        records.setdefault("_extra", {})["gnss"] = gnss_record()
        records["_extra"]["gnss"]["lopo"] = gnss_lopo()
    args.json.write_text(json.dumps(records, indent=2) + "\n")
    _write_markdown(records, args.out)
    print(json.dumps(records, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
