"""Ambient wind for the coastdown simulator: Dryden turbulence frozen along the track.

Thesis section 6.2.2 and table 6.4: the in-line (along-track) and cross-track components of the
wind are Dryden turbulence with scale length L = 30 m each and standard deviation
``sigma = turbulence ratio x mean wind`` (ratio 0.4), on top of a mean wind that may vary
linearly along the track (figure 46, parameter beta).

The thesis generated the turbulence in time with Dryden filters driven by band-limited white
noise (ACSL).  Here the turbulence is *frozen* (Taylor's hypothesis): each component is a random
function of the position x along the track, synthesised by FFT on a fine spatial grid with the
exact Dryden spatial spectra, and the vehicle samples it at its current position.  A vehicle at
speed V then sees the classic temporal Dryden spectra (``H_u``, ``H_v`` of ``ROADLOAD_MODEL.md``
section 4) with time scale L / V, and both directions of a track see a consistent field.  The thesis' band limit of the
filter input noise (DC-1 Hz, table 6.4) is a property of what the vehicle meets, in time; the
simulator applies it (:class:`~bayes_roadload.simulate.SimulationSettings.wind_bandwidth_hz`).

Ground-frame convention (used by :mod:`bayes_roadload.simulate.campaign`): the track axis is +x;
a run has direction d = +1 or -1; the along-track wind component ``w_a`` is positive when the
air moves towards -x, so the head wind of a run is ``v_h = d w_a`` (a positive mean ``w_a`` is a
head wind for the + runs and a tail wind for the - runs); the cross-track component ``w_c`` is
the cross wind ``v_x`` (its sign does not matter to the drag).

Spectra are one-sided in the spatial angular frequency Omega >= 0 (rad/m) and integrate to
sigma^2:

* longitudinal (in-line): ``Phi_u(Omega) = sigma^2 (2L/pi) / (1 + (L Omega)^2)``
* lateral (cross): ``Phi_v(Omega) = sigma^2 (L/pi) (1 + 3 (L Omega)^2) / (1 + (L Omega)^2)^2``
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from .. import thesis

Component = Literal["longitudinal", "lateral"]

# Defaults of the wind model (thesis table 6.4).
SCALE_LENGTH_M = thesis.THESIS_WIND["scale_length_m"]
"""Dryden scale length of both components, L_wh = L_wx = 30 m (table 6.4)."""
TURBULENCE_RATIO = thesis.THESIS_WIND["turbulence_ratio"]
"""sigma / mean wind (table 6.4)."""
WIND_GRID_STEP_M = 0.25
"""Spatial step of the synthesised field (m): 4 points per metre, far finer than L."""


# --------------------------------------------------------------------------- spectra

def _check_component(component: str) -> None:
    if component not in ("longitudinal", "lateral"):
        raise ValueError(f"component must be 'longitudinal' or 'lateral', not {component!r}")


def dryden_psd(wavenumber_radpm, sigma_mps: float, scale_length_m: float,
               component: Component = "longitudinal"):
    """One-sided Dryden spatial power spectral density.

    Parameters
    ----------
    wavenumber_radpm : array_like
        Spatial angular frequency Omega >= 0 (rad/m).
    sigma_mps : float
        Standard deviation of the turbulence component (m/s).
    scale_length_m : float
        Dryden scale length L (m).
    component : {"longitudinal", "lateral"}
        "longitudinal" for the in-line (head) component, "lateral" for the cross component.

    Returns
    -------
    ndarray
        Phi(Omega) in (m/s)^2 / (rad/m); integrates to sigma^2 over [0, inf).
    """
    _check_component(component)
    u = scale_length_m * np.asarray(wavenumber_radpm, dtype=float)
    if component == "longitudinal":
        return sigma_mps**2 * (2.0 * scale_length_m / math.pi) / (1.0 + u**2)
    return sigma_mps**2 * (scale_length_m / math.pi) * (1.0 + 3.0 * u**2) / (1.0 + u**2) ** 2


def dryden_psd_longitudinal(wavenumber_radpm, sigma_mps: float, scale_length_m: float = SCALE_LENGTH_M):
    """Phi_u(Omega) = sigma^2 (2L/pi) / (1 + (L Omega)^2), see :func:`dryden_psd`."""
    return dryden_psd(wavenumber_radpm, sigma_mps, scale_length_m, "longitudinal")


def dryden_psd_lateral(wavenumber_radpm, sigma_mps: float, scale_length_m: float = SCALE_LENGTH_M):
    """Phi_v(Omega) = sigma^2 (L/pi)(1 + 3 (L Omega)^2) / (1 + (L Omega)^2)^2, see :func:`dryden_psd`."""
    return dryden_psd(wavenumber_radpm, sigma_mps, scale_length_m, "lateral")


def dryden_cumulative_variance(wavenumber_radpm, sigma_mps: float, scale_length_m: float,
                               component: Component = "longitudinal"):
    """Variance in [0, Omega] of the Dryden spectrum (closed form of the integral of
    :func:`dryden_psd`), in (m/s)^2.

    With u = L Omega: longitudinal ``(2 sigma^2 / pi) atan(u)``; lateral
    ``(sigma^2 / pi) (2 atan(u) - u / (1 + u^2))``.  Both tend to sigma^2 as Omega -> inf.
    """
    _check_component(component)
    u = scale_length_m * np.asarray(wavenumber_radpm, dtype=float)
    if component == "longitudinal":
        return (2.0 * sigma_mps**2 / math.pi) * np.arctan(u)
    return (sigma_mps**2 / math.pi) * (2.0 * np.arctan(u) - u / (1.0 + u**2))


def dryden_band_variance(low_radpm, high_radpm, sigma_mps: float, scale_length_m: float,
                         component: Component = "longitudinal"):
    """Variance of the Dryden spectrum between two spatial angular frequencies (m/s)^2."""
    return (dryden_cumulative_variance(high_radpm, sigma_mps, scale_length_m, component)
            - dryden_cumulative_variance(low_radpm, sigma_mps, scale_length_m, component))


# --------------------------------------------------------------------------- synthesis

def synthesize_turbulence(n_points: int, dx_m: float, sigma_mps: float, scale_length_m: float,
                          component: Component, rng: np.random.Generator) -> np.ndarray:
    """One realisation of zero-mean Dryden turbulence on a uniform spatial grid (FFT synthesis).

    Each discrete frequency Omega_k = 2 pi k / (N dx) receives an independent Gaussian complex
    amplitude whose variance is the *exact* Dryden variance of its bin
    ``[Omega_k - dOmega/2, Omega_k + dOmega/2]`` (:func:`dryden_band_variance`), so the
    expected variance of the field is sigma^2 minus only the tail above the Nyquist frequency
    pi / dx (0.2 % of sigma^2 for L = 30 m, dx = 0.25 m).  The zero-frequency bin (wavelengths
    longer than the field) is a random constant offset.  The field is periodic with period N dx.

    Parameters
    ----------
    n_points : int
        Number of grid points N (>= 4).
    dx_m : float
        Grid step (m).
    sigma_mps : float
        Standard deviation of the component (m/s); 0 gives a zero field.
    scale_length_m : float
        Dryden scale length L (m).
    component : {"longitudinal", "lateral"}
        Spectrum to use (:func:`dryden_psd`).
    rng : numpy.random.Generator
        Source of randomness.

    Returns
    -------
    ndarray, shape (n_points,)
        The turbulent velocity (m/s) at x = 0, dx, 2 dx, ...
    """
    _check_component(component)
    if n_points < 4:
        raise ValueError("n_points must be at least 4")
    if dx_m <= 0 or scale_length_m <= 0 or sigma_mps < 0:
        raise ValueError("dx_m and scale_length_m must be positive and sigma_mps non-negative")
    n = int(n_points)
    d_omega = 2.0 * math.pi / (n * dx_m)
    k = np.arange(n // 2 + 1)
    lo = np.maximum(k - 0.5, 0.0) * d_omega
    hi = np.minimum(k + 0.5, n / 2.0) * d_omega
    var = dryden_band_variance(lo, hi, sigma_mps, scale_length_m, component)
    # x_j = (1/N) [C_0 + 2 sum_{0<k<N/2} Re(C_k e^{i Omega_k x_j}) + C_{N/2} (-1)^j]:
    # a bin 0 < k < N/2 contributes variance |C_k|^2 * 2 / N^2 when C_k = (N/2) s (z1 + i z2)
    # gives s^2, so s^2 = var_k; the real end bins take C = N s z.
    z = rng.standard_normal((2, k.size))
    coeff = 0.5 * n * np.sqrt(var) * (z[0] + 1j * z[1])
    coeff[0] = n * math.sqrt(var[0]) * z[0, 0]
    if n % 2 == 0:
        coeff[-1] = n * math.sqrt(var[-1]) * z[0, -1]
    return np.fft.irfft(coeff, n=n)


def mean_wind_profile(position_m, mean_wind_mps: float, spatial_beta: float, track_length_m: float):
    """Mean wind along the track, varying linearly with position (thesis figure 46).

    ``mean(x) = mean0 (1 + beta (x / track_length - 0.5))``: ``mean0`` at the middle of the
    track, ``mean0 (1 + beta/2)`` at the +x end and ``mean0 (1 - beta/2)`` at x = 0.
    *(Reconstructed: the thesis only says the mean wind is high at one end of the track, low at
    the other, and varies linearly with distance, by an amount set by beta.)*
    """
    x = np.asarray(position_m, dtype=float)
    return mean_wind_mps * (1.0 + spatial_beta * (x / track_length_m - 0.5))


@dataclass(frozen=True, eq=False)
class WindField:
    """Wind components on a uniform grid along the track, ground frame (see module docstring).

    Attributes
    ----------
    start_m : position of the first grid point (m, track coordinate).
    dx_m : grid step (m).
    along_mps : along-track component w_a (m/s), positive towards -x; shape (G,).
    cross_mps : cross-track component w_c (m/s); shape (G,).
    """

    start_m: float
    dx_m: float
    along_mps: np.ndarray
    cross_mps: np.ndarray

    @property
    def position_m(self) -> np.ndarray:
        """Positions of the grid points (m)."""
        return self.start_m + self.dx_m * np.arange(self.along_mps.size)

    @property
    def end_m(self) -> float:
        return self.start_m + self.dx_m * (self.along_mps.size - 1)

    def at(self, position_m) -> tuple[np.ndarray, np.ndarray]:
        """(w_a, w_c) linearly interpolated at ``position_m`` (held at the ends)."""
        x = self.position_m
        return np.interp(position_m, x, self.along_mps), np.interp(position_m, x, self.cross_mps)


def turbulence_sigmas(head_wind_mps: float, cross_wind_mps: float,
                      turbulence_ratio: float = TURBULENCE_RATIO,
                      reference: Literal["component", "total"] = "component") -> tuple[float, float]:
    """Standard deviations (m/s) of the in-line and cross turbulence.

    The thesis: "the standard deviation of the wind generated by the simulation is determined
    by multiplying the mean wind speed by the turbulence ratio".  With ``reference="component"``
    (default, reconstructed) each component uses its own mean (so a pure cross wind has no
    in-line turbulence); ``"total"`` uses the magnitude of the mean wind vector for both.
    """
    if reference == "component":
        return turbulence_ratio * abs(head_wind_mps), turbulence_ratio * abs(cross_wind_mps)
    if reference == "total":
        s = turbulence_ratio * math.hypot(head_wind_mps, cross_wind_mps)
        return s, s
    raise ValueError(f"reference must be 'component' or 'total', not {reference!r}")


def generate_wind_field(head_wind_mps: float, cross_wind_mps: float, rng: np.random.Generator, *,
                        track_length_m: float, margin_m: float, spatial_beta: float = 0.0,
                        turbulence_ratio: float = TURBULENCE_RATIO,
                        scale_length_head_m: float = SCALE_LENGTH_M,
                        scale_length_cross_m: float = SCALE_LENGTH_M,
                        dx_m: float = WIND_GRID_STEP_M,
                        turbulence_reference: Literal["component", "total"] = "component") -> WindField:
    """One realisation of the wind over ``[-margin, track_length + margin]``.

    Parameters
    ----------
    head_wind_mps : float
        Mean along-track component w_a at mid-track (m/s): a head wind for the + runs.
    cross_wind_mps : float
        Mean cross-track component at mid-track (m/s).
    rng : numpy.random.Generator
        Source of randomness (the in-line component is drawn first, then the cross component).
    track_length_m, margin_m : float
        The track is [0, track_length]; the field extends ``margin`` beyond both ends.
    spatial_beta : float
        Linear variation of the mean wind along the track (:func:`mean_wind_profile`).
    turbulence_ratio : float
        sigma / mean wind (:func:`turbulence_sigmas`).
    scale_length_head_m, scale_length_cross_m : float
        Dryden scale lengths of the in-line (longitudinal) and cross (lateral) components.
    dx_m : float
        Grid step (m).
    turbulence_reference : {"component", "total"}
        Which mean sets sigma (:func:`turbulence_sigmas`).

    Returns
    -------
    WindField
    """
    if track_length_m <= 0 or margin_m < 0:
        raise ValueError("track_length_m must be positive and margin_m non-negative")
    start = -float(margin_m)
    n = int(math.ceil((track_length_m + 2.0 * margin_m) / dx_m)) + 1
    x = start + dx_m * np.arange(n)
    sig_a, sig_c = turbulence_sigmas(head_wind_mps, cross_wind_mps, turbulence_ratio, turbulence_reference)
    turb_a = synthesize_turbulence(n, dx_m, sig_a, scale_length_head_m, "longitudinal", rng)
    turb_c = synthesize_turbulence(n, dx_m, sig_c, scale_length_cross_m, "lateral", rng)
    along = mean_wind_profile(x, head_wind_mps, spatial_beta, track_length_m) + turb_a
    cross = mean_wind_profile(x, cross_wind_mps, spatial_beta, track_length_m) + turb_c
    return WindField(start, float(dx_m), along, cross)
