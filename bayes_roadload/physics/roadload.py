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
    "tyre_speed_squared": "tyre",
    "lift_unloading": "tyre",
    "aero_drag": "aero",
    "aero_drag_table": "aero",
    "aero_drag_saturating": "aero",
    "aero_drag_levelling": "aero",
    "side_force_slip": "aero",
    "pitch_attitude": "aero",
    "driveline_polynomial": "driveline",
    "driveline_measured": "driveline",
    "undriven_wheels": "undriven",
    "gradient": None,
    "gradient_profile": None,
    "surveyed_gradient": None,
}
"""Which part of the 50 mph breakdown each term belongs to.  ``None``: not road load (the
track's gradient); a term not listed counts in the total as "other"."""

PARTS = ("tyre", "aero", "driveline", "undriven")


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
    """Road load at reference conditions split into tyre / aero / driveline / undriven /
    other (N).  ``driveline_force_n`` feeds a model whose driveline is measured rather than
    fitted (the measured loss at those speeds)."""
    c = reference_conditions(speed_mps, mass_kg, frontal_area_m2, driveline_force_n)
    comps = model.force_components_n(params, c)
    out = {part: jnp.zeros_like(c.speed_mps) for part in PARTS + ("other",)}
    for name, force in comps.items():
        part = PART_OF_TERM.get(name, "other")
        if part is not None:
            out[part] = out[part] + force
    return out


def road_load_summary(model: DragModel, params: Mapping[str, Array], mass_kg: float, frontal_area_m2: float,
                      *, driveline_curve=(0.0, 0.0, 0.0),
                      reference_speed_mps: float = config.SPEED_50MPH_MPS,
                      fit_speeds_kph=config.ROADLOAD_FIT_SPEEDS_KPH) -> dict[str, Array]:
    """F50_N and its parts, and F0_N, F1_N_per_kph, F2_N_per_kph2 (pure JAX, differentiable).

    Parameters
    ----------
    model, params : the drag model and its parameters (SI; missing ones take defaults).
    mass_kg, frontal_area_m2 : the vehicle.
    driveline_curve : (c2, c1, c0) of a measured driveline loss c0 + c1 v + c2 v^2 (N, v in
        m/s), used by the ``driveline_measured`` term.
    reference_speed_mps : the speed of the breakdown (50 mph).
    fit_speeds_kph : speeds at which the total is evaluated for the least-squares quadratic
        F = F0 + F1 v + F2 v^2 (v in km/h); exact when the model is quadratic in v.

    Returns
    -------
    dict with ``F50_N``, ``F0_N``, ``F1_N_per_kph``, ``F2_N_per_kph2``, ``F50_tyre_N``,
    ``F50_aero_N``, ``F50_driveline_N``, ``F50_undriven_N``.
    """
    grid_kph = jnp.asarray(fit_speeds_kph, float)
    v = jnp.concatenate([jnp.asarray([reference_speed_mps], float), grid_kph * config.KPH_TO_MPS])
    c2, c1, c0 = (jnp.asarray(c, float) for c in driveline_curve)
    parts = road_load_parts_n(model, params, v, mass_kg, frontal_area_m2, c0 + c1 * v + c2 * v**2)
    total = sum(parts.values())
    design = jnp.stack([jnp.ones_like(grid_kph), grid_kph, grid_kph**2], axis=1)
    coef = jnp.linalg.pinv(design) @ total[1:]
    out = {"F50_N": total[0], "F0_N": coef[0], "F1_N_per_kph": coef[1], "F2_N_per_kph2": coef[2]}
    out.update({f"F50_{p}_N": parts[p][0] for p in PARTS})
    return out
