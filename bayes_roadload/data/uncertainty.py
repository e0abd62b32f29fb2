"""The test's own uncertainty sources (Type B, GUM 4.3): declared values and instrument errors.

Each source is a standard uncertainty ``u`` of one declared value or instrument, with a default
taken from the accuracy the standards ask of the test (an accuracy limit ``a`` read as a
rectangular distribution, ``u = a / sqrt(3)``, GUM 4.3.7), and a transformation of the campaign
that shifts the source by ``delta`` (:meth:`UncertaintySource.apply`): the analysis of the
shifted campaign is the analysis of a test whose declared value or instrument was off by
``delta``.  What a source acts on in each data kind is the campaign class's
:class:`TypeBChannels` (its speed-sensor and transducer columns, its vehicle or wheel inertias).  ``vehicle.toml`` may state its own uncertainties in an ``[uncertainty]`` table (keys
as in :data:`SOURCES`, standard uncertainties in the key's unit; 0 switches a source off);
:func:`uncertainty_from_toml` validates it and the campaign carries it in
``meta["uncertainty"]``.  How the sources reach the posterior: :mod:`bayes_roadload.analysis.budget`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping

from .checks import refuse

import pandas as pd

UNCERTAINTY_TABLE = "uncertainty"


@dataclass(frozen=True)
class TypeBChannels:
    """What of a campaign the Type B sources act on: every campaign class declares one as its
    class attribute ``type_b_channels`` (the data contract, docs/architecture.md).

    Attributes
    ----------
    table : the attribute holding the measured table (``runs``, ``intervals``, ``markers``);
        the temperature, pressure, yaw and per-run mass columns are shifted where it has them.
    speed : its columns read from the vehicle-speed sensor (scaled by ``speed_scale_rel``).
    force : its columns from a force or torque transducer (scaled by ``driveline_scale_rel``).
    vehicle : the campaign has a ``vehicle`` (declared mass and rotating inertia) and an
        ``anemometer`` (airspeed factor, yaw factor).
    wheel_inertia : the campaign declares wheel inertias ``wheel_inertia_kgm2`` (a spin-down),
        which ``rotating_inertia_rel`` scales.
    """

    table: str
    speed: tuple[str, ...] = ()
    force: tuple[str, ...] = ()
    vehicle: bool = True
    wheel_inertia: bool = False


def _channels(c) -> TypeBChannels:
    return type(c).type_b_channels


def _with_table(c, transform: Callable[[pd.DataFrame], pd.DataFrame | None]):
    ch = _channels(c)
    table = transform(getattr(c, ch.table).copy())
    return None if table is None else dataclasses.replace(c, **{ch.table: table})


def _scale_columns(columns_of: Callable[[TypeBChannels], tuple[str, ...]]) -> Callable[[Any, float], Any]:
    def apply(c, delta: float):
        def scale(t: pd.DataFrame) -> pd.DataFrame | None:
            cols = [col for col in columns_of(_channels(c)) if col in t]
            if not cols:
                return None
            for col in cols:
                t[col] = t[col] * (1.0 + delta)
            return t
        return _with_table(c, scale)
    return apply


def _shift_column(column: str, bounds: tuple[float, float] | None = None) -> Callable[[Any, float], Any]:
    """Shift ``column`` by ``delta``, kept inside ``bounds`` when given (a reading the contract
    refuses outside them: the relative humidity's 0-100 %)."""
    def apply(c, delta: float):
        def shift(t: pd.DataFrame) -> pd.DataFrame | None:
            if column not in t:
                return None
            t[column] = t[column] + delta if bounds is None else (t[column] + delta).clip(*bounds)
            return t
        return _with_table(c, shift)
    return apply


UNLOGGED_HUMIDITY_CENTRE_PCT = 50.0
"""Relative humidity (%) about which :func:`_unlogged_humidity` shifts: the middle of 0-100 %."""


def _unlogged_humidity(c, delta: float):
    """A campaign whose table logs the temperature and pressure but not the humidity, with
    ``relative_humidity_pct`` = :data:`UNLOGGED_HUMIDITY_CENTRE_PCT` + ``delta`` (clipped to
    0-100 %) added: its moist air (:func:`~bayes_roadload.data.ambient.air_density`) against the
    dry air the analysis takes.  None where the humidity is logged (its hygrometer is the source
    ``relative_humidity_pct``) or the density is not measured (no temperature or pressure
    column: the reference air)."""
    from .ambient import HUMIDITY_COLUMN, PRESSURE_COLUMN, TEMPERATURE_COLUMN

    def add(t: pd.DataFrame) -> pd.DataFrame | None:
        if HUMIDITY_COLUMN in t or TEMPERATURE_COLUMN not in t or PRESSURE_COLUMN not in t:
            return None
        t[HUMIDITY_COLUMN] = min(max(UNLOGGED_HUMIDITY_CENTRE_PCT + delta, 0.0), 100.0)
        return t
    return _with_table(c, add)


def _airspeed_factor(c, delta: float):
    if not _channels(c).vehicle or "airspeed_mps" not in getattr(c, _channels(c).table):
        return None
    return dataclasses.replace(c, anemometer=dataclasses.replace(
        c.anemometer, airspeed_factor=c.anemometer.airspeed_factor * (1.0 + delta)))


def _yaw_factor(c, delta: float):
    if not _channels(c).vehicle or "yaw_rad" not in getattr(c, _channels(c).table):
        return None
    return dataclasses.replace(c, anemometer=dataclasses.replace(
        c.anemometer, yaw_factor=c.anemometer.yaw_factor * (1.0 + delta)))


def _airspeed_yaw_coefficient(c, delta: float):
    """The airspeed readings times ``1 + delta psi^2``, psi = yaw factor x yaw reading: an
    anemometer whose calibration factor changes with the yaw as ``factor (1 + e psi^2)``
    (thesis section 4.7.2, figure 43), read with ``e`` off by ``delta`` (rad^-2).  None without
    airspeed and yaw readings."""
    ch = _channels(c)
    if not ch.vehicle:
        return None
    shifted = dataclasses.replace(c.anemometer, airspeed_yaw_coefficient_per_rad2=delta)

    def scale(t: pd.DataFrame) -> pd.DataFrame | None:
        if "airspeed_mps" not in t or "yaw_rad" not in t:
            return None
        t["airspeed_mps"] = shifted.yaw_corrected_airspeed(t["airspeed_mps"].to_numpy(float),
                                                           t["yaw_rad"].to_numpy(float))
        return t
    return _with_table(c, scale)


AIRSPEED_YAW_COEFFICIENT_BOUND_PER_RAD2 = (1.107 - 1.069) / 1.092 / math.radians(25.0) ** 2
"""The bound on ``e`` of an airspeed factor ``factor (1 + e psi^2)`` (rad^-2, ~0.18): the thesis'
anemometer factor ranged 1.069-1.107 (3.5 % of its mean 1.092) over the tunnel's +-25 deg
(section 4.7.2, figure 43; tests over +-25 deg in steps of 5, section 4.5), read as the whole
range reached at the range's edge."""


def _mass(c, delta: float):
    ch = _channels(c)
    if not ch.vehicle:
        return None
    v = c.vehicle
    table = getattr(c, ch.table)
    if "mass_kg" in table:
        table = table.copy()
        table["mass_kg"] = table["mass_kg"] + delta
    return dataclasses.replace(c, **{ch.table: table}, vehicle=dataclasses.replace(
        v, mass_kg=v.mass_kg + delta, effective_mass_kg=v.effective_mass_kg + delta))


def _rotating_inertia(c, delta: float):
    ch = _channels(c)
    if ch.wheel_inertia:
        return dataclasses.replace(c, wheel_inertia_kgm2={w: i * (1.0 + delta)
                                                          for w, i in c.wheel_inertia_kgm2.items()})
    if not ch.vehicle:
        return None
    v = c.vehicle
    rotating = v.effective_mass_kg - v.mass_kg
    return dataclasses.replace(c, vehicle=dataclasses.replace(
        v, effective_mass_kg=v.mass_kg + rotating * (1.0 + delta)))


DISTRIBUTIONS = ("normal", "above")
"""How a source's error is drawn (:attr:`UncertaintySource.distribution`)."""


@dataclass(frozen=True)
class UncertaintySource:
    """One Type B source: its key in ``[uncertainty]`` (unit in the name), its default standard
    uncertainty, the accuracy it comes from, the campaign transformation and the distribution
    of its error.

    ``apply(campaign, delta)`` returns the campaign with the source shifted by ``delta`` (in
    the key's unit), or None when the campaign has nothing the source acts on (no airspeed
    channel for the anemometer's factor, no temperature channel, ...).

    ``distribution``: "normal", the error ~ N(0, u^2) about the value the analysis takes (the
    sensors' accuracies, GUM 4.3.7); or "above", the analysis takes the lower bound of the
    source's range and the true value lies uniformly above it, the error ~ U(0, sqrt(12) u)
    (mean sqrt(3) u, sd u; GUM 4.3.7 and 4.3.8: a rectangular distribution whose estimate is
    not the analysis' value): the dry air the analysis takes when the humidity is not logged.
    The sensitivity is linear (central differences of ``apply`` at +-u), so where it holds the
    draws carry the mean shift with the spread."""

    key: str
    default: float
    accuracy: str
    transform: Callable[[Any, float], Any]
    distribution: str = "normal"

    def __post_init__(self) -> None:
        if self.distribution not in DISTRIBUTIONS:
            raise ValueError(f"source {self.key}: distribution {self.distribution!r} is not one of {DISTRIBUTIONS}")

    def apply(self, campaign, delta: float):
        return self.transform(campaign, float(delta))


_SQRT3 = math.sqrt(3.0)

SOURCES: dict[str, UncertaintySource] = {s.key: s for s in (
    UncertaintySource("speed_scale_rel", 0.0017 / _SQRT3,
                      "SAE J2263 vehicle speed +-0.2 km/h, as a scale error at 115 km/h (+-0.17 %)",
                      _scale_columns(lambda ch: ch.speed)),
    UncertaintySource("airspeed_factor_rel", 0.0093 / _SQRT3,
                      "SAE J2263 relative wind speed +-1 km/h, as a factor error at 108 km/h (+-0.93 %)",
                      _airspeed_factor),
    UncertaintySource("yaw_offset_rad", math.radians(1.0) / _SQRT3,
                      "SAE J2263 yaw +-3 deg, of which a +-1 deg offset", _shift_column("yaw_rad")),
    UncertaintySource("yaw_factor_rel", 0.10 / _SQRT3,
                      "SAE J2263 yaw +-3 deg, of which a +-10 % factor (2.5 deg at 15 deg)", _yaw_factor),
    UncertaintySource("airspeed_yaw_coefficient_per_rad2", AIRSPEED_YAW_COEFFICIENT_BOUND_PER_RAD2 / _SQRT3,
                      "the anemometer's airspeed factor changing with the yaw, factor (1 + e psi^2): "
                      "the thesis' factor spanned 3.5 % over +-25 deg (section 4.7.2), |e| <= 0.18 rad^-2, "
                      "sign not known for another body or mounting; where the campaign has airspeed and yaw",
                      _airspeed_yaw_coefficient),
    UncertaintySource("mass_kg", math.sqrt(2.0) * 5.0 / _SQRT3,
                      "SAE J1263 vehicle mass +-5 kg per axle, two axles independent", _mass),
    UncertaintySource("rotating_inertia_rel", 0.10 / _SQRT3,
                      "rotating inertia +-10 % (J2263's 1.03 M default spans 1-1.5 % of M on M_e)",
                      _rotating_inertia),
    UncertaintySource("temperature_k", 1.0 / _SQRT3, "SAE J1263 ambient temperature +-1 C",
                      _shift_column("temperature_k")),
    UncertaintySource("pressure_pa", 700.0 / _SQRT3, "SAE J1263 atmospheric pressure +-0.7 kPa",
                      _shift_column("pressure_pa")),
    UncertaintySource("relative_humidity_pct", 3.0 / _SQRT3,
                      "weather-station hygrometer +-3 % relative humidity (the standards state none; "
                      "a Kestrel 5500 states +-2 %), where the campaign logs it",
                      # kept inside 0-100 %: near saturation the difference spans less than +-u,
                      # which understates a term of ~0.03 % of the density by at most a fifth
                      _shift_column("relative_humidity_pct", (0.0, 100.0))),
    UncertaintySource("driveline_scale_rel", 0.01 / _SQRT3, "wheel-torque transducer +-1 % (class 0.5-1)",
                      _scale_columns(lambda ch: ch.force)),
    UncertaintySource("relative_humidity_unlogged_pct", 100.0 / math.sqrt(12.0),
                      "relative humidity not logged: the analysis takes dry air, as SAE J1263 and 40 CFR "
                      "1066.310 do, and the day's humidity lies anywhere above it, 0-100 % (uniform: mean "
                      "50 %, u = 100 / sqrt(12)); only where the campaign logs temperature and pressure",
                      _unlogged_humidity, distribution="above"),
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


def source_distribution(key: str) -> str:
    """The distribution of campaign source ``key``'s error (:attr:`UncertaintySource.distribution`);
    "normal" for a key that is no campaign source (a model constant, whose model file may say
    otherwise: :meth:`bayes_roadload.analysis.budget.TypeB.distribution_of` reads both)."""
    return SOURCES[key].distribution if key in SOURCES else "normal"


def standard_uncertainties(campaign) -> dict[str, float]:
    """Every source's standard uncertainty for ``campaign``: its ``[uncertainty]`` values
    (``meta["uncertainty"]``) over the defaults."""
    stated = campaign.meta.get(UNCERTAINTY_TABLE) or {}
    return {k: float(stated.get(k, s.default)) for k, s in SOURCES.items()}
