"""Model variants as data: ``models/*.toml`` -> which drag terms, which parameters are free,
fixed or given a prior.

A model file has a ``[model]`` table and one ``[parameters.NAME]`` table per parameter the
analysis treats specially (``NAME`` a contract name from :data:`bayes_roadload.config.PARAMETER_UNITS`)::

    [model]
    name = "four_term"                      # optional, defaults to the file stem
    description = "AD, BD, CD0, KD free (thesis 4-term analysis, table 6.8)"
    terms = ["tyre_rolling", "aero_drag"]   # registered names from physics.terms.TERMS
    driveline = "auto"   # auto | none | measured | polynomial
    lift = "tunnel"      # tunnel | none
    air = "auto"         # auto | measured | still | wind
    admittance = "none"  # none | auto | first_order

    [parameters.AD]
    free = true
    initial = 0.012                          # optional start for optimisers (SI units)
    prior = { dist = "normal", loc = 0.01, scale = 0.01, low = 0.0 }

    [parameters.KD]
    fixed = "tunnel"                         # or a number
    fallback = 0.614                         # used when the campaign has no [tunnel] KD

    [parameters.tyre_quadratic_s2_per_m2]
    fixed = 1.0e-6
    uncertainty = 0.8e-6                     # standard uncertainty (SI) of a fixed number
    uncertainty_distribution = "normal"      # optional: "above" (the true value lies above it)

A fixed number with an ``uncertainty`` is a Type B source of the fit's uncertainty budget (a
model constant known to +-u, GUM 4.3): the posterior holds it at its value, and
:mod:`bayes_roadload.analysis.budget` carries its spread into every draw and ``budget.csv``;
with ``uncertainty_distribution = "above"`` the spread is one-sided, uniform over
[value, value + sqrt(12) u] (:data:`UNCERTAINTY_DISTRIBUTIONS`).

Meaning of the ``[model]`` switches (resolved against a campaign by :meth:`ModelSpec.build`):

``driveline``
    ``"auto"``: the measured driveline force (eq. 5.12) when the campaign logs
    ``driveline_force_n``, else none (the driveline loss is then lumped into the tyre terms);
    ``"measured"`` requires the channel; ``"polynomial"`` fits A_t + B_t v + C_t v^2 (eq. 2.14,
    2.15); ``"none"`` omits the driveline.
``lift``
    ``"tunnel"``: include tyre unloading by lift (eq. 2.40, thesis eq. 6.1) with C_L0 and K_L
    fixed from the campaign's ``[tunnel]`` table when it gives ``CL0`` (K_L = 0 if absent), or
    from ``[parameters.CL0]`` / ``[parameters.KL]`` (which take precedence); the term is left
    out when neither gives C_L0 (a real campaign without tunnel data).  ``"none"``: no lift.
``air``
    ``"auto"``: measured airspeed and yaw (with the campaign's anemometer calibration factors
    fixed) when the campaign logs both, else still air; ``"measured"``, ``"still"`` or
    ``"wind"`` (a steady wind as parameters ``head_wind_mps``, ``cross_wind_mps``) force one.
``admittance``
    The vehicle's aerodynamic admittance (thesis 6.2.3, :mod:`bayes_roadload.physics.admittance`):
    ``"first_order"`` takes the anemometer's wind through a first-order lag of time constant
    l / V_r before it acts on the body (l the vehicle's ``[vehicle] length_m``, required);
    ``"auto"`` does so when the relative air is measured and the campaign states the length,
    else reads the anemometer as the air the body feels, as ``"none"`` always does.

The ``aero_drag_table`` term takes its C_D(yaw) table from the campaign's ``[tunnel]``
``yaw_deg`` / ``cd`` when present, else the thesis table (:data:`bayes_roadload.thesis.THESIS_TUNNEL_TABLE`).

Priors are in physical (SI) units; the Bayesian layer turns them into numpyro distributions
with :meth:`Prior.to_numpyro`.  Parameters the file does not mention keep the model defaults
(the term classes' ``defaults``).
"""

from __future__ import annotations

import hashlib
import importlib.resources
import math
import os
import tomllib
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .. import config
from .. import thesis
from ..data.uncertainty import DISTRIBUTIONS
from ..physics.admittance import felt_air_readings
from ..physics.model import AIR_MODELS, DragModel, model_from_names
from ..physics.terms import TERMS


def _models_dir() -> Path:
    """The model library directory: ``bayes_roadload/models`` of an installed package (package
    data, which pyproject.toml maps from the repository's top-level ``models/``), else, for a
    source tree imported in place (editable install, ``PYTHONPATH``), the ``models/`` beside the
    package directory."""
    package = Path(str(importlib.resources.files("bayes_roadload")))
    installed = package / "models"
    return installed if installed.is_dir() else package.parent / "models"


MODELS_DIR = _models_dir()
"""The directory of the model library (``models/*.toml``), where bare model names are looked up."""

DRIVELINE_OPTIONS = ("auto", "none", "measured", "polynomial")
LIFT_OPTIONS = ("tunnel", "none")
AIR_OPTIONS = ("auto", "measured", "still", "wind")
ADMITTANCE_OPTIONS = ("none", "auto", "first_order")
TUNNEL = "tunnel"
"""The value of ``fixed`` that takes a parameter from the campaign's ``[tunnel]`` table."""

# Terms the [model] switches control: listing them in ``terms`` would be ambiguous.
_SWITCHED_TERMS = {
    "lift_unloading": "lift",
    "driveline_measured": "driveline",
    "driveline_polynomial": "driveline",
}
_DATA_TERMS = {
    "surveyed_gradient": "the campaign's track survey (track.csv)",
}
"""Terms a campaign's data add (:meth:`ModelSpec.build`); listed in a model file they would read
zeros without those data."""
_MODEL_KEYS = ("name", "description", "terms", "driveline", "lift", "air", "admittance")
_PARAMETER_KEYS = ("free", "fixed", "fallback", "initial", "prior", "uncertainty", "uncertainty_distribution")
UNCERTAINTY_DISTRIBUTIONS = DISTRIBUTIONS
"""A model constant's ``uncertainty_distribution``: "normal" about the fixed number (the
default), or "above" it: the true value lies above the fixed number, uniform over
[fixed, fixed + sqrt(12) u] (mean shift sqrt(3) u; GUM 4.3.7's rectangular distribution with
standard uncertainty u), as the budget draws the data sources of that distribution
(:func:`~bayes_roadload.analysis.budget.type_b_draws`)."""
_AIR_PARAMETERS = tuple(
    sorted({k for air in AIR_MODELS.values() for k in air.defaults})
)


class ModelSpecError(ValueError):
    """A model file was refused; the message names the file and the key at fault."""


# ----------------------------------------------------------------------------- priors

_PRIOR_KEYS = {
    # dist: (required keys, optional keys)
    "normal": (("loc", "scale"), ("low", "high")),
    "half_normal": (("scale",), ()),
    "lognormal": (("loc", "scale"), ()),
    "uniform": (("low", "high"), ()),
}
PRIOR_DISTRIBUTIONS = tuple(_PRIOR_KEYS)
"""Distribution names a prior may use."""


FELT_AIR_CACHE_SIZE = 16
"""How many campaigns' felt-air readings :func:`_cached_felt_air` keeps (least recently used
dropped first)."""

_FELT_AIR: OrderedDict[bytes, tuple[np.ndarray, np.ndarray]] = OrderedDict()


def _cached_felt_air(batch, airspeed_factor: float, yaw_factor: float, length_m: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~bayes_roadload.physics.admittance.felt_air_readings` of a batch's readings,
    remembered by content: a fit reads its campaign through :meth:`ModelSpec.to_batch` many times
    (least-squares start, problem, posterior predictive, Type B shifts), and the filter is the
    same each time.  The key is a digest of the time, speed, airspeed and yaw arrays with the
    factors and the length, so a changed campaign, factor or length is filtered anew.  Returned
    arrays are read-only copies shared between callers."""
    digest = hashlib.blake2b(digest_size=20)
    for x in (batch.time_s, batch.speed_mps, batch.airspeed_mps, batch.yaw_rad):
        a = np.ascontiguousarray(x, dtype=float)
        digest.update(repr(a.shape).encode())
        digest.update(a.tobytes())
    digest.update(np.asarray([airspeed_factor, yaw_factor, length_m], float).tobytes())
    key = digest.digest()
    if key in _FELT_AIR:
        _FELT_AIR.move_to_end(key)
        return _FELT_AIR[key]
    air, yaw = felt_air_readings(batch.time_s, batch.speed_mps, batch.airspeed_mps, batch.yaw_rad,
                                 airspeed_factor, yaw_factor, length_m)
    air, yaw = np.array(air, float), np.array(yaw, float)
    air.flags.writeable = False
    yaw.flags.writeable = False
    _FELT_AIR[key] = (air, yaw)
    while len(_FELT_AIR) > FELT_AIR_CACHE_SIZE:
        _FELT_AIR.popitem(last=False)
    return air, yaw


@dataclass(frozen=True)
class Prior:
    """A prior distribution of one parameter, in physical (SI) units.

    Parameters
    ----------
    dist : {"normal", "half_normal", "lognormal", "uniform"}
        ``normal(loc, scale)`` optionally truncated to ``[low, high]``; ``half_normal(scale)``
        on (0, inf); ``lognormal(loc, scale)`` of log(x); ``uniform(low, high)``.
    loc, scale, low, high : float or None
        The distribution's parameters (None when unused).
    softness : float or None
        Of a normal truncated from below only: the scale of its softplus coordinate as a
        fraction of ``scale`` (:func:`soft_lower_truncated_normal`); None is
        :data:`SOFTPLUS_FRACTION`.  The coordinate, not the distribution: the density is the
        same whatever the softness.
    """

    dist: str
    loc: float | None = None
    scale: float | None = None
    low: float | None = None
    high: float | None = None
    softness: float | None = None

    @property
    def center(self) -> float:
        """A central value (SI): the location clipped into the support, the half-normal's
        scale, the log-normal's median or the uniform's midpoint.  Used as the default start
        of optimisers."""
        if self.dist == "normal":
            x = self.loc
            if self.low is not None:
                x = max(x, self.low)
            if self.high is not None:
                x = min(x, self.high)
            return float(x)
        if self.dist == "half_normal":
            return float(self.scale)
        if self.dist == "lognormal":
            return float(math.exp(self.loc))
        return 0.5 * (self.low + self.high)

    @property
    def softplus_fraction(self) -> float:
        """The softplus coordinate's width as a fraction of the scale (a normal prior truncated
        from below only): ``softness``, else :data:`SOFTPLUS_FRACTION`."""
        return SOFTPLUS_FRACTION if self.softness is None else self.softness

    def to_numpyro(self):
        """The numpyro distribution (imported lazily: only the Bayesian layer needs it).  A
        normal truncated from below only is :func:`soft_lower_truncated_normal`: the same
        density, sampled through a scaled softplus instead of numpyro's exp."""
        import numpyro.distributions as dist

        if self.dist == "normal":
            if self.low is None and self.high is None:
                return dist.Normal(self.loc, self.scale)
            if self.high is None:
                return soft_lower_truncated_normal(self.loc, self.scale, self.low, self.softplus_fraction)
            return dist.TruncatedNormal(self.loc, self.scale, low=self.low, high=self.high)
        if self.dist == "half_normal":
            return dist.HalfNormal(self.scale)
        if self.dist == "lognormal":
            return dist.LogNormal(self.loc, self.scale)
        return dist.Uniform(self.low, self.high)


SOFTPLUS_FRACTION = 0.05
"""Softness of the bijection of a normal prior truncated from below, as a fraction of the
prior's scale (:func:`soft_lower_truncated_normal`), where the posterior keeps away from the
bound: a ridge along which the parameter trades linearly with another (K_D with A_D on one
pair in a cross wind) stays straight in the coordinate while it stays 3 s above the bound."""

SOFTPLUS_FRACTION_AT_BOUND = 0.3
"""The softness (fraction of the prior's scale) of a parameter whose posterior reaches its
bound (:func:`bayes_roadload.inference.nuts.soften_bounds`): the coordinate is log-like over a
strip of width ~s next to the bound, and a strip much narrower than the posterior is a wall for
the sampler.  For K_D's prior N(0.6, 1) cut at 0 alone (K_D in calm air), the largest curvature
of the potential in the coordinate over the central 99.9 % of its mass, times the coordinate's
variance (1 for a Gaussian), is about 45 at 0.05 and 1.8 at 0.3; leapfrog steps of about one
standard deviation stay stable below 4 (``tests/inference/test_spec.py`` computes it)."""

_SOFT_CLASSES: dict = {}


def soft_lower_truncated_normal(loc: float, scale: float, low: float, fraction: float = SOFTPLUS_FRACTION):
    """``TruncatedNormal(loc, scale, low=low)`` (the same density and support) whose
    unconstrained coordinate is ``x`` with ``y = low + s softplus(x)``,
    ``s = fraction * scale`` (x is dimensionless, about (y - low) / s), instead of
    numpyro's ``y = low + exp(x)``.

    The sampler and the MAP work in the unconstrained coordinate.  Through exp, a
    parameter whose posterior spans a good part of its value is curved against any parameter
    it trades with linearly: K_D against A_D on one pair (a cross-wind's yaw drag is nearly a
    constant force) made a banana whose curvature grew 400-fold within 4 Laplace standard
    deviations and gave dozens of divergences per fit.  The softplus is linear (slope within
    5 % of s) from 3 s above the bound, so such ridges stay straight, and log-like next to the
    bound, so a posterior piled against it is still sampled on a log scale.  Only the
    coordinates change, not the posterior."""
    import numpyro.distributions as dist
    from numpyro.distributions import constraints
    from numpyro.distributions.transforms import AffineTransform, ComposeTransform, SoftplusTransform, biject_to

    if not _SOFT_CLASSES:
        class _SoftGreaterThanEq(constraints._GreaterThanEq):
            """``y >= lower_bound``, unconstrained through ``lower_bound + s softplus(x)``."""

            def __init__(self, lower_bound, softness):
                super().__init__(lower_bound)
                self.softness = softness

            def tree_flatten(self):
                return (self.lower_bound, self.softness), (("lower_bound", "softness"), {})

        @biject_to.register(_SoftGreaterThanEq)
        def _soft(constraint):
            s = constraint.softness
            return ComposeTransform([SoftplusTransform(), AffineTransform(constraint.lower_bound, s)])

        class _SoftLowerTruncated(dist.LeftTruncatedDistribution):
            def __init__(self, base_dist, low=0.0, *, fraction=SOFTPLUS_FRACTION, validate_args=None):
                super().__init__(base_dist, low=low, validate_args=validate_args)
                self._support = _SoftGreaterThanEq(self.low, fraction * self.base_dist.scale)

        _SOFT_CLASSES["dist"] = _SoftLowerTruncated
    return _SOFT_CLASSES["dist"](dist.Normal(loc, scale), low=low, fraction=float(fraction))


def parse_prior(table: Any, where: str) -> Prior:
    """Validate a ``prior = {dist = ..., ...}`` table; ``where`` names the file and key."""
    if not isinstance(table, Mapping):
        raise ModelSpecError(f"{where}: a prior must be a table like "
                             "{{ dist = \"normal\", loc = 0.01, scale = 0.01 }}")
    name = table.get("dist")
    if name not in _PRIOR_KEYS:
        raise ModelSpecError(f"{where}.dist: unknown distribution {name!r}; known: "
                             f"{', '.join(PRIOR_DISTRIBUTIONS)}")
    required, optional = _PRIOR_KEYS[name]
    values: dict[str, float] = {}
    for k, v in table.items():
        if k == "dist":
            continue
        if k not in required + optional:
            raise ModelSpecError(f"{where}.{k}: not a parameter of a {name} prior "
                                 f"(it takes {', '.join(required + optional)})")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ModelSpecError(f"{where}.{k}: {v!r} is not a finite number")
        values[k] = float(v)
    for k in required:
        if k not in values:
            raise ModelSpecError(f"{where}.{k}: required by a {name} prior")
    if "scale" in values and values["scale"] <= 0:
        raise ModelSpecError(f"{where}.scale: must be positive, not {values['scale']:g}")
    low, high = values.get("low"), values.get("high")
    if low is not None and high is not None and not low < high:
        raise ModelSpecError(f"{where}: low ({low:g}) must be below high ({high:g})")
    return Prior(name, values.get("loc"), values.get("scale"), low, high)


# ----------------------------------------------------------------------------- the spec

@dataclass(frozen=True)
class ModelSpec:
    """A model variant read from ``models/*.toml``.

    Attributes
    ----------
    name, description : str
    terms : registered drag-term names (without the lift and driveline terms, which
        ``lift`` and ``driveline`` control).
    driveline : {"auto", "none", "measured", "polynomial"}
    lift : {"tunnel", "none"}
    air : {"auto", "measured", "still", "wind"}
    admittance : {"none", "auto", "first_order"}
    free : the parameters estimated, in file order.
    fixed : parameter -> value (SI) or ``"tunnel"`` (taken from the campaign's ``[tunnel]``).
    priors : free parameter -> :class:`Prior` (SI units); free parameters without a prior are
        absent.
    initial : free parameter -> starting value for optimisers (SI): the file's ``initial``,
        else the prior's :attr:`Prior.center`; absent when neither is given (the model
        default is used then).
    fallback : parameter -> value used when ``fixed = "tunnel"`` and the campaign's tunnel
        table lacks it.
    uncertainty : fixed parameter -> its standard uncertainty (SI, >= 0; 0 switches it off):
        a Type B source of the budget (module docstring); only for a fixed number.
    uncertainty_distribution : fixed parameter with an ``uncertainty`` -> "above" when its true
        value lies above the fixed number (:data:`UNCERTAINTY_DISTRIBUTIONS`); absent: normal.
    source : the file the spec was read from (None when built in code).
    """

    name: str
    description: str
    terms: tuple[str, ...]
    driveline: str = "auto"
    lift: str = "none"
    air: str = "auto"
    admittance: str = "none"
    free: tuple[str, ...] = ()
    fixed: dict[str, float | str] = field(default_factory=dict)
    priors: dict[str, Prior] = field(default_factory=dict)
    initial: dict[str, float] = field(default_factory=dict)
    fallback: dict[str, float] = field(default_factory=dict)
    uncertainty: dict[str, float] = field(default_factory=dict)
    uncertainty_distribution: dict[str, str] = field(default_factory=dict)
    source: str | None = None

    def __post_init__(self):
        _validate(self, self.source or f"model {self.name!r}")

    # -- resolution against a campaign ------------------------------------------------
    def resolve_driveline(self, campaign) -> str:
        """The driveline option after resolving ``"auto"`` against ``campaign``."""
        if self.driveline == "auto":
            return "measured" if campaign.has_driveline else "none"
        if self.driveline == "measured" and not campaign.has_driveline:
            raise ModelSpecError(f"{self._where}: [model] driveline = \"measured\" but the campaign "
                                 "does not log driveline_force_n (use \"auto\" or \"polynomial\")")
        return self.driveline

    def resolve_air(self, campaign) -> str:
        """The air model after resolving ``"auto"`` against ``campaign``."""
        if self.air == "auto":
            return "measured" if campaign.has_anemometer else "still"
        if self.air == "measured" and not campaign.has_anemometer:
            raise ModelSpecError(f"{self._where}: [model] air = \"measured\" but the campaign logs no "
                                 "airspeed_mps / yaw_rad")
        return self.air

    def resolve_admittance(self, campaign) -> float:
        """The vehicle length (m) of the admittance filter after resolving ``admittance``
        against ``campaign``; 0.0 when the anemometer is read as the air the body feels."""
        if self.admittance == "none":
            return 0.0
        measured = self.resolve_air(campaign) == "measured"
        length = campaign.vehicle.length_m
        if self.admittance == "first_order" and (not measured or length is None):
            raise ModelSpecError(f"{self._where}: [model] admittance = \"first_order\" needs the measured "
                                 "relative air and the vehicle's [vehicle] length_m (use \"auto\")")
        return float(length) if measured and length is not None else 0.0

    def to_batch(self, campaign):
        """The campaign's runs as this model reads them: :meth:`Campaign.to_batch`, with the
        anemometer readings replaced by those of the air the body feels when the admittance
        resolves on (:func:`~bayes_roadload.physics.admittance.felt_air_readings`, with the
        campaign's calibration factors)."""
        batch, run_ids = campaign.to_batch()
        length = self.resolve_admittance(campaign)
        if length > 0.0:
            anem = campaign.anemometer
            air, yaw = _cached_felt_air(batch, float(anem.airspeed_factor), float(anem.yaw_factor), length)
            batch = batch._replace(airspeed_mps=air, yaw_rad=yaw)
        return batch, run_ids

    def build(self, campaign) -> tuple[DragModel, dict[str, float], tuple[str, ...]]:
        """Resolve the spec against a campaign.

        Parameters
        ----------
        campaign : :class:`~bayes_roadload.data.Campaign`
            Supplies the logged channels (driveline, anemometer), the anemometer calibration
            factors, the optional ``[tunnel]`` table and whether the track is surveyed (then
            the ``surveyed_gradient`` term is added).

        Returns
        -------
        model : DragModel
        fixed_values : dict
            Every model parameter that is not free, with its value (SI): the spec's fixed
            values (``"tunnel"`` resolved), C_L0 / K_L from the tunnel for lift, the anemometer
            factors for measured air, and the model defaults for the rest.
        free : tuple of str
            The free parameters, in file order.
        """
        tunnel = dict(campaign.tunnel or {})
        names = list(self.terms)
        options: dict[str, dict] = {}
        lift_values: dict[str, float] = {}
        cl0_given = "CL0" in self.free or isinstance(self.fixed.get("CL0"), float)
        if self.lift == "tunnel" and ("CL0" in tunnel or cl0_given):
            names.insert(names.index("tyre_rolling") + 1 if "tyre_rolling" in names else 0,
                         "lift_unloading")
            if "CL0" in tunnel:
                lift_values = {"CL0": float(tunnel["CL0"]), "KL": float(tunnel.get("KL", 0.0))}
        driveline = self.resolve_driveline(campaign)
        if driveline != "none":
            names.append(f"driveline_{driveline}")
        if "aero_drag_table" in names:
            table = tunnel if "yaw_deg" in tunnel and "cd" in tunnel else thesis.THESIS_TUNNEL_TABLE
            options["aero_drag_table"] = {"yaw_deg": tuple(float(x) for x in table["yaw_deg"]),
                                          "cd": tuple(float(x) for x in table["cd"])}
        air = self.resolve_air(campaign)
        cup_lag = float(campaign.anemometer.distance_constant_m) if air == "measured" else 0.0
        if cup_lag > 0.0 and "anemometer_lag" not in names:
            names.append("anemometer_lag")  # the campaign states its cup's lag: undo it (eq. 2.26, thesis 4.7)
        if campaign.has_track_survey and "surveyed_gradient" not in names:
            names.append("surveyed_gradient")  # the campaign surveys its track: the grade force (eq. 2.1)
        model = model_from_names(names, air=air, **options)

        used = set(model.parameter_names)
        for p in self.free:
            if p not in used:
                raise ModelSpecError(f"{self._where}: [parameters.{p}] is free but not used by the "
                                     f"resolved model (terms {', '.join(model.term_names)})")
        values = dict(model.defaults)
        values.update(lift_values)
        if air == "measured":
            values["airspeed_factor"] = float(campaign.anemometer.airspeed_factor)
            values["yaw_factor"] = float(campaign.anemometer.yaw_factor)
        if cup_lag > 0.0 and "cup_lag_m" not in self.free:
            values["cup_lag_m"] = cup_lag
        for p, v in self.fixed.items():
            if p not in used:
                continue  # e.g. CL0 when the campaign has no tunnel lift: nothing to fix
            if v == TUNNEL:
                if p in tunnel:
                    v = tunnel[p]
                elif p in self.fallback:
                    v = self.fallback[p]
                else:
                    raise ModelSpecError(f"{self._where}: [parameters.{p}] fixed = \"tunnel\" but the "
                                         f"campaign's [tunnel] has no {p} and no fallback is given")
            values[p] = float(v)
        fixed_values = {k: v for k, v in values.items() if k not in self.free}
        return model, fixed_values, self.free

    @property
    def _where(self) -> str:
        return self.source or f"model {self.name!r}"


def _used_parameters(spec: ModelSpec) -> set[str]:
    """Parameters the spec's model can use, whatever the campaign."""
    used: set[str] = set(_AIR_PARAMETERS)
    for t in spec.terms:
        used |= set(TERMS[t].defaults)
    if spec.lift == "tunnel":
        used |= set(TERMS["lift_unloading"].defaults) | {"AD", "BD"}
    if spec.driveline == "polynomial":
        used |= set(TERMS["driveline_polynomial"].defaults)
    return used


def _validate(spec: ModelSpec, where: str) -> None:
    if not spec.terms:
        raise ModelSpecError(f"{where}: [model] terms is empty")
    for t in spec.terms:
        if t in _SWITCHED_TERMS:
            raise ModelSpecError(f"{where}: [model] terms: {t!r} is controlled by "
                                 f"[model] {_SWITCHED_TERMS[t]}, do not list it")
        if t in _DATA_TERMS:
            raise ModelSpecError(f"{where}: [model] terms: {t!r} is added by {_DATA_TERMS[t]}, "
                                 "do not list it")
        if t not in TERMS:
            raise ModelSpecError(f"{where}: [model] terms: unknown drag term {t!r}; "
                                 f"known: {', '.join(sorted(TERMS))}")
    if len(set(spec.terms)) != len(spec.terms):
        raise ModelSpecError(f"{where}: [model] terms: a term is listed twice")
    for key, value, options in (("driveline", spec.driveline, DRIVELINE_OPTIONS),
                                ("lift", spec.lift, LIFT_OPTIONS), ("air", spec.air, AIR_OPTIONS),
                                ("admittance", spec.admittance, ADMITTANCE_OPTIONS)):
        if value not in options:
            raise ModelSpecError(f"{where}: [model] {key} = {value!r}; choose one of "
                                 f"{', '.join(options)}")
    used = _used_parameters(spec)
    if len(set(spec.free)) != len(spec.free):
        raise ModelSpecError(f"{where}: a parameter is listed as free twice")
    for p in set(spec.free) | set(spec.fixed) | set(spec.priors) | set(spec.initial):
        if p not in config.PARAMETER_UNITS:
            raise ModelSpecError(f"{where}: [parameters.{p}]: unknown parameter; known: "
                                 f"{', '.join(config.PARAMETER_UNITS)}")
        if p not in used:
            raise ModelSpecError(f"{where}: [parameters.{p}]: not used by the model's terms "
                                 f"({', '.join(spec.terms)}, lift={spec.lift}, "
                                 f"driveline={spec.driveline})")
    for p in spec.free:
        if p in spec.fixed:
            raise ModelSpecError(f"{where}: [parameters.{p}]: both free and fixed")
    for p in set(spec.priors) | set(spec.initial):
        if p not in spec.free:
            raise ModelSpecError(f"{where}: [parameters.{p}]: a prior or initial value needs "
                                 "free = true")
    for p, v in spec.fixed.items():
        if v != TUNNEL and (isinstance(v, bool) or not isinstance(v, (int, float))
                            or not math.isfinite(v)):
            raise ModelSpecError(f"{where}: [parameters.{p}].fixed: {v!r} is neither a finite "
                                 "number nor \"tunnel\"")
    for p in spec.fallback:
        if spec.fixed.get(p) != TUNNEL:
            raise ModelSpecError(f"{where}: [parameters.{p}].fallback: only meaningful with "
                                 "fixed = \"tunnel\"")
    for p, u in spec.uncertainty.items():
        if p not in spec.fixed or spec.fixed[p] == TUNNEL:
            raise ModelSpecError(f"{where}: [parameters.{p}].uncertainty: only for a parameter "
                                 "fixed at a number (free ones have a prior)")
        if isinstance(u, bool) or not isinstance(u, (int, float)) or not math.isfinite(u) or u < 0.0:
            raise ModelSpecError(f"{where}: [parameters.{p}].uncertainty: {u!r} is not a finite "
                                 "standard uncertainty >= 0")
    for p, d in spec.uncertainty_distribution.items():
        if p not in spec.uncertainty:
            raise ModelSpecError(f"{where}: [parameters.{p}].uncertainty_distribution: only beside an "
                                 "uncertainty")
        if d not in UNCERTAINTY_DISTRIBUTIONS:
            raise ModelSpecError(f"{where}: [parameters.{p}].uncertainty_distribution: {d!r}; one of "
                                 f"{', '.join(UNCERTAINTY_DISTRIBUTIONS)}")


# ----------------------------------------------------------------------------- loading

def _number(v: Any, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ModelSpecError(f"{where}: {v!r} is not a finite number")
    return float(v)


def parse_model_spec(doc: Mapping[str, Any], where: str, default_name: str = "model") -> ModelSpec:
    """Build a :class:`ModelSpec` from a parsed TOML document; ``where`` names the source."""
    for k in doc:
        if k not in ("model", "parameters"):
            raise ModelSpecError(f"{where}: [{k}]: unknown table; a model file has [model] and "
                                 "[parameters.NAME]")
    if "model" not in doc:
        raise ModelSpecError(f"{where}: [model]: table is missing")
    m = doc["model"]
    for k in m:
        if k not in _MODEL_KEYS:
            raise ModelSpecError(f"{where}: [model] {k}: unknown key; known: {', '.join(_MODEL_KEYS)}")
    if "terms" not in m:
        raise ModelSpecError(f"{where}: [model] terms: required key is missing")
    terms = m["terms"]
    if not isinstance(terms, list) or not all(isinstance(t, str) for t in terms):
        raise ModelSpecError(f"{where}: [model] terms: must be a list of term names")
    free: list[str] = []
    fixed: dict[str, float | str] = {}
    priors: dict[str, Prior] = {}
    initial: dict[str, float] = {}
    fallback: dict[str, float] = {}
    uncertainty: dict[str, float] = {}
    distribution: dict[str, str] = {}
    params = doc.get("parameters", {})
    if not isinstance(params, Mapping):
        raise ModelSpecError(f"{where}: [parameters] must be a table of [parameters.NAME] tables")
    for p, table in params.items():
        key = f"[parameters.{p}]"
        if not isinstance(table, Mapping):
            raise ModelSpecError(f"{where}: {key}: must be a table (free = true, fixed = ...)")
        for k in table:
            if k not in _PARAMETER_KEYS:
                raise ModelSpecError(f"{where}: {key} {k}: unknown key; known: "
                                     f"{', '.join(_PARAMETER_KEYS)}")
        is_free = table.get("free", False)
        if not isinstance(is_free, bool):
            raise ModelSpecError(f"{where}: {key} free: must be true or false")
        if is_free and "fixed" in table:
            raise ModelSpecError(f"{where}: {key}: both free and fixed")
        if not is_free and "fixed" not in table:
            raise ModelSpecError(f"{where}: {key}: say free = true or fixed = <value | \"tunnel\">")
        if is_free:
            free.append(p)
        else:
            v = table["fixed"]
            if v != TUNNEL and (isinstance(v, bool) or not isinstance(v, (int, float))
                                or not math.isfinite(v)):
                raise ModelSpecError(f"{where}: {key} fixed: {v!r} is neither a finite number "
                                     "nor \"tunnel\"")
            fixed[p] = v if v == TUNNEL else float(v)
        if "fallback" in table:
            fallback[p] = _number(table["fallback"], f"{where}: {key} fallback")
        if "uncertainty" in table:
            uncertainty[p] = _number(table["uncertainty"], f"{where}: {key} uncertainty")
        if "uncertainty_distribution" in table:
            distribution[p] = table["uncertainty_distribution"]
        if "initial" in table:
            initial[p] = _number(table["initial"], f"{where}: {key} initial")
        if "prior" in table:
            priors[p] = parse_prior(table["prior"], f"{where}: {key} prior")
    for p, prior in priors.items():
        initial.setdefault(p, prior.center)
    name = m.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise ModelSpecError(f"{where}: [model] name: must be a non-empty string")
    return ModelSpec(
        name=name,
        description=str(m.get("description", "")),
        terms=tuple(terms),
        driveline=m.get("driveline", "auto"),
        lift=m.get("lift", "none"),
        air=m.get("air", "auto"),
        admittance=m.get("admittance", "none"),
        free=tuple(free),
        fixed=fixed,
        priors=priors,
        initial=initial,
        fallback=fallback,
        uncertainty=uncertainty,
        uncertainty_distribution=distribution,
        source=where,
    )


def load_model_spec(name_or_path: str | os.PathLike) -> ModelSpec:
    """Load a model variant.

    Parameters
    ----------
    name_or_path : str or path
        A bare name (``"four_term"``) is looked up as ``<name>.toml`` in the model library
        (:data:`MODELS_DIR`); anything with a directory part or a ``.toml`` suffix is a path.

    Raises
    ------
    ModelSpecError
        When the file is missing, not TOML, or refused; the message names the file and key.
    """
    s = str(name_or_path)
    looks_like_path = isinstance(name_or_path, os.PathLike) or s.endswith(".toml") or os.sep in s or "/" in s
    path = Path(s) if looks_like_path else MODELS_DIR / f"{s}.toml"
    if not path.is_file():
        known = ", ".join(available_models()) or "none"
        raise ModelSpecError(f"{path}: model file not found (models available: {known})")
    try:
        doc = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as e:
        raise ModelSpecError(f"{path}: not valid TOML ({e})") from e
    return parse_model_spec(doc, str(path), default_name=path.stem)


def with_undriven_wheels(spec: ModelSpec, au_n: float, bu_nspm: float) -> ModelSpec:
    """``spec`` with the undriven-wheel loss A_u + B_u v (eq. 2.16) added as a known term, fixed
    at values measured apart (a spin-down fit, thesis section 5.6), so the tyre coefficients no
    longer absorb it (the thesis' practice, section 5.6: "measured ... and included into the
    model").  Refused when the spec already has the term."""
    import dataclasses

    if "undriven_wheels" in spec.terms:
        raise ModelSpecError(f"{spec._where}: the model already has the undriven_wheels term")
    if any(not math.isfinite(x) for x in (au_n, bu_nspm)):
        raise ModelSpecError("undriven-wheel values must be finite numbers")
    terms = list(spec.terms)
    terms.insert(terms.index("aero_drag") if "aero_drag" in terms else len(terms), "undriven_wheels")
    return dataclasses.replace(spec, name=f"{spec.name}+undriven", terms=tuple(terms),
                               description=f"{spec.description}; undriven wheels fixed at Au {au_n:g} N, "
                                           f"Bu {bu_nspm:g} N s/m",
                               fixed=dict(spec.fixed, Au=float(au_n), Bu=float(bu_nspm)))


def without_free(spec: ModelSpec, names, fixed: Mapping[str, float] | None = None,
                 name: str | None = None) -> ModelSpec:
    """``spec`` with the free parameters ``names`` no longer estimated: dropped from ``free``,
    ``priors`` and ``initial``; ``fixed`` gives the values they then hold (absent: the model's
    default, or nothing where the air model no longer reads them).  Refused for a name that is
    not free."""
    import dataclasses

    drop = tuple(names)
    missing = [p for p in drop if p not in spec.free]
    if missing:
        raise ModelSpecError(f"{spec._where}: {', '.join(missing)} not free")
    return dataclasses.replace(spec, name=name or spec.name, free=tuple(p for p in spec.free if p not in drop),
                               fixed={**spec.fixed, **{k: float(v) for k, v in (fixed or {}).items()}},
                               priors={k: v for k, v in spec.priors.items() if k not in drop},
                               initial={k: v for k, v in spec.initial.items() if k not in drop})


def available_models() -> list[str]:
    """Names of the model files in the model library (:data:`MODELS_DIR`), sorted."""
    if not MODELS_DIR.is_dir():
        return []
    return sorted(p.stem for p in MODELS_DIR.glob("*.toml"))
