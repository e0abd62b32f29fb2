"""``vehicle.toml``: the vehicle, its anemometer calibration and the wind-tunnel data.

Every kind of campaign but the wheel spin-down (whose ``[spindown]`` table is read by
:mod:`~bayes_roadload.data.spindown`) has a ``vehicle.toml`` with ``[vehicle]`` (SI units),
optionally ``[anemometer]``, ``[tunnel]``, ``[uncertainty]`` (Type B standard uncertainties,
:mod:`.uncertainty`, carried in the campaign's ``meta["uncertainty"]``), ``[cfr1037]`` (40 CFR
1037.528 bench-test inputs, :mod:`.heavy_duty`, in ``meta["cfr1037"]``) and ``[meta]``; the format is in
``docs/data-format.md``.  Reading validates and refuses with the file's name and the key.
"""

from __future__ import annotations

import json
import math
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .. import config
from .checks import CampaignError, refuse
from .heavy_duty import CFR1037_TABLE, cfr1037_from_toml, cfr1037_toml_lines
from .uncertainty import UNCERTAINTY_TABLE, uncertainty_from_toml

VEHICLE_FILE = "vehicle.toml"
VEHICLE_KEYS = ("mass_kg", "effective_mass_kg", "frontal_area_m2", "rolling_radius_m", "rotating_inertia_kgm2",
                "length_m", "tyres_in_contact", "mass_in_running_order_kg")
ANEMOMETER_KEYS = ("airspeed_factor", "yaw_factor", "distance_constant_m", "airspeed_yaw_coefficient_per_rad2")
AIRSPEED_YAW_COEFFICIENT_RANGE_PER_RAD2 = (-1.0, 1.0)
"""Accepted ``[anemometer] airspeed_yaw_coefficient_per_rad2`` (rad^-2): +-1 is a factor change
of 19 % at 25 deg yaw, five times the thesis anemometer's 3.5 % (section 4.7.2)."""


@dataclass(frozen=True)
class Vehicle:
    """``[vehicle]`` of vehicle.toml, SI units.

    ``effective_mass_kg`` is M_e = M + I_w / R_r^2 (eq. 2.2); it may be given directly or as
    ``rotating_inertia_kgm2`` with ``rolling_radius_m``.  ``tyres_in_contact`` (optional) is
    the number of tyres on the road, for a standard whose effective mass counts them (40 CFR
    1037.528(h)(1): M + 56.7 kg per tyre).  ``mass_in_running_order_kg`` (optional, at most the
    test mass ``mass_kg``) is for GTR 15's estimate of the rotating mass, 3 % of (mass in running
    order + 25 kg).  ``length_m`` (optional) is the vehicle's overall length, for its aerodynamic
    admittance (:mod:`bayes_roadload.physics.admittance`); None when not stated.
    """

    mass_kg: float
    effective_mass_kg: float
    frontal_area_m2: float
    rolling_radius_m: float = 0.28
    length_m: float | None = None
    tyres_in_contact: int | None = None
    mass_in_running_order_kg: float | None = None


@dataclass(frozen=True)
class Anemometer:
    """``[anemometer]``: true = factor x reading (thesis section 4.7.3); ``distance_constant_m``
    the cup's (or propeller's) distance constant d, first order: d(reading)/dt = (a - reading)
    a / d (thesis 4.7: 1.5 m), 0 when not stated -- then the analysis takes the reading as the
    airspeed, else it undoes the lag (the ``anemometer_lag`` term, :mod:`bayes_roadload.physics.effects`).
    ``airspeed_yaw_coefficient_per_rad2`` the wind tunnel's change of the airspeed factor with
    the yaw, factor (1 + e psi^2) with psi = yaw_factor x yaw reading (thesis section 4.7.2,
    figure 43: 1.069-1.107 over +-25 deg), 0 when not stated; applied to the airspeed readings
    as they enter a fit (:meth:`yaw_corrected_airspeed`)."""

    airspeed_factor: float = 1.0
    yaw_factor: float = 1.0
    distance_constant_m: float = 0.0
    airspeed_yaw_coefficient_per_rad2: float = 0.0

    def yaw_corrected_airspeed(self, airspeed_reading_mps, yaw_reading_rad):
        """The airspeed readings times ``1 + e psi^2`` (psi = yaw_factor x yaw reading, e =
        ``airspeed_yaw_coefficient_per_rad2``): readings on which the constant factor is then
        right at every yaw.  Returned unchanged when ``e`` is 0."""
        e = self.airspeed_yaw_coefficient_per_rad2
        if e == 0.0:
            return airspeed_reading_mps
        return airspeed_reading_mps * (1.0 + e * (self.yaw_factor * np.asarray(yaw_reading_rad, float)) ** 2)

    def yaw_uncorrected_airspeed(self, airspeed_mps, yaw_reading_rad):
        """The inverse of :meth:`yaw_corrected_airspeed`: the readings that it turns into
        ``airspeed_mps`` (for data written back as readings, e.g. a planned campaign's)."""
        e = self.airspeed_yaw_coefficient_per_rad2
        if e == 0.0:
            return airspeed_mps
        return airspeed_mps / (1.0 + e * (self.yaw_factor * np.asarray(yaw_reading_rad, float)) ** 2)

    def calibrated_air(self, airspeed_reading_mps, yaw_reading_rad):
        """(relative airspeed v_r, yaw psi) from the readings: v_r = airspeed_factor x the
        :meth:`yaw_corrected_airspeed`, psi = yaw_factor x reading (thesis section 4.7.3)."""
        yaw = np.asarray(yaw_reading_rad, float)
        return (self.airspeed_factor * self.yaw_corrected_airspeed(np.asarray(airspeed_reading_mps, float), yaw),
                self.yaw_factor * yaw)


def validate_vehicle(v: Vehicle, where: str = VEHICLE_FILE) -> None:
    """Refuse a mass, effective mass, frontal area or rolling radius outside its physical range."""
    lo, hi = config.MASS_RANGE_KG
    for key in ("mass_kg", "effective_mass_kg"):
        val = getattr(v, key)
        if not (math.isfinite(val) and lo <= val <= hi):
            refuse(where, f"[vehicle] {key}", None, f"{val!r} is outside the physical range [{lo}, {hi}] kg")
    if v.effective_mass_kg < v.mass_kg:
        refuse(where, "[vehicle] effective_mass_kg", None,
               f"{v.effective_mass_kg} kg is less than the test mass {v.mass_kg} kg (eq. 2.2: M_e = M + I/R^2)")
    if v.effective_mass_kg > 1.5 * v.mass_kg:
        refuse(where, "[vehicle] effective_mass_kg", None,
               f"{v.effective_mass_kg} kg is more than 1.5 x the test mass: check the rotating inertia")
    lo, hi = config.AREA_RANGE_M2
    if not (math.isfinite(v.frontal_area_m2) and lo <= v.frontal_area_m2 <= hi):
        refuse(where, "[vehicle] frontal_area_m2", None, f"{v.frontal_area_m2!r} is outside [{lo}, {hi}] m^2")
    if not (0.01 <= v.rolling_radius_m <= 2.0):
        refuse(where, "[vehicle] rolling_radius_m", None, f"{v.rolling_radius_m!r} is outside [0.01, 2] m")
    if v.length_m is not None and not (math.isfinite(v.length_m) and 1.0 <= v.length_m <= 30.0):
        refuse(where, "[vehicle] length_m", None, f"{v.length_m!r} is outside [1, 30] m")


def vehicle_from_toml(doc: Mapping[str, Any], where: str) -> tuple[Vehicle, Anemometer, dict | None, dict]:
    """(vehicle, anemometer, tunnel, meta) of a parsed vehicle.toml, validated; ``where``
    names the file in refusals."""
    if "vehicle" not in doc:
        refuse(where, "[vehicle]", None, "table is missing")
    for name in ("vehicle", "anemometer", "tunnel", "meta"):
        if name in doc and not isinstance(doc[name], dict):
            refuse(where, f"[{name}]", None, f"is {doc[name]!r}, not a table ([{name}] followed by key = value lines)")
    t = dict(doc["vehicle"])
    for k in t:
        if k not in VEHICLE_KEYS:
            refuse(where, f"[vehicle] {k}", None, f"unknown key; known: {', '.join(sorted(VEHICLE_KEYS))}")
    for k, val in t.items():  # a quoted value ("1100", "1,85", "1100 kg") is text, not a number
        if isinstance(val, bool) or not isinstance(val, (int, float)):
            refuse(where, f"[vehicle] {k}", None, f"{val!r} is not a number (give it unquoted, in the key's unit, "
                   "with a decimal point)")
    for k in ("mass_kg", "frontal_area_m2"):
        if k not in t:
            refuse(where, f"[vehicle] {k}", None, "required key is missing")
    radius = float(t.get("rolling_radius_m", 0.28))
    if "effective_mass_kg" in t and "rotating_inertia_kgm2" in t:
        refuse(where, "[vehicle] effective_mass_kg", None,
               "give effective_mass_kg or rotating_inertia_kgm2, not both (ambiguous)")
    if "effective_mass_kg" in t:
        me = float(t["effective_mass_kg"])
    elif "rotating_inertia_kgm2" in t:
        if "rolling_radius_m" not in t:
            refuse(where, "[vehicle] rolling_radius_m", None, "needed with rotating_inertia_kgm2")
        me = float(t["mass_kg"]) + float(t["rotating_inertia_kgm2"]) / radius**2
    else:
        refuse(where, "[vehicle] effective_mass_kg", None,
               "required key is missing (or give rotating_inertia_kgm2 and rolling_radius_m)")
    tyres = t.get("tyres_in_contact")
    if tyres is not None and (isinstance(tyres, bool) or not isinstance(tyres, int) or not 2 <= tyres <= 64):
        refuse(where, "[vehicle] tyres_in_contact", None, f"{tyres!r} is not a whole number of tyres in [2, 64]")
    mro = t.get("mass_in_running_order_kg")
    if mro is not None and (isinstance(mro, bool) or not isinstance(mro, (int, float))
                            or not 0.0 < float(mro) <= float(t["mass_kg"])):
        refuse(where, "[vehicle] mass_in_running_order_kg", None,
               f"{mro!r} is not a mass in (0, mass_kg = {t['mass_kg']}]: the test mass includes the mass in running order")
    vehicle = Vehicle(float(t["mass_kg"]), me, float(t["frontal_area_m2"]), radius,
                      None if t.get("length_m") is None else float(t["length_m"]), tyres, None if mro is None else float(mro))
    validate_vehicle(vehicle, where)
    a = dict(doc.get("anemometer", {}))
    for k in a:
        if k not in ANEMOMETER_KEYS:
            refuse(where, f"[anemometer] {k}", None, f"unknown key; known: {', '.join(ANEMOMETER_KEYS)}")
    for k, val in a.items():
        if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(float(val)):
            refuse(where, f"[anemometer] {k}", None, f"{val!r} is not a number")
    anem = Anemometer(float(a.get("airspeed_factor", 1.0)), float(a.get("yaw_factor", 1.0)),
                      float(a.get("distance_constant_m", 0.0)), float(a.get("airspeed_yaw_coefficient_per_rad2", 0.0)))
    for k in ("airspeed_factor", "yaw_factor"):
        if not 0.5 <= getattr(anem, k) <= 2.0:
            refuse(where, f"[anemometer] {k}", None, f"{getattr(anem, k)} is outside [0.5, 2]")
    if not 0.0 <= anem.distance_constant_m <= 20.0:
        refuse(where, "[anemometer] distance_constant_m", None,
               f"{anem.distance_constant_m} is outside [0, 20] m (cup anemometers: 1-5 m)")
    lo, hi = AIRSPEED_YAW_COEFFICIENT_RANGE_PER_RAD2
    if not lo <= anem.airspeed_yaw_coefficient_per_rad2 <= hi:
        refuse(where, "[anemometer] airspeed_yaw_coefficient_per_rad2", None,
               f"{anem.airspeed_yaw_coefficient_per_rad2} is outside [{lo}, {hi}] rad^-2 (the thesis' anemometer: "
               "|e| about 0.18, a 3.5 % change over 25 deg)")
    tunnel = doc.get("tunnel")
    if tunnel is not None:
        tunnel = dict(tunnel)
        if ("yaw_deg" in tunnel) != ("cd" in tunnel):
            refuse(where, "[tunnel]", None, "a C_D(yaw) table needs both yaw_deg and cd")
    meta = dict(doc.get("meta", {}))
    if UNCERTAINTY_TABLE in doc:  # Type B standard uncertainties (data.uncertainty), carried in meta
        meta[UNCERTAINTY_TABLE] = uncertainty_from_toml(doc[UNCERTAINTY_TABLE], where)
    if CFR1037_TABLE in doc:  # 40 CFR 1037.528 (h)(5)/(h)(6) bench-test inputs (data.heavy_duty)
        meta[CFR1037_TABLE] = cfr1037_from_toml(doc[CFR1037_TABLE], where)
    return vehicle, anem, tunnel, meta


def read_toml_file(path: str | os.PathLike) -> dict:
    """A TOML file as a dict (a UTF-8 byte-order mark is skipped, as the CSV readers do),
    refused with the file's name when it is not UTF-8 TOML."""
    try:
        return tomllib.loads(Path(path).read_text(encoding="utf-8-sig"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise CampaignError(f"{path}: not valid TOML ({e})") from e


def read_vehicle_file(path: str | os.PathLike) -> tuple[Vehicle, Anemometer, dict | None, dict]:
    """``vehicle.toml`` (or any file of its format) as (vehicle, anemometer, tunnel, meta),
    validated; refused with the file's name when missing or not TOML."""
    vfile = Path(path)
    if not vfile.exists():
        raise CampaignError(f"{vfile}: missing")
    return vehicle_from_toml(read_toml_file(vfile), str(vfile))


# --------------------------------------------------------------------------- writing

def toml_value(v) -> str:
    """A Python / numpy value (bool, number, text or a sequence of them) as TOML text."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def toml_table(name: str, table: Mapping[str, Any] | None) -> list[str]:
    """The lines of a TOML table ``[name]`` after a blank line; none for an empty table."""
    if not table:
        return []
    return ["", f"[{name}]"] + [f"{k} = {toml_value(val)}" for k, val in table.items()]


def vehicle_toml(c) -> str:
    """The vehicle.toml text of a campaign (its ``vehicle``, ``anemometer``, ``tunnel`` and
    ``meta``), the vehicle validated first."""
    validate_vehicle(c.vehicle, "vehicle")
    v = c.vehicle
    lines = ["[vehicle]"]
    for k in ("mass_kg", "effective_mass_kg", "frontal_area_m2", "rolling_radius_m", "length_m"):
        value = getattr(v, k)
        if value is not None:
            lines.append(f"{k} = {toml_value(value)}")
    if v.tyres_in_contact is not None:
        lines.append(f"tyres_in_contact = {int(v.tyres_in_contact)}")
    if v.mass_in_running_order_kg is not None:
        lines.append(f"mass_in_running_order_kg = {toml_value(v.mass_in_running_order_kg)}")
    lines += ["", "[anemometer]",
              f"airspeed_factor = {toml_value(c.anemometer.airspeed_factor)}",
              f"yaw_factor = {toml_value(c.anemometer.yaw_factor)}"]
    if c.anemometer.distance_constant_m > 0.0:
        lines.append(f"distance_constant_m = {toml_value(c.anemometer.distance_constant_m)}")
    if c.anemometer.airspeed_yaw_coefficient_per_rad2 != 0.0:
        lines.append(f"airspeed_yaw_coefficient_per_rad2 = {toml_value(c.anemometer.airspeed_yaw_coefficient_per_rad2)}")
    meta = {k: v for k, v in c.meta.items() if k not in (UNCERTAINTY_TABLE, CFR1037_TABLE, "conversions")}
    lines += (toml_table("tunnel", c.tunnel) + toml_table("meta", meta)
              + toml_table(UNCERTAINTY_TABLE, c.meta.get(UNCERTAINTY_TABLE))
              + cfr1037_toml_lines(c.meta.get(CFR1037_TABLE), toml_value))
    return "\n".join(lines) + "\n"
