"""What sharing compiled programs across same-shaped campaigns (``BAYES_ROADLOAD_SHARE_PROGRAMS=1``,
``bayes_roadload/_jax.py``) gains and costs, with and without it, each in a new process with an
empty persistent compilation cache:

* gain: two 2-pair campaigns of the clean thesis case (seeds 1 and 2: longest runs 493 and 498
  samples), NUTS ``four_term`` pooled, 2 x (300 + 800) draws, one after the other: the second
  fit's wall time (with sharing it loads the first one's programs);
* cost: the 18-pair (36-run) campaign of ``benchmarks/cold_start.py`` (independent simulator,
  seed 2026) fitted twice with the default sampler (no retry): the second fit's warm-up and
  sampling, whose programs are then all compiled, so they time the execution.

Records: ``benchmarks/records/performance/shared_programs.json``.

    python benchmarks/shared_programs.py
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "benchmarks" / "records" / "performance" / "shared_programs.json"

CHILD = r"""
import json, sys, time, warnings
warnings.simplefilter("ignore")
import bayes_roadload  # before JAX: it sets JAX's options
import numpy as np
from bayes_roadload import config
from bayes_roadload._jax import enable_compilation_cache
from bayes_roadload.inference.nuts import fit_nuts
enable_compilation_cache()
case = sys.argv[1]
if case == "two_pairs":
    from bayes_roadload.simulate import get_case, simulate_campaign
    import dataclasses
    clean = dataclasses.replace(get_case(2), model="basic", dynamics=False, measurement_noise=True, system_noise=False)
    sampler = config.SamplerConfig(num_warmup=300, num_samples=800, num_chains=2, seed=3, retry=False)
    camps = [simulate_campaign(clean, pairs=2, seed=s) for s in (1, 2)]
else:
    from bayes_roadload.simulate.independent import simulate_independent
    sampler = config.SamplerConfig(retry=False)
    c = simulate_independent(2026, pairs=18, category="suv_van", wind="calm", sample_rate_hz=4.0)
    camps = [c, c]
rows = []
for c in camps:
    t = time.perf_counter()
    fit = fit_nuts(c, "four_term", sampler=sampler)
    rows.append({"wall_s": round(time.perf_counter() - t, 2), "padded_samples": int(fit.problem.batch.time_s.shape[-1]),
                 "steps_per_draw": round(float(np.mean(fit.stats["num_steps"])), 2),
                 **{k: round(float(v), 2) for k, v in fit.timings.items()}})
print(json.dumps(rows))
"""


def run(case: str, share: bool) -> list[dict]:
    with tempfile.TemporaryDirectory(prefix="shared_programs_") as cache:
        env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_")}
        env.update(BAYES_ROADLOAD_CACHE_DIR=cache, BAYES_ROADLOAD_SHARE_PROGRAMS="1" if share else "",
                   PYTHONPATH=os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]))
        out = subprocess.run([sys.executable, "-c", CHILD, case], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    rec = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "cpu_count": os.cpu_count(), "runs": []}
    for case in ("two_pairs", "eighteen_pairs"):
        for share in (True, False):
            rows = run(case, share)
            rec["runs"].append({"case": case, "share_programs": share, "fits": rows})
            print(json.dumps(rec["runs"][-1]), flush=True)
    rec["load_1min"] = os.getloadavg()[0]
    RECORDS.parent.mkdir(parents=True, exist_ok=True)
    RECORDS.write_text(json.dumps(rec, indent=2) + "\n")


if __name__ == "__main__":
    main()
