"""Planning study: regenerates ``docs/planning.md`` (and ``docs/planning/*.csv``).

1. ``thesis``: the thesis' planning tables 8.6, 8.8, 8.10 replayed from their summary numbers
   (table 8.3, 8.7, 8.9 spreads of 18 pairs) beside ours (:func:`studies.planning_report.thesis_replay_table`).
2. ``simulated``: the same pilot (3-term, table 8.3) through the full machinery: future
   campaigns at thesis case 14 conditions, run-to-run spreads from the pilot, hierarchical
   MAP + Laplace refits.
3. ``nuts``: Laplace half-widths against NUTS on the same future campaigns at two sizes.
4. ``yaw``: pairs needed for K_D against the mean |yaw| (cross wind 0-4 m/s).
5. ``constrained``: 4-term, 3-term (K_D fixed at the tunnel's 0.614) and 2-term (C_D0 fixed at
   0.39) refits of the same campaigns whose truth is the thesis' windy 4-term result (table
   8.11): pairs needed and the bias the constraint costs.

A section whose CSV exists is not re-run unless named in ``--rerun``.  Every fit goes through
:func:`bayes_roadload.analysis.batch.run_batch` (a local Dask cluster of ``--workers`` processes,
or ``--scheduler ADDR``).  Prints a JSON
summary of timings.

Run::

    python benchmarks/planning_study.py --workers 2 [--rerun simulated nuts nuts_laplace yaw constrained]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload import config  # noqa: E402
from bayes_roadload.analysis import planning as pl  # noqa: E402
from bayes_roadload.analysis.batch import batch_client, run_batch  # noqa: E402
from studies import planning_report as report  # noqa: E402
from studies.thesis_tables import THESIS_PILOT_PAIRS  # noqa: E402
DOC = ROOT / "docs" / "planning.md"
DATA = ROOT / "docs" / "planning"
SECTIONS = ("thesis", "simulated", "nuts", "yaw", "constrained")
RERUN = SECTIONS + ("nuts_laplace",)

THESIS_3TERM = {"AD": 0.0095, "BD": 0.214e-3, "CD0": 0.393}  # table 8.3 means
WINDY_4TERM = {"AD": 0.0100, "BD": 0.221e-3, "CD0": 0.378, "KD": 0.977}  # table 8.11
SPREADS_4TERM = {"AD": 3.2, "BD": 15.2, "CD0": 3.1}  # table 8.9


def _cached(name: str, rerun: bool, compute) -> pd.DataFrame:
    path = DATA / f"{name}.csv"
    if path.exists() and not rerun:
        return pd.read_csv(path)
    df = compute()
    DATA.mkdir(parents=True, exist_ok=True)
    df.to_csv(path, index=False)
    return df


def _conditions(case=14, pairs=6, seed=0, cross_wind=None):
    from bayes_roadload.simulate import get_case, simulate_campaign

    c = get_case(case)
    if cross_wind is not None:
        c = dataclasses.replace(c, number=100 + int(round(10 * cross_wind)), cross_wind_mps=float(cross_wind))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return simulate_campaign(c, pairs=pairs, seed=seed)


def _fmt(x, digits=3):
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "-" if x is None or np.isnan(x) else "inf"
    return f"{x:.{digits}g}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--scheduler", default=None, metavar="ADDR",
                    help="address of a running Dask scheduler (default: a local cluster of --workers processes)")
    ap.add_argument("--rerun", nargs="*", default=[], choices=RERUN,
                    help="recompute these sections (nuts_laplace: only the Laplace arm of the NUTS check)")
    ap.add_argument("--only", nargs="*", default=list(SECTIONS), choices=SECTIONS)
    ap.add_argument("--simulations", type=int, default=8)
    ap.add_argument("--nuts-simulations", type=int, default=5)
    args = ap.parse_args(argv)
    timings = {}
    frames = {}
    # every study here plans the data's share of the intervals (type_b=False): the thesis'
    # planning tables and these records have no Type B uncertainty (docs/planning.md section 8)
    with batch_client(args.workers, args.scheduler) as pool:
        if "thesis" in args.only:
            t0 = time.perf_counter()
            frames["thesis"] = _cached("thesis_replay", "thesis" in args.rerun, report.thesis_replay_table)
            timings["thesis_s"] = time.perf_counter() - t0
        if "simulated" in args.only or "nuts" in args.only:
            pilot = pl.population_from_pilot(THESIS_3TERM, {"AD": 4.3, "BD": 23.1, "CD0": 4.3}, THESIS_PILOT_PAIRS,
                                             _conditions(), "three_term", seed=1)
        if "simulated" in args.only:
            t0 = time.perf_counter()
            frames["simulated"] = _cached("simulated_records", "simulated" in args.rerun, lambda: run_batch(
                pl.plan_jobs(pilot, (2, 6, 24), simulations=args.simulations, seed=1, type_b=False,
                             tags={"study": "simulated"}), pool))
            timings["simulated_s"] = time.perf_counter() - t0
        if "nuts" in args.only:
            t0 = time.perf_counter()

            def nuts_compute():
                jobs = []
                sampler = dataclasses.replace(config.DEFAULT_SAMPLER, num_samples=500)
                for method in ("laplace", "nuts"):
                    for job in pl.plan_jobs(pilot, (2, 6), simulations=args.nuts_simulations, seed=2, method=method,
                                            type_b=False, tags={"study": "nuts"}):
                        jobs.append(dataclasses.replace(job, sampler=sampler))
                return run_batch(jobs, pool)
            if "nuts_laplace" in args.rerun and (DATA / "nuts_check_records.csv").exists():
                # keep the (slow) NUTS arm, refit the same campaigns by Laplace
                old = pd.read_csv(DATA / "nuts_check_records.csv")
                lap = run_batch(pl.plan_jobs(pilot, (2, 6), simulations=args.nuts_simulations, seed=2, type_b=False,
                                             tags={"study": "nuts"}), pool)
                pd.concat([lap, old[old["method"] == "nuts"]], ignore_index=True).to_csv(
                    DATA / "nuts_check_records.csv", index=False)
            frames["nuts"] = _cached("nuts_check_records", "nuts" in args.rerun, nuts_compute)
            timings["nuts_s"] = time.perf_counter() - t0
        if "yaw" in args.only:
            t0 = time.perf_counter()

            def yaw_compute():
                jobs = []
                for w in (0.0, 1.0, 2.0, 4.0):
                    pop = pl.population_from_pilot(WINDY_4TERM, {}, 18, _conditions(18, 4, 3, cross_wind=w),
                                                   "four_term", seed=3)
                    jobs += pl.plan_jobs(pop, (1, 4, 16), simulations=args.simulations, seed=3, type_b=False,
                                         tags={"study": "yaw", "cross_wind_mps": w})
                return run_batch(jobs, pool)
            frames["yaw"] = _cached("yaw_records", "yaw" in args.rerun, yaw_compute)
            timings["yaw_s"] = time.perf_counter() - t0
        if "constrained" in args.only:
            t0 = time.perf_counter()

            def constrained_compute():
                pop = pl.population_from_pilot(WINDY_4TERM, SPREADS_4TERM, 9, _conditions(16, 4, 4), "four_term", seed=4)
                jobs = []
                for model in ("four_term", "three_term", "two_term_tyres"):
                    jobs += pl.plan_jobs(pop, (2, 6, 24), simulations=args.simulations, seed=4, model=model, type_b=False,
                                         tags={"study": "constrained"})
                return run_batch(jobs, pool)
            frames["constrained"] = _cached("constrained_records", "constrained" in args.rerun, constrained_compute)
            timings["constrained_s"] = time.perf_counter() - t0
    DOC.write_text(markdown(frames))
    print(json.dumps({"timings_s": {k: round(v, 1) for k, v in timings.items()},
                      "records": {k: int(len(v)) for k, v in frames.items()}}, indent=2))
    return 0


def markdown(frames: dict) -> str:
    return "\n".join(report.planning_markdown(frames)) + "\n"


if __name__ == "__main__":
    sys.exit(main())
