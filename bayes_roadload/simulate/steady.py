"""Simulated steady-state torque tests (thesis sections 5.1.3, 5.4, 7.4).

A group of runs at the steady speeds of ``STEADY_SIMULATION`` (20-70 mph), each speed
driven in both directions (one opposite-direction pair per speed and repetition).  The vehicle
holds its set speed with a small constant drift (the driver fixes the throttle, section 5.4.1)
through a frozen Dryden wind field of a table 6.7 case shared by the pair's two runs
(:func:`~bayes_roadload.simulate.wind.generate_wind_field`); the tractive force at the driven
wheels is the case's drag function (the coastdown simulator's truth physics,
:func:`~bayes_roadload.simulate.campaign.case_model`, without a driveline) plus ``M_e dv/dt``, a
constant offset per run and torque-meter noise.  Logged: time, speed, tractive force, and with
``anemometer`` the true relative airspeed and yaw plus the measurement noise of table 6.6 (no
instrument dynamics: a steady run's wind varies slowly against the cup's time constant).
"""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np
import pandas as pd

from .. import config
from .. import thesis
from ..data.steady import SteadyCampaign
from ..physics.atmosphere import air_density_kgpm3
from ..physics.terms import Conditions
from . import wind as wind_mod
from .campaign import DEFAULT_SETTINGS, SimulationSettings, _relative_air, _rng, case_model, true_parameters
from .cases import SimulationCase, get_case

STEADY_SIMULATION = {"speeds_mph": (20.0, 30.0, 40.0, 50.0, 60.0, 70.0), "duration_s": 30.0,
                     "sample_rate_hz": 1.0, "force_noise_n": 15.0, "run_force_sd_n": 8.0,
                     "accel_sd_mps2": 0.02, "speed_noise_mps": 0.05, "driveline_noise_n": 10.0}
"""Simulated steady-state groups (thesis section 5.1.3: 20-70 mph in 10 mph steps, both
directions): each run held ``duration_s`` at its set speed with a constant drift of sd
``accel_sd_mps2`` (the driver holds the throttle, section 5.4.1), logged at ``sample_rate_hz``;
torque-meter noise ``force_noise_n`` per sample and a run offset of sd ``run_force_sd_n``; the
gearbox input force carries the on-load driveline loss plus ``driveline_noise_n`` noise."""


@dataclass(frozen=True)
class SteadySettings:
    """Steady speeds, run duration, logging rate and noise (defaults ``STEADY_SIMULATION``)."""

    speeds_mph: tuple[float, ...] = STEADY_SIMULATION["speeds_mph"]
    duration_s: float = STEADY_SIMULATION["duration_s"]
    sample_rate_hz: float = STEADY_SIMULATION["sample_rate_hz"]
    force_noise_n: float = STEADY_SIMULATION["force_noise_n"]
    run_force_sd_n: float = STEADY_SIMULATION["run_force_sd_n"]
    accel_sd_mps2: float = STEADY_SIMULATION["accel_sd_mps2"]
    speed_noise_mps: float = STEADY_SIMULATION["speed_noise_mps"]
    driveline_noise_n: float = STEADY_SIMULATION["driveline_noise_n"]


def simulate_steady(case: int | SimulationCase | None = 9, pairs: int = 1, seed: int = 0, *,
                    anemometer: bool = True, gearbox_input: bool = True, settings: SteadySettings = SteadySettings(),
                    simulation: SimulationSettings = DEFAULT_SETTINGS) -> SteadyCampaign:
    """``pairs`` opposite-direction pairs at each steady speed, in the winds of ``case``
    (table 6.7; default 9: 2 m/s head and cross wind; ``None``: still air), truth = the case's
    coefficients (table 6.3).  Runs 2k-1 (+) and 2k (-) form pair k.  With ``gearbox_input`` the
    gearbox input force is logged too: wheel force + the on-load driveline loss A_t + B_t v of
    thesis table 7.9 (``thesis.THESIS_DRIVELINE_ON_LOAD``) + ``driveline_noise_n`` noise."""
    sc = get_case(case if case is not None else 1) if not isinstance(case, SimulationCase) else case
    head, cross = (sc.head_wind_mps, sc.cross_wind_mps) if case is not None else (0.0, 0.0)
    model = case_model(sc)
    params = true_parameters(sc, settings=simulation)
    vehicle = simulation.vehicle
    rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(0,)))
    t = np.arange(0.0, settings.duration_s, 1.0 / settings.sample_rate_hz)
    length = simulation.track_length_m
    frames, run, pair = [], 0, 0
    for mph in settings.speeds_mph:
        v_set = mph * config.MPH_TO_MPS
        for _ in range(pairs):
            pair += 1
            field = wind_mod.generate_wind_field(head, cross, _rng(seed, pair, 0), track_length_m=length,
                                                 margin_m=simulation.wind_margin_m,
                                                 turbulence_ratio=simulation.turbulence_ratio)
            for d in (1, -1):
                run += 1
                a = rng.normal(0.0, settings.accel_sd_mps2)
                v = v_set + a * (t - t.mean())
                travelled = v_set * (t - t.mean()) + 0.5 * a * (t - t.mean()) ** 2
                x = 0.5 * length + d * travelled
                wa, wc = field.at(x)
                vr, psi = (np.asarray(z) for z in _relative_air(v, d, wa, wc))
                n = t.size
                c = Conditions(speed_mps=jnp.asarray(v), airspeed_mps=jnp.asarray(vr), yaw_rad=jnp.asarray(psi),
                               driveline_force_n=jnp.zeros(n), position_m=jnp.asarray(x), distance_m=jnp.asarray(travelled),
                               time_s=jnp.asarray(t), accel_mps2=jnp.full(n, a), direction=jnp.full(n, float(d)),
                               air_density_kgpm3=jnp.full(n, float(air_density_kgpm3())),
                               temperature_k=jnp.full(n, config.REFERENCE_TEMPERATURE_K),
                               mass_kg=jnp.full(n, vehicle.mass_kg), frontal_area_m2=jnp.full(n, vehicle.frontal_area_m2))
                force = (np.asarray(model.force_n(params, c)) + vehicle.effective_mass_kg * a
                         + rng.normal(0.0, settings.run_force_sd_n) + rng.normal(0.0, settings.force_noise_n, n))
                cols = {"run": run, "time_s": t, "speed_mps": v + rng.normal(0.0, settings.speed_noise_mps, n),
                        "tractive_force_n": force, "direction": d, "pair": pair}
                if gearbox_input:
                    on = thesis.THESIS_DRIVELINE_ON_LOAD
                    cols["gearbox_input_force_n"] = (force + on["At"] + on["Bt"] * v
                                                     + rng.normal(0.0, settings.driveline_noise_n, n))
                if anemometer:
                    cols["airspeed_mps"] = vr + rng.normal(0.0, simulation.airspeed_noise_mps, n)
                    cols["yaw_rad"] = psi + rng.normal(0.0, simulation.yaw_noise_rad, n)
                frames.append(pd.DataFrame(cols))
    truth = {k: float(params[k]) for k in ("AD", "BD", "CD0", "KD")}
    truth.update({k: float(v) for k, v in params.items()})
    if gearbox_input:
        truth.update({f"{k}_on_load": float(v) for k, v in thesis.THESIS_DRIVELINE_ON_LOAD.items()})
    truth.update({"case": sc.number if case is not None else None, "model": sc.model,
                  "sigma_force_n": settings.force_noise_n, "run_force_sd_n": settings.run_force_sd_n})
    tunnel = {"KD": float(simulation.coefficients["KD"]), "CL0": float(simulation.full_model_params["CL0"]),
              "KL": float(simulation.full_model_params["KL"])}
    meta = {"simulated": "steady", "case": truth["case"] if truth["case"] is not None else "still", "seed": int(seed),
            "pairs_per_speed": int(pairs), "head_wind_mps": head, "cross_wind_mps": cross}
    return SteadyCampaign(pd.concat(frames, ignore_index=True), vehicle, tunnel=tunnel, truth=truth, meta=meta)
