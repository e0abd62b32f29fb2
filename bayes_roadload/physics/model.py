"""A drag model is a tuple of drag terms plus a description of the relative air.

The equation of motion of a coasting vehicle (eq. 5.4) is ``M_e dv/dt = -F(v, ...)`` where ``F``
is the sum of the terms' forces.  Terms that depend on dv/dt (pitch attitude) make ``F`` affine
in the acceleration; :meth:`DragModel.acceleration_mps2` solves that exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Mapping, Sequence

import jax.numpy as jnp

from .terms import (
    TERMS,
    AeroDrag,
    AeroDragTable,
    Conditions,
    DrivelineMeasured,
    DrivelinePolynomial,
    LiftUnloading,
    PitchAttitude,
    SideForceSlip,
    Term,
    TyreRolling,
    UndrivenWheels,
)

Array = jnp.ndarray


@dataclass(frozen=True)
class MeasuredAir:
    """Relative airspeed and yaw from on-board anemometers: true = factor x reading
    (thesis section 4.7.3 calibration factors)."""

    defaults: ClassVar[Mapping[str, float]] = {"airspeed_factor": 1.0, "yaw_factor": 1.0}

    def relative_air(self, p, speed_mps, airspeed_reading_mps, yaw_reading_rad):
        return p["airspeed_factor"] * airspeed_reading_mps, p["yaw_factor"] * yaw_reading_rad


@dataclass(frozen=True)
class StillAir:
    """No anemometer and no wind: v_r = v, psi = 0."""

    defaults: ClassVar[Mapping[str, float]] = {}

    def relative_air(self, p, speed_mps, airspeed_reading_mps, yaw_reading_rad):
        return speed_mps, jnp.zeros_like(speed_mps)


@dataclass(frozen=True)
class WindAir:
    """Relative air from a steady wind given as parameters (no anemometer): head-wind
    ``head_wind_mps`` (positive opposes the motion) and cross-wind ``cross_wind_mps``;
    v_r^2 = (v + v_h)^2 + v_x^2, psi = atan2(v_x, v + v_h) (eq. 2.27-2.29).  Per-run values
    (shape [R]) give Ivens' latent wind per run."""

    defaults: ClassVar[Mapping[str, float]] = {"head_wind_mps": 0.0, "cross_wind_mps": 0.0}

    def relative_air(self, p, speed_mps, airspeed_reading_mps, yaw_reading_rad):
        along = speed_mps + p["head_wind_mps"]
        cross = p["cross_wind_mps"]
        return jnp.sqrt(along**2 + cross**2), jnp.arctan2(cross, along)


AIR_MODELS = {"measured": MeasuredAir, "still": StillAir, "wind": WindAir}


@dataclass(frozen=True)
class DragModel:
    """The total resisting force as a sum of :class:`~bayes_roadload.physics.terms.Term` s.

    Parameters
    ----------
    terms : tuple of Term
        The effects included.  Each term's parameters are looked up by name in the parameter
        mapping passed to the methods; :attr:`defaults` gives a complete mapping.
    air : MeasuredAir, StillAir or WindAir
        How the relative airspeed and yaw are obtained from the logged channels.
    """

    terms: tuple[Term, ...]
    air: MeasuredAir | StillAir | WindAir = field(default_factory=MeasuredAir)

    def __post_init__(self):
        names = [t.name for t in self.terms]
        if len(set(names)) != len(names):
            raise ValueError(f"a drag term appears twice in {names}")
        lags = {t.lag_time_constant for t in self.terms if t.lag_time_constant}
        if len(lags) > 1:
            raise ValueError(f"terms {names} name {len(lags)} lag time constants ({sorted(lags)}); "
                             "a model carries at most one lagged speed drop")
        felt = {t.felt_air_length for t in self.terms if t.felt_air_length}
        if len(felt) > 1:
            raise ValueError(f"terms {names} name {len(felt)} admittance lengths ({sorted(felt)}); "
                             "a model carries at most one felt air")

    @property
    def lag_time_constant(self) -> str:
        """The parameter naming the time constant of the lagged speed drop a term reads
        (:attr:`~bayes_roadload.physics.terms.Term.lag_time_constant`), or ""."""
        return next((t.lag_time_constant for t in self.terms if t.lag_time_constant), "")

    @property
    def felt_air_length(self) -> str:
        """The parameter naming the length of the admittance filter whose felt air a term reads
        (:attr:`~bayes_roadload.physics.terms.Term.felt_air_length`), or ""."""
        return next((t.felt_air_length for t in self.terms if t.felt_air_length), "")

    @property
    def term_names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.terms)

    @property
    def defaults(self) -> dict[str, float]:
        """Every parameter the model uses, with its default value (SI units)."""
        out: dict[str, float] = {}
        for t in self.terms:
            for k, v in t.defaults.items():
                out.setdefault(k, v)
        out.update(self.air.defaults)
        return out

    @property
    def speed_affine(self) -> bool:
        """The equation of motion is linear in the speed: measured relative air and every term
        ``speed_affine`` (:class:`~bayes_roadload.physics.terms.Term`)."""
        return isinstance(self.air, MeasuredAir) and all(t.speed_affine for t in self.terms)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(self.defaults)

    def with_terms(self, *extra: Term) -> "DragModel":
        """A new model with ``extra`` terms appended (the sim-to-real diagnosis adds effects)."""
        return DragModel(self.terms + tuple(extra), self.air)

    def without(self, *names: str) -> "DragModel":
        """A new model without the named terms."""
        return DragModel(tuple(t for t in self.terms if t.name not in names), self.air)

    def complete(self, params: Mapping[str, Array]) -> dict[str, Array]:
        """``params`` with every missing parameter filled from :attr:`defaults`."""
        out = {k: jnp.asarray(v) for k, v in self.defaults.items()}
        out.update(params)
        return out

    def force_components_n(self, params: Mapping[str, Array], c: Conditions) -> dict[str, Array]:
        """Each term's force (N) under conditions ``c``."""
        p = self.complete(params)
        return {t.name: t.force_n(p, c) for t in self.terms}

    def force_n(self, params: Mapping[str, Array], c: Conditions) -> Array:
        """Total resisting force F (N) under conditions ``c`` (``c.accel_mps2`` as given)."""
        p = self.complete(params)
        total = jnp.zeros_like(c.speed_mps)
        for t in self.terms:
            total = total + t.force_n(p, c)
        return total

    def acceleration_mps2(
        self, params: Mapping[str, Array], c: Conditions, effective_mass_kg: Array
    ) -> Array:
        """dv/dt = -F / M_e (eq. 5.4), solved exactly when a term depends on dv/dt.

        ``F`` is affine in dv/dt (pitch attitude, eq. 2.33), so with F(a) = F_0 + s a the
        solution of M_e a = -F(a) is a = -F_0 / (M_e + s); the slope s is that of the terms
        which read dv/dt (``uses_accel``), the others are evaluated once.
        """
        zero = jnp.zeros_like(c.speed_mps)
        at_rest = c._replace(accel_mps2=zero)
        f0 = self.force_n(params, at_rest)
        inertial = [t for t in self.terms if t.uses_accel]
        if not inertial:
            return -f0 / effective_mass_kg
        p = self.complete(params)
        unit = c._replace(accel_mps2=zero + 1.0)
        slope = zero
        for t in inertial:
            slope = slope + (t.force_n(p, unit) - t.force_n(p, at_rest))
        return -f0 / (effective_mass_kg + slope)


def simplified_model(*, driveline: str = "none", undriven: bool = False, lift: bool = False,
                     tunnel_table: Mapping[str, Sequence[float]] | None = None, air: str = "measured") -> DragModel:
    """The thesis' analysis model (eq. 2.49): tyres + driveline + undriven wheels + aero.

    Parameters
    ----------
    driveline : {"none", "measured", "polynomial"}
        "measured" uses the logged driveline force (eq. 5.12); "polynomial" fits
        A_t + B_t v + C_t v^2; "none" leaves the driveline loss lumped into the tyre terms.
    undriven : include A_u + B_u v.
    lift : include tyre unloading by lift (C_L known from the tunnel, as in thesis ch. 6).
    tunnel_table : ``{"yaw_deg": [...], "cd": [...]}``, C_D(psi) from this wind-tunnel table
        (:class:`~bayes_roadload.physics.terms.AeroDragTable`) instead of C_D0 + K_D psi^2.
    air : {"measured", "still", "wind"}
    """
    terms: list[Term] = [TyreRolling()]
    if lift:
        terms.append(LiftUnloading())
    if driveline == "measured":
        terms.append(DrivelineMeasured())
    elif driveline == "polynomial":
        terms.append(DrivelinePolynomial())
    elif driveline != "none":
        raise ValueError(f"driveline must be 'none', 'measured' or 'polynomial', not {driveline!r}")
    if undriven:
        terms.append(UndrivenWheels())
    if tunnel_table is None:
        terms.append(AeroDrag())
    else:
        terms.append(AeroDragTable(yaw_deg=tuple(float(x) for x in tunnel_table["yaw_deg"]),
                                   cd=tuple(float(x) for x in tunnel_table["cd"])))
    return DragModel(tuple(terms), AIR_MODELS[air]())


def full_model(*, driveline: str = "none", undriven: bool = False,
               tunnel_table: Mapping[str, Sequence[float]] | None = None, air: str = "measured") -> DragModel:
    """The complete drag function (eq. 2.48): the simplified model plus lift unloading,
    side-force slip and pitch attitude (thesis eq. 6.2 when driveline/undriven are off)."""
    base = simplified_model(driveline=driveline, undriven=undriven, lift=True,
                            tunnel_table=tunnel_table, air=air)
    return base.with_terms(SideForceSlip(), PitchAttitude())


def model_from_names(names, air: str = "measured", **term_options) -> DragModel:
    """Build a model from registered term names; ``term_options[name]`` holds keyword
    arguments for that term's constructor (e.g. a tunnel table or a gradient profile)."""
    terms = []
    for n in names:
        if n not in TERMS:
            raise ValueError(f"unknown drag term {n!r}; known: {sorted(TERMS)}")
        terms.append(TERMS[n](**term_options.get(n, {})))
    return DragModel(tuple(terms), AIR_MODELS[air]())
