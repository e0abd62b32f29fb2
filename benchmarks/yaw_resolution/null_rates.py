import sys; sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[2]))
import numpy as np, pandas as pd
from studies.proof_suite import IndependentWithheld
from studies.proof_scoring import read_records
rec = read_records(str(__import__("pathlib").Path(__file__).resolve().parents[2]) + "/docs/sim_to_real/earlier_rules/records_independent_p6_b93d6245.csv")
rec = rec[rec.true_effect.isin(["null","yaw_calibration","side_force_slip","aero_lift"])].reset_index(drop=True)
k, n = int(sys.argv[1]), int(sys.argv[2])
rec = rec.iloc[k::n]
done = {"2019","2010","2011","1004","1005"}
rec = rec[~((rec.true_effect=="null") & rec.seed.astype(str).isin(done))]
def rho1(c):
    out=[]
    for rid, g in c.runs.groupby("run", sort=False):
        t=g.time_s.to_numpy(); y=g.yaw_rad.to_numpy(); dt=np.median(np.diff(t))
        w=max(int(round(20/dt)),3)
        trend=pd.Series(y).rolling(w, center=True, min_periods=1).mean().to_numpy()
        d=y-trend
        if len(d)>3: out.append(np.corrcoef(d[:-1],d[1:])[0,1])
    return float(np.median(out)), dt
for _, r in rec.iterrows():
    eff = None if r.true_effect == "null" else r.true_effect
    c = IndependentWithheld(eff, int(r.seed), 6)()
    rh, dt = rho1(c)
    print(r.true_effect, int(r.seed), r.phase, r.category, round(1/dt,1), round(rh,2), r.top, round(float(r.get("delta_elpd_yaw_calibration")),1), flush=True)
