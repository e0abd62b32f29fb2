"""Synthetic distance-time records: the times a coasting vehicle passes markers on the track.

:func:`marker_passing_times` reads, from a speed trace with its distance travelled, the times at
which given distances are passed (a monotone cubic through the logged distance against time);
:func:`distance_campaign_from_traces` turns a simulated campaign of speed traces (any case, any
test masses: :func:`~bayes_roadload.simulate.simulate_campaign` with ``masses_kg``) into a
distance-time campaign, with an independent timing error per marker passing (a camera frame, a
light gate): seed 002's speed trap, on a full-size track.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.interpolate import PchipInterpolator

from .. import config
from ..data.campaign import Campaign
from ..data.distances import DistanceCampaign

DEFAULT_MARKERS_M = tuple(float(x) for x in np.arange(100.0, 1301.0, 100.0))
"""Marker distances from the start of the coast (m): 13 markers 100 m apart, passed between
~29 and ~10 m/s by the thesis vehicle (every simulated run of the thesis cases covers 1300 m)."""
DEFAULT_TIMING_SD_S = 0.02
"""Timing error of one marker passing (s): a 50 fps camera's frame, or a hand-held stopwatch's
best."""


def marker_passing_times(time_s, distance_m, markers_m) -> np.ndarray:
    """Times at which a run passes each distance in ``markers_m`` (same origin as
    ``distance_m``), by monotone cubic (PCHIP) interpolation of time against distance; NaN for
    a marker the run does not reach."""
    t = np.asarray(time_s, float)
    x = np.asarray(distance_m, float)
    keep = np.concatenate([[True], np.diff(x) > 0])   # a stopped vehicle: distance no longer increasing
    t, x = t[keep], x[keep]
    markers = np.asarray(markers_m, float)
    out = np.full(markers.shape, np.nan)
    inside = (markers >= x[0]) & (markers <= x[-1])
    out[inside] = PchipInterpolator(x, t)(markers[inside])
    return out


def distance_campaign_from_traces(campaign: Campaign, markers_m=DEFAULT_MARKERS_M, *,
                                  timing_sd_s: float = DEFAULT_TIMING_SD_S, seed: int = 0) -> DistanceCampaign:
    """The distance-time campaign of a campaign of speed traces: every run timed past the
    same markers.

    Parameters
    ----------
    campaign : runs with ``distance_m`` (the simulator's true distance travelled).
    markers_m : marker distances from the start of each run (m), increasing, at least
        ``config.MIN_DISTANCE_MARKERS``.
    timing_sd_s : sd of the independent Gaussian timing error of each passing (s).
    seed : seed of the timing errors (run i draws from ``SeedSequence(seed, spawn_key=(i,))``).

    Returns
    -------
    DistanceCampaign with columns run, distance_m, time_s, direction, pair and, when the traces
    carry them, mass_kg, temperature_k, pressure_pa; the truth, vehicle and tunnel of
    ``campaign``, its meta with the markers and the timing error.
    """
    markers = np.asarray(markers_m, float)
    if markers.size < config.MIN_DISTANCE_MARKERS or np.any(np.diff(markers) <= 0):
        raise ValueError(f"markers_m needs at least {config.MIN_DISTANCE_MARKERS} increasing distances")
    if "distance_m" not in campaign.runs:
        raise ValueError("the speed traces carry no distance_m: the passing times cannot be read")
    if timing_sd_s < 0:
        raise ValueError("timing_sd_s must be >= 0")
    directions = campaign.directions()
    frames = []
    for i, (rid, g) in enumerate(campaign.runs.groupby("run", sort=False)):
        rid = rid.item() if hasattr(rid, "item") else rid
        t = marker_passing_times(g["time_s"].to_numpy(), g["distance_m"].to_numpy(), markers)
        if not np.all(np.isfinite(t)):
            raise ValueError(f"run {rid!r} covers {g['distance_m'].iloc[-1]:.0f} m and does not reach the marker at "
                             f"{markers[~np.isfinite(t)][0]:g} m")
        rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(i,)))
        cols = {"run": rid, "distance_m": markers, "time_s": t + timing_sd_s * rng.standard_normal(t.size),
                "direction": directions[rid]}
        for c in ("pair", "mass_kg", "temperature_k", "pressure_pa"):
            if c in g:
                cols[c] = g[c].iloc[0] if c == "pair" else float(g[c].iloc[0])
        frames.append(pd.DataFrame(cols))
    meta = dict(campaign.meta, source="marker passings of simulated speed traces", markers_m=[float(x) for x in markers],
                timing_sd_s=float(timing_sd_s), timing_seed=int(seed))
    return DistanceCampaign(pd.concat(frames, ignore_index=True), campaign.vehicle, campaign.anemometer,
                            campaign.tunnel, campaign.truth, meta)
