import sys, time
sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[2]))
import numpy as np
import bayes_roadload.physics.integrate as I
orig = I.stride2_schedule
def patched(time_s, inputs):
    ta, h, ua, u_mid, uc, dense = orig(time_s, inputs)
    concrete = not any(isinstance(x, I.jax.core.Tracer) for x in (time_s, inputs))
    xp = np if concrete else I.jnp
    t, u = xp.asarray(time_s, dtype=float), xp.asarray(inputs, dtype=float)
    n = t.shape[-1]
    if (n - 1) % 2:
        u = xp.concatenate([u, u[..., -1:, :]], axis=-2)
    ub = u[..., 1::2, :]
    return ta, h, ua, ub, uc, dense
I.stride2_schedule = patched
import sys, time
import numpy as np
from studies.proof_suite import IndependentWithheld, INDEPENDENT_BASE_EFFECTS, INDEPENDENT_MEAN_WIND_MPS
from bayes_roadload.simulate.independent import simulate_independent
from bayes_roadload.analysis.diagnose import diagnose
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
