"""The road-load result in the terms of a test standard, and the standard's checks on a campaign.

One table, :data:`STANDARDS`, says per standard its reference conditions, units, mass
convention, wind limits, run counts and precision criterion.  The facts and their sources are
in ``docs/standards.md``; a value marked "not verified" there is a placeholder, not a clause.

From the project's reference road load (F0, F1, F2 at 100 kPa / 293.2 K in N and km/h, see
:mod:`bayes_roadload.physics.roadload`) to a standard's conditions, draw by draw:

* aerodynamic term (all of f2, still air): ``f2' = f2 rho(T', p') / rho(T_ref, p_ref)``
  with ``rho = p / (R T)`` (:func:`~bayes_roadload.physics.atmosphere.air_density_kgpm3`);
* tyre term (f0, f1): ``f' = f [1 - K_T (T' - T_ref)]`` (eq. 2.38, K_T = 0.0086 /K), applied to
  the whole of f0 and f1 (the driveline and undriven-wheel shares are not split off);
* mass convention: a coastdown measures ``F = -M_e dv/dt``, so every coefficient scales by
  ``M_e(standard) / M_e(fit)`` (J2263: ``M_e = 1.03 M`` when the rotating inertia is unknown);
* units: 1 lbf = 4.44822 N, 1 mph = 1.609344 km/h:
  ``A = f0 / 4.44822``, ``B = f1 1.609344 / 4.44822``, ``C = f2 1.609344^2 / 4.44822``;
* drag area: ``CdA = 2 f2 3.6^2 / rho`` (m^2; f2 in N/(km/h)^2).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd

from .. import config
from ..data.campaign import Campaign
from ..data.heavy_duty import CFR1037_TABLE
from ..physics.atmosphere import REFERENCE_AIR_DENSITY_KGPM3
from . import cfr1037
from .cycles import COEFFICIENTS
from .regulation import (
    GTR_MIN_SPEED_RATE_HZ,
    GTR_ROTATING_MASS_OFFSET_KG,
    GTR_ROTATING_MASS_SHARE,
    GTR_ONBOARD_MIN_PAIRS,
    GTR_PRECISION_PCT,
    MIN_REGULATION_PAIRS,
    gtr15_precision,
)

LBF_N = 4.44822
MPH_KPH = 1.609344
J2263_MASS_FACTOR = 1.03


@dataclass(frozen=True)
class Standard:
    """A test standard's conventions (SI inside; ``units`` names the reported units).

    ``mass_factor``: M_e = factor x test mass when the rotating inertia is unknown (None: the
    fit's M_e is kept).  Wind limits in m/s (None: no limit applied).  ``min_runs_per_direction``
    and ``min_pairs`` are the run counts checked; ``precision_pct`` the GTR 15 statistical
    precision limit when the standard uses it.  ``speed_range_kph = (high, low)``: the coastdown
    starts at or above ``high`` and is recorded down to ``low`` or below, by every run
    (``speed_range_per_run``) or by the runs together (split runs allowed: their ranges must
    leave no gap between the two speeds).  ``two_term``: the standard's coastdown regression has
    no linear term (F = A + C v^2, B = 0): the coefficients are the least-squares projection of
    the road-load curve onto {1, v^2} over ``speed_range_kph`` (:func:`two_term_projection`).
    ``mass_per_tyre_kg``: M_e = M + this x the tyres in contact (instead of ``mass_factor``).
    ``rotating_mass_share``, ``rotating_mass_offset_kg``: M_e = M + share x (mass in running order
    + offset) when the vehicle states its mass in running order (GTR 15's estimate of m_r), the
    fit's M_e otherwise.
    ``max_mean_along_wind_mps``: limit of each run's mean wind component along the road;
    ``min_rate_hz``: the slowest recording rate allowed.  ``min_pairs_onboard``: the pairs needed
    instead of ``min_pairs`` when the campaign has on-board anemometry.  ``segment_method``: the standard's
    own drag-area arithmetic is run on the campaign too (:mod:`~bayes_roadload.analysis.cfr1037`).
    """

    name: str
    title: str
    temperature_k: float
    pressure_pa: float
    units: str  # "SI_kph" (N, km/h) or "US" (lbf, mph)
    result: str  # "coefficients" or "cda"
    mass_factor: float | None = None
    max_mean_wind_mps: float | None = None
    max_mean_crosswind_mps: float | None = None
    ambient_range_k: tuple[float, float] | None = None
    min_runs_per_direction: int = 1
    min_pairs: int = 0
    precision_pct: float | None = None
    air_density_kgpm3: float | None = None
    cda_yaw_deg: float | None = None
    speed_range_kph: tuple[float, float] | None = None
    speed_range_per_run: bool = False
    two_term: bool = False
    mass_per_tyre_kg: float | None = None
    max_mean_along_wind_mps: float | None = None
    min_rate_hz: float | None = None
    min_pairs_onboard: int = 0
    segment_method: bool = False
    rotating_mass_share: float | None = None
    rotating_mass_offset_kg: float = 0.0

    @property
    def density_kgpm3(self) -> float:
        """The aerodynamic reference density: the standard's own figure when it states one,
        else p / (R T) at its reference conditions."""
        if self.air_density_kgpm3 is not None:
            return self.air_density_kgpm3
        return air_density(self.temperature_k, self.pressure_pa)


STANDARDS: dict[str, Standard] = {
    "gtr15": Standard("gtr15", "UN GTR 15 (WLTP) Annex 4", 293.15, 100_000.0, "SI_kph", "coefficients",
                      min_pairs=MIN_REGULATION_PAIRS, precision_pct=GTR_PRECISION_PCT,
                      min_pairs_onboard=GTR_ONBOARD_MIN_PAIRS, min_rate_hz=GTR_MIN_SPEED_RATE_HZ,
                      max_mean_wind_mps=config.WIND_LIMITS["gtr_onboard"]["mean_wind_mps"],
                      max_mean_crosswind_mps=config.WIND_LIMITS["gtr_onboard"]["mean_cross_wind_mps"],
                      rotating_mass_share=GTR_ROTATING_MASS_SHARE, rotating_mass_offset_kg=GTR_ROTATING_MASS_OFFSET_KG),
    "j2263": Standard("j2263", "SAE J2263 (on-board anemometry)", 293.15, 98_210.0, "US", "coefficients",
                      mass_factor=J2263_MASS_FACTOR, min_runs_per_direction=1, speed_range_kph=(115.0, 15.0)),
    "j1263": Standard("j1263", "SAE J1263 (stationary wind station)", 293.15, 98_210.0, "US", "coefficients",
                      max_mean_wind_mps=16.0 * config.KPH_TO_MPS, max_mean_crosswind_mps=8.0 * config.KPH_TO_MPS,
                      ambient_range_k=(278.15, 308.15), min_runs_per_direction=1),
    "cfr1066": Standard("cfr1066", "40 CFR 1066.310 / 1037.528 (heavy vehicles, CdA)", 293.15, 98_210.0, "US",
                        "cda", mass_factor=J2263_MASS_FACTOR, min_runs_per_direction=8,
                        air_density_kgpm3=1.17, cda_yaw_deg=4.5,
                        speed_range_kph=(70.0 * MPH_KPH, 15.0 * MPH_KPH), speed_range_per_run=True,
                        two_term=True),
    "cfr1037": Standard("cfr1037", "40 CFR 1037.528 (Phase 2 tractors, CdA)", 293.15, 98_210.0, "US", "cda",
                        mass_per_tyre_kg=cfr1037.MASS_PER_TYRE_KG, min_runs_per_direction=cfr1037.MIN_POINTS // 2,
                        cda_yaw_deg=4.5, max_mean_along_wind_mps=cfr1037.MAX_MEAN_ALONG_WIND_MPH * config.MPH_TO_MPS,
                        min_rate_hz=cfr1037.MIN_RATE_HZ, segment_method=True),
}
"""Per standard.  J1263's reference conditions are taken equal to J2263's (not verified);
40 CFR 1066.310 follows J1263 / J2263 (hence their temperature and mass convention), states a
reference air density of 1.17 kg/m^3 for its drag coefficient, and 40 CFR 1037.305(a)(4) adjusts
each run's drag area to +-4.5 deg yaw for the wind-averaged CdA.  Speed ranges: SAE J2263
115 -> 15 km/h (split runs allowed where the track is short); 40 CFR 1066.310 each run from
70 mph or above down to 15 mph or below (STANDARDS_FACTS.md).  40 CFR 1066.310's road-load
coefficients are A = A_m, B = 0, C = D_adj (the intercept and the density-adjusted slope of the
force against v^2; eCFR text found by search), hence ``two_term``.  40 CFR 1037.528 (Phase 2
tractors; text of 81 FR 74048 as amended to 89 FR 29783, found by search): M_e = M + 56.7 kg per
tyre in contact ((h)(1)); complete runs from above 72.0 down to 8.0 mi/h or split segments
72 -> 58 and 22 -> 8 mi/h ((d); checked by the segment method, every run through one range); the
mean wind along the road at most 6.0 mi/h per run ((c)(2)); 10 Hz recording ((d)); at least 24
high-speed ranges after the (h)(11) eliminations, with the same number of runs in each
direction ((d)(2)), hence 12 per direction; its temperature and pressure are J2263's (it
follows J2263 sections 1-9) and serve only the coefficient rows: its result is a drag area.
GTR 15 (as transposed in Regulation (EU) 2017/1151 Annex XXI Sub-Annex 4, text found by search):
5 pairs with on-board anemometry (4.3.2.4), vehicle speed at 10 Hz or more (3.1(a)), the rotating
mass estimated as 3 % of (mass in running order + 25 kg) when it is not measured (2.5.1); its wind
limits are ``config.WIND_LIMITS["gtr_onboard"]`` (mean and cross-wind; the figures are not in the
text found, see there)."""


def get_standard(name: str | Standard) -> Standard:
    if isinstance(name, Standard):
        return name
    key = str(name).lower()
    if key not in STANDARDS:
        raise ValueError(f"unknown standard {name!r}: choose from {', '.join(STANDARDS)}")
    return STANDARDS[key]


def air_density(temperature_k: float, pressure_pa: float) -> float:
    """rho = p / (R T), kg/m^3 (same law as physics.atmosphere, for plain floats)."""
    return pressure_pa / (config.GAS_CONSTANT_AIR_J_PER_KG_K * temperature_k)


def to_conditions(samples: Mapping[str, np.ndarray], temperature_k: float, pressure_pa: float, *,
                  mass_scale: float = 1.0, air_density_kgpm3: float | None = None) -> dict[str, np.ndarray]:
    """F0/F1/F2 draws (reference conditions) at other ambient conditions and effective mass
    (module docstring); same keys and units.  ``air_density_kgpm3`` overrides p / (R T) for
    the aerodynamic term."""
    tyre = 1.0 - config.TYRE_TEMPERATURE_COEFF_PER_K * (temperature_k - config.REFERENCE_TEMPERATURE_K)
    rho = air_density(temperature_k, pressure_pa) if air_density_kgpm3 is None else air_density_kgpm3
    aero = rho / REFERENCE_AIR_DENSITY_KGPM3
    f0, f1, f2 = (np.asarray(samples[k], float).reshape(-1) for k in COEFFICIENTS)
    return {"F0_N": f0 * tyre * mass_scale, "F1_N_per_kph": f1 * tyre * mass_scale,
            "F2_N_per_kph2": f2 * aero * mass_scale}


def to_us_units(f0_n, f1_n_per_kph, f2_n_per_kph2):
    """(A lbf, B lbf/mph, C lbf/mph^2) from (f0 N, f1 N/(km/h), f2 N/(km/h)^2)."""
    return (np.asarray(f0_n) / LBF_N, np.asarray(f1_n_per_kph) * MPH_KPH / LBF_N,
            np.asarray(f2_n_per_kph2) * MPH_KPH**2 / LBF_N)


def drag_area_m2(f2_n_per_kph2, air_density_kgpm3: float):
    """CdA = 2 f2 3.6^2 / rho (m^2)."""
    return 2.0 * np.asarray(f2_n_per_kph2) * 3.6**2 / air_density_kgpm3


def standard_effective_mass_kg(std: Standard, mass_kg: float | None, mass_in_running_order_kg: float | None,
                               rotating_inertia_known: bool = False) -> float | None:
    """GTR 15's estimate of the effective mass, M + 0.03 (mass in running order + 25 kg)
    (``Standard.rotating_mass_share``), or None where it does not apply: a standard without the
    rule, a measured rotating inertia, or no mass in running order stated (the fit's M_e then
    stands)."""
    if std.rotating_mass_share is None or rotating_inertia_known or mass_in_running_order_kg is None \
            or mass_kg is None:
        return None
    return float(mass_kg) + std.rotating_mass_share * (float(mass_in_running_order_kg) + std.rotating_mass_offset_kg)


def _row(quantity, unit, x) -> dict:
    x = np.asarray(x, float).reshape(-1)
    return {"quantity": quantity, "unit": unit, "mean": float(x.mean()),
            "sd": float(x.std(ddof=1)) if x.size > 1 else math.nan,
            "q2.5": float(np.quantile(x, 0.025)), "q97.5": float(np.quantile(x, 0.975))}


def mass_scale(std: "Standard", *, mass_kg: float | None, effective_mass_kg: float | None,
               rotating_inertia_known: bool = False, tyres_in_contact: int | None = None,
               mass_in_running_order_kg: float | None = None) -> float:
    """The factor M_e(standard) / M_e(fit) by which a fitted force is rescaled to the standard's
    mass convention (1 where the fit's M_e stands): ``mass_factor`` x M, M + ``mass_per_tyre_kg``
    per tyre in contact, or GTR 15's :func:`standard_effective_mass_kg`."""
    scale = 1.0
    if std.mass_factor is not None and not rotating_inertia_known:
        if mass_kg is None or effective_mass_kg is None:
            raise ValueError(f"{std.name}: the mass convention M_e = {std.mass_factor} x M needs mass_kg "
                             "and the fit's effective_mass_kg (or rotating_inertia_known=True)")
        scale = std.mass_factor * mass_kg / effective_mass_kg
    if std.mass_per_tyre_kg is not None and not rotating_inertia_known:
        if mass_kg is None or effective_mass_kg is None or tyres_in_contact is None:
            raise ValueError(f"{std.name}: the effective mass M + {std.mass_per_tyre_kg} kg per tyre in contact needs "
                             "the number of tyres: [vehicle] tyres_in_contact in vehicle.toml or --tyres-in-contact N "
                             "(or --rotating-inertia-known to keep the fit's effective mass)")
        scale = (mass_kg + std.mass_per_tyre_kg * int(tyres_in_contact)) / effective_mass_kg
    me = standard_effective_mass_kg(std, mass_kg, mass_in_running_order_kg, rotating_inertia_known)
    if me is not None:
        if effective_mass_kg is None:
            raise ValueError(f"{std.name}: rescaling to its effective mass needs the fit's effective_mass_kg")
        scale = me / effective_mass_kg
    return scale


def standard_coefficients(samples: Mapping[str, np.ndarray], standard: str | Standard,
                          scale: float = 1.0) -> dict[str, np.ndarray]:
    """The F0/F1/F2 draws (SI, per km/h) in the standard's terms: at its reference temperature,
    pressure and air density (:func:`to_conditions`), rescaled by ``scale`` to its mass
    convention (:func:`mass_scale`), and, for a two-term standard, projected onto {1, v^2}
    over its speed range (:func:`two_term_projection`)."""
    std = get_standard(standard)
    c = to_conditions(samples, std.temperature_k, std.pressure_pa, mass_scale=scale,
                      air_density_kgpm3=std.density_kgpm3)
    if std.two_term:
        alpha, beta = two_term_projection(std.speed_range_kph)
        f1 = np.asarray(c["F1_N_per_kph"], float)
        c = dict(c, F0_N=np.asarray(c["F0_N"], float) + alpha * f1, F1_N_per_kph=np.zeros_like(f1),
                 F2_N_per_kph2=np.asarray(c["F2_N_per_kph2"], float) + beta * f1)
    return c


def standard_result(samples: Mapping[str, np.ndarray], standard: str | Standard, *,
                    mass_kg: float | None = None, effective_mass_kg: float | None = None,
                    rotating_inertia_known: bool = False, frontal_area_m2: float | None = None,
                    yaw_deg: float | None = None, tyres_in_contact: int | None = None,
                    extra_yaw_deg: Mapping[str, float] | None = None,
                    mass_in_running_order_kg: float | None = None) -> pd.DataFrame:
    """The standard's result quantities with posterior mean, sd, 2.5 and 97.5 % points.

    Parameters
    ----------
    samples : draws of ``F0_N, F1_N_per_kph, F2_N_per_kph2`` at the project's reference
        conditions (from :func:`load_draws`); ``CD0`` and ``KD`` draws, when present, give
        CdA at ``yaw_deg``.
    standard : a key of :data:`STANDARDS` or a :class:`Standard`.
    mass_kg, effective_mass_kg : the test mass and the M_e the fit used; with
        ``rotating_inertia_known`` False and a standard with a ``mass_factor``, coefficients are
        rescaled to M_e = factor x mass_kg (with a ``mass_per_tyre_kg`` standard: to
        M_e = mass_kg + mass_per_tyre_kg x ``tyres_in_contact``; with a ``rotating_mass_share``
        standard and ``mass_in_running_order_kg`` given: M_e = mass_kg + share x (that mass +
        offset)).
    frontal_area_m2, yaw_deg : for CdA(yaw) = A (CD0 + KD yaw^2).
    extra_yaw_deg : more CdA(yaw) rows, ``{label: yaw in deg}`` (quantity ``CdA_yaw_<label>``).

    Returns
    -------
    DataFrame ``standard, quantity, unit, mean, sd, q2.5, q97.5``.
    """
    std = get_standard(standard)
    scale = mass_scale(std, mass_kg=mass_kg, effective_mass_kg=effective_mass_kg,
                       rotating_inertia_known=rotating_inertia_known, tyres_in_contact=tyres_in_contact,
                       mass_in_running_order_kg=mass_in_running_order_kg)
    c = standard_coefficients(samples, std, scale)
    yaw_deg = std.cda_yaw_deg if yaw_deg is None else yaw_deg
    rows = []
    if std.units == "SI_kph":
        rows += [_row("f0", "N", c["F0_N"]), _row("f1", "N/(km/h)", c["F1_N_per_kph"]),
                 _row("f2", "N/(km/h)^2", c["F2_N_per_kph2"])]
    else:
        a, b, cc = to_us_units(c["F0_N"], c["F1_N_per_kph"], c["F2_N_per_kph2"])
        rows += [_row("A", "lbf", a), _row("B", "lbf/mph", b), _row("C", "lbf/mph^2", cc)]
    if std.result == "cda":
        rows.append(_row("CdA_zero_yaw", "m^2", drag_area_m2(c["F2_N_per_kph2"], std.density_kgpm3)))
        yaws = {} if yaw_deg is None else {f"{yaw_deg:g}deg": yaw_deg}
        yaws.update(extra_yaw_deg or {})
        if yaws and frontal_area_m2 is not None and "CD0" in samples and "KD" in samples:
            for label, deg in yaws.items():
                # C_D(psi) = CD0 + KD psi^2 (eq. 2.31) is even in psi: the mean over +-psi is its value at psi;
                # a fitted force scales with the effective mass it was fitted at, so CdA(psi) takes the
                # standard's mass convention as CdA_zero_yaw does (``scale``)
                psi = math.radians(deg)
                cda = scale * frontal_area_m2 * (np.asarray(samples["CD0"], float)
                                                 + np.asarray(samples["KD"], float) * psi**2)
                rows.append(_row(f"CdA_yaw_{label}", "m^2", cda))
    out = pd.DataFrame(rows)
    out.insert(0, "standard", std.name)
    return out


TWO_TERM_GRID_POINTS = 200
"""Speeds of the uniform grid over which the road-load curve is projected onto {1, v^2}."""


def two_term_projection(speed_range_kph: tuple[float, float]) -> tuple[float, float]:
    """(alpha, beta) with v ~ alpha + beta v^2 in least squares over a uniform grid of
    ``speed_range_kph`` (km/h): the two-term fit of F0 + F1 v + F2 v^2 is then
    A = F0 + alpha F1, C = F2 + beta F1.  Uniform weighting in speed: the regulation's own
    weighting of its measurement intervals is not verified."""
    v = np.linspace(min(speed_range_kph), max(speed_range_kph), TWO_TERM_GRID_POINTS)
    design = np.column_stack([np.ones_like(v), v**2])
    alpha, beta = np.linalg.lstsq(design, v, rcond=None)[0]
    return float(alpha), float(beta)


def _check(rule: str, value, limit, passed: bool, unit: str = "") -> dict:
    return {"rule": rule, "value": value, "limit": limit, "unit": unit, "pass": bool(passed)}


def speed_range_per_run(campaign: Campaign) -> pd.DataFrame:
    """Per run of a speed-trace campaign: the highest and the lowest logged speed (km/h)."""
    g = campaign.runs.groupby("run", sort=False)["speed_mps"]
    return pd.DataFrame({"start_kph": g.max() / config.KPH_TO_MPS, "end_kph": g.min() / config.KPH_TO_MPS})


def uncovered_kph(ranges: pd.DataFrame, high: float, low: float) -> float:
    """Total speed (km/h) between ``low`` and ``high`` that no run's [end, start] range covers."""
    covered, top = 0.0, high
    for start, end in sorted(zip(ranges["start_kph"], ranges["end_kph"]), reverse=True):
        hi, lo = min(start, top), max(end, low)
        if hi > lo:
            covered += hi - lo
            top = lo
    return float(high - low - covered)


def wind_per_run(campaign: Campaign) -> pd.DataFrame:
    """Per run: mean head-wind and mean |cross-wind| (m/s) from the on-board airspeed and yaw
    (calibrated by the campaign's anemometer factors): head = v_r cos(psi) - v, cross = v_r sin(psi)."""
    rows = []
    for rid, g in campaign.runs.groupby("run", sort=False):
        vr, psi = campaign.anemometer.calibrated_air(g["airspeed_mps"], g["yaw_rad"])
        head = vr * np.cos(psi) - g["speed_mps"].to_numpy(float)
        cross = vr * np.sin(psi)
        rows.append({"run": rid, "head_mps": float(head.mean()), "cross_mps": float(np.abs(cross.mean())),
                     "wind_mps": float(np.hypot(head.mean(), cross.mean()))})
    return pd.DataFrame(rows)


def standard_checks(campaign: Campaign, standard: str | Standard) -> pd.DataFrame:
    """The standard's checks on the campaign, one row each: ``standard, rule, value, limit,
    unit, pass``.  Run counts per direction, opposite-direction pairs, GTR 15 statistical
    precision per reference speed (:func:`~bayes_roadload.analysis.regulation.gtr15_precision`),
    mean wind and cross-wind per run (worst run reported), the speed range (per run, or
    covered by the runs together: :func:`uncovered_kph`), ambient temperature range."""
    std = get_standard(standard)
    runs = campaign.runs
    rows = []
    directions = campaign.directions()
    counts = pd.Series(list(directions.values())).value_counts()
    for d in (1, -1):
        n = int(counts.get(d, 0))
        rows.append(_check(f"runs in direction {d:+d}", n, std.min_runs_per_direction,
                           n >= std.min_runs_per_direction, "runs"))
    if std.min_pairs or std.min_pairs_onboard:
        n_pairs = len(campaign.pairs())
        onboard = bool(std.min_pairs_onboard) and campaign.has_anemometer
        need = std.min_pairs_onboard if onboard else std.min_pairs
        rows.append(_check("opposite-direction pairs" + (" (on-board anemometry)" if onboard else ""), n_pairs,
                           need, n_pairs >= need, "pairs"))
    if std.precision_pct is not None and "pair" in runs:
        for r in gtr15_precision(campaign, limit_pct=std.precision_pct).itertuples():
            rows.append(_check(f"statistical precision at {r.speed_kph:g} km/h", r.precision_pct, r.limit_pct,
                               bool(r.precision_pct <= r.limit_pct), "%"))  # pair count: own row
    if (std.max_mean_wind_mps is not None or std.max_mean_crosswind_mps is not None) and campaign.has_anemometer:
        wind = wind_per_run(campaign)
        if std.max_mean_wind_mps is not None:
            worst = float(wind["wind_mps"].max())
            rows.append(_check("mean wind speed (worst run)", worst, std.max_mean_wind_mps,
                               worst <= std.max_mean_wind_mps, "m/s"))
        if std.max_mean_crosswind_mps is not None:
            worst = float(wind["cross_mps"].max())
            rows.append(_check("mean cross-wind (worst run)", worst, std.max_mean_crosswind_mps,
                               worst <= std.max_mean_crosswind_mps, "m/s"))
    if std.max_mean_along_wind_mps is not None:
        if campaign.has_anemometer:
            worst = float(wind_per_run(campaign)["head_mps"].abs().max())
            rows.append(_check("mean wind along the road (worst run, on-board estimate)", worst,
                               std.max_mean_along_wind_mps, worst <= std.max_mean_along_wind_mps, "m/s"))
        else:
            rows.append(_check("mean wind along the road: needs airspeed and yaw", math.nan,
                               std.max_mean_along_wind_mps, False, "m/s"))
    if std.min_rate_hz is not None and "time_s" in runs:
        dt = runs.groupby("run", sort=False)["time_s"].apply(
            lambda t: float(np.median(np.diff(t.to_numpy(float)))) if len(t) > 1 else math.nan)
        slowest = float(1.0 / dt.max())  # NaN (a failed check) when no run has two samples
        rows.append(_check("recording rate (slowest run)", slowest, std.min_rate_hz,
                           slowest >= std.min_rate_hz * (1 - 1e-6), "Hz"))
    if std.speed_range_kph is not None and "speed_mps" in runs:
        high, low = std.speed_range_kph
        ranges = speed_range_per_run(campaign)
        if std.speed_range_per_run:
            worst_start, worst_end = float(ranges["start_kph"].min()), float(ranges["end_kph"].max())
            rows.append(_check("start speed (lowest run)", worst_start, high, worst_start >= high, "km/h"))
            rows.append(_check("end speed (highest run)", worst_end, low, worst_end <= low, "km/h"))
        else:
            best_start, best_end = float(ranges["start_kph"].max()), float(ranges["end_kph"].min())
            gap = uncovered_kph(ranges, high, low)
            rows.append(_check("start speed (highest run)", best_start, high, best_start >= high, "km/h"))
            rows.append(_check("end speed (lowest run)", best_end, low, best_end <= low, "km/h"))
            rows.append(_check(f"speed range {high:g} -> {low:g} km/h not covered by any run", gap, 0.0,
                               gap <= 0.0, "km/h"))
    if std.ambient_range_k is not None and "temperature_k" in runs:
        lo, hi = std.ambient_range_k
        t = runs["temperature_k"].to_numpy(float)
        rows.append(_check("ambient temperature min", float(t.min()), lo, t.min() >= lo, "K"))
        rows.append(_check("ambient temperature max", float(t.max()), hi, t.max() <= hi, "K"))
    out = pd.DataFrame(rows, columns=["rule", "value", "limit", "unit", "pass"])
    out.insert(0, "standard", std.name)
    return out


def load_draws(fit_dir: str | Path) -> dict[str, np.ndarray]:
    """Flattened posterior draws of a NUTS fit directory (``posterior.nc``): the road-load
    coefficients and every scalar parameter."""
    import arviz as az  # heavy; only needed when reading a fit directory

    path = Path(fit_dir) / "posterior.nc"
    if not path.is_file():
        raise ValueError(f"{fit_dir}: no posterior.nc (a NUTS fit directory from `bayes-roadload fit`)")
    post = az.from_netcdf(str(path)).posterior
    return flat_draws({str(name): da.values for name, da in post.data_vars.items()}, path)


def flat_draws(samples: Mapping[str, np.ndarray], where: str | Path) -> dict[str, np.ndarray]:
    """The scalar parameters of posterior ``samples`` ([chain, draw] arrays; others left out)
    flattened over chains, refused naming ``where`` when the road-load coefficients are missing."""
    out = {k: np.asarray(v, float).reshape(-1) for k, v in samples.items() if np.ndim(v) == 2}
    missing = [k for k in COEFFICIENTS if k not in out]
    if missing:
        raise ValueError(f"{where}: posterior lacks {', '.join(missing)}")
    return out


def run_standard(source: str | Path | Mapping[str, np.ndarray], standard: str | Standard, *,
                 campaign: Campaign | None = None, mass_kg: float | None = None,
                 effective_mass_kg: float | None = None, rotating_inertia_known: bool = False,
                 frontal_area_m2: float | None = None, yaw_deg: float | None = None,
                 tyres_in_contact: int | None = None, delta_f_spin_n: float = 0.0, delta_f_trr_n: float = 0.0,
                 out_dir: str | Path | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Result and checks of ``standard`` for a fit directory (or draws) and its campaign.
    The vehicle's masses, frontal area and tyres in contact default to the campaign's.  A
    standard with a ``segment_method`` also runs its own drag-area arithmetic on the campaign
    (:func:`segment_method_result`): its final CdA joins the result (a point value with its
    standard error, no interval), the posterior's CdA at its effective yaw angle too, and its
    point count joins the checks.  With ``out_dir``, writes ``standard_result.csv``,
    ``standard_checks.csv``, ``standard.json`` (and ``standard_segments.csv``)."""
    std = get_standard(standard)
    draws = load_draws(source) if isinstance(source, (str, Path)) else source
    mass_in_running_order_kg = None if campaign is None else campaign.vehicle.mass_in_running_order_kg
    if campaign is not None:
        mass_kg = campaign.vehicle.mass_kg if mass_kg is None else mass_kg
        effective_mass_kg = campaign.vehicle.effective_mass_kg if effective_mass_kg is None else effective_mass_kg
        frontal_area_m2 = campaign.vehicle.frontal_area_m2 if frontal_area_m2 is None else frontal_area_m2
        tyres_in_contact = campaign.vehicle.tyres_in_contact if tyres_in_contact is None else tyres_in_contact
    segment = None
    if std.segment_method and campaign is not None:
        segment = segment_method_result(campaign, tyres_in_contact, delta_f_spin_n=delta_f_spin_n,
                                        delta_f_trr_n=delta_f_trr_n)
    extra = ({"effective": segment["effective_yaw_deg"]}
             if segment is not None and math.isfinite(segment["effective_yaw_deg"]) else None)
    result = standard_result(draws, std, mass_kg=mass_kg, effective_mass_kg=effective_mass_kg,
                             rotating_inertia_known=rotating_inertia_known, frontal_area_m2=frontal_area_m2,
                             yaw_deg=yaw_deg, tyres_in_contact=tyres_in_contact, extra_yaw_deg=extra,
                             mass_in_running_order_kg=mass_in_running_order_kg)
    checks = standard_checks(campaign, std) if campaign is not None else \
        pd.DataFrame(columns=["standard", "rule", "value", "limit", "unit", "pass"])
    if segment is not None:
        result = pd.concat([result, pd.DataFrame([segment["result_row"]])], ignore_index=True)
        checks = pd.concat([checks, pd.DataFrame(segment["check_rows"])], ignore_index=True)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        result.to_csv(out / "standard_result.csv", index=False)
        checks.to_csv(out / "standard_checks.csv", index=False)
        record = {"standard": std.name, "title": std.title, "temperature_k": std.temperature_k,
                  "pressure_pa": std.pressure_pa, "units": std.units, "mass_factor": std.mass_factor,
                  "mass_per_tyre_kg": std.mass_per_tyre_kg, "tyres_in_contact": tyres_in_contact,
                  "rotating_inertia_known": rotating_inertia_known,
                  "mass_in_running_order_kg": mass_in_running_order_kg,
                  "effective_mass_kg_standard": standard_effective_mass_kg(std, mass_kg, mass_in_running_order_kg,
                                                                           rotating_inertia_known),
                  "effective_mass_kg_of_result": None if effective_mass_kg is None else effective_mass_kg * mass_scale(
                      std, mass_kg=mass_kg, effective_mass_kg=effective_mass_kg,
                      rotating_inertia_known=rotating_inertia_known, tyres_in_contact=tyres_in_contact,
                      mass_in_running_order_kg=mass_in_running_order_kg),
                  "pass": bool(checks["pass"].all())}
        if segment is not None:
            segment["segments"].to_csv(out / "standard_segments.csv", index=False)
            record["segment_method"] = {k: segment[k] for k in ("n_points", "effective_yaw_deg", "CdA_m2",
                                                                 "CdA_se_m2", "delta_f_spin_n", "delta_f_trr_n",
                                                                 "delta_f_spin_from", "delta_f_trr_from",
                                                                 "ambient_logged")}
        (out / "standard.json").write_text(json.dumps(record, indent=2) + "\n")
    return result, checks


def segment_method_result(campaign: Campaign, tyres_in_contact: int | None, *, delta_f_spin_n: float = 0.0,
                          delta_f_trr_n: float = 0.0) -> dict:
    """40 CFR 1037.528's own drag area on the campaign (:mod:`~bayes_roadload.analysis.cfr1037`):
    the (h)(11) outcome of :func:`~bayes_roadload.analysis.cfr1037.final_drag_area` plus
    ``result_row`` (``CdA_1037.528_segments``: the final CdA as mean, its standard error as sd,
    no interval) and ``check_rows`` (the (h)(11)(iv) point count; what stops the arithmetic,
    when something does)."""
    inputs = campaign.meta.get(CFR1037_TABLE) or {}
    base = {"standard": "cfr1037", "delta_f_spin_n": float(delta_f_spin_n), "delta_f_trr_n": float(delta_f_trr_n),
            "delta_f_spin_from": "[cfr1037] per range" if "axle_spin_loss_coefficients" in inputs else "constant",
            "delta_f_trr_from": "[cfr1037] per range" if "axle" in inputs else "constant",
            "ambient_logged": bool({"temperature_k", "pressure_pa"} <= set(campaign.runs.columns))}
    empty = {"segments": pd.DataFrame(), "n_points": 0, "effective_yaw_deg": math.nan, "CdA_m2": math.nan,
             "CdA_se_m2": math.nan}
    why = None
    if tyres_in_contact is None:
        why = "needs the tyres in contact ((h)(1)): [vehicle] tyres_in_contact or --tyres-in-contact"
    elif not campaign.has_anemometer:
        why = "needs the on-board airspeed and yaw ((f))"
    if why is not None:
        final = empty
        checks = [dict(base, **_check(f"1037.528(h) segment method {why}", math.nan, cfr1037.MIN_POINTS, False,
                                      "ranges"))]
    else:
        final = cfr1037.final_drag_area(cfr1037.segment_drag_areas(
            campaign, tyres_in_contact, delta_f_spin_n=delta_f_spin_n, delta_f_trr_n=delta_f_trr_n))
        kept = final["segments"][final["segments"]["kept"]] if final["n_points"] else final["segments"].iloc[:0]
        for part in ("spin", "trr"):   # per-range corrections: their mean over the ranges kept
            if base[f"delta_f_{part}_from"] != "constant" and len(kept):
                base[f"delta_f_{part}_n"] = float(kept[f"delta_f_{part}_n"].mean())
        missing = cfr1037.runs_without_a_range(campaign)
        checks = [dict(base, **_check("runs through neither 72 -> 58 nor 22 -> 8 mi/h", len(missing), 0,
                                      not missing, "runs")),
                  dict(base, **_check("high-speed ranges left after the (h)(11) eliminations", final["n_points"],
                                      cfr1037.MIN_POINTS, final["enough"], "ranges"))]
    row = {"standard": "cfr1037", "quantity": "CdA_1037.528_segments", "unit": "m^2", "mean": final["CdA_m2"],
           "sd": final["CdA_se_m2"], "q2.5": math.nan, "q97.5": math.nan}
    return dict(base, **final, result_row=row, check_rows=[{k: c[k] for k in
                                                            ("standard", "rule", "value", "limit", "unit", "pass")}
                                                           for c in checks])


def format_standard(result: pd.DataFrame, checks: pd.DataFrame) -> str:
    """Plain-text table of the result (mean [2.5 %, 97.5 %]) and the checks."""
    lines = []
    for _, r in result.iterrows():
        if np.isfinite(r["q2.5"]):
            spread = f"[{r['q2.5']:.5g}, {r['q97.5']:.5g}]"
        elif np.isfinite(r["mean"]):  # a point value of the standard's own arithmetic: its standard error
            spread = f"(the standard's method; standard error {r['sd']:.3g})"
        else:
            lines.append(f"  {r['quantity']:<16} {'-':>12} {r['unit']:<12} (the standard's method: not computed, "
                         "see the checks)")
            continue
        lines.append(f"  {r['quantity']:<16} {r['mean']:12.5g} {r['unit']:<12} {spread}")
    width = max([40] + [len(str(x)) for x in checks["rule"]])
    for _, r in checks.iterrows():
        verdict = "pass" if r["pass"] else "FAIL"
        lines.append(f"  {verdict}  {r['rule']:<{width}} {r['value']:10.4g} (limit {r['limit']:g} {r['unit']})")
    return "\n".join(lines)
