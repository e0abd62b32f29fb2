"""The 19 simulated coastdown cases of the thesis (table 6.7), as named presets.

Each case is one pair of runs in the thesis; :func:`bayes_roadload.simulate.simulate_campaign`
simulates any number of pairs of a case.  Columns of table 6.7: instrument and vehicle
dynamics (Y/N), measurement noise (Y/N), system noise (Y/N), model ("basic" = eq. 6.1, the
simplified drag with lift unloading; "comp" = eq. 6.2, the full drag function; "table" = eq. 6.1
with C_D(psi) interpolated in the wind-tunnel table, case 13), mean head wind and cross wind.

Reconstructed readings *(see ROADLOAD_MODEL.md section 4)*: the transcript's Y/N columns for
cases 9-10 are garbled; case 9 has measurement noise and case 10 system noise, as the text
says.  The spatial variation of case 6 is not quantified in the transcript: beta = 0.5 here
(mean wind from 0.75 x to 1.25 x its mid-track value along the track).
"""

from __future__ import annotations

import operator
from dataclasses import dataclass
from typing import Literal

ModelName = Literal["basic", "comp", "table"]
MODELS = ("basic", "comp", "table")

SPATIAL_BETA_CASE_6 = 0.5
"""Spatial variation of the mean wind in case 6 (reconstructed; see :mod:`.wind`)."""


@dataclass(frozen=True)
class SimulationCase:
    """One simulation case (a row of thesis table 6.7).

    Parameters
    ----------
    number : int
        Case number (1-19 for the thesis presets; any int for a custom case).
    description : str
        Short description ("validation", "+ spatial", "dynamics", ...).
    head_wind_mps : float
        Mean along-track wind at mid-track (m/s): a head wind for the + runs, a tail wind for
        the - runs.
    cross_wind_mps : float
        Mean cross-track wind at mid-track (m/s).
    dynamics : bool
        Include the anemometer dynamics and the vehicle's aerodynamic admittance.
    measurement_noise : bool
        Add Gaussian noise to the logged speed, airspeed and yaw (table 6.6).
    system_noise : bool
        Perturb the true A_D, B_D, C_D0 of each run (table 6.6).
    model : {"basic", "comp", "table"}
        Drag model generating the data (eq. 6.1, eq. 6.2, eq. 6.1 with the tunnel C_D table).
    spatial_beta : float
        Linear variation of the mean wind along the track (0 = uniform).
    """

    number: int
    description: str
    head_wind_mps: float
    cross_wind_mps: float
    dynamics: bool = False
    measurement_noise: bool = False
    system_noise: bool = False
    model: ModelName = "basic"
    spatial_beta: float = 0.0

    def __post_init__(self):
        if self.model not in MODELS:
            raise ValueError(f"model must be one of {MODELS}, not {self.model!r}")
        if self.head_wind_mps < 0 or self.cross_wind_mps < 0:
            raise ValueError("mean head and cross winds are magnitudes (>= 0 m/s); "
                             "the - runs of a pair see the head wind as a tail wind")


def _table_6_7() -> dict[int, SimulationCase]:
    c = SimulationCase
    rows = [
        c(1, "validation", 1.0, 1.0),
        c(2, "validation", 2.0, 2.0),
        c(3, "validation", 3.0, 3.0),
        c(4, "validation", 0.0, 2.0),
        c(5, "validation", 0.0, 3.0),
        c(6, "+ spatial", 3.0, 3.0, spatial_beta=SPATIAL_BETA_CASE_6),
        c(7, "dynamics", 2.0, 2.0, dynamics=True),
        c(8, "dynamics", 3.0, 3.0, dynamics=True),
        c(9, "measurement noise", 2.0, 2.0, measurement_noise=True),
        c(10, "system noise", 2.0, 2.0, system_noise=True),
        c(11, "full model", 2.0, 2.0, model="comp"),
        c(12, "full model", 3.0, 3.0, model="comp"),
        c(13, "interp. C_D(psi)", 2.0, 2.0, model="table"),
    ]
    for number, (head, cross) in zip(range(14, 20), [(2, 2), (2, 2), (3, 3), (3, 3), (0, 3), (0, 3)]):
        rows.append(c(number, "combined", float(head), float(cross), dynamics=True,
                      measurement_noise=True, system_noise=True, model="comp"))
    return {row.number: row for row in rows}


CASES: dict[int, SimulationCase] = _table_6_7()
"""Thesis table 6.7, case number -> :class:`SimulationCase`."""


def get_case(number: int) -> SimulationCase:
    """The preset of thesis table 6.7 numbered ``number`` (1-19).

    Raises
    ------
    KeyError
        For a number that is not a case of table 6.7.
    """
    try:
        key = None if isinstance(number, bool) else operator.index(number)
    except TypeError:
        key = None
    if key not in CASES:
        raise KeyError(f"unknown simulation case {number!r}; the thesis cases (table 6.7) are "
                       f"numbered {min(CASES)}-{max(CASES)}")
    return CASES[key]
