"""Drag terms of the sim-to-real candidate effects (pure JAX, no numpyro).

The thesis blamed its unexplained track spreads on effects missing from the analysis model
(ROADLOAD_MODEL.md section 5).  The terms here are those effects not already in
:mod:`.terms`; each is parameterised so that its effect parameter is *linear* in the force and
zero means "no effect" (the diagnosis, :mod:`bayes_roadload.analysis.effects`, linearises every
candidate about that null).  Registered in :data:`~bayes_roadload.physics.terms.TERMS` like
every other term, so the simulator can use them as truth physics and model files can name them.

Sign convention as in :mod:`.terms`: a positive force opposes the motion.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Mapping

import jax.numpy as jnp

from .model import MeasuredAir
from .terms import Conditions, Params, Term, register_term, tyre_temperature_factor

Array = jnp.ndarray

SPEED_REFERENCE_MPS = 20.0
"""Reference speed of the tyre speed-power term (m/s): its coefficient is the extra rolling
loss coefficient at this speed."""

TRACK_REFERENCE_M = 2500.0
"""Track length over which :class:`SpatialWind`'s along-track wind changes by its parameter."""


@register_term
@dataclass(frozen=True)
class TyreTemperatureTransient(Term):
    """Tyre rolling loss changing over the run as the tyres cool (or warm) after the run-up:
    M g (A_D + B_D v) tyre_transient exp(-t / tyre_time_constant_s) (a transient on eq. 2.38;
    the thesis lists tyre temperature change during the run among its unexplained effects).
    ``tyre_transient`` is the fractional change of the tyre loss at the start of the run."""

    name: ClassVar[str] = "tyre_temperature_transient"
    defaults: ClassVar[Mapping[str, float]] = {"tyre_transient": 0.0, "tyre_time_constant_s": 40.0}
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "2.38 with a transient in time"

    def force_n(self, p: Params, c: Conditions) -> Array:
        tyre = c.weight_n * (p["AD"] + p["BD"] * c.speed_mps) * tyre_temperature_factor(p, c)
        return tyre * p["tyre_transient"] * jnp.exp(-c.time_s / p["tyre_time_constant_s"])


@register_term
@dataclass(frozen=True)
class TyreLossLevel(Term):
    """Tyre rolling loss off its law by a constant fraction over the run: M g (A_D + B_D v)
    tyre_level (eq. 2.38 scaled).  With one ``tyre_level`` per run it is each run's tyres
    starting at their own temperature (a warm-up that differs between runs: SAE J2452's
    temperature sensitivity of the rolling loss, GTR 15's warm-up), a level where the run is
    short against the tyres' thermal time constant."""

    name: ClassVar[str] = "tyre_loss_level"
    defaults: ClassVar[Mapping[str, float]] = {"tyre_level": 0.0}
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "2.38 scaled"

    def force_n(self, p: Params, c: Conditions) -> Array:
        tyre = c.weight_n * (p["AD"] + p["BD"] * c.speed_mps) * tyre_temperature_factor(p, c)
        return tyre * p["tyre_level"]


@register_term
@dataclass(frozen=True)
class TyreSpeedPower(Term):
    """Tyre loss growing faster than linearly with speed: M g tyre_power_coeff (v / v_ref)^b
    (the A + X_D v^b forms of eq. 2.9, b = 4 Dayman, 3.5 Emtage), v_ref =
    :data:`SPEED_REFERENCE_MPS`, ``tyre_speed_exponent`` b fixed (default 4)."""

    name: ClassVar[str] = "tyre_speed_power"
    defaults: ClassVar[Mapping[str, float]] = {"tyre_power_coeff": 0.0, "tyre_speed_exponent": 4.0}
    equation: ClassVar[str] = "2.9"

    def force_n(self, p: Params, c: Conditions) -> Array:
        ratio = jnp.maximum(c.speed_mps, 0.0) / SPEED_REFERENCE_MPS
        return c.weight_n * p["tyre_power_coeff"] * ratio ** p["tyre_speed_exponent"]


@register_term
@dataclass(frozen=True)
class SideSlipDrag(Term):
    """Tyre slip drag of the aerodynamic side force, (q_r A psi)^2 side_slip_coeff_per_n with
    side_slip_coeff_per_n = K_S^2 / (4 C_y) (eq. 2.41-2.46 with C_S = K_S psi; thesis values
    2.4^2 / (4 x 25000) = 5.8e-5 /N): :class:`~.terms.SideForceSlip` with its two parameters
    folded into the one the data can see, linear in the force."""

    name: ClassVar[str] = "side_slip_drag"
    defaults: ClassVar[Mapping[str, float]] = {"side_slip_coeff_per_n": 0.0}
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "2.41-2.46"

    def force_n(self, p: Params, c: Conditions) -> Array:
        return p["side_slip_coeff_per_n"] * (c.dynamic_pressure_area_n * c.yaw_rad) ** 2


@register_term
@dataclass(frozen=True)
class DrivelineQuadratic(Term):
    """An unlogged driveline loss growing with the square of speed, Ct v^2 (the C_t of eq.
    2.15; with the driveline lumped into the tyre terms, A_t and B_t are absorbed by A_D and
    B_D, the quadratic part is not)."""

    name: ClassVar[str] = "driveline_quadratic"
    defaults: ClassVar[Mapping[str, float]] = {"Ct": 0.0}
    equation: ClassVar[str] = "2.15"

    def force_n(self, p: Params, c: Conditions) -> Array:
        return p["Ct"] * c.speed_mps**2


@register_term
@dataclass(frozen=True)
class AnemometerLag(Term):
    """First-order lag of the cup anemometer, to first order in the lag.  The cup reads a_m
    with da_m/dt = (a - a_m) a / d (distance constant d = ``cup_lag_m``), so the true airspeed
    is a = a_m + (d / a_m) da_m/dt and the true drag q_r A C_D differs from the one computed
    with the reading by rho A C_D(psi) d da_m/dt: the reading's own rate
    (``Conditions.airspeed_rate_mps2``), which follows the gusts the cup smooths as well as
    the deceleration (with dv/dt in its place the term is an effective-mass error, rho A C_D
    d).  Negative while decelerating: the lagging reading is too high.  Uses the aerodynamic
    CD0, KD."""

    name: ClassVar[str] = "anemometer_lag"
    defaults: ClassVar[Mapping[str, float]] = {"cup_lag_m": 0.0}
    speed_affine: ClassVar[bool] = True
    needs_measured_air: ClassVar[bool] = True
    equation: ClassVar[str] = "2.26 with a first-order cup (thesis 4.7, 6.3)"

    def force_n(self, p: Params, c: Conditions) -> Array:
        cd = p.get("CD0", 0.4) + p.get("KD", 0.0) * c.yaw_rad**2
        return c.air_density_kgpm3 * c.frontal_area_m2 * cd * p["cup_lag_m"] * c.airspeed_rate_mps2


@register_term
@dataclass(frozen=True)
class AdmittanceFilter(Term):
    """The drag in the air the body feels minus the drag at the reading, scaled by
    ``admittance_gain``: admittance_gain x [q_f A C_D(psi_f) - q_r A C_D(psi)] (eq. 2.26), with
    (v_f, psi_f) the relative air after a first-order filter of the wind of time constant
    ``admittance_length_m`` / v_r (:func:`~bayes_roadload.physics.admittance.felt_air`; thesis
    6.2.3: gusts shorter than the vehicle reach the force attenuated and late), calibrated as the
    readings (``Conditions.felt_airspeed_mps``, ``Conditions.felt_yaw_rad``).  For a short
    body the filter delays the wind by the length (w_f = w - (l / v_r) dw/dt to first order,
    the vehicle's own speed not delayed); for a long one it also takes out the gusts' share of
    the mean of v_r^2 and psi^2 that the body does not feel, which no delay describes.
    Linear in the gain, zero at 0, the full filter at 1; the length is its shape.  Uses the
    aerodynamic CD0, KD."""

    name: ClassVar[str] = "admittance_filter"
    defaults: ClassVar[Mapping[str, float]] = {"admittance_gain": 0.0, "admittance_length_m": 5.0}
    speed_affine: ClassVar[bool] = True
    needs_measured_air: ClassVar[bool] = True
    felt_air_length: ClassVar[str] = "admittance_length_m"
    equation: ClassVar[str] = "2.26 in the air felt after the admittance (thesis 6.2.3)"

    def force_n(self, p: Params, c: Conditions) -> Array:
        if c.felt_airspeed_mps is None or c.felt_yaw_rad is None:
            raise ValueError("admittance_filter reads the felt air (Conditions.felt_airspeed_mps, felt_yaw_rad), "
                             "which only the integrator of logged readings computes")
        cd0, kd = p.get("CD0", 0.4), p.get("KD", 0.0)
        felt = c.felt_airspeed_mps**2 * (cd0 + kd * c.felt_yaw_rad**2)
        read = c.airspeed_mps**2 * (cd0 + kd * c.yaw_rad**2)
        return 0.5 * c.air_density_kgpm3 * c.frontal_area_m2 * p["admittance_gain"] * (felt - read)


@register_term
@dataclass(frozen=True)
class EffectiveMassError(Term):
    """An error in the stated effective mass M_e (eq. 2.2): with the true one M_e + dM the
    equation of motion (M_e + dM) dv/dt = -F is M_e dv/dt = -(F + dM dv/dt), a force
    ``mass_error_kg`` x dv/dt.  It rescales every force: with A_D, B_D, C_D0 free only the
    terms they do not scale (a fixed K_D, lift) can reveal it."""

    name: ClassVar[str] = "mass_error"
    defaults: ClassVar[Mapping[str, float]] = {"mass_error_kg": 0.0}
    uses_accel: ClassVar[bool] = True
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "2.2, 5.4"

    def force_n(self, p: Params, c: Conditions) -> Array:
        return p["mass_error_kg"] * c.accel_mps2


@register_term
@dataclass(frozen=True)
class SpatialWind(Term):
    """An along-track wind that changes along the track and that the anemometer does not
    record (wind near the ground below the probe, shelter; the thesis' spatial variation,
    section 6.2, case 6): head wind d u(x) with u(x) = ``wind_gradient_mps`` (x / L - 1/2), L =
    :data:`TRACK_REFERENCE_M`, d the direction.  To first order in u the drag changes by
    rho A C_D0 v_r d u(x).  Uses CD0."""

    name: ClassVar[str] = "spatial_wind"
    defaults: ClassVar[Mapping[str, float]] = {"wind_gradient_mps": 0.0}
    equation: ClassVar[str] = "2.26-2.28 with a wind varying along the track"

    def force_n(self, p: Params, c: Conditions) -> Array:
        u = p["wind_gradient_mps"] * (c.position_m / TRACK_REFERENCE_M - 0.5)
        return c.air_density_kgpm3 * c.frontal_area_m2 * p.get("CD0", 0.4) * c.airspeed_mps * c.direction * u


@dataclass(frozen=True)
class OffsetAir(MeasuredAir):
    """Measured relative air with a yaw-vane offset as well as the scale factors:
    true yaw = yaw_factor x reading + yaw_offset_rad (thesis 4.7.3: a vane misaligned with the
    vehicle axis)."""

    defaults: ClassVar[Mapping[str, float]] = {"airspeed_factor": 1.0, "yaw_factor": 1.0, "yaw_offset_rad": 0.0}

    def relative_air(self, p, speed_mps, airspeed_reading_mps, yaw_reading_rad):
        return (p["airspeed_factor"] * airspeed_reading_mps,
                p["yaw_factor"] * yaw_reading_rad + p["yaw_offset_rad"])
