"""Resident memory while NUTS samples, as a timeline (every 2 s, from /proc) in a process of its
own: the production sampler (:func:`bayes_roadload.inference.nuts.run_nuts`) on a thesis case 9
campaign (4 Hz, model four_term, pooled, the MAP's Laplace whitening), for

* ``--chains parallel`` (the default: one XLA device per chain) or ``sequential``;
* the package's cap of glibc's malloc arenas on (default) or off (``--no-arena-cap``, i.e.
  ``BAYES_ROADLOAD_MALLOC_ARENAS=0``: glibc's 8 per core).

Each run appends one record to ``benchmarks/records/performance/memory_timeline.jsonl``
(timeline, NUTS timings, the resident memory after the MAP, at the end of sampling and its
maximum); ``docs/performance.md`` (section *Memory*) quotes them.

    python benchmarks/memory_timeline.py --pairs 18 --warmup 100 --draws 1200
    python benchmarks/memory_timeline.py --pairs 18 --warmup 100 --draws 1200 --no-arena-cap
    python benchmarks/memory_timeline.py --pairs 54 --warmup 100 --draws 300 --chains sequential
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "benchmarks" / "records" / "performance" / "memory_timeline.jsonl"

CHILD = r'''
import dataclasses, json, sys, threading, time, warnings
sys.path.insert(0, sys.argv[1])
pairs, warm, draws, chains = int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
import bayes_roadload  # first: XLA flags, x64, the arena cap
from bayes_roadload import config
import bayes_roadload.inference.nuts as nuts
from bayes_roadload.inference.bayes import build_problem
from bayes_roadload.simulate import simulate_campaign
from bayes_roadload.simulate.campaign import SimulationSettings
from bayes_roadload.simulate.cases import get_case

def rss():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS"):
            return round(int(line.split()[1]) / 1024)

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    c = simulate_campaign(get_case(9), pairs=pairs, seed=pairs, settings=SimulationSettings(sample_rate_hz=4.0))
problem, init = nuts.prepare_problem(build_problem(c, "four_term", pooling="pooled", noise="integrated"), c)
post = nuts.unconstrained_posterior(problem, init)
m = nuts.find_map(problem, {}, posterior=post)
if chains == "sequential":
    nuts.chain_method = lambda sampler, problem: ("sequential", "benchmark: --chains sequential")
timeline, stop, t0 = [], [], time.perf_counter()
def monitor():
    while not stop:
        timeline.append((round(time.perf_counter() - t0, 1), rss()))
        time.sleep(2.0)
threading.Thread(target=monitor, daemon=True).start()
after_map = rss()
s = dataclasses.replace(config.DEFAULT_SAMPLER, num_warmup=warm, num_samples=draws, progress_bar=False, retry=False)
fit = nuts.run_nuts(problem, sampler=s, map_result=m, posterior=post)
end = rss()
stop.append(1)
print("RECORD " + json.dumps({
    "pairs": pairs, "runs": len(problem.run_ids), "samples": int(len(c.runs)),
    "warmup": warm, "draws": draws, "chains": chains, "chain_method": fit.chain_method,
    "nuts_timings_s": {k: round(v, 2) for k, v in fit.timings.items()},
    "leapfrog_per_draw": round(float(fit.stats["num_steps"].mean()), 2),
    "rss_after_map_mb": after_map, "rss_end_of_sampling_mb": end,
    "rss_max_during_sampling_mb": max(r for _, r in timeline), "timeline_mb": timeline}))
'''


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--pairs", type=int, default=18)
    p.add_argument("--warmup", type=int, default=100)
    p.add_argument("--draws", type=int, default=1200)
    p.add_argument("--chains", choices=("parallel", "sequential"), default="parallel")
    p.add_argument("--no-arena-cap", action="store_true", help="glibc's default arenas (BAYES_ROADLOAD_MALLOC_ARENAS=0)")
    a = p.parse_args()
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_ARENA_MAX"}
    env["BAYES_ROADLOAD_MALLOC_ARENAS"] = "0" if a.no_arena_cap else "2"
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", CHILD, str(ROOT), str(a.pairs), str(a.warmup), str(a.draws), a.chains],
                          capture_output=True, text=True, env=env)
    lines = [x for x in done.stdout.splitlines() if x.startswith("RECORD ")]
    if not lines:
        sys.exit(f"the probe failed (exit {done.returncode}): {done.stderr[-2000:]}")
    rec = json.loads(lines[-1][len("RECORD "):])
    rec.update(arena_cap=not a.no_arena_cap, wall_s=round(time.perf_counter() - t0, 1),
               date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), load_avg_1min=round(os.getloadavg()[0], 2))
    RECORDS.parent.mkdir(parents=True, exist_ok=True)
    with RECORDS.open("a") as f:
        f.write(json.dumps(rec) + "\n")
    print({k: v for k, v in rec.items() if k != "timeline_mb"})


if __name__ == "__main__":
    main()
