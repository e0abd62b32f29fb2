"""Regenerate the committed example diagnosis (``docs/sim_to_real/example_case14``): thesis
case 14 (the comprehensive simulation: pitch, side-force slip, instrument dynamics,
band-limited system noise), 3 pairs, seed 1, diagnosed with ``--model three_term`` through the
command line.  ``tests/analysis/test_diagnose.py`` fails when the committed example is older
than the diagnosis contract (:data:`bayes_roadload.analysis.diagnose.DIAGNOSIS_CONTRACT`) or
was made under other rules (:func:`bayes_roadload.analysis.diagnose.rules_fingerprint`).

    python benchmarks/example_diagnosis.py
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.cli import OUT_MARKER, main  # noqa: E402

EXAMPLE = ROOT / "docs" / "sim_to_real" / "example_case14"


def run(out: Path = EXAMPLE) -> float:
    """Simulate, diagnose into ``out`` (replacing it); returns the diagnosis' wall time (s)."""
    with tempfile.TemporaryDirectory() as tmp:
        campaign = Path(tmp) / "case14"
        if main(["simulate", "--case", "14", "--pairs", "3", "--seed", "1", "--out", str(campaign)]) != 0:
            raise SystemExit("simulation failed")
        shutil.rmtree(out, ignore_errors=True)
        t0 = time.perf_counter()
        code = main(["diagnose", str(campaign), "--model", "three_term", "--out", str(out)])
        wall = time.perf_counter() - t0
    if code != 0:
        raise SystemExit(f"diagnose exited {code}")
    (out / OUT_MARKER).unlink(missing_ok=True)  # it names the temporary campaign directory
    return wall


if __name__ == "__main__":
    print(f"diagnosis: {run():.0f} s wall -> {EXAMPLE}")
