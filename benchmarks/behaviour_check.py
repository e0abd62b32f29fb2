"""Behaviour check: the same command line gives the same ``summary.csv`` before and after a change.

Runs ``bayes-roadload demo --seed 1`` and one ``fit`` per data kind (speed traces by NUTS and by
least squares, interval times, distance-time records, spin-downs, steady-state tests, the
driveline channel) on campaigns simulated at fixed seeds, through the command line, and
compares every ``summary.csv`` with the committed record under
``benchmarks/records/behaviour/<name>/summary.csv``.

A refactor that keeps every floating-point operation in its order reproduces the records
bit for bit ("identical").  One that reorders arithmetic changes the NUTS trajectories (they are
chaotic in the last bit), so the script also reports, per parameter, the difference of the
posterior means in units of their Monte Carlo standard errors (``mcse_mean`` of both runs
combined); |z| < 4 for every parameter is "same within Monte Carlo error".

Run: ``python benchmarks/behaviour_check.py --record`` (write the records) or
``python benchmarks/behaviour_check.py`` (compare; exit 1 on a difference beyond MC error).
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import tempfile
import warnings
from pathlib import Path

import pandas as pd

RECORDS = Path(__file__).parent / "records" / "behaviour"
SMALL = ["--warmup", "300", "--draws", "300", "--chains", "2", "--no-progress"]


def _campaigns(work: Path) -> dict[str, Path]:
    """The simulated campaigns of the check, written under ``work``."""
    from bayes_roadload.data import save_campaign
    from bayes_roadload.data.spindown import save_spindown
    from bayes_roadload.data.steady import save_steady
    from bayes_roadload.simulate import simulate_campaign
    from bayes_roadload.simulate.distances import distance_campaign_from_traces
    from bayes_roadload.simulate.intervals import interval_campaign_from_traces
    from bayes_roadload.simulate.spindown import simulate_spindown
    from bayes_roadload.simulate.steady import simulate_steady

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        traces = simulate_campaign(9, pairs=2, seed=5, driveline=True)
        paths = {"traces": save_campaign(traces, work / "traces")}
        paths["intervals"] = save_campaign(interval_campaign_from_traces(simulate_campaign(9, pairs=3, seed=6)),
                                           work / "intervals")
        paths["distances"] = save_campaign(
            distance_campaign_from_traces(simulate_campaign(9, pairs=2, seed=7), list(range(100, 1400, 100)),
                                          timing_sd_s=0.02, seed=7), work / "distances")
        paths["spindown"] = save_spindown(simulate_spindown(tests_per_wheel=2, seed=8), work / "spindown")
        paths["steady"] = save_steady(simulate_steady(9, pairs=1, seed=9), work / "steady")
    return paths


def _commands(c: dict[str, Path], out: Path) -> dict[str, list[str]]:
    """The command lines of the check (``--force``: ``--keep DIR`` may hold an earlier run's outputs)."""
    return {name: [*argv, "--force"] for name, argv in {
        "demo_seed1": ["demo", "--seed", "1", "--out", str(out / "demo_seed1")],
        "traces_nuts": ["fit", str(c["traces"]), "--model", "four_term", *SMALL, "--out", str(out / "traces_nuts")],
        "traces_lsq": ["fit", str(c["traces"]), "--method", "lsq", "--out", str(out / "traces_lsq")],
        "intervals": ["fit", str(c["intervals"]), *SMALL, "--out", str(out / "intervals")],
        "distances": ["fit", str(c["distances"]), *SMALL, "--out", str(out / "distances")],
        "spindown": ["fit", str(c["spindown"]), *SMALL, "--out", str(out / "spindown")],
        "steady": ["fit", str(c["steady"]), *SMALL, "--out", str(out / "steady")],
        "driveline": ["fit-driveline", str(c["traces"]), *SMALL, "--out", str(out / "driveline")],
    }.items()}


def _summary_of(out: Path, name: str) -> Path:
    return out / name / ("fit_nuts" if name.startswith("demo") else "") / "summary.csv"


def compare(old: pd.DataFrame, new: pd.DataFrame) -> dict:
    """Identical text, or the largest |difference of means| / combined MCSE over parameters."""
    o, n = old.set_index("parameter"), new.set_index("parameter")
    result = {"same_rows": list(o.index) == list(n.index), "identical": o.equals(n), "max_abs_z": 0.0, "worst": None}
    if result["identical"] or not result["same_rows"] or "mean" not in o:
        return result
    for p in o.index:
        d = float(n.loc[p, "mean"]) - float(o.loc[p, "mean"])
        if d == 0.0:
            continue
        if "mcse_mean" in o and "mcse_mean" in n:
            se = math.hypot(float(o.loc[p, "mcse_mean"]), float(n.loc[p, "mcse_mean"]))
        elif "sd" in o:  # least squares: no Monte Carlo error, only round-off
            se = 1e-9 * max(abs(float(o.loc[p, "mean"])), 1e-12)
        else:
            se = float("nan")
        z = abs(d) / se if se > 0 else float("inf")
        if not z <= result["max_abs_z"]:
            result["max_abs_z"], result["worst"] = z, p
    return result


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--record", action="store_true", help="write the records instead of comparing")
    ap.add_argument("--only", nargs="+", default=None, help="names to run (default: all)")
    ap.add_argument("--keep", default=None, help="keep the outputs in this directory")
    args = ap.parse_args(argv)

    from bayes_roadload.cli import main as cli

    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="behaviour-"))
    camps = _campaigns(work / "campaigns")
    cmds = _commands(camps, work / "fits")
    report = {}
    for name, cmd in cmds.items():
        if args.only and name not in args.only:
            continue
        rc = cli(cmd)
        path = _summary_of(work / "fits", name)
        new = pd.read_csv(path)
        record = RECORDS / name / "summary.csv"
        if args.record:
            record.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, record)
            report[name] = {"rc": rc, "recorded": str(record)}
        else:
            report[name] = {"rc": rc, **compare(pd.read_csv(record), new)}
    print(json.dumps(report, indent=2))
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    if args.record:
        return 0
    bad = [k for k, r in report.items() if not (r["identical"] or (r["same_rows"] and r["max_abs_z"] < 4.0))]
    print("behaviour: " + ("same" if not bad else f"DIFFERENT in {', '.join(bad)}"))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
