"""The checks and file helpers every kind of campaign shares.

Every data kind (speed traces, interval times, distance-time records, wheel spin-downs,
steady-state torque tests) validates its table with these checks, in the same order and with
the same messages: a refusal is a :class:`CampaignError` whose message names the file, the
column and the 1-based data row (row 1 is the first line after the header) at fault.  Every
kind writes its directory through :func:`write_atomically`.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np
import pandas as pd

from .. import config


class CampaignError(ValueError):
    """A campaign was refused; the message names the file, column and row."""


# --------------------------------------------------------------------------- channels
# The contract's channels shared by the kinds that log them.

UNIT_HINTS = {
    "speed": "speed_mps (m/s)",
    "speed_kph": "speed_mps (m/s): divide km/h by 3.6",
    "speed_kmh": "speed_mps (m/s): divide km/h by 3.6",
    "speed_mph": "speed_mps (m/s): multiply mph by 0.44704",
    "velocity": "speed_mps (m/s)",
    "time": "time_s (seconds)",
    "t": "time_s (seconds)",
    "time_ms": "time_s (seconds): divide ms by 1000 (a runs table's time_ms is converted on load)",
    "airspeed": "airspeed_mps (m/s)",
    "yaw": "yaw_rad (radians)",
    "yaw_deg": "yaw_rad (radians): multiply degrees by pi/180",
    "temperature": "temperature_k (kelvin)",
    "temperature_c": "temperature_k (kelvin): add 273.15",
    "pressure": "pressure_pa (pascal)",
    "pressure_kpa": "pressure_pa (pascal): multiply kPa by 1000",
    "pressure_hpa": "pressure_pa (pascal): multiply hPa by 100",
    "relative_humidity": "relative_humidity_pct (percent, 0-100): multiply a fraction by 100",
    "humidity": "relative_humidity_pct (percent, 0-100)",
    "rh": "relative_humidity_pct (percent, 0-100)",
    "humidity_pct": "relative_humidity_pct (percent, 0-100)",
    "dew_point_c": "relative_humidity_pct (percent, 0-100): the relative humidity, not the dew point",
}
"""Column names that say a unit the contract does not use -> the column to give instead (and
the conversion): such a column is refused rather than guessed."""

CHANNEL_LIMITS = {
    # column: (low, high, what a value outside usually means)
    "speed_mps": (0.0, config.MAX_SPEED_MPS, "negative, or km/h in a m/s column: --speed-unit kph"),
    "airspeed_mps": (0.0, config.MAX_SPEED_MPS, "negative, or km/h in a m/s column: --airspeed-unit kph"),
    "yaw_rad": (-math.pi / 2, math.pi / 2, "degrees in a radian column"),
    "temperature_k": (200.0, 350.0, "degrees Celsius in a kelvin column"),
    "pressure_pa": (50_000.0, 120_000.0, "kPa, hPa or bar in a pascal column"),
    "relative_humidity_pct": (0.0, 100.0, "not a relative humidity in percent"),
    "mass_kg": config.MASS_RANGE_KG + ("not a test mass in kg",),
}
"""column -> (low, high, what a value outside usually means), SI units."""

AMBIENT_LIMITS = {c: CHANNEL_LIMITS[c] for c in ("temperature_k", "pressure_pa", "relative_humidity_pct")}
"""The ambient columns' limits (:mod:`bayes_roadload.data.ambient`), shared by every kind."""

WHEEL_TORQUE_COLUMNS = ("wheel_torque_left_nm", "wheel_torque_right_nm")


# --------------------------------------------------------------------------- refusals

def refuse(where: str, column: str | None, row: int | None, what: str):
    """Raise :class:`CampaignError` "``where``, column '``column``', row ``row``: ``what``"
    (the column and the 1-based row left out when None)."""
    parts = [where]
    if column is not None:
        parts.append(f"column '{column}'")
    if row is not None:
        parts.append(f"row {row}")
    raise CampaignError(": ".join([", ".join(parts), what]))


def plain_value(x):
    """A numpy scalar as the Python value (run ids print and serialise cleanly)."""
    return x.item() if hasattr(x, "item") else x


def check_columns(df: pd.DataFrame, known, required, hints: Mapping[str, str], what: str, where: str) -> list:
    """Refuse a table's unknown columns (naming the likely unit mistake from ``hints``) and
    missing ``required`` ones; ``what`` names the table in the message ("the contract", "an
    interval campaign", ...).  Returns the column names."""
    cols = list(df.columns)
    for c in cols:
        if c not in known:
            hint = hints.get(str(c).strip().lower())
            refuse(where, str(c), None, f"unknown column; did you mean {hint}?" if hint
                   else f"unknown column; {what} knows {', '.join(known)}")
    for c in required:
        if c not in cols:
            refuse(where, c, None, "required column is missing")
    return cols


def check_not_empty(df: pd.DataFrame, rows: str, where: str) -> None:
    """Refuse a table without data rows; ``rows`` names them ("samples", "intervals", ...)."""
    if len(df) == 0:
        refuse(where, None, None, f"no {rows}")


def check_no_missing(df: pd.DataFrame, column: str, what: str, where: str) -> None:
    """Refuse an empty cell of a label column (``run``, ``pair``, ...), naming its row;
    ``what`` is the message ("missing run id", ...)."""
    missing = df[column].isna().to_numpy()
    if missing.any():
        refuse(where, column, int(np.flatnonzero(missing)[0]) + 1, what)


def numeric_and_text_ids(df: pd.DataFrame, columns, ids, where: str) -> list:
    """The columns of ``columns`` to check as numbers: all but the id columns ``ids`` held as text
    (``run``, ``pair``: an id is an integer or text).  A text id column is refused with its row
    where a cell is empty; a numeric one is left to :func:`check_numeric` (whose refusal of an
    empty cell names the row too)."""
    out = []
    for c in columns:
        if c in ids and not pd.api.types.is_numeric_dtype(df[c]):
            check_no_missing(df, c, f"missing {c} id", where)
            if isinstance(df[c].dtype, pd.CategoricalDtype):
                df[c] = df[c].astype(object)
        else:
            out.append(c)
    return out


def check_numeric(df: pd.DataFrame, columns, limits: Mapping[str, tuple], where: str) -> None:
    """Convert ``columns`` of ``df`` to float in place, refusing a value that is not a finite
    number and one outside its ``limits[column] = (low, high, what it probably is)``, naming
    the row.  A datetime or timedelta column (parquet) is refused at row 1: pandas would read it
    as integer nanoseconds."""
    for c in columns:
        if pd.api.types.is_datetime64_any_dtype(df[c]) or pd.api.types.is_timedelta64_dtype(df[c]):
            refuse(where, c, 1, f"a {df[c].dtype} column, not a number: give "
                   + ("the seconds from the run's start as a number" if c == "time_s" else "a number in the column's unit"))
        values = pd.to_numeric(df[c], errors="coerce").to_numpy(float)
        bad = ~np.isfinite(values)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raw = plain_value(df[c].iloc[i])
            shown = "an empty cell" if isinstance(raw, float) and math.isnan(raw) else f"value {raw!r}"
            refuse(where, c, i + 1, f"{shown} is not a finite number")
        df[c] = values
        if c in limits:
            lo, hi, meaning = limits[c]
            out = (values < lo) | (values > hi)
            if out.any():
                i = int(np.flatnonzero(out)[0])
                refuse(where, c, i + 1, f"value {values[i]:g} outside [{lo:g}, {hi:g}] ({meaning})")


def check_direction_codes(df: pd.DataFrame, where: str) -> None:
    """Refuse a ``direction`` value other than +1 / -1 (when the column is present)."""
    if "direction" not in df:
        return
    d = df["direction"].to_numpy()
    bad = ~np.isin(d, (-1.0, 1.0))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        refuse(where, "direction", i + 1, f"direction code {d[i]:g} is not +1 or -1")


def check_wheel_torque_pair(columns, where: str) -> list[str]:
    """Refuse one wheel torque column without the other (naming the missing one); returns the
    wheel torque columns present (none or both)."""
    given = [c for c in WHEEL_TORQUE_COLUMNS if c in columns]
    if len(given) == 1:
        missing = next(c for c in WHEEL_TORQUE_COLUMNS if c not in columns)
        refuse(where, missing, None, "wheel torques need both the left and the right column")
    return given


ANEMOMETER_COLUMNS = ("airspeed_mps", "yaw_rad")
"""The on-board anemometer's two channels, which the model reads together (eq. 2.48: the
relative air's speed and its angle)."""


def check_anemometer_pair(columns, where: str) -> None:
    """Refuse one anemometer channel without the other (naming the missing one): the fit reads
    the relative air as speed and yaw angle together, and would otherwise drop the one given."""
    given = [c for c in ANEMOMETER_COLUMNS if c in columns]
    if len(given) == 1:
        missing = next(c for c in ANEMOMETER_COLUMNS if c not in columns)
        refuse(where, missing, None, f"{given[0]} without {missing}: the anemometer enters the model as the relative "
               f"air's speed and yaw angle together; add {missing}, or remove {given[0]} to fit without the "
               "anemometer")


def wheel_torque_force_n(df: pd.DataFrame, rolling_radius_m: float) -> pd.Series:
    """Remove the two wheel torque columns (N m) from ``df`` and return the force they make at
    the tread, (left + right) / R_r (N)."""
    return (df.pop("wheel_torque_left_nm") + df.pop("wheel_torque_right_nm")) / rolling_radius_m


# --------------------------------------------------------------------------- per-run checks

def run_rows(df: pd.DataFrame) -> Iterator[tuple[Any, np.ndarray]]:
    """(run id as a Python value, positions of its rows in ``df``) for every run, in file order."""
    positions = np.arange(len(df))
    for rid, idx in df.groupby("run", sort=False).indices.items():
        yield plain_value(rid), positions[idx]


def check_min_samples(rows: np.ndarray, rid, where: str) -> None:
    """Refuse a run of fewer than ``config.MIN_RUN_SAMPLES`` samples."""
    if len(rows) < config.MIN_RUN_SAMPLES:
        refuse(where, "run", int(rows[0]) + 1,
               f"run {rid!r} has {len(rows)} samples; at least {config.MIN_RUN_SAMPLES} are needed")


def check_contiguous(rows: np.ndarray, rid, what: str, where: str) -> None:
    """Refuse a run whose rows (positions in the table) are not one block; ``what`` names
    them ("samples", "bands", ...)."""
    if np.any(np.diff(rows) != 1):
        refuse(where, "run", int(rows[np.flatnonzero(np.diff(rows) != 1)[0] + 1]) + 1,
               f"the {what} of run {rid!r} are not contiguous")


def check_time_increases(t: np.ndarray, rows: np.ndarray, rid, where: str) -> None:
    """Refuse a run whose times ``t`` (its rows' ``time_s``) do not strictly increase."""
    dt = np.diff(t)
    if np.any(dt <= 0):
        refuse(where, "time_s", int(rows[np.flatnonzero(dt <= 0)[0] + 1]) + 1,
               f"time does not increase within run {rid!r}")


def check_run_constants(df: pd.DataFrame, rows: np.ndarray, columns, rid, where: str) -> None:
    """Refuse a run-level column (of ``columns`` present in ``df``) that changes within the run."""
    for c in columns:
        if c in df:
            vals = df[c].to_numpy()[rows]
            if np.any(vals != vals[0]):
                refuse(where, c, int(rows[np.flatnonzero(vals != vals[0])[0]]) + 1, f"{c} changes within run {rid!r}")


def check_pair_groups(df: pd.DataFrame, where: str, split_segments: bool = False) -> None:
    """Refuse ``pair`` ids that do not pair two opposite-direction runs (when the column is
    present; call after :func:`check_run_constants`, so that a run has one pair id).

    Refused: a pair id held by more than two runs, naming the first row of its third run (in
    file order); a pair id held by two runs of the same ``direction`` (when that column is
    present), naming both runs at the first row of the second.  A pair id held by one run is
    accepted: a run without a partner (the VBOX import gives one an id of its own, and a subset of
    a campaign can leave one); :func:`pairs_by_column` leaves it out of the pairs.

    ``split_segments`` (speed traces: the split runs of 40 CFR 1037.528 (d)(2), a high- and a
    low-speed segment logged as runs of their own in each direction under one pair id,
    :mod:`bayes_roadload.analysis.cfr1037`): a pair id on more than two runs is accepted when the
    ``direction`` column is present and the id holds as many runs of each direction; it is then
    not a pair of :func:`pairs_by_column` either.
    """
    if "pair" not in df:
        return
    runs_of: dict = {}  # pair id -> [(run id, position of its first row)] in file order
    pair = df["pair"].to_numpy()
    for rid, rows in run_rows(df):
        runs_of.setdefault(plain_value(pair[rows[0]]), []).append((rid, int(rows[0])))
    directions = run_directions(df) if "direction" in df else None
    for pid, runs in runs_of.items():
        ids = [r for r, _ in runs]
        if isinstance(pid, float) and pid.is_integer():
            pid = int(pid)  # a numeric id column is read as float
        if len(runs) > 2:
            if split_segments and directions is not None and sum(directions[r] for r in ids) == 0:
                continue
            split = (" (40 CFR 1037 split runs: as many segments of each direction, with a direction column)"
                     if split_segments else "")
            refuse(where, "pair", runs[2][1] + 1,
                   f"pair id {pid!r} is held by {len(runs)} runs ({', '.join(repr(r) for r in ids)}): a pair is "
                   f"two opposite-direction runs{split}; give each pair its own id")
        if len(runs) == 2 and directions is not None and directions[ids[0]] == directions[ids[1]]:
            refuse(where, "pair", runs[1][1] + 1,
                   f"pair id {pid!r}: runs {ids[0]!r} and {ids[1]!r} both have direction {directions[ids[0]]:+d}: "
                   "a pair is two opposite-direction runs")


# --------------------------------------------------------------------------- run tables
# What every kind of campaign asks of its table of runs: one row per sample, band or marker
# with a ``run`` column.

def run_ids_of(table: pd.DataFrame) -> list:
    """Run ids in file order, as plain Python values."""
    return [plain_value(r) for r in pd.unique(table["run"])]


def run_directions(table: pd.DataFrame) -> dict:
    """run id -> +1/-1 (every run +1 when the column is absent)."""
    if "direction" not in table:
        return {r: 1 for r in run_ids_of(table)}
    return {plain_value(r): int(d) for r, d in table.groupby("run", sort=False)["direction"].first().items()}


def pairs_by_column(table: pd.DataFrame) -> list[tuple] | None:
    """Pairs of run ids by the ``pair`` column, None without it: the ids held by two runs (a
    run alone under its id is left out, and so is a group of split segments, which
    :func:`check_pair_groups` accepts in speed traces only)."""
    if "pair" not in table:
        return None
    groups = table.groupby("pair", sort=False)["run"].unique()
    return [tuple(plain_value(r) for r in g) for g in groups if len(g) == 2]


def consecutive_pairs(ids: list, directions: dict | None = None) -> list[tuple]:
    """Consecutive runs in file order; a run left without a partner is dropped.  With
    ``directions`` (run id -> +1/-1) a run pairs only with the next run of the other direction:
    of two consecutive runs the same way, the first is left without a partner."""
    pairs, i = [], 0
    while i < len(ids) - 1:
        if directions is not None and directions[ids[i]] == directions[ids[i + 1]]:
            i += 1
            continue
        pairs.append((ids[i], ids[i + 1]))
        i += 2
    return pairs


def table_pairs(table: pd.DataFrame, ids: list) -> list[tuple]:
    """A run table's opposite-direction pairs: by its ``pair`` column (:func:`pairs_by_column`),
    else consecutive runs in file order, of opposite directions when it logs ``direction``
    (:func:`consecutive_pairs`)."""
    by_column = pairs_by_column(table)
    if by_column is not None:
        return by_column
    return consecutive_pairs(ids, run_directions(table) if "direction" in table else None)


def subset_table(table: pd.DataFrame, run_ids) -> pd.DataFrame:
    """The rows of some runs, in the order of ``run_ids``, re-indexed."""
    keep = table[table["run"].isin(list(run_ids))]
    order = {r: i for i, r in enumerate(run_ids)}
    return keep.sort_values("run", key=lambda s: s.map(order), kind="stable").reset_index(drop=True)


# --------------------------------------------------------------------------- files

TRUTH_FILE = "truth.json"
"""The true parameters of a simulated campaign, beside the data file of any kind."""


def data_file(root: str | os.PathLike, name: str) -> Path:
    """``root / name``, refused when it does not exist."""
    f = Path(root) / name
    if not f.exists():
        raise CampaignError(f"{root}: {name} is missing")
    return f


def read_csv_table(path: str | os.PathLike, **kwargs) -> pd.DataFrame:
    """``pd.read_csv`` of a campaign file; an empty or unparsable file is a
    :class:`CampaignError` naming it, and so is a table whose header is separated by semicolons
    or tabs rather than commas (the file names the separator, and the decimal comma that often
    comes with semicolons, to change), whether or not pandas could parse its rows."""
    _check_separator(path)
    try:
        return pd.read_csv(path, **kwargs)
    except pd.errors.EmptyDataError:
        raise CampaignError(f"{path}: the file is empty (no header, no samples)") from None
    except (pd.errors.ParserError, UnicodeDecodeError) as e:
        raise CampaignError(f"{path}: not a readable CSV table ({str(e).strip()})") from None


def _check_separator(path: str | os.PathLike) -> None:
    """Refuse a CSV file whose header line holds semicolons or tabs and no comma."""
    try:
        with open(path, encoding="utf-8-sig", errors="replace") as f:
            header = f.readline()
    except (OSError, TypeError):  # not a plain file (a buffer, ...): pandas reports what it finds
        return
    if "," in header:
        return
    for sep, name in ((";", "semicolons"), ("\t", "tabs")):
        if sep in header:
            raise CampaignError(f"{path}: the columns are separated by {name} ({header.strip()[:60]!r}): save the "
                                "table comma-separated, with decimal points (not decimal commas)")


def read_json_object(path: str | os.PathLike) -> dict[str, Any]:
    """A JSON file holding an object, as a dict (a UTF-8 byte-order mark is skipped, as the CSV
    readers do); refused naming the file when it is not UTF-8 JSON or holds no object."""
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8-sig"))
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise CampaignError(f"{path}: not valid JSON ({e})") from None
    if not isinstance(doc, dict):
        raise CampaignError(f"{path}: holds a JSON {type(doc).__name__}, not an object of names and values")
    return doc


def read_truth(root: str | os.PathLike) -> dict[str, Any] | None:
    """The ``truth.json`` of a campaign directory (:func:`read_json_object`), None when there is none."""
    f = Path(root) / TRUTH_FILE
    return read_json_object(f) if f.exists() else None


def truth_files(truth: Mapping[str, Any] | None) -> dict[str, str]:
    """``{"truth.json": text}`` for :func:`write_atomically`, empty when ``truth`` is None."""
    if truth is None:
        return {}
    return {TRUTH_FILE: json.dumps(truth, indent=2, sort_keys=True) + "\n"}


def check_csv_format(fmt: str, what: str, name: str) -> None:
    """Refuse a file format other than CSV for a kind written only as ``name``; ``what`` names
    the kind ("an interval campaign", ...)."""
    if fmt != "csv":
        raise ValueError(f"{what} is written as {name} (fmt='csv')")


def write_atomically(root: str | os.PathLike, files: Mapping[str, str | bytes], stale: tuple[str, ...] = ()
                     ) -> Path:
    """Write ``files`` (name -> text, or bytes for a binary file) into the directory ``root``.

    The files are written to a temporary directory beside ``root`` and moved into place once
    all are written; the ``stale`` names (and the names written) are removed from ``root``
    first.  Nothing in ``root`` changes when rendering or writing a file fails.  Returns ``root``.
    """
    root = Path(root)
    root.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".campaign-", dir=root.parent))
    try:
        for name, content in files.items():
            if isinstance(content, bytes):
                (tmp / name).write_bytes(content)
            else:
                (tmp / name).write_text(content)
        root.mkdir(exist_ok=True)
        for name in tuple(stale) + tuple(files):
            (root / name).unlink(missing_ok=True)
        for f in tmp.iterdir():
            shutil.move(str(f), root / f.name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return root
