"""The nuisance effects the independent simulator can inject, one name each, with the range
their sizes are drawn from and the source of that range.  A campaign injects a set of them
(default: all); the sim-to-real study withholds or injects one at a time."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Effect:
    """One injectable effect: what it does, the range of its size, where the range comes from."""

    description: str
    size: str
    source: str
    instrument: bool = False


EFFECTS: dict[str, Effect] = {
    "wind_spatial": Effect(
        "mean wind varies along the track: 1-3 sheltered stretches (tree lines, buildings) with "
        "smooth edges and a linear trend",
        "shelter depth 0-40 % of the mean wind, trend +-20 % over the track",
        "thesis ch. 6 (spatial variation beta) and ch. 8 (small-scale wind variations)"),
    "turbulence": Effect(
        "isotropic 2-D turbulence, random Fourier modes with a von Karman spectrum, frozen and "
        "carried by the mean wind",
        "intensity 0.15-0.4 of the mean wind (at least 0.2 m/s), length scale 10-60 m",
        "thesis table 6.4 (0.4, 30 m); surface-layer turbulence intensity of open terrain"),
    "wind_drift": Effect(
        "the mean wind changes from run to run",
        "speed x (1 + N(0, 0.1)), direction + N(0, 8 deg) per run",
        "SAE J1263 averages wind over each run because it changes between runs"),
    "admittance": Effect(
        "the body feels the wind through a first-order filter of time constant length / airspeed",
        "time constant = vehicle length / airspeed",
        "thesis ch. 6 (aerodynamic admittance)"),
    "humidity": Effect(
        "moist air density (the analysis takes dry air at the logged temperature and pressure)",
        "relative humidity 30-95 % (-0.2 to -1.5 % density)",
        "thermodynamics of moist air (Magnus formula)"),
    "weather_drift": Effect(
        "ambient temperature and pressure drift over the campaign",
        "+-3 K and +-300 Pa linear drift, 0.2 K / 20 Pa run-to-run",
        "SAE J1263 test window 5-35 C; a test session of 1-3 h"),
    "grade_profile": Effect(
        "undulating track elevation (six sinusoids; a level survey of it is the channel `survey`)",
        "RMS grade of the undulations 0.02-0.1 %, wavelengths 50-400 m",
        "SAE J1263 (constant grade below 0.5 %), 40 CFR 1066.310 (grade above 0.02 % analysed)"),
    "tyre_speed_law": Effect(
        "rolling resistance coefficient c0 + c1 v + c2 v^2 (the analysis: linear in v)",
        "c2 v^2 adds 5-20 % of c0 at 115 km/h",
        "SAE J2452 speed law A + B v + C v^2"),
    "tyre_temperature_law": Effect(
        "tyre loss factor exp(-k (T - 20 C)) with its own k (the analysis: 1 - 0.0086 (T - 20 C))",
        "k 0.006-0.012 /K",
        "GTR 15 Annex 4 K0 = 0.0086 /K; literature 0.6-1.2 %/K"),
    "tyre_warmup": Effect(
        "tyre temperature lags its speed equilibrium (first-order thermal model)",
        "time constant 200-900 s, equilibrium rise 0.4-0.8 K per m/s, initial excess -4..+2 K",
        "SAE J2452 / GTR 15 tyre warm-up of 20-30 min; thesis ch. 8 (tyre temperature change)"),
    "lift": Effect(
        "aerodynamic lift C_L0 + K_L psi^2 unloads the tyres (declared in vehicle.toml [tunnel])",
        "C_L0 0-0.35, K_L 0-4 rad^-2 by vehicle category",
        "thesis table (C_L0 0.273, K_L 1.78-3.64)"),
    "ride_height": Effect(
        "lift raises the body; C_D changes with ride height",
        "dC_D/dh 0.1-0.3 per m, heave stiffness 48-100 N/m per kg",
        "literature: about 0.001-0.003 C_D per 10 mm of ride height"),
    "pitch": Effect(
        "pitch from weight transfer under deceleration changes C_D (K_alpha alpha)",
        "K_alpha 0.2-1.3 rad^-1, pitch stiffness by category",
        "thesis eq. 2.33 (K_alpha 0.9, k_p 60e3 N m/rad)"),
    "side_force_slip": Effect(
        "aerodynamic side force carried by the tyres at a slip angle: induced drag F^2 / C per axle",
        "K_S 1.8-7 rad^-1, cornering stiffness 20-250 kN/rad per tyre",
        "thesis eq. 2.41-2.46 (K_S 2.4, C_y 25000 N/rad)"),
    "cd_yaw_shape": Effect(
        "C_D(psi) flattens at large yaw: + K4 psi^4",
        "K4 = -(0.5-3) K_D rad^-2",
        "thesis tunnel fits K_D 0.614 (+-15 deg) vs 0.458 (+-25 deg)"),
    "driveline": Effect(
        "driveline off-load loss A_t + B_t v + C_t v^2",
        "A_t 10-300 N, B_t 0.8-15 N s/m by category",
        "thesis table 8.12 (21.0 N, 2.09 N s/m, -0.02 N s^2/m^2)"),
    "anemometer_dynamics": Effect(
        "cup first order with over-speeding (faster up than down), vane second order",
        "distance constant 1.5-3 m, slow-down/speed-up ratio 1.2-2, vane damping 0.3-0.6, "
        "undamped wavelength 4.5-7 m",
        "thesis section 4.7 (1.5 m, damping 0.4, damped wavelength ~5 m); cup over-speeding in "
        "turbulence (Kristensen 1998)", instrument=True),
    "anemometer_position": Effect(
        "the anemometer samples the air ~2 m ahead of the nose, not at the body",
        "1.5-2.5 m ahead",
        "SAE J2263 (anemometer about 2 m ahead of the vehicle)", instrument=True),
    "anemometer_yaw_factor": Effect(
        "the airspeed calibration factor depends on yaw (the declared factor does not)",
        "factor x (1 + e psi^2), e 0-0.6 (1.069-1.107 over yaw)",
        "thesis section 5 (yaw-dependent factors 1.069-1.107)", instrument=True),
}
"""Every injectable effect by name."""

TYPE_B: dict[str, str] = {
    "speed_scale_rel": "SAE J2263 vehicle speed +-0.2 km/h, as a scale error at 115 km/h (+-0.17 %)",
    "airspeed_factor_rel": "SAE J2263 relative wind +-1 km/h, as a factor error at 108 km/h (+-0.93 %)",
    "yaw_offset_rad": "SAE J2263 yaw +-3 deg: offset +-1 deg ...",
    "yaw_factor_rel": "... and factor error +-10 % (2.5 deg at 15 deg yaw)",
    "mass_kg": "SAE J1263 vehicle mass +-5 kg per axle",
    "rotating_inertia_rel": "+-10 % of the rotating inertia (J2263's 1.03 M default spans +-1-1.5 % of M on M_e)",
    "rolling_radius_rel": "+-1 % (dynamic rolling radius with pressure, load, speed, wear)",
    "temperature_bias_k": "SAE J1263 temperature +-1 C",
    "pressure_bias_pa": "SAE J1263 atmospheric pressure +-0.7 kPa",
    "track_mean_grade": "40 CFR 1066.310: grade up to 0.02 % may be left out of the analysis",
    "driveline_scale_rel": "wheel-torque transducer class 0.5-1 %: +-1 %",
}
"""The Type B (declared-value and instrument) errors, named as in ``truth.json``
``meta.type_b_errors``, and the accuracy each is drawn inside (uniformly)."""
