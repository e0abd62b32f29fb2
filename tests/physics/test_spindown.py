"""Wheel spin-down physics (eq. 5.13-5.14) against an independent ODE solution."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from bayes_roadload.physics.spindown import (
    equivalent_mass_kg,
    spindown_interval_drag_n,
    spindown_speed_mps,
    spindown_stop_time_s,
)

M_W = float(equivalent_mass_kg(0.59, 0.28))


@pytest.mark.parametrize("aw, bw", [(1.66, 0.121), (1.58, 0.0), (0.5, 0.4)])
def test_closed_form_matches_the_ode(aw, bw):
    # I dw/dt = -(A + B w R) R integrated by scipy in the angular speed, compared in tread speed
    r, inertia = 0.28, 0.59
    t = np.linspace(0.0, 40.0, 161)
    sol = solve_ivp(lambda _, w: -(aw + bw * w * r) * r / inertia, (0.0, 40.0), [30.0 / r], t_eval=t,
                    rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(np.asarray(spindown_speed_mps(t, 30.0, aw, bw, M_W)), sol.y[0] * r, rtol=1e-8, atol=1e-8)


def test_stop_time_is_where_the_speed_reaches_zero():
    for bw in (0.121, 0.0):
        t_stop = float(spindown_stop_time_s(31.0, 1.66, bw, M_W))
        assert float(spindown_speed_mps(t_stop, 31.0, 1.66, bw, M_W)) == pytest.approx(0.0, abs=1e-9)


def test_interval_drag_recovers_the_linear_law():
    # eq. 5.14 on the exact solution: the mean drag over an interval is A + B x (time-mean speed),
    # within (B^2 / m) x O(dt^2) of A + B x (endpoint mean): at 4 Hz far below 1e-4 N
    aw, bw = 1.66, 0.121
    t = np.arange(0.0, 60.0, 0.25)
    f, s = spindown_interval_drag_n(t, np.asarray(spindown_speed_mps(t, 31.0, aw, bw, M_W)), M_W)
    np.testing.assert_allclose(np.asarray(f), aw + bw * np.asarray(s), atol=1e-4)
