"""Road load at reference conditions: the quantities a test report quotes.

The road load is the drag function of a model evaluated in still air (v_r = v, psi = 0) at
the reference conditions of the thesis (100 kPa, 293.2 K), level road, no acceleration.  Its
parts follow the thesis' breakdown at 50 mph (section 8: tyres, aerodynamics, driveline,
undriven wheels), and the regulation form F = F0 + F1 v + F2 v^2 (v in km/h) is the
least-squares quadratic through the curve over the coastdown speed range.
"""

from __future__ import annotations

from typing import Mapping

import jax.numpy as jnp

from .. import config
from .atmosphere import air_density_kgpm3
from .model import DragModel
from .terms import Conditions

Array = jnp.ndarray

PART_OF_TERM = {
    "tyre_rolling": "tyre",
    "lift_unloading": "tyre",
    "tyre_temperature": "tyre",
    "aero_drag": "aero",
    "aero_drag_table": "aero",
    "side_force_slip": "tyre",
    "pitch_attitude": "aero",
    "driveline_polynomial": "driveline",
    "driveline_measured": "driveline",
    "undriven_wheels": "undriven",
}
"""Which part of the 50 mph breakdown each term belongs to (other terms: "other")."""

PARTS = ("tyre", "aero", "driveline", "undriven")
FIT_SPEED_RANGE_MPS = (5.0, 31.3)
"""Speeds over which F0, F1, F2 are fitted: the coastdown range of the thesis."""


def reference_conditions(speed_mps: Array, mass_kg: float, frontal_area_m2: float,
                         driveline_force_n: Array | float = 0.0) -> Conditions:
    """Still air, level road, reference density and temperature, at the given speeds."""
    v = jnp.asarray(speed_mps, float)
    z = jnp.zeros_like(v)
    return Conditions(
        speed_mps=v, airspeed_mps=v, yaw_rad=z, driveline_force_n=z + driveline_force_n,
        position_m=z, distance_m=z, time_s=z, accel_mps2=z, direction=z + 1.0,
        air_density_kgpm3=z + air_density_kgpm3(), temperature_k=z + config.REFERENCE_TEMPERATURE_K,
        mass_kg=z + mass_kg, frontal_area_m2=z + frontal_area_m2,
    )


def road_load_parts_n(model: DragModel, params: Mapping[str, Array], speed_mps: Array, mass_kg: float,
                      frontal_area_m2: float, driveline_force_n: Array | float = 0.0) -> dict[str, Array]:
    """Road load at reference conditions split into tyre / aero / driveline / undriven (N).

    ``driveline_force_n`` is used by a model whose driveline is measured rather than fitted
    (the caller passes the measured loss at those speeds).  Terms outside the breakdown
    (e.g. gradient) are not part of the road load and are left out.
    """
    c = reference_conditions(speed_mps, mass_kg, frontal_area_m2, driveline_force_n)
    comps = model.force_components_n(params, c)
    out = {part: jnp.zeros_like(c.speed_mps) for part in PARTS}
    for name, force in comps.items():
        part = PART_OF_TERM.get(name)
        if part is not None:
            out[part] = out[part] + force
    return out


def road_load_summary(model: DragModel, params: Mapping[str, Array], mass_kg: float, frontal_area_m2: float,
                      driveline_force_n=None) -> dict[str, Array]:
    """F50_N and its parts, and F0_N, F1_N_per_kph, F2_N_per_kph2.

    Parameters
    ----------
    driveline_force_n : callable or None
        For a measured driveline: a function of speed (m/s) giving the measured loss (N).

    Returns
    -------
    dict with ``F50_N``, ``F50_tyre_N``, ``F50_aero_N``, ``F50_driveline_N``,
    ``F50_undriven_N``, ``F0_N``, ``F1_N_per_kph``, ``F2_N_per_kph2``.
    """
    v50 = jnp.asarray([config.SPEED_50MPH_MPS])
    grid = jnp.linspace(*FIT_SPEED_RANGE_MPS, 64)
    dl50 = 0.0 if driveline_force_n is None else driveline_force_n(v50)
    dlg = 0.0 if driveline_force_n is None else driveline_force_n(grid)
    parts50 = road_load_parts_n(model, params, v50, mass_kg, frontal_area_m2, dl50)
    out = {f"F50_{p}_N": parts50[p][0] for p in PARTS}
    out["F50_N"] = sum(parts50[p][0] for p in PARTS)
    total = sum(road_load_parts_n(model, params, grid, mass_kg, frontal_area_m2, dlg).values())
    v_kph = grid / config.KPH_TO_MPS
    design = jnp.stack([jnp.ones_like(v_kph), v_kph, v_kph**2], axis=1)
    coef, *_ = jnp.linalg.lstsq(design, total)
    out["F0_N"], out["F1_N_per_kph"], out["F2_N_per_kph2"] = coef[0], coef[1], coef[2]
    return out
