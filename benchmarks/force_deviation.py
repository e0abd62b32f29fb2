"""How the speed deviation that the simulator's random force makes inside the dynamics grows:
Var(delta_T) / (q^2 T) at T = 25, 50, 75, 100 s after a run's start, delta the logged speed of a
campaign with the force less that of the same seed without it (the speed's noise is drawn alike
with and without the force, so it cancels; the run with the force is simulated to 4 m/s so that
it covers the run without it).  1 for a random walk; (1 - exp(-2 kappa T)) / (2 kappa T) for a
deviation that reverts at kappa (the losses' d(dv/dt)/dv, aerodynamic included, since the true
airspeed moves with the true speed).

The SBC truth drawn with seed 2 (:func:`bayes_roadload.analysis.sbc.draw_from_prior`, 2 pairs,
:func:`~bayes_roadload.analysis.sbc.sbc_case`, driveline channel), q = 0.006, simulation seeds
100-119, as ``benchmarks/sbc_walk_arms.py``.  Record:
``benchmarks/records/sbc/force_deviation.log``.

    python benchmarks/force_deviation.py > benchmarks/records/sbc/force_deviation.log
"""
import dataclasses
import warnings

import numpy as np

from bayes_roadload.analysis.sbc import SBC_MODEL, draw_from_prior, sbc_case, with_drawn_truth
from bayes_roadload.simulate import SimulationSettings, simulate_campaign

Q = 0.006
TIMES_S = (25, 50, 75, 100)

warnings.simplefilter("ignore")
settings = with_drawn_truth(SimulationSettings(), draw_from_prior(SBC_MODEL, 2000))
deviations = {t: [] for t in TIMES_S}
for s in range(20):
    ref = simulate_campaign(sbc_case(), 2, 100 + s, driveline=True, settings=settings)
    forced = simulate_campaign(sbc_case(), 2, 100 + s, driveline=True,
                               settings=dataclasses.replace(settings, random_force_mps_per_sqrt_s=Q, stop_speed_mps=4.0))
    for rid in ref.run_ids:
        a = ref.runs[ref.runs["run"] == rid]
        b = forced.runs[forced.runs["run"] == rid].iloc[:len(a)]
        assert np.array_equal(a["time_s"].to_numpy(), b["time_s"].to_numpy())
        delta = b["speed_mps"].to_numpy() - a["speed_mps"].to_numpy()
        t = a["time_s"].to_numpy() - a["time_s"].to_numpy()[0]
        for tt in TIMES_S:
            i = int(np.searchsorted(t, tt))
            if i < len(t):
                deviations[tt].append(delta[i] - delta[0])
print(f"q {Q}, truth seed 2, simulation seeds 100-119, 4 runs each")
for tt in TIMES_S:
    x = np.asarray(deviations[tt])
    ratio = float(np.mean(x**2) / (Q**2 * tt))
    print(f"T {tt} s: {x.size} runs, Var(delta_T) / (q^2 T) = {ratio:.2f} +- {ratio * np.sqrt(2 / x.size):.2f}")
