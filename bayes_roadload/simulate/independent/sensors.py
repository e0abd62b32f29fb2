"""The instruments: what the data logger records of the simulated truth.

Every instrument has a fixed (Type B) error drawn once per campaign and a random error per
sample.  Conventions of the campaign contract: the anemometer's calibration factors are
``true = factor x reading`` (thesis section 4.7.3), so a reading is ``true / factor``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

KPH = 1.0 / 3.6

# Type B limits from the standards (STANDARDS_FACTS.md; each a half-width).
SPEED_ACCURACY_MPS = 0.2 * KPH             # SAE J2263: vehicle speed +-0.2 km/h
SPEED_ACCURACY_AT_MPS = 115.0 * KPH        # ... taken as a scale error at the top of the range
RELATIVE_WIND_ACCURACY_MPS = 1.0 * KPH     # SAE J2263: relative wind speed +-1 km/h
RELATIVE_WIND_ACCURACY_AT_MPS = 30.0       # ... as a factor error at ~108 km/h relative air
YAW_ACCURACY_RAD = np.deg2rad(3.0)         # SAE J2263: yaw angle +-3 deg
YAW_OFFSET_LIMIT_RAD = np.deg2rad(1.0)     # offset + factor error at 15 deg stay inside +-3 deg
YAW_FACTOR_ERROR_LIMIT = 0.10              # 1 deg + 10 % of 15 deg = 2.5 deg < 3 deg
TEMPERATURE_ACCURACY_K = 1.0               # SAE J1263: temperature +-1 C
PRESSURE_ACCURACY_PA = 700.0               # SAE J1263: atmospheric pressure +-0.7 kPa
MASS_ACCURACY_PER_AXLE_KG = 5.0            # SAE J1263: vehicle mass +-5 kg per axle
ROLLING_RADIUS_ACCURACY = 0.01             # dynamic rolling radius +-1 % (pressure, load, speed, wear)
ROTATING_INERTIA_ACCURACY = 0.10           # measured wheel/driveline inertia +-10 %; J2263's 1.03 M
                                           # default implies a +-1-1.5 % of M spread on M_e
GRADE_ACCURACY = 0.0002                    # 40 CFR 1066.310: grade above 0.02 % must enter the analysis
DRIVELINE_SCALE_ACCURACY = 0.01            # wheel-torque transducer, class 0.5-1 %
HUMIDITY_ACCURACY_PCT = 2.0                # hand-held weather meter (Kestrel 5500): +-2 % relative humidity


@dataclass(frozen=True)
class Instruments:
    """The instruments of one campaign: fixed errors and random-noise levels (SI).

    speed_scale : logged speed = scale x true speed (+ noise, quantised to
        ``speed_resolution_mps``).
    airspeed_factor, airspeed_factor_yaw : true airspeed = airspeed_factor
        (1 + airspeed_factor_yaw psi^2) x reading (the thesis found 1.069-1.107 over yaw).
    yaw_factor, yaw_offset_rad : true yaw = yaw_factor x (reading - yaw_offset_rad).
    temperature_bias_k, pressure_bias_pa : logged = true + bias (+ noise).
    driveline_scale : logged driveline force = scale x true (+ noise).
    """

    speed_source: str = "gnss"
    speed_scale: float = 1.0
    speed_noise_sd_mps: float = 0.02
    speed_resolution_mps: float = 0.0
    airspeed_factor: float = 1.0
    airspeed_factor_yaw: float = 0.0
    airspeed_noise_sd_mps: float = 0.0
    yaw_factor: float = 1.0
    yaw_offset_rad: float = 0.0
    yaw_noise_sd_rad: float = 0.0
    temperature_bias_k: float = 0.0
    temperature_noise_sd_k: float = 0.0
    pressure_bias_pa: float = 0.0
    pressure_noise_sd_pa: float = 0.0
    driveline_scale: float = 1.0
    driveline_noise_sd_n: float = 0.0

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


def perfect_instruments(speed_noise_sd_mps: float) -> Instruments:
    """Exact instruments apart from white speed noise (without which there is no error to
    estimate a standard error from)."""
    return Instruments(speed_noise_sd_mps=speed_noise_sd_mps)


def random_instruments(rng: np.random.Generator, *, type_b: bool, yaw_dependent_factor: bool,
                       speed_noise_sd_mps: float | None = None) -> Instruments:
    """Draw instruments: the true calibration of the anemometer (thesis: airspeed factor
    1.0806 in 1.069-1.107, yaw factor 0.869 in 0.849-0.900) and, with ``type_b``, a speed
    scale error inside SAE J2263's +-0.2 km/h, temperature and pressure biases inside SAE
    J1263's +-1 K / +-0.7 kPa, a vane offset and factor error inside J2263's +-3 deg, a
    driveline transducer scale error of +-1 %.  Noise levels: GNSS Doppler speed 0.01-0.05 m/s
    (VBOX 0.1 km/h RMS, u-blox 0.05 m/s), wheel-pulse speed 0.005-0.03 m/s; airspeed 0.02-0.1
    m/s, yaw 0.002-0.01 rad (thesis section 6 used 0.05 m/s and 0.01 rad)."""
    u = rng.uniform
    source = str(rng.choice(["gnss", "wheel"]))
    if speed_noise_sd_mps is None:
        speed_noise_sd_mps = float(u(0.01, 0.05) if source == "gnss" else u(0.005, 0.03))
    lim_speed = SPEED_ACCURACY_MPS / SPEED_ACCURACY_AT_MPS
    return Instruments(
        speed_source=source,
        speed_scale=1.0 + (u(-lim_speed, lim_speed) if type_b else 0.0),
        speed_noise_sd_mps=speed_noise_sd_mps,
        speed_resolution_mps=float(rng.choice([0.01 * KPH, 1e-3, 1e-5])),
        airspeed_factor=float(u(1.04, 1.10)),
        airspeed_factor_yaw=float(u(0.0, 0.6)) if yaw_dependent_factor else 0.0,
        airspeed_noise_sd_mps=float(u(0.02, 0.1)),
        yaw_factor=float(u(0.85, 1.0)),
        yaw_offset_rad=float(u(-YAW_OFFSET_LIMIT_RAD, YAW_OFFSET_LIMIT_RAD)) if type_b else 0.0,
        yaw_noise_sd_rad=float(u(0.002, 0.01)),
        temperature_bias_k=float(u(-TEMPERATURE_ACCURACY_K, TEMPERATURE_ACCURACY_K)) if type_b else 0.0,
        temperature_noise_sd_k=0.05,
        pressure_bias_pa=float(u(-PRESSURE_ACCURACY_PA, PRESSURE_ACCURACY_PA)) if type_b else 0.0,
        pressure_noise_sd_pa=10.0,
        driveline_scale=1.0 + (float(u(-DRIVELINE_SCALE_ACCURACY, DRIVELINE_SCALE_ACCURACY)) if type_b else 0.0),
        driveline_noise_sd_n=float(u(0.5, 3.0)),
    )


def _quantise(x, step):
    return np.round(x / step) * step if step > 0 else x


def read_speed(inst: Instruments, speed_mps, rng: np.random.Generator):
    """Logged speed over the ground (m/s)."""
    v = np.asarray(speed_mps, float)
    return _quantise(inst.speed_scale * v + rng.normal(0.0, inst.speed_noise_sd_mps, v.shape), inst.speed_resolution_mps)


def read_anemometer(inst: Instruments, airspeed_mps, yaw_rad, rng: np.random.Generator):
    """Logged (uncalibrated) airspeed and yaw from the true air at the instrument (or the cup
    and vane states): reading = true / factor, plus noise; the yaw reading adds the offset."""
    a = np.asarray(airspeed_mps, float)
    y = np.asarray(yaw_rad, float)
    factor = inst.airspeed_factor * (1.0 + inst.airspeed_factor_yaw * y**2)
    air = a / factor + rng.normal(0.0, inst.airspeed_noise_sd_mps, a.shape)
    yaw = y / inst.yaw_factor + inst.yaw_offset_rad + rng.normal(0.0, inst.yaw_noise_sd_rad, y.shape)
    return np.maximum(air, 0.0), np.clip(yaw, -1.5, 1.5)


def read_weather(inst: Instruments, temperature_k, pressure_pa, n: int, rng: np.random.Generator):
    """Logged ambient temperature (K) and pressure (Pa), ``n`` samples."""
    t = temperature_k + inst.temperature_bias_k + rng.normal(0.0, inst.temperature_noise_sd_k, n)
    p = pressure_pa + inst.pressure_bias_pa + rng.normal(0.0, inst.pressure_noise_sd_pa, n)
    return t, p


@dataclass(frozen=True)
class Hygrometer:
    """The weather station's relative-humidity sensor: a bias and white noise, in percent."""

    bias_pct: float = 0.0
    noise_sd_pct: float = 0.3


def random_hygrometer(rng: np.random.Generator, *, type_b: bool = True) -> Hygrometer:
    """A hygrometer whose bias is drawn inside :data:`HUMIDITY_ACCURACY_PCT` (none without
    ``type_b``)."""
    bias = float(rng.uniform(-HUMIDITY_ACCURACY_PCT, HUMIDITY_ACCURACY_PCT)) if type_b else 0.0
    return Hygrometer(bias_pct=bias)


def read_humidity(hygrometer: Hygrometer, relative_humidity: float, n: int, rng: np.random.Generator):
    """Logged relative humidity (percent, 0-100) of air at ``relative_humidity`` (a fraction),
    ``n`` samples."""
    h = 100.0 * relative_humidity + hygrometer.bias_pct + rng.normal(0.0, hygrometer.noise_sd_pct, n)
    return np.clip(np.round(h, 1), 0.0, 100.0)


def read_driveline(inst: Instruments, force_n, rng: np.random.Generator):
    """Logged driveline off-load loss (N)."""
    f = np.asarray(force_n, float)
    return inst.driveline_scale * f + rng.normal(0.0, inst.driveline_noise_sd_n, f.shape)
