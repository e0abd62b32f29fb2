"""One proof-suite campaign diagnosed under the shipped rules and with ``min_rival_share`` at 0
(every rival with a positive gain asked Vuong's test, as before that threshold): which claims
the threshold made, each tested rival's Vuong z, the best's estimates and the
readings' resolution of the gusts (diagnosis.json ``inputs``).  Appends one JSON line per campaign.

    python benchmarks/rival_share_probe.py --names null-s11018 --seeds 1001 --nulls 20 --null-seed0 11000 \
        --pairs 6 --records benchmarks/records/sim_to_real/rival_share_probe.jsonl
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload import config  # noqa: E402
from bayes_roadload.analysis.diagnose import diagnose  # noqa: E402
from studies.proof_suite import withheld_effect_jobs  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--names", nargs="+", required=True, help="campaign names, e.g. null-s11018")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1])
    ap.add_argument("--nulls", type=int, default=0)
    ap.add_argument("--null-seed0", type=int, default=1000)
    ap.add_argument("--pairs", type=int, default=6)
    ap.add_argument("--records", type=Path, required=True)
    args = ap.parse_args(argv)
    jobs = {j.name: j for j in withheld_effect_jobs(None, seeds=tuple(args.seeds), pairs=args.pairs, nulls=args.nulls,
                                                    design="independent", null_seed0=args.null_seed0)}
    args.records.parent.mkdir(parents=True, exist_ok=True)
    for name in args.names:
        campaign = jobs[name].campaign_factory()
        rec = {"name": name, "pairs": args.pairs, "category": (campaign.meta or {}).get("category")}
        for label, share in (("shipped", config.DEFAULT_DIAGNOSIS.min_rival_share), ("no_share", 0.0)):
            d = diagnose(campaign, jobs[name].model,
                         settings=dataclasses.replace(config.DEFAULT_DIAGNOSIS, min_rival_share=share))
            best = d.candidates[0]
            rec[label] = {"min_rival_share": share, "top": d.top or "none", "best": best["effect"],
                          "best_delta_elpd": round(float(best["delta_elpd"]), 3),
                          "vuong_z": {k: round(float(v), 3) for k, v in (best.get("vuong_z") or {}).items()},
                          "rivals": {c["effect"]: round(float(c["delta_elpd"]), 3) for c in d.candidates[1:]
                                     if c["delta_elpd"] > 0},
                          "estimates": best.get("estimates"), "inputs": d.result.get("inputs")}
        with args.records.open("a") as fh:
            fh.write(json.dumps(rec) + "\n")
        print(json.dumps(rec, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
