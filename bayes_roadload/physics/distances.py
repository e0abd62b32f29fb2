"""Distance-time records: the times at which a coasting vehicle passes known distances.

The coastdown equation M_e dv/dt = -F(v) (eq. 5.4), written with the distance x travelled as the
independent variable,

    dv/dx = a(v) / v,        dt/dx = 1 / v,        a = -F / M_e,

is integrated by RK4 in x from the run's first marker (speed ``v0``, time 0) through each
following marker (``DISTANCE_RK4_SUBSTEPS`` steps between two markers, one scan), giving the time
at which each marker is passed: seed 002's speed-trap model (its closed form S(T) for a
quadratic road load is the inverse of what is computed here; tested against appendix D's t(v)
with v(x) in closed form, and against ``scipy.integrate.solve_ivp``).  Pure JAX, differentiable
in every parameter and in ``v0``; runs are vmapped, markers scanned.

The deceleration comes from :meth:`~bayes_roadload.physics.model.DragModel.acceleration_mps2`
with the relative air from the model's air description (still air, or a wind given as
parameters), as for speed-gate interval times (:mod:`.intervals`, whose model checks apply:
no anemometer channels, no position-dependent terms).  The likelihood of the times between
consecutive markers is the interval-time one (:func:`~bayes_roadload.physics.intervals.
band_time_loglik`): a timing error per marker passing, shared by the two segments either side
of the marker, scatter growing with a segment's duration, and a run-level deceleration offset
integrated out, whose sensitivity (``dtime_ddecel_s_per_mps2``) is computed here by the forward
sensitivity equations integrated alongside.

Nothing here imports numpyro.
"""

from __future__ import annotations

import functools
from typing import Mapping, NamedTuple

import jax
import jax.numpy as jnp

from .model import DragModel
from .terms import Conditions

DISTANCE_RK4_SUBSTEPS = 4
"""RK4 steps (in distance) between two consecutive markers: on 100 m marker spacing from 30 m/s
the passing times agree with the closed form of a quadratic road load to ~1e-9 s over 1300 m
(tested; 8 steps: 1e-10 s, 2 steps: 2e-8 s), far below any timing error (a light gate's ~1 ms);
the error grows as the fourth power of the step (500 m spacing: ~1e-6 s)."""

DISTANCE_MIN_SPEED_MPS = 0.05
"""Floor of the speed in the distance-domain ODE (dv/dx = a / v, dt/dx = 1 / v): keeps a draw
whose vehicle would stop before the last marker finite (its times then are merely very long)."""

Array = jnp.ndarray


class MarkerRuns(NamedTuple):
    """The markers of R distance-time runs (SI units).

    ``distance_m`` [R, K]: each run's marker distances counted from its first marker (0 first),
    increasing; shorter runs padded by repeating their last distance (a zero-length segment
    changes nothing) with ``mask`` [R, K] False there.  Per-run constants ([R]): ``direction``
    (+1/-1), ``air_density_kgpm3``, ``temperature_k``, ``mass_kg``, ``effective_mass_kg``,
    ``frontal_area_m2``.
    """

    distance_m: Array
    mask: Array
    direction: Array
    air_density_kgpm3: Array
    temperature_k: Array
    mass_kg: Array
    effective_mass_kg: Array
    frontal_area_m2: Array

    @property
    def n_runs(self) -> int:
        return int(jnp.shape(self.distance_m)[0])


def _passing_one_run(model: DragModel, p: Mapping[str, Array], run: MarkerRuns, v0: Array, decel_offset: Array,
                     substeps: int) -> tuple[Array, Array, Array]:
    """Times, speeds and d time / d deceleration offset [K] at the markers of one run (scalars
    in ``run``'s constants).

    State along the distance: (v, t, u = dv/d delta, w = dt/d delta), delta a constant extra
    deceleration.  From v dv/dx = a(v) - delta and dt/dx = 1 / v,

        du/dx = (a'(v) u - 1 - u dv/dx) / v,        dw/dx = -u / v^2,

    the forward sensitivity equations, integrated by the same RK4 steps (a'(v) by a local
    forward-mode derivative): one scan over all steps, cheaper to compile and to differentiate
    than a derivative of the whole integration.
    """
    me = run.effective_mass_kg
    z = jnp.zeros(())

    def accel(v, x, t):
        airspeed, yaw = model.air.relative_air(p, v, v, z)
        c = Conditions(speed_mps=v, airspeed_mps=airspeed, yaw_rad=yaw, driveline_force_n=z, position_m=z,
                       distance_m=x, time_s=t, accel_mps2=z, direction=run.direction,
                       air_density_kgpm3=run.air_density_kgpm3, temperature_k=run.temperature_k,
                       mass_kg=run.mass_kg, frontal_area_m2=run.frontal_area_m2)
        return model.acceleration_mps2(p, c, me) - decel_offset

    def rhs(y, x):
        v = jnp.maximum(y[0], DISTANCE_MIN_SPEED_MPS)
        a, da_dv = jax.jvp(lambda vv: accel(vv, x, y[1]), (v,), (jnp.ones_like(v),))
        dv = a / v
        du = (da_dv * y[2] - 1.0 - y[2] * dv) / v
        return jnp.stack([dv, 1.0 / v, du, -y[2] / v**2])

    def step(y, xs):
        xa, h = xs
        k1 = rhs(y, xa)
        k2 = rhs(y + 0.5 * h * k1, xa + 0.5 * h)
        k3 = rhs(y + 0.5 * h * k2, xa + 0.5 * h)
        k4 = rhs(y + h * k3, xa + h)
        y = y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        return y, y

    # the distance grid: ``substeps`` equal steps between consecutive markers (padding: h = 0)
    x = run.distance_m
    frac = jnp.arange(substeps) / substeps
    starts = (x[:-1, None] + frac[None, :] * (x[1:] - x[:-1])[:, None]).reshape(-1)
    h = jnp.repeat(jnp.diff(x) / substeps, substeps)
    y0 = jnp.stack([jnp.asarray(v0, float), z, z, z])
    _, ys = jax.lax.scan(step, y0, (starts, h))
    ys = jnp.concatenate([y0[None], ys[substeps - 1::substeps]], axis=0)
    return ys[:, 1], ys[:, 0], ys[:, 3]


def passing_times(model: DragModel, params: Mapping[str, Array], runs: MarkerRuns, v0_mps: Array, *,
                  decel_offset_mps2: Array | float = 0.0,
                  substeps: int = DISTANCE_RK4_SUBSTEPS) -> dict[str, Array]:
    """Time and speed at every marker of every run (RK4 in distance, module docstring).

    Parameters
    ----------
    model : the drag model (still air or a wind given as parameters).
    params : parameter values, scalars (shared) or [R] (per run, e.g. a head wind signed by
        the run's direction); missing ones take the model defaults.
    runs : the markers (:class:`MarkerRuns`).
    v0_mps : [R] speed at each run's first marker (m/s).
    decel_offset_mps2 : a constant extra deceleration, scalar or [R] (m/s^2).
    substeps : RK4 steps between two consecutive markers.

    Returns
    -------
    dict of [R, K] arrays: ``time_s`` (0 at the first marker; padding repeats the last),
    ``speed_mps`` at each marker, and ``dtime_ddecel_s_per_mps2``, the derivative of the
    passing time with respect to a constant extra deceleration of the run (forward
    sensitivity equations, :func:`_passing_one_run`).
    """
    r = runs.n_runs
    p = {k: jnp.asarray(v, float) for k, v in model.complete(params).items()}
    v0 = jnp.broadcast_to(jnp.asarray(v0_mps, float), (r,))
    off = jnp.broadcast_to(jnp.asarray(decel_offset_mps2, float), (r,))
    t, v, w = _passing_batch(model, p, runs, v0, off, int(substeps))
    return {"time_s": t, "speed_mps": v, "dtime_ddecel_s_per_mps2": w}


@functools.partial(jax.jit, static_argnums=(0, 5))
def _passing_batch(model: DragModel, p, runs: MarkerRuns, v0, off, substeps: int):
    """:func:`_passing_one_run` vmapped over the runs; compiled once per model and shapes, so
    that eager calls (numpyro's initialisation, checks) do not recompile the scan."""
    r = runs.n_runs
    axes = {k: (0 if jnp.ndim(v) == 1 and jnp.shape(v)[0] == r else None) for k, v in p.items()}

    def one(pp, run, v, o):
        return _passing_one_run(model, pp, run, v, o, substeps)

    return jax.vmap(one, in_axes=(axes, 0, 0, 0))(p, runs, v0, off)


def segment_times(model: DragModel, params: Mapping[str, Array], runs: MarkerRuns, v0_mps: Array, *,
                  substeps: int = DISTANCE_RK4_SUBSTEPS) -> dict[str, Array]:
    """Durations of the segments between consecutive markers and their sensitivity to a
    run-level deceleration offset.

    Returns
    -------
    dict of [R, K-1] arrays: ``time_s`` (model time from marker k to marker k+1; 0 on padding),
    ``dtime_ddecel_s_per_mps2`` (d time / d constant extra deceleration, positive: a larger
    deceleration lengthens the later segments); and ``speed_mps`` [R, K] at the markers.
    """
    out = passing_times(model, params, runs, v0_mps, substeps=substeps)
    return {"time_s": jnp.diff(out["time_s"], axis=1),
            "dtime_ddecel_s_per_mps2": jnp.diff(out["dtime_ddecel_s_per_mps2"], axis=1),
            "speed_mps": out["speed_mps"]}
