"""Seeded random campaigns for the robustness suite: valid draws over data kind (speed traces,
speed-gate intervals, distance-time, spin-down, steady state), model file,
channels present, campaign size, vehicle, wind, sample rate, run length, start speed and noise,
and invalid draws (a valid campaign's files broken in one of the ways a user's data are), each
fitted through the command line in-process (:func:`run_draw`).

A valid draw must end in a written fit (exit code 0, or 3 when its gates failed and it says
so); an invalid one in a clean refusal (exit code 2, nothing written).  Anything else, an
exception escaping :func:`bayes_roadload.cli.main` included, is recorded as a failure.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import io
import time
import traceback
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from bayes_roadload import cli
from bayes_roadload.data import Vehicle, save_campaign
from bayes_roadload.simulate import simulate_campaign
from bayes_roadload.simulate.campaign import SimulationSettings
from bayes_roadload.simulate.cases import SimulationCase

KINDS = ("traces", "distances", "spindown", "steady")
"""The kinds drawn from the draw's first random stream (kept as it was, so earlier records'
seeds still draw the same campaigns)."""
INTERVAL_SHARE = 0.2
"""Share of the valid speed-trace draws turned into interval campaigns (speed-gate times, the
split method's two windows) by a second stream of the seed."""
INVALID = ("kph_in_mps", "nan_speed", "missing_time", "negative_speed", "duplicated_time", "empty_file",
           "text_in_speed")
TRACE_MODELS = ("three_term", "four_term", "split_f0_f2")
# small car to truck: mass (kg), frontal area (m^2), length (m), AD, BD (s/m), CD0
VEHICLES = {"small_car": (950.0, 1.9, 3.8, 0.011, 1.8e-4, 0.33), "saloon": (1500.0, 2.2, 4.7, 0.010, 2.0e-4, 0.30),
            "suv": (1950.0, 2.6, 4.8, 0.012, 2.5e-4, 0.38), "van": (2800.0, 3.6, 5.5, 0.010, 2.2e-4, 0.42),
            "truck": (7500.0, 7.0, 8.0, 0.007, 1.0e-4, 0.60)}
RATES_HZ = (1.0, 2.0, 4.0, 5.0, 10.0, 20.0)


def draw(seed: int, invalid: bool = False) -> dict:
    """The parameters of draw ``seed`` (a plain dict, one CSV row of the records)."""
    rng = np.random.default_rng(seed)
    kind = "traces" if invalid else str(rng.choice(KINDS, p=[0.55, 0.15, 0.15, 0.15]))
    vehicle = str(rng.choice(list(VEHICLES)))
    d = {"seed": seed, "kind": kind, "vehicle": vehicle, "invalid": str(rng.choice(INVALID)) if invalid else "",
         "pairs": int(rng.choice([1, 1, 2, 3, 6, 12, 24], p=[0.2, 0.1, 0.25, 0.2, 0.15, 0.07, 0.03])),
         "head_wind_mps": float(np.round(rng.uniform(0.0, 5.0), 2)),
         "cross_wind_mps": float(np.round(rng.uniform(0.0, 3.0), 2)),
         "rate_hz": float(rng.choice(RATES_HZ)),
         "start_speed_mps": float(np.round(rng.uniform(22.0, 36.0), 1)),
         "stop_speed_mps": float(np.round(rng.choice([0.5, 2.0, 5.0, 8.0, 12.0]), 1)),
         "dynamics": bool(rng.random() < 0.5), "measurement_noise": bool(rng.random() < 0.8),
         "system_noise": bool(rng.random() < 0.5),
         "drop_anemometer": bool(rng.random() < 0.4), "driveline": bool(rng.random() < 0.4),
         "model": str(rng.choice(TRACE_MODELS)), "method": "nuts" if rng.random() < 0.25 else "lsq"}
    if kind == "traces" and not invalid and np.random.default_rng([seed, 1]).random() < INTERVAL_SHARE:
        # the gates 95 -> 70 and 50 -> 35 km/h lie inside the run, with the logger's 1 s either side
        d.update(kind="intervals", model="split_f0_f2", start_speed_mps=max(d["start_speed_mps"], 28.0),
                 stop_speed_mps=min(d["stop_speed_mps"], 8.0))
    if d["kind"] != "traces" or d["model"] == "split_f0_f2":
        d["method"] = "nuts"  # every other kind, and the split model, are fitted by NUTS only
    if d["method"] == "nuts":
        d["pairs"] = min(d["pairs"], 3)  # NUTS draws stay small: the suite runs on a shared CPU
    if d["model"] == "split_f0_f2":
        d["drop_anemometer"] = False
    return d


def _trace_campaign(d: dict):
    """The simulated speed-trace campaign of draw ``d`` (its ``invalid`` entry aside), simulated
    once per process: the invalid draws break copies of one campaign's files."""
    return _simulated(tuple(sorted((k, v) for k, v in d.items() if k != "invalid")))


@functools.lru_cache(maxsize=4)
def _simulated(items: tuple):
    d = dict(items)
    mass, area, length, ad, bd, cd0 = VEHICLES[d["vehicle"]]
    veh = Vehicle(mass_kg=mass, effective_mass_kg=1.03 * mass, frontal_area_m2=area, length_m=length)
    case = SimulationCase(number=900, description="robustness draw", head_wind_mps=d["head_wind_mps"],
                          cross_wind_mps=d["cross_wind_mps"], dynamics=d["dynamics"],
                          measurement_noise=d["measurement_noise"], system_noise=d["system_noise"])
    settings = SimulationSettings(vehicle=veh, sample_rate_hz=d["rate_hz"], dt_s=0.01 if d["rate_hz"] <= 10 else 0.005,
                                  start_speed_mps=d["start_speed_mps"], stop_speed_mps=d["stop_speed_mps"],
                                  max_run_duration_s=900.0, track_length_m=12000.0,
                                  coefficients={"AD": ad, "BD": bd, "CD0": cd0, "KD": 0.6})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c = simulate_campaign(case, pairs=d["pairs"], seed=d["seed"], driveline=d["driveline"], settings=settings)
    if d["drop_anemometer"]:
        c.runs = c.runs.drop(columns=["airspeed_mps", "yaw_rad"])
    return c


def write_campaign(d: dict, root: Path) -> Path:
    """Simulate draw ``d`` and write its campaign directory (broken as ``d["invalid"]`` says)."""
    root = Path(root)
    if d["kind"] == "spindown":
        from bayes_roadload.data.spindown import save_spindown
        from bayes_roadload.simulate.spindown import simulate_spindown

        save_spindown(simulate_spindown(tests_per_wheel=min(d["pairs"], 4), seed=d["seed"]), root)
        return root
    if d["kind"] == "steady":
        from bayes_roadload.data.steady import save_steady
        from bayes_roadload.simulate.steady import simulate_steady

        save_steady(simulate_steady(9, pairs=min(d["pairs"], 3), seed=d["seed"]), root)
        return root
    c = _trace_campaign(d)
    if d["kind"] == "distances":
        from bayes_roadload.simulate.distances import distance_campaign_from_traces

        # markers every 100 m up to 1 km, within the reach of the shortest run (a high stop speed
        # ends a run early)
        reach = float(c.runs.groupby("run")["distance_m"].max().min())
        markers = np.arange(100.0, min(1000.0, reach) + 1.0, 100.0)
        c = distance_campaign_from_traces(c, tuple(float(x) for x in markers), seed=d["seed"])
    if d["kind"] == "intervals":
        from bayes_roadload.simulate.intervals import interval_campaign_from_traces

        c = interval_campaign_from_traces(c)
    save_campaign(c, root)
    if d["invalid"]:
        _break(root / "runs.csv", d["invalid"], np.random.default_rng(d["seed"] + 1))
    return root


def _break(path: Path, how: str, rng) -> None:
    runs = pd.read_csv(path)
    i = int(rng.integers(1, len(runs) - 1))
    if how == "kph_in_mps":
        runs["speed_mps"] = runs["speed_mps"] * 3.6
    elif how == "nan_speed":
        runs.loc[i, "speed_mps"] = np.nan
    elif how == "missing_time":
        runs = runs.drop(columns=["time_s"])
    elif how == "negative_speed":
        runs.loc[i, "speed_mps"] = -runs.loc[i, "speed_mps"]
    elif how == "duplicated_time":
        runs = pd.concat([runs.iloc[: i + 1], runs.iloc[i:]], ignore_index=True)
    elif how == "empty_file":
        runs = runs.iloc[:0]
    elif how == "text_in_speed":
        runs["speed_mps"] = runs["speed_mps"].astype(object)
        runs.loc[i, "speed_mps"] = "n/a"
    runs.to_csv(path, index=False)


def fit_args(d: dict, campaign: Path, out: Path) -> list[str]:
    args = ["fit", str(campaign), "--out", str(out), "--method", d["method"]]
    if d["kind"] == "traces":
        args += ["--model", d["model"]]
    if d["method"] == "nuts":
        args += ["--warmup", "100", "--draws", "100", "--chains", "1", "--no-progress"]
    return args


def run_draw(d: dict, workdir: Path) -> dict:
    """Simulate, write and fit draw ``d`` in ``workdir``; the record: outcome ("fitted",
    "gates_failed", "refused", or "FAILURE: ..."), exit code, wall time and the message."""
    workdir = Path(workdir)
    campaign, out = workdir / f"c{d['seed']}", workdir / f"o{d['seed']}"
    t0 = time.perf_counter()
    rc, message = None, ""
    try:
        write_campaign(d, campaign)
        buf_out, buf_err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(buf_out), contextlib.redirect_stderr(buf_err), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rc = cli.main(fit_args(d, campaign, out))
        message = buf_err.getvalue().strip().splitlines()[-1] if buf_err.getvalue().strip() else ""
    except SystemExit as e:
        rc, message = e.code, "SystemExit"
    except Exception as e:  # noqa: BLE001 - every escaping exception is a finding of the suite
        message = f"{type(e).__name__}: {e} | " + traceback.format_exc().strip().splitlines()[-3]
    written = (out / "summary.csv").exists()
    if d["invalid"]:
        outcome = "refused" if rc == 2 and not out.exists() else f"FAILURE: rc={rc}, out written={out.exists()}"
    elif rc in (0, 3) and written:
        outcome = "fitted" if rc == 0 else "gates_failed"
    else:
        outcome = f"FAILURE: rc={rc}, summary written={written}"
    return dict(d, outcome=outcome, rc=rc, time_s=round(time.perf_counter() - t0, 2), message=message[:300])
