"""The sim-to-real gap measured on speed residuals, and where it lies (plain numpy).

Residual structure (per run, then averaged over runs):

``trend_rms_mps``
    RMS of the low-frequency part of the speed residual: a centred moving average over
    :data:`TREND_WINDOW_S` (the thesis' "very low frequency trend in the residuals").
    ``trend_floor_mps`` is what white measurement noise of the fitted level leaves after the
    same filter (sigma / sqrt(samples in the window)), the level a correct model reaches.
``lag1_autocorr``
    Lag-1 autocorrelation of the residual (0 for white noise).

Localisation (:func:`localise`): the residuals binned by time into the run, speed, distance
along the track, yaw, airspeed, direction and run; per variable the mean and RMS residual per
bin and ``eta2``, the share of the residual variance the bin means explain (where the misfit
concentrates).  Plots with matplotlib (Agg).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping

import numpy as np

TREND_WINDOW_S = 20.0
"""Width of the moving average that extracts the residuals' low-frequency trend (s)."""

LOCALISATION_BINS = 6
"""Bins per continuous variable (quantile bins)."""

LOCALISATION_VARIABLES = ("time_s", "speed_mps", "distance_m", "yaw_rad", "airspeed_mps", "direction", "run")
"""The variables the residuals are binned by."""


def _moving_average(x: np.ndarray, width: int) -> np.ndarray:
    from scipy.ndimage import uniform_filter1d

    return uniform_filter1d(x, size=max(int(width), 1), mode="nearest")


def _runs(values: np.ndarray, mask: np.ndarray, time_s: np.ndarray):
    """Per run of [R, N] arrays with at least four real samples: the run index, its samples,
    its median sample interval and the width in samples of the :data:`TREND_WINDOW_S` moving
    average."""
    for r in range(values.shape[0]):
        x, t = values[r][mask[r]], time_s[r][mask[r]]
        if x.size < 4:
            continue
        dt = float(np.median(np.diff(t)))
        yield r, x, dt, int(round(TREND_WINDOW_S / dt)) if dt > 0 else 1


def _lag1(x: np.ndarray) -> float | None:
    """Lag-1 autocorrelation of ``x`` about its mean (None for a constant)."""
    xc = x - x.mean()
    denom = float(np.sum(xc**2))
    return float(np.sum(xc[1:] * xc[:-1]) / denom) if denom > 0 else None


def residual_structure(residual: np.ndarray, mask: np.ndarray, time_s: np.ndarray,
                       sigma_mps: np.ndarray | float) -> dict[str, float]:
    """``trend_rms_mps``, ``trend_floor_mps`` and ``lag1_autocorr`` of [R, N] residuals
    (module docstring); ``sigma_mps`` the fitted white-noise level per run."""
    residual, mask, time_s = np.asarray(residual, float), np.asarray(mask, bool), np.asarray(time_s, float)
    sigma = np.broadcast_to(np.asarray(sigma_mps, float), (residual.shape[0],))
    trend_sq, floor_sq, n_total, ac = 0.0, 0.0, 0, []
    for r, x, _, width in _runs(residual, mask, time_s):
        trend = _moving_average(x, width)
        trend_sq += float(np.sum(trend**2))
        floor_sq += x.size * float(sigma[r]) ** 2 / max(min(width, x.size), 1)
        n_total += x.size
        lag1 = _lag1(x)
        ac.append(0.0 if lag1 is None else lag1)
    return {"trend_rms_mps": math.sqrt(trend_sq / max(n_total, 1)),
            "trend_floor_mps": math.sqrt(floor_sq / max(n_total, 1)),
            "lag1_autocorr": float(np.mean(ac)) if ac else math.nan}


def input_resolution(time_s: np.ndarray, values: np.ndarray, mask: np.ndarray) -> dict[str, float] | None:
    """How well a logged input channel ([R, N] readings) resolves its own fluctuations.

    Per run, the reading's deviation from its centred moving average over :data:`TREND_WINDOW_S` (the
    gusts, not the run's slow course) and that deviation's lag-1 autocorrelation: near 1 when
    consecutive samples follow one gust, near 0 when each sample catches a different one (the
    logging rate is too low for the turbulence, or noise dominates).  Returns the median over
    runs, ``lag1_autocorr``, and the median ``sample_rate_hz``; None when no run has four
    samples of a varying reading."""
    time_s, values, mask = np.asarray(time_s, float), np.asarray(values, float), np.asarray(mask, bool)
    ac, rate = [], []
    for _, x, dt, width in _runs(values, mask, time_s):
        lag1 = _lag1(x - _moving_average(x, width))
        if lag1 is None:
            continue
        ac.append(lag1)
        rate.append(1.0 / dt if dt > 0 else math.nan)
    if not ac:
        return None
    return {"lag1_autocorr": float(np.median(ac)), "sample_rate_hz": float(np.median(rate))}


def localise(residual: np.ndarray, mask: np.ndarray, variables: Mapping[str, np.ndarray],
             bins: int = LOCALISATION_BINS) -> dict[str, dict]:
    """Residuals binned by each variable ([R, N] arrays, like ``residual``).

    Continuous variables get ``bins`` quantile bins; ``direction`` and ``run`` one bin per
    value.  Returns, per variable: ``bin_low``, ``bin_high`` (or ``value``), ``n``,
    ``mean_residual_mps``, ``rms_residual_mps`` (lists) and ``eta2`` (between-bin share of the
    residual variance, 0-1); plus ``"where"``: the variables sorted by ``eta2``, highest first.
    """
    m = np.asarray(mask, bool)
    e = np.asarray(residual, float)[m]
    total = float(np.sum((e - e.mean()) ** 2)) or 1.0
    out: dict[str, dict] = {}
    for name, values in variables.items():
        x = np.asarray(values, float)[m]
        if name in ("direction", "run"):
            keys = np.unique(x)
            idx = np.searchsorted(keys, x)
            entry = {"value": [float(k) for k in keys]}
        else:
            edges = np.unique(np.quantile(x, np.linspace(0.0, 1.0, bins + 1)))
            if edges.size < 2:
                edges = np.array([x.min(), x.max() + 1e-12])
            idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, edges.size - 2)
            entry = {"bin_low": [float(v) for v in edges[:-1]], "bin_high": [float(v) for v in edges[1:]]}
        k = int(idx.max()) + 1
        n = np.bincount(idx, minlength=k)
        sums = np.bincount(idx, weights=e, minlength=k)
        sq = np.bincount(idx, weights=e**2, minlength=k)
        mean = np.where(n > 0, sums / np.maximum(n, 1), 0.0)
        between = float(np.sum(n * (mean - e.mean()) ** 2))
        entry.update({"n": [int(v) for v in n], "mean_residual_mps": [float(v) for v in mean],
                      "rms_residual_mps": [float(v) for v in np.sqrt(np.where(n > 0, sq / np.maximum(n, 1), 0.0))],
                      "eta2": between / total})
        out[name] = entry
    out["where"] = sorted(variables, key=lambda v: -out[v]["eta2"])
    return out


def plot_localisation(loc: Mapping[str, dict], path: str | Path, title: str = "") -> Path:
    """One panel per variable: mean residual per bin with +- RMS whiskers; eta2 in the title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [v for v in LOCALISATION_VARIABLES if v in loc]
    cols = 4
    rows = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.6 * rows), squeeze=False)
    for ax, name in zip(axes.ravel(), names):
        d = loc[name]
        x = d["value"] if "value" in d else [0.5 * (a + b) for a, b in zip(d["bin_low"], d["bin_high"])]
        ax.errorbar(x, d["mean_residual_mps"], yerr=d["rms_residual_mps"], fmt="o", capsize=3, ms=4)
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.set_title(f"{name}  eta2={d['eta2']:.2f}", fontsize=9)
        ax.tick_params(labelsize=7)
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    axes[0, 0].set_ylabel("residual (m/s)")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_residuals(time_s: np.ndarray, residual: np.ndarray, mask: np.ndarray, path: str | Path,
                   after: np.ndarray | None = None, labels=None) -> Path:
    """Each run's speed residual against time into the run with its moving-average trend
    (and, given ``after``, the trend after the refit, dashed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.5))
    m = np.asarray(mask, bool)
    for r in range(residual.shape[0]):
        t, x = np.asarray(time_s)[r][m[r]], np.asarray(residual)[r][m[r]]
        width = int(round(TREND_WINDOW_S / max(float(np.median(np.diff(t))), 1e-9)))
        line, = ax.plot(t, _moving_average(x, width), lw=1.2,
                        label=None if labels is None else f"run {labels[r]}")
        ax.plot(t, x, lw=0.3, alpha=0.35, color=line.get_color())
        if after is not None:
            ax.plot(t, _moving_average(np.asarray(after)[r][m[r]], width), lw=1.0, ls="--", color=line.get_color())
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.set_xlabel("time into the run (s)")
    ax.set_ylabel("speed residual (m/s)")
    ax.set_title(f"residuals and their {TREND_WINDOW_S:g} s trend" + (" (dashed: after the refit)" if after is not None else ""),
                 fontsize=9)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
