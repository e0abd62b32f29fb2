"""What the tyre-lag default costs on the 36-run fit: ``fit`` with ``--model four_term`` and with
``--model four_term_tyre_lag`` (the default for NUTS) on the same campaign, each in a new process.

The campaign: thesis case 14, 18 pairs, seed 1, from the project's simulator (``bayes-roadload
simulate``); pooled (36 runs is above the hierarchical default's range).  Records per model the
wall time from before the process starts to its exit, whether every gate passed, the sampler's
timings, leapfrog steps per draw and the stages of ``diagnostics.json``, appended to
``benchmarks/records/performance/default_model_cost.jsonl``; docs/calibration.md (*Other
campaign sizes, and the lag as the default*) reads it.

    python benchmarks/default_model_cost.py
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from cli_process import run_cli  # noqa: E402
RECORDS = ROOT / "benchmarks" / "records" / "performance" / "default_model_cost.jsonl"
MODELS = ("four_term", "four_term_tyre_lag")


def run(args: list[str]) -> float:
    """Wall time of ``bayes-roadload ARGS`` in a new process (stops on a non-zero exit other
    than 3, a fit that failed a gate, which is recorded)."""
    return run_cli(args, ok=(0, 3))[0]


def main() -> None:
    stamp = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    RECORDS.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="default_model_cost_") as tmp:
        campaign = Path(tmp) / "campaign"
        run(["simulate", "--case", "14", "--pairs", "18", "--seed", "1", "--out", str(campaign), "-q"])
        for model in MODELS:
            out = Path(tmp) / model
            load = os.getloadavg()[0]
            wall = run(["fit", str(campaign), "--model", model, "--out", str(out), "--no-progress", "--no-report", "-q"])
            diag = json.loads((out / "diagnostics.json").read_text())
            rec = {"date": stamp, "case": 14, "pairs": 18, "seed": 1, "model": model, "wall_s": round(wall, 2),
                   "load_average_1min_at_start": round(load, 2), "pooling": diag["pooling"], "pass": diag["pass"],
                   "retries": len(diag.get("retries") or []), "timings_s": diag["timings_s"],
                   "mean_leapfrog_steps": diag["mean_leapfrog_steps"], "stages_s": diag.get("stages_s")}
            with RECORDS.open("a") as f:
                f.write(json.dumps(rec) + "\n")
            print(json.dumps(rec), flush=True)


if __name__ == "__main__":
    main()
