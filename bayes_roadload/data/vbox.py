"""Import Racelogic VBOX "Coastdown" CSV exports as interval campaigns.

A VBOX Coastdown export (layout as documented with the sample files: a header block, then a
table ``Run-Use, Heading, Run, Time (s), Distance (m), Start Time, Max Decel (g), <t_1> ...
<t_K>, Notes``, then VBOX's summary rows and the same table split by heading) gives per run the
time to coast through each of K consecutive speed bands.  **The gate speeds are not in the
file**: they are an argument (km/h, descending, one list per band-column group), by default
:data:`bayes_roadload.config.VBOX_DEFAULT_GATES_KPH` chosen by the number of band columns.
Whatever their origin they are checked against every run:

- the band times must add up to the run's logged ``Time (s)`` (within
  ``config.VBOX_TIME_TOLERANCE_S``; otherwise the columns are not consecutive bands);
- the distance the bands imply, sum of band time x band mid-speed (the mean speed over a
  5 km/h band is its mid-speed to ~0.1 %), must match the logged ``Distance (m)``: the median
  relative error over the runs of a column group within ``config.VBOX_DISTANCE_TOLERANCE`` or the
  import is refused (wrong gates, or m/s given for km/h, are several per cent off), and runs
  beyond 3 x that are flagged in the import report.

Interleaved files (high- and low-speed runs in one table, each run filling one group of
columns) take one gate list per group.  ``Run-Use`` becomes the ``valid`` column (On = 1),
``Heading`` the ``direction`` (+ = +1), ``Start Time`` ``start_time_of_day_s``; opposite-heading
runs of the same file and window that follow each other form the pairs.  A Kestrel weather log
(``--weather``) adds each run's temperature, station pressure and relative humidity (the sample
nearest the run's start, within ``max_weather_gap_s``).
"""

from __future__ import annotations

import io
import math
import os
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np
import pandas as pd

from .. import config
from .checks import CampaignError
from .vehicle import Anemometer, Vehicle
from .intervals import IntervalCampaign

KPH = config.KPH_TO_MPS
FIXED_COLUMNS = ("Run-Use", "Heading", "Run", "Time (s)", "Distance (m)", "Start Time", "Max Decel (g)")


@dataclass
class VboxTable:
    """The run table of one VBOX export, as read (no gates applied yet)."""

    path: Path
    test_date: str
    runs: pd.DataFrame           # the fixed columns, one row per run
    bands_s: np.ndarray          # [runs, K] band times, NaN where a run leaves a column empty
    line_of_run: list[int]       # 1-based line of each run in the file


@dataclass
class ImportReport:
    """What the importer checked and flagged."""

    files: list[str] = field(default_factory=list)
    gates_kph: dict[str, list[list[float]]] = field(default_factory=dict)
    gates_source: dict[str, str] = field(default_factory=dict)
    distance_median_error: dict[str, float] = field(default_factory=dict)
    flags: list[dict] = field(default_factory=list)
    weather: str = "none: reference conditions (100 kPa, 293.2 K)"

    def lines(self) -> list[str]:
        out = []
        for f in self.files:
            for g, gates in enumerate(self.gates_kph[f]):
                key = f"{f}#{g}"
                out.append(f"{Path(f).name}: gates {', '.join(f'{x:g}' for x in gates)} km/h "
                           f"({self.gates_source[f]}); band distance vs logged: median error "
                           f"{100 * self.distance_median_error[key]:+.2f} %")
        out += [f"flag: run {x['run']}: {x['reason']}" for x in self.flags]
        out.append(f"weather: {self.weather}")
        return out

    def to_dict(self) -> dict:
        return {"files": self.files, "gates_kph": self.gates_kph, "gates_source": self.gates_source,
                "distance_median_error": self.distance_median_error, "flags": self.flags, "weather": self.weather}


def _err(path, line, what) -> CampaignError:
    return CampaignError(f"{path}" + (f", line {line}" if line else "") + f": {what}")


def read_vbox_table(path: str | os.PathLike) -> VboxTable:
    """Read the first run table of a VBOX Coastdown CSV export (module docstring)."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except UnicodeDecodeError:
        lines = path.read_text(encoding="latin-1").splitlines()
    header = next((i for i, line in enumerate(lines) if line.startswith("Run-Use,")), None)
    if header is None:
        raise _err(path, None, "no 'Run-Use,Heading,Run,...' table: not a VBOX Coastdown export")
    cols = lines[header].split(",")
    if tuple(cols[:7]) != FIXED_COLUMNS:
        raise _err(path, header + 1, f"expected the columns {', '.join(FIXED_COLUMNS)} first, found {cols[:7]}")
    named = [c for c in cols[7:] if c.strip() and c != "Notes"]
    if named:
        raise _err(path, header + 1, f"named columns {named} after Max Decel (g): only the unnamed band-time "
                                     "columns of the split and standard exports are supported")
    n_bands = len(cols) - 8 if cols[-1] == "Notes" else len(cols) - 7
    if n_bands < 1:
        raise _err(path, header + 1, "no band-time columns")
    body = []
    line_of_run = []
    for i in range(header + 1, len(lines)):
        parts = lines[i].split(",")
        if parts[0] not in ("On", "Off"):
            break
        body.append(parts)
        line_of_run.append(i + 1)
    if not body:
        raise _err(path, header + 2, "the run table is empty")
    rows, bands = [], np.full((len(body), n_bands), np.nan)
    for k, (parts, line) in enumerate(zip(body, line_of_run)):
        if parts[1] not in ("+", "-"):
            raise _err(path, line, f"Heading {parts[1]!r} is not + or -")
        try:
            total, dist = float(parts[3]), float(parts[4])
            run = int(parts[2])
        except ValueError as e:
            raise _err(path, line, f"Run, Time (s) or Distance (m) is not a number ({e})") from e
        clock_s = _clock_seconds(parts[5])
        if clock_s is False:
            raise _err(path, line, f"Start Time {parts[5]!r} is neither hh:mm:ss.sss nor mm:ss.s")
        for j in range(n_bands):
            cell = parts[7 + j] if 7 + j < len(parts) else ""
            if cell.strip():
                try:
                    bands[k, j] = float(cell)
                except ValueError as e:
                    raise _err(path, line, f"band column {j + 1}: {cell!r} is not a number") from e
        rows.append({"valid": 1 if parts[0] == "On" else 0, "direction": 1 if parts[1] == "+" else -1, "vbox_run": run,
                     "total_time_s": total, "distance_m": dist, "start_time_of_day_s": clock_s})
    first = lines[0]
    date = first.split(":", 1)[1].strip() if first.startswith("Test Date") else ""
    return VboxTable(path, date, pd.DataFrame(rows), bands, line_of_run)


def _clock_seconds(text: str):
    """``hh:mm:ss.sss`` -> seconds since midnight; ``mm:ss.s`` (some exports drop the hour) ->
    None (the time of day is unknown: not guessed); anything else -> False."""
    for fmt, full in (("%H:%M:%S.%f", True), ("%H:%M:%S", True), ("%M:%S.%f", False)):
        try:
            t = datetime.strptime(text.strip(), fmt)
        except ValueError:
            continue
        return t.hour * 3600 + t.minute * 60 + t.second + t.microsecond / 1e6 if full else None
    return False


def parse_gates(text: str) -> list[list[float]]:
    """``"95,90,85,80,75,70"`` -> [[95, ...]]; groups of an interleaved file joined by ``/``."""
    groups = []
    for chunk in text.split("/"):
        try:
            g = [float(x) for x in chunk.split(",") if x.strip()]
        except ValueError as e:
            raise ValueError(f"gate speeds {chunk!r}: comma-separated numbers in km/h expected") from e
        if len(g) < 2 or any(b >= a for a, b in zip(g, g[1:])):
            raise ValueError(f"gate speeds {chunk!r}: at least two, strictly descending (km/h)")
        groups.append(g)
    return groups


def _group_columns(gates: list[list[float]], n_bands: int, path) -> list[slice]:
    sizes = [len(g) - 1 for g in gates]
    if sum(sizes) != n_bands:
        raise _err(path, None, f"the file has {n_bands} band columns but the gate lists give "
                               f"{' + '.join(map(str, sizes))} bands: pass --gates with matching lists "
                               "(one per column group, km/h, descending)")
    out, start = [], 0
    for s in sizes:
        out.append(slice(start, start + s))
        start += s
    return out


def read_kestrel(path: str | os.PathLike) -> pd.DataFrame:
    """A Kestrel weather-meter CSV log as ``datetime, temperature_k, pressure_pa`` (station
    pressure) and, when the log has its ``Rel. Hum.`` column (percent), ``relative_humidity_pct``;
    the log's ``Time`` is ``dd/mm/yyyy hh:mm``."""
    path = Path(path)
    text = path.read_text(encoding="latin-1").splitlines()
    header = next((i for i, line in enumerate(text) if line.startswith("Time,")), None)
    if header is None:
        raise _err(path, None, "no 'Time,Temp,...' header: not a Kestrel log")
    df = pd.read_csv(io.StringIO("\n".join([text[header]] + text[header + 2:])))
    if "Temp" not in df or "Station P." not in df:
        raise _err(path, header + 1, "the log needs Temp (Celsius) and Station P. (mb) columns")
    t = pd.to_datetime(df["Time"], format="%d/%m/%Y %H:%M", errors="coerce")
    out = pd.DataFrame({"datetime": t, "temperature_k": pd.to_numeric(df["Temp"], errors="coerce") + 273.15,
                        "pressure_pa": pd.to_numeric(df["Station P."], errors="coerce") * 100.0})
    humidity = pd.to_numeric(df["Rel. Hum."], errors="coerce") if "Rel. Hum." in df else None
    if humidity is not None and humidity.notna().any():
        out["relative_humidity_pct"] = humidity
    return out.dropna().sort_values("datetime").reset_index(drop=True)


def import_vbox(paths, vehicle: Vehicle, *, gates: list[str | None] | None = None, weather=None,
                max_weather_gap_s: float = 600.0, meta: dict | None = None) -> tuple[IntervalCampaign, ImportReport]:
    """Read VBOX Coastdown exports into one interval campaign (module docstring).

    Parameters
    ----------
    paths : one or more export files (e.g. the high and the low window of one vehicle).
    vehicle : the vehicle (its mass is not in the exports).
    gates : one gate text per file (:func:`parse_gates`), ``None`` entries (or no list) for the
        documented defaults by band count.
    weather : optional Kestrel log (:func:`read_kestrel`) for temperature, pressure and humidity.
    max_weather_gap_s : largest distance in time from a run's start to a weather sample.

    Returns
    -------
    (IntervalCampaign, ImportReport)
    """
    paths = [Path(p) for p in ([paths] if isinstance(paths, (str, os.PathLike)) else paths)]
    gates = list(gates or [None] * len(paths))
    if len(gates) != len(paths):
        raise ValueError(f"{len(paths)} files but {len(gates)} gate lists: give one per file (an interleaved "
                         "file's groups joined by '/')")
    report = ImportReport(weather="none: reference conditions (100 kPa, 293.2 K)")
    rows = []
    run_meta = []
    for path, gate_text in zip(paths, gates):
        table = read_vbox_table(path)
        n_bands = table.bands_s.shape[1]
        if gate_text is None:
            if n_bands not in config.VBOX_DEFAULT_GATES_KPH:
                raise _err(path, None, f"{n_bands} band columns and no default gate set for that count: "
                                       "pass --gates (km/h, descending)")
            groups = [list(g) for g in config.VBOX_DEFAULT_GATES_KPH[n_bands]]
            report.gates_source[str(path)] = f"default for {n_bands} band columns"
        else:
            groups = parse_gates(gate_text)
            report.gates_source[str(path)] = "given"
        report.files.append(str(path))
        report.gates_kph[str(path)] = groups
        slices = _group_columns(groups, n_bands, path)
        stem = path.stem
        group_errors: dict[int, list[float]] = {g: [] for g in range(len(groups))}
        for k, run in table.runs.iterrows():
            line = table.line_of_run[k]
            filled = [g for g, s in enumerate(slices) if np.all(np.isfinite(table.bands_s[k, s]))]
            empty = [g for g, s in enumerate(slices) if np.all(~np.isfinite(table.bands_s[k, s]))]
            if len(filled) != 1 or len(filled) + len(empty) != len(slices):
                raise _err(path, line, "a run must fill exactly one group of band columns completely "
                                       f"(groups of {[s.stop - s.start for s in slices]} columns)")
            g = filled[0]
            t = table.bands_s[k, slices[g]]
            gate = np.asarray(groups[g]) * KPH
            if abs(t.sum() - run["total_time_s"]) > config.VBOX_TIME_TOLERANCE_S:
                raise _err(path, line, f"band times add up to {t.sum():.2f} s but the run's Time (s) is "
                                       f"{run['total_time_s']:.2f} s: the columns are not consecutive bands")
            implied = float(np.sum(t * 0.5 * (gate[:-1] + gate[1:])))
            rel = (implied - run["distance_m"]) / run["distance_m"]
            group_errors[g].append(rel)
            rid = f"{stem}-{int(run['vbox_run'])}"
            if abs(rel) > 3 * config.VBOX_DISTANCE_TOLERANCE:
                report.flags.append({"run": rid, "reason": f"band distance {implied:.1f} m vs logged "
                                                           f"{run['distance_m']:.1f} m ({100 * rel:+.1f} %)"})
            window = f"{groups[g][0]:g}-{groups[g][-1]:g}kph"
            run_meta.append((rid, stem, window, int(run["direction"]), table.test_date, run["start_time_of_day_s"]))
            for j in range(len(t)):
                rows.append({"run": rid, "window": window, "direction": int(run["direction"]),
                             "valid": int(run["valid"]), "speed_start_mps": gate[j], "speed_end_mps": gate[j + 1],
                             "interval_s": float(t[j]), "run_distance_m": float(run["distance_m"]),
                             "start_time_of_day_s": run["start_time_of_day_s"]})
        for g, errs in group_errors.items():
            med = float(np.median(errs)) if errs else math.nan
            report.distance_median_error[f"{path}#{g}"] = med
            if errs and abs(med) > config.VBOX_DISTANCE_TOLERANCE:
                raise _err(path, None, f"gate speeds {', '.join(f'{x:g}' for x in groups[g])} km/h do not reproduce "
                                       f"the logged distances (median error {100 * med:+.2f} % over "
                                       f"{len(errs)} runs, tolerance {100 * config.VBOX_DISTANCE_TOLERANCE:.1f} %): "
                                       "wrong gates, or not km/h; pass the logger's gates with --gates")
    df = pd.DataFrame(rows)
    df["pair"] = df["run"].map(_pairs(run_meta))
    if df["start_time_of_day_s"].isna().any():
        # a Start Time without its hour (mm:ss.s): the time of day is not known, not guessed
        df = df.drop(columns="start_time_of_day_s")
        report.flags.append({"run": "all", "reason": "Start Time without the hour (mm:ss.s) in some export: "
                                                     "start_time_of_day_s left out, no weather matching"})
        run_meta = [m[:5] + (None,) for m in run_meta]
    if weather is not None:
        df, report.weather = _add_weather(df, run_meta, read_kestrel(weather), max_weather_gap_s, weather)
    meta = dict(meta or {})
    meta.setdefault("source", ", ".join(p.name for p in paths))
    camp = IntervalCampaign(df, vehicle, Anemometer(), None, None, meta)
    return camp, report


def _pairs(run_meta) -> dict:
    """Consecutive opposite-heading runs of the same file and window -> a pair id; a run that
    finds no partner gets its own id (unpaired)."""
    out, waiting, n = {}, {}, 0
    for rid, stem, window, direction, _date, _clock in run_meta:
        key = (stem, window)
        other = waiting.get(key)
        if other is not None and other[1] != direction:
            n += 1
            out[other[0]] = out[rid] = f"{stem}-{window}-p{n}"
            waiting[key] = None
        else:
            if other is not None:
                out[other[0]] = f"{other[0]}-unpaired"
            waiting[key] = (rid, direction)
    for other in waiting.values():
        if other is not None:
            out[other[0]] = f"{other[0]}-unpaired"
    return out


def _add_weather(df, run_meta, log: pd.DataFrame, max_gap_s: float, source) -> tuple[pd.DataFrame, str]:
    ambient = [c for c in ("temperature_k", "pressure_pa", "relative_humidity_pct") if c in log]
    values, missing = {c: {} for c in ambient}, []
    times = log["datetime"].to_numpy()
    for rid, _stem, _window, _d, date, clock in run_meta:
        if clock is None:
            missing.append(rid)
            continue
        try:
            day = datetime.strptime(date.split()[0], "%d/%m/%Y")
        except (ValueError, IndexError):
            missing.append(rid)
            continue
        when = np.datetime64(day) + np.timedelta64(int(round(clock)), "s")
        k = int(np.argmin(np.abs(times - when))) if len(times) else -1
        if k < 0 or abs((times[k] - when) / np.timedelta64(1, "s")) > max_gap_s:
            missing.append(rid)
            continue
        for c in ambient:
            values[c][rid] = float(log[c].iloc[k])
    if missing:
        return df, (f"{Path(source).name} does not cover {len(missing)} of {len(run_meta)} runs (first: "
                    f"{missing[0]}); not used: reference conditions (100 kPa, 293.2 K)")
    df = df.copy()
    for c in ambient:
        df[c] = df["run"].map(values[c])
    return df, f"{Path(source).name}: nearest sample to each run's start"


def write_vbox_csv(campaign: IntervalCampaign, path: str | os.PathLike, *, test_date: str = "01/01/2026 12:00",
                   start_clock_s: float = 43200.0, run_spacing_s: float = 120.0) -> Path:
    """Write an interval campaign in the VBOX Coastdown export layout (module docstring), for
    synthetic examples and tests: one window per file (refused otherwise), band times rounded to
    0.01 s like the logger, the distance from band time x band mid-speed, no gate speeds."""
    df = campaign.intervals
    windows = df["window"].unique() if "window" in df else ["all"]
    if len(windows) != 1:
        raise ValueError(f"a VBOX export holds one window; this campaign has {len(windows)}")
    runs = campaign.run_table()
    k = int(runs["bands"].max())
    lines = [f"Test Date: {test_date}", "Time zone,UTC", "Test Date,", "Trigger", "Requires Trigger,Off",
             "Trigger Channel,", "Deceleration", "Ignore runs that exceed (g),0.20", "Smooth Level,4",
             "Speed Quality", "Check,Off", "Speed threshold (km/h),0.10", "In (s),0.05", "",
             ",".join(FIXED_COLUMNS + ("",) * k + ("Notes",))]
    for n, (rid, g) in enumerate(df.groupby("run", sort=False)):
        t = np.round(g["interval_s"].to_numpy(float), 2)
        mid = 0.5 * (g["speed_start_mps"].to_numpy() + g["speed_end_mps"].to_numpy())
        clock = start_clock_s + n * run_spacing_s
        hh, mm, ss = int(clock // 3600), int(clock % 3600 // 60), clock % 60
        valid = "On" if ("valid" not in g or g["valid"].iloc[0] == 1) else "Off"
        heading = "+" if ("direction" not in g or g["direction"].iloc[0] > 0) else "-"
        lines.append(",".join([valid, heading, str(n + 1), f"{t.sum():.2f}", f"{np.sum(t * mid):.2f}",
                               f"{hh:02d}:{mm:02d}:{ss:06.3f}", "0.05"] + [f"{x:.2f}" for x in t] + [""]))
    path = Path(path)
    path.write_text("\ufeff" + "\n".join(lines) + "\n", encoding="utf-8")
    return path
