import sys, time, json, dataclasses
import numpy as np
sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[2]))
from studies.proof_suite import IndependentWithheld, INDEPENDENT_BASE_EFFECTS, INDEPENDENT_MEAN_WIND_MPS
from bayes_roadload.simulate.independent import simulate_independent
from bayes_roadload.analysis.diagnose import diagnose
seeds=[int(s) for s in sys.argv[1].split(",")]
variants={"base":INDEPENDENT_BASE_EFFECTS}
for e in INDEPENDENT_BASE_EFFECTS:
    variants["no_"+e]=tuple(x for x in INDEPENDENT_BASE_EFFECTS if x!=e)
for seed in seeds:
    f=IndependentWithheld(None, seed, 6); arm=f.arm()
    for name, eff in variants.items():
        t=time.time()
        c = simulate_independent(seed, pairs=6, vehicle=arm["vehicle"], effects=eff, type_b=False,
                                 errors=arm["errors"], run_to_run_sd=arm["run_to_run_sd"], mean_wind_mps=INDEPENDENT_MEAN_WIND_MPS)
        d = diagnose(c, "three_term")
        cands = d.candidates if hasattr(d,"candidates") else None
        js = d.to_json() if hasattr(d,"to_json") else None
        out={c["effect"]: round(float(c["delta_elpd"]),1) for c in d.candidates if c.get("delta_elpd") is not None}
        top=sorted(out.items(), key=lambda kv:-kv[1])[:3]
        print(seed, d.top, arm["vehicle"].category, name, top, f"{time.time()-t:.0f}s", flush=True)
