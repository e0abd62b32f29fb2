"""Instrument and vehicle dynamics of the coastdown simulator (thesis section 6.2.3, table 6.5).

Three blocks, all with time constants that scale with the relative airspeed V_air (they are
fixed in *distance*, as the instruments and the vehicle respond to the air that passes them):

* **cup anemometer** (relative airspeed): first order, time constant ``tau = d_cup / V_air``
  with distance constant d_cup = 1.5 m;
* **yaw vane** (relative yaw angle): second order, damping ratio zeta = 0.4 and undamped natural
  frequency ``omega_n = 2 pi V_air / lambda_n``;
* **vehicle aerodynamic admittance**: first order, ``tau = l_vehicle / V_air`` with the vehicle
  length l = 4.5 m, applied to the wind components the vehicle "feels" for its aerodynamic force.

The simulator integrates these blocks together with the vehicle by RK4 on a fine time grid
(:func:`rk4_step`, :func:`sensor_rates`); the step-response helpers below run the *same* rate
functions through the *same* stepper, so tests of the step responses test the discrete
implementation the simulator uses.

Vane wavelength *(reconstructed)*: the thesis gives a vane "distance constant" of 1.07 m and a
measured damped wavelength of about 5 m.  We take the damped wavelength
``lambda_d = 5.0 m`` as the defining number, so ``lambda_n = lambda_d sqrt(1 - zeta^2)``
(4.58 m at zeta = 0.4) and the damped period is ``lambda_d / V_air``.  With these values the
distance travelled by the air while the vane reaches 50 % of a step (its delay distance,
:func:`vane_delay_distance_m`) is 0.90 m; reading 1.07 m as that delay distance instead would
give lambda_n ~ 5.4 m.  Both numbers are fields of :class:`SensorConfig`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from .. import thesis

Array = jnp.ndarray


@dataclass(frozen=True)
class SensorConfig:
    """Dynamic characteristics of the anemometers and of the vehicle (thesis table 6.5).

    Parameters
    ----------
    cup_distance_constant_m : float
        Distance constant of the cup anemometer d_cup (m): tau = d_cup / V_air.
    vane_damping_ratio : float
        Damping ratio zeta of the yaw vane (0 < zeta < 1).
    vane_damped_wavelength_m : float
        Distance the air travels during one damped oscillation of the vane (m).

    The vehicle's aerodynamic admittance uses the vehicle length
    (:attr:`bayes_roadload.data.Vehicle.length_m`), passed separately to :func:`sensor_rates`.
    """

    cup_distance_constant_m: float = thesis.THESIS_SENSORS["cup_distance_constant_m"]
    vane_damping_ratio: float = thesis.THESIS_SENSORS["vane_damping_ratio"]
    vane_damped_wavelength_m: float = thesis.THESIS_SENSORS["vane_damped_wavelength_m"]

    def __post_init__(self):
        if not 0.0 < self.vane_damping_ratio < 1.0:
            raise ValueError("vane_damping_ratio must be in (0, 1) (an under-damped vane)")
        for name in ("cup_distance_constant_m", "vane_damped_wavelength_m"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be positive")

    @property
    def vane_natural_wavelength_m(self) -> float:
        """Undamped natural wavelength lambda_n = lambda_d sqrt(1 - zeta^2) (m)."""
        return self.vane_damped_wavelength_m * math.sqrt(1.0 - self.vane_damping_ratio**2)


DEFAULT_SENSORS = SensorConfig()
VEHICLE_LENGTH_M = thesis.THESIS_VEHICLE["length_m"]
"""Vehicle length of the thesis simulation (table 6.5), for the admittance time constant."""


# --------------------------------------------------------------------------- rate functions

def first_order_rate(output, target, airspeed_mps, distance_constant_m):
    """d(output)/dt of a first-order lag with time constant ``distance_constant / airspeed``.

    Parameters
    ----------
    output : current output of the lag.
    target : its input (the value it tends to).
    airspeed_mps : airspeed V_air setting the time constant (m/s).
    distance_constant_m : the lag's distance constant (m).
    """
    return (target - output) * airspeed_mps / distance_constant_m


def cup_rate(reading_mps, airspeed_mps, cup_distance_constant_m):
    """Cup anemometer: d(reading)/dt = (V_air - reading) V_air / d_cup (m/s^2)."""
    return first_order_rate(reading_mps, airspeed_mps, airspeed_mps, cup_distance_constant_m)


def second_order_rates(output, output_rate, target, natural_frequency_radps, damping_ratio):
    """x'' + 2 zeta omega_n x' + omega_n^2 x = omega_n^2 u: returns (x', x'')."""
    accel = (natural_frequency_radps**2 * (target - output)
             - 2.0 * damping_ratio * natural_frequency_radps * output_rate)
    return output_rate, accel


def vane_rates(angle_rad, angle_rate_radps, yaw_rad, airspeed_mps, damping_ratio, natural_wavelength_m):
    """Yaw vane, second order: angle'' + 2 zeta omega_n angle' + omega_n^2 angle = omega_n^2 psi,
    omega_n = 2 pi V_air / lambda_n.

    Returns
    -------
    (d angle / dt, d angle_rate / dt) in rad/s and rad/s^2.
    """
    omega_n = 2.0 * math.pi * airspeed_mps / natural_wavelength_m
    return second_order_rates(angle_rad, angle_rate_radps, yaw_rad, omega_n, damping_ratio)


def admittance_rate(felt_wind_mps, wind_mps, airspeed_mps, vehicle_length_m):
    """Aerodynamic admittance of the vehicle: the wind it "feels" lags the true wind by a first
    order with time constant l_vehicle / V_air (m/s^2)."""
    return first_order_rate(felt_wind_mps, wind_mps, airspeed_mps, vehicle_length_m)


N_SENSOR_STATES = 5
"""Sensor state vector: [felt along-track wind, felt cross wind, cup reading, vane angle,
vane angular rate]."""


def sensor_initial_state(wind_along_mps, wind_cross_mps, airspeed_mps, yaw_rad):
    """Steady state of the sensor blocks for constant inputs (the start of a run)."""
    return jnp.stack([
        jnp.asarray(wind_along_mps, float),
        jnp.asarray(wind_cross_mps, float),
        jnp.asarray(airspeed_mps, float),
        jnp.asarray(yaw_rad, float),
        jnp.zeros_like(jnp.asarray(yaw_rad, float)),
    ])


def sensor_rates(state: Array, wind_along_mps, wind_cross_mps, airspeed_mps, yaw_rad,
                 sensors: SensorConfig = DEFAULT_SENSORS,
                 vehicle_length_m: float = VEHICLE_LENGTH_M) -> Array:
    """Time derivative of the sensor state vector (see :data:`N_SENSOR_STATES`).

    Parameters
    ----------
    state : [5] array, the sensor states.
    wind_along_mps, wind_cross_mps : the true wind components at the vehicle (m/s), inputs of
        the admittance filters.
    airspeed_mps, yaw_rad : the true relative airspeed and yaw, inputs of the cup and the vane;
        the airspeed also sets every time constant.
    sensors : the dynamic characteristics of the anemometers.
    vehicle_length_m : length setting the admittance time constant l / V_air (m).
    """
    d_along = admittance_rate(state[0], wind_along_mps, airspeed_mps, vehicle_length_m)
    d_cross = admittance_rate(state[1], wind_cross_mps, airspeed_mps, vehicle_length_m)
    d_cup = cup_rate(state[2], airspeed_mps, sensors.cup_distance_constant_m)
    d_angle, d_rate = vane_rates(state[3], state[4], yaw_rad, airspeed_mps,
                                 sensors.vane_damping_ratio, sensors.vane_natural_wavelength_m)
    return jnp.stack([d_along, d_cross, d_cup, d_angle, d_rate])


def rk4_step(rate: Callable[[Array], Array], y: Array, dt_s) -> Array:
    """One classical Runge-Kutta step of dy/dt = rate(y) (autonomous; the simulator makes the
    inputs a function of the state, e.g. the wind at the current position)."""
    k1 = rate(y)
    k2 = rate(y + 0.5 * dt_s * k1)
    k3 = rate(y + 0.5 * dt_s * k2)
    k4 = rate(y + dt_s * k3)
    return y + (dt_s / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


# --------------------------------------------------------------------------- step responses

def simulate_sensor_step(airspeed_before_mps: float, airspeed_after_mps: float, yaw_step_rad: float,
                         duration_s: float, dt_s: float, sensors: SensorConfig = DEFAULT_SENSORS,
                         wind_step_mps: float = 0.0,
                         vehicle_length_m: float = VEHICLE_LENGTH_M) -> dict[str, np.ndarray]:
    """Step responses of the discrete sensor blocks, as integrated by the simulator.

    At t = 0 the inputs jump from (airspeed_before, yaw 0, wind 0) to
    (airspeed_after, yaw_step, wind_step); the states start in steady state before the step.
    The states are advanced with :func:`rk4_step` of :func:`sensor_rates` at ``dt_s``.

    Returns
    -------
    dict of [n] arrays: ``time_s``, ``cup_mps``, ``vane_rad``, ``felt_along_mps``,
    ``felt_cross_mps`` (n = round(duration / dt) + 1).
    """
    n = int(round(duration_s / dt_s))
    y0 = sensor_initial_state(0.0, 0.0, airspeed_before_mps, 0.0)

    def rate(y):
        return sensor_rates(y, wind_step_mps, wind_step_mps, airspeed_after_mps, yaw_step_rad,
                            sensors, vehicle_length_m)

    def step(y, _):
        y1 = rk4_step(rate, y, dt_s)
        return y1, y1

    _, ys = jax.lax.scan(step, y0, None, length=n)
    ys = np.asarray(jnp.concatenate([y0[None], ys]))
    return {
        "time_s": dt_s * np.arange(n + 1),
        "felt_along_mps": ys[:, 0],
        "felt_cross_mps": ys[:, 1],
        "cup_mps": ys[:, 2],
        "vane_rad": ys[:, 3],
    }


def first_order_step_exact(time_s, before, after, airspeed_mps, distance_constant_m):
    """Closed-form step response of a first-order lag of distance constant d at constant
    airspeed: ``after + (before - after) exp(-t V / d)`` (63.2 % of the step at t = d / V)."""
    t = np.asarray(time_s, float)
    return after + (before - after) * np.exp(-t * airspeed_mps / distance_constant_m)


def vane_step_exact(time_s, yaw_step_rad, airspeed_mps, sensors: SensorConfig = DEFAULT_SENSORS):
    """Closed-form unit-step response of the second-order vane (from rest at 0)::

        psi_m(t) = step [1 - exp(-zeta w_n t) (cos w_d t + zeta / sqrt(1 - zeta^2) sin w_d t)]
    """
    t = np.asarray(time_s, float)
    z = sensors.vane_damping_ratio
    wn = 2.0 * math.pi * airspeed_mps / sensors.vane_natural_wavelength_m
    wd = wn * math.sqrt(1.0 - z**2)
    return yaw_step_rad * (1.0 - np.exp(-z * wn * t) * (np.cos(wd * t) + z / math.sqrt(1.0 - z**2) * np.sin(wd * t)))


def vane_overshoot(damping_ratio: float) -> float:
    """Fractional first overshoot of a second-order step: exp(-pi zeta / sqrt(1 - zeta^2))
    (0.254 at zeta = 0.4)."""
    return math.exp(-math.pi * damping_ratio / math.sqrt(1.0 - damping_ratio**2))


def vane_damped_period_s(airspeed_mps: float, sensors: SensorConfig = DEFAULT_SENSORS) -> float:
    """Damped period of the vane at airspeed V: lambda_d / V (s)."""
    return sensors.vane_damped_wavelength_m / airspeed_mps


def vane_delay_distance_m(sensors: SensorConfig = DEFAULT_SENSORS) -> float:
    """Distance the air travels while the vane reaches 50 % of a step (m), from the closed form
    (independent of the airspeed)."""
    from scipy.optimize import brentq

    # at V = 1 m/s time equals distance; the first 50 % crossing is before the first peak
    peak = 0.5 * sensors.vane_damped_wavelength_m
    return float(brentq(lambda t: vane_step_exact(t, 1.0, 1.0, sensors) - 0.5, 1e-9, peak))
