"""Undriven-wheel spin-down (thesis section 5.6, eq. 5.13-5.14): pure JAX.

A wheel of the undriven axle, jacked off the ground, is spun up by a motor, released and left to
decelerate while its angular speed is logged.  Its equation of motion (eq. 5.13, reconstructed:
the transcript lost the equation) is

    I_w d(omega)/dt = -F_w(v) R_r,      F_w(v) = A_w + B_w v,      v = omega R_r

with ``I_w`` the wheel's polar moment of inertia (kg m^2) about its axle (wheel, tyre, hub,
brake disc), ``R_r`` the rolling radius and ``F_w`` the drag of that wheel referred to its tread
(bearing friction and brake drag, eq. 2.16 for one wheel).  In the tread speed ``v`` it is a
coastdown of the equivalent mass ``m_w = I_w / R_r^2``:

    m_w dv/dt = -(A_w + B_w v).

For this linear drag the speed has a closed form (used by the fit instead of an integrator):

    v(t) = v_0 exp(-k t) - (A_w / m_w) (1 - exp(-k t)) / k,     k = B_w / m_w,

tending to ``v_0 - A_w t / m_w`` as ``B_w -> 0`` (evaluated with ``expm1`` so that limit is
exact).  It holds while the wheel turns (``v > 0``); the Coulomb part ``A_w`` stops it at
:func:`spindown_stop_time_s`.

Eq. 5.14 is the thesis' classical analysis: integrating eq. 5.13 between consecutive samples
gives the mean drag over each interval, ``-m_w (v_{i+1} - v_i) / (t_{i+1} - t_i)`` at the mean
speed ``(v_i + v_{i+1}) / 2`` (:func:`spindown_interval_drag_n`), and a least-squares straight
line through those points gives ``A_w`` and ``B_w``.  The vehicle's undriven-wheel loss
(eq. 2.16) is the sum over its undriven wheels, ``A_u = sum A_w``, ``B_u = sum B_w`` (thesis
table 7.10: nearside 1.66 + offside 1.58 -> A_u = 3.24 N).
"""

from __future__ import annotations

import jax.numpy as jnp

Array = jnp.ndarray


def equivalent_mass_kg(wheel_inertia_kgm2, rolling_radius_m):
    """``m_w = I_w / R_r^2``: the mass whose coastdown in the tread speed is the wheel's spin-down."""
    return jnp.asarray(wheel_inertia_kgm2) / jnp.asarray(rolling_radius_m) ** 2


def spindown_speed_mps(time_s: Array, v0_mps: Array, aw_n: Array, bw_nspm: Array,
                       equivalent_mass: Array) -> Array:
    """Tread speed of a freely decelerating wheel (eq. 5.13 integrated; module docstring).

    Parameters
    ----------
    time_s : times since the release (s); broadcasts with the other arguments.
    v0_mps : tread speed at ``t = 0`` (m/s).
    aw_n, bw_nspm : the wheel's drag ``A_w`` (N) and ``B_w`` (N s/m).
    equivalent_mass : ``I_w / R_r^2`` (kg).

    Returns
    -------
    The speed (m/s); meaningful while it is positive.
    """
    t = jnp.asarray(time_s)
    k = bw_nspm / equivalent_mass
    decay = jnp.exp(-k * t)
    # (1 - exp(-k t)) / k, exact as k -> 0 (value t)
    small = jnp.abs(k) < 1e-12
    k_safe = jnp.where(small, 1.0, k)
    ramp = jnp.where(small, t, -jnp.expm1(-k_safe * t) / k_safe)
    return v0_mps * decay - aw_n / equivalent_mass * ramp


def spindown_stop_time_s(v0_mps, aw_n, bw_nspm, equivalent_mass):
    """Time at which the closed form reaches ``v = 0`` (A_w > 0): ``ln(1 + B_w v_0 / A_w) / k``,
    ``m_w v_0 / A_w`` when ``B_w = 0``."""
    k = bw_nspm / equivalent_mass
    small = jnp.abs(k) < 1e-12
    k_safe = jnp.where(small, 1.0, k)
    return jnp.where(small, equivalent_mass * v0_mps / aw_n,
                     jnp.log1p(bw_nspm * v0_mps / aw_n) / k_safe)


def spindown_interval_drag_n(time_s: Array, speed_mps: Array, equivalent_mass) -> tuple[Array, Array]:
    """Eq. 5.14: the mean drag of the wheel over each sample interval and the interval's mean
    speed, ``(-m_w dv / dt, (v_i + v_{i+1}) / 2)`` ([n - 1] each)."""
    t = jnp.asarray(time_s)
    v = jnp.asarray(speed_mps)
    return -equivalent_mass * jnp.diff(v) / jnp.diff(t), 0.5 * (v[1:] + v[:-1])
