"""The admittance candidate on the independent simulator's admittance campaigns: for each
(seed, pairs), the three candidates with the largest delta_elpd, whether each is supported, and
the admittance family's gain and length (``studies.proof_suite.independent_withheld_campaign``
with ``aero_admittance`` injected, ``diagnose`` under the shipped rules).  Used on the seeds whose
confirmatory runs under the rules 8870425e missed the admittance (601-605 at 6 pairs, 701-705 at
3 pairs), which are design seeds of the current rules.  Appends one JSON line per campaign.

    python benchmarks/admittance_candidates.py 601:6 602:6 603:6 604:6 605:6 \\
        >> benchmarks/records/sim_to_real/admittance_candidates.jsonl
"""

from __future__ import annotations

import json
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.analysis.diagnose import diagnose, rules_fingerprint  # noqa: E402
from bayes_roadload.analysis.effects import load_library  # noqa: E402
from studies.proof_suite import independent_withheld_campaign  # noqa: E402


def main(argv: list[str]) -> int:
    library_sha = rules_fingerprint(load_library())["library_sha256"]
    for job in argv:
        seed, pairs = (int(x) for x in job.split(":"))
        factory, model = independent_withheld_campaign("aero_admittance", seed, pairs=pairs)
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            d = diagnose(factory(), model)
        by = {c["effect"]: c for c in d.candidates}
        top = sorted((c for c in d.candidates if c["delta_elpd"] == c["delta_elpd"]), key=lambda c: -c["delta_elpd"])[:3]
        adm = by["aero_admittance"]
        print(json.dumps({"seed": seed, "pairs": pairs, "library_sha256": library_sha,
                          "top3": [[c["effect"], round(float(c["delta_elpd"]), 2), bool(c["supported"])] for c in top],
                          "estimates": adm["estimates"], "shape": adm.get("shape", {}).get("values"),
                          "wall_s": round(time.perf_counter() - start, 1)}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
