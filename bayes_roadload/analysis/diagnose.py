"""Sim-to-real diagnosis: the gap, where it lies, which effect causes it, how far it shrinks.

:func:`diagnose` answers, for a campaign and a model (issue 6):

1. **the gap** (:mod:`.gap`, :mod:`.effects`): residual trend and lag-1 autocorrelation,
   leave-one-pair-out log predictive density, excess between-run spread of the coefficients;
2. **where**: the residuals binned by time into the run, speed, distance, yaw, airspeed,
   direction and run (:func:`.gap.localise`);
3. **which effect**: every candidate of the library (``models/effects/library.toml``) added on
   top of the model and scored by its gain in expected log predictive density
   (``delta_elpd``, :mod:`.effects`), ranked; supported when ``delta_elpd`` reaches
   ``config.DEFAULT_DIAGNOSIS.support_delta_elpd`` *and* it is identifiable here, otherwise
   the statement says "not identifiable here, needs X";
4. **how far it shrinks**: each gap metric after refitting with the candidate, and the shrink
   in percent of its excess over its floor (what a correct model leaves: the trend of white
   noise, zero autocorrelation, a spread ratio of 1); the leading supported candidates are
   refitted together (Gauss-Newton, re-linearised) for the combined shrink.

:func:`write_diagnosis` writes ``diagnosis.json`` (exactly ``gap``, ``localisation``,
``candidates``), ``report.md`` and its plots.  :class:`DiagnoseJob` sends diagnoses through the
batch door (:func:`bayes_roadload.analysis.batch.run_batch`); :func:`withheld_effect_jobs`
builds the proof suite (campaigns simulated with one effect that the analysis model
withholds, and null controls).
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from .. import config
from ..data.campaign import Campaign
from . import effects as fx
from .gap import localise, plot_localisation, plot_residuals, residual_structure

SHRINK_FLOORS = {"trend_rms_mps": "trend_floor_mps", "lag1_autocorr": 0.0, "spread_excess": 1.0,
                 "spread_excess_AD": 1.0, "spread_excess_BD": 1.0, "spread_excess_CD0": 1.0}
"""Gap metrics with a shrink, and the level a correct model leaves (a number, or the gap key
holding it)."""


def _pair_groups(campaign: Campaign, run_ids) -> list[list[int]]:
    index = {r: i for i, r in enumerate(run_ids)}
    groups = [[index[a], index[b]] for a, b in campaign.pairs() if a in index and b in index]
    seen = {i for g in groups for i in g}
    groups += [[i] for i in range(len(run_ids)) if i not in seen]
    return groups


def _variables(lin: fx.Linearisation) -> dict[str, np.ndarray]:
    b = lin.batch
    t = np.asarray(b.time_s, float)
    v = np.asarray(b.speed_mps, float)
    dist = np.concatenate([np.zeros((v.shape[0], 1)), np.cumsum(0.5 * (v[:, 1:] + v[:, :-1]) * np.diff(t, axis=1), axis=1)],
                          axis=1)
    run = np.broadcast_to(np.arange(1, v.shape[0] + 1, dtype=float)[:, None], v.shape)
    return {"time_s": t, "speed_mps": v, "distance_m": dist, "yaw_rad": np.asarray(b.yaw_rad, float),
            "airspeed_mps": np.asarray(b.airspeed_mps, float),
            "direction": np.broadcast_to(np.asarray(b.direction, float)[:, None], v.shape), "run": run}


def gap_metrics(lin: fx.Linearisation, residual: np.ndarray, sol: fx.Solution | None, effects: tuple[str, ...],
                library: Mapping[str, fx.Effect], groups) -> dict[str, float]:
    """Every gap metric of the model plus ``effects`` (fitted as ``sol``; None: the model's
    own fit) with residuals ``residual``."""
    b = lin.batch
    out = residual_structure(residual, np.asarray(b.mask), np.asarray(b.time_s), lin.sigma_mps)
    n = lin.n_samples
    gain = sol.loglik_gain if sol is not None else fx.fit_effects(lin, (), library).loglik_gain
    out["insample_lpd_per_sample"] = (float(lin.loglik.sum()) + gain) / n
    out["lopo_lpd_per_sample"] = fx.lopo_lpd(lin, effects, library, groups) / n if len(groups) > 1 else math.nan
    # the spread against what the noise left by this model predicts (its noise levels refitted
    # to its residuals: a misfit inflates the integrated error, and with it every covariance)
    spread = fx.coefficient_spread(fx.with_noise(lin, *fx.fit_noise(lin, residual)), sol, library)
    if any(library[e].kind == "run" for e in effects if e in library):
        # each run its own coefficients: no spread left to compare (the refit is the spread)
        spread = {k: math.nan for k in spread}
    out.update(spread)
    return out


def shrink(before: Mapping[str, float], after: Mapping[str, float], n_runs: int = 2) -> dict[str, float]:
    """Shrink (%) of each metric's excess over its floor (:data:`SHRINK_FLOORS`): 100 = the
    refit removes the whole excess, 0 = nothing, negative = worse, above 100 = the metric ends
    below its floor (by its noise).  NaN when there was no
    excess to remove: the trend within its floor of the floor (twice white noise's), the
    autocorrelation below 0.05, a spread ratio within two of its standard errors of 1
    (1 / sqrt(2 (R - 1)) for R runs; for the Birge ratio ``spread_excess``, whose sd is
    1 / sqrt(2 (R - 1) P), the same margin is the stricter), where a percentage would be noise
    over noise."""
    out = {}
    for k, floor in SHRINK_FLOORS.items():
        if k not in before or k not in after or before[k] is None or after[k] is None:
            continue
        f = before[floor] if isinstance(floor, str) else floor
        if k == "trend_rms_mps":
            margin = f
        elif k == "lag1_autocorr":
            margin = 0.05
        else:
            margin = 2.0 / math.sqrt(2.0 * max(n_runs - 1, 1))
        excess = before[k] - f
        out[k] = 100.0 * (before[k] - after[k]) / excess if excess > margin and math.isfinite(excess) else math.nan
    return out


def vuong_z(best: list[float] | None, rival: list[float] | None) -> float:
    """Vuong's statistic over the runs: the summed difference of the two candidates' per-run
    gains (parameters charged) over its standard error sqrt(n) sd; inf without per-run gains
    or when every run agrees exactly."""
    if best is None or rival is None or len(best) < 2:
        return math.inf
    d = np.asarray(best, float) - np.asarray(rival, float)
    sd = float(np.std(d, ddof=1))
    return float(d.sum() / (math.sqrt(d.size) * sd)) if sd > 0 else (math.inf if d.sum() > 0 else -math.inf)


def select_effects(lin: fx.Linearisation, entries: list[dict], library, settings: config.DiagnosisConfig) -> list[str]:
    """Decide which candidates are supported (sets ``supported`` in ``entries``) and return them
    in order.  A candidate *qualifies* when it is identifiable here and its own delta_elpd
    reaches ``support_delta_elpd``.  The best qualifying candidate is claimed only when it
    beats every other candidate (qualifying or not) by ``ambiguity_margin``; otherwise the
    candidates within the margin explain the gap alike and none is supported ("not
    distinguishable here"); likewise a rival reaching support with nearly the same signature
    (``min_distinct_share``, VIF rule) and any rival explaining part of the gap that the best
    does not beat run by run (``min_vuong_z``, Vuong's test; not asked of a run-level best,
    whose gain lies by construction in the runs that differ most).  After the claimed one, the other
    qualifying candidates join by forward selection, each when it still gains
    ``support_delta_elpd`` given those already in (at most ``max_refit_effects``).  The
    airspeed scale adds the paired-run kinematics (independent data) to its dynamics, less
    their disagreement (:func:`.effects.kinematic_conflict`), also in the forward selection."""
    scored = [c for c in entries if math.isfinite(c["delta_elpd"])]
    qualifying = sorted((c for c in scored if c["qualifies"]), key=lambda c: -c["delta_elpd"])
    for c in entries:
        c["supported"] = False
    if not qualifying:
        return []
    best = qualifying[0]
    rivals = [c for c in scored if c is not best and c["delta_elpd"] > best["delta_elpd"] - settings.ambiguity_margin]
    if not best.get("kinematics"):
        for c in scored:
            if c is best or c in rivals or c.get("kinematics") or c["delta_elpd"] <= 0.0:
                continue
            # a rival with nearly the same signature (what is left of the best's information
            # once the rival is fitted: VIF rule) that explains the gap on its own cannot be
            # told apart by this campaign, however the gains fall
            if c["delta_elpd"] >= settings.support_delta_elpd:
                share = fx.distinct_share(lin, best["effect"], c["effect"], library)
                best.setdefault("distinct_share", {})[c["effect"]] = share
                if share < settings.min_distinct_share:
                    rivals.append(c)
                    continue
            # and any rival that explains part of it must lose run by run, not by one run's
            # luck (Vuong's test of non-nested models over the runs' gains).  Not asked of a
            # run-level best (each run its own coefficients): its gain lies, by what it is, in
            # the runs that differ most, and runs that happen to match the mean gain nothing
            if getattr(library.get(best["effect"]), "kind", "term") == "run":
                continue
            z = vuong_z(best.get("run_gains"), c.get("run_gains"))
            best.setdefault("vuong_z", {})[c["effect"]] = z
            if z < settings.min_vuong_z:
                rivals.append(c)
    if rivals:
        group = [best] + rivals
        for c in group:
            c["ambiguous_with"] = [o["effect"] for o in group if o is not c]
        return []
    chosen = [best["effect"]]
    best["supported"] = True
    # the claimed effect's parameters are refitted in the dynamics too (an airspeed scale
    # claimed from the kinematics included: what it leaves in the drag must not be credited
    # to the next candidate)
    dynamic = [best["effect"]]
    current = fx.fit_effects(lin, tuple(dynamic), library).loglik_gain
    for c in qualifying[1:]:
        if len(chosen) >= settings.max_refit_effects:
            break
        if c.get("kinematics"):
            # joint again, given the effects in: the dynamics' gain and factor with them
            # refitted, the kinematics with a claimed vane factor
            trial = tuple(dynamic + [c["effect"]])
            sol = fx.fit_effects(lin, trial, library)
            names = [lin.columns[j] for j in sol.shared]
            dyn = None
            if "airspeed_factor" in names:
                j = names.index("airspeed_factor")
                dyn = {"estimate": float(lin.values.get("airspeed_factor", 1.0) + sol.beta[j]),
                       "sd": float(math.sqrt(max(sol.cov_shared[j, j], 0.0)))}
            kin = c.get("kinematics_given_yaw") if "yaw_calibration" in chosen and c.get("kinematics_given_yaw") \
                else c["kinematics"]
            k = fx.n_added_parameters(lin, (c["effect"],), library)
            given = sol.loglik_gain - current - k + kin["loglik_gain"] - fx.kinematic_conflict(dyn, kin)
            c["delta_elpd_given_supported"] = float(given)
            gain_ok = given >= settings.support_delta_elpd
            if gain_ok:
                dynamic.append(c["effect"])
                current = sol.loglik_gain
        else:
            trial = tuple(dynamic + [c["effect"]])
            gain = fx.fit_effects(lin, trial, library).loglik_gain
            k = fx.n_added_parameters(lin, (c["effect"],), library)
            c["delta_elpd_given_supported"] = float(gain - current - k)
            gain_ok = gain - current - k >= settings.support_delta_elpd
            if gain_ok:
                dynamic.append(c["effect"])
                current = gain
        if gain_ok:
            c["supported"] = True
            chosen.append(c["effect"])
    return chosen


def _statement(effect: fx.Effect, entry: dict, cfg: config.DiagnosisConfig) -> str:
    if entry.get("ambiguous_with"):
        return (f"not distinguishable here from {', '.join(entry['ambiguous_with'])} (delta_elpd "
                f"{entry['delta_elpd']:.1f}: within {cfg.ambiguity_margin:g} of the best, or the same signature, "
                f"or not ahead run by run: distinct_share, vuong_z); needs {effect.needs}")
    if entry["unavailable"]:
        return f"not applicable: {entry['unavailable']}"
    kin = entry.get("kinematics")
    if kin and not entry["supported"]:
        return (f"not supported: invisible in the dynamics (C_D0 absorbs an airspeed scale); the paired-run kinematics "
                f"give airspeed_factor {kin['factor']:.4f} +- {kin['se']:.4f} from {kin['n_pairs']} pairs (z = {kin['z']:.1f})")
    if entry["supported"]:
        how = " (from the paired-run kinematics)" if kin else ""
        given = entry.get("delta_elpd_given_supported")
        extra = f", {given:.1f} given the effects ranked above it" if given is not None else ""
        return f"supported{how}: delta_elpd {entry['delta_elpd']:.1f} >= {cfg.support_delta_elpd:g}{extra}"
    if entry.get("qualifies"):
        given = entry.get("delta_elpd_given_supported")
        return (f"not supported: explained by the effects ranked above it" +
                (f" (delta_elpd {given:.1f} given them)" if given is not None else ""))
    if not entry["identifiable"]:
        what = ", ".join(effect.confounded_with) or "the model's coefficients"
        worst = min(entry["identification"].items(), key=lambda kv: kv[1]["contraction"])
        return (f"not identifiable here ({worst[0]}: the data shrink its prior by {100 * worst[1]['contraction']:.0f} %, "
                f"{100 * (1 - worst[1]['information_ratio']):.1f} % of its signature is that of {what}), "
                f"needs {effect.needs}")
    return f"not supported: delta_elpd {entry['delta_elpd']:.1f} < {cfg.support_delta_elpd:g}"


def _json_safe(x):
    if isinstance(x, dict):
        return {str(k): _json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_safe(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


@dataclass
class Diagnosis:
    """The result of :func:`diagnose`.

    ``result`` is the content of ``diagnosis.json``; ``refit`` the combined refit of the leading
    supported candidates (effects, estimates, gap after, shrink); the arrays are for plots.
    """

    result: dict[str, Any]
    refit: dict[str, Any]
    model: str
    residual: np.ndarray
    residual_after: np.ndarray
    time_s: np.ndarray
    mask: np.ndarray
    run_ids: tuple
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def candidates(self) -> list[dict]:
        return self.result["candidates"]

    @property
    def top(self) -> str | None:
        """The top-ranked supported effect, or None when no candidate is supported."""
        c = self.candidates[0] if self.candidates else None
        return c["effect"] if c is not None and c["supported"] else None


def diagnose(campaign: Campaign, model: Any = "three_term", *, library: Mapping[str, fx.Effect] | None = None,
             settings: config.DiagnosisConfig = config.DEFAULT_DIAGNOSIS) -> Diagnosis:
    """Diagnose the sim-to-real gap of ``model`` (a ``models/*.toml`` name or a ModelSpec) on
    ``campaign`` (module docstring).  One MAP fit of the model, the rest linearised about it."""
    from ..inference.bayes import build_problem
    from ..inference.nuts import find_map, prepare_problem

    library = fx.load_library() if library is None else library
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        problem, init = prepare_problem(build_problem(campaign, model), campaign)
        fit = find_map(problem, init)
    timings["map_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    lin = fx.linearise(problem, fit.constrained, library)
    timings["linearise_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    groups = _pair_groups(campaign, problem.run_ids)
    base_sol = fx.fit_effects(lin, (), library)
    before = gap_metrics(lin, lin.residual, None, (), library, groups)
    loc = localise(lin.residual, np.asarray(lin.batch.mask), _variables(lin))

    entries = []
    for name in fx.EFFECT_NAMES:
        e = library.get(name)
        if e is None:
            continue
        entry: dict[str, Any] = {"effect": name, "rank": None, "supported": False, "qualifies": False,
                                 "delta_elpd": math.nan,
                                 "gap_before": before, "gap_after": {}, "shrink_pct": {},
                                 "identifiable": False, "identification": {}, "estimates": {},
                                 "unavailable": lin.available.get(name)}
        if entry["unavailable"] is None and name in lin.effects:
            sol = fx.fit_effects(lin, (name,), library)
            k = fx.n_added_parameters(lin, (name,), library)
            delta = sol.loglik_gain - base_sol.loglik_gain - k
            # each run's share of the gain, less the added parameters spread over the runs
            entry["run_gains"] = [fx.run_loglik_gain(sol, i) - fx.run_loglik_gain(base_sol, i) - k / lin.n_runs
                                  for i in range(lin.n_runs)]
            ident = fx.identifiability(lin, name, library)
            identifiable = all(v["contraction"] >= settings.min_contraction for v in ident.values())
            entry.update(identification=ident, identifiable=identifiable,
                         estimates={p: v["estimate"] for p, v in ident.items()})
            if name == "airspeed_calibration":
                kin = fx.airspeed_kinematics(problem, campaign, float(lin.values.get("airspeed_factor", 1.0)))
                if kin is not None:
                    # one factor for both: the dynamics' and the kinematics' gains (each a
                    # Gaussian in the factor) add, less their disagreement at the joint optimum
                    conflict = fx.kinematic_conflict(ident.get("airspeed_factor"), kin)
                    kin = dict(kin, conflict=conflict)
                    entry["kinematics"] = kin
                    delta += kin["loglik_gain"] - conflict
                    # the paired runs identify the scale where the dynamics cannot
                    identifiable = identifiable or kin["loglik_gain"] - 1.0 >= settings.support_delta_elpd
                    entry["identifiable"] = identifiable
                    entry["estimates"] = {"airspeed_factor": kin["factor"]}
            entry["delta_elpd"] = float(delta)
            entry["qualifies"] = bool(identifiable and delta >= settings.support_delta_elpd)
            after = gap_metrics(lin, fx.refit_residual(lin, sol), sol, (name,), library, groups)
            entry["gap_after"] = after
            if math.isfinite(before["lopo_lpd_per_sample"]):
                # the same comparison out of sample: leave-one-pair-out log predictive density gain
                entry["delta_lopo_lpd"] = (after["lopo_lpd_per_sample"] - before["lopo_lpd_per_sample"]) * lin.n_samples
            entry["shrink_pct"] = shrink(before, after, lin.n_runs)
        entry["needs"] = e.needs
        entries.append(entry)
    air = next((c for c in entries if c.get("kinematics")), None)
    yaw = next((c for c in entries if c["effect"] == "yaw_calibration" and "yaw_factor" in c["estimates"]), None)
    if air is not None and yaw is not None:
        # the paired-run ratios use the vane (a cos psi): as they come out with the vane's factor estimated
        air["kinematics_given_yaw"] = fx.airspeed_kinematics(problem, campaign,
                                                             float(lin.values.get("airspeed_factor", 1.0)),
                                                             yaw_factor=yaw["estimates"]["yaw_factor"])
    chosen = select_effects(lin, entries, library, settings)
    for entry in entries:
        entry["statement"] = _statement(library[entry["effect"]], entry, settings)
    entries.sort(key=lambda c: (not c["supported"], -(c["delta_elpd"] if math.isfinite(c["delta_elpd"]) else -1e300)))
    for i, c in enumerate(entries, 1):
        c["rank"] = i
    timings["candidates_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    kinematic = {c["effect"] for c in entries if c.get("kinematics")}
    refit, after_resid = combined_refit(lin, [c for c in chosen if c not in kinematic], library, settings, groups,
                                        before)
    timings["refit_s"] = time.perf_counter() - t0
    result = {"gap": before, "localisation": loc, "candidates": entries}
    spec_name = getattr(model, "name", model)
    return Diagnosis(result=_json_safe(result), refit=_json_safe(refit), model=str(spec_name),
                     residual=lin.residual, residual_after=after_resid, time_s=np.asarray(lin.batch.time_s),
                     mask=np.asarray(lin.batch.mask), run_ids=lin.run_ids, timings=timings)


def combined_refit(lin: fx.Linearisation, chosen: list[str], library, settings: config.DiagnosisConfig, groups,
                   before: Mapping[str, float]) -> tuple[dict, np.ndarray]:
    """Refit the model with the supported candidates ``chosen`` together (:func:`select_effects`;
    the caller leaves out an airspeed scale judged from the kinematics, which the dynamics
    cannot refit), with
    ``gauss_newton_steps`` re-linearisations about the refit (the residuals after are the
    nonlinear model's).  Returns the refit summary and the residuals after."""
    if not chosen:
        return {"effects": [], "gap_after": dict(before), "shrink_pct": shrink(before, before, lin.n_runs), "estimates": {}}, lin.residual
    effects = tuple(chosen)
    work = lin
    for _ in range(settings.gauss_newton_steps):
        sol = fx.fit_effects(work, effects, library)
        work = fx.relinearise(work, fx.step_values(work, sol))
    sol = fx.fit_effects(work, effects, library)
    after = gap_metrics(work, fx.refit_residual(work, sol), sol, effects, library, groups)
    x = fx.step_values(work, sol)
    estimates = {lin.columns[j]: float(np.mean(x[:, j])) for j in sol.shared}
    return {"effects": list(effects), "gap_after": after, "shrink_pct": shrink(before, after, lin.n_runs),
            "estimates": estimates}, fx.refit_residual(work, sol)


# ----------------------------------------------------------------------------- outputs

def _fmt(x, digits=4) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    if isinstance(x, float):
        return f"{x:.{digits}g}"
    return str(x)


def plot_candidates(entries: list[dict], path: Path, threshold: float) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [c["effect"] for c in entries][::-1]
    vals = [c["delta_elpd"] if c["delta_elpd"] is not None else 0.0 for c in entries][::-1]
    colors = ["tab:green" if c["supported"] else ("tab:orange" if not c["identifiable"] and not c["unavailable"] else "0.6")
              for c in entries][::-1]
    fig, ax = plt.subplots(figsize=(7, 4))
    shown = [np.sign(v) * np.log10(1.0 + abs(v)) for v in vals]
    ax.barh(names, shown, color=colors)
    ax.axvline(np.log10(1.0 + threshold), color="k", ls="--", lw=0.8)
    ax.set_xlabel("sign x log10(1 + |delta_elpd|)  (dashed: support threshold)")
    ax.set_title("candidates (green supported, orange not identifiable here)", fontsize=9)
    ax.tick_params(labelsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def write_diagnosis(diag: Diagnosis, out_dir: str | Path,
                    settings: config.DiagnosisConfig = config.DEFAULT_DIAGNOSIS) -> Path:
    """Write ``diagnosis.json`` (keys ``gap``, ``localisation``, ``candidates``),
    ``refit.json`` (the combined refit), ``report.md`` and its plots into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "diagnosis.json").write_text(json.dumps(diag.result, indent=1))
    (out / "refit.json").write_text(json.dumps(diag.refit, indent=1))
    plot_localisation(diag.result["localisation"], out / "localisation.png", title=f"residuals of {diag.model}")
    plot_residuals(diag.time_s, diag.residual, diag.mask, out / "residuals.png",
                   after=diag.residual_after if diag.refit["effects"] else None, labels=diag.run_ids)
    plot_candidates(diag.candidates, out / "candidates.png", settings.support_delta_elpd)
    gap = diag.result["gap"]
    lines = [f"# Sim-to-real diagnosis: model `{diag.model}`", ""]
    top = diag.top
    ambiguous = [c["effect"] for c in diag.candidates if c.get("ambiguous_with")]
    if top:
        verdict = f"`{top}` is the leading supported effect."
    elif ambiguous:
        verdict = ("the model misses something, but " + ", ".join(f"`{e}`" for e in ambiguous)
                   + f" explain it alike (delta_elpd within {settings.ambiguity_margin:g}): not distinguishable here.")
    else:
        verdict = ("no candidate effect is supported at the stated threshold (delta_elpd >= "
                   f"{settings.support_delta_elpd:g}, identifiable, ahead of the others by {settings.ambiguity_margin:g}).")
    lines += [f"**Verdict**: {verdict} Residual trend {_fmt(gap['trend_rms_mps'])} m/s against a white-noise floor "
              f"of {_fmt(gap['trend_floor_mps'])} m/s.", ""]
    lines += ["## 1. The gap", "", "| metric | value |", "| --- | --- |"]
    lines += [f"| {k} | {_fmt(v)} |" for k, v in gap.items()]
    lines += ["", "![residuals](residuals.png)", "", "## 2. Where", ""]
    loc = diag.result["localisation"]
    lines += ["| variable | eta2 (share of residual variance between bins) |", "| --- | --- |"]
    lines += [f"| {v} | {loc[v]['eta2']:.3f} |" for v in loc["where"]]
    lines += ["", "![localisation](localisation.png)", "", "## 3. Which effect", "",
              "| rank | effect | supported | delta_elpd | delta LOPO lpd | trend shrink % | statement |",
              "| --- | --- | --- | --- | --- | --- | --- |"]
    for c in diag.candidates:
        lines.append(f"| {c['rank']} | `{c['effect']}` | {'yes' if c['supported'] else 'no'} | {_fmt(c['delta_elpd'], 3)} | "
                     f"{_fmt(c.get('delta_lopo_lpd'), 3)} | {_fmt(c['shrink_pct'].get('trend_rms_mps'), 3)} | "
                     f"{c['statement']} |")
    lines += ["", "![candidates](candidates.png)", "", "## 4. How far it shrinks", ""]
    r = diag.refit
    if r["effects"]:
        lines += [f"Refitted with {', '.join('`%s`' % e for e in r['effects'])}; estimates: "
                  + ", ".join(f"{k} = {_fmt(v)}" for k, v in r["estimates"].items()), "",
                  "| metric | before | after | shrink % |", "| --- | --- | --- | --- |"]
        for k in gap:
            lines.append(f"| {k} | {_fmt(gap[k])} | {_fmt(r['gap_after'].get(k))} | {_fmt(r['shrink_pct'].get(k), 3)} |")
    else:
        lines.append("Nothing to refit: no candidate is supported.")
    lines += ["", f"Timings (s): " + ", ".join(f"{k} {v:.1f}" for k, v in diag.timings.items()), ""]
    (out / "report.md").write_text("\n".join(lines))
    return out / "diagnosis.json"


# ----------------------------------------------------------------------------- the proof suite

@dataclass(frozen=True)
class Distorted:
    """A picklable campaign factory distorting another's logged channels or stated vehicle:
    ``airspeed_scale`` x airspeed reading, yaw reading = (true yaw - ``yaw_offset_rad``) /
    ``yaw_factor`` (so true = yaw_factor x reading + offset), stated effective mass x
    ``effective_mass_factor``.  A run whose distorted yaw reading leaves
    ``|yaw| <= config.MAX_LOGGED_YAW_RAD`` ends before that sample, as a simulated run does.
    The truth records the distortion."""

    factory: Callable[[], Campaign]
    airspeed_scale: float = 1.0
    yaw_factor: float = 1.0
    yaw_offset_rad: float = 0.0
    effective_mass_factor: float = 1.0

    def __call__(self) -> Campaign:
        c = self.factory()
        runs = c.runs.copy()
        runs["airspeed_mps"] = runs["airspeed_mps"] * self.airspeed_scale
        runs["yaw_rad"] = (runs["yaw_rad"] - self.yaw_offset_rad) / self.yaw_factor
        over = (runs["yaw_rad"].abs() > config.MAX_LOGGED_YAW_RAD).astype(int)
        runs = runs[over.groupby(runs["run"], sort=False).cummax() == 0].reset_index(drop=True)
        vehicle = dataclasses.replace(c.vehicle, effective_mass_kg=c.vehicle.effective_mass_kg * self.effective_mass_factor)
        truth = dict(c.truth or {}, airspeed_scale=self.airspeed_scale, yaw_factor=self.yaw_factor,
                     yaw_offset_rad=self.yaw_offset_rad, effective_mass_factor=self.effective_mass_factor)
        return dataclasses.replace(c, runs=runs, vehicle=vehicle, truth=truth)


PROOF_CASE = 9
"""The suite's base conditions: thesis case 9 (2 m/s head and cross wind with Dryden
turbulence, table 6.6 measurement noise, the "basic" drag model with lift), which
``three_term`` fits correctly specified but for the input noise."""


PROOF_DESIGNS = ("standard", "identifying")
"""The proof suite's campaign designs (``[proof]`` of ``models/effects/library.toml``)."""


def proof_design(name: str = "identifying", path=fx.LIBRARY_PATH) -> dict[str, Any]:
    """The ``[proof.NAME]`` table of the library ("standard" is case 9 as it is: empty)."""
    import tomllib

    if name not in PROOF_DESIGNS:
        raise ValueError(f"unknown proof design {name!r}: one of {PROOF_DESIGNS}")
    if name == "standard":
        return {}
    doc = tomllib.loads(Path(path).read_text())
    design = dict(doc.get("proof", {}).get(name, {}))
    unknown = set(design) - {"pairs", "head_wind_mps", "cross_wind_mps", "masses_kg", "start_speeds_mps",
                             "size_factor"}
    if unknown:
        raise ValueError(f"{path}: [proof.{name}]: unknown keys {sorted(unknown)}")
    for e in design.get("size_factor", {}):
        if e not in fx.EFFECT_NAMES:
            raise ValueError(f"{path}: [proof.{name}.size_factor]: {e!r} is not an effect of the library")
    return design


def withheld_campaign(effect: str | None, seed: int, pairs: int = 3,
                      design: str = "standard") -> tuple[Callable[[], Campaign], Any]:
    """A campaign factory with ``effect`` present (None: the null control) and the analysis
    model that withholds it (``three_term``; for ``aero_lift`` ``three_term`` without its
    tunnel lift).

    ``design="standard"``: thesis case 9 conditions, ``pairs`` pairs, the effect at a plausible
    size (README, docs/sim_to_real.md): gradient 0.1 %, tyre loss 10 % higher at the start
    decaying over 40 s, airspeed readings 3 % high, the thesis' vane factor 0.869 and a 0.02
    rad offset, the thesis' lift, side-force slip (K_S 2.4, C_y 25 kN/rad) and pitch (K_alpha
    0.9, l_p 0.55 m, k_p 60 kN m/rad), C_t 0.03 N s^2/m^2, tyre X 3e-4 (v / 20 m/s)^4, 2 m/s of
    unrecorded wind change along the track, the cup, vane and admittance dynamics of table 6.5,
    run-to-run offsets of 4 % / 20 % / 4 % (the thesis' track spreads) and an effective mass
    stated 3 % high.  ``design="identifying"``: the campaign of ``[proof.identifying]`` in the
    library (its pairs, winds, test masses and start speeds; ``pairs`` is ignored) with the
    effect ``size_factor`` times the plausible size."""
    from ..inference.spec import load_model_spec
    from ..physics import effects as pe
    from ..physics.terms import Gradient, PitchAttitude
    from ..simulate import SimulationSettings, get_case
    from .batch import SimulatedCampaign
    from .pooling import CombinedCampaign

    plan = proof_design(design)
    f = float(plan.get("size_factor", {}).get(effect, 1.0)) if effect else 1.0
    case = get_case(PROOF_CASE)
    case = dataclasses.replace(case, head_wind_mps=float(plan.get("head_wind_mps", case.head_wind_mps)),
                               cross_wind_mps=float(plan.get("cross_wind_mps", case.cross_wind_mps)))
    settings = SimulationSettings()
    model: Any = "three_term"
    extra = {
        "track_gradient": ((Gradient(),), {"grade_rad": 0.001 * f}),
        "tyre_temperature": ((pe.TyreTemperatureTransient(),), {"tyre_transient": 0.1 * f, "tyre_time_constant_s": 40.0}),
        "side_force_slip": ((pe.SideSlipDrag(),), {"side_slip_coeff_per_n": f * 2.4**2 / (4 * 25_000.0)}),
        "pitch_attitude": ((PitchAttitude(),), {"Kalpha": 0.9 * f, "pitch_gain": 1100.0 * 0.55 / 60e3}),
        "driveline_quadratic": ((pe.DrivelineQuadratic(),), {"Ct": 0.03 * f}),
        "tyre_speed_exponent": ((pe.TyreSpeedPower(),), {"tyre_power_coeff": 3e-4 * f, "tyre_speed_exponent": 4.0}),
        "spatial_wind": ((pe.SpatialWind(),), {"wind_gradient_mps": 2.0 * f}),
    }
    if effect in extra:
        terms, params = extra[effect]
        settings = dataclasses.replace(settings, extra_terms=terms, extra_params=params)
    elif effect == "anemometer_dynamics":
        case = dataclasses.replace(case, dynamics=True)
        s = settings.sensors
        settings = dataclasses.replace(settings, sensors=dataclasses.replace(
            s, cup_distance_constant_m=s.cup_distance_constant_m * f))
    elif effect == "run_to_run_variation":
        case = dataclasses.replace(case, system_noise=True)
        settings = dataclasses.replace(settings, system_noise_mode="per_run",
                                       system_noise_std={"AD": 4e-4 * f, "BD": 4e-5 * f, "CD0": 0.016 * f})
    elif effect == "aero_lift":
        model = dataclasses.replace(load_model_spec("three_term"), name="three_term_no_lift", lift="none")
        full = dict(settings.full_model_params)
        full.update(CL0=full["CL0"] * f, KL=full["KL"] * f)
        settings = dataclasses.replace(settings, full_model_params=full)
    elif effect not in (None, "airspeed_calibration", "yaw_calibration", "mass_error"):
        raise ValueError(f"unknown effect {effect!r}")
    n_pairs = int(plan.get("pairs", pairs))
    masses = tuple(float(m) for m in plan["masses_kg"]) if "masses_kg" in plan else None
    starts = [float(v) for v in plan.get("start_speeds_mps", [settings.start_speed_mps])]
    parts = []
    for i, v0 in enumerate(starts):
        k = n_pairs // len(starts) + (1 if i < n_pairs % len(starts) else 0)
        if k:
            parts.append(SimulatedCampaign(case, pairs=k, seed=seed + 7919 * i,
                                           settings=dataclasses.replace(settings, start_speed_mps=v0),
                                           masses_kg=masses))
    factory: Callable[[], Campaign] = parts[0] if len(parts) == 1 else CombinedCampaign(tuple(parts))
    if effect == "airspeed_calibration":
        factory = Distorted(factory, airspeed_scale=1.0 + 0.03 * f)
    elif effect == "yaw_calibration":
        factory = Distorted(factory, yaw_factor=1.0 - 0.131 * f, yaw_offset_rad=0.02 * f)
    elif effect == "mass_error":
        factory = Distorted(factory, effective_mass_factor=1.0 + 0.03 * f)
    return factory, model


@dataclass(frozen=True)
class DiagnoseJob:
    """A diagnosis for the batch door (:func:`bayes_roadload.analysis.batch.run_batch`):
    ``run()`` builds the campaign, diagnoses it and returns a flat record."""

    name: str
    campaign_factory: Callable[[], Campaign] | Campaign
    model: Any = "three_term"
    tags: Mapping[str, Any] = field(default_factory=dict)

    def run(self) -> dict[str, Any]:
        rec: dict[str, Any] = {"name": self.name, "model": str(getattr(self.model, "name", self.model)), "error": None}
        rec.update(self.tags)
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                campaign = self.campaign_factory if isinstance(self.campaign_factory, Campaign) else self.campaign_factory()
                rec["time_simulate_s"] = time.perf_counter() - t0
                d = diagnose(campaign, self.model)
            rec.update(diagnosis_record(d))
        except Exception as exc:  # noqa: BLE001 - one failed job must not end the batch
            import traceback

            rec["error"] = f"{type(exc).__name__}: {exc}"
            rec["traceback"] = traceback.format_exc(limit=8)
        rec["time_total_s"] = time.perf_counter() - t0
        return rec


def diagnosis_record(d: Diagnosis) -> dict[str, Any]:
    """A flat record of a diagnosis: the top-ranked supported effect (``"none"``), the
    supported and not-identifiable effects, every candidate's delta_elpd, the gap before and
    after the combined refit and its shrink, timings."""
    rec: dict[str, Any] = {"top": d.top or "none",
                           "supported": ",".join(c["effect"] for c in d.candidates if c["supported"]),
                           "not_identifiable": ",".join(c["effect"] for c in d.candidates
                                                        if not c["identifiable"] and not c["unavailable"]),
                           "not_distinguishable": ",".join(c["effect"] for c in d.candidates if c.get("ambiguous_with")),
                           "refit_effects": ",".join(d.refit["effects"])}
    for c in d.candidates:
        rec[f"delta_elpd_{c['effect']}"] = c["delta_elpd"]
        rec[f"delta_lopo_{c['effect']}"] = c.get("delta_lopo_lpd")
    for k, v in d.result["gap"].items():
        rec[f"before_{k}"] = v
    for k, v in d.refit["gap_after"].items():
        rec[f"after_{k}"] = v
    for k, v in d.refit["shrink_pct"].items():
        rec[f"shrink_{k}"] = v
    top = d.candidates[0] if d.candidates else None
    if top is not None:
        for k, v in top["shrink_pct"].items():
            rec[f"top_shrink_{k}"] = v
    rec.update({f"time_{k}": v for k, v in d.timings.items()})
    return rec


def withheld_effect_jobs(effects=fx.EFFECT_NAMES, seeds=(1,), pairs: int = 3, nulls: int = 0,
                         design: str = "standard") -> list[DiagnoseJob]:
    """The proof suite: one job per (effect, seed) and ``nulls`` null controls (seeds 1000+),
    ordered seed by seed with the nulls spread over the rounds, so that a suite stopped early
    has every arm about equally often; campaigns of ``design`` (:func:`withheld_campaign`)."""
    jobs = []
    per_round = -(-nulls // max(len(seeds), 1)) if nulls else 0
    made = 0
    for seed in seeds:
        for effect in effects:
            factory, model = withheld_campaign(effect, seed, pairs, design)
            jobs.append(DiagnoseJob(f"{effect}-s{seed}", factory, model,
                                    tags={"true_effect": effect, "seed": seed, "pairs": pairs, "design": design}))
        for _ in range(min(per_round, nulls - made)):
            factory, model = withheld_campaign(None, 1000 + made, pairs, design)
            jobs.append(DiagnoseJob(f"null-s{1000 + made}", factory, model,
                                    tags={"true_effect": "null", "seed": 1000 + made, "pairs": pairs,
                                          "design": design}))
            made += 1
    return jobs
