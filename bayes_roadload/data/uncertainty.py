"""The test's own uncertainty sources (Type B, GUM 4.3): declared values and instrument errors.

Each source is a standard uncertainty ``u`` of one declared value or instrument, with a default
taken from the accuracy the standards ask of the test (an accuracy limit ``a`` read as a
rectangular distribution, ``u = a / sqrt(3)``, GUM 4.3.7), and a transformation of the campaign
that shifts the source by ``delta`` (:meth:`UncertaintySource.apply`): the analysis of the
shifted campaign is the analysis of a test whose declared value or instrument was off by
``delta``.  ``vehicle.toml`` may state its own uncertainties in an ``[uncertainty]`` table (keys
as in :data:`SOURCES`, standard uncertainties in the key's unit; 0 switches a source off);
:func:`uncertainty_from_toml` validates it and the campaign carries it in
``meta["uncertainty"]``.  How the sources reach the posterior: :mod:`bayes_roadload.analysis.budget`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Mapping

from .checks import refuse

if TYPE_CHECKING:  # the campaign classes read vehicle.toml, whose [uncertainty] this module checks
    from .traces import Campaign

UNCERTAINTY_TABLE = "uncertainty"


def _scale_column(column: str) -> Callable[[Campaign, float], Campaign | None]:
    def apply(c: Campaign, delta: float) -> Campaign | None:
        if column not in c.runs:
            return None
        runs = c.runs.copy()
        runs[column] = runs[column] * (1.0 + delta)
        return dataclasses.replace(c, runs=runs)
    return apply


def _shift_column(column: str) -> Callable[[Campaign, float], Campaign | None]:
    def apply(c: Campaign, delta: float) -> Campaign | None:
        if column not in c.runs:
            return None
        runs = c.runs.copy()
        runs[column] = runs[column] + delta
        return dataclasses.replace(c, runs=runs)
    return apply


def _speed_scale(c: Campaign, delta: float) -> Campaign | None:
    runs = c.runs.copy()
    for col in ("speed_mps", "distance_m", "position_m"):
        if col in runs:
            runs[col] = runs[col] * (1.0 + delta)
    return dataclasses.replace(c, runs=runs)


def _airspeed_factor(c: Campaign, delta: float) -> Campaign | None:
    if "airspeed_mps" not in c.runs:
        return None
    return dataclasses.replace(c, anemometer=dataclasses.replace(
        c.anemometer, airspeed_factor=c.anemometer.airspeed_factor * (1.0 + delta)))


def _yaw_factor(c: Campaign, delta: float) -> Campaign | None:
    if "yaw_rad" not in c.runs:
        return None
    return dataclasses.replace(c, anemometer=dataclasses.replace(
        c.anemometer, yaw_factor=c.anemometer.yaw_factor * (1.0 + delta)))


def _mass(c: Campaign, delta: float) -> Campaign | None:
    v = c.vehicle
    runs = c.runs
    if "mass_kg" in runs:
        runs = runs.copy()
        runs["mass_kg"] = runs["mass_kg"] + delta
    return dataclasses.replace(c, runs=runs, vehicle=dataclasses.replace(
        v, mass_kg=v.mass_kg + delta, effective_mass_kg=v.effective_mass_kg + delta))


def _rotating_inertia(c: Campaign, delta: float) -> Campaign | None:
    v = c.vehicle
    rotating = v.effective_mass_kg - v.mass_kg
    return dataclasses.replace(c, vehicle=dataclasses.replace(
        v, effective_mass_kg=v.mass_kg + rotating * (1.0 + delta)))


@dataclass(frozen=True)
class UncertaintySource:
    """One Type B source: its key in ``[uncertainty]`` (unit in the name), its default standard
    uncertainty, the accuracy it comes from, and the campaign transformation.

    ``apply(campaign, delta)`` returns the campaign with the source shifted by ``delta`` (in
    the key's unit), or None when the campaign has nothing the source acts on (no airspeed
    channel for the anemometer's factor, no temperature channel, ...)."""

    key: str
    default: float
    accuracy: str
    transform: Callable[[Campaign, float], Campaign | None]

    def apply(self, campaign: Campaign, delta: float) -> Campaign | None:
        return self.transform(campaign, float(delta))


_SQRT3 = math.sqrt(3.0)

SOURCES: dict[str, UncertaintySource] = {s.key: s for s in (
    UncertaintySource("speed_scale_rel", 0.0017 / _SQRT3,
                      "SAE J2263 vehicle speed +-0.2 km/h, as a scale error at 115 km/h (+-0.17 %)", _speed_scale),
    UncertaintySource("airspeed_factor_rel", 0.0093 / _SQRT3,
                      "SAE J2263 relative wind speed +-1 km/h, as a factor error at 108 km/h (+-0.93 %)",
                      _airspeed_factor),
    UncertaintySource("yaw_offset_rad", math.radians(1.0) / _SQRT3,
                      "SAE J2263 yaw +-3 deg, of which a +-1 deg offset", _shift_column("yaw_rad")),
    UncertaintySource("yaw_factor_rel", 0.10 / _SQRT3,
                      "SAE J2263 yaw +-3 deg, of which a +-10 % factor (2.5 deg at 15 deg)", _yaw_factor),
    UncertaintySource("mass_kg", math.sqrt(2.0) * 5.0 / _SQRT3,
                      "SAE J1263 vehicle mass +-5 kg per axle, two axles independent", _mass),
    UncertaintySource("rotating_inertia_rel", 0.10 / _SQRT3,
                      "rotating inertia +-10 % (J2263's 1.03 M default spans 1-1.5 % of M on M_e)",
                      _rotating_inertia),
    UncertaintySource("temperature_k", 1.0 / _SQRT3, "SAE J1263 ambient temperature +-1 C",
                      _shift_column("temperature_k")),
    UncertaintySource("pressure_pa", 700.0 / _SQRT3, "SAE J1263 atmospheric pressure +-0.7 kPa",
                      _shift_column("pressure_pa")),
    UncertaintySource("driveline_scale_rel", 0.01 / _SQRT3, "wheel-torque transducer +-1 % (class 0.5-1)",
                      _scale_column("driveline_force_n")),
)}
"""Every Type B source by its ``[uncertainty]`` key."""


def uncertainty_from_toml(table: Mapping[str, Any] | None, where: str) -> dict[str, float]:
    """The validated ``[uncertainty]`` table: key -> standard uncertainty (key's unit).
    Unknown keys, non-numbers and negative values are refused naming the file and the key."""
    out: dict[str, float] = {}
    for k, val in dict(table or {}).items():
        if k not in SOURCES:
            refuse(where, f"[{UNCERTAINTY_TABLE}] {k}", None, f"unknown key; known: {', '.join(SOURCES)}")
        if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(float(val)):
            refuse(where, f"[{UNCERTAINTY_TABLE}] {k}", None, f"{val!r} is not a number")
        if float(val) < 0.0:
            refuse(where, f"[{UNCERTAINTY_TABLE}] {k}", None, f"{val!r} is negative (a standard uncertainty)")
        out[k] = float(val)
    return out


def standard_uncertainties(campaign: Campaign) -> dict[str, float]:
    """Every source's standard uncertainty for ``campaign``: its ``[uncertainty]`` values
    (``meta["uncertainty"]``) over the defaults."""
    stated = campaign.meta.get(UNCERTAINTY_TABLE) or {}
    return {k: float(stated.get(k, s.default)) for k, s in SOURCES.items()}
