"""A chassis-dynamometer coastdown with known parasitic losses.

On the rolls the vehicle decelerates under the dynamometer's set load plus the parasitic
losses (rolls, bearings, the vehicle's own driveline and tyres on the rolls)::

    M_dyno dv/dt = -[(a_s + a_p) + (b_s + b_p) V + (c_s + c_p) V^2]     (V in km/h, forces in N)

integrated with RK4 from ``v0_kph`` to ``v_end_kph``; ``M_dyno`` is the inertia setting (kg).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pandas as pd

from .. import config
from ..data.dyno import DynoCoastdown


def simulate_dyno_coastdown(set_coefficients: Sequence[float], parasitic_coefficients: Sequence[float],
                            inertia_kg: float, *, v0_kph: float = 130.0, v_end_kph: float = 10.0,
                            dt_s: float = 0.1, speed_noise_mps: float = 0.0, seed: int = 0) -> pd.DataFrame:
    """Speed trace ``time_s, speed_mps`` of one dynamometer coastdown (module docstring).

    Parameters
    ----------
    set_coefficients, parasitic_coefficients : (a N, b N/(km/h), c N/(km/h)^2).
    inertia_kg : the dynamometer's inertia setting.
    speed_noise_mps : standard deviation of white measurement noise added to the speed.
    """
    total = np.asarray(set_coefficients, float) + np.asarray(parasitic_coefficients, float)
    kph = 1.0 / config.KPH_TO_MPS

    def accel(v):
        vk = v * kph
        return -(total[0] + total[1] * vk + total[2] * vk**2) / inertia_kg

    v, t = v0_kph * config.KPH_TO_MPS, 0.0
    ts, vs = [t], [v]
    while v > v_end_kph * config.KPH_TO_MPS and t < 3600.0:
        k1 = accel(v)
        k2 = accel(v + 0.5 * dt_s * k1)
        k3 = accel(v + 0.5 * dt_s * k2)
        k4 = accel(v + dt_s * k3)
        v = v + dt_s / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t += dt_s
        ts.append(t)
        vs.append(v)
    speed = np.asarray(vs)
    if speed_noise_mps > 0:
        speed = speed + np.random.default_rng(seed).normal(0.0, speed_noise_mps, speed.size)
    return pd.DataFrame({"time_s": np.asarray(ts), "speed_mps": speed})


def simulate_dyno(set_coefficients: Sequence[float], parasitic_coefficients: Sequence[float], inertia_kg: float,
                  **kwargs) -> DynoCoastdown:
    """A dynamometer coastdown directory's content (:class:`~bayes_roadload.data.dyno.DynoCoastdown`)
    with the true parasitic losses recorded; ``kwargs`` go to :func:`simulate_dyno_coastdown`."""
    runs = simulate_dyno_coastdown(set_coefficients, parasitic_coefficients, inertia_kg, **kwargs)
    return DynoCoastdown(runs, float(inertia_kg), tuple(float(x) for x in set_coefficients),
                         tuple(float(x) for x in parasitic_coefficients))
