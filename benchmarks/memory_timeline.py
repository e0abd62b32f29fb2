"""Resident memory while NUTS samples, as a timeline (every 2 s, from /proc) in a process of its
own: the production sampler (:func:`bayes_roadload.inference.nuts.run_nuts`) on a thesis case 9
campaign (4 Hz, model four_term, pooled, the MAP's Laplace whitening), for

* ``--chains parallel`` (the default: one XLA device per chain, numpyro's ``pmap``),
  ``sequential``, ``vectorized`` (numpyro's: the chains vmapped in one program on one device)
  or ``threads`` (each chain its own single-device program, the two run at once from two Python
  threads: concurrency without ``pmap``);
* ``--xla-flags``: XLA options added to ``XLA_FLAGS``, ``--env``: other environment of the
  probe's process (e.g. to switch off a runtime feature);
* the package's cap of glibc's malloc arenas on (default) or off (``--no-arena-cap``, i.e.
  ``BAYES_ROADLOAD_MALLOC_ARENAS=0``: glibc's 8 per core).

Each run appends one record to ``benchmarks/records/performance/memory_timeline.jsonl``
(timeline, NUTS timings, the resident memory after the MAP, at the end of sampling and its
maximum, and from the probe of 2026-12-05 on, the bytes glibc's malloc holds in use
(``mallinfo2().uordblks``) beside each resident-memory reading: live allocations, as against
memory freed but kept by the allocator); ``docs/performance.md`` (section *Memory*) quotes them.

    python benchmarks/memory_timeline.py --pairs 18 --warmup 100 --draws 1200
    python benchmarks/memory_timeline.py --pairs 18 --warmup 100 --draws 1200 --no-arena-cap
    python benchmarks/memory_timeline.py --pairs 54 --warmup 100 --draws 300 --chains sequential
    python benchmarks/memory_timeline.py --pairs 54 --warmup 100 --draws 200 --chains threads
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

import ctypes
class MallInfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                               "fsmblks", "uordblks", "fordblks", "keepcost")]
try:
    _mallinfo2 = ctypes.CDLL("libc.so.6").mallinfo2
    _mallinfo2.restype = MallInfo2
    def in_use():  # MB that glibc's malloc has handed out and not had back (heap and mmapped chunks)
        m = _mallinfo2()
        return round((m.uordblks + m.hblkhd) / 2**20)
except (OSError, AttributeError):
    def in_use():
        return None

def threaded_map(fn):
    """numpyro ``chain_method`` callable: each chain jitted on a device of its own and run from
    a Python thread of its own, the chains at once (JAX releases the GIL while a program runs)."""
    import jax
    from concurrent.futures import ThreadPoolExecutor
    def run(args):
        n = jax.tree_util.tree_leaves(args)[0].shape[0]
        devices, jitted = jax.local_devices(), jax.jit(fn)
        def one(i):
            a = jax.tree_util.tree_map(lambda x: jax.device_put(x[i], devices[i % len(devices)]), args)
            return jax.block_until_ready(jitted(a))
        with ThreadPoolExecutor(n) as ex:
            outs = list(ex.map(one, range(n)))
        return jax.tree_util.tree_map(lambda *xs: jax.numpy.stack([jax.device_put(x, devices[0]) for x in xs]), *outs)
    return run

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    c = simulate_campaign(get_case(9), pairs=pairs, seed=pairs, settings=SimulationSettings(sample_rate_hz=4.0))
problem, init = nuts.prepare_problem(build_problem(c, "four_term", pooling="pooled", noise="integrated"), c)
post = nuts.unconstrained_posterior(problem, init)
m = nuts.find_map(problem, {}, posterior=post)
if chains != "parallel":
    how = threaded_map if chains == "threads" else chains
    nuts.chain_method = lambda sampler, problem: (how, f"benchmark: --chains {chains}")
timeline, stop, t0 = [], [], time.perf_counter()
def monitor():
    while not stop:
        timeline.append((round(time.perf_counter() - t0, 1), rss(), in_use()))
        time.sleep(2.0)
threading.Thread(target=monitor, daemon=True).start()
after_map, after_map_in_use = rss(), in_use()
s = dataclasses.replace(config.DEFAULT_SAMPLER, num_warmup=warm, num_samples=draws, progress_bar=False, retry=False)
fit = nuts.run_nuts(problem, sampler=s, map_result=m, posterior=post)
end, end_in_use = rss(), in_use()
stop.append(1)
print("RECORD " + json.dumps({
    "pairs": pairs, "runs": len(problem.run_ids), "samples": int(len(c.runs)),
    "warmup": warm, "draws": draws, "chains": chains,
    "chain_method": {"method": chains, "reason": fit.chain_method["reason"]},
    "nuts_timings_s": {k: round(v, 2) for k, v in fit.timings.items()},
    "leapfrog_per_draw": round(float(fit.stats["num_steps"].mean()), 2),
    "rss_after_map_mb": after_map, "rss_end_of_sampling_mb": end,
    "rss_max_during_sampling_mb": max(r[1] for r in timeline), "timeline_mb": timeline,
    "malloc_in_use_after_map_mb": after_map_in_use, "malloc_in_use_end_of_sampling_mb": end_in_use,
    "malloc_in_use_max_during_sampling_mb": max((r[2] for r in timeline if r[2] is not None), default=None)}))
'''


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--pairs", type=int, default=18)
    p.add_argument("--warmup", type=int, default=100)
    p.add_argument("--draws", type=int, default=1200)
    p.add_argument("--chains", choices=("parallel", "sequential", "vectorized", "threads"), default="parallel")
    p.add_argument("--xla-flags", default="", help="added to XLA_FLAGS in the probe's process")
    p.add_argument("--env", nargs="*", default=[], metavar="NAME=VALUE",
                   help="further environment of the probe's process (e.g. JAX_CPU_ENABLE_ASYNC_DISPATCH=false)")
    p.add_argument("--no-arena-cap", action="store_true", help="glibc's default arenas (BAYES_ROADLOAD_MALLOC_ARENAS=0)")
    a = p.parse_args()
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_ARENA_MAX"}
    env["BAYES_ROADLOAD_MALLOC_ARENAS"] = "0" if a.no_arena_cap else "2"
    env.update(dict(item.split("=", 1) for item in a.env))
    if a.xla_flags:
        env["XLA_FLAGS"] = f"{env.get('XLA_FLAGS', '')} {a.xla_flags}".strip()
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", CHILD, str(ROOT), str(a.pairs), str(a.warmup), str(a.draws), a.chains],
                          capture_output=True, text=True, env=env)
    lines = [x for x in done.stdout.splitlines() if x.startswith("RECORD ")]
    if not lines:
        sys.exit(f"the probe failed (exit {done.returncode}): {done.stderr[-2000:]}")
    rec = json.loads(lines[-1][len("RECORD "):])
    rec.update(arena_cap=not a.no_arena_cap, xla_flags=a.xla_flags, env=a.env, wall_s=round(time.perf_counter() - t0, 1),
               date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), load_avg_1min=round(os.getloadavg()[0], 2))
    RECORDS.parent.mkdir(parents=True, exist_ok=True)
    with RECORDS.open("a") as f:
        f.write(json.dumps(rec) + "\n")
    print({k: v for k, v in rec.items() if k != "timeline_mb"})


if __name__ == "__main__":
    main()
