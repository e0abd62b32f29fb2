"""The batch door's local workers on planning refits: page faults and compilation.

Runs ``--refits`` planning refits of ``--pairs`` pairs (``plan``'s jobs, from the posterior of
``--fit-dir``) on a 2-worker ``LocalCluster`` (:func:`~bayes_roadload.analysis.batch.batch_client`)
in three arms, each with its own cluster and its own empty persistent compilation cache:

* ``dask_trim``: the workers with Dask's ``MALLOC_TRIM_THRESHOLD_=65536`` (set in this
  process's environment, which the spawned workers inherit), all refits submitted at once;
* ``default``: the batch door as it is (no trim threshold), all at once;
* ``lead``: as ``default``, the first refit alone and the others after it
  (``run_batch(..., lead=planning.refit_size)``), so that the second worker loads the
  compiled programs from the persistent cache.

Records per arm (JSON lines): wall time, the workers' minor page faults and user / system CPU
time (``getrusage(RUSAGE_CHILDREN)`` around the cluster's life: the workers are this process's
children), and the refits' total and compile times.

    python benchmarks/batch_workers.py --fit-dir FIT --pairs 8 --refits 12 \\
        --records benchmarks/records/performance/batch_workers.jsonl
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ARMS = ("dask_trim", "default", "lead")


def run_arm(arm: str, fit_dir: Path, pairs: int, refits: int) -> dict:
    """One arm in a new process (its environment and caches its own); returns its record."""
    with tempfile.TemporaryDirectory(prefix="batch_workers_") as cache:
        env = dict(os.environ, BAYES_ROADLOAD_CACHE_DIR=cache)
        if arm == "dask_trim":
            env["MALLOC_TRIM_THRESHOLD_"] = "65536"
        else:
            env.pop("MALLOC_TRIM_THRESHOLD_", None)
        out = subprocess.run([sys.executable, __file__, "--arm", arm, "--fit-dir", str(fit_dir), "--pairs", str(pairs),
                              "--refits", str(refits)], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _arm(arm: str, fit_dir: Path, pairs: int, refits: int) -> dict:
    from bayes_roadload._jax import enable_compilation_cache
    from bayes_roadload.analysis.batch import batch_client, run_batch
    from bayes_roadload.analysis.planning import plan_jobs, population_from_samples, refit_size
    from bayes_roadload.data import load_campaign
    from bayes_roadload.output import read_fit_dir

    enable_compilation_cache()
    src = read_fit_dir(fit_dir)
    pop = population_from_samples(src.samples, src.record["free"], src.model, load_campaign(src.record["campaign"]),
                                  source=str(fit_dir))
    jobs = plan_jobs(pop, [pairs], simulations=refits)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    with batch_client(2) as client:
        client.run(lambda: None)  # the workers are up before the clock starts
        t0 = time.perf_counter()
        rec = run_batch(jobs, client, progress=False, lead=refit_size if arm == "lead" else None)
        wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return {"arm": arm, "pairs": pairs, "refits": refits, "wall_s": round(wall, 1),
            "workers_minor_faults": after.ru_minflt - before.ru_minflt,
            "workers_user_s": round(after.ru_utime - before.ru_utime, 1),
            "workers_system_s": round(after.ru_stime - before.ru_stime, 1),
            "refit_s": round(float(rec["time_total_s"].sum()), 1),
            "compile_s": round(float(rec["time_compile_s"].sum()), 1),
            "first_two_compile_s": [round(float(x), 1) for x in sorted(rec["time_compile_s"], reverse=True)[:2]],
            "errors": int(rec["error"].notna().sum()) if "error" in rec else 0}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--fit-dir", type=Path, required=True, help="a fit directory (plan's source posterior)")
    p.add_argument("--pairs", type=int, default=8)
    p.add_argument("--refits", type=int, default=12)
    p.add_argument("--arms", nargs="+", choices=ARMS, default=list(ARMS))
    p.add_argument("--records", type=Path, default=None, help="JSON lines to append to")
    p.add_argument("--note", default="")
    p.add_argument("--arm", choices=ARMS, default=None, help=argparse.SUPPRESS)  # one arm, in this process
    a = p.parse_args()
    if a.arm is not None:
        print(json.dumps(_arm(a.arm, a.fit_dir, a.pairs, a.refits)))
        return
    for arm in a.arms:
        rec = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), **run_arm(arm, a.fit_dir, a.pairs, a.refits),
               "note": a.note}
        print(json.dumps(rec), flush=True)
        if a.records is not None:
            a.records.parent.mkdir(parents=True, exist_ok=True)
            with a.records.open("a") as f:
                f.write(json.dumps(rec) + "\n")


if __name__ == "__main__":
    main()
