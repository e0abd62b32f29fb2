"""Regulation precision criteria on a campaign, and the pairs still needed when they fail.

* **EEC** (thesis appendix A): the total road load at a reference speed from each pair's
  classical fit; accepted when ``t s / (sqrt(n) X) <= 2 %`` at 95 % (``t`` Student's quantile
  with n - 1 degrees of freedom, ``s`` the standard deviation of the n pairs' loads, ``X``
  their mean).
* **GTR 15** (WLTP, Annex 4, coastdown method): at every reference speed v_j, each run's
  coastdown time from v_j + 5 to v_j - 5 km/h (read from the measured speed, no model), the
  harmonic mean of a pair's two directions ``dt_j``; accepted when the statistical precision
  ``p_j = h s_j / (sqrt(n) mean(dt_j)) <= 3 %`` with ``h = t(0.975, n - 1)`` and n >= 3 pairs.

When a criterion fails, ``extra_pairs`` is what the regulation's own arithmetic asks for
(the observed spread taken as the truth, as the thesis does); ``extra_pairs_assured`` keeps the
uncertainty of that spread (:func:`~bayes_roadload.analysis.planning.predictive_half_widths`)
and asks for the number of pairs that meets the criterion with probability
:data:`~bayes_roadload.config.PLAN_ASSURANCE`.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
import pandas as pd
from scipy import stats

from .. import config
from ..data.campaign import Campaign

EEC_PRECISION_PCT = 2.0
"""EEC coastdown acceptance (thesis appendix A): t s / (sqrt(n) X) <= 2 % at 95 %, X the mean
total road load at the reference speed over the n pairs and s their standard deviation."""

GTR_PRECISION_PCT = 3.0
"""GTR 15 (WLTP, Annex 4) coastdown statistical precision: p_j = h s_j / (sqrt(n) dt_j) <= 3 %
at every reference speed v_j, dt_j the pairs' mean coastdown time from v_j + 5 to v_j - 5 km/h
(harmonic mean of the two directions of a pair), h = t(0.975, n - 1)."""

GTR_SPEED_HALF_BAND_KPH = 5.0
"""Half width of the GTR 15 coastdown-time speed band around each reference speed (km/h)."""

GTR_REFERENCE_SPEEDS_KPH = (20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 90.0, 100.0, 110.0, 120.0, 130.0)
"""GTR 15 reference speeds (km/h); those inside every run's speed range are checked."""

MIN_REGULATION_PAIRS = 3
"""GTR 15 needs at least three pairs."""
GTR_ONBOARD_MIN_PAIRS = 5
"""GTR 15 with on-board anemometry: "a minimum of 5 pairs of coastdown runs" (Regulation (EU)
2017/1151 Annex XXI Sub-Annex 4, 4.3.2.4, which transposes GTR 15 Annex 4)."""
GTR_ROTATING_MASS_SHARE = 0.03
GTR_ROTATING_MASS_OFFSET_KG = 25.0
"""GTR 15: "m_r may be estimated to be 3 per cent of the sum of the mass in running order and
25 kg" (Regulation (EU) 2017/1151 Annex XXI Sub-Annex 4, 2.5.1)."""
GTR_MIN_SPEED_RATE_HZ = 10.0
"""GTR 15: vehicle speed "with a measurement frequency of at least 10 Hz" (Regulation (EU)
2017/1151 Annex XXI Sub-Annex 4, 3.1(a)); the on-board procedure's own 5 Hz (4.3.2.3) is the
lower of the two."""

REGULATION_MAX_PAIRS = 200
"""Largest number of pairs searched for the pairs a failing criterion still needs."""

MAX_PAIRS = REGULATION_MAX_PAIRS


def _band_time(t: np.ndarray, v: np.ndarray, high: float, low: float) -> float:
    """Time from the first fall through ``high`` to the first fall through ``low`` after it,
    linearly interpolated between samples; NaN when the run does not span the band."""
    def crossing(level: float, start: int) -> float:
        below = np.flatnonzero(v[start:] <= level)
        if below.size == 0:
            return math.nan
        i = start + below[0]
        if i == 0:
            return math.nan  # started below the level
        return t[i - 1] + (v[i - 1] - level) / (v[i - 1] - v[i]) * (t[i] - t[i - 1])

    t_high = crossing(high, 0)
    if not math.isfinite(t_high):
        return math.nan
    t_low = crossing(low, int(np.searchsorted(t, t_high)))
    return t_low - t_high


def coastdown_times(campaign: Campaign, speeds_kph: Sequence[float] = GTR_REFERENCE_SPEEDS_KPH,
                    half_band_kph: float = GTR_SPEED_HALF_BAND_KPH) -> pd.DataFrame:
    """Each run's coastdown time (s) through each reference speed's band: rows = runs (``run``,
    ``pair``), columns = reference speeds in km/h."""
    rows = []
    for rid, g in campaign.runs.groupby("run", sort=False):
        t, v = g["time_s"].to_numpy(float), g["speed_mps"].to_numpy(float)
        row = {"run": rid, "pair": g["pair"].iloc[0] if "pair" in g else None}
        for s in speeds_kph:
            row[float(s)] = _band_time(t, v, (s + half_band_kph) * config.KPH_TO_MPS, (s - half_band_kph) * config.KPH_TO_MPS)
        rows.append(row)
    return pd.DataFrame(rows)


def pairs_needed(spread_pct: float, n_now: int, limit_pct: float, *, assured: float | None = None,
                 confidence: float = 0.95, max_pairs: int = MAX_PAIRS, simulations: int = 4000, seed: int = 0) -> int | None:
    """Smallest number of pairs n >= max(n_now, 2) with ``t(n - 1) s / sqrt(n) <= limit_pct``
    (s = ``spread_pct``, the coefficient of variation in percent): plug-in when ``assured`` is
    None, else with probability >= ``assured`` over the spread's uncertainty given ``n_now``
    pairs.  None when not reached by ``max_pairs``."""
    from .planning import predictive_half_widths

    lo = max(n_now, 2)
    if not math.isfinite(spread_pct):
        return None
    if assured is None:
        for n in range(lo, max_pairs + 1):
            if stats.t.ppf((1 + confidence) / 2, n - 1) * spread_pct / math.sqrt(n) <= limit_pct:
                return n
        return None
    if n_now < 2:
        return None
    # doubling search, then bisection, on the predictive assurance
    def ok(n: int) -> bool:
        hw = predictive_half_widths(spread_pct, n_now, n, confidence=confidence, simulations=simulations, seed=seed)
        return float((hw <= limit_pct).mean()) >= assured

    hi = lo
    while not ok(hi):
        if hi >= max_pairs:
            return None
        hi = min(2 * hi, max_pairs)
    low = max(lo, hi // 2)
    while low < hi:
        mid = (low + hi) // 2
        if ok(mid):
            hi = mid
        else:
            low = mid + 1
    return hi


def _criterion_row(criterion: str, speed_kph: float, values: np.ndarray, limit_pct: float, minimum: int,
                   assurance: float) -> dict:
    values = values[np.isfinite(values)]
    n = int(values.size)
    mean = float(values.mean()) if n else math.nan
    sd = float(values.std(ddof=1)) if n > 1 else math.nan
    spread = 100.0 * sd / abs(mean) if n > 1 else math.nan
    h = float(stats.t.ppf(0.975, n - 1)) if n > 1 else math.nan
    precision = h * spread / math.sqrt(n) if n > 1 else math.nan
    passed = bool(n >= minimum and precision <= limit_pct)
    need = None if passed else pairs_needed(spread, n, limit_pct)
    need_assured = None if passed else pairs_needed(spread, n, limit_pct, assured=assurance)
    if need is not None:
        need = max(need, minimum)
    if need_assured is not None:
        need_assured = max(need_assured, minimum)
    return {"criterion": criterion, "speed_kph": speed_kph, "n_pairs": n, "mean": mean, "sd": sd, "h": h,
            "precision_pct": precision, "limit_pct": limit_pct, "pass": passed,
            "extra_pairs": 0 if passed else (None if need is None else need - n),
            "extra_pairs_assured": 0 if passed else (None if need_assured is None else max(need_assured - n, 0))}


def gtr15_precision(campaign: Campaign, speeds_kph: Sequence[float] | None = None, *,
                    limit_pct: float = GTR_PRECISION_PCT,
                    assurance: float = config.PLAN_ASSURANCE) -> pd.DataFrame:
    """GTR 15 statistical precision at each reference speed spanned by every run (module
    docstring).  Columns: ``criterion`` ("GTR15"), ``speed_kph``, ``n_pairs``, ``mean`` and
    ``sd`` of the pairs' coastdown times (s), ``h``, ``precision_pct``, ``limit_pct``,
    ``pass``, ``extra_pairs``, ``extra_pairs_assured``."""
    if "pair" not in campaign.runs:
        raise ValueError("GTR 15 works on opposite-direction pairs: the campaign needs a `pair` column")
    times = coastdown_times(campaign, speeds_kph or GTR_REFERENCE_SPEEDS_KPH)
    speeds = [c for c in times.columns if isinstance(c, float) and times[c].notna().all()]
    rows = []
    for s in speeds:
        per_pair = []
        for _, g in times.groupby("pair", sort=False):
            if len(g) == 2:
                per_pair.append(2.0 / (1.0 / g[s]).sum())  # harmonic mean of the two directions
        rows.append(_criterion_row("GTR15", s, np.asarray(per_pair, float), limit_pct,
                                   MIN_REGULATION_PAIRS, assurance))
    return pd.DataFrame(rows)


def eec_precision(campaign: Campaign, model: str = "three_term", *, limit_pct: float = EEC_PRECISION_PCT,
                  assurance: float = config.PLAN_ASSURANCE) -> pd.DataFrame:
    """EEC criterion on the total road load at 50 mph (reference conditions) from each pair's
    classical least-squares fit with ``model`` (module docstring); one row like
    :func:`gtr15_precision`'s, ``mean`` and ``sd`` in N."""
    from ..inference.lsq import fit_lsq

    res = fit_lsq(campaign, model, grouping="pair")
    loads = np.asarray([g.estimate.get("F50_N", math.nan) for g in res.groups], float)
    return pd.DataFrame([_criterion_row("EEC", round(config.SPEED_50MPH_MPS / config.KPH_TO_MPS, 2), loads,
                                        limit_pct, 2, assurance)])


def regulation_checks(campaign: Campaign, model: str = "three_term", *,
                      assurance: float = config.PLAN_ASSURANCE) -> pd.DataFrame:
    """EEC and GTR 15 rows together (:func:`eec_precision`, :func:`gtr15_precision`)."""
    return pd.concat([eec_precision(campaign, model, assurance=assurance),
                      gtr15_precision(campaign, assurance=assurance)], ignore_index=True)
