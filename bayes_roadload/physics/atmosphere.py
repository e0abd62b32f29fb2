"""Air density and the reference conditions of the thesis (section 2.2.1.3)."""

from __future__ import annotations

import jax.numpy as jnp

from .. import config


def air_density_kgpm3(pressure_pa=config.REFERENCE_PRESSURE_PA,
                      temperature_k=config.REFERENCE_TEMPERATURE_K):
    """rho = p / (R T) for dry air, R = 287.05 J/(kg K).

    At the reference conditions (100 kPa, 293.2 K) this is 1.1882 kg/m^3.
    """
    return jnp.asarray(pressure_pa) / (config.GAS_CONSTANT_AIR_J_PER_KG_K * jnp.asarray(temperature_k))


REFERENCE_AIR_DENSITY_KGPM3 = float(air_density_kgpm3())
