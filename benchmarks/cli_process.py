"""``bayes-roadload`` in a new Python process, timed from before the process starts to its exit:
the one runner of the benchmarks that measure the command line (``cold_start.py``,
``default_model_cost.py``, ``plan_time.py``)."""

from __future__ import annotations

import subprocess
import sys
import time
from typing import Iterable, Mapping


def run_cli(args: Iterable[str], *, env: Mapping[str, str] | None = None,
            ok: Iterable[int] | None = (0,)) -> tuple[float, subprocess.CompletedProcess]:
    """Run ``python -m bayes_roadload ARGS`` with its output captured; returns the wall time (s)
    and the finished process.  An exit code outside ``ok`` stops the benchmark with the command's
    last stderr (``ok=None`` accepts every exit code, for callers that record it)."""
    args = [str(a) for a in args]
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "bayes_roadload", *args], env=None if env is None else dict(env),
                          capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if ok is not None and proc.returncode not in tuple(ok):
        raise SystemExit(f"bayes-roadload {' '.join(args)} exited {proc.returncode}:\n{proc.stderr[-2000:]}")
    return wall, proc
