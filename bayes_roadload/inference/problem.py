"""The written contract every fit problem implements, whatever its data kind.

A *problem* is a campaign resolved against a model variant (:class:`~.spec.ModelSpec`): the
arrays the likelihood needs, the priors, and the starting values.  The sampler
(:func:`~bayes_roadload.inference.nuts.sample_problem`: MAP, Laplace whitening, NUTS, gates),
the summary tables and the fit-directory writer (:mod:`bayes_roadload.output`) only ever use
the members of :class:`Problem`; nothing is looked up by ``getattr`` with a default and no
problem carries a field it does not use.

Implementations: :class:`~.bayes.FitProblem` (speed traces), :class:`~.intervals.IntervalProblem`
(interval times), :class:`~.distances.DistanceProblem` (distance-time records),
:class:`~.spindown.SpindownProblem` (wheel spin-downs), :class:`~.steady.SteadyProblem`
(steady-state forces) and :class:`~.driveline.DrivelineProblem` (the driveline channel alone).
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache, partial
from typing import Any, Callable, Protocol, runtime_checkable

import jax
import jax.numpy as jnp
import numpy as np

from ..physics.roadload import road_load_summary
from .spec import ModelSpec

ROAD_LOAD_DERIVED = ("F50_N", "F50_tyre_N", "F50_aero_N", "F50_driveline_N", "F50_undriven_N",
                     "F0_N", "F1_N_per_kph", "F2_N_per_kph2")
"""Derived road load at reference conditions (still air, 100 kPa, 293.2 K; thesis eq. 2.16 and
the F0/F1/F2 fit of section 2.4) of the problems whose model is a drag model."""


@runtime_checkable
class Problem(Protocol):
    """What a fit problem of any data kind provides.

    Attributes
    ----------
    kind : the data kind (a key of :data:`bayes_roadload.inference.kinds.KINDS`, or
        ``"driveline"`` for the driveline channel).
    spec : the model variant.
    free : names of the sampled coefficients (summary rows, in this order).
    initial : constrained starting values of the sample sites (SI), the start of the MAP.
    run_ids : the fitted runs, in the order of every per-run axis.
    """

    kind: str
    spec: ModelSpec
    free: tuple[str, ...]
    initial: dict[str, Any]
    run_ids: tuple

    @property
    def numpyro_model(self) -> Callable[[Any], None]:
        """The numpyro model; called with the problem as its only argument."""
        ...

    @property
    def hessian_runs(self) -> int:
        """Block structure of the MAP's finite-difference Hessian
        (:func:`~bayes_roadload.inference.nuts.fd_hessian`): the number ``R`` of runs whose
        per-run sites (unconstrained sites of shape ``(R,)``) do not interact with each other
        given the shared sites; 0 when every coordinate is to be treated as shared (sites
        that couple several runs, e.g. one per wheel or per pair)."""
        ...

    @property
    def n_observations(self) -> int:
        """Size of the problem's per-observation arrays as the likelihood evaluates them
        (padded samples of every run, interval times, markers, ...): what the cost and the
        memory of a gradient scale with (:func:`~bayes_roadload.inference.nuts.chain_method`)."""
        ...

    def settings(self) -> dict[str, Any]:
        """The likelihood options of the fit (``pooling``, ``noise``, ``robust``), recorded
        in ``diagnostics.json`` and ``fit.json``."""
        ...

    def alternative_coordinates(self, values: dict[str, Any]) -> "tuple[Problem, dict[str, Any], str] | None":
        """The same posterior sampled in other coordinates, which the retry after divergences
        samples (:func:`~bayes_roadload.inference.nuts.sample_problem`): that problem, ``values``
        (constrained values of this problem's sites, e.g. its MAP) as its starting values, and
        what changed, for ``diagnostics.json``; None when the problem has no other coordinates."""
        ...

    def beyond_support(self, z: dict[str, Any], cov: np.ndarray) -> float:
        """The share of the Laplace approximation (unconstrained sites ``z`` at the MAP,
        covariance ``cov`` of their flat vector in ravel order) at which a sampled coordinate maps
        to a coefficient outside its prior's support: a wall inside the sampled space, where the
        potential jumps to infinity and NUTS diverges whatever its step.  0 for a problem whose
        sampled coordinates map into the supports by construction."""
        ...

    def shift_constant(self, name: str, delta: float) -> "Problem | None":
        """The same problem with its fixed model constant ``name`` moved by ``delta`` (SI),
        everything else as it is: a model constant's Type B shift
        (:mod:`bayes_roadload.analysis.budget`).  None when ``name`` is not among the problem's
        fixed constants."""
        ...

    def postprocess(self, samples: dict[str, np.ndarray], seed: int) -> dict[str, np.ndarray]:
        """Sites added to the NUTS draws ([chain, draw, ...] arrays) after sampling, e.g. the
        run-level coefficients integrated out while sampling; ``{}`` when there are none."""
        ...

    def derived(self, samples: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Derived quantities of every draw ([chain, draw] arrays), summary rows after the
        sampled ones."""
        ...

    def truth_values(self, truth: dict | None) -> dict[str, float]:
        """The truth of a simulated campaign keyed by summary row (scalar truths and the
        derived quantities at them); ``{}`` without a truth."""
        ...


def shifted_constant(problem, name: str, delta: float):
    """``problem`` (a data class with a ``fixed`` dict) with ``fixed[name]`` moved by
    ``delta``, or None when ``name`` is not fixed there (:meth:`Problem.shift_constant`)."""
    if name not in problem.fixed:
        return None
    return dataclasses.replace(problem, fixed={**problem.fixed, name: float(problem.fixed[name]) + float(delta)})


class PooledRunProblem:
    """Protocol members shared by the pooled problems whose runs are independent given the
    coefficients (interval times, distance-time records): every run its own Hessian block, no
    sites drawn after sampling, the road load at reference conditions as the derived rows.  A
    subclass sets ``noise_model`` (recorded in ``diagnostics.json`` / ``fit.json``) and has the
    members ``run_ids``, ``free``, ``fixed``, ``model``, ``mass_kg``, ``frontal_area_m2``."""

    noise_model = ""

    @property
    def n_runs(self) -> int:
        return len(self.run_ids)

    @property
    def hessian_runs(self) -> int:
        return self.n_runs

    def settings(self) -> dict[str, Any]:
        return {"pooling": "pooled", "noise": self.noise_model, "robust": False}

    def alternative_coordinates(self, values: dict[str, Any]) -> None:
        return None

    def beyond_support(self, z: dict[str, Any], cov: np.ndarray) -> float:
        """0: every sampled coordinate maps into its support (:class:`Problem`)."""
        return 0.0

    def shift_constant(self, name: str, delta: float):
        return shifted_constant(self, name, delta)

    def postprocess(self, samples: dict[str, Any], seed: int) -> dict[str, Any]:
        return {}

    def derived(self, samples: dict[str, Any]) -> dict[str, Any]:
        """Road load at reference conditions (:func:`road_load_draws`)."""
        return road_load_draws(self, samples)

    def truth_values(self, truth: dict | None) -> dict[str, float]:
        return dict(truth or {}, **road_load_truth(self, truth))


def road_load_draws(problem, samples: dict[str, np.ndarray], *,
                    driveline_curve=(0.0, 0.0, 0.0)) -> dict[str, np.ndarray]:
    """Road load at reference conditions (:data:`ROAD_LOAD_DERIVED`) for every draw of the free
    coefficients of a problem with a drag model (``model``, ``fixed``, ``mass_kg``,
    ``frontal_area_m2``); ``driveline_curve`` (c2, c1, c0) adds a measured driveline loss."""
    chains = samples[problem.free[0]].shape[0] if problem.free else 1
    free = {k: jnp.asarray(_flat(samples[k])) for k in problem.free}
    fixed = {k: jnp.asarray(v, float) for k, v in problem.fixed.items()}
    args = (fixed, jnp.asarray(problem.mass_kg, float), jnp.asarray(problem.frontal_area_m2, float),
            tuple(jnp.asarray(c, float) for c in driveline_curve))
    try:
        hash(problem.model)
    except TypeError:  # a model that is not hashable: compiled for this call alone
        program = _road_load_program.__wrapped__(problem.model)
    else:
        program = _road_load_program(problem.model)
    out = program(free, *args)
    return {k: _unflat(np.asarray(out[k]), chains) for k in ROAD_LOAD_DERIVED}


def _road_load_one(model, values, fixed, mass_kg, frontal_area_m2, driveline_curve):
    return road_load_summary(model, dict(fixed, **values), mass_kg, frontal_area_m2, driveline_curve=driveline_curve)


@lru_cache(maxsize=32)
def _road_load_program(model) -> Callable[..., Any]:
    """:func:`road_load_summary` of ``model`` over draws, compiled once per model with the
    fixed values, mass, area and driveline curve as arguments: the draws of a fit and the
    Type B step's shifted campaigns (another mass, other fixed values) reuse it."""
    return jax.jit(jax.vmap(partial(_road_load_one, model), in_axes=(0, None, None, None, None)))


def road_load_truth(problem, truth: dict | None, *, driveline_curve=(0.0, 0.0, 0.0)) -> dict[str, float]:
    """:data:`ROAD_LOAD_DERIVED` at the true coefficients (every free one must be in ``truth``),
    with every other model constant the truth states at its true value too: a constant the
    analysis holds at an assumed value (the tyre's v^2 coefficient of
    ``four_term_tyre_lag_j2452_mean``) is the simulator's where the simulator says, so that
    the analysis' assumption does not enter the truth it is scored against.

    A truth that states a road-load quantity itself (a simulator whose physics differs from
    the analysis model, e.g. :mod:`bayes_roadload.simulate.independent`, reports its own road
    load at the reference conditions) keeps its value: the analysis model's formula at the
    true coefficients would leave out what the model does not describe."""
    if not truth:
        return {}
    stated = {k: float(truth[k]) for k in ROAD_LOAD_DERIVED if isinstance(truth.get(k), (int, float))}
    if not all(isinstance(truth.get(k), (int, float)) for k in problem.free):
        return stated
    values = {k: float(truth[k]) for k in problem.model.parameter_names if isinstance(truth.get(k), (int, float))}
    out = road_load_summary(problem.model, dict(problem.fixed, **values), problem.mass_kg, problem.frontal_area_m2,
                            driveline_curve=driveline_curve)
    return {k: float(v) for k, v in out.items()} | stated


def _flat(x: np.ndarray) -> np.ndarray:
    return x.reshape((-1,) + x.shape[2:])


def _unflat(x: np.ndarray, chains: int) -> np.ndarray:
    return x.reshape((chains, -1) + x.shape[1:])
