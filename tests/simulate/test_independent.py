"""The independent simulator: no shared code with the analysis, exact dynamics, the contract,
Type B draws inside the standards, and recovery by the project's least squares."""

import ast
import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from bayes_roadload.data import load_campaign, save_campaign
from bayes_roadload.simulate.independent import (EFFECTS, TYPE_B, RunConditions, apply_effects, first_draws,
                                                 random_vehicle, simulate_independent, simulate_run,
                                                 true_roadload)
from bayes_roadload.simulate.independent import sensors as sens
from bayes_roadload.simulate.independent.dynamics import AnemometerDynamics, anemometer_response, moist_air_density
from bayes_roadload.simulate.independent.wind import von_karman_turbulence

PACKAGE = Path(__file__).resolve().parents[2] / "bayes_roadload" / "simulate" / "independent"
FORBIDDEN = ("bayes_roadload.physics", "bayes_roadload.inference", "bayes_roadload.config",
             "bayes_roadload.analysis", "bayes_roadload.simulate", "jax", "numpyro")
OWN = "bayes_roadload.simulate.independent"


def _imported_modules(path: Path) -> list[str]:
    """Absolute names of every module a file imports (relative imports resolved)."""
    package = OWN.split(".")
    names = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            names += [module] + [f"{module}.{a.name}" for a in node.names]
    return names


def test_no_module_imports_the_analysis():
    files = sorted(PACKAGE.glob("*.py"))
    assert len(files) >= 7
    for f in files:
        for name in _imported_modules(f):
            if name.startswith(OWN):
                continue
            bad = [p for p in FORBIDDEN if name == p or name.startswith(p + ".")]
            assert not bad, f"{f.name} imports {name}"


def _quadratic_vehicle(rng):
    """A vehicle whose drag in still air on a level road is a + b v + c v^2."""
    v = apply_effects(random_vehicle(rng, "mid_car"), frozenset())
    return dataclasses.replace(v, driveline_a_n=12.0, driveline_b_nspm=1.5, driveline_c_ns2pm2=0.0)


def test_still_air_coastdown_matches_the_closed_form():
    rng = np.random.default_rng(0)
    veh = _quadratic_vehicle(rng)
    cond = RunConditions(direction=1, start_position_m=0.0, v0_mps=32.0, v_stop_mps=5.0, gravity_mps2=9.80665)
    trace = simulate_run(veh, cond, np.arange(0.0, 500.0, 0.25))
    g, m, me = cond.gravity_mps2, veh.mass_kg, veh.effective_mass_kg
    rho = moist_air_density(cond.pressure_pa, cond.temperature_k)
    a = m * g * veh.rr_c0 + veh.driveline_a_n
    b = m * g * veh.rr_c1_s_per_m + veh.driveline_b_nspm
    c = 0.5 * rho * veh.frontal_area_m2 * veh.cd0
    k = math.sqrt(4 * a * c - b * b)
    # ROADLOAD_MODEL.md section 6 (appendix D) inverted for v(t)
    v = (k * np.tan(np.arctan((2 * c * 32.0 + b) / k) - k * trace.time_s / (2 * me)) - b) / (2 * c)
    assert trace.speed_mps[-1] > 5.0 and trace.speed_mps[-1] < 5.0 + 0.25 * 0.5  # stopped at v_stop
    assert np.max(np.abs(trace.speed_mps - v)) < 1e-6
    # the distance is the integral of the speed (trapezoid error ~ h^2 |v''| T / 12 < 1e-3 m)
    assert abs(trace.distance_m[-1] - np.trapezoid(trace.speed_mps, trace.time_s)) < 1e-2


def test_a_run_that_never_reaches_its_stop_speed_ends_where_it_leaves_the_track():
    """On a 3 % downhill grade the car's rolling loss (about 1 % of its weight) no longer
    balances the slope below ~20 m/s: the speed settles above the stop speed.  The logging ends
    at the track's end (every kept sample on the track, the next one off it); on a track longer
    than the sample times reach the run is refused as before."""
    from bayes_roadload.simulate.independent.track import Track

    veh = _quadratic_vehicle(np.random.default_rng(0))
    cond = RunConditions(direction=1, start_position_m=0.0, v0_mps=32.0, v_stop_mps=5.0, gravity_mps2=9.80665)
    samples = np.arange(0.0, 500.0, 0.25)
    trace = simulate_run(veh, cond, samples, track=Track(start_m=-400.0, end_m=3000.0, mean_grade=-0.03))
    assert trace.position_m[-1] <= 3000.0 < trace.position_m[-1] + trace.speed_mps[-1] * 0.25
    assert trace.speed_mps[-1] > 15.0 and trace.time_s.size < samples.size
    with pytest.raises(RuntimeError, match="did not reach its stop speed .* nor leave the track"):
        simulate_run(veh, cond, samples, track=Track(start_m=-400.0, end_m=1e6, mean_grade=-0.03))


def test_truth_of_a_linear_tyre_law_is_exact():
    rng = np.random.default_rng(1)
    veh = _quadratic_vehicle(rng)
    g = 9.79
    truth = true_roadload(veh, g)
    assert truth["AD"] == pytest.approx(veh.rr_c0 * g / 9.81, rel=1e-12)
    assert truth["BD"] == pytest.approx(veh.rr_c1_s_per_m * g / 9.81, rel=1e-9)
    v = 50 * 0.44704
    rho = 1e5 / (287.05 * 293.2)
    f50 = veh.mass_kg * g * (veh.rr_c0 + veh.rr_c1_s_per_m * v) + 0.5 * rho * veh.frontal_area_m2 * veh.cd0 * v**2 + 12.0 + 1.5 * v
    assert truth["F50_N"] == pytest.approx(f50, rel=1e-12)
    # quadratic in v: F0 + F1 V + F2 V^2 (V in km/h) reproduces it exactly
    V = 50 * 1.609344
    assert truth["F0_N"] + truth["F1_N_per_kph"] * V + truth["F2_N_per_kph2"] * V**2 == pytest.approx(f50, rel=1e-9)
    assert truth["F50_tyre_N"] + truth["F50_aero_N"] + truth["F50_driveline_N"] == pytest.approx(f50, rel=1e-12)


def test_campaign_reads_back_through_the_contract(tmp_path):
    c = simulate_independent(5, pairs=1, category="small_car", sample_rate_hz=2.0,
                             withhold=("turbulence",))
    out = save_campaign(c, tmp_path / "ind")
    back = load_campaign(out)
    assert set(back.runs.columns) >= {"run", "time_s", "speed_mps", "direction", "pair", "airspeed_mps",
                                      "yaw_rad", "temperature_k", "pressure_pa", "position_m",
                                      "driveline_force_n"}
    np.testing.assert_allclose(back.runs["speed_mps"], c.runs["speed_mps"], rtol=1e-9)
    assert back.vehicle.mass_kg == pytest.approx(c.vehicle.mass_kg, rel=1e-9)
    assert back.anemometer.airspeed_factor == pytest.approx(c.anemometer.airspeed_factor, rel=1e-9)
    assert sorted(back.directions().values()) == [-1, 1]
    for k in ("AD", "BD", "CD0", "KD", "At", "Bt", "Ct", "F0_N", "F1_N_per_kph", "F2_N_per_kph2", "F50_N"):
        assert math.isfinite(back.truth[k])
    assert set(back.truth["meta"]["effects"]) == set(EFFECTS) - {"turbulence"}
    assert back.tunnel["CL0"] == pytest.approx(back.truth["meta"]["vehicle_simulated"]["cl0"])


def test_type_b_draws_inside_the_standards_accuracies():
    limits = {"speed_scale_rel": sens.SPEED_ACCURACY_MPS / sens.SPEED_ACCURACY_AT_MPS,
              "airspeed_factor_rel": sens.RELATIVE_WIND_ACCURACY_MPS / sens.RELATIVE_WIND_ACCURACY_AT_MPS,
              "yaw_offset_rad": math.radians(1.0), "yaw_factor_rel": 0.10,
              "temperature_bias_k": 1.0, "pressure_bias_pa": 700.0, "rolling_radius_rel": 0.01,
              "rotating_inertia_rel": 0.10, "track_mean_grade": 0.0002, "driveline_scale_rel": 0.01}
    seen_nonzero = set()
    for seed in range(6):
        c = simulate_independent(seed, pairs=1, effects=(), sample_rate_hz=1.0)
        m = c.truth["meta"]
        err = m["type_b_errors"]
        assert set(TYPE_B) == set(err) - {"effective_mass_kg"}   # every draw is documented
        for k, lim in limits.items():
            assert abs(err[k]) <= lim, (seed, k, err[k])
            if err[k] != 0.0:
                seen_nonzero.add(k)
        axles = {"heavy_truck": 5}.get(m["vehicle_true"]["category"], 2)
        assert abs(err["mass_kg"]) <= 5.0 * axles
        # the vane's combined error at 15 deg stays inside J2263's +-3 deg
        yaw = math.radians(15.0)
        assert abs(yaw * err["yaw_factor_rel"]) + abs(err["yaw_offset_rad"]) < math.radians(3.0)
        # declared values are the ones written to vehicle.toml
        assert c.vehicle.mass_kg == pytest.approx(m["vehicle_true"]["mass_kg"] + err["mass_kg"])
    assert seen_nonzero == set(limits)
    assert set(limits) | {"mass_kg"} == set(TYPE_B)
    clean = simulate_independent(0, pairs=1, effects=(), sample_rate_hz=1.0, type_b=False)
    assert all(v == 0.0 for k, v in clean.truth["meta"]["type_b_errors"].items())


def test_first_draws_are_the_campaigns_vehicle_and_rate():
    """What the studies' readings rebuild without simulating is what a campaign of the same seed
    and a given size draws (its truth's vehicle and its logging rate)."""
    for seed in (3001, 9020):
        vehicle, rate = first_draws(seed)
        meta = simulate_independent(seed, pairs=1).truth["meta"]
        assert meta["vehicle_true"] == json.loads(json.dumps(vehicle.as_dict()))
        assert meta["sample_rate_hz"] == rate


def test_a_realisation_keeps_the_campaign_and_redraws_the_runs():
    """``realisation``: the campaign-level draws are the seed's (vehicle, rate, instruments,
    Type B errors, mean wind), the runs' own draws and the gusts are another realisation's."""
    def runs_meta(c):
        return [{k: r[k] for k in ("v0_mps", "v_stop_mps", "tyre_factor", "cd_factor", "clock_start_s")}
                for r in c.truth["meta"]["runs"]]

    legacy, first, again, second = (simulate_independent(9056, pairs=1, sample_rate_hz=2.0, realisation=r)
                                    for r in (None, 0, 0, 1))
    for c in (first, second):
        for key in ("vehicle_true", "declared", "type_b_errors", "instruments", "wind", "track", "gravity_mps2"):
            assert c.truth["meta"][key] == legacy.truth["meta"][key], key
        assert c.meta["realisation"] in (0, 1) and "realisation" not in legacy.meta
    assert runs_meta(first) == runs_meta(again) and first.runs.equals(again.runs)
    for a, b in ((legacy, first), (first, second)):
        ra, rb = runs_meta(a), runs_meta(b)
        assert all(x["v0_mps"] != y["v0_mps"] and x["cd_factor"] != y["cd_factor"] for x, y in zip(ra, rb))
    # the gusts: the same start speed and noise-free instruments cannot give the same airspeed
    quiet = dict(pairs=1, sample_rate_hz=2.0, perfect_instruments=True, speed_noise_sd_mps=0.0,
                 effects=("turbulence",), mean_wind_mps=(3.0, 1.0))
    a, b = (simulate_independent(9056, realisation=r, **quiet) for r in (0, 1))
    assert a.truth["meta"]["wind"] == b.truth["meta"]["wind"]
    n = 20
    va, vb = (c.runs["airspeed_mps"].to_numpy()[:n] - c.runs["speed_mps"].to_numpy()[:n] for c in (a, b))
    assert np.max(np.abs(va - vb)) > 0.05


@pytest.mark.slow  # a cross-check kept out of the default run's 10 minutes
def test_a_realisations_runs_keep_their_draws_when_an_effect_is_withheld():
    """With ``realisation`` each run draws from its own stream: withholding an effect that
    changes the first run's length leaves the second run's draws as they were; with the one
    stream of ``realisation=None`` the same ablation shifts them."""
    def draws(c, run):
        r = c.truth["meta"]["runs"][run]
        return (r["v0_mps"], r["v_stop_mps"], r["tyre_factor"], r["cd_factor"], r["tyre_initial_excess_k"])

    kw = dict(pairs=1, category="small_car", sample_rate_hz=20.0)
    for realisation, same in ((0, True), (None, False)):
        every, withheld = (simulate_independent(3001, realisation=realisation, withhold=w, **kw)
                           for w in ((), ("grade_profile",)))
        assert every.truth["meta"]["runs"][0]["samples"] != withheld.truth["meta"]["runs"][0]["samples"]
        assert draws(every, 0) == draws(withheld, 0)
        assert (draws(every, 1) == draws(withheld, 1)) is same


@pytest.mark.slow  # a cross-check kept out of the default run's 10 minutes
def test_withholding_an_effect_keeps_every_other_draw():
    """Each effect withheld in turn (its draws made and discarded): the vehicle, site, mean wind,
    Type B errors, declared values and, with ``realisation``, every run's own draws are those of
    the campaign with every effect."""
    def fixed(c):
        m = c.truth["meta"]
        runs = [{k: r[k] for k in ("direction", "v0_mps", "v_stop_mps", "tyre_factor", "cd_factor")} for r in m["runs"]]
        return (m["vehicle_true"], m["declared"], m["type_b_errors"], m["gravity_mps2"], m["temperature0_k"],
                m["wind"]["mean_speed_mps"], m["wind"]["direction_rad"], runs)

    kw = dict(pairs=1, category="small_car", sample_rate_hz=1.0, realisation=0)
    every = fixed(simulate_independent(11, **kw))
    for name in EFFECTS:
        assert fixed(simulate_independent(11, withhold=(name,), **kw)) == every, name


def test_effect_names_are_checked_and_sourced():
    with pytest.raises(ValueError, match="unknown effect"):
        simulate_independent(0, pairs=1, withhold=("no_such_effect",))
    for name, e in EFFECTS.items():
        assert e.size and e.source, name
    c = simulate_independent(0, pairs=1, category="small_car", effects=(), sample_rate_hz=1.0)
    assert "CL0" not in c.tunnel and c.truth["meta"]["vehicle_simulated"]["cl0"] == 0.0
    assert "driveline_force_n" not in c.runs


def test_turbulence_has_the_stated_intensity():
    sigma, scale = 1.2, 25.0
    turb = von_karman_turbulence(np.random.default_rng(3), sigma, scale)
    x = np.arange(0.0, 100_000.0, 2.0)
    ux, uy = turb.velocity(x, np.zeros_like(x))
    # sum of both components' variances is set exactly (sum a^2 / 2 = 2 sigma^2); along a
    # 100 km line (4000 length scales, 200 of the longest modelled wavelength 20 L) the sample
    # variance is within ~2 %; allow 5 %
    assert (ux.var() + uy.var()) / (2 * sigma**2) == pytest.approx(1.0, abs=0.05)


def test_cup_over_speeds_in_a_fluctuating_wind():
    t = np.arange(0.0, 60.0, 1.0 / 400.0)
    air = 20.0 + 3.0 * np.sin(2 * np.pi * 2.0 * t)       # 2 Hz gusts of 3 m/s
    yaw = np.zeros_like(t)
    sym, _ = anemometer_response(AnemometerDynamics(distance_constant_m=2.0, overspeed_ratio=1.0), t, air, yaw)
    fast, _ = anemometer_response(AnemometerDynamics(distance_constant_m=2.0, overspeed_ratio=1.8), t, air, yaw)
    tail = t > 5.0
    # a symmetric first-order sensor is unbiased to first order (bias ~ amplitude^2 effects,
    # < 1 % here); the asymmetric one over-reads by a sizeable fraction of the amplitude
    assert abs(sym[tail].mean() - 20.0) < 0.2
    assert fast[tail].mean() - 20.0 > 0.3


def test_fit_lsq_recovers_F50_with_perfect_instruments_and_no_effects():
    from bayes_roadload.inference.lsq import fit_lsq

    c = simulate_independent(11, pairs=1, effects=(), type_b=False, run_to_run_sd=0.0, sample_rate_hz=2.0,
                             perfect_instruments=True, speed_noise_sd_mps=0.03)
    assert c.truth["meta"]["type_b_errors"]["mass_kg"] == 0.0
    res = fit_lsq(c, "three_term", grouping="all")
    est, se = res.weighted_mean["F50_N"], res.weighted_se["F50_N"]
    # the simulator and the analysis then describe the same physics up to the integrators'
    # errors (< 1e-4 N) and the air constant (287.058 vs 287.05 J/(kg K): 3e-5 relative on the
    # aero part, ~0.01 N), so the estimate is unbiased with standard error se: |z| < 4 fails
    # with probability 6e-5 under the null
    assert 0 < se < 0.02 * est
    assert abs(est - c.truth["F50_N"]) < 4.0 * se + 0.05
    for p in ("AD", "BD", "CD0"):
        assert abs(res.weighted_mean[p] - c.truth[p]) < 4.0 * res.weighted_se[p], p


def test_set_errors_and_mean_wind_replace_the_draws():
    """``errors=`` sets the named Type B errors (the others stay zero without ``type_b``, or
    as drawn with it), ``mean_wind_mps=`` the mean wind; unknown errors are refused."""
    from bayes_roadload.simulate.independent.campaign import SETTABLE_ERRORS
    want = {"mass_kg": 25.0, "airspeed_factor_rel": 0.03, "yaw_factor_rel": -0.08, "yaw_offset_rad": 0.03,
            "track_mean_grade": 0.0007, "rotating_inertia_rel": 0.2}
    assert set(want) == set(SETTABLE_ERRORS)
    c = simulate_independent(3, pairs=1, effects=(), sample_rate_hz=1.0, type_b=False, errors=want,
                             mean_wind_mps=(2.0, -1.5))
    m = c.truth["meta"]
    for k, v in want.items():
        assert m["type_b_errors"][k] == pytest.approx(v, rel=1e-12), k
    assert m["type_b_errors"]["speed_scale_rel"] == 0.0 and m["type_b_errors"]["pressure_bias_pa"] == 0.0
    assert c.vehicle.mass_kg == pytest.approx(m["vehicle_true"]["mass_kg"] + 25.0)
    assert c.anemometer.airspeed_factor == pytest.approx(m["instruments"]["airspeed_factor"] * 1.03)
    assert m["wind"]["mean_speed_mps"] == pytest.approx(math.hypot(2.0, 1.5))
    assert m["wind"]["direction_rad"] == pytest.approx(math.atan2(-1.5, 2.0))
    # the rest of the campaign is the one drawn without them
    plain = simulate_independent(3, pairs=1, effects=(), sample_rate_hz=1.0, type_b=False)
    assert plain.truth["meta"]["vehicle_true"] == m["vehicle_true"]
    with pytest.raises(ValueError, match="unknown"):
        simulate_independent(3, pairs=1, effects=(), errors={"speed_scale": 0.01})


@pytest.mark.slow  # a cross-check kept out of the default run's 10 minutes
def test_an_overflowing_trial_step_of_the_stiff_wind_filter_is_rejected_not_raised():
    """Seed 6155 at 4 pairs draws a 30 t, 16 m truck in gusty wind: a trial step of DOP853 on
    the body's wind filter (time constant length / airspeed) overflowed the airspeed, and
    Python's float power raised OverflowError out of ``solve_ivp``.  The solver now sees inf,
    rejects the step and shortens it: the campaign comes out finite, every run from its start
    speed down to its stop speed."""
    c = simulate_independent(6155, pairs=4)
    runs = c.runs
    assert np.isfinite(runs.select_dtypes("number").to_numpy()).all()
    ends = runs.groupby("run")["speed_mps"].agg(["first", "last"])
    assert len(ends) == 8 and (ends["first"] > 30.0).all() and (ends["last"] < 6.0).all()


def test_humidity_is_logged_on_request_and_leaves_every_other_draw_alone(tmp_path):
    """The ``humidity`` channel adds the hygrometer's reading (bias inside its +-2 %, noise
    0.3 %) and changes nothing else of the seed; without the humidity effect there is no vapour
    to read and no column."""
    from bayes_roadload.simulate.independent import CHANNELS, DEFAULT_CHANNELS

    assert "humidity" in CHANNELS and "humidity" not in DEFAULT_CHANNELS
    plain = simulate_independent(7, pairs=1)
    logged = simulate_independent(7, pairs=1, channels=DEFAULT_CHANNELS + ("humidity",))
    back = load_campaign(save_campaign(logged, tmp_path / "c"))
    assert "relative_humidity_pct" in back.runs
    rh = logged.runs.pop("relative_humidity_pct").to_numpy()
    assert logged.runs.equals(plain.runs)
    true_pct = 100.0 * logged.truth["meta"]["relative_humidity"]
    assert 30.0 <= true_pct <= 95.0
    # bias within +-2 %, noise 0.3 % (5 sd), rounding 0.05 %
    assert np.all(np.abs(rh - true_pct) <= sens.HUMIDITY_ACCURACY_PCT + 5 * 0.3 + 0.05)
    assert abs(rh.mean() - true_pct - logged.truth["meta"]["hygrometer"]["bias_pct"]) < 0.1
    dry = simulate_independent(7, pairs=1, withhold=("humidity",), channels=DEFAULT_CHANNELS + ("humidity",))
    assert "relative_humidity_pct" not in dry.runs


def test_the_track_survey_is_logged_on_request_and_leaves_every_other_draw_alone(tmp_path):
    """The ``survey`` channel writes ``track.csv``: stations every 10 m over the whole track, the
    undulations without the mean grade (the Type B ``track_mean_grade``), each station's error
    inside its drawn sd and the 1 mm rounding; the runs are those of the campaign without it.
    The grade it puts on each logged position differs from that of the error-free stations by
    the segment grades' error, two stations' errors over 10 m: rms at most sqrt(2) sqrt(sigma^2
    + (1 mm)^2 / 6) / 10 m (each station's error and the two roundings), with a margin of 1.25
    for the rms estimated from a few hundred segments (6 of its standard errors)."""
    from bayes_roadload.data.track import grade_at
    from bayes_roadload.simulate.independent import CHANNELS, DEFAULT_CHANNELS
    from bayes_roadload.simulate.independent.campaign import SURVEY_NOISE_M, SURVEY_SPACING_M

    assert "survey" in CHANNELS and "survey" not in DEFAULT_CHANNELS
    with pytest.raises(ValueError, match="needs 'position'"):
        simulate_independent(7, pairs=1, channels=("anemometer", "survey"))
    plain = simulate_independent(7, pairs=2, effects=("grade_profile",))
    c = simulate_independent(7, pairs=2, effects=("grade_profile",), channels=DEFAULT_CHANNELS + ("survey",))
    assert plain.track is None and c.runs.equals(plain.runs)
    assert "surveyed" not in plain.truth["meta"]["track"]   # a campaign without it writes the truth it wrote before
    meta = c.truth["meta"]["track"]
    sigma = meta["surveyed"]["noise_sd_m"]
    assert SURVEY_NOISE_M[0] <= sigma <= SURVEY_NOISE_M[1]
    x = c.track["position_m"].to_numpy()
    np.testing.assert_allclose(np.diff(x), SURVEY_SPACING_M)
    np.testing.assert_allclose(x, meta["survey_stations_m"])
    # the true elevation without its mean grade, against the survey: 5 sd of the error and the rounding
    true_z = np.asarray(meta["survey_elevation_m"]) - meta["mean_grade"] * (x - x[0])
    assert np.max(np.abs(c.track["elevation_m"].to_numpy() - true_z)) <= 5 * sigma + 1e-3
    # the grade at the logged positions against the undulations' grade (the mean grade removed)
    pos = c.runs["position_m"].to_numpy()
    stations, elevation = np.asarray(meta["survey_stations_m"]), true_z
    fine = np.interp(pos, 0.5 * (stations[1:] + stations[:-1]), np.diff(elevation) / SURVEY_SPACING_M)
    rms_undulation = meta["rms_undulation_grade"]
    bound = 1.25 * np.sqrt(2) * np.hypot(sigma, 1e-3 / np.sqrt(6)) / SURVEY_SPACING_M
    err = grade_at(c.track, pos) - np.arctan(fine)
    assert np.sqrt(np.mean(err**2)) <= bound
    assert np.std(grade_at(c.track, pos)) > 0.5 * rms_undulation   # the survey sees the undulations
    back = load_campaign(save_campaign(c, tmp_path / "c"))
    assert back.has_track_survey


@pytest.mark.parametrize("effect", ["anemometer_yaw_factor", "humidity", "turbulence", "anemometer_dynamics"])
def test_a_withheld_effect_leaves_the_campaigns_other_draws_as_they_were(effect):
    """An ablation's two arms differ by the withheld effect alone in everything drawn per
    campaign: the withheld effect's draws are made and discarded, so the instruments, the
    Type B errors, the wind's mean and the first run's start are those of the campaign with it
    on; and the campaign with every effect on is unchanged by the option."""
    full = simulate_independent(3001, pairs=1)
    off = simulate_independent(3001, pairs=1, withhold=(effect,))
    a, b = full.truth["meta"], off.truth["meta"]
    assert a["type_b_errors"] == b["type_b_errors"] and a["declared"] == b["declared"]
    inst_a, inst_b = dict(a["instruments"]), dict(b["instruments"])
    if effect == "anemometer_yaw_factor":
        assert inst_a.pop("airspeed_factor_yaw") > 0.0 and inst_b.pop("airspeed_factor_yaw") == 0.0
    assert inst_a == inst_b
    assert a["wind"]["mean_speed_mps"] == b["wind"]["mean_speed_mps"]
    assert a["sample_rate_hz"] == b["sample_rate_hz"]
    assert effect in a["effects"] and effect not in b["effects"]
    assert a["hygrometer"] == b["hygrometer"]


def test_withholding_an_effect_that_was_not_asked_for_changes_nothing():
    """``withhold`` takes effects out of those asked for: withholding one outside ``effects``
    leaves the campaign of ``effects`` as it is (its draws are not made either)."""
    asked = simulate_independent(3001, pairs=1, effects=("turbulence",))
    also = simulate_independent(3001, pairs=1, effects=("turbulence",), withhold=("humidity",))
    assert also.runs.equals(asked.runs)
