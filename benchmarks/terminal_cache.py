"""Does a fit on a terminal reuse its compiled sampler?  ``bayes-roadload fit`` run in a
pseudo-terminal (``script``), so that progress is drawn, twice with one persistent compilation
cache (cold, then warm), once with the default time bar and once with ``--iteration-bars``
(numpyro's bars, drawn by host callbacks inside the sampler's program; JAX does not write such
programs to its persistent cache).  The campaign: thesis case 9, 2 pairs, seed 1, from the
project's simulator, ``--model four_term``.  Records the ``compile``, ``warmup``, ``sampling``
and ``total`` stages of ``diagnostics.json`` and the cache's size to
``benchmarks/records/performance/terminal_cache.jsonl`` (one line per run).

    python benchmarks/terminal_cache.py
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "benchmarks" / "records" / "performance" / "terminal_cache.jsonl"
sys.path.insert(0, str(ROOT / "benchmarks"))

from gradient_cost import commit_of  # noqa: E402


def cache_bytes(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def run_in_terminal(args: list[str], env: dict[str, str]) -> float:
    """``python -m bayes_roadload ARGS`` inside ``script`` (a pseudo-terminal); wall time (s)."""
    cmd = shlex.join([sys.executable, "-m", "bayes_roadload", *args])
    t0 = time.perf_counter()
    proc = subprocess.run(["script", "-qec", cmd, "/dev/null"], env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"{cmd} exited {proc.returncode}:\n{proc.stdout[-2000:]}")
    return time.perf_counter() - t0


def main() -> int:
    if shutil.which("script") is None:
        raise SystemExit("needs util-linux's `script` for a pseudo-terminal")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        subprocess.run([sys.executable, "-m", "bayes_roadload", "simulate", "--case", "9", "--pairs", "2", "--seed", "1",
                        "--out", str(tmp / "camp"), "-q"], check=True)
        for mode, extra in (("time bar", []), ("iteration bars", ["--iteration-bars"])):
            cache = tmp / f"cache_{len(rows)}"
            env = dict(os.environ, BAYES_ROADLOAD_CACHE_DIR=str(cache))
            for start in ("cold", "warm"):
                out = tmp / f"out_{len(rows)}"
                wall = run_in_terminal(["fit", str(tmp / "camp"), "--out", str(out), "--model", "four_term",
                                        "--no-report", *extra], env)
                stages = json.loads((out / "diagnostics.json").read_text())["stages_s"]
                rows.append({"benchmark": "terminal_cache", "mode": mode, "start": start, "wall_s": round(wall, 2),
                             **{f"{k}_s": stages[k] for k in ("compile", "warmup", "sampling", "total")},
                             "cache_mb": round(cache_bytes(cache) / 1e6, 2), "code": commit_of(ROOT),
                             "date": time.strftime("%Y-%m-%d %H:%M")})
                print(json.dumps(rows[-1]), flush=True)
    RECORDS.parent.mkdir(parents=True, exist_ok=True)
    with RECORDS.open("a") as f:
        for r in rows:
            f.write(json.dumps(r) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
