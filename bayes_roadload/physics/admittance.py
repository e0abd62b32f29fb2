"""The vehicle's aerodynamic admittance: the wind the body feels, from the wind its anemometer reads.

Thesis section 6.2.3: "as the gust passes along the car the flow pattern is modified and the
aerodynamic forces change.  This can be simply represented using a first order system, where
the time constant is based on the length of the vehicle and the airspeed".  The anemometer
samples the air at one point; the body integrates it over its length, so gusts shorter than
the vehicle reach the force attenuated.  For the wind components w felt by the body:

    dw_felt/dt = (w - w_felt) V_r / l,         w = (along-track wind, cross wind),

l the vehicle's length and V_r the relative airspeed.  The wind is the relative air minus the
vehicle's own motion (the body feels its own speed at once): w_along = V_r cos(psi) - v,
w_cross = V_r sin(psi).  With the readings calibrated (true = factor x reading, thesis
4.7.3), the felt relative air is V_f = |(v + w_along_felt, w_cross_felt)|, psi_f its angle.

Used by the analysis as a transform of the logged channels (:func:`felt_air_readings`): the
felt air is returned in reading units, so that the calibration factors (and their Type B
shifts) act on it as on the readings.  Without the transform a fit takes the anemometer's
gusts as the body's: the variance of psi^2 and of V_r^2 it sees exceeds the one that acts on
the body, which attenuates K_D and C_D0 (an errors-in-variables bias, longer vehicles more).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .integrate import affine_scan

Array = jnp.ndarray

MIN_AIRSPEED_MPS = 1.0
"""Floor of the airspeed in the time constant l / V_r (a reading of zero would stop the filter)."""


@jax.jit
def first_order_lag(time_s: Array, target: Array, time_constant_s: Array) -> Array:
    """The output y of dy/dt = (x - y) / tau on the sample grid ([N] arrays), y(0) = x(0), for
    ``target`` x piecewise linear between samples and tau held over each step (its mean over
    the step's two samples), exact for that input:

        y_{k+1} = a_k y_k + x_{k+1} - a_k x_k - (x_{k+1} - x_k) tau_k (1 - a_k) / h_k,
        a_k = exp(-h_k / tau_k).

    Zero-length steps (padding) leave y unchanged.  Composed as affine maps by
    :func:`~bayes_roadload.physics.integrate.affine_scan` (as :func:`~bayes_roadload.physics.integrate.lagged_speed_drop`),
    in its sequential form: the filter transforms the data once and is not differentiated, so
    the program that compiles fastest is the one to take."""
    t = jnp.asarray(time_s, float)
    x = jnp.asarray(target, float)
    tau_s = jnp.asarray(time_constant_s, float)
    tau = 0.5 * (tau_s[1:] + tau_s[:-1])
    h = jnp.diff(t)
    ok = h > 0
    a = jnp.where(ok, jnp.exp(-h / tau), 1.0)
    ratio = jnp.where(ok, -jnp.expm1(-h / tau) * tau / jnp.where(ok, h, 1.0), 1.0)
    dx = jnp.diff(x)
    b = jnp.where(ok, x[1:] - a * x[:-1] - dx * ratio, 0.0)
    gain, offset = affine_scan(a, b, sequential=True)
    return jnp.concatenate([x[:1], gain * x[0] + offset])


@jax.jit
def felt_air(time_s: Array, speed_mps: Array, airspeed_mps: Array, yaw_rad: Array,
             vehicle_length_m: Array) -> tuple[Array, Array]:
    """The relative airspeed (m/s) and yaw (rad) the body feels, from the true relative air at
    the anemometer and the vehicle's speed over the ground ([N] arrays of one run): the wind
    components through :func:`first_order_lag` with tau = l / V_r (module docstring)."""
    v = jnp.asarray(speed_mps, float)
    va = jnp.asarray(airspeed_mps, float)
    psi = jnp.asarray(yaw_rad, float)
    along = va * jnp.cos(psi) - v
    cross = va * jnp.sin(psi)
    tau = vehicle_length_m / jnp.maximum(va, MIN_AIRSPEED_MPS)
    along_f = first_order_lag(time_s, along, tau)
    cross_f = first_order_lag(time_s, cross, tau)
    return jnp.hypot(v + along_f, cross_f), jnp.arctan2(cross_f, v + along_f)


def felt_air_readings(time_s: Array, speed_mps: Array, airspeed_reading: Array, yaw_reading: Array,
                      airspeed_factor: float, yaw_factor: float, vehicle_length_m: float) -> tuple[Array, Array]:
    """:func:`felt_air` of calibrated readings, returned as readings (divided by the factors):
    [N] or [R, N] arrays (runs on the first axis; padded samples, whose time step is zero,
    hold the last value).  One compiled program per array shape: the factors and the length
    are its arguments, so a Type B shift of a factor reuses it."""
    t = jnp.asarray(time_s, float)
    args = (t, jnp.asarray(speed_mps, float), jnp.asarray(airspeed_reading, float), jnp.asarray(yaw_reading, float),
            jnp.asarray(airspeed_factor, float), jnp.asarray(yaw_factor, float), jnp.asarray(vehicle_length_m, float))
    return _felt_air_readings(*args) if t.ndim == 1 else _felt_air_readings_runs(*args)


def _felt_air_reading(t, v, a, y, airspeed_factor, yaw_factor, length):
    va, psi = felt_air(t, v, airspeed_factor * a, yaw_factor * y, length)
    return va / airspeed_factor, psi / yaw_factor


_felt_air_readings = jax.jit(_felt_air_reading)
_felt_air_readings_runs = jax.jit(jax.vmap(_felt_air_reading, in_axes=(0, 0, 0, 0, None, None, None)))
