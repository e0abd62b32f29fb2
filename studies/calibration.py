"""Anemometer calibration: what a wrong airspeed factor does to C_D0 and K_D, and its recovery
(thesis sections 4.7.3 and 6.6).

The on-board cup anemometer reads the relative airspeed; true = ``airspeed_factor`` x reading
(:class:`~bayes_roadload.data.Anemometer`).  The aerodynamic force goes as
C_D0 (factor x reading)^2, so a reading 1 % high with the factor fixed at its old value makes
the fit's C_D0 ~2 % low, and K_D too in the 4-term analysis (thesis 6.6: "a 1 % error in the
relative airspeed measurement resulted in a 2 % error in CD0").  The thesis calibrated the
factor at the track from the opposite-direction pairs (section 4.7.3, table 4.1: group
factors 1.0719-1.0903, std 0.0063 over groups of 3 pairs); the Bayesian models
``models/*_calibrated.toml`` estimate it jointly with the coefficients from the same pairs
(:func:`bayes_roadload.inference.bayes.airspeed_pair_ratios`).

:class:`AirspeedScaled` makes a campaign whose airspeed readings are off by a known factor;
:func:`calibration_study` compares, through the batch door
(:func:`~bayes_roadload.analysis.batch.run_batch`) and the classical per-pair least squares:

``lsq_pair``
    the thesis' per-pair 3-term / 4-term least squares with the campaign's factor (wrong),
    weighted mean over pairs (eq. 5.15, 5.16);
``lsq_pair_calibrated``
    the same with the factor fixed at the mean of the campaign's own pair ratios (the thesis'
    practice: calibrate, then analyse);
``nuts_fixed``
    NUTS ``three_term`` / ``four_term`` with the factor fixed (wrong);
``nuts_calibrated``
    NUTS ``three_term_calibrated`` / ``four_term_calibrated``: the factor estimated with the
    coefficients, calibrated by the pair ratios.

:func:`markdown` turns the study's table into the validation report's section.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Sequence

import numpy as np
import pandas as pd
from scipy import stats

from bayes_roadload import config
from bayes_roadload.analysis.batch import FitJob, SimulatedCampaign, quantile_key, run_batch, successful
from bayes_roadload.data.campaign import Anemometer, Campaign
from bayes_roadload.inference.bayes import airspeed_pair_ratios, calibration_pairs
from bayes_roadload.inference.lsq import Z95, fit_lsq
from bayes_roadload.inference.spec import load_model_spec

LEVEL = 0.95
"""Central interval level of the study's intervals and in-interval flags."""

ANALYSES = ("lsq_pair", "lsq_pair_calibrated", "nuts_fixed", "nuts_calibrated")
"""The arms of :func:`calibration_study` (module docstring)."""

STUDY_COLUMNS = ("analysis", "model", "scale", "seed", "case", "pairs",
                 "CD0_estimate", "CD0_low", "CD0_high", "CD0_truth", "CD0_error_pct", "CD0_in_interval",
                 "KD_estimate", "KD_low", "KD_high", "KD_truth", "KD_error_pct", "KD_in_interval",
                 "airspeed_factor_estimate", "airspeed_factor_low", "airspeed_factor_high",
                 "airspeed_factor_truth", "airspeed_factor_error_pct", "airspeed_factor_in_interval",
                 "gate_pass", "gates_failed", "error")
"""Columns of :func:`calibration_study`'s table.  ``X_low``, ``X_high``: the central 95 %
interval (posterior quantiles for NUTS; estimate -+ 1.96 SE for least squares, the factor's
from the pair ratios with Student-t quantiles); ``X_error_pct`` = 100 (estimate / truth - 1);
``X_in_interval``: the truth lies in the interval (None when not estimated).  A parameter the
analysis fixes has its fixed value as estimate (and error against the truth) but no interval.
``gate_pass``, ``gates_failed``: the NUTS fit passed its diagnostic gates, the ones it failed
(None for least squares); ``error``: why a fit failed (None on success)."""


# --------------------------------------------------------------------------- the campaigns

@dataclass(frozen=True)
class AirspeedScaled:
    """A picklable campaign factory whose logged airspeed readings are ``scale`` x those of
    another factory's campaign (an anemometer reading ``scale - 1`` too high).

    Everything else is kept: the other channels, the vehicle and its ``[anemometer]`` factors
    (so an analysis that fixes the factor now uses a wrong one), the tunnel table, the truth
    and the meta.  The truth gains ``airspeed_factor`` = old true factor / ``scale`` (the old
    true factor is the truth's ``airspeed_factor`` when given, else the campaign's
    ``[anemometer]`` factor: a simulated campaign logs the true relative airspeed, factor 1);
    the meta gains ``airspeed_scale`` (multiplied into an existing one).

    Parameters
    ----------
    factory : callable or Campaign
        A zero-argument callable returning a campaign (e.g.
        :class:`~bayes_roadload.analysis.batch.SimulatedCampaign`), or a campaign.
    scale : float
        Factor applied to ``airspeed_mps`` (e.g. 1.01: readings 1 % high).
    """

    factory: Callable[[], Campaign] | Campaign
    scale: float

    def __post_init__(self):
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"scale must be a positive number, not {self.scale!r}")

    def __call__(self) -> Campaign:
        base = self.factory if isinstance(self.factory, Campaign) else self.factory()
        if "airspeed_mps" not in base.runs:
            raise ValueError("AirspeedScaled: the campaign logs no airspeed_mps to scale")
        runs = base.runs.copy()
        runs["airspeed_mps"] = runs["airspeed_mps"] * self.scale
        truth = None
        if base.truth is not None:
            truth = dict(base.truth)
            true_factor = truth.get("airspeed_factor", base.anemometer.airspeed_factor)
            truth["airspeed_factor"] = float(true_factor) / self.scale
        meta = dict(base.meta)
        meta["airspeed_scale"] = float(meta.get("airspeed_scale", 1.0)) * self.scale
        return Campaign(runs, base.vehicle, base.anemometer, base.tunnel, truth, meta)


def pair_calibration(campaign: Campaign) -> pd.DataFrame:
    """The track calibration of the airspeed factor from the campaign's opposite-direction pairs
    (thesis section 4.7.3, table 4.1).

    Returns
    -------
    pandas.DataFrame
        One row per pair (``pair`` column; :func:`~bayes_roadload.inference.bayes.
        calibration_pairs`): ``runs``, ``ratio`` (the estimate of the factor used by the
        Bayesian models, :func:`~bayes_roadload.inference.bayes.airspeed_pair_ratios`, with the
        campaign's ``yaw_factor``), ``ratio_plain`` (the thesis' mean ground speed / mean
        airspeed reading, without the yaw cosine: biased high in reading, low in factor,
        under cross-wind), ``mean_yaw_rad`` (of the calibrated yaw over the pair's samples).
    """

    if not campaign.has_anemometer:
        raise ValueError("pair_calibration: the campaign logs no airspeed_mps / yaw_rad")
    batch, run_ids = campaign.to_batch()
    pairs = calibration_pairs(campaign, run_ids)
    cols = ["runs", "ratio", "ratio_plain", "mean_yaw_rad"]
    if not pairs:
        return pd.DataFrame(columns=cols)
    yaw_factor = campaign.anemometer.yaw_factor
    ratio = np.asarray(airspeed_pair_ratios(batch, pairs, yaw_factor))
    plain = np.asarray(airspeed_pair_ratios(batch, pairs, 0.0))  # cos(0) = 1: the plain ratio
    mask = np.asarray(batch.mask)
    yaw = np.asarray(batch.yaw_rad) * yaw_factor
    rows = []
    for (i, j), r, rp in zip(pairs, ratio, plain):
        m = mask[[i, j]]
        rows.append({"runs": f"{run_ids[i]}+{run_ids[j]}", "ratio": float(r), "ratio_plain": float(rp),
                     "mean_yaw_rad": float(yaw[[i, j]][m].mean())})
    return pd.DataFrame(rows, columns=cols)


# --------------------------------------------------------------------------- the study

def _row(analysis: str, model: str, scale: float, seed: int, case: Any, pairs: int) -> dict[str, Any]:
    row: dict[str, Any] = {c: math.nan for c in STUDY_COLUMNS}
    row.update(analysis=analysis, model=model, scale=float(scale), seed=int(seed), case=getattr(case, "number", case),
               pairs=int(pairs),
               gate_pass=None, gates_failed=None, error=None)
    for name in ("CD0", "KD", "airspeed_factor"):
        row[f"{name}_in_interval"] = None
    return row


def _fill(row: dict[str, Any], name: str, estimate: float, low: float, high: float, truth: float | None) -> None:
    t = math.nan if truth is None else float(truth)
    row[f"{name}_estimate"], row[f"{name}_low"], row[f"{name}_high"] = float(estimate), float(low), float(high)
    row[f"{name}_truth"] = t
    row[f"{name}_error_pct"] = 100.0 * (float(estimate) / t - 1.0) if math.isfinite(t) and t != 0 else math.nan
    known = math.isfinite(t) and math.isfinite(low) and math.isfinite(high)
    row[f"{name}_in_interval"] = bool(low <= t <= high) if known else None


def _fill_fixed(row: dict[str, Any], campaign: Campaign, model: str, free: Sequence[str]) -> None:
    """Estimate columns of the parameters ``model`` fixes: their fixed values on ``campaign``
    (no interval), against the campaign's truth."""

    _, fixed, _ = load_model_spec(model).build(campaign)
    truth = campaign.truth or {}
    for name in ("CD0", "KD", "airspeed_factor"):
        if name not in free and name in fixed:
            _fill(row, name, fixed[name], math.nan, math.nan, truth.get(name))


def _lsq_rows(campaign: Campaign, models: Sequence[str], seed: int, scale: float, case: Any,
              pairs: int) -> list[dict[str, Any]]:
    """The classical arms on one campaign: per-pair least squares with the campaign's factor
    and with the factor from the campaign's own pair ratios."""

    truth = campaign.truth or {}
    true_factor = truth.get("airspeed_factor")
    cal = pair_calibration(campaign)
    k = len(cal)
    factor = float(cal["ratio"].mean()) if k else math.nan
    half = (stats.t.ppf(0.5 + LEVEL / 2, k - 1) * cal["ratio"].std(ddof=1) / math.sqrt(k)) if k > 1 else math.nan
    calibrated = Campaign(campaign.runs, campaign.vehicle,
                          Anemometer(factor, campaign.anemometer.yaw_factor) if k else campaign.anemometer,
                          campaign.tunnel, campaign.truth, dict(campaign.meta))
    rows = []
    for analysis, camp in (("lsq_pair", campaign), ("lsq_pair_calibrated", calibrated)):
        for model in models:
            row = _row(analysis, model, scale, seed, case, pairs)
            try:
                if analysis == "lsq_pair_calibrated" and not k:
                    raise ValueError("no opposite-direction pairs to calibrate the airspeed factor")
                spec = load_model_spec(model)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)
                    res = fit_lsq(camp, spec, grouping="pair")
                _fill_fixed(row, camp, model, res.free)
                for name in ("CD0", "KD"):
                    if name in res.free:
                        m, s = res.weighted_mean[name], res.weighted_se[name]
                        _fill(row, name, m, m - Z95 * s, m + Z95 * s, truth.get(name))
                if analysis == "lsq_pair_calibrated":
                    _fill(row, "airspeed_factor", factor, factor - half, factor + half, true_factor)
            except Exception as exc:  # noqa: BLE001 - one failed fit must not end the study
                row["error"] = f"{type(exc).__name__}: {exc}"
            rows.append(row)
    return rows


def _nuts_row(rec: dict[str, Any], campaign: Campaign, case: Any, pairs: int) -> dict[str, Any]:
    row = _row(rec["analysis"], rec["model"], rec["scale"], rec["seed"], case, pairs)
    row["error"] = rec.get("error")
    if row["error"] is not None and not (isinstance(row["error"], float) and math.isnan(row["error"])):
        return row
    row["error"] = None
    row["gate_pass"] = bool(rec["gate_pass"])
    row["gates_failed"] = str(rec.get("gates_failed") or "")
    lo, hi = quantile_key((1.0 - LEVEL) / 2.0), quantile_key((1.0 + LEVEL) / 2.0)
    free = str(rec.get("parameters", "")).split(",")
    _fill_fixed(row, campaign, rec["model"], free)
    for name in ("CD0", "KD", "airspeed_factor"):
        if name in free:
            truth = rec.get(f"{name}_truth")
            truth = None if truth is None or (isinstance(truth, float) and math.isnan(truth)) else truth
            _fill(row, name, rec[f"{name}_mean"], rec[f"{name}_{lo}"], rec[f"{name}_{hi}"], truth)
    return row


def calibration_study(case: int = 15, pairs: int = 3, seeds: Iterable[int] = range(5),
                      scale: float | Sequence[float] = 1.01, executor: Any | None = None, *,
                      models: Sequence[str] = ("three_term", "four_term"),
                      analyses: Sequence[str] = ANALYSES,
                      sampler: config.SamplerConfig = config.DEFAULT_SAMPLER) -> pd.DataFrame:
    """Compare analyses of campaigns whose airspeed readings are ``scale`` x the truth.

    Parameters
    ----------
    case : int
        Thesis simulation case (table 6.7); 15 is the thesis' 6.6 reference (combined effects,
        2 m/s head and cross wind, instrument dynamics, measurement and system noise).
    pairs : int
        Opposite-direction pairs per campaign.
    seeds : iterable of int
        One simulated campaign per seed (common to every scale and analysis).
    scale : float or sequence of float
        Reading scale(s); include 1.0 for the control (the analysis model's own error on the
        case, e.g. the unmodelled pitch attitude of the "comp" cases).
    executor : object with ``map``, optional
        Passed to :func:`~bayes_roadload.analysis.batch.run_batch` for the NUTS fits (None:
        sequential in this process).  The least-squares arms run in this process.
    models : the fixed-factor model variants; the NUTS calibrated arm uses ``{model}_calibrated``.
    analyses : the arms to run (subset of :data:`ANALYSES`).
    sampler : NUTS settings of every fit.

    Returns
    -------
    pandas.DataFrame
        One row per analysis, model, scale and seed, columns :data:`STUDY_COLUMNS`.
    """
    unknown = set(analyses) - set(ANALYSES)
    if unknown:
        raise ValueError(f"unknown analyses {sorted(unknown)}; choose from {ANALYSES}")
    scales = [float(scale)] if np.isscalar(scale) else [float(s) for s in scale]
    seeds = [int(s) for s in seeds]
    rows: list[dict[str, Any]] = []
    campaigns: dict[tuple[float, int], Campaign] = {}
    for seed in seeds:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # |yaw| cut-offs: the runs are shorter, that is all
            base = SimulatedCampaign(case, pairs=pairs, seed=seed)()
        for s in scales:
            campaigns[s, seed] = AirspeedScaled(base, s)()
            if {"lsq_pair", "lsq_pair_calibrated"} & set(analyses):
                rows += [r for r in _lsq_rows(campaigns[s, seed], models, seed, s, case, pairs)
                         if r["analysis"] in analyses]
    jobs = []
    for s in scales:
        for seed in seeds:
            factory = AirspeedScaled(SimulatedCampaign(case, pairs=pairs, seed=seed), s)
            for analysis in ("nuts_fixed", "nuts_calibrated"):
                if analysis not in analyses:
                    continue
                for model in models:
                    name = model if analysis == "nuts_fixed" else f"{model}_calibrated"
                    jobs.append(FitJob(f"{analysis}-{name}-scale{s:g}-seed{seed}", factory, model=name,
                                       sampler=sampler, levels=(LEVEL,),
                                       tags={"analysis": analysis, "scale": s, "seed": seed}))
    if jobs:
        records = run_batch(jobs, executor=executor)
        rows += [_nuts_row(rec, campaigns[rec["scale"], rec["seed"]], case, pairs)
                 for rec in records.to_dict("records")]
    df = pd.DataFrame(rows, columns=list(STUDY_COLUMNS))
    order = {a: i for i, a in enumerate(ANALYSES)}
    return df.sort_values(["analysis", "model", "scale", "seed"], key=lambda c: c.map(order) if c.name == "analysis"
                          else c, kind="stable").reset_index(drop=True)


# --------------------------------------------------------------------------- the report

def _fmt(x: float, digits: int = 2) -> str:
    """``x`` with its sign at ``digits`` decimals; a value that rounds to zero is "+0.00", never "-0.00"."""
    return "-" if x is None or not math.isfinite(x) else f"{round(x, digits) + 0.0:+.{digits}f}"


def _estimated(g: pd.DataFrame, name: str) -> bool:
    """The analysis estimates ``name`` (it has an interval), rather than fixing it."""
    return bool(g[f"{name}_low"].astype(float).notna().any())


def _share(flags: pd.Series) -> str:
    known = flags.dropna()
    return "-" if known.empty else f"{int(known.astype(bool).sum())}/{len(known)}"


def markdown(df: pd.DataFrame) -> str:
    """The study's table as a markdown section for the validation report.

    One line per analysis, model and scale: the number of campaigns, the mean and standard
    deviation over seeds of the C_D0 and K_D errors (%), the mean estimated airspeed factor
    against its truth, how many 95 % intervals hold the truth (C_D0, K_D, factor) and how many
    NUTS fits passed their gates.  When the table holds scale 1.0 too, the change of the C_D0
    and K_D estimates per +1 % reading error is given relative to the same analysis of the same
    seed at scale 1 (the thesis 6.6 figure: -2 %).
    """
    ok = successful(df)
    lines = [
        "| analysis | model | reading scale | n | CD0 error % (mean +- sd) | KD error % (mean +- sd) | "
        "factor estimate (truth) | CD0 in 95 % | KD in 95 % | factor in 95 % | gates passed |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (analysis, model, scale), g in ok.groupby(["analysis", "model", "scale"], sort=False):
        cd0, kd = g["CD0_error_pct"].astype(float), g["KD_error_pct"].astype(float)
        factor, truth = g["airspeed_factor_estimate"].astype(float), g["airspeed_factor_truth"].astype(float)
        gates = g["gate_pass"].dropna()
        sd = (lambda x: f"{abs(x.std(ddof=1)):.2f}" if len(x) > 1 else "-")
        lines.append(
            f"| {analysis} | {model} | {scale:g} | {len(g)} | {_fmt(cd0.mean())} +- {sd(cd0)} | "
            + (f"{_fmt(kd.mean())} +- {sd(kd)}" if _estimated(g, "KD") else "fixed")
            + f" | {factor.mean():.4f}{'' if _estimated(g, 'airspeed_factor') else ' fixed'} ({truth.mean():.4f}) | {_share(g['CD0_in_interval'])} | "
            f"{_share(g['KD_in_interval'])} | {_share(g['airspeed_factor_in_interval'])} | "
            f"{'-' if gates.empty else f'{int(gates.astype(bool).sum())}/{len(gates)}'} |")
    out = ["Readings scaled by the factor shown (true airspeed = truth x reading); errors are "
           "100 (estimate / truth - 1) against the nominal coefficients of the case.", "", *lines]
    control = ok[ok["scale"] == 1.0]
    sens = []
    if not control.empty:
        keys = ["analysis", "model", "seed"]
        merged = ok[ok["scale"] != 1.0].merge(control[keys + ["CD0_estimate", "KD_estimate"]], on=keys,
                                               suffixes=("", "_control"))
        for (analysis, model, scale), g in merged.groupby(["analysis", "model", "scale"], sort=False):
            per = 100.0 * (scale - 1.0)
            d_cd0 = 100.0 * (g["CD0_estimate"] / g["CD0_estimate_control"] - 1.0) / per
            d_kd = 100.0 * (g["KD_estimate"] / g["KD_estimate_control"] - 1.0) / per
            sd = (lambda x: f"{abs(x.std(ddof=1)):.2f}" if len(x) > 1 else "-")
            sens.append(f"| {analysis} | {model} | {scale:g} | {len(g)} | {_fmt(d_cd0.mean())} +- {sd(d_cd0)} | "
                        + (f"{_fmt(d_kd.mean())} +- {sd(d_kd)}" if _estimated(g, "KD") else "fixed") + " |")
    if sens:
        out += ["", "Change of the estimate per +1 % reading error, relative to the same analysis of the same "
                "seed at scale 1 (thesis 6.6: -2 % in CD0, and in KD for the 4-term analysis):", "",
                "| analysis | model | reading scale | n | CD0 % per 1 % | KD % per 1 % |", "|---|---|---|---|---|---|",
                *sens]
    if "gates_failed" in ok:
        gated = ok[ok["gate_pass"].notna() & ~ok["gate_pass"].astype(bool)]
        if len(gated):
            out += ["", "NUTS fits that failed a diagnostic gate: " + "; ".join(
                f"{r.model} scale {r.scale:g} seed {r.seed} ({r.gates_failed})" for r in gated.itertuples())]
    failed = df[df["error"].notna()] if "error" in df else df.iloc[:0]
    if len(failed):
        out += ["", f"{len(failed)} fit(s) failed: " + "; ".join(sorted(set(failed["error"].astype(str))))[:500]]
    return "\n".join(out) + "\n"
