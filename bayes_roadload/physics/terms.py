"""Drag terms: one class per physical effect of the thesis' drag function (eq. 2.48).

Each term is a small frozen object that names its parameters (with defaults and units from
:mod:`bayes_roadload.config`) and returns its contribution to the total resisting force, in
newtons, as a pure JAX function of the parameters and the instantaneous :class:`Conditions`.
A drag model (:mod:`bayes_roadload.physics.model`) is a tuple of terms; adding an effect is one
new class here, registered with :func:`register_term`, and nothing else.

Sign convention: a positive force opposes the motion (it decelerates the vehicle).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Mapping, NamedTuple

import jax.numpy as jnp
import numpy as np

from .. import config

Array = jnp.ndarray
Params = Mapping[str, Array]


class Conditions(NamedTuple):
    """The instantaneous state and inputs a term may use (all SI, scalars or equal shapes).

    Attributes
    ----------
    speed_mps : vehicle speed over the ground, v.
    airspeed_mps : true relative airspeed v_r (after anemometer calibration).
    yaw_rad : true aerodynamic yaw angle psi.
    driveline_force_n : measured driveline (off-load) force at the wheels, 0 if not logged.
    position_m : position along the track from a fixed reference (same for both directions).
    distance_m : distance travelled since the start of the run.
    time_s : time since the start of the run.
    accel_mps2 : dv/dt, for terms that depend on it (pitch attitude, eq. 2.33).
    direction : +1 or -1, the direction of travel along the track axis.
    air_density_kgpm3 : ambient air density rho.
    temperature_k : ambient (tyre) temperature T_0.
    mass_kg : test mass M.
    frontal_area_m2 : frontal area A.
    airspeed_rate_mps2 : d/dt of the airspeed *reading* (the logged channel, before
        calibration), for terms that undo an instrument lag; 0 where no reading is integrated.
    track_grade_rad : the track's rise in its +x direction at the logged position, from a
        level survey of the track (:class:`SurveyedGradient`); 0 where no survey is given.
    felt_airspeed_mps, felt_yaw_rad : the relative air the body feels after an admittance
        filter of the length a model term names (``felt_air_length``;
        :func:`~bayes_roadload.physics.admittance.felt_air`), calibrated as ``airspeed_mps``
        and ``yaw_rad``; None unless a term of the model names that length.
    speed_drop_lagged_mps : the part of the measured speed drop since the start of the run
        that a first-order lag of the model's time constant has not yet followed
        (:func:`~bayes_roadload.physics.integrate.lagged_speed_drop`); 0 unless a term of the
        model names a ``lag_time_constant``.
    speed_measured_mps : the logged speed at the same time, where the model is integrated along a
        speed trace (None elsewhere): a term whose force is not affine in the speed may be
        linearised about it, so that the equation of motion stays affine in the state.
    """

    speed_mps: Array
    airspeed_mps: Array
    yaw_rad: Array
    driveline_force_n: Array
    position_m: Array
    distance_m: Array
    time_s: Array
    accel_mps2: Array
    direction: Array
    air_density_kgpm3: Array
    temperature_k: Array
    mass_kg: Array
    frontal_area_m2: Array
    airspeed_rate_mps2: Array = 0.0
    speed_drop_lagged_mps: Array = 0.0
    track_grade_rad: Array = 0.0
    speed_measured_mps: Array | None = None
    felt_airspeed_mps: Array | None = None
    felt_yaw_rad: Array | None = None

    @property
    def dynamic_pressure_area_n(self) -> Array:
        """q_r A = 0.5 rho v_r^2 A, in newtons (eq. 2.26)."""
        return 0.5 * self.air_density_kgpm3 * self.airspeed_mps**2 * self.frontal_area_m2

    @property
    def weight_n(self) -> Array:
        return self.mass_kg * config.GRAVITY_MPS2


TERMS: dict[str, type["Term"]] = {}


def register_term(cls: type["Term"]) -> type["Term"]:
    """Class decorator: make a term available by its ``name`` (model TOML files use it)."""
    if cls.name in TERMS:
        raise ValueError(f"drag term {cls.name!r} registered twice")
    TERMS[cls.name] = cls
    return cls


@dataclass(frozen=True)
class Term:
    """Base class of a drag term.

    Subclasses set ``name`` (the registry key), ``defaults`` (parameter name -> default value
    in SI units) and implement :meth:`force_n`.  ``uses_accel`` marks terms that depend on
    dv/dt; the model then solves the (affine) implicit equation for the deceleration exactly.
    ``speed_affine`` marks terms whose force is affine in the vehicle speed once the relative
    air (airspeed, yaw) and the logged channels are given, and does not depend on the
    position or distance: with measured air, a model of such terms has a linear equation of
    motion, which the integrator solves in parallel over time
    (:func:`~bayes_roadload.physics.integrate.integrate_run`).  Conservative default: False.
    ``needs_measured_air`` marks terms of the anemometer's reading (its lag, its calibration):
    without a logged airspeed they describe nothing.
    ``lag_time_constant`` names the parameter (a time, s) of the lagged speed drop the term
    reads from :attr:`Conditions.speed_drop_lagged_mps`; the integrator of speed traces
    computes that channel from the measured speed when a model term names one.
    ``felt_air_length`` names the parameter (a length, m) of the admittance filter whose felt
    air the term reads (:attr:`Conditions.felt_airspeed_mps`, :attr:`Conditions.felt_yaw_rad`);
    the integrator computes those channels from the readings and the measured speed.
    """

    name: ClassVar[str] = ""
    defaults: ClassVar[Mapping[str, float]] = {}
    uses_accel: ClassVar[bool] = False
    speed_affine: ClassVar[bool] = False
    needs_measured_air: ClassVar[bool] = False
    lag_time_constant: ClassVar[str] = ""
    felt_air_length: ClassVar[str] = ""
    equation: ClassVar[str] = ""

    def force_n(self, p: Params, c: Conditions) -> Array:  # pragma: no cover - abstract
        raise NotImplementedError


def tyre_temperature_factor(p: Params, c: Conditions) -> Array:
    """[1 - K_T (T_0 - T_s)] of eq. 2.38-2.40, T_s the reference temperature."""
    return 1.0 - p["KT"] * (c.temperature_k - config.REFERENCE_TEMPERATURE_K)


@register_term
@dataclass(frozen=True)
class TyreRolling(Term):
    """Tyre rolling loss M g (A_D + B_D v) [1 - K_T (T_0 - T_s)] (eq. 2.38-2.40, 2.49)."""

    name: ClassVar[str] = "tyre_rolling"
    defaults: ClassVar[Mapping[str, float]] = {
        "AD": 0.01,
        "BD": 2.0e-4,
        "KT": config.TYRE_TEMPERATURE_COEFF_PER_K,
    }
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "2.38-2.40"

    def force_n(self, p: Params, c: Conditions) -> Array:
        return c.weight_n * (p["AD"] + p["BD"] * c.speed_mps) * tyre_temperature_factor(p, c)


@register_term
@dataclass(frozen=True)
class TyreThermalLag(Term):
    """Tyre rolling loss away from its speed equilibrium while the tyre temperature lags the
    falling speed: -M g (A_D + B_D v)[1 - K_T(T_0 - T_s)] G_T L(t).

    A_D and B_D (eq. 2.38) are then the rolling loss with the tyres at the temperature they
    reach at each steady speed.  In a coastdown the tyres cool more slowly than the speed
    falls: with a first-order tyre temperature of time constant tau and a steady rise of r
    kelvin per m/s above ambient, the excess over the equilibrium is dT = r L, where L is the
    speed drop since the start not yet followed by a lag of time constant tau
    (dL/dt = -L / tau - dv/dt, :func:`~bayes_roadload.physics.integrate.lagged_speed_drop`),
    and the rolling loss falls by k dT, k the loss's temperature coefficient (the same law as
    eq. 2.39 about the equilibrium instead of the ambient temperature).  ``tyre_lag_gain_per_mps``
    is G_T = k r (1/(m/s)); ``tyre_lag_time_constant_s`` is tau.  The run starts at equilibrium
    (L(0) = 0, the standards' warm-up at the start speed).  Speed-trace kinds only."""

    name: ClassVar[str] = "tyre_thermal_lag"
    defaults: ClassVar[Mapping[str, float]] = {"tyre_lag_gain_per_mps": 0.0, "tyre_lag_time_constant_s": 400.0}
    speed_affine: ClassVar[bool] = True
    lag_time_constant: ClassVar[str] = "tyre_lag_time_constant_s"
    equation: ClassVar[str] = "2.38-2.39 with a first-order tyre temperature"

    def force_n(self, p: Params, c: Conditions) -> Array:
        tyre = c.weight_n * (p["AD"] + p["BD"] * c.speed_mps) * tyre_temperature_factor(p, c)
        return -tyre * p["tyre_lag_gain_per_mps"] * c.speed_drop_lagged_mps


def _quadratic_line_on_grid(speeds_kph) -> tuple[float, float]:
    """(a, b) of the least-squares line a + b v through v^2 on the road-load speeds (v in m/s)."""
    v = np.asarray(speeds_kph, float) * config.KPH_TO_MPS
    b, a = np.polyfit(v, v**2, 1)
    return float(a), float(b)


TYRE_QUADRATIC_LINE = _quadratic_line_on_grid(config.ROADLOAD_FIT_SPEEDS_KPH)
"""(a, b) of :class:`TyreSpeedSquared`: the least-squares line a + b v through v^2 (m/s) on the
road-load speeds :data:`~bayes_roadload.config.ROADLOAD_FIT_SPEEDS_KPH`."""


@register_term
@dataclass(frozen=True)
class TyreSpeedSquared(Term):
    """The speed-squared part of the rolling loss, orthogonal to A_D + B_D v on the road-load
    speeds: M g C_R (v^2 - a - b v)[1 - K_T (T_0 - T_s)].

    A tyre's rolling coefficient follows A + B v + C v^2 (the SAE J2452 speed law); eq. 2.38
    keeps A_D + B_D v.  Here ``tyre_quadratic_s2_per_m2`` is C_R (s^2/m^2) and a + b v the
    least-squares line through v^2 on the speeds of the F0 + F1 v + F2 v^2 fit
    (:data:`TYRE_QUADRATIC_LINE`), so the term adds no line on those speeds: A_D and B_D keep
    their meaning of the least-squares line through the rolling coefficient over 15-115 km/h,
    whatever C_R.  The lift unloading (eq. 2.40) and the tyre lag act on A_D + B_D v only: on
    a part of a few per cent of the rolling loss, their share of it is of second order.  Along
    a speed trace v^2 is linearised about the logged speed (:attr:`Conditions.speed_measured_mps`),
    which keeps the equation of motion affine in v (the integrator's parallel solution)."""

    name: ClassVar[str] = "tyre_speed_squared"
    defaults: ClassVar[Mapping[str, float]] = {"tyre_quadratic_s2_per_m2": 0.0,
                                               "KT": config.TYRE_TEMPERATURE_COEFF_PER_K}
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "2.38 with the SAE J2452 speed law"

    def force_n(self, p: Params, c: Conditions) -> Array:
        a, b = TYRE_QUADRATIC_LINE
        v = c.speed_mps
        vm = v if c.speed_measured_mps is None else c.speed_measured_mps
        # v^2 about the logged speed vm: vm^2 + 2 vm (v - vm), off by (v - vm)^2 (1e-4 of v^2
        # for 0.1 m/s between model and log at 10 m/s), affine in the state v
        square = vm * (2.0 * v - vm)
        return c.weight_n * p["tyre_quadratic_s2_per_m2"] * (square - a - b * v) * tyre_temperature_factor(p, c)


@register_term
@dataclass(frozen=True)
class LiftUnloading(Term):
    """Tyre unloading by aerodynamic lift: -q_r A C_L(psi) (A_D + B_D v)[1 - K_T(T_0 - T_s)],
    with C_L = C_L0 + K_L psi^2 (eq. 2.40, 2.48).  Uses the tyre coefficients AD, BD."""

    name: ClassVar[str] = "lift_unloading"
    defaults: ClassVar[Mapping[str, float]] = {"CL0": 0.273, "KL": 3.64}
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "2.40, 2.48"

    def force_n(self, p: Params, c: Conditions) -> Array:
        cl = p["CL0"] + p["KL"] * c.yaw_rad**2
        tyre = (p["AD"] + p["BD"] * c.speed_mps) * tyre_temperature_factor(p, c)
        return -c.dynamic_pressure_area_n * cl * tyre


@register_term
@dataclass(frozen=True)
class AeroDrag(Term):
    """Aerodynamic drag q_r A (C_D0 + K_D psi^2) (eq. 2.26, 2.31)."""

    name: ClassVar[str] = "aero_drag"
    defaults: ClassVar[Mapping[str, float]] = {"CD0": 0.4, "KD": 0.614}
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "2.26, 2.31"

    def force_n(self, p: Params, c: Conditions) -> Array:
        return c.dynamic_pressure_area_n * (p["CD0"] + p["KD"] * c.yaw_rad**2)


@register_term
@dataclass(frozen=True)
class AeroDragSaturating(Term):
    """Aerodynamic drag whose yaw rise levels off: q_r A (C_D0 + K_D psi^2 / (1 + c_psi psi^2))
    (eq. 2.26, 2.31 with a saturating yaw shape).

    K_D stays the curvature at zero yaw (d^2 C_D / d psi^2 / 2 at psi = 0, eq. 2.31's K_D);
    ``yaw_saturation_per_rad2`` is c_psi (rad^-2): the yaw term reaches half its ceiling K_D / c_psi
    at psi = 1 / sqrt(c_psi).  c_psi = 0 is :class:`AeroDrag`.  Wind-tunnel C_D(psi) curves rise
    as psi^2 at small yaw and level off beyond 15-25 deg (thesis tunnel table: the quadratic
    fitted over +-15 deg gives K_D 0.76, over +-25 deg 0.45, and this form fits the table with
    K_D 1.16, c_psi 7.7 +- 2.3, rms 0.004 against 0.009 for the quadratic), so a quadratic fitted
    to yaw spread up to 20-40 deg at low speed reads a K_D below the zero-yaw curvature."""

    name: ClassVar[str] = "aero_drag_saturating"
    defaults: ClassVar[Mapping[str, float]] = {"CD0": 0.4, "KD": 0.614, "yaw_saturation_per_rad2": 0.0}
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "2.26, 2.31 with a saturating yaw shape"

    def force_n(self, p: Params, c: Conditions) -> Array:
        psi2 = c.yaw_rad**2
        return c.dynamic_pressure_area_n * (p["CD0"] + p["KD"] * psi2 / (1.0 + p["yaw_saturation_per_rad2"] * psi2))


@register_term
@dataclass(frozen=True)
class AeroDragLevelling(Term):
    """Aerodynamic drag whose yaw rise levels off beyond a knee, linear in its coefficients:
    q_r A (C_D0 + K_D psi^2 - L_psi psi^4 / (psi_k^2 + psi^2)) (eq. 2.26, 2.31 with a levelling
    yaw term).

    K_D stays the curvature at zero yaw (the extra term is O(psi^4)); ``yaw_levelling_per_rad2``
    L_psi is the curvature given up well beyond the knee ``yaw_knee_rad`` psi_k, where C_D rises
    as (K_D - L_psi) psi^2 + L_psi psi_k^2: L_psi = 0 is :class:`AeroDrag`, and L_psi = K_D is
    :class:`AeroDragSaturating` with c_psi = 1 / psi_k^2 (the yaw term levels off at K_D psi_k^2).
    With psi_k = 20 deg the thesis tunnel table (case 13, +-25 deg) gives K_D 1.21, L_psi 1.22,
    rms 0.0042 (the quadratic: 0.009).  Unlike c_psi of the saturating form, L_psi enters
    linearly and has no bound at "no levelling", so a posterior that cannot tell the two
    apart is a straight ridge rather than a cone with its apex at c_psi = 0."""

    name: ClassVar[str] = "aero_drag_levelling"
    defaults: ClassVar[Mapping[str, float]] = {"CD0": 0.4, "KD": 0.614, "yaw_levelling_per_rad2": 0.0,
                                               "yaw_knee_rad": 0.349}
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "2.26, 2.31 with a levelling yaw term"

    def force_n(self, p: Params, c: Conditions) -> Array:
        psi2 = c.yaw_rad**2
        levelling = p["yaw_levelling_per_rad2"] * psi2**2 / (p["yaw_knee_rad"] ** 2 + psi2)
        return c.dynamic_pressure_area_n * (p["CD0"] + p["KD"] * psi2 - levelling)


@register_term
@dataclass(frozen=True)
class AeroDragTable(Term):
    """Aerodynamic drag with C_D(psi) from a wind-tunnel table, linearly interpolated:
    C_D = C_D0 + [C_D,table(psi) - C_D,table(0)], so C_D0 stays the fitted zero-yaw value and
    the table gives the shape (thesis case 13).  Yaw outside the table is held at its ends.

    ``yaw_deg`` (deg, strictly increasing) and ``cd`` (-) are the table; there is no default
    table (the thesis' is :data:`bayes_roadload.thesis.THESIS_TUNNEL_TABLE`)."""

    name: ClassVar[str] = "aero_drag_table"
    defaults: ClassVar[Mapping[str, float]] = {"CD0": 0.4}
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "2.26 with a tabulated C_D(psi)"
    yaw_deg: tuple[float, ...]
    cd: tuple[float, ...]

    def __post_init__(self):
        if len(self.yaw_deg) != len(self.cd) or len(self.yaw_deg) < 2:
            raise ValueError("tunnel table needs matching yaw_deg and cd lists of length >= 2")
        if any(b <= a for a, b in zip(self.yaw_deg, self.yaw_deg[1:])):
            raise ValueError("tunnel table yaw_deg must be strictly increasing")

    def shape(self, yaw_rad: Array) -> Array:
        xp = jnp.deg2rad(jnp.asarray(self.yaw_deg))
        fp = jnp.asarray(self.cd)
        return jnp.interp(yaw_rad, xp, fp) - jnp.interp(0.0, xp, fp)

    def force_n(self, p: Params, c: Conditions) -> Array:
        return c.dynamic_pressure_area_n * (p["CD0"] + self.shape(c.yaw_rad))


@register_term
@dataclass(frozen=True)
class SideForceSlip(Term):
    """Tyre slip drag from the aerodynamic side force: (q_r A |C_S(psi)|)^2 / (4 C_y),
    C_S = K_S psi (eq. 2.41-2.46)."""

    name: ClassVar[str] = "side_force_slip"
    defaults: ClassVar[Mapping[str, float]] = {"KS": 2.4, "Cy": 25_000.0}
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "2.41-2.46"

    def force_n(self, p: Params, c: Conditions) -> Array:
        side = c.dynamic_pressure_area_n * p["KS"] * c.yaw_rad
        return side**2 / (4.0 * p["Cy"])


@register_term
@dataclass(frozen=True)
class PitchAttitude(Term):
    """Drag change with pitch: q_r A K_alpha alpha, alpha = (M l_p / k_p) dv/dt = pitch_gain
    dv/dt (eq. 2.33-2.35)."""

    name: ClassVar[str] = "pitch_attitude"
    defaults: ClassVar[Mapping[str, float]] = {"Kalpha": 0.9, "pitch_gain": 1100.0 * 0.55 / 60e3}
    uses_accel: ClassVar[bool] = True
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "2.33-2.35"

    def force_n(self, p: Params, c: Conditions) -> Array:
        return c.dynamic_pressure_area_n * p["Kalpha"] * p["pitch_gain"] * c.accel_mps2


@register_term
@dataclass(frozen=True)
class DrivelineMeasured(Term):
    """Driveline off-load loss taken from the measured wheel torque (eq. 5.12)."""

    name: ClassVar[str] = "driveline_measured"
    defaults: ClassVar[Mapping[str, float]] = {}
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "5.12"

    def force_n(self, p: Params, c: Conditions) -> Array:
        return c.driveline_force_n


@register_term
@dataclass(frozen=True)
class DrivelinePolynomial(Term):
    """Driveline off-load loss A_t + B_t v + C_t v^2 (eq. 2.14, 2.15); no loss unless the
    coefficients are given or fitted."""

    name: ClassVar[str] = "driveline_polynomial"
    defaults: ClassVar[Mapping[str, float]] = {"At": 0.0, "Bt": 0.0, "Ct": 0.0}
    equation: ClassVar[str] = "2.14, 2.15"

    def force_n(self, p: Params, c: Conditions) -> Array:
        v = c.speed_mps
        return p["At"] + p["Bt"] * v + p["Ct"] * v**2


@register_term
@dataclass(frozen=True)
class UndrivenWheels(Term):
    """Undriven wheel bearing and brake loss A_u + B_u v (eq. 2.16); no loss unless the
    coefficients are given or fitted."""

    name: ClassVar[str] = "undriven_wheels"
    defaults: ClassVar[Mapping[str, float]] = {"Au": 0.0, "Bu": 0.0}
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "2.16"

    def force_n(self, p: Params, c: Conditions) -> Array:
        return p["Au"] + p["Bu"] * c.speed_mps


@register_term
@dataclass(frozen=True)
class Gradient(Term):
    """Constant track gradient: M g sin(d theta), theta the rise of the track in its +x
    direction (rad) and d the direction of travel (eq. 2.1)."""

    name: ClassVar[str] = "gradient"
    defaults: ClassVar[Mapping[str, float]] = {"grade_rad": 0.0}
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "2.1"

    def force_n(self, p: Params, c: Conditions) -> Array:
        return c.weight_n * jnp.sin(c.direction * p["grade_rad"])


@register_term
@dataclass(frozen=True)
class GradientProfile(Term):
    """Track gradient varying along the track: M g sin(d theta(x)), theta(x) linearly
    interpolated in a profile of (position_m, grade_rad) points; ``grade_scale`` scales it
    (1 = the profile as given)."""

    name: ClassVar[str] = "gradient_profile"
    defaults: ClassVar[Mapping[str, float]] = {"grade_scale": 1.0}
    equation: ClassVar[str] = "2.1 with theta(x)"
    position_m: tuple[float, ...] = (0.0, 1.0)
    grade_rad: tuple[float, ...] = (0.0, 0.0)

    def __post_init__(self):
        if len(self.position_m) != len(self.grade_rad) or len(self.position_m) < 2:
            raise ValueError("gradient profile needs matching position_m and grade_rad lists")
        if any(b <= a for a, b in zip(self.position_m, self.position_m[1:])):
            raise ValueError("gradient profile position_m must be strictly increasing")

    def force_n(self, p: Params, c: Conditions) -> Array:
        theta = jnp.interp(c.position_m, jnp.asarray(self.position_m), jnp.asarray(self.grade_rad))
        return c.weight_n * jnp.sin(c.direction * p["grade_scale"] * theta)


@register_term
@dataclass(frozen=True)
class SurveyedGradient(Term):
    """Track gradient from a level survey of the track, read at the vehicle's logged position:
    M g sin(d theta(x)) (eq. 2.1 with theta(x)), theta the ``track_grade_rad`` channel that the
    campaign derives from its survey (``track.csv``) and the logged ``position_m``.  A logged
    channel like the measured driveline force, so the force is affine in the speed and the
    integrator keeps its parallel solve; no parameter."""

    name: ClassVar[str] = "surveyed_gradient"
    defaults: ClassVar[Mapping[str, float]] = {}
    speed_affine: ClassVar[bool] = True
    equation: ClassVar[str] = "2.1 with theta(x) surveyed"

    def force_n(self, p: Params, c: Conditions) -> Array:
        return c.weight_n * jnp.sin(c.direction * c.track_grade_rad)
