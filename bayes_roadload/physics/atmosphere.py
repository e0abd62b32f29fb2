"""Air density and the reference conditions of the thesis (section 2.2.1.3)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .. import config


SATURATION_COEFFICIENTS = (1.2378847e-5, -1.9121316e-2, 33.93711047, -6.3431645e3)
"""A (K^-2), B (K^-1), C, D (K) of the saturation vapour pressure over water of the CIPM-2007
air-density equation (Picard et al., Metrologia 45 (2008) 149, eq. A1.6)."""
ENHANCEMENT_COEFFICIENTS = (1.00062, 3.14e-8, 5.6e-7)
"""alpha, beta (Pa^-1), gamma (K^-2) of the enhancement factor f = alpha + beta p + gamma t^2
(t in degrees Celsius), CIPM-2007 eq. A1.7."""
VAPOUR_MOLAR_MASS_RATIO = 18.01528 / 28.96546
"""M_v / M_a: water vapour over dry air (CIPM-2007), so 1 - M_v / M_a = 0.37804."""


def _xp(*values):
    return jnp if any(isinstance(v, jax.Array) for v in values) else np


def saturation_vapour_pressure_pa(temperature_k):
    """p_sv = exp(A T^2 + B T + C + D / T) over liquid water (CIPM-2007 eq. A1.6, 273-303 K
    and used a little beyond): 611.7 Pa at 0.01 C, 2339 Pa at 20 C, 4247 Pa at 30 C."""
    xp = _xp(temperature_k)
    t = xp.asarray(temperature_k)
    a, b, c, d = SATURATION_COEFFICIENTS
    return xp.exp(a * t * t + b * t + c + d / t)


def vapour_mole_fraction(pressure_pa, temperature_k, relative_humidity):
    """x_v = h f(p, t) p_sv(T) / p (CIPM-2007 eq. A1.5), ``relative_humidity`` h as a fraction."""
    xp = _xp(pressure_pa, temperature_k, relative_humidity)
    p, t = xp.asarray(pressure_pa), xp.asarray(temperature_k)
    alpha, beta, gamma = ENHANCEMENT_COEFFICIENTS
    f = alpha + beta * p + gamma * (t - 273.15) ** 2
    return xp.asarray(relative_humidity) * f * saturation_vapour_pressure_pa(t) / p


def air_density_kgpm3(pressure_pa=config.REFERENCE_PRESSURE_PA,
                      temperature_k=config.REFERENCE_TEMPERATURE_K,
                      relative_humidity=None):
    """rho = p / (R T) [1 - x_v (1 - M_v / M_a)]: dry air (R = 287.05 J/(kg K)) with the
    water vapour of ``relative_humidity`` (a fraction, 0-1; None or 0: dry air) replacing its
    own volume of air (CIPM-2007 eq. A1.1 with the compressibility Z = 1, as in the dry case;
    x_v from :func:`vapour_mole_fraction`).

    Moist air is lighter: at 20 C and 100 kPa, 50 % relative humidity lowers the density by
    0.45 % (1.1829 against 1.1882 kg/m^3), at 30 C by 0.81 %.  The standards' corrections
    (SAE J1263, 40 CFR 1066.310) take dry air at the logged temperature and pressure, the
    reference density included; with the humidity logged, the coefficients of the dynamic
    pressure (C_D0, K_D) are the air's own and F2 is the road load in dry reference air.

    A JAX array (or tracer) in gives a JAX array; NumPy or Python numbers give NumPy (no device
    dispatch, which would compile a small program for every new array shape while a campaign is
    read).
    """
    xp = _xp(pressure_pa, temperature_k, relative_humidity)
    dry = xp.asarray(pressure_pa) / (config.GAS_CONSTANT_AIR_J_PER_KG_K * xp.asarray(temperature_k))
    if relative_humidity is None:
        return dry
    x_v = vapour_mole_fraction(pressure_pa, temperature_k, relative_humidity)
    return dry * (1.0 - x_v * (1.0 - VAPOUR_MOLAR_MASS_RATIO))


REFERENCE_AIR_DENSITY_KGPM3 = float(air_density_kgpm3())
