"""RK4 integration of the coastdown equation over the sample grid of each run.

The state is (speed v, distance travelled s).  Between two samples the measured inputs
(airspeed, yaw, driveline force, air density, temperature, the surveyed track grade at the
logged position, and the airspeed reading's rate for
terms that undo an instrument lag) are linearly interpolated, so the
RK4 stages at the half step see the mean of the two neighbouring samples (thesis section 5.2).
Runs of unequal length are padded to a common length by repeating their last sample: a padded
step has dt = 0 and leaves the state unchanged, and ``mask`` marks the real samples.
"""

from __future__ import annotations

from typing import Mapping, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .. import config
from .model import DragModel
from .terms import Conditions

Array = jnp.ndarray


class RunBatch(NamedTuple):
    """The logged channels of one run ([N] arrays) or of R padded runs ([R, N] arrays).

    Per-sample channels: ``time_s`` (from the start of the run), ``speed_mps`` (measured),
    ``airspeed_mps`` and ``yaw_rad`` (anemometer readings, uncalibrated), ``driveline_force_n``,
    ``air_density_kgpm3``, ``temperature_k``, ``track_grade_rad`` (the surveyed track's rise in
    its +x direction at the logged position, 0 without a survey), ``mask`` (True on real
    samples).
    Per-run constants ([] or [R]): ``direction`` (+1/-1), ``start_position_m``, ``mass_kg``,
    ``effective_mass_kg``, ``frontal_area_m2``.
    """

    time_s: Array
    speed_mps: Array
    airspeed_mps: Array
    yaw_rad: Array
    driveline_force_n: Array
    air_density_kgpm3: Array
    temperature_k: Array
    track_grade_rad: Array
    mask: Array
    direction: Array
    start_position_m: Array
    mass_kg: Array
    effective_mass_kg: Array
    frontal_area_m2: Array

    @property
    def n_runs(self) -> int:
        return 1 if self.time_s.ndim == 1 else self.time_s.shape[0]

    def run(self, i: int) -> "RunBatch":
        """The i-th run of a batch (still padded)."""
        return RunBatch(*(jnp.asarray(x)[i] for x in self))


_CHANNELS = ("airspeed_mps", "yaw_rad", "driveline_force_n", "air_density_kgpm3", "temperature_k",
             "track_grade_rad")
"""The logged channels of a run the forces read, in the order of the inputs' last axis."""

_INPUTS = _CHANNELS + ("airspeed_rate_mps2", "speed_measured_mps", "speed_drop_lagged_mps",
                       "felt_airspeed_reading", "felt_yaw_reading")
"""Every column of the inputs' last axis: the logged channels, then what :func:`_inputs`
derives from them (the reading's rate, the measured speed), then the channels that
:func:`_with_model_channel` appends only for a model whose terms read them, in this order: the
lagged speed drop (a term naming a ``lag_time_constant``), the felt air's readings (a term
naming a ``felt_air_length``)."""

_AT = {name: i for i, name in enumerate(_INPUTS)}
_BASE = _AT["speed_drop_lagged_mps"]
"""The number of input columns every model has (:func:`_inputs`)."""


def _model_columns(model: DragModel) -> dict[str, int]:
    """The columns :func:`_with_model_channel` appends for ``model``, by name, at their index."""
    names = (("speed_drop_lagged_mps",) if model.lag_time_constant else ()) + (
        ("felt_airspeed_reading", "felt_yaw_reading") if model.felt_air_length else ())
    return {name: _BASE + i for i, name in enumerate(names)}


def _conditions(model: DragModel, p, run: RunBatch, v, s, t, u) -> Conditions:
    """The conditions at speed ``v``, distance ``s`` and time ``t`` with the inputs ``u``
    (the columns of :data:`_INPUTS`, those of :func:`_model_columns` only when the model
    appended them)."""
    airspeed, yaw = model.air.relative_air(p, v, u[_AT["airspeed_mps"]], u[_AT["yaw_rad"]])
    extra = _model_columns(model)
    felt_airspeed = felt_yaw = None
    if "felt_airspeed_reading" in extra:
        felt_airspeed, felt_yaw = model.air.relative_air(p, v, u[extra["felt_airspeed_reading"]],
                                                         u[extra["felt_yaw_reading"]])
    return Conditions(
        speed_mps=v,
        airspeed_mps=airspeed,
        yaw_rad=yaw,
        driveline_force_n=u[_AT["driveline_force_n"]],
        position_m=run.start_position_m + run.direction * s,
        distance_m=s,
        time_s=t,
        accel_mps2=jnp.zeros_like(v),
        direction=run.direction,
        air_density_kgpm3=u[_AT["air_density_kgpm3"]],
        temperature_k=u[_AT["temperature_k"]],
        track_grade_rad=u[_AT["track_grade_rad"]],
        mass_kg=run.mass_kg,
        frontal_area_m2=run.frontal_area_m2,
        airspeed_rate_mps2=u[_AT["airspeed_rate_mps2"]],
        speed_drop_lagged_mps=u[extra["speed_drop_lagged_mps"]] if "speed_drop_lagged_mps" in extra else 0.0,
        speed_measured_mps=u[_AT["speed_measured_mps"]],
        felt_airspeed_mps=felt_airspeed,
        felt_yaw_rad=felt_yaw,
    )


@jax.jit
def lagged_speed_drop(time_s: Array, speed_mps: Array, time_constant_s: Array) -> Array:
    """The part of the speed drop since the first sample not yet followed by a first-order lag:
    L(0) = 0, dL/dt = -L / tau - dv/dt, on the sample grid ([N] arrays, the speed
    piecewise linear between samples), exact for that speed:
    L_{k+1} = a_k L_k - (v_{k+1} - v_k) tau (1 - a_k) / h_k with a_k = exp(-h_k / tau).
    Zero-length steps (padding) leave L unchanged.  Composed as affine maps by
    ``jax.lax.associative_scan`` (no sequential loop to differentiate); jitted, so that a call
    outside a compiled function is one program, not the scan's levels op by op.
    :class:`~bayes_roadload.physics.terms.TyreThermalLag` reads it."""
    t = jnp.asarray(time_s, float)
    v = jnp.asarray(speed_mps, float)
    tau = jnp.asarray(time_constant_s, float)
    h = jnp.diff(t)
    a = jnp.exp(-h / tau)
    ok = h > 0
    # tau (1 - a) / h, -> 1 as h -> 0
    ratio = jnp.where(ok, -jnp.expm1(-h / tau) * tau / jnp.where(ok, h, 1.0), 1.0)
    b = -jnp.diff(v) * ratio
    _, lag = affine_scan(a, b)
    return jnp.concatenate([jnp.zeros_like(v[:1]), lag])


def affine_scan(a: Array, b: Array, sequential: bool = False) -> tuple[Array, Array]:
    """The recurrence y_{k+1} = a_k y_k + b_k over the last axis of ``a`` and ``b`` as the
    cumulative maps (gain_k, offset_k) with y_{k+1} = gain_k y_0 + offset_k.

    By default composed by ``jax.lax.associative_scan`` (log depth, no sequential loop to
    differentiate: the likelihood's lagged speed drop).  ``sequential=True`` runs the same
    recurrence as one ``jax.lax.scan`` loop: the same numbers to rounding, a program that
    compiles in about a third of the time, for transforms of the data that are computed once
    and not differentiated (the admittance filter of :mod:`~bayes_roadload.physics.admittance`)."""
    def compose(first, second):
        return second[0] * first[0], second[0] * first[1] + second[1]

    if not sequential:
        return jax.lax.associative_scan(compose, (a, b), axis=-1)

    def step(carry, ab):
        carry = compose(carry, ab)
        return carry, carry

    first = (jnp.ones(jnp.shape(a)[:-1], jnp.result_type(a)), jnp.zeros(jnp.shape(b)[:-1], jnp.result_type(b)))
    _, (gain, offset) = jax.lax.scan(step, first, (jnp.moveaxis(a, -1, 0), jnp.moveaxis(b, -1, 0)))
    return jnp.moveaxis(gain, 0, -1), jnp.moveaxis(offset, 0, -1)


def _with_model_channel(model: DragModel, p, run: RunBatch, u, schedule):
    """Append the channels of :func:`_model_columns` to the inputs and to the stride-2
    schedule: the lagged speed drop (:func:`lagged_speed_drop`) when a term of ``model`` reads
    it, the readings of the air felt after the admittance filter of the length a term names
    (:func:`~bayes_roadload.physics.admittance.felt_air_readings` of the readings and the
    measured speed, calibration factors 1: the model's air calibrates them as the readings);
    else return them unchanged."""
    columns = []
    if model.lag_time_constant:
        columns.append(lagged_speed_drop(run.time_s, run.speed_mps, p[model.lag_time_constant]))
    if model.felt_air_length:
        from .admittance import felt_air_readings

        columns.extend(felt_air_readings(run.time_s, run.speed_mps, run.airspeed_mps, run.yaw_rad,
                                         1.0, 1.0, p[model.felt_air_length]))
    if not columns:
        return u, schedule
    added = jnp.stack([jnp.asarray(c) for c in columns], axis=-1)
    u = jnp.concatenate([jnp.asarray(u), added], axis=-1)
    if schedule is None:
        return u, None
    t0, h, ua, um, uc, dense = schedule
    _, _, la, lm, lc, _ = stride2_schedule(run.time_s, added)
    join = lambda x, y: jnp.concatenate([jnp.asarray(x), jnp.asarray(y)], axis=-1)  # noqa: E731
    return u, (t0, h, join(ua, la), join(um, lm), join(uc, lc), dense)


def stride2_schedule(time_s, inputs) -> tuple:
    """The data-only part of RK4 steps spanning two sample intervals (``stride = 2``).

    ``time_s`` [..., N], ``inputs`` [..., N, C] (the columns of :data:`_INPUTS`).  Returns
    ``(t0, h, u0, u_mid, u1, dense)`` per step ([..., G] and [..., G, C], ``dense``
    [..., G, 2, 3]): the step's start time and length, the inputs at its start and end, the
    inputs its half-step stages see, and the weights of RK4's continuous extension at the
    middle and last sample.  The half-step stages see the mean of the piecewise-linear input
    over the middle half of the step ((u0 + 6 u_middle + u1) / 8 on a uniform grid), so a
    force linear in the inputs integrates exactly as with one step per sample, at both
    samples.  Computed with numpy when the data are concrete (once per trace, not per call).
    """
    concrete = not any(isinstance(x, jax.core.Tracer) for x in (time_s, inputs))
    xp = np if concrete else jnp
    t, u = xp.asarray(time_s, dtype=float), xp.asarray(inputs, dtype=float)
    n = t.shape[-1]
    if (n - 1) % 2:  # an odd number of intervals: one dt = 0 interval at the end
        t = xp.concatenate([t, t[..., -1:]], axis=-1)
        u = xp.concatenate([u, u[..., -1:, :]], axis=-2)
    ta, tb, tc = t[..., 0:-1:2], t[..., 1::2], t[..., 2::2]
    ua, ub, uc = u[..., 0:-1:2, :], u[..., 1::2, :], u[..., 2::2, :]
    h = tc - ta

    def safe_div(x, y):
        ok = y > 0
        return xp.where(ok, x / xp.where(ok, y, 1.0), 0.0)

    def integral(x):  # int_{ta}^{x} of the piecewise-linear input, [..., G, C]
        out = 0.0
        for t0, t1, u0, u1 in ((ta, tb, ua, ub), (tb, tc, ub, uc)):
            length = (xp.clip(x, t0, t1) - t0)[..., None]
            out = out + u0 * length + 0.5 * safe_div(u1 - u0, (t1 - t0)[..., None]) * length**2
        return out

    lo, hi = ta + 0.25 * h, ta + 0.75 * h
    u_mid = xp.where((h > 0)[..., None], safe_div(integral(hi) - integral(lo), (hi - lo)[..., None]), ua)
    th = xp.stack([xp.where(h > 0, safe_div(tb - ta, h), 1.0), xp.ones_like(h)], axis=-1)  # [..., G, 2]
    dense = xp.stack([th - 1.5 * th**2 + (2.0 / 3.0) * th**3, th**2 - (2.0 / 3.0) * th**3,
                      -0.5 * th**2 + (2.0 / 3.0) * th**3], axis=-1)
    return ta, h, ua, u_mid, uc, dense


def reading_rate(time_s, reading, mask):
    """d/dt of a logged channel ([..., N]): central differences on the sample grid (one-sided
    at the ends), zero on padded samples and where the step is zero."""
    concrete = not any(isinstance(x, jax.core.Tracer) for x in (time_s, reading, mask))
    xp = np if concrete else jnp
    t, x, m = xp.asarray(time_s, dtype=float), xp.asarray(reading, dtype=float), xp.asarray(mask, dtype=bool)
    pad_t = lambda a: xp.concatenate([a[..., :1], a, a[..., -1:]], axis=-1)  # noqa: E731
    tt, xx = pad_t(t), pad_t(x)
    # neighbours: the sample itself at the ends (one-sided differences there)
    dt = tt[..., 2:] - tt[..., :-2]
    dx = xx[..., 2:] - xx[..., :-2]
    ok = m & (dt > 0)
    return xp.where(ok, dx / xp.where(ok, dt, 1.0), 0.0)


def _inputs(run: RunBatch):
    """The input channels stacked on a last axis ([..., N, C]): the columns of :data:`_INPUTS`
    but the model's own: those of ``_CHANNELS``, the rate of the airspeed reading
    (:func:`reading_rate`) and the measured speed; with numpy when they are concrete, so that
    data-only work on them is done once per trace."""
    channels = [getattr(run, ch) for ch in _CHANNELS]
    channels.append(reading_rate(run.time_s, run.airspeed_mps, run.mask))
    channels.append(run.speed_mps)
    assert len(channels) == _BASE
    if any(isinstance(x, jax.core.Tracer) for x in channels):
        return jnp.stack([jnp.asarray(x) for x in channels], axis=-1)
    return np.stack([np.asarray(x) for x in channels], axis=-1)


def _solves_in_parallel(model: DragModel, integrator: config.IntegratorConfig) -> bool:
    """Whether the integrator solves ``model`` in parallel over time (:func:`_affine_stages`,
    :func:`_compose_affine`): stride 2, ``integrator.parallel`` and an equation of motion
    affine in the speed."""
    return integrator.stride == 2 and integrator.parallel and model.speed_affine


def _schedule_of(batch: RunBatch, integrator: config.IntegratorConfig):
    """The stride-2 schedule of a batch (computed once, outside any vmap), else None."""
    return stride2_schedule(batch.time_s, _inputs(batch)) if integrator.stride == 2 else None


def integrate_run(
    model: DragModel,
    params: Mapping[str, Array],
    run: RunBatch,
    v0_mps: Array | None = None,
    integrator: config.IntegratorConfig = config.DEFAULT_INTEGRATOR,
    schedule: tuple | None = None,
) -> tuple[Array, Array]:
    """Integrate eq. 5.4 for one run with RK4 on its sample grid.

    Parameters
    ----------
    model : the drag model.
    params : parameter values (SI); missing ones take the model defaults.
    run : one run's channels ([N] arrays, scalar constants).
    v0_mps : initial speed; defaults to the first measured speed (thesis practice).
    integrator : RK4 substeps per sample interval, or one step per two intervals
        (:class:`~bayes_roadload.config.IntegratorConfig`).
    schedule : for ``stride = 2``, this run's :func:`stride2_schedule` if already computed.

    Returns
    -------
    speed_mps, distance_m : [N] arrays at the sample times.
    """
    p = model.complete(params)
    v0 = run.speed_mps[0] if v0_mps is None else jnp.asarray(v0_mps, dtype=float)
    u = _inputs(run)  # [N, C]
    m, stride = integrator.substeps, integrator.stride
    if stride not in (1, 2) or (stride == 2 and m != 1):
        raise ValueError(f"stride must be 1, or 2 with substeps = 1 (got stride {stride}, substeps {m})")

    def rhs(y, t, uu):
        v, s = y
        if model.speed_affine:  # linear in v: no runaway, and the parallel solution stays equal
            c = _conditions(model, p, run, v, s, t, uu)
            return jnp.stack([model.acceleration_mps2(p, c, run.effective_mass_kg), v])
        # eq. 5.4 with the forces seen at v >= 0: below zero the trajectory continues at the
        # forces of standstill, a(0) (a quadratic drag in a negative ground speed would grow
        # without bound).  Where the speed crosses zero its gradient in the parameters jumps
        # only by the forces' speed slope at standstill, and a trajectory that stops before its
        # run's last sample is penalised smoothly.  Holding it at zero put a kink into the
        # likelihood wherever an integrator stage crossed zero, and NUTS' step size collapsed
        # there (a one-pair GNSS fit of a light car: one chain at tree depth 10).  Runs end
        # while the vehicle moves (traces.check_moving), so no measured sample is at standstill.
        moving = jnp.maximum(v, 0.0)
        c = _conditions(model, p, run, moving, s, t, uu)
        return jnp.stack([model.acceleration_mps2(p, c, run.effective_mass_kg), moving])

    def rk4(y, ta, h, ua, um, ub):
        k1 = rhs(y, ta, ua)
        k2 = rhs(y + 0.5 * h * k1, ta + 0.5 * h, um)
        k3 = rhs(y + 0.5 * h * k2, ta + 0.5 * h, um)
        k4 = rhs(y + h * k3, ta + h, ub)
        return k1, k2, k3, k4

    if stride == 2 and schedule is None:
        schedule = stride2_schedule(run.time_s, u)
    if _solves_in_parallel(model, integrator):
        stages = _hold(_affine_stages(model, p, run, schedule))
        return _compose_affine(stages, v0, schedule, run.time_s.shape[0])
    u, schedule = _with_model_channel(model, p, run, u, schedule)
    y0 = jnp.stack([v0, jnp.zeros_like(v0)])
    if stride == 1:
        def step(y, xs):
            t0, t1, u0, u1 = xs
            h = (t1 - t0) / m

            def sub(j, y):
                fa, fm, fb = j / m, (j + 0.5) / m, (j + 1.0) / m
                k1, k2, k3, k4 = rk4(y, t0 + j * h, h, u0 + fa * (u1 - u0), u0 + fm * (u1 - u0), u0 + fb * (u1 - u0))
                return y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)

            y = jax.lax.fori_loop(0, m, sub, y)
            return y, y

        _, ys = jax.lax.scan(step, y0, (run.time_s[:-1], run.time_s[1:], u[:-1], u[1:]))
    else:
        n = run.time_s.shape[0]

        def step(y, xs):
            t0, hk, u0, umk, u2, w = xs
            k1, k2, k3, k4 = rk4(y, t0, hk, u0, umk, u2)
            mid = y + hk * (w[0, 0] * k1 + w[0, 1] * (k2 + k3) + w[0, 2] * k4)
            end = y + hk * (w[1, 0] * k1 + w[1, 1] * (k2 + k3) + w[1, 2] * k4)
            return end, (mid, end)

        _, (y_mid, y_end) = jax.lax.scan(step, y0, tuple(jnp.asarray(x) for x in schedule))
        ys = jnp.stack([y_mid, y_end], axis=1).reshape(-1, 2)[: n - 1]
    ys = jnp.concatenate([y0[None, :], ys], axis=0)
    return ys[:, 0], ys[:, 1]


def _affine_stages(model: DragModel, p, run: RunBatch, schedule) -> tuple:
    """For a model whose deceleration is affine in the speed, a(t, v) = alpha(t) + beta(t) v
    (``model.speed_affine``): alpha and beta at the RK4 stage points of every stride-2 step
    of one run, ``(alpha_1, beta_1, alpha_2, beta_2, alpha_4, beta_4)`` (stage 3 shares
    stage 2's point), each [K]."""
    u = jnp.asarray(_inputs(run))
    _, schedule = _with_model_channel(model, p, run, u, schedule)
    t0, h, ua, um, uc, _ = (jnp.asarray(x) for x in schedule)

    def coefficients(t, uu):
        def acc(v):
            c = _conditions(model, p, run, v, jnp.zeros_like(v), t, uu.T)
            return model.acceleration_mps2(p, c, run.effective_mass_kg)

        a0 = acc(jnp.zeros_like(t))
        return a0, acc(jnp.ones_like(t)) - a0

    return coefficients(t0, ua) + coefficients(t0 + 0.5 * h, um) + coefficients(t0 + h, uc)


def _hold(stages: tuple) -> tuple:
    """``stages`` unchanged, computed once and held in memory: passed through a ``lax.cond``
    whose predicate, ``x == x`` on the first stage coefficient x, is true unless x is NaN (the
    other branch then makes every output NaN, where the first run's already is).  XLA's CPU
    fusion otherwise copies the arithmetic of the model's force terms into each fused loop
    that reads the stage coefficients, forward and in the gradient, where about 20 loops
    read them (``jax.lax.optimization_barrier`` is removed before fusion; measured in
    docs/performance.md, *The gradient's cost*).  Under ``vmap`` the ``cond`` becomes a
    select: the same values, without the hold."""
    if stages[0].size == 0:  # a one-sample run has no steps
        return stages
    key = stages[0].reshape(-1)[0]
    return jax.lax.cond(key == key, lambda x: x, lambda x: tuple(a + 0.0 * key for a in x), stages)


def _compose_affine(stages: tuple, v0: Array, schedule, n: int) -> tuple[Array, Array]:
    """The stride-2 RK4 of :func:`integrate_run` for a speed-affine model, computed in
    parallel over time from its stage coefficients (:func:`_affine_stages`).  Each RK4 step
    is then an affine map of the speed at its start, v_end = Phi v + Gamma (Phi > 0:
    1 - h beta + ..., the step is far shorter than the deceleration's time scale), and so are
    the middle-sample output and the distance increments; the maps are built for all steps at
    once and composed by cumulative sums.  The arithmetic is RK4's, so the result equals the
    sequential scan to rounding (tested), and reverse-mode gradients through it are cheap: no
    sequential loop is left.  Returns the [n] speed and distance."""
    al1, be1, al2, be2, al4, be4 = stages
    h, w = jnp.asarray(schedule[1]), jnp.asarray(schedule[5])
    # stage speeds y_i and slopes k_i as (constant, coefficient of v)
    y1 = (jnp.zeros_like(h), jnp.ones_like(h))
    k1 = (al1, be1)
    y2 = (0.5 * h * k1[0], 1.0 + 0.5 * h * k1[1])
    k2 = (al2 + be2 * y2[0], be2 * y2[1])
    y3 = (0.5 * h * k2[0], 1.0 + 0.5 * h * k2[1])
    k3 = (al2 + be2 * y3[0], be2 * y3[1])
    y4 = (h * k3[0], 1.0 + h * k3[1])
    k4 = (al4 + be4 * y4[0], be4 * y4[1])

    def combine(j, a, b, c, d):  # h (w1 a + w23 (b + c) + w4 d) at output j (0: middle, 1: end)
        return tuple(h * (w[:, j, 0] * a[i] + w[:, j, 1] * (b[i] + c[i]) + w[:, j, 2] * d[i]) for i in (0, 1))

    dv_mid, dv_end = combine(0, k1, k2, k3, k4), combine(1, k1, k2, k3, k4)
    ds_mid, ds_end = combine(0, y1, y2, y3, y4), combine(1, y1, y2, y3, y4)

    # compose the steps' maps v -> Phi_k v + Gamma_k: with P_k = Phi_1 ... Phi_k (the
    # sensitivity to the initial speed, 0.8-1 over a coastdown), the speed after step k is
    # P_k (v0 + sum_{j<=k} Gamma_j / P_j): two cumulative sums, no sequential loop
    log_p = jnp.cumsum(jnp.log(1.0 + dv_end[1]))
    v_end = jnp.exp(log_p) * (v0 + jnp.cumsum(dv_end[0] * jnp.exp(-log_p)))
    v_start = jnp.concatenate([v0[None], v_end[:-1]])
    v_mid = v_start + dv_mid[0] + dv_mid[1] * v_start
    s_step = ds_end[0] + ds_end[1] * v_start
    s_end = jnp.cumsum(s_step)
    s_start = s_end - s_step
    s_mid = s_start + ds_mid[0] + ds_mid[1] * v_start
    speed = jnp.concatenate([v0[None], jnp.stack([v_mid, v_end], axis=1).reshape(-1)[: n - 1]])
    dist = jnp.concatenate([jnp.zeros_like(v0)[None], jnp.stack([s_mid, s_end], axis=1).reshape(-1)[: n - 1]])
    return speed, dist


def integrate_batch(
    model: DragModel,
    params: Mapping[str, Array],
    batch: RunBatch,
    v0_mps: Array | None = None,
    integrator: config.IntegratorConfig = config.DEFAULT_INTEGRATOR,
) -> tuple[Array, Array]:
    """:func:`integrate_run` vmapped over the R runs of a padded batch.

    Parameters whose value has shape [R] are per run (hierarchical models, per-run effects);
    scalars are shared by all runs.  Returns [R, N] speed and distance.
    """
    r = batch.n_runs
    p = model.complete(params)
    axes = {k: (0 if jnp.ndim(v) == 1 and jnp.shape(v)[0] == r else None) for k, v in p.items()}
    v0 = batch.speed_mps[:, 0] if v0_mps is None else jnp.broadcast_to(jnp.asarray(v0_mps, float), (r,))

    schedule = _schedule_of(batch, integrator)
    if _solves_in_parallel(model, integrator):
        # every run's stage coefficients first, held once for the whole batch (_hold)
        stages = jax.vmap(lambda pp, run, sched: _affine_stages(model, pp, run, sched),
                          in_axes=(axes, 0, 0))(p, batch, schedule)
        stages = _hold(stages)
        n = batch.time_s.shape[-1]
        return jax.vmap(lambda st, v, sched: _compose_affine(st, v, sched, n))(stages, v0, schedule)

    def one(pp, run, v0r, sched):
        return integrate_run(model, pp, run, v0r, integrator, sched)

    return jax.vmap(one, in_axes=(axes, 0, 0, 0))(p, batch, v0, schedule)


def reversion_rate(
    model: DragModel,
    params: Mapping[str, Array],
    batch: RunBatch,
    speed_mps: Array,
) -> Array:
    """[R, N] kappa = -d(dv/dt)/dv of eq. 5.4 at each sample, along the speed trace
    ``speed_mps`` (the model's own, [R, N]) with the logged inputs held: the rate at which a
    speed error decays through the model's speed-dependent forces (the tyres' B_D, the
    driveline, and the aerodynamic force when the relative air is computed from the speed;
    with a measured airspeed the aerodynamic force follows the reading instead).  The distance
    is the trapezoid of the speed.  Zero on padding.  Parameters with an [R] value are per run,
    as in :func:`integrate_batch`."""
    r = batch.n_runs
    p = model.complete(params)
    axes = {k: (0 if jnp.ndim(v) == 1 and jnp.shape(v)[0] == r else None) for k, v in p.items()}

    def one(pp, run, v):
        u, _ = _with_model_channel(model, pp, run, jnp.asarray(_inputs(run)), None)
        s = jnp.concatenate([jnp.zeros_like(v[:1]), jnp.cumsum(0.5 * (v[1:] + v[:-1]) * jnp.diff(run.time_s))])

        def accel(vk, sk, tk, uk):
            c = _conditions(model, pp, run, jnp.maximum(vk, 0.0), sk, tk, uk)
            return model.acceleration_mps2(pp, c, run.effective_mass_kg)

        slope = jax.vmap(jax.grad(accel))(v, s, run.time_s, u)
        return jnp.where(run.mask & (v > 0.0), -slope, 0.0)

    return jax.vmap(one, in_axes=(axes, 0, 0))(p, batch, jnp.asarray(speed_mps))


def quadratic_coastdown_time(v_mps, v0_mps, a_n, b_n_per_mps, c_n_per_mps2, effective_mass_kg):
    """Time to coast from v0 to v with F = a + b v + c v^2 and no wind (appendix D).

    Valid for 4ac > b^2: t(v) = (2 M_e / k)[atan((2 c v0 + b)/k) - atan((2 c v + b)/k)],
    k = sqrt(4 a c - b^2).
    """
    k = jnp.sqrt(4.0 * a_n * c_n_per_mps2 - b_n_per_mps**2)
    return (2.0 * effective_mass_kg / k) * (
        jnp.arctan((2.0 * c_n_per_mps2 * v0_mps + b_n_per_mps) / k)
        - jnp.arctan((2.0 * c_n_per_mps2 * v_mps + b_n_per_mps) / k)
    )


def quadratic_coastdown_speed(t_s, v0_mps, a_n, b_n_per_mps, c_n_per_mps2, effective_mass_kg):
    """Speed after coasting for t from v0 with F = a + b v + c v^2 (inverse of appendix D)."""
    k = jnp.sqrt(4.0 * a_n * c_n_per_mps2 - b_n_per_mps**2)
    phase = jnp.arctan((2.0 * c_n_per_mps2 * v0_mps + b_n_per_mps) / k) - k * t_s / (2.0 * effective_mass_kg)
    return (k * jnp.tan(phase) - b_n_per_mps) / (2.0 * c_n_per_mps2)


def make_run(
    time_s,
    speed_mps,
    *,
    airspeed_mps=None,
    yaw_rad=None,
    driveline_force_n=None,
    air_density_kgpm3=None,
    temperature_k=None,
    track_grade_rad=None,
    direction=1.0,
    start_position_m=0.0,
    mass_kg,
    effective_mass_kg,
    frontal_area_m2,
) -> RunBatch:
    """Build a single-run :class:`RunBatch` from arrays, filling absent channels with
    still air at reference conditions.

    The vehicle is required: ``mass_kg`` M (kg), ``effective_mass_kg`` M_e, the mass plus the
    rotating inertia (kg, eq. 2.5) and ``frontal_area_m2`` A (m^2)."""
    from .atmosphere import REFERENCE_AIR_DENSITY_KGPM3

    # built in NumPy and moved to the device once per field: eager jnp operations would compile
    # a small program for every run length
    t = np.asarray(time_s, float)
    v = np.asarray(speed_mps, float)
    full = lambda x, d: np.broadcast_to(np.asarray(d if x is None else x, float), t.shape)  # noqa: E731
    host = RunBatch(
        time_s=t,
        speed_mps=v,
        airspeed_mps=full(airspeed_mps, v if airspeed_mps is None else airspeed_mps),
        yaw_rad=full(yaw_rad, 0.0),
        driveline_force_n=full(driveline_force_n, 0.0),
        air_density_kgpm3=full(air_density_kgpm3, REFERENCE_AIR_DENSITY_KGPM3),
        temperature_k=full(temperature_k, config.REFERENCE_TEMPERATURE_K),
        track_grade_rad=full(track_grade_rad, 0.0),
        mask=np.ones(t.shape, bool),
        direction=np.asarray(direction, float),
        start_position_m=np.asarray(start_position_m, float),
        mass_kg=np.asarray(mass_kg, float),
        effective_mass_kg=np.asarray(effective_mass_kg, float),
        frontal_area_m2=np.asarray(frontal_area_m2, float),
    )
    return RunBatch(*(jnp.asarray(x) for x in host))


def bucket_length(n: int, sizes_per_octave: int) -> int:
    """The smallest length >= ``n`` of the form ``m * 2**k`` with ``sizes_per_octave`` <= m <
    2 ``sizes_per_octave`` (``sizes_per_octave`` a power of two; 0 or ``n`` below it: ``n``
    itself): lengths padded to it exceed ``n`` by less than 1/``sizes_per_octave``."""
    n = int(n)
    if sizes_per_octave <= 0 or n <= sizes_per_octave:
        return n
    step = 2 ** max(n.bit_length() - 1 - (int(sizes_per_octave).bit_length() - 1), 0)
    return -(-n // step) * step


def stack_runs(runs: list[RunBatch], length: int | None = None, sizes_per_octave: int = 0) -> RunBatch:
    """Pad single runs to a common length (repeating the last sample; ``mask`` False there)
    and stack them.  ``length``: pad to at least this many samples (campaigns of one padded
    shape share their compiled fits, :mod:`bayes_roadload.inference.laplace`); that length is
    then rounded up by :func:`bucket_length` with ``sizes_per_octave`` (0: not rounded)."""
    n = bucket_length(max([int(r.time_s.shape[0]) for r in runs] + [int(length or 0)]), sizes_per_octave)
    # padded on the host: one device transfer per field, no per-shape programs
    padded = [RunBatch(*(_pad_samples(f, n, 1) for f in r)) for r in runs]
    return RunBatch(*(jnp.asarray(np.stack(fields)) for fields in zip(*padded)))


def _pad_samples(x, length: int, per_sample_ndim: int) -> np.ndarray:
    """One field of a run or batch padded on the host along its last (sample) axis to
    ``length``: the last sample repeated, False for a mask; a per-run constant (fewer than
    ``per_sample_ndim`` dimensions) is returned as it is."""
    x = np.asarray(x)
    if x.ndim < per_sample_ndim or x.shape[-1] >= length:
        return x
    extra = length - x.shape[-1]
    if x.dtype == bool:
        return np.concatenate([x, np.zeros(x.shape[:-1] + (extra,), bool)], axis=-1)
    return np.concatenate([x, np.repeat(x[..., -1:], extra, axis=-1)], axis=-1)


def pad_batch(batch: RunBatch, length: int) -> RunBatch:
    """``batch`` ([R, N] or one run's [N]) padded along its samples to ``length`` as
    :func:`stack_runs` pads (the last sample repeated, ``mask`` False there): padded samples
    add nothing to a residual or a likelihood.  Per-run constants are kept; a batch at least
    ``length`` long is returned as it is."""
    if length <= int(batch.time_s.shape[-1]):
        return batch
    return RunBatch(*(jnp.asarray(_pad_samples(x, length, np.ndim(batch.time_s))) for x in batch))


def integrate_batch_forward_sensitivity(
    model: DragModel,
    fixed: Mapping[str, Array],
    free: Mapping[str, Array],
    batch: RunBatch,
    v0_mps: Array,
    integrator: config.IntegratorConfig = config.DEFAULT_INTEGRATOR,
) -> Array:
    """[R, N] speeds like :func:`integrate_batch`, differentiated by forward sensitivities.

    Reverse-mode autodiff through the RK4 scan stores every step and runs a second scan of
    about ten times the forward cost.  Each run depends only on the few free parameters and
    its own initial speed, so the Jacobian of its speed trace with respect to them (k
    tangents, k = number of free parameters + 1) is computed in forward mode alongside the
    solution and contracted with the incoming cotangent (a ``jax.custom_vjp``): about 3x the
    forward cost on a campaign of 36 runs.  Values are identical to :func:`integrate_batch`.

    Parameters
    ----------
    fixed : parameter values not differentiated (closed over).
    free : parameter values to differentiate, each a scalar (shared) or [R] (per run).
    batch : the runs (not differentiated; closed over).
    v0_mps : [R] initial speeds (differentiated).

    Notes
    -----
    Supports reverse mode (``jax.grad``), which is what NUTS uses.  Forward mode over it is
    not defined (a ``custom_vjp``); use :func:`integrate_batch` for Hessians.
    """
    if _solves_in_parallel(model, integrator):
        # no sequential loop to differentiate: reverse mode through the parallel solution is cheap
        return integrate_batch(model, dict(fixed, **free), batch, v0_mps, integrator)[0]
    names = tuple(free)
    r = batch.n_runs
    base = model.complete(fixed)

    schedule = _schedule_of(batch, integrator)

    def speeds_of_x(x, run, sched):
        p = dict(base)
        p.update({n: x[i] for i, n in enumerate(names)})
        return integrate_run(model, p, run, x[-1], integrator, sched)[0]

    @jax.custom_vjp
    def speeds(x):
        return jax.vmap(speeds_of_x)(x, batch, schedule)

    def speeds_fwd(x):
        def one(xr, run, sched):
            def f(z):
                y = speeds_of_x(z, run, sched)
                return y, y

            return jax.jacfwd(f, has_aux=True)(xr)

        jac, y = jax.vmap(one)(x, batch, schedule)
        return y, jac

    def speeds_bwd(jac, ct):
        return (jnp.einsum("rn,rnk->rk", ct, jac),)

    speeds.defvjp(speeds_fwd, speeds_bwd)
    cols = [jnp.broadcast_to(jnp.asarray(free[n], float), (r,)) for n in names]
    x = jnp.stack(cols + [jnp.broadcast_to(jnp.asarray(v0_mps, float), (r,))], axis=1)
    return speeds(x)
