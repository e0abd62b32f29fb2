"""Speed-gate interval times: the time (and distance) to coast between two speeds.

From the coastdown equation M_e dv/dt = -F(v) (eq. 5.4) the time to fall from v_1 to v_2 < v_1
is

    t = integral_{v_2}^{v_1} M_e / F(v) dv = integral_{v_2}^{v_1} dv / (-a(v)),

and the distance covered on the way ``integral v / (-a(v)) dv`` (the speed-trap model of seed
002 and the closed form of appendix D for a quadratic F, :func:`~bayes_roadload.physics.
integrate.quadratic_coastdown_time`).  Both are evaluated by Gauss-Legendre quadrature over the
speed with a fixed number of nodes (``INTERVAL_QUADRATURE_NODES``): 1/F is smooth and
far from zero over a speed band, so 8 nodes are exact to ~1e-13 relative on a 5 km/h band of a
quadratic road load (tested against appendix D), pure JAX and differentiable in every
parameter.

The deceleration comes from :meth:`~bayes_roadload.physics.model.DragModel.acceleration_mps2`
with the relative air from the model's air description at the node speed (still air, or a
wind given as parameters; measured anemometer channels do not exist in a speed-gate record),
so any term that depends on the speed, the air, the direction (a constant grade) or dv/dt (pitch)
works.  Terms that depend on the position along the track (a gradient profile) cannot be
evaluated in the speed domain and are refused.

Nothing here imports numpyro.
"""

from __future__ import annotations

from typing import Mapping, NamedTuple

import jax.numpy as jnp
import numpy as np

from .model import DragModel, MeasuredAir
from .terms import Conditions

INTERVAL_QUADRATURE_NODES = 8
"""Gauss-Legendre nodes per speed band for t = integral M_e / F(v) dv (exact to ~1e-13 relative
on a 5 km/h band of a quadratic road load, tested against appendix D)."""

Array = jnp.ndarray

POSITION_TERMS = ("gradient_profile",)
"""Terms that need the position along the track, which a speed-gate record does not give."""


class IntervalBands(NamedTuple):
    """Speed bands of interval-time records, flattened over runs ([B] arrays, SI units).

    ``speed_start_mps > speed_end_mps`` (a coastdown decelerates); the per-run constants
    (``direction``, ``air_density_kgpm3``, ``temperature_k``, ``mass_kg``,
    ``effective_mass_kg``, ``frontal_area_m2``) are repeated on each band of the run.
    """

    speed_start_mps: Array
    speed_end_mps: Array
    direction: Array
    air_density_kgpm3: Array
    temperature_k: Array
    mass_kg: Array
    effective_mass_kg: Array
    frontal_area_m2: Array


def gauss_legendre(n: int = INTERVAL_QUADRATURE_NODES) -> tuple[np.ndarray, np.ndarray]:
    """Nodes on [-1, 1] and weights of the n-point Gauss-Legendre rule (numpy constants)."""
    return np.polynomial.legendre.leggauss(int(n))


def check_speed_domain(model: DragModel) -> None:
    """Refuse models that cannot be evaluated from the speed alone."""
    bad = [t for t in model.term_names if t in POSITION_TERMS]
    if bad:
        raise ValueError(f"drag terms {bad} depend on the position along the track, which interval "
                         "times do not record; use the constant 'gradient' term instead")
    if isinstance(model.air, MeasuredAir):
        raise ValueError("interval times carry no anemometer channels: the model's air must be "
                         "'still' or 'wind', not 'measured'")


def _node_conditions(bands: IntervalBands, v: Array, model: DragModel, p: Mapping[str, Array]) -> Conditions:
    """Conditions at the quadrature speeds ``v`` [B, n] of every band."""
    col = lambda x: jnp.asarray(x, float)[:, None] + jnp.zeros_like(v)  # noqa: E731
    airspeed, yaw = model.air.relative_air(p, v, v, jnp.zeros_like(v))
    z = jnp.zeros_like(v)
    return Conditions(
        speed_mps=v, airspeed_mps=airspeed + z, yaw_rad=yaw + z, driveline_force_n=z, position_m=z,
        distance_m=z, time_s=z, accel_mps2=z, direction=col(bands.direction),
        air_density_kgpm3=col(bands.air_density_kgpm3), temperature_k=col(bands.temperature_k),
        mass_kg=col(bands.mass_kg), frontal_area_m2=col(bands.frontal_area_m2))


def interval_times(model: DragModel, params: Mapping[str, Array], bands: IntervalBands,
                   n_nodes: int = INTERVAL_QUADRATURE_NODES) -> dict[str, Array]:
    """Time, distance and force sensitivity of every band (Gauss-Legendre in the speed).

    Parameters
    ----------
    model : the drag model (still air or a wind given as parameters).
    params : parameter values, scalars or [B] arrays (one value per band, e.g. a per-run
        head wind repeated on the run's bands); missing ones take the model defaults.
    bands : the speed bands (:class:`IntervalBands`).
    n_nodes : quadrature nodes per band.

    Returns
    -------
    dict of [B] arrays
        ``time_s``: the time to coast from ``speed_start_mps`` to ``speed_end_mps``;
        ``distance_m``: the distance covered meanwhile;
        ``dtime_dforce_s_per_n``: d time / d(a constant extra resisting force), negative
        (integral of -1 / (M_e a^2) dv): how a run-level force offset moves the band's time.
    """
    x, w = gauss_legendre(n_nodes)
    v1 = jnp.asarray(bands.speed_start_mps, float)
    v2 = jnp.asarray(bands.speed_end_mps, float)
    half = 0.5 * (v1 - v2)
    v = 0.5 * (v1 + v2)[:, None] + half[:, None] * jnp.asarray(x)[None, :]
    p = {k: (jnp.asarray(val)[:, None] if jnp.ndim(val) == 1 else jnp.asarray(val))
         for k, val in model.complete(params).items()}
    me = jnp.asarray(bands.effective_mass_kg, float)[:, None]
    decel = -model.acceleration_mps2(p, _node_conditions(bands, v, model, p), me)
    weights = half[:, None] * jnp.asarray(w)[None, :]
    return {
        "time_s": jnp.sum(weights / decel, axis=1),
        "distance_m": jnp.sum(weights * v / decel, axis=1),
        "dtime_dforce_s_per_n": -jnp.sum(weights / (me * decel**2), axis=1),
    }


def band_time_loglik(residual_s: Array, mask: Array, duration_s: Array, sensitivity_s: Array,
                     sigma_gate_s: Array, band_noise: Array, effect_sd: Array) -> Array:
    """[R] Gaussian log-likelihood of each run's band-time residuals (observed - modelled).

    The covariance of a run's K band times is

        Sigma = sigma_gate^2 T + band_noise^2 diag(duration) + effect_sd^2 s s^T,

    where T is tridiagonal (2 on the diagonal, -1 beside it): the band time is the difference
    of two gate-crossing times, each with an independent timing error, so neighbouring bands
    share one crossing with opposite signs; ``band_noise^2 x duration`` is independent scatter
    growing with the band's duration (force fluctuations within the run); and ``s`` [K] is the
    bands' sensitivity to one run-level effect (a constant deceleration offset of sd
    ``effect_sd``), integrated out (Sherman-Morrison over the tridiagonal part).  The
    tridiagonal part is factored by a pivot recursion in plain JAX (K is small, the loop is
    unrolled; no LAPACK call).

    Parameters
    ----------
    residual_s, mask, duration_s, sensitivity_s : [R, K] (padded bands: mask False).
    sigma_gate_s, band_noise, effect_sd : scalars.
    """
    m = jnp.asarray(mask, bool)
    diag = jnp.where(m, 2.0 * sigma_gate_s**2 + band_noise**2 * duration_s, 1.0)
    both = m[:, 1:] & m[:, :-1]
    off = jnp.where(both, -sigma_gate_s**2, 0.0)                  # [R, K-1]
    r = jnp.where(m, residual_s, 0.0)
    s = jnp.where(m, sensitivity_s, 0.0)
    k = diag.shape[1]
    # forward elimination (Thomas) for both right-hand sides, with the pivots for the log det
    pivots, fr, fs = [], [], []
    for i in range(k):
        if i == 0:
            piv, yr, ys = diag[:, 0], r[:, 0], s[:, 0]
        else:
            factor = off[:, i - 1] / pivots[-1]
            piv = diag[:, i] - factor * off[:, i - 1]
            yr = r[:, i] - factor * fr[-1]
            ys = s[:, i] - factor * fs[-1]
        pivots.append(piv)
        fr.append(yr)
        fs.append(ys)
    # back substitution: x = A^-1 r, z = A^-1 s
    xr, xs = [None] * k, [None] * k
    for i in reversed(range(k)):
        nr, ns = fr[i], fs[i]
        if i < k - 1:
            nr = nr - off[:, i] * xr[i + 1]
            ns = ns - off[:, i] * xs[i + 1]
        xr[i], xs[i] = nr / pivots[i], ns / pivots[i]
    piv = jnp.stack(pivots, axis=1)
    x_r, x_s = jnp.stack(xr, axis=1), jnp.stack(xs, axis=1)
    quad = jnp.sum(r * x_r, axis=1)
    sr = jnp.sum(s * x_r, axis=1)
    ss = jnp.sum(s * x_s, axis=1)
    v2 = effect_sd**2
    denom = 1.0 + v2 * ss
    quad = quad - v2 * sr**2 / denom
    logdet = jnp.sum(jnp.log(piv), axis=1) + jnp.log(denom)
    n = jnp.sum(m, axis=1)
    return -0.5 * (quad + logdet + n * jnp.log(2.0 * jnp.pi))


def band_time_covariance(mask, duration_s, sensitivity_s, sigma_gate_s, band_noise, effect_sd):
    """[R, K, K] the covariance of :func:`band_time_loglik` (dense, for checks and for drawing
    replicated band times; padded bands get an identity block)."""
    m = jnp.asarray(mask, bool)
    k = m.shape[1]
    eye = jnp.eye(k)
    tri = 2.0 * eye - jnp.eye(k, k=1) - jnp.eye(k, k=-1)
    mm = m[:, :, None] & m[:, None, :]
    s = jnp.where(m, sensitivity_s, 0.0)
    cov = (sigma_gate_s**2 * tri[None] + band_noise**2 * duration_s[:, :, None] * eye[None]
           + effect_sd**2 * s[:, :, None] * s[:, None, :])
    return jnp.where(mm, cov, eye[None])
