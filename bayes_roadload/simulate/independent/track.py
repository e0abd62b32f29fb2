"""The track's elevation: a smooth profile (mean grade plus undulations), sampled at survey
stations every 10 m to the millimetre, and the cubic spline through those stations that the
simulator drives on."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline


@dataclass(frozen=True)
class Track:
    """Surveyed elevation ``elevation_m`` at ``stations_m``; ``grade(x)`` = dz/dx of the
    spline through them (level when every elevation is 0)."""

    stations_m: np.ndarray
    elevation_m: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "_spline", CubicSpline(self.stations_m, self.elevation_m))
        object.__setattr__(self, "_level", not np.any(self.elevation_m))

    def grade(self, x):
        """dz/dx (-) at track position x (m)."""
        if self._level:
            return np.zeros_like(np.asarray(x, float))
        return self._spline(x, 1)


def level_track(start_m: float, end_m: float) -> Track:
    s = np.arange(start_m, end_m + 10.0, 10.0)
    return Track(s, np.zeros_like(s))


def surveyed_track(rng: np.random.Generator, start_m: float, end_m: float, *, mean_grade: float,
                   rms_undulation_grade: float) -> Track:
    """A track of mean grade ``mean_grade`` with undulations of wavelengths 50-400 m whose
    grade has RMS ``rms_undulation_grade``; elevations rounded to 1 mm (a level survey)."""
    s = np.arange(start_m, end_m + 10.0, 10.0)
    n = 6
    wavelength = rng.uniform(50.0, 400.0, n)
    k = 2 * np.pi / wavelength
    raw = rng.normal(size=n)
    # grade amplitude of mode j is h_j k_j; RMS grade = sqrt(sum (h_j k_j)^2 / 2)
    grade_amp = raw / np.sqrt(np.sum(raw**2) / 2.0) * rms_undulation_grade
    h = grade_amp / k
    phase = rng.uniform(0, 2 * np.pi, n)
    z = mean_grade * (s - start_m) + np.sum(h * np.sin(np.multiply.outer(s, k) + phase), axis=1)
    return Track(s, np.round(z, 3))
