"""A random coastdown campaign from the independent simulator, in the campaign contract.

The campaign's ``vehicle.toml`` holds the *declared* values (test mass, effective mass,
rolling radius, anemometer factors: the true ones with their Type B errors); ``truth.json``
holds the true parameters in the analysis' terms (:mod:`.reference`) and, under ``meta``,
every draw: the true vehicle, the instruments and their errors, the wind, the track, the
weather and the conditions of every run.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Iterable, Mapping

import numpy as np
import pandas as pd

from ...data import Anemometer, Campaign, Vehicle
from . import reference as ref
from . import sensors as sens
from .dynamics import AnemometerDynamics, RunConditions, simulate_run
from .effects import EFFECTS
from .track import Track, surveyed_track
from .vehicles import TrueVehicle, random_vehicle
from .wind import Shelter, WindField, random_shelter, von_karman_turbulence

CHANNELS = ("anemometer", "weather", "position", "driveline", "humidity", "survey")
"""Optional logged channels: airspeed_mps + yaw_rad, temperature_k + pressure_pa, position_m
+ distance_m, driveline_force_n (only when the vehicle has a driveline loss),
relative_humidity_pct (a hygrometer's reading; only when the ``humidity`` effect is on), and a
level survey of the track (``track.csv``, :func:`level_survey`; needs ``position``)."""
DEFAULT_CHANNELS = ("anemometer", "weather", "position", "driveline")
"""The channels logged by default: every one but the humidity and the track survey, which the
studies' campaigns did not log before they were channels (their records stay reproducible)."""
HYGROMETER_STREAM = 0x68756D
"""Second entropy word of the hygrometer's own random stream (``default_rng([seed, this])``),
so that logging the humidity leaves every other draw of a seed as it was."""
RUN_STREAM = 0x72756E
"""Second entropy word of a run's own random stream with ``realisation`` given
(``default_rng([seed, this, realisation, run index])``)."""
SURVEY_STREAM = 0x737276
"""Second entropy word of the track survey's own random stream (``default_rng([seed, this])``),
so that surveying the track leaves every other draw of a seed as it was."""
SURVEY_SPACING_M = 10.0
"""Station spacing of the track survey (m)."""
SURVEY_NOISE_M = (0.0005, 0.002)
"""Range of the survey's per-station elevation error (standard deviation, m): digital levelling
between 10 m stations, 0.5-2 mm per set-up."""
TURBULENCE_STREAM = 0x747262
"""Second entropy word of the turbulence's phases and directions with ``realisation`` given
(``default_rng([seed, this, realisation])``)."""
SAMPLE_RATES_HZ = (1.0, 2.0, 4.0, 5.0, 10.0, 20.0)
AXLES_OF = {"small_car": 2, "mid_car": 2, "suv_van": 2, "light_truck": 2, "heavy_truck": 5}
MAX_MEAN_WIND_MPS = 16.0 / 3.6   # SAE J1263: no test with average wind above 16 km/h ...
MAX_CROSS_WIND_MPS = 8.0 / 3.6   # ... or cross wind above 8 km/h

SETTABLE_ERRORS = ("mass_kg", "rotating_inertia_rel", "airspeed_factor_rel", "yaw_factor_rel", "yaw_offset_rad",
                   "track_mean_grade")
"""The Type B errors :func:`simulate_independent` can be given (``errors=``) instead of drawing."""
YAW_LOG_LIMIT_RAD = math.radians(60.0)
"""A run's record ends before the first sample whose yaw (true or logged) exceeds this: near the
stop a tail wind gust can turn the relative air beyond any vane calibration (and beyond the
contract's +-90 deg)."""


def apply_effects(vehicle: TrueVehicle, effects: frozenset[str]) -> TrueVehicle:
    """The vehicle with the properties of withheld effects switched off."""
    off = {}
    if "lift" not in effects:
        off.update(cl0=0.0, kl_per_rad2=0.0)
    if "ride_height" not in effects:
        off.update(ride_height_cd_per_m=0.0)
    if "pitch" not in effects:
        off.update(k_alpha_per_rad=0.0)
    if "side_force_slip" not in effects:
        off.update(ks_per_rad=0.0)
    if "cd_yaw_shape" not in effects:
        off.update(k4_per_rad4=0.0)
    if "tyre_speed_law" not in effects:
        off.update(rr_c2_s2_per_m2=0.0)
    if "tyre_temperature_law" not in effects:
        off.update(tyre_temp_coeff_per_k=ref.ANALYSIS_TYRE_TEMPERATURE_COEFF_PER_K, tyre_temperature_law="linear")
    if "tyre_warmup" not in effects:
        off.update(tyre_rise_k_per_mps=0.0)
    if "driveline" not in effects:
        off.update(driveline_a_n=0.0, driveline_b_nspm=0.0, driveline_c_ns2pm2=0.0)
    return dataclasses.replace(vehicle, **off)


def true_roadload(vehicle: TrueVehicle, gravity_mps2: float) -> dict:
    """The true parameters in the analysis' terms and the road load at reference conditions
    (still air, level, dry air at 100 kPa and 293.2 K, tyres at their speed equilibrium).

    ``AD, BD``: the least-squares line through the rolling-resistance coefficient times
    ``g / g_a`` (exact for a linear law); ``CD0, KD``: the quadratic part of C_D(psi);
    ``F50_N`` etc.: this simulator's road load, lift unloading and ride height included.
    """
    veh, g = vehicle, gravity_mps2
    rho = ref.REFERENCE_DENSITY_KGPM3

    def coefficient(v):
        return veh.rr_c0 + veh.rr_c1_s_per_m * v + veh.rr_c2_s2_per_m2 * v**2

    def parts(v):
        q_area = 0.5 * rho * v**2 * veh.frontal_area_m2
        lift = q_area * veh.cl0
        tyre = (veh.mass_kg * g - lift) * coefficient(v)
        aero = q_area * (veh.cd0 + veh.ride_height_cd_per_m * lift / veh.heave_stiffness_n_per_m)
        driveline = veh.driveline_a_n + veh.driveline_b_nspm * v + veh.driveline_c_ns2pm2 * v**2
        return tyre, aero, driveline

    ad, bd = ref.linear_tyre_coefficients(lambda v: coefficient(v) * g / ref.ANALYSIS_GRAVITY_MPS2)
    out = {"AD": ad, "BD": bd, "CD0": veh.cd0, "KD": veh.kd_per_rad2}
    if veh.has_driveline:
        out.update(At=veh.driveline_a_n, Bt=veh.driveline_b_nspm, Ct=veh.driveline_c_ns2pm2)
    out.update(ref.quadratic_roadload(lambda v: sum(parts(v))))
    v50 = np.array([ref.SPEED_50MPH_MPS])
    tyre, aero, driveline = (float(p[0]) if np.ndim(p) else float(p) for p in parts(v50))
    out.update(F50_tyre_N=tyre, F50_aero_N=aero, F50_driveline_N=driveline)
    return out


def _drawn(effect: str, drawn: frozenset, chosen: frozenset, draw, off):
    """``draw()`` when ``effect`` is chosen; ``off`` when it is not.  A withheld effect
    (in ``drawn`` but not ``chosen``) still calls ``draw()`` and discards it, so that the
    random stream -- and with it every later draw of the campaign (instruments, Type B errors,
    noise) -- is the one of the campaign with the effect on: the two arms of an ablation then
    differ by the effect alone."""
    if effect not in drawn:
        return off
    value = draw()
    return value if effect in chosen else off


def _random_wind(rng, wind, effects, start_m, end_m, mean_wind_mps=None, drawn=None) -> WindField:
    """The campaign's wind: mean inside SAE J1263's limits, with the shelter and turbulence
    of ``effects``; ``drawn`` (default ``effects``) the effects whose draws are made (a
    withheld one's are made and discarded, :func:`_drawn`)."""
    effects = frozenset(effects)
    drawn = effects if drawn is None else frozenset(drawn)
    if isinstance(wind, WindField):
        return wind
    if wind == "calm":
        return WindField()
    if wind != "random":
        raise ValueError(f"wind must be 'random', 'calm' or a WindField, not {wind!r}")
    if mean_wind_mps is not None:
        along, cross = (float(x) for x in mean_wind_mps)
    else:
        while True:  # SAE J1263 wind limits
            along, cross = rng.uniform(-MAX_MEAN_WIND_MPS, MAX_MEAN_WIND_MPS), rng.uniform(-MAX_CROSS_WIND_MPS, MAX_CROSS_WIND_MPS)
            if math.hypot(along, cross) <= MAX_MEAN_WIND_MPS:
                break
    speed, direction = math.hypot(along, cross), math.atan2(cross, along)
    shelter = _drawn("wind_spatial", drawn, effects,
                     lambda: random_shelter(rng, start_m, end_m, max_depth=0.4, max_trend=0.2), Shelter())
    turbulence = _drawn("turbulence", drawn, effects,
                        lambda: von_karman_turbulence(rng, max(rng.uniform(0.15, 0.4) * speed, 0.2),
                                                      rng.uniform(10.0, 60.0)),
                        von_karman_turbulence(rng, 0.0, 30.0))
    return WindField(speed, direction, shelter, turbulence)


def _json_safe(x):
    if isinstance(x, dict):
        return {str(k): _json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_json_safe(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    return x


def _vehicle_and_rate(rng: np.random.Generator, vehicle: TrueVehicle | None = None, category: str | None = None,
                      sample_rate_hz: float | None = None) -> tuple[TrueVehicle, float]:
    """The campaign's vehicle and logging rate, each drawn from ``rng`` (in this order) unless given."""
    base = random_vehicle(rng, category) if vehicle is None else vehicle
    return base, float(rng.choice(SAMPLE_RATES_HZ)) if sample_rate_hz is None else float(sample_rate_hz)


def first_draws(seed: int) -> tuple[TrueVehicle, float]:
    """The vehicle and the logging rate :func:`simulate_independent` draws first for ``seed``
    when the campaign size is given and the vehicle, its category and the rate are not (as the
    studies call it: ``analysis.calibration.calibration_jobs``), without simulating: for
    reading a study's records against the simulator's own draws."""
    return _vehicle_and_rate(np.random.default_rng(seed))


def simulate_independent(seed: int, *, pairs: int | None = None, vehicle: TrueVehicle | None = None,
                         category: str | None = None, wind: str | WindField = "random",
                         effects: Iterable[str] | None = None, withhold: Iterable[str] = (),
                         type_b: bool = True, run_to_run_sd: float = 0.01,
                         sample_rate_hz: float | None = None, channels: Iterable[str] = DEFAULT_CHANNELS,
                         perfect_instruments: bool = False, speed_noise_sd_mps: float | None = None,
                         mean_wind_mps: tuple[float, float] | None = None,
                         errors: Mapping[str, float] | None = None,
                         realisation: int | None = None, rtol: float = 1e-9) -> Campaign:
    """Simulate a campaign of opposite-direction coastdown pairs.

    Parameters
    ----------
    seed : seeds every draw.
    pairs : number of pairs (default: drawn from 1-12).
    vehicle : the true vehicle (default: drawn, of ``category`` if given).
    wind : ``"random"`` (mean wind inside SAE J1263's limits, 16 km/h mean, 8 km/h cross),
        ``"calm"`` or a :class:`~.wind.WindField`.
    effects : the effects of :data:`~.effects.EFFECTS` to inject (default: all); ``withhold``
        removes some from them.
    type_b : draw the declared values and instrument errors inside the standards' accuracies
        (:data:`~.effects.TYPE_B`); else declared = true.
    run_to_run_sd : relative standard deviation of the run-to-run variation of the
        rolling-resistance constant and C_D0 (the thesis' system noise).
    sample_rate_hz : logging rate (default: drawn from 1-20 Hz).
    channels : optional channels to log (:data:`CHANNELS`; default :data:`DEFAULT_CHANNELS`).
    perfect_instruments : the logger records exactly what the body feels (no instrument
        effect, no Type B error, no quantisation), apart from white speed noise.
    speed_noise_sd_mps : the speed noise (default: drawn with the instrument).
    mean_wind_mps : (along-track, cross) mean wind in m/s with ``wind="random"``, instead of
        a draw inside SAE J1263's limits (the shelter and turbulence are still drawn).
    errors : Type B errors set to these values instead of drawn (or zero without ``type_b``),
        named as in ``truth.json`` ``meta.type_b_errors``: one of :data:`SETTABLE_ERRORS`.
    realisation : ``None`` (default): every draw comes from one stream seeded by ``seed``, in
        the order the campaign is built, so a change of one run's length (an effect withheld)
        shifts the draws of every later run.  An integer: the campaign-level draws (vehicle,
        size, rate, site, weather, track, mean wind, shelter, the turbulence's intensity and
        length scale, instruments, Type B errors, declared values, first direction) are those
        of ``seed`` as before, while each run's own draws (start and stop speeds, run-to-run
        spread, wind and weather drift, tyre warm-up, sensor noise, turn-round) come from its
        own stream ``[seed, RUN_STREAM, realisation, run]`` and the turbulence's phases and
        directions (with ``wind="random"``) from ``[seed, TURBULENCE_STREAM, realisation]``:
        another day's runs of the same vehicle, site and instruments, and an ablation that
        leaves every run's draws alone (a run still starts when the previous one ended plus
        its turn-round, so the gusts it meets follow the earlier runs' lengths).
    rtol : relative tolerance of the integrator on the motion.

    Returns
    -------
    Campaign with ``truth`` (true parameters in the analysis' terms, ``per_run``, ``meta``).
    """
    rng = np.random.default_rng(seed)
    errors = dict(errors or {})
    if set(errors) - set(SETTABLE_ERRORS):
        raise ValueError(f"errors: unknown {sorted(set(errors) - set(SETTABLE_ERRORS))}; settable: {SETTABLE_ERRORS}")
    if perfect_instruments and errors:
        raise ValueError("errors: perfect instruments have no Type B errors")
    requested = frozenset(EFFECTS) if effects is None else frozenset(effects)
    chosen = requested - frozenset(withhold)
    unknown = (chosen | frozenset(withhold)) - frozenset(EFFECTS)
    if unknown:
        raise ValueError(f"unknown effect(s) {sorted(unknown)}; known: {sorted(EFFECTS)}")
    drawn = requested  # a withheld effect's draws are made and discarded (_drawn)
    if perfect_instruments:
        chosen = frozenset(e for e in chosen if not EFFECTS[e].instrument)
        drawn = frozenset(e for e in drawn if not EFFECTS[e].instrument)
        type_b = False
    channels = tuple(channels)
    bad = set(channels) - set(CHANNELS)
    if bad:
        raise ValueError(f"unknown channel(s) {sorted(bad)}; known: {CHANNELS}")
    if "survey" in channels and "position" not in channels:
        raise ValueError("channel 'survey' needs 'position': the runs are placed on the survey by position_m")
    n_pairs = int(rng.integers(1, 13)) if pairs is None else int(pairs)
    if n_pairs < 1:
        raise ValueError("pairs must be at least 1")
    base, rate = _vehicle_and_rate(rng, vehicle, category, sample_rate_hz)
    veh = apply_effects(base, chosen)

    # site and weather: SAE J1263 test window 5-35 C; station pressure of low-lying tracks
    gravity = float(rng.uniform(9.780, 9.832))            # equator to pole
    temperature0 = float(rng.uniform(278.15, 308.15))
    pressure0 = float(rng.uniform(95e3, 103e3))
    humidity = _drawn("humidity", drawn, chosen, lambda: float(rng.uniform(0.3, 0.95)), 0.0)
    drift_t, drift_p = _drawn("weather_drift", drawn, chosen,
                              lambda: (float(rng.uniform(-3, 3)), float(rng.uniform(-300, 300))), (0.0, 0.0))

    # the track: long enough for the longest coast of this vehicle in still air
    probe = simulate_run(veh, RunConditions(1, 0.0, 33.5, 4.2, gravity_mps2=gravity), np.arange(0.0, 3000.0, 1.0),
                         rtol=1e-6)
    length = float(probe.distance_m[-1]) * 1.15 + 100.0
    mean_grade = float(rng.uniform(-sens.GRADE_ACCURACY, sens.GRADE_ACCURACY)) if type_b else 0.0
    mean_grade = float(errors.get("track_mean_grade", mean_grade))
    undulation = _drawn("grade_profile", drawn, drawn, lambda: float(rng.uniform(0.0002, 0.001)), 0.0)
    track = surveyed_track(rng, -400.0, length + 400.0, mean_grade=mean_grade, rms_undulation_grade=undulation)
    if "grade_profile" not in chosen:  # withheld: its undulations drawn above, then discarded
        undulation, track = 0.0, Track(track.start_m, track.end_m, mean_grade)
    field = _random_wind(rng, wind, chosen, -400.0, length + 400.0, mean_wind_mps, drawn=drawn)
    if realisation is not None and not isinstance(wind, WindField) and field.turbulence.amp.size:
        gusts = field.turbulence
        field = dataclasses.replace(field, turbulence=von_karman_turbulence(
            np.random.default_rng([int(seed), TURBULENCE_STREAM, int(realisation)]),
            gusts.sigma_mps, gusts.length_scale_m))

    inst = (sens.perfect_instruments(speed_noise_sd_mps if speed_noise_sd_mps is not None else 0.02)
            if perfect_instruments else
            sens.random_instruments(rng, type_b=type_b, yaw_dependent_factor="anemometer_yaw_factor" in drawn,
                                    speed_noise_sd_mps=speed_noise_sd_mps))
    if "anemometer_yaw_factor" not in chosen:  # withheld: drawn above, then discarded (_drawn)
        inst = dataclasses.replace(inst, airspeed_factor_yaw=0.0)
    dyn = _drawn("anemometer_dynamics", drawn, chosen,
                 lambda: AnemometerDynamics(distance_constant_m=float(rng.uniform(1.5, 3.0)),
                                            overspeed_ratio=float(rng.uniform(1.2, 2.0)),
                                            vane_damping=float(rng.uniform(0.3, 0.6)),
                                            vane_wavelength_m=float(rng.uniform(4.5, 7.0))), None)
    ahead = _drawn("anemometer_position", drawn, chosen, lambda: float(rng.uniform(1.5, 2.5)), None)
    hygrometer_rng = np.random.default_rng([int(seed), HYGROMETER_STREAM])
    hygrometer = sens.random_hygrometer(hygrometer_rng, type_b=type_b and not perfect_instruments)
    if "yaw_offset_rad" in errors:
        inst = dataclasses.replace(inst, yaw_offset_rad=float(errors["yaw_offset_rad"]))

    # declared values (Type B)
    u = rng.uniform if type_b else (lambda lo, hi: 0.0)
    axles = AXLES_OF.get(base.category, 2)
    declared_mass = base.mass_kg + float(u(-sens.MASS_ACCURACY_PER_AXLE_KG * axles, sens.MASS_ACCURACY_PER_AXLE_KG * axles))
    declared_inertia = base.rotating_inertia_kgm2 * (1.0 + float(u(-sens.ROTATING_INERTIA_ACCURACY, sens.ROTATING_INERTIA_ACCURACY)))
    declared_radius = base.rolling_radius_m * (1.0 + float(u(-sens.ROLLING_RADIUS_ACCURACY, sens.ROLLING_RADIUS_ACCURACY)))
    wind_lim = sens.RELATIVE_WIND_ACCURACY_MPS / sens.RELATIVE_WIND_ACCURACY_AT_MPS
    declared_air = inst.airspeed_factor * (1.0 + float(u(-wind_lim, wind_lim)))
    declared_yaw = inst.yaw_factor * (1.0 + float(u(-sens.YAW_FACTOR_ERROR_LIMIT, sens.YAW_FACTOR_ERROR_LIMIT)))
    if "mass_kg" in errors:
        declared_mass = base.mass_kg + float(errors["mass_kg"])
    if "rotating_inertia_rel" in errors:
        declared_inertia = base.rotating_inertia_kgm2 * (1.0 + float(errors["rotating_inertia_rel"]))
    if "airspeed_factor_rel" in errors:
        declared_air = inst.airspeed_factor * (1.0 + float(errors["airspeed_factor_rel"]))
    if "yaw_factor_rel" in errors:
        declared_yaw = inst.yaw_factor * (1.0 + float(errors["yaw_factor_rel"]))
    declared = Vehicle(mass_kg=declared_mass, effective_mass_kg=declared_mass + declared_inertia / declared_radius**2,
                       frontal_area_m2=base.frontal_area_m2, rolling_radius_m=declared_radius, length_m=base.length_m)

    has_driveline = veh.has_driveline
    frames, per_run, run_meta = [], {}, []
    clock = 0.0
    first = int(rng.choice([1, -1]))
    samples = np.arange(0.0, 3000.0, 1.0 / rate)
    truth = true_roadload(veh, gravity)
    for k in range(2 * n_pairs):
        run_rng = rng if realisation is None else np.random.default_rng([int(seed), RUN_STREAM, int(realisation), k])
        direction = first if k % 2 == 0 else -first
        frac = k / max(2 * n_pairs - 1, 1)
        speed, heading = field.mean_speed_mps, field.direction_rad
        if speed > 0:
            speed, heading = _drawn("wind_drift", drawn, chosen,
                                    lambda: (max(speed * (1.0 + 0.1 * run_rng.normal()), 0.0),
                                             heading + np.deg2rad(8.0) * run_rng.normal()), (speed, heading))
        run_wind = field.with_mean(speed, heading)
        t_amb = temperature0 + drift_t * frac + _drawn("weather_drift", drawn, chosen, lambda: 0.2 * run_rng.normal(), 0.0)
        p_amb = pressure0 + drift_p * frac + _drawn("weather_drift", drawn, chosen, lambda: 20.0 * run_rng.normal(), 0.0)
        tyre_factor, cd_factor = 1.0 + run_to_run_sd * run_rng.normal(size=2)
        cond = RunConditions(
            direction=direction, start_position_m=0.0 if direction > 0 else length,
            v0_mps=float(run_rng.uniform(31.3, 33.5)), v_stop_mps=float(run_rng.uniform(4.2, 5.5)),
            temperature_k=t_amb, pressure_pa=p_amb, relative_humidity=humidity, gravity_mps2=gravity,
            clock_start_s=clock, tyre_factor=float(tyre_factor), cd_factor=float(cd_factor),
            tyre_initial_excess_k=_drawn("tyre_warmup", drawn, chosen, lambda: float(run_rng.uniform(-4.0, 2.0)), 0.0))
        trace = simulate_run(veh, cond, samples, wind=run_wind if speed > 0 or field.turbulence.amp.size else None,
                             track=track, admittance="admittance" in chosen, anemometer=dyn,
                             anemometer_ahead_m=ahead, rtol=rtol)
        n = trace.time_s.size
        rid = k + 1
        row = {"run": np.full(n, rid), "time_s": trace.time_s,
               "speed_mps": sens.read_speed(inst, trace.speed_mps, run_rng),
               "direction": np.full(n, direction), "pair": np.full(n, k // 2 + 1)}
        if "anemometer" in channels:
            if perfect_instruments:
                row["airspeed_mps"], row["yaw_rad"] = trace.airspeed_mps.copy(), trace.yaw_rad.copy()
            else:
                row["airspeed_mps"], row["yaw_rad"] = sens.read_anemometer(inst, trace.cup_mps, trace.vane_rad, run_rng)
        if "weather" in channels:
            row["temperature_k"], row["pressure_pa"] = sens.read_weather(inst, t_amb, p_amb, n, run_rng)
        if "humidity" in channels and humidity > 0.0:
            row["relative_humidity_pct"] = sens.read_humidity(hygrometer, humidity, n, hygrometer_rng)
        if "position" in channels:
            row["position_m"], row["distance_m"] = trace.position_m, trace.distance_m
        if "driveline" in channels and has_driveline:
            row["driveline_force_n"] = sens.read_driveline(inst, trace.driveline_force_n, run_rng)
        frame = pd.DataFrame(row)
        beyond = np.abs(trace.yaw_rad) > YAW_LOG_LIMIT_RAD
        if "yaw_rad" in frame:
            beyond |= np.abs(frame["yaw_rad"].to_numpy()) > YAW_LOG_LIMIT_RAD
        kept = int(np.argmax(beyond)) if beyond.any() else n
        if kept < 10:
            raise RuntimeError(f"run {rid}: the relative air leaves +-60 deg yaw within 10 samples")
        frames.append(frame.iloc[:kept])
        per_run[str(rid)] = {
            "AD": truth["AD"] + (cond.tyre_factor - 1.0) * veh.rr_c0 * gravity / ref.ANALYSIS_GRAVITY_MPS2,
            "BD": truth["BD"], "CD0": veh.cd0 * cond.cd_factor, "KD": veh.kd_per_rad2}
        run_meta.append({**dataclasses.asdict(cond), "wind_speed_mps": speed, "wind_direction_rad": heading,
                         "samples": kept, "duration_s": float(trace.time_s[kept - 1]),
                         "truncated": kept < n,
                         "air_density_kgpm3": trace.air_density_kgpm3,
                         "mean_abs_yaw_rad": float(np.mean(np.abs(trace.yaw_rad)))})
        clock += float(trace.time_s[-1]) + float(run_rng.uniform(120.0, 400.0))   # turn-round

    runs = pd.concat(frames, ignore_index=True)
    survey = track.survey(10.0)
    surveyed = level_survey(track, np.random.default_rng([int(seed), SURVEY_STREAM])) if "survey" in channels else None
    tunnel = {"KD": veh.kd_per_rad2}
    if "lift" in chosen:
        tunnel.update(CL0=veh.cl0, KL=veh.kl_per_rad2)
    meta = {
        "effects": sorted(chosen), "type_b": type_b, "perfect_instruments": perfect_instruments,
        "run_to_run_sd": run_to_run_sd, "sample_rate_hz": rate, "channels": list(channels),
        "gravity_mps2": gravity, "relative_humidity": humidity,
        "temperature0_k": temperature0, "pressure0_pa": pressure0,
        "temperature_drift_k": drift_t, "pressure_drift_pa": drift_p,
        "vehicle_true": base.as_dict(), "vehicle_simulated": veh.as_dict(),
        "effective_mass_true_kg": veh.effective_mass_kg,
        "declared": {"mass_kg": declared.mass_kg, "effective_mass_kg": declared.effective_mass_kg,
                     "rotating_inertia_kgm2": declared_inertia, "rolling_radius_m": declared_radius,
                     "airspeed_factor": declared_air, "yaw_factor": declared_yaw},
        "type_b_errors": {
            "mass_kg": declared.mass_kg - base.mass_kg,
            "rotating_inertia_rel": declared_inertia / base.rotating_inertia_kgm2 - 1.0,
            "rolling_radius_rel": declared_radius / base.rolling_radius_m - 1.0,
            "effective_mass_kg": declared.effective_mass_kg - veh.effective_mass_kg,
            "airspeed_factor_rel": declared_air / inst.airspeed_factor - 1.0,
            "yaw_factor_rel": declared_yaw / inst.yaw_factor - 1.0,
            "yaw_offset_rad": inst.yaw_offset_rad, "speed_scale_rel": inst.speed_scale - 1.0,
            "temperature_bias_k": inst.temperature_bias_k, "pressure_bias_pa": inst.pressure_bias_pa,
            "driveline_scale_rel": inst.driveline_scale - 1.0, "track_mean_grade": mean_grade},
        "instruments": inst.as_dict(), "hygrometer": dataclasses.asdict(hygrometer),
        "anemometer_dynamics": dataclasses.asdict(dyn) if dyn else None, "anemometer_ahead_m": ahead,
        "wind": {"mean_speed_mps": field.mean_speed_mps, "direction_rad": field.direction_rad,
                 "shelter": dataclasses.asdict(field.shelter),
                 "turbulence_sigma_mps": field.turbulence.sigma_mps,
                 "turbulence_length_scale_m": field.turbulence.length_scale_m},
        "track": {"length_m": length, "mean_grade": mean_grade, "rms_undulation_grade": undulation,
                  "survey_stations_m": survey[0], "survey_elevation_m": survey[1],
                  **({} if surveyed is None else {"surveyed": surveyed.attrs})},
        "runs": run_meta,
    }
    truth.update(case="independent", model="independent simulator", per_run=per_run, meta=_json_safe(meta))
    vmeta = {"simulator": "independent", "seed": int(seed), "pairs": n_pairs, "category": base.category,
             "sample_rate_hz": rate}
    if realisation is not None:
        vmeta["realisation"] = int(realisation)
    # the cup's distance constant as its data sheet states it (the speed-up one: the slower
    # slow-down of an over-speeding cup is not on the sheet)
    stated_d = float(dyn.distance_constant_m) if dyn is not None else 0.0
    return Campaign(runs, declared, Anemometer(airspeed_factor=declared_air, yaw_factor=declared_yaw,
                                               distance_constant_m=stated_d),
                    tunnel=tunnel, truth=_json_safe(truth), meta=vmeta, track=surveyed)


def level_survey(track: Track, rng: np.random.Generator) -> pd.DataFrame:
    """The track as a level survey states it (``track.csv``): stations every
    :data:`SURVEY_SPACING_M` over the track, each elevation with an independent error of
    standard deviation drawn from :data:`SURVEY_NOISE_M` and rounded to 1 mm.  The survey levels
    the stations against each other, not the track against the horizontal: its elevations hold
    the undulations but not the mean grade, which stays the Type B error ``track_mean_grade``
    (40 CFR 1066.310's 0.02 %).  ``attrs`` records the spacing and the error's sd."""
    noise_sd = float(rng.uniform(*SURVEY_NOISE_M))
    x = np.arange(track.start_m, track.end_m + SURVEY_SPACING_M, SURVEY_SPACING_M)
    z = track.elevation(x) - track.mean_grade * (x - track.start_m) + rng.normal(0.0, noise_sd, x.size)
    df = pd.DataFrame({"position_m": x, "elevation_m": np.round(z, 3)})
    df.attrs = {"spacing_m": SURVEY_SPACING_M, "noise_sd_m": noise_sd}
    return df
