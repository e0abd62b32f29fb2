"""Simulated undriven-wheel spin-downs (thesis section 5.6): the closed form of eq. 5.13 sampled
at the logging rate until the wheel slows to the end speed, plus white wheel-speed noise."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .. import thesis
from ..data.spindown import SpindownCampaign
from ..physics.spindown import equivalent_mass_kg, spindown_speed_mps

SPINDOWN_SIMULATION = {"v0_mps": 31.0, "v_end_mps": 3.0, "sample_rate_hz": 4.0, "speed_noise_mps": 0.02}
"""Simulated spin-downs: released at ~70 mph tread speed (the thesis' maximum test speed), logged at
4 Hz until the tread speed falls to 3 m/s, wheel-speed noise 0.02 m/s (a toothed-wheel pickup;
the coastdown speed channel's 0.05 m/s of table 6.6 is an upper bound)."""


@dataclass(frozen=True)
class SpindownSettings:
    """Release speed, end speed, logging rate and noise (defaults ``SPINDOWN_SIMULATION``)."""

    v0_mps: float = SPINDOWN_SIMULATION["v0_mps"]
    v_end_mps: float = SPINDOWN_SIMULATION["v_end_mps"]
    sample_rate_hz: float = SPINDOWN_SIMULATION["sample_rate_hz"]
    speed_noise_mps: float = SPINDOWN_SIMULATION["speed_noise_mps"]


def thesis_wheels() -> dict[str, tuple[float, float]]:
    """Per-wheel (A_w, B_w): the means printed in thesis table 7.10 (nearside 1.66 / 0.121,
    offside 1.58 / 0.114; totals 3.24 N, 0.235 N s/m)."""
    return {w: tuple(float(x) for x in t["mean"]) for w, t in thesis.THESIS_UNDRIVEN_PER_WHEEL.items()}


def simulate_spindown(wheels: dict[str, tuple[float, float]] | None = None, *, tests_per_wheel: int = 3,
                      wheel_inertia_kgm2: float = thesis.THESIS_WHEEL_INERTIA_KGM2,
                      rolling_radius_m: float = thesis.THESIS_VEHICLE["rolling_radius_m"],
                      undriven_wheels: int | None = None, seed: int = 0,
                      settings: SpindownSettings = SpindownSettings(),
                      test_sd: tuple[float, float] = (0.0, 0.0)) -> SpindownCampaign:
    """``tests_per_wheel`` spin-downs of each wheel (default: the two rear wheels of the thesis
    car, table 7.10 means) with ``truth`` the per-wheel values and the vehicle totals Au, Bu.

    Each run is logged from release at ``settings.v0_mps`` (tread speed) to ``v_end_mps``; the
    logged tread speed carries N(0, ``speed_noise_mps``) noise, kept positive.  ``test_sd``:
    standard deviations of each test's own offsets of A_w and B_w (test-to-test scatter; table
    7.10's tests scatter by ~0.1 N and ~0.004 N s/m), recorded per run in ``truth["per_run"]``.
    """
    wheels = thesis_wheels() if wheels is None else dict(wheels)
    rng = np.random.default_rng(seed)
    m = float(equivalent_mass_kg(wheel_inertia_kgm2, rolling_radius_m))
    frames = []
    run = 0
    per_run = {}
    for w, (aw0, bw0) in wheels.items():
        for _ in range(tests_per_wheel):
            run += 1
            aw = aw0 + (rng.normal(0.0, test_sd[0]) if test_sd[0] > 0 else 0.0)
            bw = bw0 + (rng.normal(0.0, test_sd[1]) if test_sd[1] > 0 else 0.0)
            per_run[str(run)] = {"Au": aw, "Bu": bw}
            # time to fall from v0 to the end speed: (v + A/B) decays as exp(-B t / m)
            t_end = (m * (settings.v0_mps - settings.v_end_mps) / aw if bw == 0.0 else
                     m / bw * np.log((settings.v0_mps + aw / bw) / (settings.v_end_mps + aw / bw)))
            t = np.arange(0.0, t_end, 1.0 / settings.sample_rate_hz)
            v = np.asarray(spindown_speed_mps(t, settings.v0_mps, aw, bw, m))
            y = np.maximum(v + rng.normal(0.0, settings.speed_noise_mps, v.size), 1e-3)
            frames.append(pd.DataFrame({"run": run, "wheel": w, "time_s": t, "wheel_speed_mps": y}))
    undriven = len(wheels) if undriven_wheels is None else undriven_wheels
    scale = undriven / len(wheels)
    truth = {"Au": scale * sum(a for a, _ in wheels.values()), "Bu": scale * sum(b for _, b in wheels.values()),
             "Au_wheel": {w: a for w, (a, _) in wheels.items()}, "Bu_wheel": {w: b for w, (_, b) in wheels.items()},
             "sigma_mps": settings.speed_noise_mps, "per_run": per_run}
    return SpindownCampaign(pd.concat(frames, ignore_index=True), {w: float(wheel_inertia_kgm2) for w in wheels},
                            float(rolling_radius_m), int(undriven), truth, {"simulated": "spindown", "seed": seed})
