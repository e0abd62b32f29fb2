"""Air density and the reference conditions of the thesis (section 2.2.1.3)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .. import config


def air_density_kgpm3(pressure_pa=config.REFERENCE_PRESSURE_PA,
                      temperature_k=config.REFERENCE_TEMPERATURE_K):
    """rho = p / (R T) for dry air, R = 287.05 J/(kg K).

    At the reference conditions (100 kPa, 293.2 K) this is 1.1882 kg/m^3.  A JAX array (or
    tracer) in gives a JAX array; NumPy or Python numbers give NumPy (no device dispatch, which
    would compile a small program for every new array shape while a campaign is read).
    """
    xp = jnp if isinstance(pressure_pa, jax.Array) or isinstance(temperature_k, jax.Array) else np
    return xp.asarray(pressure_pa) / (config.GAS_CONSTANT_AIR_J_PER_KG_K * xp.asarray(temperature_k))


REFERENCE_AIR_DENSITY_KGPM3 = float(air_density_kgpm3())
