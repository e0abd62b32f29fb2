"""The vehicle's aerodynamic admittance (physics.admittance) and its use by the analysis."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import bayes_roadload.simulate.sensors as S
from bayes_roadload.data.checks import CampaignError
from bayes_roadload.data.vehicle import vehicle_from_toml, vehicle_toml
from bayes_roadload.inference.lsq import fit_lsq
from bayes_roadload.inference.spec import ModelSpecError, load_model_spec
from bayes_roadload.physics.admittance import felt_air, felt_air_readings, first_order_lag
from bayes_roadload.simulate import simulate_campaign


def test_first_order_lag_is_exact_for_a_ramp_and_holds_on_padding():
    t = np.linspace(0.0, 10.0, 41)
    tau = 0.7
    y = np.asarray(first_order_lag(t, 2.0 * t, np.full_like(t, tau)))
    exact = 2.0 * t - 2.0 * tau * (1.0 - np.exp(-t / tau))   # y(0) = x(0) = 0
    assert np.max(np.abs(y - exact)) < 1e-12
    padded = np.concatenate([t, np.full(4, t[-1])])
    yp = np.asarray(first_order_lag(padded, np.concatenate([2.0 * t, np.full(4, 99.0)]), np.full_like(padded, tau)))
    assert np.all(yp[-5:] == yp[-5])   # zero-length steps leave the output unchanged


def test_the_sequential_affine_scan_is_the_associative_one():
    """The filter's sequential form of the recurrence y_{k+1} = a_k y_k + b_k gives the
    likelihood's associative one on [runs, samples] arrays, and the loop written out by hand."""
    from bayes_roadload.physics.integrate import affine_scan

    rng = np.random.default_rng(4)
    a, b = rng.uniform(0.5, 1.0, (3, 40)), rng.normal(size=(3, 40))
    seq, par = affine_scan(a, b, sequential=True), affine_scan(a, b)
    y = np.zeros(3)
    for k in range(40):  # y_0 = 0: the offsets are the recurrence itself
        y = a[:, k] * y + b[:, k]
    # 40 products of factors below one: rounding of a few ulp in either order
    np.testing.assert_allclose(np.asarray(seq[1])[:, -1], y, rtol=1e-12, atol=1e-12)
    for s, p in zip(seq, par):
        np.testing.assert_allclose(np.asarray(s), np.asarray(p), rtol=1e-12, atol=1e-12)


def test_admittance_step_matches_the_simulators_block():
    """A step of wind (along and across) at constant airspeed: the felt wind against the
    thesis simulator's admittance block (simulate.sensors, RK4 on a fine grid), within that
    stepper's error."""
    length, airspeed, step, dt = 4.5, 25.0, 2.0, 0.002
    r = S.simulate_sensor_step(airspeed, airspeed, 0.0, 5 * length / airspeed, dt,
                               wind_step_mps=step, vehicle_length_m=length)
    t = np.asarray(r["time_s"])
    v = np.full_like(t, airspeed)
    # the true relative air after the step: the vehicle at airspeed - step into a head wind
    # `step` and a cross wind `step`; before it, still air
    along, cross = np.where(t > 0, step, 0.0), np.where(t > 0, step, 0.0)
    va, psi = felt_air(t, v - along, np.hypot(v, cross), np.arctan2(cross, v), length)
    felt_cross = np.asarray(va * np.sin(psi))
    assert np.max(np.abs(felt_cross - np.asarray(r["felt_cross_mps"]))) < 0.01 * step
    assert np.interp(length / airspeed, t, felt_cross) / step == pytest.approx(1 - math.exp(-1), abs=0.01)


def test_steady_air_is_felt_unchanged_and_readings_keep_their_calibration():
    t = np.linspace(0.0, 20.0, 81)
    v = 30.0 - 0.8 * t                                  # decelerating, steady wind
    wind_along, wind_cross = 3.0, 2.0
    va, psi = np.hypot(v + wind_along, wind_cross), np.arctan2(wind_cross, v + wind_along)
    fa, fy = 1.08, 0.87
    air, yaw = felt_air_readings(t[None], v[None], va[None] / fa, psi[None] / fy, fa, fy, 5.0)
    assert np.max(np.abs(np.asarray(air)[0] * fa - va)) < 1e-9   # the body's own speed is felt at once
    assert np.max(np.abs(np.asarray(yaw)[0] * fy - psi)) < 1e-9


def test_gusts_shorter_than_the_vehicle_are_attenuated():
    """A sinusoidal cross gust of angular frequency w reaches the body with the first-order
    gain 1 / sqrt(1 + (w tau)^2), tau = l / V_r."""
    t = np.arange(0.0, 60.0, 0.01)
    v = np.full_like(t, 25.0)
    omega, amp, length = 2 * math.pi * 2.0, 1.0, 8.0
    cross = amp * np.sin(omega * t)
    va, psi = felt_air(t, v, np.hypot(v, cross), np.arctan2(cross, v), length)
    felt = np.asarray(va * np.sin(psi))[t > 30]
    tau = length / 25.0   # V_r within 0.1 % of 25 m/s
    expected = amp / math.sqrt(1 + (omega * tau) ** 2)
    assert (felt.max() - felt.min()) / 2 == pytest.approx(expected, rel=0.01)


DOC = {"vehicle": {"mass_kg": 1000.0, "effective_mass_kg": 1030.0, "frontal_area_m2": 2.0}}


def test_vehicle_length_is_optional_checked_and_written_when_stated():
    vehicle = vehicle_from_toml(DOC, "v.toml")[0]
    assert vehicle.length_m is None
    stated = vehicle_from_toml({"vehicle": dict(DOC["vehicle"], length_m=4.2)}, "v.toml")[0]
    assert stated.length_m == 4.2
    with pytest.raises(CampaignError, match=r"v\.toml.*\[vehicle\] length_m"):
        vehicle_from_toml({"vehicle": dict(DOC["vehicle"], length_m=0.2)}, "v.toml")
    c = simulate_campaign(1, pairs=1, seed=0)
    assert "length_m = 4.5" in vehicle_toml(c)
    assert "length_m" not in vehicle_toml(dataclasses.replace(c, vehicle=dataclasses.replace(c.vehicle, length_m=None)))


def test_the_admittance_option_resolves_against_the_campaign():
    c = simulate_campaign(7, pairs=1, seed=0)
    spec = load_model_spec("four_term")
    assert spec.admittance == "none" and spec.resolve_admittance(c) == 0.0
    auto = dataclasses.replace(spec, admittance="auto")
    assert auto.resolve_admittance(c) == pytest.approx(4.5)
    unstated = dataclasses.replace(c, vehicle=dataclasses.replace(c.vehicle, length_m=None))
    assert auto.resolve_admittance(unstated) == 0.0
    still = dataclasses.replace(c, runs=c.runs.drop(columns=["airspeed_mps", "yaw_rad"]))
    assert auto.resolve_admittance(still) == 0.0
    with pytest.raises(ModelSpecError, match="length_m"):
        dataclasses.replace(spec, admittance="first_order").resolve_admittance(unstated)
    with pytest.raises(ModelSpecError, match="admittance"):
        dataclasses.replace(spec, admittance="second_order")
    b_none, _ = spec.to_batch(c)
    b_auto, _ = auto.to_batch(c)
    assert np.array_equal(np.asarray(b_none.speed_mps), np.asarray(b_auto.speed_mps))
    assert not np.allclose(np.asarray(b_none.yaw_rad), np.asarray(b_auto.yaw_rad))



def test_a_campaigns_felt_air_is_filtered_once_and_anew_when_it_changes(monkeypatch):
    """ModelSpec.to_batch remembers the filtered readings by content: the same campaign read
    again (a fit reads it for its start, its problem, its predictive and each Type B shift) runs
    the filter once and gives the same arrays; another factor, another length or another
    reading runs it again, with the result of an uncached call."""
    import bayes_roadload.inference.spec as spec_module

    calls = []
    real = spec_module.felt_air_readings

    def counted(*args):
        calls.append(args[4:])
        return real(*args)

    monkeypatch.setattr(spec_module, "felt_air_readings", counted)
    monkeypatch.setattr(spec_module, "_FELT_AIR", type(spec_module._FELT_AIR)())
    c = simulate_campaign(7, pairs=1, seed=3)
    auto = dataclasses.replace(load_model_spec("four_term"), admittance="auto")
    first, _ = auto.to_batch(c)
    again, _ = auto.to_batch(c)
    assert len(calls) == 1
    assert np.array_equal(first.yaw_rad, again.yaw_rad) and np.array_equal(first.airspeed_mps, again.airspeed_mps)
    with pytest.raises(ValueError):
        again.yaw_rad[0, 0] = 0.0  # shared between callers: read-only

    def uncached(campaign, length):
        raw, _ = campaign.to_batch()
        a = campaign.anemometer
        return [np.asarray(x) for x in real(raw.time_s, raw.speed_mps, raw.airspeed_mps, raw.yaw_rad,
                                              float(a.airspeed_factor), float(a.yaw_factor), length)]

    shifted = dataclasses.replace(c, anemometer=dataclasses.replace(c.anemometer, yaw_factor=1.05))
    longer = dataclasses.replace(c, vehicle=dataclasses.replace(c.vehicle, length_m=6.0))
    runs = c.runs.copy()
    runs["yaw_rad"] = runs["yaw_rad"] + 0.01
    gustier = dataclasses.replace(c, runs=runs)
    for changed, length in ((shifted, 4.5), (longer, 6.0), (gustier, 4.5)):
        before = len(calls)
        batch, _ = auto.to_batch(changed)
        assert len(calls) == before + 1
        air, yaw = uncached(changed, length)
        assert np.array_equal(batch.airspeed_mps, air) and np.array_equal(batch.yaw_rad, yaw)
        assert not np.array_equal(batch.yaw_rad, first.yaw_rad)
    auto.to_batch(c)
    assert len(calls) == 4  # the first campaign is still remembered

@pytest.mark.parametrize("case", [7, 8])
def test_the_admittance_removes_the_bias_of_the_thesis_simulators_dynamics(case):
    """Thesis cases 7 and 8 (instrument and vehicle dynamics, no noise): the simulator's body
    feels the wind through this admittance, so with it the least-squares coefficients move
    to the truth, A_D, B_D, C_D0 at least halving their error; the vane's dynamics (not in the
    analysis) keep a part of K_D's.  This checks the implementation against a simulator that
    follows the same thesis block, not the physics against independent data (that is the
    calibration study's)."""
    c = simulate_campaign(case, pairs=2, seed=0)
    spec = load_model_spec("four_term")
    err = {}
    for option in ("none", "first_order"):
        fit = fit_lsq(c, dataclasses.replace(spec, admittance=option), grouping="all")
        err[option] = {k: abs(fit.weighted_mean[k] / c.truth[k] - 1.0) for k in ("AD", "BD", "CD0", "KD")}
    for k in ("AD", "BD", "CD0"):
        assert err["first_order"][k] < 0.5 * err["none"][k], (k, err)
    assert err["first_order"]["KD"] < err["none"]["KD"], err
