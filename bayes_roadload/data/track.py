"""A level survey of the test track (``track.csv``): elevation against position along the track.

40 CFR 1066.310 has a grade above 0.02 % over the test surface enter the analysis as a function
of distance (SAE J2263 section 11.5); a speed-trace campaign states it with ``track.csv``, one row
per surveyed station:

* ``position_m`` (m): the station's position along the track, in the frame of the runs'
  ``position_m`` column (the same for both directions), strictly increasing;
* ``elevation_m`` (m): its elevation above any fixed datum.

The grade between two stations is the rise over the run of that segment, theta = arctan(dz/dx),
placed at the segment's middle and linearly interpolated between middles (the end segments'
grade held beyond them): :func:`grade_at`.  A campaign with a survey reads the grade at every
logged position into the ``track_grade_rad`` channel, which the ``surveyed_gradient`` term
(eq. 2.1 with theta(x)) turns into the force M g sin(d theta).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .checks import check_columns, check_not_empty, check_numeric, plain_value, refuse

TRACK_FILE = "track.csv"
COLUMNS = ("position_m", "elevation_m")
MIN_STATIONS = 2
MAX_GRADE = 0.05
"""The steepest segment a survey may show (rise over run): SAE J1263 asks for a constant grade
below 0.5 %, so a segment above 5 % is an elevation in the wrong unit (mm, cm) or a position
column that is not the distance along the track."""
UNIT_HINTS = {"elevation": "elevation_m", "height": "elevation_m", "altitude": "elevation_m",
              "elevation_mm": "elevation_m (metres)", "elevation_cm": "elevation_m (metres)",
              "z": "elevation_m", "h": "elevation_m", "distance_m": "position_m", "station": "position_m",
              "x": "position_m", "position": "position_m"}


def validate_track(df: pd.DataFrame, where: str = TRACK_FILE) -> pd.DataFrame:
    """Check a survey table against the contract and return a normalised copy: the two
    columns, at least two stations, finite numbers, positions strictly increasing and no
    segment steeper than :data:`MAX_GRADE`; a refusal names the column and the 1-based row."""
    df = df.copy()
    check_columns(df, COLUMNS, COLUMNS, UNIT_HINTS, "a track survey", where)
    check_not_empty(df, "stations", where)
    if len(df) < MIN_STATIONS:
        refuse(where, None, None, f"{len(df)} station; a survey needs at least {MIN_STATIONS}")
    check_numeric(df, COLUMNS, {}, where)
    x, z = df["position_m"].to_numpy(float), df["elevation_m"].to_numpy(float)
    step = np.diff(x)
    if (step <= 0).any():
        i = int(np.flatnonzero(step <= 0)[0]) + 1
        refuse(where, "position_m", i + 1, f"position {x[i]:g} m does not increase on the station "
               f"before it ({x[i - 1]:g} m): list the stations in order along the track, once each")
    grade = np.diff(z) / step
    if (np.abs(grade) > MAX_GRADE).any():
        i = int(np.flatnonzero(np.abs(grade) > MAX_GRADE)[0]) + 1
        refuse(where, "elevation_m", i + 1, f"grade {100 * grade[i - 1]:.3g} % from the station before: "
               f"steeper than {100 * MAX_GRADE:g} % (a test track is level within 0.5 %, SAE J1263); "
               "is the elevation in metres and the position the distance along the track?")
    return df[list(COLUMNS)].reset_index(drop=True)


def segment_grades(track: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """The middles of the survey's segments (m) and their grades theta = arctan(dz/dx) (rad)."""
    x, z = track["position_m"].to_numpy(float), track["elevation_m"].to_numpy(float)
    return 0.5 * (x[1:] + x[:-1]), np.arctan(np.diff(z) / np.diff(x))


def grade_at(track: pd.DataFrame, position_m) -> np.ndarray:
    """The track's rise in its +x direction (rad) at ``position_m``: the segment grades of
    :func:`segment_grades` linearly interpolated between the segments' middles."""
    middle, theta = segment_grades(track)
    if middle.size == 1:
        return np.full(np.shape(position_m), theta[0])
    return np.interp(np.asarray(position_m, float), middle, theta)


def check_runs_on_track(runs: pd.DataFrame, track: pd.DataFrame, where: str) -> None:
    """Refuse a survey the runs cannot be placed on: runs without ``position_m``, a logged
    position outside the surveyed stretch, or a run whose ``direction`` (+1: ``position_m``
    increases, every run +1 without the column) disagrees with the way its logged position
    moves, which would give it the grade of the other direction (naming the run and the row of
    ``where``)."""
    if "position_m" not in runs:
        refuse(where, "position_m", None, f"{TRACK_FILE} surveys the track but the runs do not log "
               "their position along it; add position_m (the same frame as the survey's stations)")
    x = runs["position_m"].to_numpy(float)
    lo, hi = float(track["position_m"].iloc[0]), float(track["position_m"].iloc[-1])
    out = (x < lo) | (x > hi)
    if out.any():
        i = int(np.flatnonzero(out)[0])
        refuse(where, "position_m", i + 1, f"run {plain_value(runs['run'].iloc[i])!r} at {x[i]:g} m, outside the "
               f"surveyed stretch {lo:g} to {hi:g} m of {TRACK_FILE}")
    run_of = runs["run"].to_numpy()
    for rid in pd.unique(run_of):
        rows = np.flatnonzero(run_of == rid)
        travel = np.sign(x[rows[-1]] - x[rows[0]])
        d = float(runs["direction"].iloc[rows[0]]) if "direction" in runs else 1.0
        if travel != 0 and travel != np.sign(d):
            way = "increases" if travel > 0 else "decreases"
            if "direction" in runs:
                refuse(where, "direction", int(rows[0]) + 1,
                       f"run {plain_value(rid)!r} has direction {d:+g} but its position_m {way} "
                       f"({x[rows[0]]:g} to {x[rows[-1]]:g} m); with {TRACK_FILE} direction +1 means position_m "
                       "increases, -1 that it decreases (the grade's sign in the run's direction)")
            refuse(where, "position_m", int(rows[0]) + 1,
                   f"run {plain_value(rid)!r}'s position_m decreases ({x[rows[0]]:g} to {x[rows[-1]]:g} m) "
                   f"and the runs have no direction column (every run +1); with {TRACK_FILE} add direction: "
                   "+1 where position_m increases, -1 where it decreases")
