"""Simulate a coastdown campaign (thesis chapter 6) in the campaign contract format.

Each run is integrated in JAX by RK4 at a fine internal step (0.01 s) with state

    [v, s, t, band-limited wind (2 components x 2 states), felt along-track wind,
     felt cross wind, cup reading, vane angle, vane rate]

(speed, distance travelled, time, the wind band limit, the vehicle's admittance filters and the
anemometer states).  The wind is read from a frozen spatial field (:mod:`.wind`) at the current
track position ``x = start + d s`` (+ runs start at x = 0, - runs at the far end of the track)
and band-limited in time by a second-order Butterworth low-pass at 1 Hz *(reconstructed from
table 6.4's "Dryden filter input noise bandwidth DC-1 Hz"; it removes 6-9 % of the turbulence
std at 31 m/s and 1-2 % at 5 m/s, and keeps the wind smooth enough for 4 Hz logging)*.  The truth
physics is the :class:`~bayes_roadload.physics.DragModel` of the case, called through
:meth:`~bayes_roadload.physics.DragModel.acceleration_mps2` -- the same physics the fitters use:

* "basic" -- :func:`~bayes_roadload.physics.simplified_model` with lift (thesis eq. 6.1);
* "comp"  -- :func:`~bayes_roadload.physics.full_model` (eq. 6.2: + side-force slip, pitch);
* "table" -- eq. 6.1 with C_D(psi) from the wind-tunnel table (case 13).

Without dynamics the aerodynamic force uses the instantaneous wind and the logged airspeed and
yaw are the true relative values; with dynamics the force uses the admittance-filtered wind and
the logged channels are the cup and vane outputs (:mod:`.sensors`).  The states are sampled at
4 Hz; a run ends at the last sample before the true speed falls below 5 m/s.  Measurement noise
(speed, airspeed, yaw; table 6.6) is added to the logged channels and the speed is written to 5
decimals, as the thesis' data files were.  System noise perturbs A_D, B_D, C_D0 per run.

Randomness: every run draws from its own streams, ``SeedSequence(seed, spawn_key=(run, k))``
with k = 0 wind, 1 system noise, 2 measurement noise, so a run's data do not depend on the number
of pairs, and two cases simulated with the same seed share their wind and noise draws (common
random numbers: case 7 differs from case 2 by the dynamics alone).
"""

from __future__ import annotations

import functools
import math
import warnings
from dataclasses import dataclass, field
from typing import Literal, Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from .. import config
from .. import thesis
from ..data.campaign import Anemometer, Campaign, Vehicle
from ..physics.atmosphere import air_density_kgpm3
from ..physics.model import DragModel, full_model, simplified_model
from ..physics.terms import Conditions, DrivelinePolynomial
from . import wind as wind_mod
from .cases import SimulationCase, get_case
from .sensors import (DEFAULT_SENSORS, SensorConfig, rk4_step, second_order_rates,
                      sensor_initial_state, sensor_rates)

Array = jnp.ndarray

_THESIS_VEHICLE = Vehicle(
    mass_kg=thesis.THESIS_VEHICLE["mass_kg"],
    effective_mass_kg=thesis.THESIS_VEHICLE["effective_mass_kg"],
    frontal_area_m2=thesis.THESIS_VEHICLE["frontal_area_m2"],
    rolling_radius_m=thesis.THESIS_VEHICLE["rolling_radius_m"],
    length_m=thesis.THESIS_VEHICLE["length_m"],
)


@dataclass(frozen=True)
class SimulationSettings:
    """Everything of a simulated campaign that is not the case (defaults: thesis ch. 6).

    Parameters
    ----------
    dt_s : float
        Internal RK4 step (s).
    sample_rate_hz : float
        Logging rate (4 Hz, thesis); ``1 / (sample_rate_hz dt_s)`` must be an integer.
    start_speed_mps : float
        Speed at the start of every run (70 mph = 31.29 m/s).
    stop_speed_mps : float
        A run ends at the last sample before the true speed falls below this (m/s).
    max_run_duration_s : float
        Length of the integration window; a run that has not slowed to ``stop_speed_mps`` by
        then is an error.
    track_length_m : float
        Length of the track (m); + runs start at x = 0, - runs at x = track_length.
    wind_margin_m : float
        The wind field extends this far beyond both ends of the track (m).
    wind_grid_step_m : float
        Spatial step of the wind field (m).
    scale_length_head_m, scale_length_cross_m : float
        Dryden scale lengths (table 6.4).
    turbulence_ratio : float
        sigma / mean wind (table 6.4).
    turbulence_reference : {"component", "total"}
        Which mean wind sets sigma (:func:`.wind.turbulence_sigmas`).
    wind_bandwidth_hz : float or None
        Band limit of the wind the vehicle meets: a second-order Butterworth low-pass in time at
        this cut-off (table 6.4's "input noise bandwidth DC-1 Hz"; reconstructed), applied to
        the frozen field sampled at the vehicle's position.  None: the field as it is.
    speed_noise_mps, airspeed_noise_mps, yaw_noise_rad : float
        Measurement noise standard deviations (table 6.6).
    driveline_noise_n : float
        Noise on the optional driveline force channel (N).
    system_noise_std : mapping
        Standard deviation of the true coefficients' system noise (table 6.6).
    system_noise_mode : {"band_limited", "per_run"}
        "band_limited" (default): Gaussian noise added to the coefficients over time, band
        limited to DC-``system_noise_bandwidth_hz`` like the thesis' other noise inputs (ACSL
        adds the noise inside the simulation; reconstructed).  This reproduces the thesis'
        test-to-test spreads of cases 14-19 (table 6.8).  "per_run": one constant offset per run
        (run-to-run variation, as a hierarchical model assumes).
    system_noise_bandwidth_hz : float
        Band limit of the "band_limited" system noise.
    random_force_mps_per_sqrt_s : float
        Intensity q of a white random acceleration (an unmodelled random force per unit
        effective mass, e.g. road roughness): after every internal step of length dt the speed
        moves by q sqrt(dt) N(0, 1), so over a time t it wanders by q sqrt(t) -- the
        integrated (process) noise of the analysis' likelihood
        (:mod:`bayes_roadload.physics.residuals`).  :func:`simulate_campaign` applies it in
        every case, also without measurement or system noise, from a random stream of its own
        (the wind and the other noise do not change with it); default 0 (none).
    speed_decimals : int
        Decimals the logged speed is rounded to (5, as in the thesis data files).
    max_yaw_rad : float
        A run also ends before the first sample whose true or logged yaw exceeds this in
        magnitude (the contract holds |yaw| <= pi/2; strong tail winds near the stop speed can
        turn the relative air round).  A warning is issued when this happens.
    coefficients : mapping
        True A_D, B_D, C_D0, K_D (table 6.3).
    full_model_params : mapping
        C_L0, K_L (lift, all models) and K_S, C_y, K_alpha, pitch gain ("comp" model).
    driveline_params : mapping
        A_t, B_t, C_t of the optional driveline loss (table 8.12).
    sensors : SensorConfig
        Anemometer dynamics (table 6.5).
    vehicle : bayes_roadload.data.Vehicle
        Test vehicle (table 6.3); its length sets the aerodynamic admittance.
    extra_terms : tuple of Term
        Drag terms added to the case's truth physics (e.g. a track gradient or a tyre
        temperature transient the analysis model withholds: the sim-to-real proof suite,
        :mod:`bayes_roadload.analysis.diagnose`).
    extra_params : mapping
        Values of the extra terms' parameters (SI; missing ones take the terms' defaults);
        recorded in the truth.
    """

    dt_s: float = 0.01
    sample_rate_hz: float = 4.0
    start_speed_mps: float = 70.0 * config.MPH_TO_MPS
    stop_speed_mps: float = 5.0
    max_run_duration_s: float = 240.0
    track_length_m: float = 2500.0
    wind_margin_m: float = 500.0
    wind_grid_step_m: float = wind_mod.WIND_GRID_STEP_M
    scale_length_head_m: float = wind_mod.SCALE_LENGTH_M
    scale_length_cross_m: float = wind_mod.SCALE_LENGTH_M
    turbulence_ratio: float = wind_mod.TURBULENCE_RATIO
    turbulence_reference: Literal["component", "total"] = "component"
    wind_bandwidth_hz: float | None = thesis.THESIS_WIND["bandwidth_hz"]
    speed_noise_mps: float = thesis.THESIS_MEASUREMENT_NOISE["speed_mps"]
    airspeed_noise_mps: float = thesis.THESIS_MEASUREMENT_NOISE["airspeed_mps"]
    yaw_noise_rad: float = thesis.THESIS_MEASUREMENT_NOISE["yaw_rad"]
    driveline_noise_n: float = thesis.THESIS_MEASUREMENT_NOISE["driveline_force_n"]
    system_noise_std: Mapping[str, float] = field(default_factory=lambda: dict(thesis.THESIS_SYSTEM_NOISE))
    system_noise_mode: Literal["band_limited", "per_run"] = "band_limited"
    system_noise_bandwidth_hz: float = thesis.THESIS_WIND["bandwidth_hz"]
    random_force_mps_per_sqrt_s: float = 0.0
    speed_decimals: int = 5
    max_yaw_rad: float = config.MAX_LOGGED_YAW_RAD
    coefficients: Mapping[str, float] = field(default_factory=lambda: dict(thesis.THESIS_COEFFICIENTS))
    full_model_params: Mapping[str, float] = field(default_factory=lambda: dict(thesis.THESIS_FULL_MODEL))
    driveline_params: Mapping[str, float] = field(default_factory=lambda: dict(thesis.THESIS_DRIVELINE))
    sensors: SensorConfig = DEFAULT_SENSORS
    vehicle: Vehicle = _THESIS_VEHICLE
    extra_terms: tuple = ()
    extra_params: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self):
        substeps = 1.0 / (self.sample_rate_hz * self.dt_s)
        if self.dt_s <= 0 or self.sample_rate_hz <= 0 or abs(substeps - round(substeps)) > 1e-9:
            raise ValueError("dt_s and sample_rate_hz must be positive with 1/(sample_rate_hz dt_s) "
                             f"an integer, got {substeps:g}")
        if not 0 < self.stop_speed_mps < self.start_speed_mps:
            raise ValueError("need 0 < stop_speed_mps < start_speed_mps")
        if not 0 < self.max_yaw_rad <= math.pi / 2:
            raise ValueError("max_yaw_rad must be in (0, pi/2]")
        if self.system_noise_mode not in ("band_limited", "per_run"):
            raise ValueError("system_noise_mode must be 'band_limited' or 'per_run'")
        if not self.random_force_mps_per_sqrt_s >= 0:
            raise ValueError("random_force_mps_per_sqrt_s must be >= 0")

    @property
    def substeps(self) -> int:
        """Internal steps per logged sample."""
        return int(round(1.0 / (self.sample_rate_hz * self.dt_s)))


DEFAULT_SETTINGS = SimulationSettings()


def case_model(case: SimulationCase | str, *, driveline: bool = False) -> DragModel:
    """The drag model generating the data of a case (its ``model`` field, or the name).

    The relative air is "measured" (the simulator passes the true v_r and psi).  With
    ``driveline`` the off-load driveline loss A_t + B_t v + C_t v^2 is added.
    """
    name = case.model if isinstance(case, SimulationCase) else case
    if name == "basic":
        model = simplified_model(lift=True)
    elif name == "comp":
        model = full_model()
    elif name == "table":
        model = simplified_model(lift=True, tunnel_table=thesis.THESIS_TUNNEL_TABLE)
    else:
        raise ValueError(f"unknown model {name!r}; expected 'basic', 'comp' or 'table'")
    return model.with_terms(DrivelinePolynomial()) if driveline else model


def true_parameters(case: SimulationCase | str, *, driveline: bool = False,
                    settings: SimulationSettings = DEFAULT_SETTINGS) -> dict[str, float]:
    """Nominal true parameters of a case's model (before system noise)."""
    model = case_model(case, driveline=driveline)
    values = {**settings.coefficients, **settings.full_model_params, **settings.driveline_params}
    return {k: float(values[k]) for k in model.parameter_names if k in values}


def run_effective_mass_kg(vehicle: Vehicle, mass_kg: float) -> float:
    """Effective mass of a run at test mass ``mass_kg``: M_e moves by the same amount as M
    (eq. 2.2, M_e = M + I_w / R_r^2, the rotating inertia unchanged by the load), as
    :meth:`bayes_roadload.data.Campaign.to_batch` reads a run's ``mass_kg``."""
    return float(vehicle.effective_mass_kg + (float(mass_kg) - vehicle.mass_kg))


def pair_masses_kg(masses_kg: Sequence[float] | None, pairs: int, vehicle: Vehicle) -> list[float]:
    """The test mass of each of ``pairs`` pairs: the masses assigned to the pairs in turn
    (pair k gets ``masses_kg[(k - 1) % len(masses_kg)]``); without masses every pair is at the
    vehicle's mass.  Refused: masses outside ``config.MASS_RANGE_KG``."""
    if masses_kg is None:
        return [float(vehicle.mass_kg)] * int(pairs)
    masses = [float(m) for m in np.atleast_1d(np.asarray(masses_kg, float))]
    lo, hi = config.MASS_RANGE_KG
    if not masses:
        raise ValueError("masses_kg must hold at least one test mass")
    for m in masses:
        if not (math.isfinite(m) and lo <= m <= hi):
            raise ValueError(f"test mass {m!r} kg is outside the physical range [{lo}, {hi}] kg")
    return [masses[k % len(masses)] for k in range(int(pairs))]


# --------------------------------------------------------------------------- JAX core

def _relative_air(speed, direction, wind_along, wind_cross):
    """v_r, psi from the ground speed and the ground-frame wind (module docstring of .wind)."""
    along = speed + direction * wind_along
    return jnp.sqrt(along**2 + wind_cross**2), jnp.arctan2(wind_cross, along)


BUTTERWORTH_DAMPING = 1.0 / math.sqrt(2.0)
"""Damping ratio of the second-order Butterworth low-pass that band-limits the wind."""


SYSTEM_NOISE_STEP_S = 0.05
"""Time step of the band-limited system-noise series (interpolated linearly in between)."""


def band_limited_noise(n: int, dt_s: float, bandwidth_hz: float, rng: np.random.Generator) -> np.ndarray:
    """Unit-variance Gaussian noise with a flat spectrum from DC to ``bandwidth_hz``, by FFT
    synthesis on ``n`` points ``dt_s`` apart."""
    freqs = np.fft.rfftfreq(n, dt_s)
    keep = (freqs > 0) & (freqs <= bandwidth_hz)
    spec = np.zeros(freqs.size, complex)
    spec[keep] = rng.standard_normal(keep.sum()) + 1j * rng.standard_normal(keep.sum())
    x = np.fft.irfft(spec, n)
    return x / np.sqrt(np.mean(x**2)) if np.any(x) else x


@functools.partial(jax.jit, static_argnames=("model", "n_samples", "substeps", "dynamics", "sensors",
                                             "band_limited", "noise_names"))
def _integrate_runs(params, fields, direction, start_m, masses, consts, sys_noise, kicks, *, model, n_samples,
                    substeps, dynamics, sensors, band_limited, noise_names):
    """Integrate R runs ([R] params, [R, G, 2] wind fields, [R, 2] test and effective masses)
    and sample every ``substeps``.

    ``sys_noise`` ([R, T, k]) is added over time to the parameters ``noise_names`` (a series
    ``SYSTEM_NOISE_STEP_S`` apart, linearly interpolated).  ``kicks`` ([R, n_samples,
    substeps] m/s, or [R, 1, 1] zeros) are added to the speed after each internal step while
    the vehicle moves: the random force of ``SimulationSettings.random_force_mps_per_sqrt_s``.

    State: [v, s, t, band-limited w_a, its rate, band-limited w_c, its rate, 5 sensor states,
    L]: L the speed drop not yet followed by a first-order lag of the model's
    ``lag_time_constant`` (dL/dt = -L / tau - dv/dt, L(0) = 0, of the true speed; the tyre
    thermal lag's :attr:`~bayes_roadload.physics.terms.Conditions.speed_drop_lagged_mps`), kept
    at 0 when the model has no lag.
    Returns a dict of [R, n_samples] arrays.
    """
    (grid_start, grid_dx, dt, v0, v_floor, rho, temp, area, length, band_omega) = consts
    n_grid = fields.shape[1]

    def one_run(p, field_, d, x0, mass_pair, noise_, kick):
        mass, eff_mass = mass_pair[0], mass_pair[1]
        n_noise = noise_.shape[0]

        def params_at(t):
            if not noise_names:
                return p
            u = t / SYSTEM_NOISE_STEP_S
            i = jnp.clip(jnp.floor(u), 0, n_noise - 2).astype(jnp.int32)
            f = jnp.clip(u - i, 0.0, 1.0)
            dz = noise_[i] + f * (noise_[i + 1] - noise_[i])
            return {**p, **{name: p[name] + dz[j] for j, name in enumerate(noise_names)}}

        def field_at(s):
            pos = x0 + d * s
            u = (pos - grid_start) / grid_dx
            i = jnp.clip(jnp.floor(u), 0, n_grid - 2).astype(jnp.int32)
            f = jnp.clip(u - i, 0.0, 1.0)
            w = field_[i] + f * (field_[i + 1] - field_[i])
            return pos, w[0], w[1]

        def wind_seen(y):
            """Position and the wind the vehicle meets (band-limited when asked)."""
            pos, wa, wc = field_at(y[1])
            return (pos, y[3], y[5]) if band_limited else (pos, wa, wc)

        def rate(y):
            v, s, t, lp, sens, lag = y[0], y[1], y[2], y[3:7], y[7:12], y[12]
            pos, wa_field, wc_field = field_at(s)
            if band_limited:
                d_lp = jnp.stack([
                    *second_order_rates(lp[0], lp[1], wa_field, band_omega, BUTTERWORTH_DAMPING),
                    *second_order_rates(lp[2], lp[3], wc_field, band_omega, BUTTERWORTH_DAMPING)])
                wa, wc = lp[0], lp[2]
            else:
                d_lp = jnp.zeros(4)
                wa, wc = wa_field, wc_field
            vr, psi = _relative_air(v, d, wa, wc)
            vr_f, psi_f = _relative_air(v, d, sens[0], sens[1]) if dynamics else (vr, psi)
            c = Conditions(
                speed_mps=v, airspeed_mps=vr_f, yaw_rad=psi_f, driveline_force_n=jnp.zeros_like(v),
                position_m=pos, distance_m=s, time_s=t, accel_mps2=jnp.zeros_like(v), direction=d,
                air_density_kgpm3=rho, temperature_k=temp, mass_kg=mass, frontal_area_m2=area,
                speed_drop_lagged_mps=lag)
            moving = v > v_floor
            p_t = params_at(t)
            dv = jnp.where(moving, model.acceleration_mps2(p_t, c, eff_mass), 0.0)
            ds = jnp.where(moving, v, 0.0)
            d_sens = sensor_rates(sens, wa, wc, vr, psi, sensors, length)
            d_lag = -lag / p_t[model.lag_time_constant] - dv if model.lag_time_constant else jnp.zeros(())
            return jnp.concatenate([jnp.stack([dv, ds, jnp.ones(())]), d_lp, d_sens, d_lag[None]])

        def observe(y):
            pos, wa, wc = wind_seen(y)
            vr, psi = _relative_air(y[0], d, wa, wc)
            return {"speed_mps": y[0], "distance_m": y[1], "position_m": pos, "time_s": y[2],
                    "airspeed_true_mps": vr, "yaw_true_rad": psi, "cup_mps": y[9], "vane_rad": y[10],
                    "wind_along_mps": wa, "wind_cross_mps": wc}

        _, wa0, wc0 = field_at(jnp.zeros(()))
        vr0, psi0 = _relative_air(v0, d, wa0, wc0)
        zero = jnp.zeros(())
        y0 = jnp.concatenate([jnp.stack([v0, zero, zero, wa0, zero, wc0, zero]),
                              sensor_initial_state(wa0, wc0, vr0, psi0), jnp.zeros(1)])

        random = kick.shape[1] > 1

        def substep(j, yy, kick_k):
            yy = rk4_step(rate, yy, dt)
            if random:
                k = jnp.where(yy[0] > v_floor, kick_k[j], 0.0)
                yy = yy.at[0].add(k).at[12].add(-k)  # the lagged speed drop follows the speed's kick
            return yy

        def sample(y, k):
            out = observe(y)
            kick_k = kick[jnp.minimum(k, kick.shape[0] - 1)]
            y = jax.lax.fori_loop(0, substeps, lambda j, yy: substep(j, yy, kick_k), y)
            return y, out

        _, outs = jax.lax.scan(sample, y0, jnp.arange(n_samples))
        return outs

    return jax.vmap(one_run)(params, fields, direction, start_m, masses, sys_noise, kicks)


def simulate_true_runs(model: DragModel, params: Sequence[Mapping[str, float]],
                       winds: Sequence[wind_mod.WindField], directions: Sequence[int], *,
                       dynamics: bool, settings: SimulationSettings = DEFAULT_SETTINGS,
                       system_noise: Mapping[str, np.ndarray] | None = None,
                       masses_kg: Sequence[float] | None = None,
                       random_force: np.ndarray | None = None
                       ) -> list[dict[str, np.ndarray]]:
    """Noise-free channels of coastdown runs through given wind fields, at the logging rate.

    Parameters
    ----------
    model : the truth drag model (relative air "measured": it is given the true v_r, psi).
    params : per run, the model's parameter values (missing ones take the model defaults).
    winds : per run, the wind field (all on the same grid).
    directions : per run, +1 (starting at x = 0) or -1 (starting at x = track_length).
    dynamics : force from the admittance-filtered wind (else the instantaneous wind).
    settings : the simulation settings.
    system_noise : optional, parameter name -> [R, T] perturbation series added over time
        (``SYSTEM_NOISE_STEP_S`` apart, T covering ``settings.max_run_duration_s``).
    masses_kg : optional, per run, the test mass M (kg); default ``settings.vehicle.mass_kg``.
        The effective mass moves by the same amount, M_e = vehicle M_e + (M - vehicle M): the
        rotating inertia does not change with the load (:func:`run_effective_mass_kg`).
    random_force : optional [R, n_samples, substeps] standard normal draws, scaled by
        ``settings.random_force_mps_per_sqrt_s * sqrt(settings.dt_s)`` into the speed's
        increments after each internal step (n_samples = max_run_duration_s x sample rate + 1).

    Returns
    -------
    list of dict of [n_r] arrays, one per run, truncated at the last sample before the speed
    falls below ``settings.stop_speed_mps``: ``time_s``, ``speed_mps``, ``distance_m``,
    ``position_m``, ``airspeed_true_mps``, ``yaw_true_rad`` (the relative air that reaches
    the anemometers), ``cup_mps``, ``vane_rad`` (their dynamic outputs), ``wind_along_mps``,
    ``wind_cross_mps`` (the ground-frame wind at the vehicle).
    """
    r = len(params)
    if not (len(winds) == len(directions) == r) or r == 0:
        raise ValueError("params, winds and directions need one entry per run (at least one)")
    if any(d not in (1, -1) for d in directions):
        raise ValueError("directions must be +1 or -1")
    grid = {(w.start_m, w.dx_m, w.along_mps.size) for w in winds}
    if len(grid) != 1:
        raise ValueError("all wind fields must share one grid")
    start, dx, _ = grid.pop()
    full = [model.complete({k: float(v) for k, v in p.items()}) for p in params]
    stacked = {k: jnp.asarray([float(f[k]) for f in full]) for k in full[0]}
    fields = jnp.asarray(np.stack([np.stack([w.along_mps, w.cross_mps], axis=-1) for w in winds]))
    direction = jnp.asarray(directions, float)
    start_m = jnp.where(direction > 0, 0.0, settings.track_length_m)
    veh = settings.vehicle
    run_masses = [veh.mass_kg] * r if masses_kg is None else [float(m) for m in masses_kg]
    if len(run_masses) != r:
        raise ValueError(f"masses_kg needs one entry per run ({r}), got {len(run_masses)}")
    masses = jnp.asarray([[m, run_effective_mass_kg(veh, m)] for m in run_masses])
    consts = tuple(jnp.asarray(x, float) for x in (
        start, dx, settings.dt_s, settings.start_speed_mps, 0.5 * settings.stop_speed_mps,
        air_density_kgpm3(), config.REFERENCE_TEMPERATURE_K, veh.frontal_area_m2, veh.length_m,
        2.0 * math.pi * (settings.wind_bandwidth_hz or 1.0)))
    n_samples = int(math.floor(settings.max_run_duration_s * settings.sample_rate_hz)) + 1
    names = tuple(system_noise) if system_noise else ()
    if names:
        sys_noise = jnp.asarray(np.stack([np.asarray(system_noise[k], float) for k in names], axis=-1))
    else:
        sys_noise = jnp.zeros((r, 2, 0))
    q = settings.random_force_mps_per_sqrt_s
    if q > 0:
        if random_force is None or np.shape(random_force) != (r, n_samples, settings.substeps):
            raise ValueError(f"random_force_mps_per_sqrt_s = {q:g} needs random_force draws of shape "
                             f"{(r, n_samples, settings.substeps)}")
        kicks = jnp.asarray(q * math.sqrt(settings.dt_s) * np.asarray(random_force, float))
    else:
        kicks = jnp.zeros((r, 1, 1))
    outs = _integrate_runs(stacked, fields, direction, start_m, masses, consts, sys_noise, kicks, model=model,
                           noise_names=names,
                           n_samples=n_samples, substeps=settings.substeps, dynamics=bool(dynamics),
                           sensors=settings.sensors,
                           band_limited=settings.wind_bandwidth_hz is not None)
    outs = {k: np.asarray(v) for k, v in outs.items()}
    runs = []
    for i in range(r):
        below = np.flatnonzero(outs["speed_mps"][i] < settings.stop_speed_mps)
        if below.size == 0:
            raise RuntimeError(
                f"run {i + 1} did not slow to {settings.stop_speed_mps} m/s within "
                f"{settings.max_run_duration_s} s; increase SimulationSettings.max_run_duration_s")
        n = int(below[0])
        run = {k: v[i, :n] for k, v in outs.items()}
        run["time_s"] = np.arange(n) / settings.sample_rate_hz
        w = winds[i]
        if run["position_m"].min() < w.start_m or run["position_m"].max() > w.end_m:
            raise ValueError(
                f"run {i + 1} left the wind field [{w.start_m:g}, {w.end_m:g}] m; increase "
                "SimulationSettings.track_length_m or wind_margin_m")
        runs.append(run)
    return runs


# --------------------------------------------------------------------------- campaign

def _rng(seed: int, run: int, stream: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(int(run), stream)))


def simulate_campaign(case: int | SimulationCase, pairs: int = 1, seed: int = 0, *,
                      driveline: bool = False, settings: SimulationSettings | None = None,
                      masses_kg: Sequence[float] | None = None) -> Campaign:
    """Simulate ``pairs`` opposite-direction pairs of coastdowns of a thesis case (table 6.7).

    Parameters
    ----------
    case : int or SimulationCase
        A case number of table 6.7 (:data:`.cases.CASES`) or a custom case.
    pairs : int
        Number of pairs; runs 2k-1 (direction +1) and 2k (direction -1) form pair k.
    seed : int
        Seed of every random draw; the same seed gives identical data.
    driveline : bool
        Add the driveline off-load loss A_t + B_t v + C_t v^2 (table 8.12) to the truth physics
        and log it as ``driveline_force_n`` (with ``settings.driveline_noise_n`` of Gaussian
        noise when the case has measurement noise).  Fit it with
        ``simplified_model(driveline="measured")``.
    settings : SimulationSettings, optional
        Everything else (defaults: thesis chapter 6).
    masses_kg : sequence of float, optional
        Test masses M (kg) of a campaign at several loads (seed 002's way of separating
        rolling resistance from drag): assigned to the pairs in turn, pair k at
        ``masses_kg[(k - 1) % len(masses_kg)]`` (:func:`pair_masses_kg`); each run's effective
        mass is the vehicle's shifted by the same amount (:func:`run_effective_mass_kg`).  The
        runs then carry a ``mass_kg`` column.  Default: every run at
        ``settings.vehicle.mass_kg``, no column.  A run's wind and noise draws do not depend on
        its mass (common random numbers between loads).

    Returns
    -------
    bayes_roadload.data.Campaign
        Runs with columns run, time_s, speed_mps, direction, pair, airspeed_mps, yaw_rad,
        distance_m, position_m (and driveline_force_n, and mass_kg with ``masses_kg``).
        ``truth`` holds the nominal true
        parameters (A_D, B_D, C_D0, K_D, C_L0, K_L, the "comp" extras, A_t, B_t, C_t when
        simulated), ``tyre_lag_gain_per_mps`` and ``tyre_quadratic_s2_per_m2`` 0 unless an extra
        term sets them (the cases' tyres have no thermal lag and a linear speed law), the case
        number and model, and ``per_run``: ``str(run id)`` -> the A_D, B_D, C_D0 of that run
        after system noise (string keys, as JSON stores them; for the band-limited system noise,
        their mean over the run).
        ``meta`` holds the case, seed and number of pairs and the case's settings.
    """
    settings = DEFAULT_SETTINGS if settings is None else settings
    sc = case if isinstance(case, SimulationCase) else get_case(case)
    if int(pairs) < 1:
        raise ValueError("pairs must be at least 1")
    pairs = int(pairs)
    model = case_model(sc, driveline=driveline).with_terms(*settings.extra_terms)
    nominal = true_parameters(sc, driveline=driveline, settings=settings)
    nominal.update({k: float(v) for k, v in settings.extra_params.items()})

    run_ids = list(range(1, 2 * pairs + 1))
    directions = [1 if rid % 2 == 1 else -1 for rid in run_ids]
    pair_mass = pair_masses_kg(masses_kg, pairs, settings.vehicle)
    run_mass = [pair_mass[(rid - 1) // 2] for rid in run_ids]
    winds, params, per_run = [], [], {}
    n_noise = int(math.ceil(settings.max_run_duration_s / SYSTEM_NOISE_STEP_S)) + 2
    band = sc.system_noise and settings.system_noise_mode == "band_limited"
    series = {k: np.zeros((len(run_ids), n_noise)) for k in settings.system_noise_std} if band else None
    for rid in run_ids:
        winds.append(wind_mod.generate_wind_field(
            sc.head_wind_mps, sc.cross_wind_mps, _rng(seed, rid, 0),
            track_length_m=settings.track_length_m, margin_m=settings.wind_margin_m,
            spatial_beta=sc.spatial_beta, turbulence_ratio=settings.turbulence_ratio,
            scale_length_head_m=settings.scale_length_head_m,
            scale_length_cross_m=settings.scale_length_cross_m, dx_m=settings.wind_grid_step_m,
            turbulence_reference=settings.turbulence_reference))
        p = dict(nominal)
        rng_sys = _rng(seed, rid, 1)
        z = rng_sys.standard_normal(len(settings.system_noise_std))
        if sc.system_noise and not band:
            for zi, (name, std) in zip(z, settings.system_noise_std.items()):
                p[name] = p[name] + std * zi
        if band:
            for name, std in settings.system_noise_std.items():
                series[name][rid - 1] = std * band_limited_noise(
                    n_noise, SYSTEM_NOISE_STEP_S, settings.system_noise_bandwidth_hz, rng_sys)
        params.append(p)

    random_force = None
    if settings.random_force_mps_per_sqrt_s > 0:
        shape = (int(math.floor(settings.max_run_duration_s * settings.sample_rate_hz)) + 1, settings.substeps)
        random_force = np.stack([_rng(seed, rid, 3).standard_normal(shape) for rid in run_ids])
    runs = simulate_true_runs(model, params, winds, directions, dynamics=sc.dynamics, settings=settings,
                              system_noise=series, masses_kg=run_mass, random_force=random_force)
    for i, (rid, p, run) in enumerate(zip(run_ids, params, runs)):
        # per run: the coefficients (band-limited noise: their mean over the run's duration)
        k = max(int(run["time_s"][-1] / SYSTEM_NOISE_STEP_S), 1)
        per_run[str(rid)] = {name: float(p[name] + (series[name][i, :k].mean() if band else 0.0))
                             for name in settings.system_noise_std}

    frames = []
    for rid, d, run, p, mass in zip(run_ids, directions, runs, params, run_mass):
        n = run["speed_mps"].size
        noise = _rng(seed, rid, 2).standard_normal((4, n))
        m = 1.0 if sc.measurement_noise else 0.0
        airspeed = (run["cup_mps"] if sc.dynamics else run["airspeed_true_mps"])
        yaw = (run["vane_rad"] if sc.dynamics else run["yaw_true_rad"])
        cols = {
            "run": np.full(n, rid),
            "time_s": run["time_s"],
            # the speed and the airspeed are magnitudes: a sensor's reading never goes below 0
            # (with a tail wind near the vehicle's speed the relative airspeed nears 0)
            "speed_mps": np.round(np.maximum(run["speed_mps"] + m * settings.speed_noise_mps * noise[0], 0.0),
                                  settings.speed_decimals),
            "direction": np.full(n, d),
            "pair": np.full(n, (rid + 1) // 2),
            "airspeed_mps": np.maximum(airspeed + m * settings.airspeed_noise_mps * noise[1], 0.0),
            "yaw_rad": yaw + m * settings.yaw_noise_rad * noise[2],
            "distance_m": run["distance_m"],
            "position_m": run["position_m"],
        }
        if masses_kg is not None:
            cols["mass_kg"] = np.full(n, mass)
        if driveline:
            v = run["speed_mps"]
            cols["driveline_force_n"] = (p["At"] + p["Bt"] * v + p["Ct"] * v**2
                                         + m * settings.driveline_noise_n * noise[3])
        bad = np.flatnonzero((np.abs(run["yaw_true_rad"]) > settings.max_yaw_rad)
                             | (np.abs(cols["yaw_rad"]) > settings.max_yaw_rad))
        if bad.size:
            k = int(bad[0])
            warnings.warn(f"case {sc.number}, seed {seed}, run {rid}: |yaw| exceeds "
                          f"{settings.max_yaw_rad} rad at {run['speed_mps'][k]:.2f} m/s; the run "
                          "is cut there", RuntimeWarning, stacklevel=2)
            cols = {k2: v2[:k] for k2, v2 in cols.items()}
        frames.append(pd.DataFrame(cols))
    runs_df = pd.concat(frames, ignore_index=True)

    truth: dict = {k: float(settings.coefficients[k]) for k in ("AD", "BD", "CD0", "KD")}
    truth.update({k: float(v) for k, v in nominal.items()})
    truth.update({"case": sc.number, "model": sc.model, "per_run": per_run})
    truth.setdefault("tyre_lag_gain_per_mps", 0.0)  # the case's tyres have no thermal lag unless a term adds one
    truth.setdefault("tyre_quadratic_s2_per_m2", 0.0)  # nor a rolling coefficient curved in speed
    meta = {"case": sc.number, "seed": int(seed), "pairs": pairs, "description": sc.description,
            "model": sc.model, "head_wind_mps": sc.head_wind_mps, "cross_wind_mps": sc.cross_wind_mps,
            "spatial_beta": sc.spatial_beta, "dynamics": sc.dynamics,
            "measurement_noise": sc.measurement_noise, "system_noise": sc.system_noise,
            "system_noise_mode": settings.system_noise_mode,
            "random_force_mps_per_sqrt_s": float(settings.random_force_mps_per_sqrt_s),
            "driveline": bool(driveline), "generator": "bayes_roadload.simulate"}
    if masses_kg is not None:
        meta["masses_kg"] = list(dict.fromkeys(pair_mass))
    tunnel = {"KD": float(settings.coefficients["KD"]),
              "CL0": float(settings.full_model_params["CL0"]),
              "KL": float(settings.full_model_params["KL"]),
              "yaw_deg": list(thesis.THESIS_TUNNEL_TABLE["yaw_deg"]),
              "cd": list(thesis.THESIS_TUNNEL_TABLE["cd"])}
    # a campaign with a lagging cup states its distance constant, as a data sheet would
    anemometer = Anemometer(distance_constant_m=float(settings.sensors.cup_distance_constant_m)
                            if sc.dynamics else 0.0)
    return Campaign(runs_df, settings.vehicle, anemometer, tunnel=tunnel, truth=truth, meta=meta)
