"""Run validity: wind limits, outlier detection, and rejecting a run with its partner.

A coastdown run is only usable when the wind was within the regulation's limits and nothing
else (braking, traffic, a logger glitch) disturbed it; the opposite-direction pair is the unit of
the test (the wind and the grade cancel over a pair), so a rejected run takes its partner with
it (``partner of ...`` in the reason).

- **Wind limits** (:data:`bayes_roadload.config.WIND_LIMITS`), checked on campaigns with on-board
  anemometers: the run's mean wind speed, its peak, and the mean cross-wind component, from the
  calibrated relative air (true = factor x reading) minus the vehicle's motion.
- **Outliers** by a Hampel identifier (a value further than ``k`` x 1.4826 x MAD from the median
  of its group, ``config.HAMPEL_THRESHOLD``): on interval campaigns each run's total time through
  its window against the runs of the same window and direction (the headings differ
  systematically when there is wind or grade), the scale floored at
  ``config.HAMPEL_MIN_RELATIVE_SPREAD`` of the median; on speed traces a running Hampel filter over
  each run's speed flags spikes, and a run with more than ``config.HAMPEL_MAX_SPIKE_FRACTION`` of
  its samples flagged is rejected.
- The operator's own flag (``valid = 0``, VBOX ``Run-Use = Off``) rejects a run as well.
- **How well the yaw reading follows the gusts** (reported, never a rejection): each run's yaw
  sample rate and the lag-1 autocorrelation of its gusts
  (:func:`bayes_roadload.analysis.gap.input_resolution`); below
  ``DiagnosisConfig.min_input_lag1`` the summary line says so (the diagnosis then reports the
  yaw-term candidates not identifiable, docs/method.md section 7).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .. import config
from ..data import IntervalCampaign
from .gap import input_resolution

MAD_TO_SD = 1.4826
"""Scale of the median absolute deviation to a normal standard deviation."""


def hampel_scores(values, min_relative_spread: float = 0.0) -> np.ndarray:
    """(x - median) / scale for each value of a group, scale = max(1.4826 MAD,
    ``min_relative_spread`` x |median|) (0 where the scale is 0)."""
    x = np.asarray(values, float)
    med = np.median(x)
    scale = max(MAD_TO_SD * np.median(np.abs(x - med)), min_relative_spread * abs(med))
    return (x - med) / scale if scale > 0 else np.zeros_like(x)


def hampel_filter(x, half_window: int = config.HAMPEL_HALF_WINDOW, k: float = config.HAMPEL_THRESHOLD):
    """Hampel filter of a decelerating speed trace: flags samples whose deviation from a local
    quadratic trend (Savitzky-Golay over ``2 half_window + 1`` samples) is further than ``k``
    scaled MADs from the median deviation in the same window.  The trend is removed first
    because a coastdown's steady deceleration exceeds the speed noise per sample: a plain
    running median then returns the centre sample itself, the deviations are mostly exact zeros
    and the MAD collapses (measured: 18 % of the samples of a clean simulated run flagged).
    Returns (flags, the series with flagged samples replaced by the trend)."""
    from scipy.signal import savgol_filter

    x = np.asarray(x, float)
    n = x.size
    width = 2 * half_window + 1
    if n < width:
        return np.zeros(n, bool), x.copy()
    trend = savgol_filter(x, width, 2, mode="interp")
    dev = x - trend
    win = np.lib.stride_tricks.sliding_window_view(np.pad(dev, half_window, mode="reflect"), width)[:n]
    med = np.median(win, axis=1)
    mad = MAD_TO_SD * np.median(np.abs(win - med[:, None]), axis=1)
    flags = np.abs(dev - med) > k * np.maximum(mad, 1e-12)
    return flags, np.where(flags, trend, x)


def reject_with_partners(table: pd.DataFrame, pairs) -> pd.DataFrame:
    """Mark the partner of every rejected run (``rejected``, ``reason`` columns of ``table``,
    indexed by run id) as rejected too."""
    table = table.copy()
    first = dict(zip(table["run"], table["rejected"]))
    for a, b in pairs:
        for x, y in ((a, b), (b, a)):
            if first.get(x) and not first.get(y) and y in set(table["run"]):
                i = table.index[table["run"] == y][0]
                table.loc[i, "rejected"] = True
                table.loc[i, "reason"] = f"partner of {x}"
    return table


def interval_validity(campaign, k: float = config.HAMPEL_THRESHOLD) -> pd.DataFrame:
    """One row per run of an interval campaign: total time, Hampel score within its window and
    direction, the operator's flag, ``rejected`` and the ``reason`` (module docstring)."""
    runs = campaign.run_table()
    if "window" not in runs:
        runs["window"] = "all"
    if "direction" not in runs:
        runs["direction"] = 1
    runs["hampel_score"] = 0.0
    for _, idx in runs.groupby(["window", "direction"]).groups.items():
        runs.loc[idx, "hampel_score"] = hampel_scores(runs.loc[idx, "total_time_s"], config.HAMPEL_MIN_RELATIVE_SPREAD)
    operator = runs["valid"].to_numpy() == 0 if "valid" in runs else np.zeros(len(runs), bool)
    outlier = np.abs(runs["hampel_score"].to_numpy()) > k
    reasons = []
    for off, out, z, t in zip(operator, outlier, runs["hampel_score"], runs["total_time_s"]):
        r = []
        if off:
            r.append("operator: Run-Use Off")
        if out:
            r.append(f"Hampel outlier: total time {t:.2f} s, {z:+.1f} scaled MADs (floored at 2 %) from its window and direction")
        reasons.append("; ".join(r))
    runs["rejected"] = operator | outlier
    runs["reason"] = reasons
    cols = ["run", "window", "direction"] + (["pair"] if "pair" in runs else []) + [
        "bands", "total_time_s", "hampel_score", "rejected", "reason"]
    return reject_with_partners(runs[cols], campaign.pairs())


def trace_validity(campaign, limits: str = config.DEFAULT_WIND_LIMITS, k: float = config.HAMPEL_THRESHOLD
                   ) -> pd.DataFrame:
    """One row per run of a speed-trace campaign: mean and peak wind speed and mean cross wind
    (with anemometers), the fraction of speed samples a running Hampel filter flags, and the
    verdict against ``config.WIND_LIMITS[limits]`` (module docstring)."""
    if limits not in config.WIND_LIMITS:
        raise ValueError(f"wind limits {limits!r} unknown; choose one of {', '.join(config.WIND_LIMITS)}")
    lim = config.WIND_LIMITS[limits]
    rows = []
    for rid, g in campaign.runs.groupby("run", sort=False):
        rid = rid.item() if hasattr(rid, "item") else rid
        v = g["speed_mps"].to_numpy(float)
        flags, _ = hampel_filter(v, k=k)
        row = {"run": rid, "direction": int(g["direction"].iloc[0]) if "direction" in g else 1,
               "samples": len(g), "speed_spike_fraction": float(flags.mean())}
        reasons = []
        if campaign.has_anemometer:
            a, psi = campaign.anemometer.calibrated_air(g["airspeed_mps"], g["yaw_rad"])
            head = a * np.cos(psi) - v          # along-track wind met by the vehicle (+ head wind)
            cross = a * np.sin(psi)
            speed = np.hypot(head, cross)
            row.update(mean_wind_mps=float(np.hypot(head.mean(), cross.mean())), peak_wind_mps=float(speed.max()),
                       mean_cross_wind_mps=float(abs(cross.mean())))
            res = input_resolution(g["time_s"].to_numpy(float)[None], g["yaw_rad"].to_numpy(float)[None],
                                   np.ones((1, len(g)), bool))
            row.update(yaw_sample_rate_hz=res["sample_rate_hz"] if res else np.nan,
                       yaw_lag1_autocorr=res["lag1_autocorr"] if res else np.nan)
            for key, name in (("mean_wind_mps", "mean wind"), ("peak_wind_mps", "peak wind"),
                              ("mean_cross_wind_mps", "mean cross wind")):
                if row[key] > lim[key]:
                    reasons.append(f"{name} {row[key]:.1f} m/s > {lim[key]:g} m/s ({limits})")
        if row["speed_spike_fraction"] > config.HAMPEL_MAX_SPIKE_FRACTION:
            reasons.append(f"{100 * row['speed_spike_fraction']:.1f} % of speed samples are Hampel outliers")
        row["rejected"] = bool(reasons)
        row["reason"] = "; ".join(reasons)
        rows.append(row)
    table = pd.DataFrame(rows)
    return reject_with_partners(table, campaign.pairs())


def validity_table(campaign, limits: str = config.DEFAULT_WIND_LIMITS) -> pd.DataFrame:
    """:func:`interval_validity` or :func:`trace_validity` by the campaign's kind."""
    if isinstance(campaign, IntervalCampaign):
        return interval_validity(campaign)
    return trace_validity(campaign, limits)


def format_validity(table: pd.DataFrame) -> str:
    """Lines for the terminal: how many runs were rejected and why."""
    bad = table[table["rejected"]]
    lines = [f"validity: {len(table) - len(bad)} of {len(table)} runs accepted"
             + (f", {len(bad)} rejected:" if len(bad) else "")]
    lines += [f"  rejected run {r}: {why}" for r, why in zip(bad["run"], bad["reason"])]
    if "yaw_lag1_autocorr" in table and table["yaw_lag1_autocorr"].notna().any():
        ac, rate = float(table["yaw_lag1_autocorr"].median()), float(table["yaw_sample_rate_hz"].median())
        floor = config.DEFAULT_DIAGNOSIS.min_input_lag1
        if ac < floor:
            lines.append(f"  note: the yaw reading does not follow its gusts (lag-1 autocorrelation {ac:.2f} < {floor:g} "
                         f"at {rate:.3g} Hz, median of the runs): what scales the yaw term (K_D, a vane factor) may be "
                         "off; log the anemometer faster")
    return "\n".join(lines)
