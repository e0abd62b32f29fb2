"""The default's first attempt on each pair of the eco-car's GNSS traces, with and without the
check for a support wall before sampling (``config.MAX_BEYOND_SUPPORT_SHARE``; without it the
tyre-lag model samples its apparent coefficients, whose C_D0 = C_D0' - kappa B_D G_T crosses
C_D0's bound at 0 for this 78 kg car).  Retry off, the default sampler otherwise (seed 7).
Records per fit: the Laplace share beyond a support, the coordinates sampled, divergences, max
R-hat, the gates failed, wall time, to ``benchmarks/records/real_data/gnss_walls.jsonl``.

    python benchmarks/gnss_walls.py
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "benchmarks" / "records" / "real_data" / "gnss_walls.jsonl"
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT))

from gradient_cost import commit_of  # noqa: E402
from real_data import GNSS_DIR, gnss_campaign  # noqa: E402

from bayes_roadload import config  # noqa: E402
from bayes_roadload.inference import nuts  # noqa: E402
from bayes_roadload.inference.results import diagnostics, summary_table, to_inference_data  # noqa: E402

MODEL = "four_term_tyre_lag_admittance_pitch_shapes"
PAIRS = (("Michelin60A", "Michelin60B"), ("Michelin60A1", "Michelin60B1"))


def main() -> int:
    if not GNSS_DIR.is_dir():
        print(json.dumps({"skipped": f"{GNSS_DIR} not found"}))
        return 0
    camp = gnss_campaign()
    sampler = dataclasses.replace(config.DEFAULT_SAMPLER, seed=7, retry=False)
    rows = []
    for check in (True, False):
        config.MAX_BEYOND_SUPPORT_SHARE = 1e-3 if check else math.inf
        for pair in PAIRS:
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fit = nuts.fit_nuts(camp.subset(list(pair)), MODEL, sampler=sampler)
            wall = time.perf_counter() - t0
            idata = to_inference_data(fit)
            diag = diagnostics(fit, idata, summary_table(fit, idata))
            rows.append({"benchmark": "gnss_walls", "pair": list(pair), "wall_check": check,
                         "coordinates": fit.coordinates or ("apparent" if fit.problem.apparent is not None else "direct"),
                         "divergences": diag["divergences"], "max_r_hat": round(diag["max_r_hat"], 4),
                         "failed": diag["failed"], "wall_s": round(wall, 1), "code": commit_of(ROOT),
                         "date": time.strftime("%Y-%m-%d %H:%M")})
            print(json.dumps(rows[-1]), flush=True)
    RECORDS.parent.mkdir(parents=True, exist_ok=True)
    with RECORDS.open("a") as f:
        for r in rows:
            f.write(json.dumps(r) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
