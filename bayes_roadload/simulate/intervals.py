"""Synthetic speed-gate interval times: what a VBOX "Coastdown" logger would record.

:func:`gate_crossing_times` times a speed trace through given gate speeds the way a logger does
(a local straight-line fit of the speed against time around each crossing, which averages the
speed noise); :func:`interval_campaign_from_traces` turns a simulated (or measured) campaign of
speed traces into an interval campaign of the split method: the runs of the first pairs are
timed through the high window, the others through the low one, as on a track where the high
and the low runs are separate coastdowns.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .. import config
from ..data.campaign import Campaign
from ..data.intervals import IntervalCampaign

SPLIT_WINDOWS_KPH = config.VBOX_DEFAULT_GATES_KPH[5][0], config.VBOX_DEFAULT_GATES_KPH[3][0]
"""The split method's high (95 -> 70 km/h) and low (50 -> 35 km/h) gate speeds."""


def gate_crossing_times(time_s, speed_mps, gates_mps, half_window_s: float = 1.0) -> np.ndarray:
    """Times at which a decelerating speed trace crosses each gate speed.

    Around the first sample below each gate, a straight line is fitted to the samples within
    ``half_window_s`` and solved for the gate speed (a logger's smoothing: with 0.05 m/s speed
    noise at 4 Hz and ~0.3 m/s^2 deceleration the crossing time scatters by ~0.06 s instead of
    ~0.17 s from the raw samples).  NaN for a gate the trace never reaches.
    """
    t = np.asarray(time_s, float)
    v = np.asarray(speed_mps, float)
    out = np.full(len(gates_mps), np.nan)
    for j, g in enumerate(gates_mps):
        below = np.flatnonzero(v < g)
        if below.size == 0 or below[0] == 0:
            continue
        i = below[0]
        near = np.abs(t - t[i]) <= half_window_s
        slope, intercept = np.polyfit(t[near], v[near], 1)
        out[j] = (g - intercept) / slope
    return out


def interval_campaign_from_traces(campaign: Campaign, windows_kph=SPLIT_WINDOWS_KPH, *,
                                  split_pairs: bool = True, half_window_s: float = 1.0) -> IntervalCampaign:
    """Time every run of a trace campaign through speed gates (:func:`gate_crossing_times`).

    Parameters
    ----------
    campaign : runs with speed traces covering the windows.
    windows_kph : gate lists (km/h, descending), one per window.
    split_pairs : True: the pairs are shared out over the windows in turn (first pairs high,
        next low, as separate coastdowns of the split method); False: every run is timed
        through every window (one run id per run and window).
    """
    rows = []
    pairs = campaign.pairs()
    directions = campaign.directions()
    n_win = len(windows_kph)
    assignment: dict = {}
    for k, pair in enumerate(pairs):
        for r in pair:
            assignment[r] = [min(k * n_win // max(len(pairs), 1), n_win - 1)] if split_pairs else list(range(n_win))
    for rid, g in campaign.runs.groupby("run", sort=False):
        rid = rid.item() if hasattr(rid, "item") else rid
        for w in assignment.get(rid, []):
            gates = np.asarray(windows_kph[w], float)
            cross = gate_crossing_times(g["time_s"].to_numpy(), g["speed_mps"].to_numpy(), gates * config.KPH_TO_MPS,
                                        half_window_s)
            if not np.all(np.isfinite(cross)):
                raise ValueError(f"run {rid!r} does not cover the window {gates[0]:g} -> {gates[-1]:g} km/h")
            label = f"{gates[0]:g}-{gates[-1]:g}kph"
            pair = next(f"p{k + 1}-{label}" for k, p in enumerate(pairs) if rid in p)
            for j in range(len(gates) - 1):
                rows.append({"run": f"{rid}-{label}" if not split_pairs else str(rid), "window": label,
                             "direction": directions[rid], "pair": pair,
                             "speed_start_mps": gates[j] * config.KPH_TO_MPS,
                             "speed_end_mps": gates[j + 1] * config.KPH_TO_MPS,
                             "interval_s": cross[j + 1] - cross[j]})
    meta = dict(campaign.meta, source="gate crossings of simulated speed traces")
    return IntervalCampaign(pd.DataFrame(rows), campaign.vehicle, campaign.anemometer, campaign.tunnel,
                            campaign.truth, meta)
