"""The steady-state torque test kind (thesis sections 5.4, 7.4): ``steady.csv`` + ``vehicle.toml``.

The vehicle is driven at a set of steady speeds (the thesis: 20, 30, ..., 70 mph, both
directions) while the torque at the driven wheels is logged; the tractive force there is the
road load without the driveline loss (eq. 5.5), plus the small inertial term ``M_e dv/dt`` of
the speed the driver could not hold exactly.  One row per sample (or per run, a run's mean):

==========================================  =====  ========  ===========================================
column                                      unit   required  meaning
==========================================  =====  ========  ===========================================
``run``                                     id     yes       one steady-speed run; rows contiguous
``speed_mps``                               m/s    yes       vehicle speed over the ground
``tractive_force_n``                        N      one of    tractive force at the driven wheels, or ...
``wheel_torque_left_nm``, ``..._right_nm``  N m    the two   ... the two wheel torques: (left + right) / R_r
``time_s``                                  s      no        time; gives ``accel_mps2`` when that is absent
``accel_mps2``                              m/s^2  no        dv/dt (the inertial correction M_e dv/dt)
``airspeed_mps``, ``yaw_rad``               m/s,   no        on-board anemometer readings (calibrated by
                                            rad              ``[anemometer]`` as for coastdowns)
``direction``, ``pair``                     +/-1,  no        heading and the opposite-direction pair
                                            id               (consecutive runs pair up without ``pair``)
``temperature_k``, ``pressure_pa``          K, Pa  no        ambient conditions (air density, tyre temperature)
``gearbox_input_force_n``                   N      no        gearbox input (engine output) torque referred to
                                                             the driven wheels (x overall ratio / R_r): minus
                                                             the wheel force it is the on-load driveline loss
==========================================  =====  ========  ===========================================

Without ``accel_mps2`` the acceleration of a run logged with ``time_s`` is the slope of a
least-squares quadratic of speed against time over the run (the polynomial method of thesis
section 1.2.1, which the thesis uses for this corrective term, section 5.4.1); a run without
either is taken as steady (``accel_mps2 = 0``; :attr:`SteadyCampaign.accel_source` says which).
``vehicle.toml`` is the coastdown one (``[vehicle]``, ``[anemometer]``, ``[tunnel]``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .. import config
from .ambient import check_humidity_percent
from .units import check_plausible_airspeed
from .checks import (
    read_csv_table,
    CHANNEL_LIMITS,
    UNIT_HINTS,
    WHEEL_TORQUE_COLUMNS,
    check_columns,
    check_contiguous,
    check_csv_format,
    check_direction_codes,
    check_no_missing,
    check_not_empty,
    check_numeric,
    check_pair_groups,
    check_run_constants,
    check_time_increases,
    check_anemometer_pair,
    check_wheel_torque_pair,
    data_file,
    table_pairs,
    read_truth,
    refuse,
    run_directions,
    run_ids_of,
    run_rows,
    truth_files,
    wheel_torque_force_n,
)
from .uncertainty import TypeBChannels
from .vehicle import VEHICLE_FILE, Anemometer, Vehicle, read_vehicle_file, validate_vehicle, vehicle_toml

KIND = "steady"
FILES = ("steady.csv",)
DESCRIPTION = "steady-state torque tests"
OPTIONS: tuple[str, ...] = ()
OPTIONAL_FILES: tuple[str, ...] = ()

FORCE_COLUMNS = ("tractive_force_n",)
TORQUE_COLUMNS = WHEEL_TORQUE_COLUMNS
OPTIONAL_COLUMNS = ("time_s", "accel_mps2", "airspeed_mps", "yaw_rad", "direction", "pair",
                    "temperature_k", "pressure_pa", "relative_humidity_pct", "gearbox_input_force_n")
KNOWN_COLUMNS = ("run", "speed_mps") + FORCE_COLUMNS + TORQUE_COLUMNS + OPTIONAL_COLUMNS
RUN_CONSTANT = ("direction", "pair")

_AMBIGUOUS_HINTS = {
    "force": "tractive_force_n (newtons)",
    "tractive_force": "tractive_force_n (newtons)",
    "tractive_force_kn": "tractive_force_n (newtons): multiply kN by 1000",
    "torque": "wheel_torque_left_nm and wheel_torque_right_nm (N m), or tractive_force_n",
    "wheel_torque_nm": "wheel_torque_left_nm and wheel_torque_right_nm (each wheel), or tractive_force_n",
    "speed_kph": "speed_mps (m/s): divide km/h by 3.6",
    "speed_mph": "speed_mps (m/s): multiply mph by 0.44704",
    "accel_g": "accel_mps2 (m/s^2): multiply g by 9.81",
    "yaw_deg": "yaw_rad (radians): multiply degrees by pi/180",
    "temperature_c": "temperature_k (kelvin): add 273.15",
    **{k: v for k, v in UNIT_HINTS.items() if v.startswith("relative_humidity_pct")},
}


@dataclass
class SteadyCampaign:
    """A loaded, validated steady-state campaign.

    Attributes
    ----------
    runs : ``run``, ``speed_mps``, ``tractive_force_n``, ``accel_mps2`` and the optional columns.
    vehicle, anemometer, tunnel, truth, meta : as for :class:`~bayes_roadload.data.Campaign`.
    accel_source : how ``accel_mps2`` was obtained: "logged", "polynomial (time_s)" or "none (steady)".
    """

    runs: pd.DataFrame
    vehicle: Vehicle
    anemometer: Anemometer = field(default_factory=Anemometer)
    tunnel: dict[str, Any] | None = None
    truth: dict[str, Any] | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    accel_source: str = "logged"
    kind = KIND
    type_b_channels = TypeBChannels("runs", speed=("speed_mps",), force=("tractive_force_n", "gearbox_input_force_n"))

    def __post_init__(self):
        self.runs, source = validate_steady(self.runs, "steady", self.vehicle.rolling_radius_m)
        if source != "logged":
            self.accel_source = source
        validate_vehicle(self.vehicle, "vehicle")

    @property
    def run_ids(self) -> list:
        return run_ids_of(self.runs)

    @property
    def has_anemometer(self) -> bool:
        return "airspeed_mps" in self.runs and "yaw_rad" in self.runs

    @property
    def has_driveline(self) -> bool:
        """False: the wheel torque is measured beyond the driveline (thesis section 5.4.1)."""
        return False

    has_track_survey = False  # track.csv is read with speed traces only

    @property
    def has_driveline_loss(self) -> bool:
        """The gearbox input is logged: the on-load driveline loss is measured (section 5.5.2)."""
        return "gearbox_input_force_n" in self.runs

    def driveline_loss_n(self) -> np.ndarray:
        """The on-load driveline loss of every sample, gearbox input minus wheel force (N;
        thesis section 5.5.2: "not necessary to correct the measured data as the difference is
        required")."""
        if not self.has_driveline_loss:
            raise ValueError("steady.csv logs no gearbox_input_force_n: the on-load driveline loss is not measured")
        return (self.runs["gearbox_input_force_n"] - self.runs["tractive_force_n"]).to_numpy(float)

    def directions(self) -> dict:
        return run_directions(self.runs)

    def pairs(self) -> list[tuple]:
        """Opposite-direction pairs: the ``pair`` column, else consecutive runs; unpaired runs dropped."""
        return table_pairs(self.runs, self.run_ids)


def validate_steady(df: pd.DataFrame, where: str = "steady.csv", rolling_radius_m: float | None = None
                    ) -> tuple[pd.DataFrame, str]:
    """Check a steady-state table; returns it normalised (``tractive_force_n`` and
    ``accel_mps2`` present) and the source of the acceleration."""
    df = df.copy()
    cols = check_columns(df, KNOWN_COLUMNS, ("run", "speed_mps"), _AMBIGUOUS_HINTS, "a steady-state table", where)
    torques = [c for c in TORQUE_COLUMNS if c in cols]
    if "tractive_force_n" in cols and torques:
        refuse(where, "tractive_force_n", None, "give tractive_force_n or the wheel torques, not both (ambiguous)")
    check_wheel_torque_pair(cols, where)
    check_anemometer_pair(cols, where)
    if "tractive_force_n" not in cols and not torques:
        refuse(where, "tractive_force_n", None, "required: tractive_force_n (N) or the two wheel torques (N m)")
    check_not_empty(df, "samples", where)
    check_no_missing(df, "run", "missing run id", where)
    check_numeric(df, [c for c in cols if c != "run" and not (c == "pair" and not pd.api.types.is_numeric_dtype(df[c]))],
                  CHANNEL_LIMITS, where)
    check_humidity_percent(df, where)
    if (df["speed_mps"] <= 0).any():
        refuse(where, "speed_mps", int(np.flatnonzero(df["speed_mps"].to_numpy() <= 0)[0]) + 1,
              "a steady-state run needs a positive speed")
    if "accel_mps2" in cols and (df["accel_mps2"].abs() > config.STEADY_MAX_ACCEL_MPS2).any():
        i = int(np.flatnonzero(df["accel_mps2"].abs().to_numpy() > config.STEADY_MAX_ACCEL_MPS2)[0])
        refuse(where, "accel_mps2", i + 1, f"|dv/dt| {df['accel_mps2'].iloc[i]:g} m/s^2 above "
              f"{config.STEADY_MAX_ACCEL_MPS2:g}: not a steady-speed run (or g / km/h/s in an m/s^2 column)")
    check_direction_codes(df, where)
    if torques:
        if rolling_radius_m is None:
            refuse(where, "wheel_torque_left_nm", None, "needs [vehicle] rolling_radius_m")
        df["tractive_force_n"] = wheel_torque_force_n(df, rolling_radius_m)
    accel = np.zeros(len(df))
    sources = set()
    for rid, rows in run_rows(df):
        check_contiguous(rows, rid, "rows", where)
        check_run_constants(df, rows, RUN_CONSTANT, rid, where)
        if "time_s" in cols:
            t = df["time_s"].to_numpy()[rows]
            check_time_increases(t, rows, rid, where)
            if "accel_mps2" not in cols and rows.size >= 3:
                accel[rows] = polynomial_acceleration(t, df["speed_mps"].to_numpy()[rows])
                sources.add("polynomial (time_s)")
    check_pair_groups(df, where)
    if "accel_mps2" in cols:
        source = "logged"
    else:
        df["accel_mps2"] = accel
        source = "polynomial (time_s)" if sources else "none (steady)"
    return df.reset_index(drop=True), source


def polynomial_acceleration(time_s, speed_mps) -> np.ndarray:
    """dv/dt of a run from a least-squares quadratic of speed against time (thesis section 1.2.1,
    applied to the corrective term only, section 5.4.1)."""
    t = np.asarray(time_s, float) - float(np.mean(time_s))
    c2, c1, _ = np.polyfit(t, np.asarray(speed_mps, float), 2)
    return c1 + 2.0 * c2 * t


def load(root: str | os.PathLike) -> SteadyCampaign:
    """Load and validate a steady-state campaign directory (``steady.csv``, ``vehicle.toml``,
    optional ``truth.json``); airspeeds logged in km/h or mph under ``airspeed_mps`` are refused
    as for coastdowns (:func:`~bayes_roadload.data.units.check_plausible_airspeed`)."""
    root = Path(root)
    f = data_file(root, "steady.csv")
    vehicle, anem, tunnel, meta = read_vehicle_file(root / VEHICLE_FILE)
    df, source = validate_steady(read_csv_table(f), str(f), vehicle.rolling_radius_m)
    check_plausible_airspeed(df, str(f), anem.airspeed_factor, convertible=False)
    return SteadyCampaign(df, vehicle, anem, tunnel, read_truth(root), meta, accel_source=source)


load_steady = load


def files(c: SteadyCampaign, fmt: str = "csv") -> dict[str, str]:
    """The files of a steady-state campaign directory (name -> text), validated first:
    ``steady.csv`` (with the force and the acceleration used), ``vehicle.toml``,
    ``truth.json`` when the truth is known."""
    check_csv_format(fmt, "a steady-state campaign", "steady.csv")
    c.runs, _ = validate_steady(c.runs, "steady", c.vehicle.rolling_radius_m)
    return ({"steady.csv": c.runs.to_csv(index=False, float_format="%.10g"), VEHICLE_FILE: vehicle_toml(c)}
            | truth_files(c.truth))


def save_steady(c: SteadyCampaign, path: str | os.PathLike) -> Path:
    """Validate and write a steady-state campaign directory (:func:`~bayes_roadload.data.io.save_campaign`)."""
    from .io import save_campaign  # io imports this module: its registry lists the kinds

    return save_campaign(c, path)
