"""The coastdown of a vehicle through the wind field, integrated with an adaptive scipy solver.

State ``y = [s, v, dT, wfx, wfy]``: distance travelled (m), speed (m/s), tyre temperature
above its speed equilibrium (K), the wind felt by the body after the aerodynamic admittance
filter (m/s, track frame).  The anemometer (cup rotor speed, vane angle and rate) does not act on
the motion and is integrated afterwards along the motion's dense output.  Forces (N, opposing the motion when positive):

* tyres: ``(M g cos(theta) - L) (c0 + c1 v + c2 v^2) phi_T``, ``L`` the aerodynamic lift and
  ``phi_T`` the tyre temperature factor (ambient and warm-up, linear or exponential law);
* aerodynamics: ``q A C_D`` with ``q = rho v_r^2 / 2`` of the relative air and
  ``C_D = CD0 + KD psi^2 + K4 psi^4 + (dC_D/dh) dh + K_alpha alpha``, ``dh = L / k_heave`` the
  ride-height rise under lift, ``alpha = (M h_cg / k_pitch) dv/dt`` the pitch under braking;
* side-force slip: the aerodynamic side force ``q A K_S psi`` split between the axles, each
  carried at a slip angle ``F_axle / C_axle``, drag ``sum F_axle^2 / C_axle``;
* driveline: ``a + b v + c v^2``;
* gravity along the track: ``M g sin(theta)``, theta from the surveyed elevation.

The inertial pitch term makes the equation implicit in dv/dt; it is linear, so
``dv/dt = -F / (M_e + q A K_alpha M h_cg / k_pitch)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from .track import Track
from .vehicles import TrueVehicle
from .wind import WindField

REFERENCE_TEMPERATURE_K = 293.2
"""Reference of the tyre temperature law (20 C, GTR 15 / thesis T_s = 293.2 K)."""


def moist_air_density(pressure_pa, temperature_k, relative_humidity=0.0):
    """Density of moist air (kg/m^3): dry air and water vapour as ideal gases, vapour
    pressure from the Magnus formula over water."""
    t_c = np.asarray(temperature_k, float) - 273.15
    p_sat = 610.94 * np.exp(17.625 * t_c / (t_c + 243.04))
    p_v = relative_humidity * p_sat
    return (np.asarray(pressure_pa, float) - p_v) / (287.058 * temperature_k) + p_v / (461.495 * temperature_k)


@dataclass(frozen=True)
class AnemometerDynamics:
    """Dynamics of the cup and vane of the on-board anemometer.

    distance_constant_m : cup first-order response length (time constant d / V).
    overspeed_ratio : slow-down time constant / speed-up time constant (>= 1: the rotor
        speeds up faster than it slows down, so it over-reads in turbulence).
    The instrument's position is the ``anemometer_ahead_m`` argument of :func:`simulate_run`.
    vane_damping, vane_wavelength_m : second-order vane, omega_n = 2 pi V / wavelength.
    """

    distance_constant_m: float = 1.5
    overspeed_ratio: float = 1.0
    vane_damping: float = 0.4
    vane_wavelength_m: float = 5.8


INSTRUMENT_STEP_S = 1.0 / 400.0
"""Step of the anemometer's integration (s): 400 Hz, several steps per vane period (the
vane's natural frequency stays below 10 Hz up to 45 m/s at a 4.5 m wavelength)."""


def anemometer_response(dyn: AnemometerDynamics, time_s, airspeed_mps, yaw_rad):
    """Cup and vane states along a fine time grid, driven by the true air at the instrument.

    Cup: first order, rate ``V / d`` towards the airspeed ``V``, divided by
    ``overspeed_ratio`` when slowing down; each step is the exact exponential for the step's
    input.  Vane: ``psi'' = omega^2 (psi_air - psi) - 2 zeta omega psi'``, ``omega = 2 pi V /
    wavelength``, by the trapezoidal (Tustin) rule, which is stable at any step.
    """
    t = np.asarray(time_s, float)
    va, ya = np.asarray(airspeed_mps, float), np.asarray(yaw_rad, float)
    n = t.size
    cup, vane = np.empty(n), np.empty(n)
    c, p, r = va[0], ya[0], 0.0
    for i in range(n):
        if i:
            h = t[i] - t[i - 1]
            target = 0.5 * (va[i] + va[i - 1])
            gain = target / dyn.distance_constant_m
            if target < c:
                gain /= dyn.overspeed_ratio
            c = target + (c - target) * math.exp(-gain * h)
            w = 2 * math.pi * target / dyn.vane_wavelength_m
            a21, a22 = -w * w, -2 * dyn.vane_damping * w
            u = w * w * 0.5 * (ya[i] + ya[i - 1])
            # (I - A h/2) x1 = (I + A h/2) x0 + B h u,  A = [[0, 1], [a21, a22]], B = [0, 1]
            r0 = p + 0.5 * h * r
            r1 = 0.5 * h * a21 * p + (1 + 0.5 * h * a22) * r + h * u
            m11, m12, m21, m22 = 1.0, -0.5 * h, -0.5 * h * a21, 1.0 - 0.5 * h * a22
            det = m11 * m22 - m12 * m21
            p, r = (m22 * r0 - m12 * r1) / det, (-m21 * r0 + m11 * r1) / det
        cup[i], vane[i] = c, p
    return cup, vane


@dataclass(frozen=True)
class RunConditions:
    """What is fixed over one coastdown run (SI)."""

    direction: int
    start_position_m: float
    v0_mps: float
    v_stop_mps: float
    temperature_k: float = REFERENCE_TEMPERATURE_K
    pressure_pa: float = 100_000.0
    relative_humidity: float = 0.0
    gravity_mps2: float = 9.80665
    clock_start_s: float = 0.0
    tyre_factor: float = 1.0
    cd_factor: float = 1.0
    tyre_initial_excess_k: float = 0.0


@dataclass(frozen=True)
class RunTrace:
    """A simulated run on the sample grid ``time_s``; ``airspeed_mps``/``yaw_rad`` are the
    relative air the body feels, ``anem_*`` the true air at the anemometer, ``cup_mps`` and
    ``vane_rad`` the instrument states (before calibration factors, noise and offsets)."""

    time_s: np.ndarray
    position_m: np.ndarray
    distance_m: np.ndarray
    speed_mps: np.ndarray
    airspeed_mps: np.ndarray
    yaw_rad: np.ndarray
    anem_airspeed_mps: np.ndarray
    anem_yaw_rad: np.ndarray
    cup_mps: np.ndarray
    vane_rad: np.ndarray
    driveline_force_n: np.ndarray
    tyre_excess_k: np.ndarray
    air_density_kgpm3: float


def _relative_air(v, direction, wx, wy):
    """Airspeed (m/s) and yaw (rad, positive for air moving to the vehicle's left) of the air
    relative to a vehicle moving at ``v`` in ``direction`` through the wind ``(wx, wy)``."""
    u = v - direction * wx
    c = direction * wy
    return math.hypot(u, c), math.atan2(c, u)


def _tyre_temperature_factor(veh: TrueVehicle, ambient_k: float, excess_k):
    dt = ambient_k - REFERENCE_TEMPERATURE_K + excess_k
    if veh.tyre_temperature_law == "linear":
        return 1.0 - veh.tyre_temp_coeff_per_k * dt
    return np.exp(-veh.tyre_temp_coeff_per_k * dt)


MIN_RUN_SAMPLES = 10
"""Fewest samples of a run cut at the track's end (:func:`_cut_at_track_end`): the data
contract's minimum run length, restated here because this simulator imports nothing of the
analysis."""


def _cut_at_track_end(t: np.ndarray, y: np.ndarray, cond: RunConditions, track: Track | None
                      ) -> tuple[np.ndarray, np.ndarray]:
    """A run whose road load balances above its stop speed (a heavy vehicle of low rolling
    resistance on a downhill mean grade) never reaches it: the logging ends where the vehicle
    leaves the track (``track.start_m``-``track.end_m``), as the driver's would at the end of the
    straight, and the samples on the track are kept.  Raised when there is no track, or when
    the vehicle stays on it to the last sample time or leaves it within
    :data:`MIN_RUN_SAMPLES` samples."""
    if track is None:
        raise RuntimeError("the run did not reach its stop speed within the sample times")
    x = cond.start_position_m + float(cond.direction) * y[0]
    off = np.flatnonzero((x < track.start_m) | (x > track.end_m))
    if off.size == 0:
        raise RuntimeError("the run did not reach its stop speed within the sample times, nor leave the track")
    if off[0] < MIN_RUN_SAMPLES:
        raise RuntimeError(f"the run did not reach its stop speed and left the track after {off[0]} samples "
                           f"(fewer than {MIN_RUN_SAMPLES})")
    return t[:off[0]], y[:, :off[0]]


def simulate_run(vehicle: TrueVehicle, cond: RunConditions, sample_times_s: np.ndarray, *,
                 wind: WindField | None = None, track: Track | None = None, admittance: bool = False,
                 anemometer: AnemometerDynamics | None = None, anemometer_ahead_m: float | None = None,
                 rtol: float = 1e-9) -> RunTrace:
    """Integrate one coastdown from ``v0_mps`` until the speed falls to ``v_stop_mps`` (or, when
    its road load balances above that speed, until it leaves the track: :func:`_cut_at_track_end`).

    Parameters
    ----------
    vehicle : the true vehicle (effects switched off by zeroing its properties).
    cond : the run's conditions.
    sample_times_s : increasing sample times from 0 (s); those after the stop are dropped.
    wind : the wind field (None: still air); track : elevation (None: level).
    admittance : the body feels the wind through a first-order filter of time constant
        length / airspeed (else the wind at its centre, instantly).
    anemometer : cup and vane dynamics (None: their states are not integrated and the
        returned cup / vane equal the true air at the anemometer).
    anemometer_ahead_m : the anemometer's distance ahead of the nose (None: it samples the
        air at the body's centre).
    rtol : relative tolerance of ``solve_ivp`` (DOP853).
    """
    veh, d = vehicle, float(cond.direction)
    m, me, area, g = veh.mass_kg, veh.effective_mass_kg, veh.frontal_area_m2, cond.gravity_mps2
    rho = float(moist_air_density(cond.pressure_pa, cond.temperature_k, cond.relative_humidity))
    pitch_gain = veh.k_alpha_per_rad * m * veh.cg_height_m / veh.pitch_stiffness_nm_per_rad
    ahead = 0.0 if anemometer_ahead_m is None else 0.5 * veh.length_m + anemometer_ahead_m

    def wind_at(x, t):
        if wind is None:
            return 0.0, 0.0
        return wind.velocity_at(float(x), cond.clock_start_s + t)

    def forces(t, y):
        s, v, dtemp, wfx, wfy = y[0], y[1], y[2], y[3], y[4]
        x = cond.start_position_m + d * s
        wx, wy = (wfx, wfy) if admittance else wind_at(x, t)
        vr, psi = _relative_air(v, d, wx, wy)
        vr = np.float64(vr)  # a trial step may overflow: inf (rejected by the solver), not an exception
        q_area = 0.5 * rho * vr**2 * area
        lift = q_area * (veh.cl0 + veh.kl_per_rad2 * psi**2)
        grade = track.grade_at(x) * d if track is not None else 0.0
        cos_t, sin_t = 1.0 / np.sqrt(1.0 + grade**2), grade / np.sqrt(1.0 + grade**2)
        load = m * g * cos_t - lift
        rr = (veh.rr_c0 * cond.tyre_factor + veh.rr_c1_s_per_m * v + veh.rr_c2_s2_per_m2 * v**2)
        tyre = load * rr * _tyre_temperature_factor(veh, cond.temperature_k, dtemp)
        cd = (veh.cd0 * cond.cd_factor + veh.kd_per_rad2 * psi**2 + veh.k4_per_rad4 * psi**4
              + veh.ride_height_cd_per_m * lift / veh.heave_stiffness_n_per_m)
        side = q_area * veh.ks_per_rad * psi
        slip = ((veh.front_side_share * side) ** 2 / veh.axle_cornering_front_n_per_rad
                + ((1.0 - veh.front_side_share) * side) ** 2 / veh.axle_cornering_rear_n_per_rad)
        driveline = veh.driveline_a_n + veh.driveline_b_nspm * v + veh.driveline_c_ns2pm2 * v**2
        total = tyre + q_area * cd + slip + driveline + m * g * sin_t
        accel = -total / (me + q_area * pitch_gain)
        return accel, vr, psi, x, driveline

    def rhs(t, y):
        accel, vr, psi, x, _ = forces(t, y)
        v = y[1]
        dy = np.zeros_like(y)
        dy[0] = v
        dy[1] = accel
        dy[2] = -y[2] / veh.tyre_tau_s - veh.tyre_rise_k_per_mps * accel
        if admittance:
            wx, wy = wind_at(x, t)
            rate = vr / veh.length_m
            dy[3] = (wx - y[3]) * rate
            dy[4] = (wy - y[4]) * rate
        return dy

    def stop(t, y):
        return y[1] - cond.v_stop_mps
    stop.terminal, stop.direction = True, -1

    x0 = cond.start_position_m
    w0 = wind_at(x0, 0.0)
    y0 = np.array([0.0, cond.v0_mps, cond.tyre_initial_excess_k, w0[0], w0[1]])
    # tight on the motion (distance, speed, tyre temperature), looser on the wind filter
    atol = np.array([1e-7, 1e-10, 1e-9, 1e-7, 1e-7])
    rtol_vec = np.array([rtol, rtol, rtol, 1e3 * rtol, 1e3 * rtol])
    ts = np.asarray(sample_times_s, float)
    # the wind filter is stiff where length / airspeed is short: a trial step of DOP853 can
    # overflow there, and the solver rejects it on its error estimate and takes a shorter one
    with np.errstate(over="ignore", invalid="ignore"):
        sol = solve_ivp(rhs, (0.0, ts[-1]), y0, method="DOP853", rtol=rtol_vec, atol=atol,
                        t_eval=ts, events=stop, dense_output=anemometer is not None)
    if sol.status < 0:
        raise RuntimeError(f"coastdown integration failed: {sol.message}")
    t, y = sol.t, sol.y
    if sol.status == 0:
        t, y = _cut_at_track_end(t, y, cond, track)
    out = np.array([forces(ti, yi) for ti, yi in zip(t, y.T)])
    vr, psi, x, drv = out[:, 1], out[:, 2], out[:, 3], out[:, 4]
    anem = np.array([_relative_air(yi[1], d, *wind_at(xi + d * ahead, ti)) for ti, yi, xi in zip(t, y.T, x)])
    if anemometer is not None:
        # the instruments do not act on the motion: integrated afterwards along it
        grid = np.arange(0.0, t[-1] + INSTRUMENT_STEP_S, INSTRUMENT_STEP_S)
        s_grid, v_grid = sol.sol(grid)[:2]
        x_anem = cond.start_position_m + d * (s_grid + ahead)
        if wind is None:
            wxg, wyg = np.zeros_like(grid), np.zeros_like(grid)
        else:
            wxg, wyg = wind.velocity(x_anem, cond.clock_start_s + grid)
        ug, cg = v_grid - d * wxg, d * wyg
        cup_g, vane_g = anemometer_response(anemometer, grid, np.hypot(ug, cg), np.arctan2(cg, ug))
        cup, vane = np.interp(t, grid, cup_g), np.interp(t, grid, vane_g)
    else:
        cup, vane = anem[:, 0], anem[:, 1]
    return RunTrace(time_s=t, position_m=x, distance_m=y[0], speed_mps=y[1], airspeed_mps=vr, yaw_rad=psi,
                    anem_airspeed_mps=anem[:, 0], anem_yaw_rad=anem[:, 1], cup_mps=cup, vane_rad=vane,
                    driveline_force_n=drv, tyre_excess_k=y[2], air_density_kgpm3=rho)
