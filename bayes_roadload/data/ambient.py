"""The ambient-air columns every data kind may log, and the air density they give.

``temperature_k`` (K), ``pressure_pa`` (Pa, station pressure) and ``relative_humidity_pct``
(percent, 0-100) are optional in every kind's table (per sample in speed traces and steady
tests, per run in interval and distance-time campaigns).  Without them the analysis takes the
thesis' reference conditions (293.2 K, 100 kPa) and dry air, as the standards' corrections do
(SAE J1263, 40 CFR 1066.310: density from temperature and pressure).  With the humidity the
density is the moist air's (:func:`bayes_roadload.physics.atmosphere.air_density_kgpm3`): at
20-30 C and 30-95 % relative humidity 0.3-1.5 % below the dry value, which a fit of the dry
value reads as C_D0 and K_D low by the same fraction.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .. import config
from ..physics.atmosphere import air_density_kgpm3
from .checks import refuse

TEMPERATURE_COLUMN = "temperature_k"
PRESSURE_COLUMN = "pressure_pa"
HUMIDITY_COLUMN = "relative_humidity_pct"
AMBIENT_COLUMNS = (TEMPERATURE_COLUMN, PRESSURE_COLUMN, HUMIDITY_COLUMN)
"""The ambient columns of every kind's contract (docs/data-format.md)."""


def air_density(table: pd.DataFrame) -> np.ndarray:
    """The air density (kg/m^3) of every row of ``table`` from its ambient columns (module
    docstring): the reference temperature and pressure where a column is absent, dry air
    without ``relative_humidity_pct``."""
    n = len(table)
    temp = table[TEMPERATURE_COLUMN].to_numpy(float) if TEMPERATURE_COLUMN in table else np.full(
        n, config.REFERENCE_TEMPERATURE_K)
    press = table[PRESSURE_COLUMN].to_numpy(float) if PRESSURE_COLUMN in table else np.full(
        n, config.REFERENCE_PRESSURE_PA)
    humidity = table[HUMIDITY_COLUMN].to_numpy(float) / 100.0 if HUMIDITY_COLUMN in table else None
    return np.asarray(air_density_kgpm3(press, temp, humidity), float)


def mean_air_density(table: pd.DataFrame) -> float:
    """The mean of :func:`air_density` over the rows of ``table``."""
    return float(np.mean(air_density(table))) if len(table) else float(air_density_kgpm3())


def check_humidity_percent(df: pd.DataFrame, where: str) -> None:
    """Refuse a ``relative_humidity_pct`` column whose every value is at most 1: a fraction in
    a percent column (outdoor air below 1 % relative humidity is not a test day)."""
    if HUMIDITY_COLUMN in df and len(df):
        values = pd.to_numeric(df[HUMIDITY_COLUMN], errors="coerce").to_numpy(float)
        if np.all(values[np.isfinite(values)] <= 1.0):
            refuse(where, HUMIDITY_COLUMN, 1, f"every value is at most 1 (first {values[0]:g}): a fraction "
                   "in a percent column; multiply by 100")


def ambient_record(campaign) -> dict:
    """What air a fit of ``campaign`` assumed, for ``fit.json`` (``provenance.ambient``) and the
    line ``fit`` prints: the means of the logged ambient columns of its measured table (the
    table its class declares, :class:`~bayes_roadload.data.uncertainty.TypeBChannels`; None
    where a column is absent), the mean air density, and ``air`` "moist" (the humidity logged)
    or "dry"."""
    table = getattr(campaign, type(campaign).type_b_channels.table)
    mean = {c: (float(table[c].astype(float).mean()) if c in table else None) for c in AMBIENT_COLUMNS}
    return {**mean, "air_density_kgpm3": mean_air_density(table),
            "air": "moist" if mean[HUMIDITY_COLUMN] is not None else "dry"}


def ambient_line(record: dict) -> str:
    """One line saying what air the fit took (:func:`ambient_record`)."""
    t, p, h = (record[c] for c in AMBIENT_COLUMNS)
    where = (f"{t:.1f} K, {p / 1000:.1f} kPa" if t is not None and p is not None else
             f"{'logged' if t is not None else 'reference'} temperature, "
             f"{'logged' if p is not None else 'reference'} pressure")
    air = (f"moist air at {h:.0f} % relative humidity" if h is not None else
           "dry air (no relative_humidity_pct column: humid air is up to 1.5 % lighter"
           + ("; the Type B budget takes the humidity as 0-100 %, relative_humidity_unlogged_pct)"
              if t is not None and p is not None else ", read as C_D0 that much low)"))
    return f"air: {where}, {air}; mean density {record['air_density_kgpm3']:.4f} kg/m^3"
