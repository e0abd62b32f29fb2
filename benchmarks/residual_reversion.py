"""Does the speed residual of a random force stay a random walk?  Measured against the
mean-reverting (Ornstein-Uhlenbeck) prediction.

A random force of intensity q (``SimulationSettings.random_force_mps_per_sqrt_s``) acts inside
the simulated dynamics: it moves the true speed, and with it every speed-dependent force of the
truth.  The analysis model integrates its own speed v_m and reads the airspeed from the
anemometer, so the aerodynamic feedback of a speed change reaches both (through the airspeed
reading) and cancels in the residual r = v - v_m, but the rolling loss M g B_D v and the
driveline loss B_t v + C_t v^2 are evaluated at v in the truth and at v_m in the model.  The
residual then obeys dr = -kappa(t) r dt + q dW, kappa = (M g B_D + B_t + 2 C_t v) / M_e
(the lift's small share of the tyre load left out), not the random walk dr = q dW that the
likelihood assumes (:mod:`bayes_roadload.physics.residuals`).  This script simulates the SBC's
campaigns (:func:`bayes_roadload.analysis.sbc.sbc_case`, one prior draw, 2 pairs, driveline) with
the random force alone (no measurement noise), computes r at the true coefficients and prints,
at times T, the measured Var(r_T) / (q^2 T) (1 for a random walk) beside the OU prediction
integral_0^T exp(-2 integral_s^T kappa) ds / T along each run's model trajectory.

Run::

    python benchmarks/residual_reversion.py > benchmarks/records/sbc/residual_reversion.log
"""

import numpy as np

from bayes_roadload.analysis.sbc import SBC_MODEL, draw_from_prior, sbc_case, with_drawn_truth
from bayes_roadload.inference.bayes import build_problem, integrated_speed
from bayes_roadload.simulate import SimulationSettings, simulate_campaign

Q = 0.02
TIMES_S = (25, 50, 75, 100)
CAMPAIGNS = 30


def ou_ratio(t: np.ndarray, kappa: np.ndarray, k: int) -> float:
    """integral_0^T exp(-2 integral_s^T kappa) ds / T at T = t[k] (trapezoid on the samples)."""
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * np.diff(t))])
    weight = np.exp(-2.0 * (cum[k] - cum[:k + 1]))
    return float(np.trapezoid(weight, t[:k + 1]) / t[k])


def main() -> None:
    base = SimulationSettings()
    drawn = draw_from_prior(SBC_MODEL, 2000)
    settings = with_drawn_truth(base, drawn, speed_noise_mps=0.0, airspeed_noise_mps=0.0, yaw_noise_rad=0.0,
                                driveline_noise_n=0.0, random_force_mps_per_sqrt_s=Q)
    measured = {T: [] for T in TIMES_S}
    predicted = {T: [] for T in TIMES_S}
    for s in range(CAMPAIGNS):
        c = simulate_campaign(sbc_case(), 2, 500 + s, driveline=True, settings=settings)
        problem = build_problem(c, SBC_MODEL)
        truth = {k: float(c.truth[k]) for k in problem.free}
        b = problem.batch
        vm = np.asarray(integrated_speed(problem, {**truth, "v0_mps": np.asarray(b.speed_mps)[:, 0]}))
        r = np.asarray(b.speed_mps) - vm
        mask = np.asarray(b.mask, bool)
        veh = c.vehicle
        for i in range(r.shape[0]):
            n = int(mask[i].sum())
            t = np.asarray(b.time_s)[i, :n]
            kappa = (veh.mass_kg * 9.80665 * truth["BD"] + truth["Bt"] + 2 * truth["Ct"] * vm[i, :n]) / veh.effective_mass_kg
            for T in TIMES_S:
                k = int(round(T * 4))
                if k < n:
                    measured[T].append(r[i, k])
                    predicted[T].append(ou_ratio(t, kappa, k))
    print(f"q {Q} m/s/sqrt(s), {CAMPAIGNS} campaigns of 2 pairs; B_D {truth['BD']:.3g} s/m, B_t {truth['Bt']:.3g} N s/m, "
          f"M {veh.mass_kg:g} kg, M_e {veh.effective_mass_kg:g} kg")
    print("T_s  runs  measured Var(r_T)/(q^2 T)  +-se  OU prediction  random walk")
    for T in TIMES_S:
        v = np.asarray(measured[T])
        if v.size:
            print(f"{T:4d}  {v.size:4d}  {np.mean(v**2) / (Q**2 * T):.3f}  {np.sqrt(2 / v.size) * np.mean(v**2) / (Q**2 * T):.3f}"
                  f"  {np.mean(predicted[T]):.3f}  1.000")


if __name__ == "__main__":
    main()
