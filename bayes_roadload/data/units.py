"""Units of a speed-trace table: conversion on load, and the plausibility of the road load the
speeds imply.

SI inside: the contract's columns are ``speed_mps``, ``airspeed_mps``, ``yaw_rad``,
``temperature_k`` and ``pressure_pa``.  A column whose name states another unit
(``speed_kph``, ``speed_mph``, ``airspeed_kph``, ``yaw_deg``, ``temperature_c``,
``pressure_kpa``, ...) is converted on load, and so is the speed (or airspeed) column whose
unit the user states (``--speed-unit`` / ``--airspeed-unit``: ``mps``, ``kph``, ``mph``),
whatever its name says; a name without a unit (``speed``) is refused unless the user states
one.  Every conversion is recorded (:class:`Conversion`, ``campaign.meta["conversions"]``, the
fit's ``fit.json``).

The plausibility check (:func:`check_plausible_road_load`) reads the road load the speed
traces imply, F/M_e = -dv/dt = c0 + c2 v^2 by least squares over every run, as a rolling
resistance coefficient c0 M_e / (M g) and a drag area 2 c2 M_e / rho.  A speed logged in
km/h but read as m/s scales the speeds and the decelerations by 3.6: c0 by 3.6 and c2 by
1 / 3.6, so the rolling coefficient comes out too large and the drag area too small at the
same time.  A campaign is refused with the conversion to make when its implied road load is
plausible once read in km/h (or mph) and, read in m/s, either implausible in exactly that way,
or implausible in any way while its speeds exceed :data:`COASTDOWN_TOP_SPEED_MPS` (a large
vehicle's drag area read 3.6-fold too small can stay above the plausible minimum, but its
speeds then reach 80-100 "m/s").  Times logged in milliseconds but read as seconds divide the
decelerations, so c0 and c2, by 1000: the rolling coefficient and the drag area both come out
below their ranges (a car: 1e-5 and 0.001 m^2); a campaign implausible that way and plausible
with its times read in ms is refused naming ``time_s`` (a ``time_ms`` column is converted), and
one whose ``time_ms`` column holds seconds (both 1000-fold too large) naming ``time_ms``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from .. import config
from .checks import refuse

SPEED_UNITS = {"mps": 1.0, "kph": 1.0 / 3.6, "mph": 0.44704}
"""``--speed-unit`` / ``--airspeed-unit`` value -> factor to m/s."""

SPEED_UNIT_NAMES = {"mps": "m/s", "kph": "km/h", "mph": "mph"}

_SUFFIX_UNIT = {"mps": "mps", "kph": "kph", "kmh": "kph", "mph": "mph"}

STATED_UNIT_COLUMNS = {
    # column as logged: (contract column, scale, offset, unit stated by the name)
    "yaw_deg": ("yaw_rad", np.pi / 180.0, 0.0, "deg"),
    "temperature_c": ("temperature_k", 1.0, 273.15, "degC"),
    "pressure_kpa": ("pressure_pa", 1000.0, 0.0, "kPa"),
    "pressure_hpa": ("pressure_pa", 100.0, 0.0, "hPa"),
    "pressure_mbar": ("pressure_pa", 100.0, 0.0, "mbar"),
    "time_ms": ("time_s", 0.001, 0.0, "ms"),
}
"""Non-speed columns whose name states a unit: SI value = scale * value + offset."""

SPEED_CHANNELS = {"speed": "speed_mps", "airspeed": "airspeed_mps"}
"""Speed channel stem -> its contract column."""

PLAUSIBLE_ROLLING = (0.003, 0.025)
"""Implied rolling resistance coefficient c0 M_e / (M g) of a road vehicle coasting in neutral
(tyres and the undriven driveline; J2263 / GTR 15 road loads of cars to trucks lie inside)."""

PLAUSIBLE_DRAG_AREA_M2 = (0.3, 15.0)
"""Implied drag area C_D A (m^2): a small car (~0.5) to a truck with trailer (~10)."""

COASTDOWN_TOP_SPEED_MPS = 50.0
"""Speed (m/s, 180 km/h) above which a coastdown trace is suspect: the standards' coastdowns
start below it (J2263 at 115 km/h or more; GTR 15 above its highest reference speed, at most
130 km/h); a trace above it with an implausible road load is read as a speed unit error."""


@dataclass(frozen=True)
class Conversion:
    """One column converted on load: ``column`` as logged, the contract column it became,
    SI = ``scale`` * value + ``offset``, and how the unit was known (``"column name"`` or the
    user's option)."""

    file: str
    column: str
    to: str
    unit: str
    scale: float
    offset: float
    stated_by: str

    def record(self) -> dict:
        return asdict(self)


def _speed_column(df: pd.DataFrame, stem: str, where: str) -> tuple[str, str | None] | None:
    """The column of speed channel ``stem`` present in ``df`` and the unit its name states
    (None for a bare name); refuses two columns of the same channel."""
    found = [(c, _SUFFIX_UNIT.get(c[len(stem) + 1:]) if c != stem else None) for c in df.columns
             if c == stem or (c.startswith(stem + "_") and c[len(stem) + 1:] in _SUFFIX_UNIT)]
    if len(found) > 1:
        refuse(where, found[1][0], None, f"two {stem} columns ({found[0][0]}, {found[1][0]}): ambiguous, keep one")
    return found[0] if found else None


def convert_units(df: pd.DataFrame, where: str, speed_unit: str | None = None,
                  airspeed_unit: str | None = None) -> tuple[pd.DataFrame, list[Conversion]]:
    """Convert the speed and unit-suffixed columns of a runs table to the contract's SI
    columns; returns the converted copy and the conversions made.

    ``speed_unit`` / ``airspeed_unit`` (``mps``, ``kph``, ``mph``) state the unit of the speed
    / airspeed column whatever its name says; without them a name's suffix states it and a
    bare name (``speed``) is refused.  A stated unit that contradicts a name's non-SI suffix
    is refused (``speed_kph`` with ``--speed-unit mph``).  Values are converted as numbers;
    what is not a number is left for the table's checks to refuse with its row.
    """
    df = df.copy()
    conversions: list[Conversion] = []
    for stem, stated in (("speed", speed_unit), ("airspeed", airspeed_unit)):
        if stated is not None and stated not in SPEED_UNITS:
            raise ValueError(f"--{stem}-unit {stated!r}: give one of {', '.join(SPEED_UNITS)}")
        found = _speed_column(df, stem, where)
        if found is None:
            if stated is not None and stated != "mps":
                refuse(where, SPEED_CHANNELS[stem], None, f"--{stem}-unit {stated} given but the table has no "
                       f"{stem} column")
            continue
        column, named = found
        target = SPEED_CHANNELS[stem]
        if stated is None and named is None:
            refuse(where, column, None, f"the column name states no unit: name it {target} (m/s), "
                   f"{stem}_kph or {stem}_mph, or give --{stem}-unit mps|kph|mph")
        if stated is not None and named not in (None, "mps", stated):
            refuse(where, column, None, f"the column name says {SPEED_UNIT_NAMES[named]} but --{stem}-unit "
                   f"says {SPEED_UNIT_NAMES[stated]}: ambiguous, give one")
        unit = stated or named
        if unit == "mps" and column == target:
            continue
        values = pd.to_numeric(df.pop(column), errors="coerce")
        df[target] = values * SPEED_UNITS[unit]
        conversions.append(Conversion(where, column, target, SPEED_UNIT_NAMES[unit], SPEED_UNITS[unit], 0.0,
                                      f"--{stem}-unit" if stated else "column name"))
    for column, (target, scale, offset, unit) in STATED_UNIT_COLUMNS.items():
        if column in df.columns:
            if target in df.columns:
                refuse(where, column, None, f"both {column} and {target}: ambiguous, keep one")
            df[target] = pd.to_numeric(df.pop(column), errors="coerce") * scale + offset
            conversions.append(Conversion(where, column, target, unit, scale, offset, "column name"))
    return df, conversions


def implied_road_load(df: pd.DataFrame, effective_mass_kg: float, mass_kg: float,
                      air_density_kgpm3: float) -> dict | None:
    """The road load the speed traces imply, in the units the table is read in.

    Per run, -dv/dt by central differences of ``speed_mps`` over ``time_s`` (runs of fewer than
    5 samples are skipped); over every run, least squares of -dv/dt = c0 + c2 v^2 (both
    directions pooled, so a steady wind averages out to first order).  Returns ``rolling`` =
    c0 M_e / (M g), ``drag_area_m2`` = 2 c2 M_e / rho, ``c0``, ``c2`` and ``top_speed``; None
    when fewer than 10 samples or under 5 m/s of speed range are usable.
    """
    v_all, a_all = [], []
    for _, g in df.groupby("run", sort=False):
        t = g["time_s"].to_numpy(float)
        v = g["speed_mps"].to_numpy(float)
        if len(t) < 5 or np.any(np.diff(t) <= 0):
            continue
        v_all.append(v[1:-1])
        a_all.append(-(v[2:] - v[:-2]) / (t[2:] - t[:-2]))
    if not v_all:
        return None
    v, a = np.concatenate(v_all), np.concatenate(a_all)
    ok = np.isfinite(v) & np.isfinite(a)
    v, a = v[ok], a[ok]
    if len(v) < 10 or np.ptp(v) < 5.0:
        return None
    (c0, c2), *_ = np.linalg.lstsq(np.column_stack([np.ones_like(v), v * v]), a, rcond=None)
    return {"c0": float(c0), "c2": float(c2), "top_speed": float(v.max()),
            "rolling": float(c0 * effective_mass_kg / (mass_kg * config.GRAVITY_MPS2)),
            "drag_area_m2": float(2.0 * c2 * effective_mass_kg / air_density_kgpm3)}


def _plausible(rolling: float, drag_area: float) -> bool:
    return (PLAUSIBLE_ROLLING[0] <= rolling <= PLAUSIBLE_ROLLING[1]
            and PLAUSIBLE_DRAG_AREA_M2[0] <= drag_area <= PLAUSIBLE_DRAG_AREA_M2[1])


MAX_WIND_MPS = max(limits["peak_wind_mps"] for limits in config.WIND_LIMITS.values())
"""The strongest wind a coastdown may meet (m/s): the largest peak wind the standards admit
(GTR 15 with on-board anemometry, 10 m/s; :data:`~bayes_roadload.config.WIND_LIMITS`)."""


def check_plausible_airspeed(df: pd.DataFrame, where: str, airspeed_factor: float = 1.0,
                             convertible: bool = True) -> float | None:
    """Refuse airspeeds logged in km/h or mph but read as m/s (``airspeed_mps`` below the
    100 m/s range check); returns the campaign's median excess airspeed (m/s), None without an
    airspeed channel.

    The band comes from the physics: the relative air is the vehicle's motion plus the wind, so
    at every sample the true airspeed exceeds the ground speed by at most the wind speed (the
    triangle inequality; the ratio airspeed / speed is at most 1 + w / v).  The coastdown's
    wind is bounded by the standards, whose largest peak wind is :data:`MAX_WIND_MPS` (10 m/s;
    the mean winds they admit are 3-7 m/s), so the median over the campaign's samples of the
    excess airspeed ``airspeed_factor x airspeed_mps - speed_mps`` (the reading calibrated by
    ``[anemometer] airspeed_factor``) stays below it even in a campaign of one direction, and
    near zero over opposite-direction pairs (a ratio near 1).  Read in km/h an airspeed is 3.6
    x (v + w), its excess 2.6 v + 3.6 w: 30-90 m/s at the 15-40 m/s of a coastdown (a ratio near
    3.6); in mph 2.237 x (v + w), an excess of 1.24 v + 2.24 w, 10-50 m/s (a ratio near 2.24).
    A median excess above :data:`MAX_WIND_MPS` that the km/h (or mph) reading brings within it
    is refused naming the file, ``airspeed_mps`` and the first row beyond the wind limit, with
    the unit (the one of the two whose reading leaves the smaller median excess) to state
    (``convertible``: the kind converts ``airspeed_kph`` / ``--airspeed-unit``), or, for a kind
    that reads m/s only, the factor to convert the column by.
    """
    if "airspeed_mps" not in df:
        return None
    a = df["airspeed_mps"].to_numpy(float) * airspeed_factor
    v = df["speed_mps"].to_numpy(float)
    excess = float(np.median(a - v))
    if excess <= MAX_WIND_MPS:
        return excess
    read_as = {u: float(np.median(a * SPEED_UNITS[u] - v)) for u in ("kph", "mph")}
    unit = min(read_as, key=lambda u: abs(read_as[u]))
    if abs(read_as[unit]) > MAX_WIND_MPS:
        return excess
    row = int(np.flatnonzero(a - v > MAX_WIND_MPS)[0]) + 1
    name = SPEED_UNIT_NAMES[unit]
    remedy = (f"give --airspeed-unit {unit} or rename the column airspeed_{unit}" if convertible
              else f"convert them to m/s (multiply {name} by {SPEED_UNITS[unit]:.6g})")
    refuse(where, "airspeed_mps", row,
           f"the airspeeds look logged in {name}: {remedy} "
           f"(the median airspeed exceeds the speed by {excess:.1f} m/s, median ratio "
           f"{float(np.median(a / v)):.2f}: beyond the {MAX_WIND_MPS:g} m/s peak wind the standards admit; read in "
           f"{name} it is {read_as[unit]:+.1f} m/s)")


MS_PER_S = 1000.0


def check_plausible_road_load(df: pd.DataFrame, where: str, effective_mass_kg: float, mass_kg: float,
                              air_density_kgpm3: float, time_column: str = "time_s") -> dict | None:
    """Refuse speed traces whose implied road load (:func:`implied_road_load`) is implausible
    the way a speed logged in km/h or mph but read as m/s makes it (rolling coefficient above
    :data:`PLAUSIBLE_ROLLING` and drag area below :data:`PLAUSIBLE_DRAG_AREA_M2` at once, or
    either outside its range while the top speed exceeds :data:`COASTDOWN_TOP_SPEED_MPS`) and
    plausible when the speeds are read in that unit; the message names the file, the column
    and the conversion.  Likewise times 1000-fold off (both below their ranges and plausible
    with the decelerations x 1000: milliseconds in ``time_s``; both above and plausible / 1000:
    seconds in a ``time_ms`` column, ``time_column`` being the time column as logged).  Returns
    the implied road load (None when the data cannot say)."""
    implied = implied_road_load(df, effective_mass_kg, mass_kg, air_density_kgpm3)
    if implied is None:
        return None
    rolling, area = implied["rolling"], implied["drag_area_m2"]
    implied_text = (f"the road load they imply, rolling coefficient {rolling:.3g} and drag area {area:.3g} m^2, is "
                    "not a road vehicle's")
    if rolling < PLAUSIBLE_ROLLING[0] and area < PLAUSIBLE_DRAG_AREA_M2[0] and \
            _plausible(rolling * MS_PER_S, area * MS_PER_S):
        refuse(where, time_column, None,
               f"the times look logged in milliseconds: rename the column time_ms (converted to seconds on load) "
               f"({implied_text}; read in ms it is {rolling * MS_PER_S:.4f} and {area * MS_PER_S:.2f} m^2)")
    if time_column == "time_ms" and rolling > PLAUSIBLE_ROLLING[1] and area > PLAUSIBLE_DRAG_AREA_M2[1] and \
            _plausible(rolling / MS_PER_S, area / MS_PER_S):
        refuse(where, time_column, None,
               f"the times look logged in seconds: rename the column time_s ({implied_text}; read in s it is "
               f"{rolling / MS_PER_S:.4f} and {area / MS_PER_S:.2f} m^2)")
    unit_error_shape = rolling > PLAUSIBLE_ROLLING[1] and area < PLAUSIBLE_DRAG_AREA_M2[0]
    too_fast = implied["top_speed"] > COASTDOWN_TOP_SPEED_MPS and not _plausible(rolling, area)
    if not (unit_error_shape or too_fast):
        return implied
    for unit in ("kph", "mph"):
        s = SPEED_UNITS[unit]  # speeds and decelerations both scale by s: c0 by s, c2 by 1/s
        if _plausible(rolling * s, area / s):
            refuse(where, "speed_mps", None,
                   f"the speeds look logged in {SPEED_UNIT_NAMES[unit]}: give --speed-unit {unit} or rename the "
                   f"column speed_{unit} (the road load they imply, rolling coefficient {rolling:.3f} and drag "
                   f"area {area:.2f} m^2 up to {implied['top_speed']:.1f} m/s, is not a road vehicle's; read in "
                   f"{SPEED_UNIT_NAMES[unit]} it is {rolling * s:.4f} and {area / s:.2f} m^2)")
    return implied
