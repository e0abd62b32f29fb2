"""The track's elevation: a mean grade plus undulations (sinusoids of 50-400 m wavelength).
The vehicle drives on this smooth profile; a level survey of it (stations every 10 m, rounded to
the millimetre) is what a test report would hold, and is kept with the truth."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Track:
    """Elevation ``z(x) = mean_grade (x - start_m) + sum_j h_j sin(k_j x + phi_j)`` (m)."""

    start_m: float = 0.0
    end_m: float = 1000.0
    mean_grade: float = 0.0
    heights_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    wavenumbers_per_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    phases_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def elevation(self, x):
        """z (m) at track position x (m)."""
        x = np.asarray(x, float)
        waves = np.sin(np.multiply.outer(x, self.wavenumbers_per_m) + self.phases_rad) @ self.heights_m
        return self.mean_grade * (x - self.start_m) + waves

    def grade(self, x):
        """dz/dx (-) at track position x (m)."""
        x = np.asarray(x, float)
        hk = self.heights_m * self.wavenumbers_per_m
        return self.mean_grade + np.cos(np.multiply.outer(x, self.wavenumbers_per_m) + self.phases_rad) @ hk

    def grade_at(self, x: float) -> float:
        """:meth:`grade` at one position (for the integrator)."""
        if self.heights_m.size == 0:
            return self.mean_grade
        return self.mean_grade + float(np.cos(self.wavenumbers_per_m * x + self.phases_rad)
                                       @ (self.heights_m * self.wavenumbers_per_m))

    def survey(self, spacing_m: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
        """Stations (m) and their elevations rounded to 1 mm: a level survey of the track."""
        s = np.arange(self.start_m, self.end_m + spacing_m, spacing_m)
        return s, np.round(self.elevation(s), 3)


def surveyed_track(rng: np.random.Generator, start_m: float, end_m: float, *, mean_grade: float,
                   rms_undulation_grade: float, modes: int = 6) -> Track:
    """A track of mean grade ``mean_grade`` with undulations of wavelengths 50-400 m whose
    grade has RMS ``rms_undulation_grade`` (no undulation when it is 0)."""
    if rms_undulation_grade <= 0.0:
        return Track(start_m, end_m, mean_grade)
    k = 2 * np.pi / rng.uniform(50.0, 400.0, modes)
    raw = rng.normal(size=modes)
    # grade amplitude of mode j is h_j k_j; RMS grade = sqrt(sum (h_j k_j)^2 / 2)
    grade_amp = raw / np.sqrt(np.sum(raw**2) / 2.0) * rms_undulation_grade
    return Track(start_m, end_m, mean_grade, grade_amp / k, k, rng.uniform(0, 2 * np.pi, modes))
