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
from the fitted one only in their data: the fit's MAP compiles the potential with the data as
arguments (:func:`potential_program`), and :class:`SharedPotential` evaluates the shifted
campaigns with that compilation and starts each shifted MAP at the fit's (1.7-3.2x faster than a
compilation per campaign, the same sensitivities: ``docs/calibration.md``; no compilation of its
own when the MAP's program is at hand).  One Newton step
from the unshifted mode instead of each refit was off by up to 30 % on a spin-down's wheel
inertia, so those kinds refit the MAPs (:func:`map_sensitivities`).  A speed-trace fit takes
the Newton step (:func:`newton_sensitivities`) with the noise scales and run-effect spreads
held at the MAP, and keeps it only where the potential is quadratic over it
(:meth:`SharedPotential.newton_step`); elsewhere it refits.  Without a fit, the speed-trace
kind has the least-squares analogue (:func:`~bayes_roadload.inference.lsq.linear_sensitivities`)."""

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
from .nuts import MapResult, find_map, newton_map, site_layout, unconstrained_posterior
from .problem import Problem
from .spec import ModelSpec

log = logging.getLogger(__name__)

Shifts = Mapping[str, tuple[Any, Any, float]]
"""Source key -> (campaign shifted by +h, campaign shifted by -h, h); for a model constant,
:class:`FixedShift` in place of the two campaigns."""

NEWTON_STEP_AGREEMENT = 0.1
"""A Newton step of :meth:`SharedPotential.newton_step` is kept when the decrease of the
potential it achieves is within this fraction of the quadratic model's prediction.  The error of
the step is of the relative size of the potential's cubic term over it, and so is this
mismatch: 10 % keeps each Type B contribution to about the few per cent a budget is read to."""
NEWTON_STEP_FLOOR = 1e-8
"""Nats: a step whose predicted decrease is below this (a source that hardly moves the
posterior) is kept whatever the ratio, which rounding decides at that size."""


@dataclasses.dataclass(frozen=True)
class FixedShift:
    """A shift of a fixed model constant rather than of the campaign: the fitted problem with
    that constant moved (:meth:`~bayes_roadload.inference.problem.Problem.shift_constant`), used as
    it is where a shift's campaign would go through the kind's problem builder."""

    problem: Problem

    def subset(self, runs) -> "FixedShift":
        """Itself: the fitted problem holds the fitted runs already (a campaign shift is cut to
        them by :meth:`~bayes_roadload.data.Campaign.subset`)."""
        return self


def shifted_problem(shifted, build: Callable[[Any], Problem]) -> Problem:
    """The problem of one side of a Type B shift: a :class:`FixedShift`'s own, else the shifted
    campaign through the kind's problem builder ``build``."""
    return shifted.problem if isinstance(shifted, FixedShift) else build(shifted)


def campaign_shifts(shifts: Mapping[str, tuple]) -> dict[str, tuple]:
    """The shifts of the campaign in ``shifts`` (the least-squares refits take those; they have
    no model constants to shift), without the :class:`FixedShift` ones."""
    return {k: v for k, v in shifts.items() if not isinstance(v[0], FixedShift)}


def fixed_shifts(problem: Problem, uncertainty: Mapping[str, float]) -> tuple[dict, dict[str, str]]:
    """The Type B shifts of the model constants ``uncertainty`` (name -> standard uncertainty
    ``u``, a model file's ``[parameters.NAME] uncertainty``): ``name -> (FixedShift(+u),
    FixedShift(-u), u)`` for each constant ``problem`` fixes, and a note for each it does not
    (switched off by ``u = 0``, or not a constant of this problem)."""
    shifts: dict[str, tuple[FixedShift, FixedShift, float]] = {}
    notes: dict[str, str] = {}
    for name, u in uncertainty.items():
        if u <= 0.0:
            notes[name] = "switched off (uncertainty = 0 in the model file)"
            continue
        plus, minus = problem.shift_constant(name, u), problem.shift_constant(name, -u)
        if plus is None or minus is None:
            notes[name] = "not applicable (not a fixed constant of the fitted problem)"
            continue
        shifts[name] = (FixedShift(plus), FixedShift(minus), float(u))
    return shifts, notes


def _scalars(values: Mapping[str, Any]) -> dict[str, float]:
    out = {}
    for k, v in values.items():
        a = np.asarray(v, float)
        if a.size == 1 and math.isfinite(float(a.reshape(-1)[0])):
            out[k] = float(a.reshape(-1)[0])
    return out


def quantities_at(problem: Problem, constrained: Mapping[str, Any]) -> dict[str, float]:
    """Every scalar reported quantity of ``problem`` at one point: the constrained and
    deterministic sites (``constrained``) and its derived figures
    (:meth:`~.problem.Problem.derived`), as one draw of one chain.  The sites a problem adds
    after sampling (:meth:`~.problem.Problem.postprocess`: the run-level coefficients of a
    hierarchical fit) are per run, not reported quantities of the campaign, and are not
    computed."""
    samples = {k: np.asarray(v)[None, None] for k, v in constrained.items()}
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


class SharedData:
    """Functions of a problem compiled once for every problem of ``template``'s structure
    (:func:`_data_leaves`: the same model variant, priors, sites and array shapes, other
    data), the data passed as arguments."""

    def __init__(self, template: Problem):
        self.template = template
        self.leaves: list = []
        self.structure = _data_leaves(template, self.leaves)
        self.shapes = [np.shape(x) for x in self.leaves]

    def _leaves(self, problem: Problem) -> list | None:
        """``problem``'s data leaves as it holds them, or None when it has another structure."""
        leaves: list = []
        structure = _data_leaves(problem, leaves)
        if not _same_structure(structure, self.structure) or [np.shape(x) for x in leaves] != self.shapes:
            return None
        return leaves

    def data_of(self, problem: Problem) -> list | None:
        """``problem``'s data leaves, or None when it has another structure."""
        leaves = self._leaves(problem)
        return None if leaves is None else [jnp.asarray(x) for x in leaves]

    def with_data(self, leaves) -> Problem:
        """The template with the data ``leaves`` (arrays or tracers) in place of its own."""
        return _with_leaves(self.template, self.structure, list(leaves))

    def accepts(self, problem: Problem) -> bool:
        """Whether ``problem`` has this template's structure (:meth:`data_of` is not None)."""
        return self._leaves(problem) is not None

    def compile(self, fn: Callable[..., Any]) -> Callable[..., Any]:
        """``call(problem, *args)``: ``fn(problem, *args)`` compiled once with the problem's data
        as arguments; None for a problem of another structure.  ``fn`` is compiled once per
        process for each structure (:func:`_compiled`): a later template of the same structure
        (the next refit of a study, the next same-shaped campaign of a fleet) is traced and
        compiled again only when ``fn`` is another function object, so ``fn`` should be defined
        at module level."""
        jitted = _compiled(self, fn)

        def call(problem: Problem, *args):
            data = self.data_of(problem)
            return None if data is None else jitted(data, *args)
        return call


_RECENT_COMPILED: list[tuple[Callable[..., Any], SharedData, Callable[..., Any]]] = []
COMPILED_KEPT = 4
"""The programs :meth:`SharedData.compile` keeps per process, most recently used first."""


def _compiled(shared: SharedData, fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` jitted with the data of ``shared``'s structure as arguments: the program compiled
    for an earlier template of the same structure (:func:`_data_leaves`: the same model variant,
    priors, sites and shapes; the other fields, compared by value, equal) when one of the last
    :data:`COMPILED_KEPT` was, else a new one.  The earlier template's fields outside the data
    equal this one's, so its :meth:`SharedData.with_data` builds the same problem from the same
    leaves."""
    return _most_recent(_RECENT_COMPILED, COMPILED_KEPT,
                        lambda entry: entry[0] is fn and entry[1].accepts(shared.template),
                        lambda: (fn, shared, jax.jit(lambda leaves, *args: fn(shared.with_data(leaves), *args))))[2]


def _most_recent(kept: list, size: int, matches: Callable[[Any], bool], build: Callable[[], Any]) -> Any:
    """The first entry of ``kept`` (most recently used first) that ``matches``, moved to the
    front; else ``build()``'s, put in front, ``kept`` cut to ``size``."""
    for i, entry in enumerate(kept):
        if matches(entry):
            kept.insert(0, kept.pop(i))
            return entry
    entry = build()
    kept.insert(0, entry)
    del kept[size:]
    return entry


class PotentialProgram(SharedData):
    """numpyro's potential of ``template`` and its gradient, ``fg(leaves, y)``, and the
    constrained and deterministic values of an unconstrained point, ``constrained(leaves, x)``,
    compiled once with the data as arguments (:func:`_data_leaves`) in the O(1)-scaled
    unconstrained coordinates of :func:`~bayes_roadload.inference.nuts.site_layout` (``x = y
    scale``).  Every problem of the template's structure -- the same model variant, priors,
    sites and array shapes, other data -- reuses the compilation."""

    def __init__(self, template: Problem, z: dict[str, Any]):
        super().__init__(template)
        self.z_structure = _site_structure(z)
        self.unravel, self.scale, self.run_index = site_layout(template, z)
        model, unravel, scale = template.numpyro_model, self.unravel, self.scale

        def objective(leaves, y):
            return potential_energy(model, (self.with_data(leaves),), {}, unravel(y * scale))

        def constrained(leaves, x):
            return constrain_fn(model, (self.with_data(leaves),), {}, unravel(x), return_deterministic=True)

        self.fg_compiled = jax.jit(jax.value_and_grad(objective, argnums=1))
        self.constrained_compiled = jax.jit(constrained)

    def fg(self, leaves, y):
        """The potential and its gradient at the scaled point ``y`` (taken as a NumPy array:
        a JAX array of the same values is another entry of the compilation cache)."""
        return self.fg_compiled(leaves, np.asarray(y, float))

    def constrained(self, leaves, x):
        """The constrained and deterministic values at the unconstrained point ``x`` (likewise)."""
        return self.constrained_compiled(leaves, np.asarray(x, float))


def _site_structure(z: dict[str, Any]) -> tuple:
    """The sites of ``z`` and their shapes, in the order of their names (a MAP's values come in
    another order than the trace's)."""
    return tuple(sorted((k, np.shape(v)) for k, v in z.items()))


_RECENT_PROGRAMS: list[PotentialProgram] = []
PROGRAMS_KEPT = 4
"""The potential programs :func:`potential_program` keeps per process, most recently used
first: a fit's MAP compiles its problem's and the fit's Type B step reuses it, and so do the
next fits of the same structure in the process."""


def potential_program(problem: Problem, z: dict[str, Any]) -> PotentialProgram:
    """The :class:`PotentialProgram` for ``problem`` with the site layout of ``z``: one built
    earlier in this process, for ``problem`` itself or for a problem of the same structure
    (:func:`_data_leaves`: the same model variant, priors, sites and array shapes; only the data
    differ), when one of the last :data:`PROGRAMS_KEPT` was, else a new one.  Its site layout
    (:func:`~bayes_roadload.inference.nuts.site_layout`) is a function of that structure, and the
    data go in as arguments, so a study's refits and a fleet's same-shaped campaigns trace and
    compile the potential once per process."""
    structure = _site_structure(z)
    return _most_recent(_RECENT_PROGRAMS, PROGRAMS_KEPT,
                        lambda program: program.z_structure == structure
                        and (program.template is problem or program.accepts(problem)),
                        lambda: PotentialProgram(problem, z))


class SharedPotential:
    """The Type B step's use of the fitted problem's :class:`PotentialProgram` (the one its MAP
    compiled: :func:`potential_program`): the shifted campaigns of a budget differ from the
    fitted one only in their data, so every problem of the same structure reuses the
    compilation.  ``mode(problem)`` is the MAP of such a problem
    (:func:`~bayes_roadload.inference.nuts.newton_map` from ``start``, the template's scaled
    MAP), ``newton_step(problem)`` one Newton step towards it; both None when ``problem`` has
    another structure."""

    def __init__(self, template: Problem, start: MapResult):
        self.program, self.start = potential_program(template, start.z), start
        self._conditional: dict[tuple[str, ...], Any] = {}
        self.y0 = np.asarray(ravel_pytree(start.z)[0]) / self.program.scale

    def data_of(self, problem: Problem) -> list | None:
        """``problem``'s data leaves, or None when it has another structure."""
        return self.program.data_of(problem)

    def newton_step(self, problem: Problem, held: tuple[str, ...] = ()) -> dict[str, Any] | None:
        """The constrained values one Newton step from the template's MAP ``x*`` towards the
        MAP of ``problem``, the sites ``held`` kept at ``x*``: ``dx = -H_kk^-1 g_k`` on the
        other coordinates k, ``g`` the gradient of ``problem``'s potential ``U`` at ``x*`` and
        ``H`` the template's Hessian there (the inverse of its Laplace covariance;
        unconstrained coordinates).  By the implicit function theorem at the mode this is the
        shifted conditional MAP to first order in the shift, the posterior's own curvature --
        priors included -- deciding how far each coordinate moves.  Holding the sites that
        scale the likelihood (noise, run-effect spreads) keeps the step out of their funnels,
        where a hierarchical posterior of few runs is far from quadratic (a 2-pair fit: the
        full step raised ``U`` by 42 nats on the airspeed shift, its shifted Hessian having a
        negative eigenvalue); they weight the residuals and hardly move the centre.

        The step is kept only where ``U`` is quadratic over it: the decrease it achieves,
        ``U(x*) - U(x* + dx)``, must be within :data:`NEWTON_STEP_AGREEMENT` of the decrease
        the quadratic model predicts, ``g_k' H_kk^-1 g_k / 2`` (the trust-region ratio of
        Nocedal and Wright, Numerical Optimization, eq. 4.4).  None: the step failed it,
        another structure, or a Laplace covariance that is not the inverse Hessian (the MAP
        did not converge, its Hessian was not positive definite or was replaced by the
        L-BFGS-B estimate).  A positive definite Hessian whose small eigenvalues were raised
        to bound its condition (:func:`~bayes_roadload.inference.nuts.laplace_covariance`) is
        used: the raised directions shorten the step there, and the test rejects the step
        where that matters."""
        cov = self._conditional_covariance(tuple(held))
        if cov is None:
            return None
        keep, cov = cov
        data = self.data_of(problem)
        if data is None:
            return None
        fg, scale = self.program.fg, self.program.scale
        u0, g = (np.asarray(a, float) for a in fg(data, self.y0))
        if not (np.isfinite(u0) and np.all(np.isfinite(g))):
            return None
        gk = (g / scale)[keep]
        dx = np.zeros_like(g)
        dx[keep] = -cov @ gk
        predicted = 0.5 * float(gk @ cov @ gk)
        achieved = float(u0 - fg(data, self.y0 + dx / scale)[0])
        if not abs(achieved - predicted) <= NEWTON_STEP_AGREEMENT * predicted + NEWTON_STEP_FLOOR:
            return None
        return self.program.constrained(data, self.y0 * scale + dx)

    def _conditional_covariance(self, held: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray] | None:
        """(mask of the coordinates not ``held``, the inverse of the Hessian's block on them),
        or None without a usable Laplace covariance."""
        if held not in self._conditional:
            start, out = self.start, None
            cov = None if start.cov is None else np.asarray(start.cov, float)
            # a Hessian clipped only for its condition (positive definite, differenced, not
            # replaced) is used: the step's agreement test rejects it where the clipping matters
            usable = not start.hessian_regularised or (start.min_eigenvalue > 0.0 and start.hessian_step > 0.0)
            if cov is not None and start.success and usable and np.all(np.isfinite(cov)):
                keep = ~np.asarray(ravel_pytree({k: jnp.full(np.shape(v), k in held) for k, v in start.z.items()})[0],
                                   bool)
                hessian = np.linalg.inv(cov)
                out = (keep, np.linalg.inv(hessian[np.ix_(keep, keep)]))
            self._conditional[held] = out
        return self._conditional[held]

    def mode(self, problem: Problem) -> dict[str, Any] | None:
        """The constrained values at the MAP of ``problem`` with the shared compilation
        (None: another structure, or the optimiser did not converge)."""
        data = self.data_of(problem)
        if data is None:
            return None
        program = self.program
        res = newton_map(lambda y: program.fg(data, y), self.y0, program.run_index, program.scale)
        if not res["success"]:
            return None
        return program.constrained(data, res["y"] * program.scale)


def _shared_points(shared: SharedPotential | None, problems: list[Problem], how: str,
                   held: tuple[str, ...] = ()) -> list[dict[str, Any] | None]:
    """The point of each shifted problem of one source from the shared compilation:
    ``shared.mode`` (``how="mode"``), or ``shared.newton_step(problem, held)`` for both and,
    unless both steps are kept, the modes of both (``"newton"``: the two ends of a central
    difference come from the same approximation); None where there is no shared compilation
    or it does not apply (the caller fits that problem on its own)."""
    if shared is None:
        return [None] * len(problems)
    try:
        if how == "newton":
            steps = []
            for p in problems:   # the second step is not taken once the first is refused
                steps.append(shared.newton_step(p, held))
                if steps[-1] is None:
                    break
            else:
                return steps
            log.debug("Type B: a Newton step left the quadratic region; the shifted MAPs are refitted")
        return [shared.mode(p) for p in problems]
    except Exception as e:  # noqa: BLE001 - e.g. a value the model needs concrete: its own compilation instead
        log.debug("Type B: shared compilation not usable (%s: %s)", type(e).__name__, e)
        return [None] * len(problems)


def _shared(base: tuple[Problem, MapResult] | None) -> SharedPotential | None:
    if base is None:
        return None
    try:
        return SharedPotential(*base)
    except Exception as e:  # noqa: BLE001 - the problem cannot take its data as arguments
        log.debug("Type B: no shared compilation (%s: %s); each shifted campaign compiles its own",
                  type(e).__name__, e)
        return None


def _central_differences(build: Callable[[Any], Problem], shifts: Shifts, shared: SharedPotential | None,
                         how: str, held: tuple[str, ...] = ()) -> dict[str, dict[str, float]]:
    """Source -> quantity -> ``(x(+h) - x(-h)) / 2h``, ``x`` every quantity of the shifted
    problem at the point :func:`_shared_points` gives, or at its own MAP (:func:`mode_of`) when
    that is None.  A source whose shifted problems differ in their quantities keeps those they
    share; one whose problem cannot be built, or whose own MAP fails or does not converge, is
    left out (logged)."""
    out: dict[str, dict[str, float]] = {}
    for key, (plus, minus, h) in shifts.items():
        try:
            problems = [shifted_problem(c, build) for c in (plus, minus)]
            points = _shared_points(shared, problems, how, held)
            values = []
            for shifted, constrained in zip(problems, points):
                if constrained is None:
                    mode = mode_of(shifted)
                    if not mode.success:
                        log.warning("Type B source %s left out: the MAP of its shifted campaign did not converge "
                                    "(%s)", key, mode.message)
                        break
                    constrained = mode.constrained
                values.append(quantities_at(shifted, constrained))
        except Exception as e:  # noqa: BLE001 - a source that cannot be refitted is left out, not fatal
            log.warning("Type B source %s left out: the MAP of its shifted campaign failed (%s: %s)",
                        key, type(e).__name__, e)
            continue
        if len(values) == 2:
            out[key] = {q: (values[0][q] - values[1][q]) / (2.0 * h) for q in values[0] if q in values[1]}
    return out


def map_sensitivities(build: Callable[[Any], Problem], shifts: Shifts,
                      base: tuple[Problem, MapResult] | None = None) -> dict[str, dict[str, float]]:
    """Source -> quantity -> dx/ds by central differences of the MAPs of the shifted campaigns
    (module docstring); ``build`` makes the problem of a campaign.  With ``base`` (the fitted
    problem and its MAP) the shifted problems of its structure share one compilation
    (:class:`SharedPotential`) and start at its MAP; the others, and any whose shared MAP does
    not converge, are fitted on their own (:func:`mode_of`).  A source whose shifted MAP fails
    or does not converge is left out (logged), so that a fit never stops here."""
    return _central_differences(build, shifts, _shared(base), "mode")


def newton_sensitivities(build: Callable[[Any], Problem], shifts: Shifts, base: tuple[Problem, MapResult],
                         held: tuple[str, ...] = ()) -> dict[str, dict[str, float]]:
    """As :func:`map_sensitivities`, each shifted MAP replaced by one Newton step from the
    fitted MAP (:meth:`SharedPotential.newton_step`, the sites ``held`` at the MAP): two
    evaluations of the potential per shifted campaign instead of an optimisation, first-order
    exact, like the central differences themselves.  A step outside the potential's quadratic region is replaced by
    the shifted MAP (from the fitted one, shared compilation); a shifted problem of another
    structure, or a fitted MAP without a usable Laplace covariance, by that problem's own MAP."""
    return _central_differences(build, shifts, _shared(base), "newton", tuple(held))
