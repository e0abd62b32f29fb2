"""Speed-gate interval times: the time (and distance) to coast between two speeds.

From the coastdown equation M_e dv/dt = -F(v) (eq. 5.4) the time to fall from v_1 to v_2 < v_1
is

    t = integral_{v_2}^{v_1} M_e / F(v) dv = integral_{v_2}^{v_1} dv / (-a(v)),

and the distance covered on the way ``integral v / (-a(v)) dv`` (the speed-trap model of seed
002 and the closed form of appendix D for a quadratic F, :func:`~bayes_roadload.physics.
integrate.quadratic_coastdown_time`).  Both are evaluated by Gauss-Legendre quadrature over the
speed with a fixed number of nodes (``config.INTERVAL_QUADRATURE_NODES``): 1/F is smooth and
far from zero over a speed band, so 8 nodes are exact to ~1e-13 relative on a 5 km/h band of a
quadratic road load (tested against appendix D), pure JAX and differentiable in every
parameter.

The deceleration comes from :meth:`~bayes_roadload.physics.model.DragModel.acceleration_mps2`
with the relative air from the model's air description at the node speed (still air, or a
wind given as parameters; measured anemometer channels do not exist in a speed-gate record),
so any term that depends on the speed, the air, the direction (a constant grade) or dv/dt (pitch)
works.  Terms that depend on the position along the track (a gradient profile) cannot be
evaluated in the speed domain and are refused.

Nothing here imports numpyro.
"""

from __future__ import annotations

from typing import Mapping, NamedTuple

import jax.numpy as jnp
import numpy as np

from .. import config
from .model import DragModel, MeasuredAir
from .terms import Conditions

Array = jnp.ndarray

POSITION_TERMS = ("gradient_profile",)
"""Terms that need the position along the track, which a speed-gate record does not give."""


class IntervalBands(NamedTuple):
    """Speed bands of interval-time records, flattened over runs ([B] arrays, SI units).

    ``speed_start_mps > speed_end_mps`` (a coastdown decelerates); the per-run constants
    (``direction``, ``air_density_kgpm3``, ``temperature_k``, ``mass_kg``,
    ``effective_mass_kg``, ``frontal_area_m2``) are repeated on each band of the run.
    """

    speed_start_mps: Array
    speed_end_mps: Array
    direction: Array
    air_density_kgpm3: Array
    temperature_k: Array
    mass_kg: Array
    effective_mass_kg: Array
    frontal_area_m2: Array


def gauss_legendre(n: int = config.INTERVAL_QUADRATURE_NODES) -> tuple[np.ndarray, np.ndarray]:
    """Nodes on [-1, 1] and weights of the n-point Gauss-Legendre rule (numpy constants)."""
    return np.polynomial.legendre.leggauss(int(n))


def check_speed_domain(model: DragModel) -> None:
    """Refuse models that cannot be evaluated from the speed alone."""
    bad = [t for t in model.term_names if t in POSITION_TERMS]
    if bad:
        raise ValueError(f"drag terms {bad} depend on the position along the track, which interval "
                         "times do not record; use the constant 'gradient' term instead")
    if isinstance(model.air, MeasuredAir):
        raise ValueError("interval times carry no anemometer channels: the model's air must be "
                         "'still' or 'wind', not 'measured'")


def _node_conditions(bands: IntervalBands, v: Array, model: DragModel, p: Mapping[str, Array]) -> Conditions:
    """Conditions at the quadrature speeds ``v`` [B, n] of every band."""
    col = lambda x: jnp.asarray(x, float)[:, None] + jnp.zeros_like(v)  # noqa: E731
    airspeed, yaw = model.air.relative_air(p, v, v, jnp.zeros_like(v))
    z = jnp.zeros_like(v)
    return Conditions(
        speed_mps=v, airspeed_mps=airspeed + z, yaw_rad=yaw + z, driveline_force_n=z, position_m=z,
        distance_m=z, time_s=z, accel_mps2=z, direction=col(bands.direction),
        air_density_kgpm3=col(bands.air_density_kgpm3), temperature_k=col(bands.temperature_k),
        mass_kg=col(bands.mass_kg), frontal_area_m2=col(bands.frontal_area_m2))


def interval_times(model: DragModel, params: Mapping[str, Array], bands: IntervalBands,
                   n_nodes: int = config.INTERVAL_QUADRATURE_NODES) -> dict[str, Array]:
    """Time, distance and force sensitivity of every band (Gauss-Legendre in the speed).

    Parameters
    ----------
    model : the drag model (still air or a wind given as parameters).
    params : parameter values, scalars or [B] arrays (one value per band, e.g. a per-run
        head wind repeated on the run's bands); missing ones take the model defaults.
    bands : the speed bands (:class:`IntervalBands`).
    n_nodes : quadrature nodes per band.

    Returns
    -------
    dict of [B] arrays
        ``time_s``: the time to coast from ``speed_start_mps`` to ``speed_end_mps``;
        ``distance_m``: the distance covered meanwhile;
        ``dtime_dforce_s_per_n``: d time / d(a constant extra resisting force), negative
        (integral of -1 / (M_e a^2) dv): how a run-level force offset moves the band's time.
    """
    x, w = gauss_legendre(n_nodes)
    v1 = jnp.asarray(bands.speed_start_mps, float)
    v2 = jnp.asarray(bands.speed_end_mps, float)
    half = 0.5 * (v1 - v2)
    v = 0.5 * (v1 + v2)[:, None] + half[:, None] * jnp.asarray(x)[None, :]
    p = {k: (jnp.asarray(val)[:, None] if jnp.ndim(val) == 1 else jnp.asarray(val))
         for k, val in model.complete(params).items()}
    me = jnp.asarray(bands.effective_mass_kg, float)[:, None]
    decel = -model.acceleration_mps2(p, _node_conditions(bands, v, model, p), me)
    weights = half[:, None] * jnp.asarray(w)[None, :]
    return {
        "time_s": jnp.sum(weights / decel, axis=1),
        "distance_m": jnp.sum(weights * v / decel, axis=1),
        "dtime_dforce_s_per_n": -jnp.sum(weights / (me * decel**2), axis=1),
    }
