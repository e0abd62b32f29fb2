"""The drag area by the regulation's own arithmetic: 40 CFR 1037.528 (Phase 2 tractors).

This is the classical result the regulation asks for, computed from the campaign's speed,
airspeed and yaw traces; it sits beside the posterior's drag area (``--standard cfr1037``,
:mod:`bayes_roadload.analysis.standards`), not inside the model.  Clauses of 40 CFR 1037.528
(81 FR 74048, as amended to 89 FR 29783):

* (g)(1) outliers: every channel is filtered by the Hampel method, a window of 3 s either side,
  standard deviation = 1.4826 x the window's median absolute deviation, a value more than three
  of them from the window's median is replaced by the median (:func:`hampel_filter`);
* (h)(1) effective mass: ``M_e = M + 56.7 kg`` per tyre in contact with the road
  (:func:`effective_mass_kg`);
* (d), (h)(3) speed ranges 70 -> 60 mi/h (high) and 20 -> 10 mi/h (low); each end point is the
  mean speed and mean time of the continuous interval from the first sample below
  ``nominal + 2 mi/h`` to the first sample at or below ``nominal - 2 mi/h``
  (:func:`speed_point`);
* (h)(4) road-load force of a range, Eq. 1037.528-7:
  ``F = M_e (v_start - v_end) / (t_end - t_start) - M a_g (h_end - h_start) / (D_end - D_start)``
  (:func:`range_force`; the grade term needs ``elevation_m`` and ``distance_m`` columns, else it
  is 0).  The form is checked against the regulation's worked example (F = 4645.5 N) in the
  tests;
* (h)(7)-(h)(9) mean squared airspeed of each range; the low range's force and squared
  airspeed averaged over each pair of opposite runs; mean air temperature and pressure of the
  high range;
* (h)(10), Eq. 1037.528-16, per high-speed range:
  ``CdA = [(F_hi - F_lo,pair) - (dF_spin + dF_TRR)] / [rho / 2 (v2_air,hi - v2_air,lo,pair)]``
  with ``rho = P_act / (R T)``, R = 287.058 J/(kg K).  The equation is an image in the text
  available here; this form is reconstructed from its variables as the clause defines them and
  is marked not verified in ``docs/standards.md``;
* (h)(5) drive-axle spin loss: ``F_spin = P_loss(f) / v_seg`` with ``f = v_seg TRPM`` the
  wheel speed (r/s) and ``P_loss = c0 + c1 f + c2 f^2`` the axle's zero-torque power loss
  (1037.560), ``v_seg`` the mean speed of the segment; dF_spin = F_spin,hi - F_spin,lo, Eq.
  1037.528-10 (:func:`spin_loss_force_n`);
* (h)(6) tyre rolling resistance per axle position, SAE J2452's regression
  ``F = n_t p^alpha (L / n_t)^beta (a + b v + c v^2)`` (p in kPa, L in N, v in km/h), summed over
  the positions and adjusted to the segment's air temperature by ``[1 + 0.006 (24 - T)]`` (T in
  deg C); dF_TRR = F_TRR,hi - F_TRR,lo (:func:`tyre_rolling_force_n`).  The (h)(5) and (h)(6)
  equations are images in the text available here; these forms are reconstructed from their
  variables and reproduce every figure of the regulation's worked examples (tests).  With a
  ``[cfr1037]`` table in vehicle.toml (:mod:`bayes_roadload.data.heavy_duty`) both are computed
  per high-speed range from its segment and its pair's low segments; without it they are the
  caller's constants (``--delta-f-spin-n``, ``--delta-f-trr-n``; 0 when not given, and the result
  says so);
* (h)(11) final value: drop ranges whose |yaw| differs from the median |yaw| by more than
  1.0 deg, then those more than 2.0 standard deviations from the mean CdA; at least 24 must
  remain; the effective yaw angle is their mean |yaw| rounded to 0.1 deg and the result their
  mean CdA (:func:`final_drag_area`).  The yaw is taken as its magnitude: a run's sign follows
  its direction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .. import config
from ..data.campaign import Campaign
from ..data.heavy_duty import CFR1037_TABLE

MASS_PER_TYRE_KG = 56.7
"""(h)(1): added to the measured mass per tyre in contact with the road."""
GAS_CONSTANT_J_PER_KG_K = 287.058
"""(h)(10): the specific gas constant of air in Eq. 1037.528-16."""
GRAVITY_MPS2 = 9.8061
"""a_g of the regulation's worked example (40 CFR 1065.630 gives it by latitude)."""
HIGH_RANGE_MPH = (70.0, 60.0)
LOW_RANGE_MPH = (20.0, 10.0)
POINT_BAND_MPH = 2.0
"""(h)(3): an end point is averaged from nominal + 2 to nominal - 2 mi/h."""
HAMPEL_HALF_WINDOW_S = 3.0
HAMPEL_SIGMA_PER_MAD = 1.4826
HAMPEL_N_SIGMA = 3.0
YAW_BAND_DEG = 1.0
CDA_BAND_SD = 2.0
MIN_POINTS = 24
"""(h)(11)(iv): at least 24 high-speed ranges must remain."""
MIN_RATE_HZ = 10.0
"""(d), (e), (f): speed, airspeed and yaw recorded at 10 Hz or more."""
MAX_MEAN_ALONG_WIND_MPH = 6.0
"""(c)(2): the mean wind component parallel to the road, per run."""
MILE_M = 1609.344
TRR_TEMPERATURE_COEFFICIENT = 0.006
TRR_REFERENCE_C = 24.0
"""(h)(6)(iv): F_TRR x [1 + 0.006 (24 - T)], T in deg C."""


def effective_mass_kg(mass_kg: float, tyres_in_contact: int) -> float:
    """(h)(1): M_e = M + 56.7 kg x tyres in contact."""
    return float(mass_kg) + MASS_PER_TYRE_KG * int(tyres_in_contact)


def hampel_filter(t: np.ndarray, x: np.ndarray, half_window_s: float = HAMPEL_HALF_WINDOW_S,
                  n_sigma: float = HAMPEL_N_SIGMA) -> np.ndarray:
    """(g)(1): each value more than ``n_sigma`` x 1.4826 x MAD from the median of the samples
    within ``half_window_s`` of it (fewer at the ends of the run) is replaced by that median."""
    t, x = np.asarray(t, float), np.asarray(x, float)
    lo = np.searchsorted(t, t - half_window_s - 1e-9, side="left")
    hi = np.searchsorted(t, t + half_window_s + 1e-9, side="right")
    if x.size == 0:
        return x.copy()
    width = int((hi - lo).max())
    idx = lo[:, None] + np.arange(width)[None, :]
    windows = np.where(idx < hi[:, None], x[np.minimum(idx, x.size - 1)], np.nan)
    med = np.nanmedian(windows, axis=1)
    sigma = HAMPEL_SIGMA_PER_MAD * np.nanmedian(np.abs(windows - med[:, None]), axis=1)
    return np.where(np.abs(x - med) > n_sigma * sigma, med, x)


def speed_point(t: np.ndarray, v: np.ndarray, nominal_mps: float,
                band_mps: float = POINT_BAND_MPH * config.MPH_TO_MPS) -> tuple[float, float] | None:
    """(h)(3): (mean speed, mean time) of the continuous interval that begins with the first
    sample below ``nominal + band`` and ends with the first sample at or below
    ``nominal - band``; None when the run does not pass through it."""
    v = np.asarray(v, float)
    above = np.flatnonzero(v < nominal_mps + band_mps)
    if above.size == 0 or v[0] < nominal_mps + band_mps:
        return None  # the run starts inside or below the band: the start of the interval is not seen
    i0 = int(above[0])
    below = np.flatnonzero(v[i0:] <= nominal_mps - band_mps)
    if below.size == 0:
        return None
    i1 = i0 + int(below[0])
    return float(v[i0:i1 + 1].mean()), float(np.asarray(t, float)[i0:i1 + 1].mean())


def range_force(m_e: float, mass_kg: float, v_start: float, v_end: float, t_start: float, t_end: float,
                h_start: float = 0.0, h_end: float = 0.0, d_start: float = 0.0, d_end: float = 1.0,
                g: float = GRAVITY_MPS2) -> float:
    """Eq. 1037.528-7: the road-load force (N) of a speed range, the grade's share removed."""
    return m_e * (v_start - v_end) / (t_end - t_start) - mass_kg * g * (h_end - h_start) / (d_end - d_start)


def spin_loss_force_n(v_seg_mps: float, tyre_revolutions_per_mile: float, coefficients) -> float:
    """(h)(5)(iii): the drive-axle spin loss force (N) at the segment's mean speed: the axle's
    power loss ``c0 + c1 f + c2 f^2`` (W) at the wheel speed ``f = v TRPM`` (r/s), divided by v."""
    f = v_seg_mps * tyre_revolutions_per_mile / MILE_M
    c0, c1, c2 = coefficients
    return (c0 + c1 * f + c2 * f * f) / v_seg_mps


def tyre_rolling_force_n(v_seg_mps: float, axles, temperature_k: float | None = None) -> float:
    """(h)(6)(ii)-(iv): the tyres' rolling resistance force (N) at the segment's mean speed,
    SAE J2452's ``n_t p^alpha (L / n_t)^beta (a + b v + c v^2)`` (v in km/h) summed over the axle
    positions (dicts as :func:`~bayes_roadload.data.heavy_duty.cfr1037_from_toml` gives them),
    times ``1 + 0.006 (24 - T)`` at the segment's air temperature ``T`` (none when None)."""
    v = v_seg_mps * 3.6
    total = sum(a["tyres"] * a["pressure_kpa"] ** a["alpha"] * (a["load_n"] / a["tyres"]) ** a["beta"]
                * (a["a"] + a["b"] * v + a["c"] * v * v) for a in axles)
    if temperature_k is None:
        return total
    return total * (1.0 + TRR_TEMPERATURE_COEFFICIENT * (TRR_REFERENCE_C - (temperature_k - 273.15)))


def delta_forces_n(inputs, v_hi_mps: float, v_lo_mps: float, t_hi_k: float, t_lo_k: float) -> tuple[float, float]:
    """(h)(5)(iv), (h)(6)(v): (dF_spin, dF_TRR) between a high and a low segment from the
    ``[cfr1037]`` inputs; a part the inputs do not give is NaN."""
    spin = trr = math.nan
    if "axle_spin_loss_coefficients" in inputs:
        args = (inputs["tyre_revolutions_per_mile"], inputs["axle_spin_loss_coefficients"])
        spin = spin_loss_force_n(v_hi_mps, *args) - spin_loss_force_n(v_lo_mps, *args)
    if "axle" in inputs:
        trr = tyre_rolling_force_n(v_hi_mps, inputs["axle"], t_hi_k) - tyre_rolling_force_n(v_lo_mps, inputs["axle"], t_lo_k)
    return spin, trr


def drag_area(f_hi: float, f_lo_pair: float, v2_air_hi: float, v2_air_lo_pair: float, temperature_k: float,
              pressure_pa: float, delta_f_spin_n: float = 0.0, delta_f_trr_n: float = 0.0) -> float:
    """Eq. 1037.528-16 (form reconstructed, module docstring): CdA (m^2) of one high-speed range."""
    rho = pressure_pa / (GAS_CONSTANT_J_PER_KG_K * temperature_k)
    return ((f_hi - f_lo_pair) - (delta_f_spin_n + delta_f_trr_n)) / (0.5 * rho * (v2_air_hi - v2_air_lo_pair))


@dataclass(frozen=True)
class _Range:
    force_n: float
    v2_air: float
    yaw_deg: float
    temperature_k: float
    pressure_pa: float
    mean_speed_mps: float


def _range(g: pd.DataFrame, filt: dict[str, np.ndarray], m_e: float, mass_kg: float, nominal: tuple[float, float],
           ambient: tuple[float, float]) -> _Range | None:
    """The range ``nominal`` of run ``g`` from its Hampel-filtered channels ``filt``, or None."""
    t = g["time_s"].to_numpy(float)
    start = speed_point(t, filt["speed_mps"], nominal[0] * config.MPH_TO_MPS)
    end = speed_point(t, filt["speed_mps"], nominal[1] * config.MPH_TO_MPS)
    if start is None or end is None:
        return None
    grade = {}
    if {"elevation_m", "distance_m"} <= set(g.columns):
        for key, (_, tp) in (("start", start), ("end", end)):
            grade[f"h_{key}"] = float(np.interp(tp, t, g["elevation_m"].to_numpy(float)))
            grade[f"d_{key}"] = float(np.interp(tp, t, g["distance_m"].to_numpy(float)))
    force = range_force(m_e, mass_kg, start[0], end[0], start[1], end[1], **grade)
    inside = (t >= start[1]) & (t <= end[1])
    temperature = float(g["temperature_k"][inside].mean()) if "temperature_k" in g else ambient[0]
    pressure = float(g["pressure_pa"][inside].mean()) if "pressure_pa" in g else ambient[1]
    return _Range(force, float(np.mean(filt["airspeed_mps"][inside] ** 2)),
                  float(np.degrees(np.abs(np.mean(filt["yaw_rad"][inside])))), temperature, pressure,
                  float(np.mean(filt["speed_mps"][inside])))


def segment_drag_areas(campaign: Campaign, tyres_in_contact: int, *, delta_f_spin_n: float = 0.0,
                       delta_f_trr_n: float = 0.0) -> pd.DataFrame:
    """Per high-speed range of every run: ``run, pair, direction, F_hi_N, F_lo_pair_N,
    v2_air_hi, v2_air_lo_pair, yaw_deg, temperature_k, pressure_pa, v_seg_hi_mps,
    v_seg_lo_pair_mps, delta_f_spin_n, delta_f_trr_n, CdA_m2`` ((h)(1)-(h)(10)).

    dF_spin and dF_TRR: from the campaign's ``[cfr1037]`` inputs (``meta["cfr1037"]``) per range,
    at the high segment's and the pair's low segments' mean speed (and air temperature), where
    the inputs give them; else the constants ``delta_f_spin_n``, ``delta_f_trr_n``.  A constant
    other than 0 for a part the inputs give is refused as ambiguous.

    Each run gives the ranges it passes through: both (complete runs, (d)(1)) or one (split
    runs, (d)(2): high-speed segments and low-speed segments logged as runs of their own).  The
    low range of a pair is the mean over the pair's low ranges ((h)(8): two for complete runs
    or one split segment per direction, four for two), and every high range of the pair is
    divided by it.  A pair is the ``pair`` column's group of runs when the column is there (of
    any size: split segments of both directions), else :meth:`Campaign.pairs`; a run without a
    pair is its own.  High ranges of a pair without a low range are left out.  Air temperature
    and pressure come from ``temperature_k`` / ``pressure_pa`` when logged, else the project's
    reference conditions are taken.  The airspeed and yaw are the readings calibrated by the
    campaign's anemometer factors (:meth:`~bayes_roadload.data.vehicle.Anemometer.calibrated_air`,
    as every other use of them), then Hampel-filtered with the speed."""
    if not campaign.has_anemometer:
        raise ValueError("40 CFR 1037.528 needs the on-board airspeed and yaw ((f)); the campaign has none")
    inputs = campaign.meta.get(CFR1037_TABLE) or {}
    for part, key, value in (("axle_spin_loss_coefficients", "--delta-f-spin-n", delta_f_spin_n),
                             ("axle", "--delta-f-trr-n", delta_f_trr_n)):
        if part in inputs and value != 0.0:
            raise ValueError(f"{key} {value:g} and vehicle.toml [cfr1037] {part} both give the correction: "
                             "ambiguous; give one")
    runs = campaign.runs
    m_e = effective_mass_kg(campaign.vehicle.mass_kg, tyres_in_contact)
    # without temperature_k / pressure_pa columns the air is taken at the project's reference
    # conditions (the result's ``ambient_logged`` says which)
    ambient = (config.REFERENCE_TEMPERATURE_K, config.REFERENCE_PRESSURE_PA)
    directions = campaign.directions()
    if "pair" in runs:
        pair_of = runs.groupby("run", sort=False)["pair"].first().to_dict()
    else:
        pair_of = {r: i for i, pair in enumerate(campaign.pairs()) for r in pair}
    highs, lows = [], {}
    for rid, g in runs.groupby("run", sort=False):
        pair = pair_of.get(rid, f"unpaired {rid}")
        t = g["time_s"].to_numpy(float)
        air, yaw = campaign.anemometer.calibrated_air(g["airspeed_mps"], g["yaw_rad"])
        filt = {c: hampel_filter(t, x) for c, x in
                (("speed_mps", g["speed_mps"].to_numpy(float)), ("airspeed_mps", air), ("yaw_rad", yaw))}
        hi = _range(g, filt, m_e, campaign.vehicle.mass_kg, HIGH_RANGE_MPH, ambient)
        lo = _range(g, filt, m_e, campaign.vehicle.mass_kg, LOW_RANGE_MPH, ambient)
        if lo is not None:
            lows.setdefault(pair, []).append(lo)
        if hi is not None:
            highs.append({"run": rid, "pair": pair, "direction": directions.get(rid, 0), "F_hi_N": hi.force_n,
                          "v2_air_hi": hi.v2_air, "yaw_deg": hi.yaw_deg, "temperature_k": hi.temperature_k,
                          "pressure_pa": hi.pressure_pa, "v_seg_hi_mps": hi.mean_speed_mps})
    cols = ["run", "pair", "direction", "F_hi_N", "F_lo_pair_N", "v2_air_hi", "v2_air_lo_pair", "yaw_deg",
            "temperature_k", "pressure_pa", "v_seg_hi_mps", "v_seg_lo_pair_mps", "delta_f_spin_n", "delta_f_trr_n",
            "CdA_m2"]
    rows = []
    for h in highs:
        if h["pair"] not in lows:
            continue
        low = lows[h["pair"]]
        v_lo = float(np.mean([lo.mean_speed_mps for lo in low]))
        spin, trr = delta_forces_n(inputs, h["v_seg_hi_mps"], v_lo, h["temperature_k"],
                                   float(np.mean([lo.temperature_k for lo in low])))
        rows.append(dict(h, F_lo_pair_N=float(np.mean([lo.force_n for lo in low])),
                         v2_air_lo_pair=float(np.mean([lo.v2_air for lo in low])), v_seg_lo_pair_mps=v_lo,
                         delta_f_spin_n=delta_f_spin_n if math.isnan(spin) else spin,
                         delta_f_trr_n=delta_f_trr_n if math.isnan(trr) else trr))
    if not rows:
        return pd.DataFrame(columns=cols)
    df = pd.DataFrame(rows)
    df["CdA_m2"] = [drag_area(r.F_hi_N, r.F_lo_pair_N, r.v2_air_hi, r.v2_air_lo_pair, r.temperature_k,
                              r.pressure_pa, r.delta_f_spin_n, r.delta_f_trr_n) for r in df.itertuples()]
    return df[cols]


def runs_without_a_range(campaign: Campaign) -> list:
    """Runs that pass through neither the 70 -> 60 nor the 20 -> 10 mi/h range with their
    end-point bands ((d): a complete run covers 72 -> 8 mi/h, a split segment 72 -> 58 or
    22 -> 8 mi/h)."""
    out = []
    for rid, g in campaign.runs.groupby("run", sort=False):
        t, v = g["time_s"].to_numpy(float), g["speed_mps"].to_numpy(float)
        if not any(speed_point(t, v, a * config.MPH_TO_MPS) is not None and
                   speed_point(t, v, b * config.MPH_TO_MPS) is not None for a, b in (HIGH_RANGE_MPH, LOW_RANGE_MPH)):
            out.append(rid)
    return out


def final_drag_area(segments: pd.DataFrame) -> dict:
    """(h)(11): the ranges kept (``kept`` column added), the effective yaw angle (deg, mean |yaw|
    of the kept ranges rounded to 0.1 deg), the final CdA (their mean, m^2), its standard error
    (sd / sqrt(n), not a clause of the regulation) and ``enough`` (n >= 24)."""
    seg = segments.copy()
    keep = np.isfinite(seg["CdA_m2"].to_numpy(float))
    if keep.any():
        med = float(np.median(seg["yaw_deg"][keep]))
        keep &= np.abs(seg["yaw_deg"].to_numpy(float) - med) <= YAW_BAND_DEG
    if keep.sum() > 1:
        cda = seg["CdA_m2"].to_numpy(float)
        mean, sd = cda[keep].mean(), cda[keep].std(ddof=1)
        keep &= np.abs(cda - mean) <= CDA_BAND_SD * sd
    seg["kept"] = keep
    n = int(keep.sum())
    cda = seg["CdA_m2"].to_numpy(float)[keep]
    return {"segments": seg, "n_points": n, "enough": n >= MIN_POINTS,
            "effective_yaw_deg": round(float(seg["yaw_deg"][keep].mean()), 1) if n else math.nan,
            "CdA_m2": float(cda.mean()) if n else math.nan,
            "CdA_se_m2": float(cda.std(ddof=1) / math.sqrt(n)) if n > 1 else math.nan}
