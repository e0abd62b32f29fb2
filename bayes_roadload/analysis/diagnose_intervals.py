"""Sim-to-real diagnosis of speed-gate interval campaigns (``intervals.csv``) and
distance-time records (``distances.csv``).

The trace diagnosis (:mod:`.diagnose`) linearises speed traces; a gate logger records only the
time through each speed band (a marker record the time between known distances), with no
anemometer and no time or position inside a band.  Here
every candidate that such data can carry is added to the model and *refitted* with NUTS, and
the candidates are compared by leave-one-run-out predictive density (PSIS-LOO over runs,
``arviz.loo``): ``delta_elpd`` = elpd_loo(model + candidate) - elpd_loo(model), with the
standard error of the difference (``arviz.compare``).

* ``track_gradient``: a constant grade (``gradient``, grade_rad ~ normal(0, the library's sd));
* ``spatial_wind``: an along-track wind the logger does not record (``air = "wind"``, steady:
  interval times carry no position along the track, so not its variation);
* ``tyre_speed_exponent``: ``tyre_speed_power`` (X (v / 20 m/s)^4, X ~ normal(0, the library's sd)).

The others are stated, not scored: the anemometer effects (airspeed and yaw calibration, cup
lag, side-force slip) need an anemometer; lift and a driveline C_t v^2 have the signature of
C_D0 when the air is not measured; pitch, an effective-mass error and a tyre transient act
through the deceleration or the time in the run, which the band-time quadrature does not carry;
run-to-run variation is in the likelihood already (each run's deceleration offset).

The gap: ``band_z_rms`` (RMS of the band times' standardised residuals against the posterior
predictive, floor 1), ``lag1_autocorr`` (of those residuals along each run's bands, floor 0),
``heading_z_diff`` (mean residual of the + runs minus the - runs: a grade or a wind leaves
one, floor 0), ``coverage_90`` (share of bands inside their central 90 % predictive interval)
and ``loo_elpd_per_run``.  ``localisation`` bins the residuals by band speed, direction, window
and run (eta^2).  ``diagnosis.json`` has the contract keys of the trace diagnosis.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from typing import Any, Mapping

import numpy as np

from .. import config
from . import effects as fx

SCORED = ("track_gradient", "spatial_wind", "tyre_speed_exponent")
"""Library effects an interval campaign can score."""

STATEMENTS = {
    "airspeed_calibration": "not applicable: interval times carry no anemometer reading to calibrate",
    "yaw_calibration": "not applicable: interval times carry no yaw reading",
    "anemometer_dynamics": "not applicable: interval times carry no anemometer reading",
    "aero_admittance": "not applicable: interval times carry no anemometer reading",
    "side_force_slip": "not applicable: needs the yaw angle, which interval times do not carry",
    "aero_lift": "not identifiable here: with the air not measured, lift unloading C_L0 A_D q looks like a "
                 "change of C_D0; needs tunnel lift coefficients or wheel loads",
    "driveline_quadratic": "not identifiable here: with the air not measured, C_t v^2 is C_D0's signature; "
                           "needs the driveline torque logged",
    "pitch_attitude": "not applicable: acts through the deceleration, which the band-time quadrature "
                      "does not carry; needs pitch measured",
    "mass_error": "not applicable here: rescales every band time alike; needs runs at a second, weighed test mass",
    "tyre_temperature": "not applicable: a transient over the time in the run; needs speed traces with "
                        "tyre temperature, or runs started at different speeds",
    "run_to_run_variation": "in the model already: each run's deceleration offset is part of the band-time "
                            "likelihood (run_decel_sd_mps2)",
    "tyre_start_temperature": "in the model already: each run's rolling level is part of its deceleration "
                              "offset (run_decel_sd_mps2); needs tyre temperature logged at each run's start "
                              "to be told from the other run-level causes",
}

GAP_FLOORS = {"band_z_rms": 1.0, "lag1_autocorr": 0.0, "heading_z_diff": 0.0}


def candidate_spec(spec, effect: str, library: Mapping[str, fx.Effect]):
    """``spec`` with the candidate ``effect`` added (free parameter, prior from the library);
    None when the model has it already."""
    from ..inference.spec import Prior

    e = library[effect]
    if effect == "track_gradient":
        if "gradient" in spec.terms:
            return None
        return dataclasses.replace(spec, name=f"{spec.name}+{effect}", terms=spec.terms + ("gradient",),
                                   free=spec.free + ("grade_rad",), source=None,
                                   priors={**spec.priors, "grade_rad": Prior("normal", 0.0, e.prior_sd["grade_rad"])})
    if effect == "spatial_wind":
        if spec.air == "wind":
            return None
        fixed = {k: v for k, v in spec.fixed.items() if k != "head_wind_mps"}
        fixed.setdefault("cross_wind_mps", 0.0)
        return dataclasses.replace(spec, name=f"{spec.name}+{effect}", air="wind", fixed=fixed,
                                   free=spec.free + ("head_wind_mps",), source=None,
                                   priors={**spec.priors,
                                           "head_wind_mps": Prior("normal", 0.0, e.prior_sd["wind_gradient_mps"])})
    if effect == "tyre_speed_exponent":
        if "tyre_speed_power" in spec.terms:
            return None
        return dataclasses.replace(spec, name=f"{spec.name}+{effect}", terms=spec.terms + ("tyre_speed_power",),
                                   free=spec.free + ("tyre_power_coeff",), source=None,
                                   fixed={**spec.fixed, **e.fixed},
                                   priors={**spec.priors,
                                           "tyre_power_coeff": Prior("normal", 0.0, e.prior_sd["tyre_power_coeff"])})
    raise ValueError(f"{effect!r} is not scored on interval campaigns ({', '.join(SCORED)})")


def _eta2(z: np.ndarray, groups: np.ndarray) -> float:
    ok = np.isfinite(z)
    z, groups = z[ok], groups[ok]
    total = float(np.sum((z - z.mean()) ** 2))
    if total <= 0:
        return 0.0
    between = sum(len(z[groups == g]) * (z[groups == g].mean() - z.mean()) ** 2 for g in np.unique(groups))
    return float(between / total)


def residual_z(problem, samples, n_draws: int = 400) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Standardised residuals [R, K] of the observed band times against the posterior
    predictive (NaN on padding), and the 5 % / 95 % predictive quantiles."""
    from ..inference.intervals import observed_band_times, predictive_band_times

    pred = predictive_band_times(problem, samples, n_draws=n_draws)["interval_s"]
    obs = observed_band_times(problem)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        z = (obs - np.nanmean(pred, axis=0)) / np.nanstd(pred, axis=0)
        lo, hi = np.nanpercentile(pred, [5.0, 95.0], axis=0)
    inside = np.where(np.isfinite(obs), (obs >= lo) & (obs <= hi), np.nan)
    return z, inside, obs


def gap_metrics(problem, samples, loo) -> tuple[dict[str, float], np.ndarray]:
    z, inside, _ = residual_z(problem, samples)
    dirs = np.asarray(problem.directions)
    lag = [a * b for row in z for a, b in zip(row[:-1], row[1:]) if np.isfinite(a) and np.isfinite(b)]
    var = np.nanmean(z**2)
    run_mean = np.nanmean(z, axis=1)
    plus, minus = run_mean[dirs > 0], run_mean[dirs < 0]
    heading = float(abs(plus.mean() - minus.mean())) if len(plus) and len(minus) else math.nan
    gap = {"band_z_rms": float(np.sqrt(var)), "lag1_autocorr": float(np.mean(lag) / var) if lag else math.nan,
           "heading_z_diff": heading, "coverage_90": float(np.nanmean(inside)),
           "loo_elpd_per_run": float(loo.elpd_loo) / problem.n_runs}
    return gap, z


def localise(problem, z: np.ndarray) -> dict[str, Any]:
    """eta^2 of the standardised residuals by band speed (interval times: mid-speed, 5 km/h
    bins), segment (distance-time records: its place in the run), direction, window (interval
    times) and run, and their mean per bin; ``where`` orders the variables by eta^2."""
    mask = np.asarray(problem.mask)
    variables: dict[str, Any] = {}
    if hasattr(problem, "bands"):
        idx = np.asarray(problem.band_index)
        mid = 0.5 * (np.asarray(problem.bands.speed_start_mps) + np.asarray(problem.bands.speed_end_mps))[idx]
        variables["speed_mps"] = np.round(mid / (5.0 * config.KPH_TO_MPS)) * 5.0 * config.KPH_TO_MPS
    else:
        variables["segment"] = np.broadcast_to(np.arange(z.shape[1], dtype=float)[None, :], z.shape)
    variables["direction"] = np.broadcast_to(np.asarray(problem.directions)[:, None], z.shape)
    if hasattr(problem, "windows"):
        variables["window"] = np.broadcast_to(np.asarray(problem.windows, dtype=object)[:, None], z.shape)
    variables["run"] = np.broadcast_to(np.asarray([str(r) for r in problem.run_ids], dtype=object)[:, None], z.shape)
    out: dict[str, Any] = {}
    for name, g in variables.items():
        g = np.asarray(g)[mask]
        zz = z[mask]
        keys = list(dict.fromkeys(g.tolist()))
        out[name] = {"eta2": _eta2(zz, np.asarray(g)),
                     "bins": [{"value": k if isinstance(k, str) else float(k),
                               "mean_z": float(np.nanmean(zz[g == k])), "n": int(np.sum(g == k))} for k in keys]}
    out["where"] = sorted(variables, key=lambda k: -out[k]["eta2"])
    return out


def _shrink(before: Mapping[str, float], after: Mapping[str, float]) -> dict[str, float]:
    out = {}
    for k, floor in GAP_FLOORS.items():
        excess = before[k] - floor
        out[k] = 100.0 * (before[k] - after[k]) / excess if math.isfinite(excess) and excess > 0.1 else math.nan
    return out


def _fit(campaign, spec, sampler, runs):
    """NUTS fit of an interval or distance-time campaign through its kind's entry
    (:data:`~bayes_roadload.inference.kinds.KINDS`), with its report and PSIS-LOO."""
    import arviz as az

    from ..inference.kinds import FitOptions, kind_of

    entry = kind_of(campaign)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = entry.fit(campaign, spec, FitOptions(sampler=sampler, runs=runs))
        report = entry.report(fit, campaign)
        loo = az.loo(report.idata, var_name=fit.problem.observed_name)
    return fit, report.idata, report.summary, report.diagnostics, loo


def diagnose_intervals(campaign, model: Any = "split_f0_f2", *, library: Mapping[str, fx.Effect] | None = None,
                       sampler: config.SamplerConfig | None = None, runs=None,
                       settings: config.DiagnosisConfig = config.DEFAULT_DIAGNOSIS):
    """Diagnose ``model`` on an interval campaign (module docstring); returns a
    :class:`.diagnose.Diagnosis` whose ``result`` has the contract keys."""
    import time

    import arviz as az

    from ..inference.spec import load_model_spec
    from .diagnose import Diagnosis, _json_safe

    library = fx.load_library() if library is None else library
    spec = load_model_spec(model) if isinstance(model, str) else model
    sampler = sampler or config.SamplerConfig(num_warmup=500, num_samples=1000, seed=11, target_accept=0.9)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    fit, _, _, diag, loo = _fit(campaign, spec, sampler, runs)
    runs = list(fit.problem.run_ids)
    timings["fit_s"] = time.perf_counter() - t0
    before, z = gap_metrics(fit.problem, fit.samples, loo)
    before["gates_pass"] = bool(diag["pass"])
    loc = localise(fit.problem, z)
    loos = {"model": loo}
    entries = []
    t0 = time.perf_counter()
    for name in fx.EFFECT_NAMES:
        e = library.get(name)
        if e is None:
            continue
        entry: dict[str, Any] = {"effect": name, "rank": None, "supported": False, "delta_elpd": math.nan,
                                 "gap_before": before, "gap_after": {}, "shrink_pct": {}, "needs": e.needs,
                                 "cause": e.cause,
                                 "identifiable": name in SCORED,
                                 "unavailable": None if name in SCORED else STATEMENTS[name]}
        cand = candidate_spec(spec, name, library) if name in SCORED else None
        if name in SCORED and cand is None:
            entry["statement"] = "in the model already"
        elif cand is None:
            entry["statement"] = STATEMENTS[name]
        else:
            cfit, _, csummary, cdiag, closs = _fit(campaign, cand, sampler, runs)
            loos[name] = closs
            after, _ = gap_metrics(cfit.problem, cfit.samples, closs)
            after["gates_pass"] = bool(cdiag["pass"])
            s = csummary.set_index("parameter")
            added = [p for p in cand.free if p not in spec.free]
            entry.update(delta_elpd=float(closs.elpd_loo - loo.elpd_loo), gap_after=after,
                         shrink_pct=_shrink(before, after),
                         estimates={p: {"mean": float(s.loc[p, "mean"]), "sd": float(s.loc[p, "sd"])}
                                    for p in added if p in s.index})
        entries.append(entry)
    timings["candidates_s"] = time.perf_counter() - t0
    scored = [c for c in entries if math.isfinite(c["delta_elpd"])]
    if scored:
        for c in scored:
            # standard error of the difference to the model alone
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                pair = az.compare({"model": loos["model"], c["effect"]: loos[c["effect"]]})
            c["delta_elpd_se"] = float(pair["dse"].max())
        ranked = sorted(scored, key=lambda c: -c["delta_elpd"])
        best = ranked[0]
        rivals = [c for c in ranked[1:] if c["delta_elpd"] > best["delta_elpd"] - settings.ambiguity_margin]
        if best["delta_elpd"] >= settings.support_delta_elpd and best["delta_elpd"] > 2.0 * best["delta_elpd_se"]:
            if rivals:
                for c in [best] + rivals:
                    c["ambiguous_with"] = [o["effect"] for o in [best] + rivals if o is not c]
            elif best["gap_after"].get("gates_pass", False):
                best["supported"] = True
        for c in scored:
            if c["supported"]:
                c["statement"] = (f"supported: delta_elpd_loo {c['delta_elpd']:.1f} +- {c['delta_elpd_se']:.1f} "
                                  f">= {settings.support_delta_elpd:g}")
            elif c.get("ambiguous_with"):
                c["statement"] = (f"not distinguishable here: explains the gap as well as "
                                  f"{', '.join(c['ambiguous_with'])}; needs {c['needs']}")
            else:
                c["statement"] = (f"not supported: delta_elpd_loo {c['delta_elpd']:.1f} +- {c['delta_elpd_se']:.1f}"
                                  + ("" if c["gap_after"].get("gates_pass", True) else " (its fit failed the gates)"))
    entries.sort(key=lambda c: (not c["supported"], -(c["delta_elpd"] if math.isfinite(c["delta_elpd"]) else -1e300)))
    for i, c in enumerate(entries, 1):
        c["rank"] = i
    chosen = [c for c in entries if c["supported"]]
    refit = {"effects": [c["effect"] for c in chosen],
             "gap_after": chosen[0]["gap_after"] if chosen else dict(before),
             "shrink_pct": chosen[0]["shrink_pct"] if chosen else _shrink(before, before),
             "estimates": {p: v["mean"] for c in chosen for p, v in c.get("estimates", {}).items()}}
    from .diagnose import rules_fingerprint

    result = {"gap": before, "localisation": loc, "candidates": entries, "rules": rules_fingerprint(library, settings)}
    from ..inference.intervals import observed_band_times

    mask = np.asarray(fit.problem.mask)
    return Diagnosis(result=_json_safe(result), refit=_json_safe(refit), model=str(spec.name),
                     residual=np.nan_to_num(z), residual_after=np.nan_to_num(z),
                     time_s=np.cumsum(np.nan_to_num(observed_band_times(fit.problem)), axis=1),
                     mask=mask, run_ids=fit.problem.run_ids, timings=timings)


def _plot_bands(diag, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    loc = diag.result["localisation"]
    names = [v for v in ("speed_mps", "segment", "direction", "window", "run") if v in loc]
    fig, axes = plt.subplots(1, len(names), figsize=(3.4 * len(names), 2.8), squeeze=False)
    for ax, name in zip(axes[0], names):
        bins = loc[name]["bins"]
        labels = [b["value"] if isinstance(b["value"], str) else f"{b['value']:.3g}" for b in bins]
        ax.bar(range(len(bins)), [b["mean_z"] for b in bins], color="tab:blue")
        ax.set_xticks(range(len(bins)), labels, rotation=60, fontsize=6)
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.set_title(f"{name}  eta2={loc[name]['eta2']:.2f}", fontsize=9)
    axes[0, 0].set_ylabel("mean standardised residual")
    fig.suptitle(f"band-time residuals of {diag.model}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def write_interval_diagnosis(diag, out_dir, settings: config.DiagnosisConfig = config.DEFAULT_DIAGNOSIS):
    """``diagnosis.json`` (keys ``gap``, ``localisation``, ``candidates``), ``refit.json``,
    ``report.md`` with ``localisation.png`` and ``candidates.png``."""
    import json
    from pathlib import Path

    from .diagnose import _fmt, plot_candidates

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "diagnosis.json").write_text(json.dumps(diag.result, indent=1))
    (out / "refit.json").write_text(json.dumps(diag.refit, indent=1))
    _plot_bands(diag, out / "localisation.png")
    plot_candidates(diag.candidates, out / "candidates.png", settings.support_delta_elpd)
    gap = diag.result["gap"]
    top = diag.top
    verdict = (f"`{top}` is the leading supported effect." if top else
               "no candidate effect is supported (delta_elpd_loo >= "
               f"{settings.support_delta_elpd:g} and twice its standard error, ahead of the others by "
               f"{settings.ambiguity_margin:g}).")
    lines = [f"# Sim-to-real diagnosis of gate or marker times: model `{diag.model}`", "",
             f"**Verdict**: {verdict} Band-time residuals: RMS {_fmt(gap['band_z_rms'])} predictive sd (floor 1), "
             f"+/- heading difference {_fmt(gap['heading_z_diff'])} sd, 90 % coverage {_fmt(gap['coverage_90'])}.", "",
             "## 1. The gap", "", "| metric | value |", "| --- | --- |"]
    lines += [f"| {k} | {_fmt(v) if not isinstance(v, bool) else v} |" for k, v in gap.items()]
    loc = diag.result["localisation"]
    lines += ["", "## 2. Where", "", "| variable | eta2 |", "| --- | --- |"]
    lines += [f"| {v} | {loc[v]['eta2']:.3f} |" for v in loc["where"]]
    lines += ["", "![localisation](localisation.png)", "", "## 3. Which effect (refitted, PSIS-LOO over runs)", "",
              "| rank | effect | supported | delta_elpd_loo | se | heading shrink % | statement |",
              "| --- | --- | --- | --- | --- | --- | --- |"]
    for c in diag.candidates:
        lines.append(f"| {c['rank']} | `{c['effect']}` | {'yes' if c['supported'] else 'no'} | {_fmt(c['delta_elpd'], 3)} | "
                     f"{_fmt(c.get('delta_elpd_se'), 3)} | {_fmt(c['shrink_pct'].get('heading_z_diff'), 3)} | "
                     f"{c['statement']} |")
    lines += ["", "![candidates](candidates.png)", "", "## 4. How far it shrinks", ""]
    r = diag.refit
    if r["effects"]:
        lines += [f"Refitted with `{r['effects'][0]}`; estimates: "
                  + ", ".join(f"{k} = {_fmt(v)}" for k, v in r["estimates"].items()), "",
                  "| metric | before | after | shrink % |", "| --- | --- | --- | --- |"]
        for k in GAP_FLOORS:
            lines.append(f"| {k} | {_fmt(gap[k])} | {_fmt(r['gap_after'].get(k))} | {_fmt(r['shrink_pct'].get(k), 3)} |")
    else:
        lines.append("Nothing to refit: no candidate is supported.")
    lines += ["", "Timings (s): " + ", ".join(f"{k} {v:.1f}" for k, v in diag.timings.items()), ""]
    (out / "report.md").write_text("\n".join(lines))
    return out / "diagnosis.json"
