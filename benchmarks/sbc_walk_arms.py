"""Where does the simulator arm's BD / CD0 conservatism come from?  Replicates of one SBC
truth whose integrated error enters the data in different ways, fitted alike.

``ARM N Q TRUTH_SEED [OFFSET]``: N replicate campaigns (simulation seeds 100 + OFFSET ...) of the
SBC truth drawn with seed TRUTH_SEED (:func:`bayes_roadload.analysis.sbc.draw_from_prior`,
2 pairs, :func:`~bayes_roadload.analysis.sbc.sbc_case`, driveline channel), each fitted by MAP +
Laplace (:func:`~bayes_roadload.inference.laplace.fit_laplace`, no importance correction); prints
per replicate the z of AD, BD, CD0, KD, At, Bt and the MAP's q, then the spread of the MAP over
the mean Laplace sd.  Arms, all with a random-walk intensity Q:

* ``sim``: the simulator's random force (``random_force_mps_per_sqrt_s = Q``), acting inside the
  dynamics (it moves the true speed, the airspeed the vehicle meets, its losses);
* ``sim_fixed_end``: as ``sim``, but each run ends at the time the run without the force ends
  (simulated to 4 m/s, cut there), not where its own speed, moved by the walk, falls to the stop
  speed: the sim arm's one data-selection rule that depends on the walk;
* ``posthoc_same``: the logged speed of ``sim_fixed_end`` with the other channels (airspeed,
  yaw, driveline) of the same seed's campaign without the force: the speed's noise is drawn
  alike with and without the force, so this is the campaign without the force plus the
  deviation the force made in the true speed (the walk, reverting through every loss,
  aerodynamic included), which the other channels do not carry;
* ``posthoc``: the simulator without it, the walk added to the logged speed afterwards;
* ``exact``: as the exact SBC arm draws: the model's own integration of the noisy logged inputs,
  plus the walk and white noise 0.05 m/s, the driveline channel from the new speeds;
* ``exact_clean``: as ``exact`` but integrated from noise-free inputs, the noise added to the
  airspeed and yaw channels afterwards;
* ``exact_reverting``: as ``exact``, the walk replaced by a deviation that reverts at
  :data:`KAPPA_PER_S` (an Ornstein-Uhlenbeck process of the same increments over short times),
  the rate the force's own deviation shows (``benchmarks/force_deviation.py``).

Records (2026-11-27, Q = 0.006, truth seed 2): ``benchmarks/records/sbc/walk_arms/*.log``
(``_b`` files continue an arm at OFFSET 30, ``_c`` at OFFSET 43 with N 60; ``sim_fixed_end``
stopped after 19 replicates and ``posthoc_same`` after 42, both from OFFSET 0, so that they pair
with ``sim``'s replicates of the same seeds; ``exact_reverting`` 0-24 and, ``_b``, 25-49, which
pair with ``exact``'s: the same normal draws make the walk and the reverting deviation).

    python benchmarks/sbc_walk_arms.py sim 30 0.006 2 > benchmarks/records/sbc/walk_arms/arms_sim.log
"""
import sys, dataclasses, json
import numpy as np
from bayes_roadload import config
from bayes_roadload.analysis.sbc import SBC_MODEL, draw_from_prior, sbc_case, with_drawn_truth
from bayes_roadload.simulate import SimulationSettings, simulate_campaign
from bayes_roadload.inference.laplace import fit_laplace
from bayes_roadload.inference.bayes import build_problem, integrated_speed
from bayes_roadload.data.campaign import Campaign

KAPPA_PER_S = 0.016
"""Reversion rate of ``exact_reverting`` (1/s)."""

ARMS = ("sim", "sim_fixed_end", "posthoc_same", "posthoc", "exact", "exact_clean", "exact_reverting")

arm = sys.argv[1]; n = int(sys.argv[2]); q = float(sys.argv[3]); tseed = int(sys.argv[4]); off = int(sys.argv[5]) if len(sys.argv) > 5 else 0
if arm not in ARMS:  # the last branch below draws every exact-style arm: a misspelt arm would run as "exact"
    sys.exit(f"unknown arm {arm!r}: one of {', '.join(ARMS)}")
base = SimulationSettings()
drawn = draw_from_prior(SBC_MODEL, tseed * 1000)
settings = with_drawn_truth(base, drawn)
P = ["AD", "BD", "CD0", "KD", "At", "Bt"]
rows = []
for s in range(off, off + n):
    if arm == "posthoc":
        c = simulate_campaign(sbc_case(), 2, 100 + s, driveline=True, settings=settings)
        rng = np.random.default_rng([s, 99])
        runs = c.runs.copy()
        for rid in c.run_ids:
            sel = (runs["run"] == rid).to_numpy(); m = int(sel.sum())
            runs.loc[sel, "speed_mps"] += np.cumsum(np.r_[0.0, rng.normal(0, 1, m - 1) * q * np.sqrt(0.25)])
        c = Campaign(runs, c.vehicle, c.anemometer, c.tunnel, c.truth, c.meta)
    elif arm == "sim":
        c = simulate_campaign(sbc_case(), 2, 100 + s, driveline=True,
                              settings=dataclasses.replace(settings, random_force_mps_per_sqrt_s=q))
    elif arm in ("sim_fixed_end", "posthoc_same"):
        ref = simulate_campaign(sbc_case(), 2, 100 + s, driveline=True, settings=settings)
        c = simulate_campaign(sbc_case(), 2, 100 + s, driveline=True,
                              settings=dataclasses.replace(settings, random_force_mps_per_sqrt_s=q, stop_speed_mps=4.0))
        end = ref.runs.groupby("run")["time_s"].max()
        runs = c.runs[c.runs["time_s"].to_numpy() <= c.runs["run"].map(end).to_numpy()].reset_index(drop=True)
        assert (runs.groupby("run")["time_s"].max() == end).all(), "a run with the force stopped before the run without it"
        if arm == "posthoc_same":  # the speed's noise is drawn alike with and without the force (same seed)
            free = ref.runs.copy()
            assert np.array_equal(free["time_s"].to_numpy(), runs["time_s"].to_numpy())
            free["speed_mps"] = runs["speed_mps"].to_numpy()
            runs = free
        c = Campaign(runs, c.vehicle, c.anemometer, c.tunnel, c.truth, c.meta)
    else:
        clean = arm == "exact_clean"
        t = simulate_campaign(sbc_case(), 2, 100 + s, driveline=True,
                              settings=dataclasses.replace(settings, airspeed_noise_mps=0.0, yaw_noise_rad=0.0) if clean else settings)
        problem = build_problem(t, SBC_MODEL)
        truth = {p: float(t.truth[p]) for p in problem.free}
        b = problem.batch
        first = np.asarray(b.speed_mps)[:, 0]
        v_model = np.asarray(integrated_speed(problem, {**truth, "v0_mps": first}))
        rng = np.random.default_rng([s, 99])
        runs = t.runs.copy(); speed = runs["speed_mps"].to_numpy(float).copy()
        tt = np.asarray(b.time_s); mask = np.asarray(b.mask, bool)
        for r, rid in enumerate(problem.run_ids):
            rows_r = np.flatnonzero((runs["run"] == rid).to_numpy()); m = int(mask[r].sum())
            dt = np.diff(tt[r, :m], prepend=tt[r, 0])
            if arm == "exact_reverting":  # delta_k = phi_k delta_{k-1} + w_k, Var(w_k) = q^2 (1 - phi_k^2) / (2 kappa)
                phi = np.exp(-KAPPA_PER_S * dt)
                w = rng.normal(0, 1, m) * q * np.sqrt((1.0 - phi**2) / (2.0 * KAPPA_PER_S))
                walk = np.zeros(m)
                for k in range(1, m):
                    walk[k] = phi[k] * walk[k - 1] + w[k]
            else:
                walk = np.cumsum(rng.normal(0, 1, m) * q * np.sqrt(dt))
            speed[rows_r] = v_model[r, :m] + walk + rng.normal(0, 0.05, m)
        runs["speed_mps"] = speed
        pp = {**problem.fixed, **truth}
        runs["driveline_force_n"] = pp["At"] + pp["Bt"] * speed + pp["Ct"] * speed**2 + rng.normal(0, 1.0, speed.size)
        if clean:
            rng2 = np.random.default_rng([s, 77])
            runs["airspeed_mps"] = np.maximum(runs["airspeed_mps"] + 0.05 * rng2.standard_normal(len(runs)), 0.0)
            runs["yaw_rad"] = runs["yaw_rad"] + 0.01 * rng2.standard_normal(len(runs))
        c = Campaign(runs, t.vehicle, t.anemometer, t.tunnel, t.truth, t.meta)
    c.meta["pad_to_samples"] = 400
    f = fit_laplace(c, SBC_MODEL, importance=False, draws=2000)
    row = {p: (float(f.map.constrained[p]), float(np.std(f.samples[p])), float(c.truth[p])) for p in P}
    row["q"] = float(f.map.constrained["q_mps_per_sqrt_s"])
    rows.append(row)
    print(s, json.dumps({k: (round(v, 5) if k == "q" else round((v[0] - v[2]) / v[1], 2)) for k, v in row.items()}), flush=True)
print("arm", arm, "q", q)
for p in P:
    m = np.array([r[p][0] for r in rows]); sd = np.array([r[p][1] for r in rows]); t = rows[0][p][2]
    print(p, "spread/sd", round(m.std(ddof=1) / sd.mean(), 2), "mean z", round(((m - t) / sd).mean(), 2), "rel spread", m.std(ddof=1)/t)
print("q MAP mean", np.mean([r["q"] for r in rows]))
