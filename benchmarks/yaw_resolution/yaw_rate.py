import sys, time
sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[2]))
import numpy as np
from studies.proof_suite import IndependentWithheld, INDEPENDENT_BASE_EFFECTS, INDEPENDENT_MEAN_WIND_MPS
from bayes_roadload.simulate.independent import simulate_independent
from bayes_roadload.analysis.diagnose import diagnose


def main():
    """Diagnose the null ``argv[1]`` at its own rate and at each rate of ``argv[2:]`` (Hz)."""
    seed=int(sys.argv[1]); rates=[None]+[float(r) for r in sys.argv[2:]]
    f=IndependentWithheld(None, seed, 6); arm=f.arm()
    for rate in rates:
        t=time.time()
        c = simulate_independent(seed, pairs=6, vehicle=arm["vehicle"], effects=INDEPENDENT_BASE_EFFECTS, type_b=False,
                                 errors=arm["errors"], run_to_run_sd=arm["run_to_run_sd"], mean_wind_mps=INDEPENDENT_MEAN_WIND_MPS,
                                 sample_rate_hz=rate)
        r0=c.runs[c.runs["run"]==c.runs["run"].iloc[0]]; dt=np.median(np.diff(r0.time_s.to_numpy()))
        d = diagnose(c, "three_term")
        yc=[x for x in d.candidates if x["effect"]=="yaw_calibration"][0]
        print(seed, "rate", 1/dt, "top", d.top, "yaw delta", round(yc["delta_elpd"],1), {k:v for k,v in yc.items() if k in ("estimates","estimate","values")}, f"{time.time()-t:.0f}s", flush=True)


if __name__ == "__main__":
    main()
