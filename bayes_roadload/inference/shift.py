"""The sensitivity of a posterior's mode to a change of the campaign, for any problem.

A declared value or an instrument of the test (a Type B source, :mod:`bayes_roadload.data.
uncertainty`) shifted by ``+-h`` gives two shifted campaigns and, through the kind's problem
builder, two shifted problems.  Their MAPs (:func:`~bayes_roadload.inference.nuts.find_map`)
give every reported quantity ``x`` -- the sampled coefficients and the kind's derived figures,
which may read the shifted campaign directly (a mass enters the road load itself) -- and

    dx/ds = (x(MAP of the +h campaign) - x(MAP of the -h campaign)) / (2 h),

the central difference of the measurement result that GUM 5.1.3 takes as the sensitivity
coefficient.  Compiling is most of a small MAP's time (a distance-time gradient: 8.8 s to
compile, 0.9 ms to evaluate, ``benchmarks/type_b_cost.py``), and the shifted campaigns differ
from the fitted one only in their data: :class:`SharedPotential` compiles the potential once
with the data as arguments and starts each shifted MAP at the fit's (1.7-3.2x faster than a
compilation per campaign, the same sensitivities: ``docs/calibration.md``).  One Newton step
from the unshifted mode instead of each refit was off by up to 30 % on a spin-down's wheel
inertia, so the MAPs are refitted.
The speed-trace kind has the least-squares analogue
(:func:`~bayes_roadload.inference.lsq.linear_sensitivities`)."""

from __future__ import annotations

import copy
import dataclasses
import logging
import math
from typing import Any, Callable, Mapping

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from numpyro.infer.util import constrain_fn, potential_energy

from ..physics.model import DragModel
from .nuts import MapResult, find_map, newton_map, unconstrained_posterior
from .problem import Problem
from .spec import ModelSpec

log = logging.getLogger(__name__)

Shifts = Mapping[str, tuple[Any, Any, float]]
"""Source key -> (campaign shifted by +h, campaign shifted by -h, h)."""


def _scalars(values: Mapping[str, Any]) -> dict[str, float]:
    out = {}
    for k, v in values.items():
        a = np.asarray(v, float)
        if a.size == 1 and math.isfinite(float(a.reshape(-1)[0])):
            out[k] = float(a.reshape(-1)[0])
    return out


def quantities_at(problem: Problem, constrained: Mapping[str, Any]) -> dict[str, float]:
    """Every scalar reported quantity of ``problem`` at one point: the constrained and
    deterministic sites (``constrained``), the sites the problem adds after sampling
    (:meth:`~.problem.Problem.postprocess`) and its derived figures
    (:meth:`~.problem.Problem.derived`), as one draw of one chain."""
    samples = {k: np.asarray(v)[None, None] for k, v in constrained.items()}
    samples.update(problem.postprocess(samples, 0))
    samples.update(problem.derived(samples))
    return _scalars({k: np.asarray(v)[0, 0] for k, v in samples.items()})


def mode_of(problem: Problem) -> MapResult:
    """The MAP of ``problem`` from its starting values."""
    return find_map(problem, {}, posterior=unconstrained_posterior(problem, problem.initial))


# ----------------------------------------------------------------------------- one compilation

_STATIC = object()


def _data_leaves(obj, leaves: list) -> Any:
    """The structure of a problem with its data taken out: every array and float of its own
    fields, of nested data classes and named tuples (the runs, bands, conditions), and of plain
    tuples and dicts that hold any (a driveline curve, the fixed values a campaign declares, the
    apparent coefficients' line) is appended to ``leaves`` and marked; the model variant, priors
    and the rest stay in the structure (compared by value).  ``initial`` (the MAP's start) is
    not part of the structure."""
    if _holds_data(obj):
        leaves.append(obj)
        return _STATIC
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type) and not isinstance(obj, (ModelSpec, DragModel)):
        return (type(obj),) + tuple((f.name, _data_leaves(getattr(obj, f.name), leaves))
                                    for f in dataclasses.fields(obj) if f.name != "initial")
    if isinstance(obj, tuple) and hasattr(obj, "_fields"):   # a NamedTuple of arrays (bands, marker runs, conditions)
        return (type(obj),) + tuple((name, _data_leaves(getattr(obj, name), leaves)) for name in obj._fields)
    if type(obj) is tuple and any(_holds_data(x) for x in obj):   # e.g. a driveline curve (c2, c1, c0)
        return (tuple,) + tuple((i, _data_leaves(x, leaves)) for i, x in enumerate(obj))
    if type(obj) is dict and any(_holds_data(x) for x in obj.values()):   # e.g. fixed values from the campaign
        return (dict,) + tuple((k, _data_leaves(v, leaves)) for k, v in obj.items())
    return obj


def _holds_data(x) -> bool:
    """An array or a float: a data leaf of :func:`_data_leaves`."""
    return isinstance(x, (jax.Array, np.ndarray)) or (isinstance(x, float) and not isinstance(x, bool))


def _with_leaves(template, structure, leaves: list):
    """``template`` with the leaves :func:`_data_leaves` took out replaced, in order, by
    ``leaves`` (consumed): a shallow copy per data class, no constructor run (tracers pass)."""
    if structure is _STATIC:
        return leaves.pop(0)
    if isinstance(structure, tuple) and structure and isinstance(structure[0], type):
        if structure[0] is tuple:
            return tuple(_with_leaves(template[i], sub, leaves) for i, sub in structure[1:])
        if structure[0] is dict:
            return {k: _with_leaves(template[k], sub, leaves) for k, sub in structure[1:]}
        if issubclass(structure[0], tuple):   # NamedTuple
            return template._replace(**{name: _with_leaves(getattr(template, name), sub, leaves)
                                        for name, sub in structure[1:]})
        if dataclasses.is_dataclass(structure[0]):
            out = copy.copy(template)
            for name, sub in structure[1:]:
                object.__setattr__(out, name, _with_leaves(getattr(template, name), sub, leaves))
            return out
    return template


def _same_structure(a, b) -> bool:
    try:
        return bool(a == b)
    except Exception:  # noqa: BLE001 - arrays compared element-wise: not the same static structure
        return False


class SharedPotential:
    """numpyro's potential of ``template`` and its gradient, compiled once with the problem's
    data as arguments (:func:`_data_leaves`), so that every problem of the same structure --
    the same model variant, priors, sites and array shapes, other data -- reuses the
    compilation: the shifted campaigns of a Type B budget.  ``mode(problem)`` is the MAP of
    such a problem (:func:`~bayes_roadload.inference.nuts.newton_map` from ``start``, the
    template's scaled MAP), or None when ``problem`` has another structure."""

    def __init__(self, template: Problem, start: MapResult):
        self.template = template
        self.leaves: list = []
        self.structure = _data_leaves(template, self.leaves)
        post = unconstrained_posterior(template, template.initial)
        self.unravel, self.scale, self.run_index = post.unravel, post.scale, post.run_index
        self.y0 = np.asarray(ravel_pytree(start.z)[0]) / self.scale
        self.shapes = [np.shape(x) for x in self.leaves]
        model = template.numpyro_model

        def objective(leaves, y):
            problem = _with_leaves(self.template, self.structure, list(leaves))
            return potential_energy(model, (problem,), {}, self.unravel(y * self.scale))

        self._fg = jax.jit(jax.value_and_grad(objective, argnums=1))

    def data_of(self, problem: Problem) -> list | None:
        leaves: list = []
        structure = _data_leaves(problem, leaves)
        if not _same_structure(structure, self.structure) or [np.shape(x) for x in leaves] != self.shapes:
            return None
        return [jnp.asarray(x) for x in leaves]

    def gradient_at_start(self, problem: Problem) -> np.ndarray | None:
        """The gradient of ``problem``'s potential at the template's MAP, in the scaled
        coordinates (None: another structure): what one Newton step from that MAP needs."""
        data = self.data_of(problem)
        if data is None:
            return None
        return np.asarray(self._fg(data, jnp.asarray(self.y0))[1])

    def mode(self, problem: Problem) -> dict[str, Any] | None:
        """The constrained values at the MAP of ``problem`` with the shared compilation
        (None: another structure, or the optimiser did not converge)."""
        data = self.data_of(problem)
        if data is None:
            return None
        res = newton_map(lambda y: self._fg(data, y), self.y0, self.run_index, self.scale)
        if not res["success"]:
            return None
        z = self.unravel(jnp.asarray(res["y"] * self.scale))
        return constrain_fn(problem.numpyro_model, (problem,), {}, z, return_deterministic=True)


def _shared_mode(shared: SharedPotential | None, problem: Problem) -> dict[str, Any] | None:
    """``shared.mode(problem)``, or None (the caller fits the problem on its own) when there is
    no shared compilation or it does not apply."""
    if shared is None:
        return None
    try:
        return shared.mode(problem)
    except Exception as e:  # noqa: BLE001 - e.g. a value the model needs concrete: its own compilation instead
        log.debug("Type B: shared compilation not usable (%s: %s)", type(e).__name__, e)
        return None


def map_sensitivities(build: Callable[[Any], Problem], shifts: Shifts,
                      base: tuple[Problem, MapResult] | None = None) -> dict[str, dict[str, float]]:
    """Source -> quantity -> dx/ds by central differences of the MAPs of the shifted campaigns
    (module docstring); ``build`` makes the problem of a campaign.  With ``base`` (the fitted
    problem and its MAP) the shifted problems of its structure share one compilation
    (:class:`SharedPotential`) and start at its MAP; the others, and any whose shared MAP does
    not converge, are fitted on their own (:func:`mode_of`).  A source whose shifted problems
    differ in their quantities keeps those they share; one whose shifted MAP fails or does not
    converge is left out (logged), so that a fit never stops here."""
    shared = None
    if base is not None:
        try:
            shared = SharedPotential(*base)
        except Exception as e:  # noqa: BLE001 - the problem cannot take its data as arguments
            log.debug("Type B: no shared compilation (%s: %s); each shifted campaign compiles its own",
                      type(e).__name__, e)
    out: dict[str, dict[str, float]] = {}
    for key, (plus, minus, h) in shifts.items():
        values = []
        for c in (plus, minus):
            try:
                shifted = build(c)
                constrained = _shared_mode(shared, shifted)
                if constrained is None:
                    mode = mode_of(shifted)
                    if not mode.success:
                        log.warning("Type B source %s left out: the MAP of its shifted campaign did not converge "
                                    "(%s)", key, mode.message)
                        break
                    constrained = mode.constrained
            except Exception as e:  # noqa: BLE001 - a source that cannot be refitted is left out, not fatal
                log.warning("Type B source %s left out: the MAP of its shifted campaign failed (%s: %s)",
                            key, type(e).__name__, e)
                break
            values.append(quantities_at(shifted, constrained))
        if len(values) == 2:
            out[key] = {q: (values[0][q] - values[1][q]) / (2.0 * h) for q in values[0] if q in values[1]}
    return out
