"""The sensitivity of a posterior's mode to a change of the campaign, for any problem.

A declared value or an instrument of the test (a Type B source, :mod:`bayes_roadload.data.
uncertainty`) shifted by ``+-h`` gives two shifted campaigns and, through the kind's problem
builder, two shifted problems.  Their MAPs (:func:`~bayes_roadload.inference.nuts.find_map`)
give every reported quantity ``x`` -- the sampled coefficients and the kind's derived figures,
which may read the shifted campaign directly (a mass enters the road load itself) -- and

    dx/ds = (x(MAP of the +h campaign) - x(MAP of the -h campaign)) / (2 h),

the central difference of the measurement result that GUM 5.1.3 takes as the sensitivity
coefficient.  One Newton step from the unshifted mode instead of each refit was measured as
no faster (each shifted problem compiles its own gradient either way, and compilation is most
of a small MAP's time) and off by up to 30 % on a spin-down's wheel inertia, so the MAPs are
refitted.  The speed-trace kind has the least-squares analogue
(:func:`~bayes_roadload.inference.lsq.linear_sensitivities`)."""

from __future__ import annotations

import logging
import math
from typing import Any, Callable, Mapping

import numpy as np

from .nuts import MapResult, find_map, unconstrained_posterior
from .problem import Problem

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


def map_sensitivities(build: Callable[[Any], Problem], shifts: Shifts) -> dict[str, dict[str, float]]:
    """Source -> quantity -> dx/ds by central differences of the MAPs of the shifted campaigns
    (module docstring); ``build`` makes the problem of a campaign.  A source whose shifted
    problems differ in their quantities keeps those they share; one whose shifted MAP fails or
    does not converge is left out (logged), so that a fit never stops here."""
    out: dict[str, dict[str, float]] = {}
    for key, (plus, minus, h) in shifts.items():
        values = []
        for c in (plus, minus):
            try:
                shifted = build(c)
                mode = mode_of(shifted)
            except Exception as e:  # noqa: BLE001 - a source that cannot be refitted is left out, not fatal
                log.warning("Type B source %s left out: the MAP of its shifted campaign failed (%s: %s)",
                            key, type(e).__name__, e)
                break
            if not mode.success:
                log.warning("Type B source %s left out: the MAP of its shifted campaign did not converge (%s)",
                            key, mode.message)
                break
            values.append(quantities_at(shifted, mode.constrained))
        if len(values) == 2:
            out[key] = {q: (values[0][q] - values[1][q]) / (2.0 * h) for q in values[0] if q in values[1]}
    return out
