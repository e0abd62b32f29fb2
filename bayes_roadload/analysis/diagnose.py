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
``candidates``), ``report.md`` and its plots.  The proof suite that checks the method on
campaigns simulated with a known effect is a study outside the package (``studies/proof_suite.py``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .. import config
from ..data.campaign import Campaign
from . import effects as fx
from .gap import input_resolution, localise, plot_localisation, plot_residuals, residual_structure

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
    if any(library[e].run_coefficients for e in effects if e in library):
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


def _cause_of(library, name: str) -> str:
    """The physical effect candidate ``name`` stands for (:attr:`.effects.Effect.cause`)."""
    return library[name].cause if name in library else name


def select_effects(lin: fx.Linearisation, entries: list[dict], library, settings: config.DiagnosisConfig) -> list[str]:
    """Decide which candidates are supported (sets ``supported`` in ``entries``) and return them
    in order.  A candidate *qualifies* when it is identifiable here and its own delta_elpd
    reaches ``support_delta_elpd``.  The best qualifying candidate is claimed only when it
    beats every other candidate (qualifying or not) by ``ambiguity_margin``; otherwise the
    candidates within the margin explain the gap alike and none is supported ("not
    distinguishable here"); likewise a rival reaching support with nearly the same signature
    (``min_distinct_share``, VIF rule) and any rival explaining part of the gap, at least
    ``min_rival_share`` of the best's gain, that the best does not beat run by run
    (``min_vuong_z``, Vuong's test; not asked of a run-level best, whose gain lies by
    construction in the runs that differ most).  After the claimed one, the other
    qualifying candidates join by forward selection, each when it still gains
    ``support_delta_elpd`` given those already in (at most ``max_refit_effects``).  Forms of
    one cause (:attr:`.effects.Effect.cause`) are not each other's rivals.  The
    airspeed scale adds the paired-run kinematics (independent data) to its dynamics, less
    their disagreement (:func:`.effects.kinematic_conflict`), also in the forward selection."""
    scored = [c for c in entries if math.isfinite(c["delta_elpd"])]
    qualifying = sorted((c for c in scored if c["qualifies"]), key=lambda c: -c["delta_elpd"])
    for c in entries:
        c["supported"] = False
    if not qualifying:
        return []
    best = qualifying[0]
    cause = _cause_of(library, best["effect"])
    # forms of the best's own cause name the same effect: they are not its rivals
    others = [c for c in scored if c is not best and _cause_of(library, c["effect"]) != cause]
    rivals = [c for c in others if c["delta_elpd"] > best["delta_elpd"] - settings.ambiguity_margin]
    if not best.get("kinematics"):
        for c in others:
            if c in rivals or c.get("kinematics") or c["delta_elpd"] <= 0.0:
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
            # the runs that differ most, and runs that happen to match the mean gain nothing;
            # nor against a rival that explains too little of the gap to be another
            # explanation of it (below min_rival_share of the best's gain)
            if best["effect"] in library and library[best["effect"]].per_run:
                continue
            if c["delta_elpd"] < settings.min_rival_share * best["delta_elpd"]:
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


def _plan_hint(effect: fx.Effect) -> str:
    """Where `plan` scores the test that would identify ``effect``."""
    if effect.per_run:
        return " (`plan` counts the pairs)"
    return f" (`plan --identify {effect.name} --design ...` scores such a test)"


def _shape_text(entry: dict) -> str:
    """``; shape P = v`` for a family's profiled shape (empty otherwise)."""
    values = (entry.get("shape") or {}).get("values", {})
    return "; shape " + ", ".join(f"{p} = {v:.3g}" for p, v in values.items()) if values else ""


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
    if entry.get("against_sign"):
        what = ", ".join(f"{p} {v:.3g}" for p, v in entry["against_sign"].items())
        return (f"not supported: estimated with a sign no {effect.name} has ({what}); scored at its constrained "
                f"optimum, no effect")
    if entry["supported"]:
        how = " (from the paired-run kinematics)" if kin else ""
        given = entry.get("delta_elpd_given_supported")
        extra = f", {given:.1f} given the effects ranked above it" if given is not None else ""
        form = f" (a form of {effect.cause})" if effect.cause != effect.name else ""
        return (f"supported{how}{form}: delta_elpd {entry['delta_elpd']:.1f} >= {cfg.support_delta_elpd:g}{extra}"
                f"{_shape_text(entry)}")
    if entry.get("qualifies"):
        given = entry.get("delta_elpd_given_supported")
        return (f"not supported: explained by the effects ranked above it" +
                (f" (delta_elpd {given:.1f} given them)" if given is not None else ""))
    if entry.get("unresolved"):
        what = "; ".join(f"{ch} lag-1 autocorrelation {ac:.2f} < {cfg.min_input_lag1:g}" for ch, ac in entry["unresolved"].items())
        return (f"not identifiable here (the reading does not resolve the fluctuations this effect's signature reads: "
                f"{what}; each sample stands for a stretch of the run it does not measure), needs the anemometer "
                f"logged fast enough to follow the gusts, or {effect.needs}")
    if not entry["identifiable"]:
        what = ", ".join(effect.confounded_with) or "the model's coefficients"
        worst = min(entry["identification"].items(), key=lambda kv: kv[1]["contraction"])
        return (f"not identifiable here ({worst[0]}: the data shrink its prior by {100 * worst[1]['contraction']:.0f} %, "
                f"{100 * (1 - worst[1]['information_ratio']):.1f} % of its signature is that of {what}), "
                f"needs {effect.needs}{_plan_hint(effect)}")
    sizes = ", ".join(f"|{p} - null| >= {v['detectable']:.3g}" for p, v in entry["identification"].items()
                      if math.isfinite(v.get("detectable", math.inf)))
    seen = f"; this campaign would support it at {sizes}" if sizes else ""
    return (f"not supported: delta_elpd {entry['delta_elpd']:.1f} < {cfg.support_delta_elpd:g}{_shape_text(entry)}{seen}; smaller "
            f"effects need {effect.needs}{_plan_hint(effect)}")


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


DIAGNOSIS_CONTRACT = 6
"""Version of ``diagnosis.json``'s contract: the keys ``gap``, ``localisation``, ``inputs`` (each
logged anemometer channel's :func:`.gap.input_resolution`, null when not logged),
``candidates`` (each candidate with :data:`CANDIDATE_KEYS`), ``contract`` (this number) and
``rules`` (:func:`rules_fingerprint`).  Raised whenever a key is added or its meaning changes,
so a committed diagnosis older than the code is detected."""

CANDIDATE_KEYS = ("effect", "rank", "supported", "qualifies", "delta_elpd", "gap_before", "gap_after", "shrink_pct",
                  "identifiable", "identification", "estimates", "against_sign", "unavailable", "needs", "statement",
                  "shape", "unresolved", "cause")
"""The keys every candidate entry of ``diagnosis.json`` carries (``against_sign``: the
estimates whose sign no physical value of the effect has, :meth:`.effects.Effect.against_sign`;
empty when none; ``shape``: for a family, its profiled shape and the gain at every grid point,
:func:`.effects.fit_shapes`, else empty; ``unresolved``: the channels of its ``resolved_inputs``
whose reading does not follow the gusts, with their lag-1 autocorrelation, empty when none;
``cause``: the physical effect the candidate is a form of, :attr:`.effects.Effect.cause`)."""


def _sha256_json(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


def rules_fingerprint(library: Mapping[str, fx.Effect],
                      settings: config.DiagnosisConfig = config.DEFAULT_DIAGNOSIS) -> dict[str, Any]:
    """The frozen rules a diagnosis ran under: SHA-256 of the candidate library (each effect's
    terms, priors, fixed constants, as read from ``models/effects/library.toml``) and of the
    thresholds (:class:`~bayes_roadload.config.DiagnosisConfig`), both as sorted JSON, with
    the thresholds themselves.  A study records it before its confirmatory seeds run; a
    committed report whose fingerprint differs from the code's was made under other rules."""
    # options an effect leaves unused (no shape grid, not each-run, no resolved inputs) are not
    # hashed: declaring them changes the fingerprint, their existence does not
    lib = {name: {k: v for k, v in dataclasses.asdict(e).items()
                  if not (k in ("shape", "each_run", "resolved_inputs", "form_of") and not v)}
           for name, e in sorted(library.items())}
    thresholds = dataclasses.asdict(settings)
    return {"library_sha256": _sha256_json(lib), "thresholds_sha256": _sha256_json(thresholds),
            "thresholds": thresholds}


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
    lin = fx.linearise(problem, fit.constrained, library, problem.spec.resolve_admittance(campaign))
    timings["linearise_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    lin, shapes = fx.fit_shapes(lin, library)
    timings["shapes_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    groups = _pair_groups(campaign, problem.run_ids)
    base_sol = fx.fit_effects(lin, (), library)
    before = gap_metrics(lin, lin.residual, None, (), library, groups)
    loc = localise(lin.residual, np.asarray(lin.batch.mask), _variables(lin))
    channels = lin.batch._asdict()
    resolution = {ch: input_resolution(lin.batch.time_s, channels[ch], lin.batch.mask) for ch in fx.RESOLVABLE_INPUTS}

    entries = []
    for name in fx.EFFECT_NAMES:
        e = library.get(name)
        if e is None:
            continue
        entry: dict[str, Any] = {"effect": name, "rank": None, "supported": False, "qualifies": False,
                                 "delta_elpd": math.nan,
                                 "gap_before": before, "gap_after": {}, "shrink_pct": {},
                                 "identifiable": False, "identification": {}, "estimates": {}, "against_sign": {},
                                 "unavailable": lin.available.get(name), "shape": shapes.get(name, {}),
                                 "unresolved": {ch: resolution[ch]["lag1_autocorr"] for ch in e.resolved_inputs
                                                if resolution.get(ch) is not None
                                                and resolution[ch]["lag1_autocorr"] < settings.min_input_lag1}}
        if entry["unavailable"] is None and name in lin.effects:
            sol = fx.fit_effects(lin, (name,), library)
            k = fx.n_added_parameters(lin, (name,), library)
            delta = sol.loglik_gain - base_sol.loglik_gain - k
            # each run's share of the gain, less the added parameters spread over the runs
            entry["run_gains"] = [fx.run_loglik_gain(sol, i) - fx.run_loglik_gain(base_sol, i) - k / lin.n_runs
                                  for i in range(lin.n_runs)]
            ident = fx.identifiability(lin, name, library, settings.support_delta_elpd)
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
            against = e.against_sign(entry["estimates"])
            if against:
                # the constrained optimum of a one-parameter Gaussian score is the null
                delta = -float(k)
                entry["run_gains"] = [-k / lin.n_runs] * lin.n_runs
                entry["against_sign"] = against
                sol = base_sol
            entry["delta_elpd"] = float(delta)
            # a reading that does not resolve the fluctuations the signature reads cannot tell
            # the effect from what its sampling does to the fit (DiagnosisConfig.min_input_lag1)
            identifiable = identifiable and not entry["unresolved"]
            entry["identifiable"] = identifiable
            entry["qualifies"] = bool(identifiable and delta >= settings.support_delta_elpd)
            after = gap_metrics(lin, fx.refit_residual(lin, sol), sol, () if against else (name,), library, groups)
            entry["gap_after"] = after
            if math.isfinite(before["lopo_lpd_per_sample"]):
                # the same comparison out of sample: leave-one-pair-out log predictive density gain
                entry["delta_lopo_lpd"] = (after["lopo_lpd_per_sample"] - before["lopo_lpd_per_sample"]) * lin.n_samples
            entry["shrink_pct"] = shrink(before, after, lin.n_runs)
        entry["needs"] = e.needs
        entry["cause"] = e.cause
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
    result = {"gap": before, "localisation": loc, "inputs": resolution, "candidates": entries, "contract": DIAGNOSIS_CONTRACT,
              "rules": rules_fingerprint(library, settings)}
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
    """Write ``diagnosis.json`` (keys ``gap``, ``localisation``, ``inputs``, ``candidates``,
    ``contract``, ``rules``: :data:`DIAGNOSIS_CONTRACT`),
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
    causes = {c["effect"]: c["cause"] for c in diag.candidates}
    if top:
        form = f" (a form of `{causes[top]}`)" if causes[top] != top else ""
        verdict = f"`{top}`{form} is the leading supported effect."
    elif ambiguous:
        verdict = ("the model misses something, but " + ", ".join(f"`{e}`" for e in ambiguous)
                   + f" explain it alike (within {settings.ambiguity_margin:g} of the best's delta_elpd, the same "
                   "signature, or the best not ahead run by run; section 3 says which): not distinguishable here.")
    else:
        verdict = ("no candidate effect is supported at the stated threshold (delta_elpd >= "
                   f"{settings.support_delta_elpd:g}, identifiable, ahead of the others by {settings.ambiguity_margin:g}).")
    lines += [f"**Verdict**: {verdict} Residual trend {_fmt(gap['trend_rms_mps'])} m/s against a white-noise floor "
              f"of {_fmt(gap['trend_floor_mps'])} m/s.", ""]
    lines += ["## 1. The gap", "", "| metric | value |", "| --- | --- |"]
    lines += [f"| {k} | {_fmt(v)} |" for k, v in gap.items()]
    inputs = {ch: v for ch, v in (diag.result.get("inputs") or {}).items() if v}
    if inputs:
        lines += ["", "Anemometer readings (how well the samples follow the gusts: lag-1 autocorrelation of the "
                  "deviation from a 20 s moving average; below "
                  f"{settings.min_input_lag1:g} the yaw-term candidates are not identifiable here):", "",
                  "| reading | sample rate (Hz) | lag-1 autocorrelation |", "| --- | --- | --- |"]
        lines += [f"| {ch} | {_fmt(v['sample_rate_hz'], 3)} | {_fmt(v['lag1_autocorr'], 3)} |" for ch, v in inputs.items()]
    lines += ["", "![residuals](residuals.png)", "", "## 2. Where", ""]
    loc = diag.result["localisation"]
    lines += ["| variable | eta2 (share of residual variance between bins) |", "| --- | --- |"]
    lines += [f"| {v} | {loc[v]['eta2']:.3f} |" for v in loc["where"]]
    lines += ["", "![localisation](localisation.png)", "", "## 3. Which effect", "",
              "| rank | effect | supported | delta_elpd | delta LOPO lpd | trend shrink % | statement |",
              "| --- | --- | --- | --- | --- | --- | --- |"]
    for c in diag.candidates:
        name = f"`{c['effect']}`" + (f" (form of `{c['cause']}`)" if c["cause"] != c["effect"] else "")
        lines.append(f"| {c['rank']} | {name} | {'yes' if c['supported'] else 'no'} | {_fmt(c['delta_elpd'], 3)} | "
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
    rules = diag.result["rules"]
    lines += ["", f"Rules: contract {diag.result['contract']}, candidate library sha256 "
              f"`{rules['library_sha256'][:16]}`, thresholds sha256 `{rules['thresholds_sha256'][:16]}` "
              "(diagnosis.json `rules`).", "",
              f"Timings (s): " + ", ".join(f"{k} {v:.1f}" for k, v in diag.timings.items()), ""]
    (out / "report.md").write_text("\n".join(lines))
    return out / "diagnosis.json"
