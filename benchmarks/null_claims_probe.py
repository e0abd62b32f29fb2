"""Which base effect of the ``independent`` proof design makes a null campaign claim a
candidate: the null of seed S diagnosed with base effects removed, one variant per line.

    python benchmarks/null_claims_probe.py --seeds 2001 2005 2006 \
        --drop "" turbulence turbulence,weather_drift,humidity

Records (JSON lines): ``benchmarks/records/sim_to_real/null_claims_probe.jsonl``: seed, vehicle
category, the base effects removed, the top claim and every candidate's delta_elpd.  An
exploratory probe of the confirmatory nulls that claimed ``yaw_calibration``
(docs/sim_to_real.md); it changes no rule.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import studies.proof_suite as ps  # noqa: E402
from bayes_roadload.analysis.diagnose import diagnose  # noqa: E402

RECORDS = ROOT / "benchmarks" / "records" / "sim_to_real" / "null_claims_probe.jsonl"


def probe(seed: int, drop: tuple[str, ...], yaw_noise_off: bool = False, model: str = "three_term") -> dict:
    """The null campaign of ``seed`` (6 pairs) with the base effects ``drop`` removed (and the
    vane's random noise set to 0, the random streams unchanged), diagnosed with ``model`` (the
    design's ``three_term``, K_D fixed at the campaign's tunnel value, or ``four_term``, K_D free)."""
    import dataclasses

    import bayes_roadload.simulate.independent.campaign as camp

    base, instruments = ps.INDEPENDENT_BASE_EFFECTS, camp.sens.random_instruments
    ps.INDEPENDENT_BASE_EFFECTS = tuple(e for e in base if e not in drop)
    if yaw_noise_off:
        camp.sens.random_instruments = lambda *a, **k: dataclasses.replace(instruments(*a, **k), yaw_noise_sd_rad=0.0)
    try:
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            campaign = ps.IndependentWithheld(None, seed, 6)()
            d = diagnose(campaign, model)
    finally:
        ps.INDEPENDENT_BASE_EFFECTS, camp.sens.random_instruments = base, instruments
    return {"seed": seed, "category": (campaign.meta or {}).get("category"), "removed": list(drop),
            "yaw_noise_off": yaw_noise_off, "model": model,
            "top": d.top or "none", "delta_elpd": {c["effect"]: round(float(c["delta_elpd"]), 3) for c in d.candidates},
            "time_s": round(time.perf_counter() - t0, 1)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", required=True)
    ap.add_argument("--drop", nargs="+", default=[""], help="comma-separated base effects to remove, one variant each")
    ap.add_argument("--yaw-noise-off", action="store_true", help="the vane's random noise set to 0")
    ap.add_argument("--model", default="three_term", help="analysis model (the design's: three_term)")
    a = ap.parse_args(argv)
    RECORDS.parent.mkdir(parents=True, exist_ok=True)
    with RECORDS.open("a") as f:
        for seed in a.seeds:
            for variant in a.drop:
                rec = probe(seed, tuple(x for x in variant.split(",") if x), a.yaw_noise_off, a.model)
                f.write(json.dumps(rec) + "\n")
                print(f"seed {seed} ({rec['category']}, {a.model}) without [{variant}]"
                      f"{' yaw noise off' if a.yaw_noise_off else ''}: "
                      f"top {rec['top']}, "
                      f"yaw_calibration {rec['delta_elpd'].get('yaw_calibration')}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
