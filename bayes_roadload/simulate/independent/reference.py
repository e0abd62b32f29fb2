"""The definition of the true parameters in the analysis' terms (the only thing shared with it).

The analysis model (``ROADLOAD_MODEL.md`` eq. 2.49, ``docs/data-format.md``) reports

* ``AD`` (-), ``BD`` (s/m): tyre loss ``M g_a (AD + BD v)`` with the analysis' convention
  ``g_a = 9.81 m/s^2`` and the test mass ``M``;
* ``CD0`` (-), ``KD`` (rad^-2): ``C_D(psi) = CD0 + KD psi^2``;
* ``At`` (N), ``Bt`` (N s/m), ``Ct`` (N s^2/m^2): driveline loss ``At + Bt v + Ct v^2``;
* ``F50_N``: the road load at 50 mph in still air, level road, 100 kPa, 293.2 K, and
  ``F0_N, F1_N_per_kph, F2_N_per_kph2``: the least-squares quadratic in v (km/h) through the
  road load at 15, 20, ..., 115 km/h.

These numbers are definitions of the contract, restated here (not imported) so that the
independent simulator shares no code with the analysis.  The simulator's own physics uses its
own constants (local gravity, moist air) and only meets these definitions when it reports the
truth.
"""

from __future__ import annotations

import numpy as np

ANALYSIS_GRAVITY_MPS2 = 9.81
"""The g that multiplies M in the analysis' tyre term (the definition of AD, BD)."""
REFERENCE_PRESSURE_PA = 100_000.0
REFERENCE_TEMPERATURE_K = 293.2
DRY_AIR_GAS_CONSTANT = 287.05
"""J/(kg K): the reference density is p / (R T) of dry air at the reference conditions."""
REFERENCE_DENSITY_KGPM3 = REFERENCE_PRESSURE_PA / (DRY_AIR_GAS_CONSTANT * REFERENCE_TEMPERATURE_K)
ANALYSIS_TYRE_TEMPERATURE_COEFF_PER_K = 0.0086
"""K_T of the analysis' tyre correction [1 - K_T (T_0 - T_s)] (GTR 15 Annex 4)."""
MPH_MPS = 0.44704
SPEED_50MPH_MPS = 50.0 * MPH_MPS
ROADLOAD_GRID_KPH = np.arange(15.0, 116.0, 5.0)
"""Speeds (km/h) of the F0 + F1 v + F2 v^2 least-squares fit."""


def quadratic_roadload(total_n_of_mps) -> dict[str, float]:
    """``F50_N`` and ``F0_N, F1_N_per_kph, F2_N_per_kph2`` of a road-load curve.

    Parameters
    ----------
    total_n_of_mps : callable
        Road load (N) at reference conditions as a function of speed (m/s, array).
    """
    grid = ROADLOAD_GRID_KPH
    f = np.asarray(total_n_of_mps(grid / 3.6), float)
    design = np.stack([np.ones_like(grid), grid, grid**2], axis=1)
    coef, *_ = np.linalg.lstsq(design, f, rcond=None)
    return {"F50_N": float(np.asarray(total_n_of_mps(np.array([SPEED_50MPH_MPS])))[0]),
            "F0_N": float(coef[0]), "F1_N_per_kph": float(coef[1]), "F2_N_per_kph2": float(coef[2])}


def linear_tyre_coefficients(coefficient_of_mps) -> tuple[float, float]:
    """``AD, BD`` of a rolling-resistance coefficient law: the least-squares line
    ``AD + BD v`` through it on the road-load grid (exact when the law is linear).

    ``coefficient_of_mps`` returns the tyre force divided by ``M g_a`` (dimensionless)."""
    v = ROADLOAD_GRID_KPH / 3.6
    design = np.stack([np.ones_like(v), v], axis=1)
    coef, *_ = np.linalg.lstsq(design, np.asarray(coefficient_of_mps(v), float), rcond=None)
    return float(coef[0]), float(coef[1])
