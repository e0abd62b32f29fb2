"""The wind along the track: a mean wind with a direction, a smooth spatial variation
(sheltering by tree lines or buildings and a linear trend), and turbulence synthesised as
random Fourier modes with a von Karman energy spectrum, frozen in the air and carried by the
mean wind (Taylor's hypothesis).

Track frame: x along the track axis (m), y across it; a wind vector ``(wx, wy)`` is the air's
velocity over the ground (m/s).  The track lies on y = 0.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import math

import numpy as np


@dataclass(frozen=True)
class Shelter:
    """Smooth sheltered stretches: the mean wind is multiplied by
    ``(1 + trend (x - centre) / span) (1 - sum_j depth_j B_j(x))`` with ``B_j`` a plateau of
    logistic edges (width ``edge_m``) between ``start_j`` and ``end_j``."""

    starts_m: tuple[float, ...] = ()
    ends_m: tuple[float, ...] = ()
    depths: tuple[float, ...] = ()
    edge_m: float = 30.0
    trend: float = 0.0
    centre_m: float = 0.0
    span_m: float = 1000.0

    def factor(self, x):
        x = np.asarray(x, float)
        out = 1.0 + self.trend * (x - self.centre_m) / self.span_m
        cover = np.zeros_like(x)
        for a, b, d in zip(self.starts_m, self.ends_m, self.depths):
            plateau = 1.0 / (1.0 + np.exp(-(x - a) / self.edge_m)) - 1.0 / (1.0 + np.exp(-(x - b) / self.edge_m))
            cover = cover + d * plateau
        return out * (1.0 - np.clip(cover, 0.0, 0.9))

    def factor_at(self, x: float) -> float:
        """:meth:`factor` at one position (scalar arithmetic, for the integrator)."""
        out = 1.0 + self.trend * (x - self.centre_m) / self.span_m
        cover = 0.0
        for a, b, d in zip(self.starts_m, self.ends_m, self.depths):
            # logistic(z) = (1 + tanh(z / 2)) / 2, free of overflow
            cover += d * 0.5 * (math.tanh(0.5 * (x - a) / self.edge_m) - math.tanh(0.5 * (x - b) / self.edge_m))
        return out * (1.0 - min(max(cover, 0.0), 0.9))


@dataclass(frozen=True)
class Turbulence:
    """Isotropic 2-D random Fourier modes: ``u(r) = sum_n a_n e_n cos(k_n . r + phi_n)`` with
    ``e_n`` perpendicular to ``k_n`` (divergence free) and ``a_n^2`` proportional to the von
    Karman energy spectrum ``E(k) ~ (k L)^4 / (1 + (k L)^2)^(17/6)`` times the band width, scaled
    so each horizontal component has standard deviation ``sigma``."""

    kx: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ky: np.ndarray = field(default_factory=lambda: np.zeros(0))
    amp: np.ndarray = field(default_factory=lambda: np.zeros(0))
    phase: np.ndarray = field(default_factory=lambda: np.zeros(0))
    sigma_mps: float = 0.0
    length_scale_m: float = 30.0

    def velocity(self, x, y):
        """Turbulent velocity (m/s) at points ``(x, y)`` of the frozen field."""
        x = np.asarray(x, float)
        if self.amp.size == 0:
            return np.zeros_like(x), np.zeros_like(x)
        arg = np.multiply.outer(x, self.kx) + np.multiply.outer(np.asarray(y, float), self.ky) + self.phase
        c = np.cos(arg) * self.amp
        kmag = np.hypot(self.kx, self.ky)
        # unit vector perpendicular to k: (-ky, kx) / |k|
        return c @ (-self.ky / kmag), c @ (self.kx / kmag)

    def velocity_at(self, x: float, y: float) -> tuple[float, float]:
        """:meth:`velocity` at one point (for the integrator)."""
        if self.amp.size == 0:
            return 0.0, 0.0
        c = np.cos(self.kx * x + self.ky * y + self.phase)
        ex, ey = self._directions
        return float(c @ ex), float(c @ ey)

    @property
    def _directions(self):
        cached = self.__dict__.get("_dirs")
        if cached is None:
            kmag = np.hypot(self.kx, self.ky)
            cached = (self.amp * -self.ky / kmag, self.amp * self.kx / kmag)
            object.__setattr__(self, "_dirs", cached)
        return cached


def von_karman_turbulence(rng: np.random.Generator, sigma_mps: float, length_scale_m: float, *,
                          n_modes: int = 64, smallest_m: float = 4.0) -> Turbulence:
    """Draw a turbulence field (see :class:`Turbulence`); wavelengths from 20 L down to
    ``smallest_m`` (smaller eddies are averaged out over the vehicle's length)."""
    if sigma_mps <= 0.0:
        return Turbulence()
    k_lo, k_hi = 2 * np.pi / (20.0 * length_scale_m), 2 * np.pi / smallest_m
    edges = np.geomspace(k_lo, k_hi, n_modes + 1)
    k = np.sqrt(edges[:-1] * edges[1:])
    dk = np.diff(edges)
    kl = k * length_scale_m
    energy = kl**4 / (1.0 + kl**2) ** (17.0 / 6.0) * dk
    # var(u_x) + var(u_y) = sum a^2 / 2  (cos^2 averages 1/2); each component sigma^2
    amp = np.sqrt(energy / energy.sum() * 4.0 * sigma_mps**2)
    theta = rng.uniform(0.0, 2 * np.pi, n_modes)
    return Turbulence(kx=k * np.cos(theta), ky=k * np.sin(theta), amp=amp,
                      phase=rng.uniform(0.0, 2 * np.pi, n_modes), sigma_mps=sigma_mps,
                      length_scale_m=length_scale_m)


@dataclass(frozen=True)
class WindField:
    """Mean wind ``mean_speed_mps`` blowing towards ``direction_rad`` (0 = along +x), scaled
    along the track by :class:`Shelter`, plus :class:`Turbulence` advected by the mean wind."""

    mean_speed_mps: float = 0.0
    direction_rad: float = 0.0
    shelter: Shelter = field(default_factory=Shelter)
    turbulence: Turbulence = field(default_factory=Turbulence)

    def velocity(self, x, t):
        """Wind over the ground ``(wx, wy)`` (m/s) at track position ``x`` (m), time ``t`` (s)."""
        x = np.asarray(x, float)
        ux, uy = self.mean_speed_mps * np.cos(self.direction_rad), self.mean_speed_mps * np.sin(self.direction_rad)
        s = self.shelter.factor(x)
        tx, ty = self.turbulence.velocity(x - ux * t, 0.0 * x - uy * t)
        return s * ux + s * tx, s * uy + s * ty

    def velocity_at(self, x: float, t: float) -> tuple[float, float]:
        """:meth:`velocity` at one position and time (scalar, for the integrator)."""
        ux, uy = self.mean_speed_mps * math.cos(self.direction_rad), self.mean_speed_mps * math.sin(self.direction_rad)
        s = self.shelter.factor_at(x)
        tx, ty = self.turbulence.velocity_at(x - ux * t, -uy * t)
        return s * (ux + tx), s * (uy + ty)

    def with_mean(self, speed_mps: float, direction_rad: float) -> "WindField":
        return WindField(speed_mps, direction_rad, self.shelter, self.turbulence)


def random_shelter(rng: np.random.Generator, track_start_m: float, track_end_m: float, *,
                   max_depth: float, max_trend: float) -> Shelter:
    """1-3 sheltered stretches of 80-400 m with depths up to ``max_depth`` and a linear trend
    of up to ``max_trend`` over the track."""
    n = int(rng.integers(1, 4))
    span = track_end_m - track_start_m
    starts = rng.uniform(track_start_m, track_end_m - 80.0, n)
    ends = starts + rng.uniform(80.0, 400.0, n)
    return Shelter(tuple(starts), tuple(ends), tuple(rng.uniform(0.0, max_depth, n)),
                   edge_m=float(rng.uniform(15.0, 50.0)), trend=float(rng.uniform(-max_trend, max_trend)),
                   centre_m=0.5 * (track_start_m + track_end_m), span_m=span)
