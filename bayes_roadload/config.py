"""Every default of the package, in one place.

Physical constants and the reference conditions of the thesis (Passmore 1990, section 2 and
``ROADLOAD_MODEL.md``), the parameter names of the data contract with their units and O(1)
scales, and the default settings of the integrator and of the samplers.  Other modules import
from here rather than writing literals of their own.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

# Chains run in parallel on the CPU cores: XLA must be told before its backend starts.
if "xla_force_host_platform_device_count" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "")
                               + f" --xla_force_host_platform_device_count={max(os.cpu_count() or 1, 1)}").strip()

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

# --- physical constants -------------------------------------------------------------------
GRAVITY_MPS2 = 9.81
"""Acceleration due to gravity used by the thesis (m/s^2)."""
GAS_CONSTANT_AIR_J_PER_KG_K = 287.05
"""Specific gas constant of dry air (J/(kg K))."""

# --- reference conditions (thesis section 2.2.1.3) ----------------------------------------
REFERENCE_PRESSURE_PA = 100_000.0
REFERENCE_TEMPERATURE_K = 293.2
TYRE_TEMPERATURE_COEFF_PER_K = 0.0086
"""K_T of eq. 2.38-2.40: tyre loss falls by 0.86 % per kelvin above the reference."""

# --- the data contract: parameter names, units and scales ----------------------------------
PARAMETER_UNITS: dict[str, str] = {
    "AD": "-",
    "BD": "s/m",
    "CD0": "-",
    "KD": "rad^-2",
    "At": "N",
    "Bt": "N s/m",
    "Ct": "N s^2/m^2",
    "Au": "N",
    "Bu": "N s/m",
    "CL0": "-",
    "KL": "rad^-2",
    "KS": "rad^-1",
    "Cy": "N/rad",
    "Kalpha": "rad^-1",
    "pitch_gain": "rad s^2/m",
    "KT": "1/K",
    "grade_rad": "rad",
    "grade_scale": "-",
    "airspeed_factor": "-",
    "yaw_factor": "-",
    "head_wind_mps": "m/s",
    "cross_wind_mps": "m/s",
    # candidate effects of the sim-to-real diagnosis (physics/effects.py)
    "tyre_transient": "-",
    "tyre_time_constant_s": "s",
    "tyre_power_coeff": "-",
    "tyre_speed_exponent": "-",
    "side_slip_coeff_per_n": "1/N",
    "cup_lag_m": "m",
    "mass_error_kg": "kg",
    "wind_gradient_mps": "m/s",
    "yaw_offset_rad": "rad",
}
"""Units of every named model parameter.  AD, BD, CD0, KD, At, Bt, Ct, Au, Bu are the
contract names used in code, outputs and docs."""

PARAMETER_SCALES: dict[str, float] = {
    "AD": 0.01,
    "BD": 1e-4,
    "CD0": 0.4,
    "KD": 1.0,
    "At": 10.0,
    "Bt": 1.0,
    "Ct": 0.01,
    "Au": 1.0,
    "Bu": 0.1,
    "CL0": 0.1,
    "KL": 1.0,
    "KS": 1.0,
    "Cy": 1e4,
    "Kalpha": 1.0,
    "pitch_gain": 0.01,
    "KT": 0.01,
    "grade_rad": 0.001,
    "grade_scale": 1.0,
    "airspeed_factor": 1.0,
    "yaw_factor": 1.0,
    "head_wind_mps": 1.0,
    "cross_wind_mps": 1.0,
    "tyre_transient": 0.1,
    "tyre_time_constant_s": 10.0,
    "tyre_power_coeff": 1e-3,
    "tyre_speed_exponent": 1.0,
    "side_slip_coeff_per_n": 1e-4,
    "cup_lag_m": 1.0,
    "mass_error_kg": 10.0,
    "wind_gradient_mps": 1.0,
    "yaw_offset_rad": 0.01,
}
"""Typical magnitude of each parameter: optimisers and samplers work on ``value / scale`` so
that every unknown is O(1)."""

# --- the thesis test vehicle and simulation inputs (tables 6.3-6.6, section 3) --------------
THESIS_VEHICLE = {
    "mass_kg": 1100.0,
    "effective_mass_kg": 1130.0,
    "frontal_area_m2": 1.85,
    "rolling_radius_m": 0.28,
    "length_m": 4.5,
}
THESIS_COEFFICIENTS = {"AD": 0.01, "BD": 2.0e-4, "CD0": 0.4, "KD": 0.614}
THESIS_FULL_MODEL = {
    "CL0": 0.273,
    "KL": 3.64,
    "KS": 2.4,
    "Cy": 25_000.0,
    "Kalpha": 0.9,
    # alpha = (M l_p / k_p) dv/dt with M = 1100 kg, l_p = 0.55 m (C of G height, reconstructed),
    # k_p = 60e3 N m/rad.
    "pitch_gain": 1100.0 * 0.55 / 60e3,
}
THESIS_DRIVELINE = {"At": 21.0, "Bt": 2.09, "Ct": -0.02}
THESIS_DRIVELINE_ON_LOAD = {"At": 36.3, "Bt": 0.0, "Ct": 0.0}
"""On-load (steady-state) driveline loss, thesis table 7.9: weighted averages of five sets, A_t 36.3 N
(standard error 2.2), B_t 0.0 N s/m (0.11); C_t not fitted (straight line, section 5.5.2)."""
THESIS_UNDRIVEN = {"Au": 3.24, "Bu": 0.232}
THESIS_UNDRIVEN_PER_WHEEL = {
    "nearside": {"Aw": (1.76, 1.58, 1.55), "Bw": (0.117, 0.123, 0.125), "mean": (1.66, 0.121)},
    "offside": {"Aw": (1.57, 1.58, 1.58), "Bw": (0.109, 0.115, 0.121), "mean": (1.58, 0.114)},
}
"""Thesis table 7.10, undriven (rear) wheel spin-downs, three tests per wheel: A (N) and B (N s/m) of
each test and the table's means (as printed: the nearside A tests as transcribed average 1.63, not
1.66; the totals use the printed means).  Vehicle totals ``THESIS_UNDRIVEN``: A_u = 3.24 N (std
0.155, 4.8 %), B_u = 0.232 N s/m (std 0.012, 5.1 %; the printed means add up to 0.235)."""
THESIS_UNDRIVEN_SD = {"Au": 0.155, "Bu": 0.012}
"""Table 7.10's "total std. dev." of A_u and B_u."""
THESIS_WHEEL_INERTIA_KGM2 = 0.59
"""Polar moment of inertia of one wheel of the thesis car *(reconstructed: the transcript gives
none; M_e - M = 30 kg over four wheels at R_r = 0.28 m, drivetrain inertia neglected)*."""
THESIS_TABLE_7_11 = {
    "coastdown_low_wind": {"AD": 0.0094, "BD": 0.231e-3, "CD0": 0.386},
    "coastdown_high_wind": {"AD": 0.0103, "BD": 0.260e-3, "CD0": 0.384},
    "coastdown_set_of_24": {"AD": 0.0098, "BD": 0.233e-3, "CD0": 0.391},
    "steady_state": {"AD": 0.0110, "BD": 0.208e-3, "CD0": 0.410},
    "wind_tunnel": {"CD0": 0.401},
    "std_pct": {"coastdown_low_wind": {"AD": 5.5, "BD": 31.4, "CD0": 8.3},
                "coastdown_high_wind": {"AD": 6.2, "BD": 31.2, "CD0": 9.6},
                "coastdown_set_of_24": {"AD": 4.9, "BD": 27.3, "CD0": 6.4},
                "steady_state": {"AD": 7.6, "BD": 131.7, "CD0": 12.9}},
}
"""Thesis table 7.11, "Summary of initial study results", transcribed from the transcript: mean
coefficients of the coastdowns (low wind, high wind, the set of 24) and of the five steady-state
sets (table 7.6), with their test-to-test standard deviations in %.  The text: steady state gives
AD ~10 % higher, BD ~12 % lower, the aerodynamic term 4.5 % higher and the total drag at 50 mph
4.5 % higher (tyres transmitting torque, section 2.3.1.6); both within 2.5 % of the tunnel C_D0."""
THESIS_TUNNEL_TABLE = {
    "yaw_deg": [-25.0, -20.0, -15.0, -10.0, -5.0, 0.0, 5.0, 10.0, 15.0, 20.0, 25.0],
    "cd": [0.491, 0.468, 0.455, 0.422, 0.412, 0.401, 0.409, 0.426, 0.456, 0.481, 0.486],
    "cs": [-1.121, -0.873, -0.627, -0.415, -0.208, -0.013, 0.186, 0.387, 0.595, 0.841, 1.101],
    "cl": [0.654, 0.629, 0.515, 0.407, 0.317, 0.273, 0.297, 0.383, 0.530, 0.667, 0.662],
}

# --- the thesis simulation study (tables 6.4-6.6; reconstructions marked in the simulator) ---
THESIS_WIND = {"scale_length_m": 30.0, "turbulence_ratio": 0.4, "bandwidth_hz": 1.0}
"""Dryden scale length of head and cross wind, sigma / mean wind, noise band DC-1 Hz (table 6.4)."""
THESIS_SENSORS = {"cup_distance_constant_m": 1.5, "vane_damping_ratio": 0.4, "vane_damped_wavelength_m": 5.0}
"""Cup anemometer and yaw vane characteristics (table 6.5, section 3 of the reference)."""
THESIS_MEASUREMENT_NOISE = {"speed_mps": 0.05, "airspeed_mps": 0.05, "yaw_rad": 0.01, "driveline_force_n": 1.0}
"""Standard deviations of the measurement noise (table 6.6; driveline: this project's choice)."""
THESIS_SYSTEM_NOISE = {"AD": 1.0e-4, "BD": 1.0e-5, "CD0": 5.0e-3}
"""Standard deviations of the system noise on the coefficients (table 6.6)."""

# --- data validation limits -----------------------------------------------------------------
MAX_SPEED_MPS = 100.0
MIN_RUN_SAMPLES = 10
MASS_RANGE_KG = (0.5, 60_000.0)
AREA_RANGE_M2 = (0.001, 15.0)

# --- reporting --------------------------------------------------------------------------------
MPH_TO_MPS = 0.44704
KPH_TO_MPS = 1.0 / 3.6
SPEED_50MPH_MPS = 50.0 * MPH_TO_MPS
ROADLOAD_FIT_SPEEDS_KPH = tuple(float(v) for v in range(15, 120, 5))
"""Speeds (km/h) at which F = F0 + F1 v + F2 v^2 is fitted through the still-air road load."""

# --- speed-gate interval times (physics.intervals, data.vbox, inference.intervals) -------------
INTERVAL_QUADRATURE_NODES = 8
"""Gauss-Legendre nodes per speed band for t = integral M_e / F(v) dv (exact to ~1e-13 relative
on a 5 km/h band of a quadratic road load, tested against appendix D)."""
VBOX_DEFAULT_GATES_KPH = {
    5: ((95.0, 90.0, 85.0, 80.0, 75.0, 70.0),),
    3: ((50.0, 45.0, 40.0, 35.0),),
    10: ((95.0, 90.0, 85.0, 80.0, 75.0, 70.0), (55.0, 50.0, 45.0, 40.0, 35.0, 30.0)),
    14: (tuple(float(v) for v in range(100, 25, -5)),),
}
"""Gate speeds (km/h, descending) assumed for a VBOX Coastdown export by its number of interval
columns, when ``--gates`` is not given: 5 columns = the split method's high window 95 -> 70 km/h
in 5 km/h bands, 3 = the low window 50 -> 35 km/h, 10 = interleaved high and low runs (high runs
fill the first 5 columns; low runs the last 5, 55 -> 30 km/h), 14 = the "Standard" multi-interval
method, 100 -> 30 km/h in 5 km/h bands.  The files do not state them;
these are the set-ups whose band times reproduce every run's logged distance (median |error|
0.03-0.14 % with band mid-speeds; the next candidates, 90 -> 70 in 4 km/h bands or 45 -> 35,
are 2.8-5.8 % off) in the sample exports of docs/real_data.md.  The importer checks them
against each run's total time and distance (:data:`VBOX_DISTANCE_TOLERANCE`)."""
VBOX_TIME_TOLERANCE_S = 0.03
"""Largest |sum of a run's band times - its logged total time| accepted (the export rounds each
to 0.01 s)."""
VBOX_DISTANCE_TOLERANCE = 0.005
"""Largest |median over runs of (sum of band time x band mid-speed - logged distance) / logged
distance| accepted for a set of gate speeds; a run beyond ``3 x`` this is flagged."""
INTERVAL_NOISE_PRIORS = {
    "sigma_gate_s": 0.05,            # mean of the Gamma(4) prior of the gate-crossing timing error (s)
    "run_decel_sd_mps2": 0.005,      # mean of the Gamma(2) prior of a run's deceleration offset (m/s^2)
    "band_noise_s_per_sqrt_s": 0.02,  # mean of the Gamma(2) prior of the within-run band noise
}
"""Nuisance priors of the interval-time likelihood (:mod:`bayes_roadload.inference.intervals`).
Gamma priors (shapes below) vanish at 0 (no funnel at the boundary).  ``sigma_gate_s``: timing error of one
gate crossing (GNSS speed noise / deceleration, after the logger's smoothing); ``run_decel_sd_mps2``:
run-to-run scatter of a constant deceleration offset (gusts, tyre temperature, driver), 0.005
m/s^2 is 7.5 N on a 1500 kg car; ``band_noise_s_per_sqrt_s``: independent scatter of each band
growing as the square root of its duration (force fluctuations within a run)."""
INTERVAL_NOISE_PRIOR_SHAPES = {"sigma_gate_s": 4.0, "run_decel_sd_mps2": 2.0, "band_noise_s_per_sqrt_s": 2.0}
"""Gamma shapes of those priors.  ``sigma_gate_s`` has shape 4 (sd 0.025 s about the mean 0.05 s):
on the Ioniq exports the band noise dominates and the gate error is barely identified (posterior
0.008-0.18 s with shape 2, its upper tail mixing too slowly for the tail-ESS gate)."""

# --- distance-time records (data.distances, physics.distances, inference.distances) ------------
MIN_DISTANCE_MARKERS = 3
"""Fewest markers a distance-time run may pass: its speed at the first marker is unknown, so two
markers (one segment time) only determine that speed."""
DISTANCE_SEGMENT_SPEED_RANGE_MPS = (0.1, MAX_SPEED_MPS)
"""Accepted mean speed between two consecutive markers of a run (m/s); outside it the units are
wrong (km or mm in ``distance_m``, ms in ``time_s``)."""
DISTANCE_RK4_SUBSTEPS = 4
"""RK4 steps (in distance) between two consecutive markers: on 100 m marker spacing from 30 m/s
the passing times agree with the closed form of a quadratic road load to ~1e-9 s over 1300 m
(tested; 8 steps: 1e-10 s, 2 steps: 2e-8 s), far below any timing error (a light gate's ~1 ms);
the error grows as the fourth power of the step (500 m spacing: ~1e-6 s)."""
DISTANCE_MIN_SPEED_MPS = 0.05
"""Floor of the speed in the distance-domain ODE (dv/dx = a / v, dt/dx = 1 / v): keeps a draw
whose vehicle would stop before the last marker finite (its times then are merely very long)."""
DISTANCE_NOISE_PRIORS = {
    "sigma_gate_s": 0.05,            # mean of the Gamma(4) prior of one marker-passing timing error (s)
    "run_decel_sd_mps2": 0.005,      # mean of the Gamma(2) prior of a run's deceleration offset (m/s^2)
    "band_noise_s_per_sqrt_s": 0.02,  # mean of the Gamma(2) prior of the within-run segment noise
}
"""Nuisance priors of the distance-time likelihood (:mod:`bayes_roadload.inference.distances`):
the interval-time likelihood's three (the segment between two markers plays the band): a timing
error per marker passing (a camera frame at 25-30 fps is 0.03-0.04 s, a light gate ~0.001 s),
scatter growing with a segment's duration, and a run-level deceleration offset."""
DISTANCE_NOISE_PRIOR_SHAPES = {"sigma_gate_s": 4.0, "run_decel_sd_mps2": 4.0, "band_noise_s_per_sqrt_s": 2.0}
"""Gamma shapes of those priors: the interval-time ones but shape 4 (sd half the mean) for the run
effect, which a few runs barely identify: with shape 2 the sampler reached run-effect sds of
0.0002 m/s^2, where the coefficients' posterior narrows into a funnel, and diverged in some of
1000 draws of every 4-run fit at target acceptance 0.9 (benchmarks/distance_masses.py, seeds 5-7;
seed 7: 9 divergences, 2 with shape 4, the rest in the curved tails of AD-BD-CD0, which target
acceptance 0.95 removes).  Shape 4 for the segment noise too did not help (4)."""
DISTANCE_V0_PRIOR_SD_MPS = 5.0
"""sd of the Normal prior of each run's speed at its first marker, centred on the speed a
quadratic through the run's first three passing times gives (the data fix it to ~0.01 m/s)."""


@dataclass(frozen=True)
class IntegratorConfig:
    """Settings of the RK4 integrator.

    Parameters
    ----------
    substeps : int
        RK4 steps taken between consecutive samples (the measured inputs are linearly
        interpolated inside the interval).  The thesis used one step per 0.25 s sample.
    stride : int
        1, or 2: one RK4 step spans two sample intervals (with ``substeps = 1``).  Its
        half-step stages see the mean of the interpolated inputs over the middle half of the
        step, so that a force linear in the inputs integrates exactly as with one step per
        sample, and the speed at the middle sample comes from RK4's third-order continuous
        extension: half the sequential steps (the fit's gradient is dominated by them) for a
        change far below the speed noise (the coastdown decelerates on a time scale of
        minutes; measured in ``tests/physics/test_integrate.py``).
    parallel : bool
        With ``stride = 2``, solve models whose equation of motion is linear in the speed
        (``DragModel.speed_affine``: measured air, the thesis' terms) in parallel over time
        (a prefix scan of the RK4 steps' affine maps) instead of step by step; same result.
    """

    substeps: int = 1
    stride: int = 1
    parallel: bool = True

    def __post_init__(self):
        if self.substeps < 1 or self.stride < 1:
            raise ValueError(f"substeps and stride must be >= 1, got {self.substeps} and {self.stride}")


DEFAULT_INTEGRATOR = IntegratorConfig(stride=2)


@dataclass(frozen=True)
class SamplerConfig:
    """Settings of the NUTS fit (:func:`bayes_roadload.inference.nuts.fit_nuts`).

    Parameters
    ----------
    num_warmup, num_samples, num_chains : draws per chain and number of chains (run in
        parallel on the CPU cores when there are enough).  300 warm-up draws suffice after
        the Laplace preconditioning (measured on 18 pairs: max R-hat 1.009, min bulk ESS 2682
        against 1.008 / 2142 with 500); 1000 draws per chain keep the max split R-hat over
        ~80 quantities below 1.01 (with 500 it reached 1.017-1.02 on the same fit).
    target_accept : NUTS target acceptance probability.  0.8 (numpyro's and Stan's default):
        on 18 pairs 10.5 leapfrog steps per draw against 14.8 at 0.9, both without
        divergences; the demo (6 pairs) passes every gate with 0 divergences.  Campaigns of one
        or two pairs barely identify the integrated noise q and may diverge where q is small:
        the divergence gate then fails and the CLI prints the remedy (``--target-accept
        0.95``, what the tests use for two pairs).
    max_tree_depth : NUTS tree-depth limit (2^depth - 1 leapfrog steps).
    precondition : "laplace" (default) runs NUTS on coordinates whitened by the Laplace
        covariance at the MAP, chains starting from Laplace draws; "none" is numpyro's default
        NUTS (diagonal mass adaptation from a random start), kept for the benchmark.
    mass_matrix : mass matrix adapted during warm-up in the Laplace-whitened coordinates:
        "dense" (also corrects rotations the Laplace approximation gets wrong), "diag" (only
        scales) or "identity" (trust the Laplace fit).  "auto" (default) is dense up to
        ``DENSE_MASS_MAX_DIM`` unconstrained dimensions and diagonal above: numpyro estimates
        the mass matrix from warm-up windows of 25, 50, 100 ... draws, and a dense estimate from
        fewer draws than dimensions is rank-deficient (its regularisation then gives some
        directions ~1e-4 of their variance and the trees saturate: measured on 18 pairs,
        77 dimensions).
    seed : PRNG seed.
    progress_bar : show numpyro's progress bar.
    """

    num_warmup: int = 300
    num_samples: int = 1000
    num_chains: int = 2
    target_accept: float = 0.8
    max_tree_depth: int = 10
    precondition: str = "laplace"
    mass_matrix: str = "auto"
    seed: int = 0
    progress_bar: bool = False
    posterior_predictive_draws: int = 200

    def __post_init__(self):
        if self.precondition not in ("laplace", "none"):
            raise ValueError("precondition must be 'laplace' or 'none'")
        if self.mass_matrix not in ("auto", "diag", "dense", "identity"):
            raise ValueError("mass_matrix must be 'auto', 'diag', 'dense' or 'identity'")
        if min(self.num_warmup, self.num_samples, self.num_chains) < 1:
            raise ValueError("num_warmup, num_samples and num_chains must be positive")


DENSE_MASS_MAX_DIM = 20
"""Largest number of unconstrained dimensions for which ``mass_matrix="auto"`` adapts a dense
mass matrix (numpyro's first warm-up window has 25 draws)."""


@dataclass(frozen=True)
class Gates:
    """Pass/fail thresholds every NUTS fit is checked against (reported in diagnostics.json).

    Defaults follow Vehtari et al. (2021): split R-hat <= 1.01, bulk and tail ESS >= 100 per
    chain, no divergent transitions, E-BFMI >= 0.3, and (a sign of a badly scaled posterior)
    at most 1 % of draws hitting the tree-depth limit.
    """

    max_r_hat: float = 1.01
    min_ess_bulk_per_chain: float = 100.0
    min_ess_tail_per_chain: float = 100.0
    max_divergences: int = 0
    min_bfmi: float = 0.3
    max_tree_depth_hits_fraction: float = 0.01


DEFAULT_SAMPLER = SamplerConfig()
DEFAULT_GATES = Gates()

# Priors of the nuisance parameters of the Bayesian models (physical units).
NOISE_PRIORS = {
    "sigma_mps": 0.1,          # half-normal scale of the speed measurement noise, per run
    "q_mps_per_sqrt_s": 0.005,  # mean of the Gamma(2) prior of the integrated (process) noise
    "v0_scale_mps": 0.5,       # normal scale of each run's initial speed around its first sample
    "student_df_rate": 0.1,    # Gamma(2, rate) prior of the Student-t degrees of freedom
    "sigma_driveline_n": 10.0,  # half-normal scale of the logged driveline force's noise (N)
    "airspeed_calibration_sd": 0.01,  # mean of the Gamma(2) prior of s_cal (see below)
}
"""``airspeed_calibration_sd`` (s_cal, dimensionless): scatter of one opposite-direction pair's
calibration ratio r_k about the true airspeed factor, when a model file frees
``airspeed_factor`` (:func:`bayes_roadload.inference.bayes.airspeed_pair_ratios`).  Gamma(2)
with mean 0.01 (sd 0.007; vanishes at 0, so few pairs do not leave a funnel at s_cal -> 0):
measured 0.0078 per pair over 100 simulated pairs at 2 m/s head and cross wind (the
turbulence that does not average out over a run), and the thesis' track groups of 3 pairs
scattered by 0.0063 (table 4.1), ~0.011 per pair."""
TAU_PRIOR_SCALES = {"AD": 1.0e-3, "BD": 5.0e-5, "CD0": 0.02}
"""Prior means of the run-to-run spreads tau of the hierarchical model, Gamma(2) priors (10 %,
25 %, 5 % of typical values: the thesis' track spreads were 4.3 %, 23.1 %, 4.3 %)."""


# Undriven-wheel spin-down (bayes_roadload.data.spindown, inference.spindown)
WHEEL_INERTIA_RANGE_KGM2 = (0.01, 50.0)
"""Plausible polar moments of inertia of one road wheel (kg m^2): a car wheel with tyre and disc
is ~0.5-1.5, a truck wheel ~10-20; outside, the unit is likely wrong (kg cm^2, g m^2)."""
SPINDOWN_TAU_PRIOR_MEANS = {"Au": 0.1, "Bu": 0.005}
"""Prior means of the test-to-test spreads of one wheel's A_w (N) and B_w (N s/m) in a
hierarchical spin-down fit, Gamma(2) priors (~6 % and ~4 % of table 7.10's values; the table's
three tests per wheel scatter by 0.02-0.11 N and 0.003-0.006 N s/m)."""
DEFAULT_UNDRIVEN_WHEELS = 2
"""Undriven wheels of a two-axle vehicle with one driven axle (``[spindown] undriven_wheels``)."""
SPINDOWN_SIMULATION = {"v0_mps": 31.0, "v_end_mps": 3.0, "sample_rate_hz": 4.0, "speed_noise_mps": 0.02}
"""Simulated spin-downs: released at ~70 mph tread speed (the thesis' maximum test speed), logged at
4 Hz until the tread speed falls to 3 m/s, wheel-speed noise 0.02 m/s (a toothed-wheel pickup;
the coastdown speed channel's 0.05 m/s of table 6.6 is an upper bound)."""


# Steady-state torque tests (bayes_roadload.data.steady, inference.steady, simulate.steady)
STEADY_MAX_ACCEL_MPS2 = 0.5
"""Largest |dv/dt| of a steady-speed sample: beyond it the run is not steady (or the column holds
g or km/h/s); the inertial correction M_e dv/dt is then no longer a small correction."""
STEADY_NOISE_PRIORS = {"sigma_force_n": 20.0, "run_force_sd_n": 10.0, "pair_wind_mps": 3.0}
"""Priors of the steady-state likelihood: ``sigma_force_n`` half-normal scale of the
sample-to-sample scatter of the tractive force (N; the thesis' steady residuals are an order of
magnitude above the coastdown's, section 7.4); ``run_force_sd_n`` mean of the Gamma(2) prior of a
run's constant force offset (gusts averaged over the run, tyre temperature, the driver; vanishes at
0, no funnel); ``pair_wind_mps`` normal scale of the latent along-track wind of an
opposite-direction pair when no anemometer was fitted."""
STEADY_SIMULATION = {"speeds_mph": (20.0, 30.0, 40.0, 50.0, 60.0, 70.0), "duration_s": 30.0,
                     "sample_rate_hz": 1.0, "force_noise_n": 15.0, "run_force_sd_n": 8.0,
                     "accel_sd_mps2": 0.02, "speed_noise_mps": 0.05, "driveline_noise_n": 10.0}
"""Simulated steady-state groups (thesis section 5.1.3: 20-70 mph in 10 mph steps, both
directions): each run held ``duration_s`` at its set speed with a constant drift of sd
``accel_sd_mps2`` (the driver holds the throttle, section 5.4.1), logged at ``sample_rate_hz``;
torque-meter noise ``force_noise_n`` per sample and a run offset of sd ``run_force_sd_n``; the
gearbox input force carries the on-load driveline loss plus ``driveline_noise_n`` noise."""


# Run validity (bayes_roadload.analysis.validity)
WIND_LIMITS = {
    "eec": {"mean_wind_mps": 3.0, "peak_wind_mps": 5.0, "mean_cross_wind_mps": 2.0},
    "gtr_stationary": {"mean_wind_mps": 5.0, "peak_wind_mps": 8.0, "mean_cross_wind_mps": 2.0},
    "gtr_onboard": {"mean_wind_mps": 7.0, "peak_wind_mps": 10.0, "mean_cross_wind_mps": 4.0},
}
"""Wind limits of a valid coastdown run (m/s).

``eec``: Directive 70/220/EEC as amended by 88/436/EEC (road load; ECE R15.04 alike): "wind
speeds averaging less than 3 m/s with peak speeds less than 5 m/s; the vector component of the
wind speed across the test road less than 2 m/s".  Checked against two texts: the thesis quotes
it word for word (transcript, section 1.5, citing EEC 88/436; its table 7.1 lists average 3.0,
peak 5.0, cross-track 2.0 m/s as "ECE 15.04"), and the German transposition,
StVZO Anlage XXIII 3.9.2.3 (regelwerke.vbg.de/vbg_vero/nstvzo/nstvzo_533_.html: mean at most
3 m/s, gusts below 5 m/s, cross component below 2 m/s, measured 0.7 m above the road).

``gtr_stationary`` / ``gtr_onboard``: UN GTR No. 15 (WLTP) Annex 4, paragraphs 4.1.1.1.1
(stationary anemometry: average below 5 m/s, peaks below 8 m/s for less than 2 s, cross component
below 2 m/s) and 4.1.1.1.2 (on-board anemometry: overall average below 7 m/s, peaks below 10 m/s,
cross component below 4 m/s).  The paragraphs' text was not among the sources searchable here
(searched 2026-11): UNECE/globalautoregs pages name the GTR's amendments only, and an extract of
its EU transposition, Regulation (EU) 2017/1151 Annex XXI Sub-Annex 4, confirms the on-board
procedure around it (4.3.2.4: at least 5 pairs; a run failing the on-board anemometry conditions
is rejected with its opposite-direction partner, as :mod:`bayes_roadload.analysis.validity` does)
and that Regulation (EU) 2018/1832 replaced 4.1.1.1 - 4.1.1.1.2 ("Permissible wind conditions"),
but stops before the figures.  The values are those of the consolidated GTR 15 as the project
reads it, unverified against the text, and unchanged.
The stationary peak limit allows peaks above 8 m/s shorter than 2 s; the check here
(:mod:`bayes_roadload.analysis.validity`) applies the peak to the maximum of the run, which is
stricter by that allowance."""
DEFAULT_WIND_LIMITS = "gtr_onboard"
"""The limits applied to campaigns with on-board anemometers unless another set is chosen."""
HAMPEL_THRESHOLD = 3.0
"""A value further than this many scaled MADs (1.4826 MAD) from its group's median is an outlier."""
HAMPEL_MIN_RELATIVE_SPREAD = 0.02
"""Floor of the scaled MAD of a group of run times, as a fraction of its median: run-to-run
scatter of ~2 % is ordinary on a track (wind, tyre temperature), and groups of 5-10 runs with a
tight core would otherwise reject ordinary runs (measured on the Ioniq exports of
docs/real_data.md: the MAD of 6 runs was 0.04 s on 35 s)."""
HAMPEL_HALF_WINDOW = 10
"""Samples on each side of the running Hampel filter over a speed trace (with 5 the MAD of 11
samples was too noisy: 1-3 % of clean simulated samples flagged)."""
HAMPEL_MAX_SPIKE_FRACTION = 0.05
"""A speed trace with more than this fraction of Hampel-flagged samples is rejected.  On clean
Gaussian speed noise the filter flags 1.3 % of the samples on average (at most 2.3 % over 50
traces of 400 samples: the local MAD of 21 samples is itself noisy), on the simulated campaigns
of the tests 0.5-2.9 %."""

# Studies of many fits (bayes_roadload.analysis.batch)
COVERAGE_LEVELS = (0.5, 0.9, 0.95)
"""Central posterior interval levels recorded for every quantity (and checked for coverage)."""

CLEAR_JAX_CACHES_ABOVE_MB = 4096.0
"""Resident memory (MB) above which :func:`bayes_roadload.analysis.batch.run_fit_job` clears JAX's compilation caches after a
job.  Clearing after every job would bound the memory at ~1.2 GB but costs 5-8 s per later fit
(the shared pieces are recompiled); never clearing grows by 85-165 MB per fit."""


# MAP + Laplace fits of studies (bayes_roadload.inference.laplace)
LAPLACE_DRAWS = 2000
"""Draws per MAP + Laplace fit (proposals of the importance-sampling correction)."""

LAPLACE_PROPOSAL_DF = 5
"""Degrees of freedom of the multivariate-t proposal around the MAP (heavier tails than the
Gaussian, so that the importance weights of a right-skewed posterior stay bounded)."""

LAPLACE_PROPOSAL_INFLATION = (1.0, 1.5, 2.0)
"""Scale factors of the proposal's covariance tried in turn while the Pareto k is above
``LAPLACE_GOOD_PARETO_K`` (the best proposal is kept).  Measured on one pair, pooled: k 0.81 at
1.0, 0.63 at 2.0 (the coefficients' posterior sd there is ~2x the Laplace sd)."""

LAPLACE_GOOD_PARETO_K = 0.5
"""Pareto k below which the first proposal is accepted without trying wider ones."""

LAPLACE_MAX_PARETO_K = 0.7
"""A Laplace fit whose importance weights have a Pareto k above this fails its gate (PSIS,
Vehtari et al. 2024: the corrected estimates are then unreliable)."""


# Test planning (bayes_roadload.analysis.planning) and the regulation checks
QUANTITY_UNITS: dict[str, str] = {**PARAMETER_UNITS, "F50_N": "N", "F50_tyre_N": "N", "F0_N": "N",
                                  "F2_N_per_kph2": "N/(km/h)^2"}
"""Units of the quantities a planning target may name (absolute targets are in these units)."""

MAX_LOGGED_YAW_RAD = 1.5
"""Largest |yaw| a simulated future run logs (the simulator's ``max_yaw_rad``; the data contract
holds |yaw| <= pi/2)."""

PLAN_CONFIDENCE = 0.95
"""Level of the interval whose half-width a planning target bounds."""

PLAN_ASSURANCE = 0.8
"""Planning recommends the smallest number of pairs whose half-width meets the target in at
least this fraction of the simulated future campaigns."""

PLAN_TARGETS = ("AD=1%", "BD=5%", "CD0=1%", "F50_N=0.5%")
"""Default planning targets: the thesis' (section 8.2: A_D, C_D0 within 1 %, B_D within 5 %) and
the road load at 50 mph within 0.5 %."""

PLAN_PAIRS = (1, 2, 3, 4, 6, 8, 12, 16, 24)
"""Campaign sizes (pairs) a plan simulates by default."""

PLAN_SIMULATIONS = 40
"""Future campaigns simulated per number of pairs (the assurance's binomial sd is <= 0.08)."""

EEC_PRECISION_PCT = 2.0
"""EEC coastdown acceptance (thesis appendix A): t s / (sqrt(n) X) <= 2 % at 95 %, X the mean
total road load at the reference speed over the n pairs and s their standard deviation."""

GTR_PRECISION_PCT = 3.0
"""GTR 15 (WLTP, Annex 4) coastdown statistical precision: p_j = h s_j / (sqrt(n) dt_j) <= 3 %
at every reference speed v_j, dt_j the pairs' mean coastdown time from v_j + 5 to v_j - 5 km/h
(harmonic mean of the two directions of a pair), h = t(0.975, n - 1)."""

GTR_SPEED_HALF_BAND_KPH = 5.0
"""Half width of the GTR 15 coastdown-time speed band around each reference speed (km/h)."""

GTR_REFERENCE_SPEEDS_KPH = (20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 90.0, 100.0, 110.0, 120.0, 130.0)
"""GTR 15 reference speeds (km/h); those inside every run's speed range are checked."""

MIN_REGULATION_PAIRS = 3
"""GTR 15 needs at least three pairs."""

REGULATION_MAX_PAIRS = 200
"""Largest number of pairs searched for the pairs a failing criterion still needs."""

# Sim-to-real diagnosis (bayes_roadload.analysis.diagnose, issue 6)
@dataclass(frozen=True)
class DiagnosisConfig:
    """Thresholds of the sim-to-real diagnosis.

    support_delta_elpd : a candidate is *supported* when adding it raises the estimated
        expected log predictive density (gain in maximised log likelihood minus the parameters
        it adds, Akaike) by at least this much (nats): odds of e^5 ~ 150 to 1.  For one added
        parameter under no effect the gain is chi^2_1 / 2 - 1, so a single null candidate
        passes with probability P(chi^2_1 > 12) = 5e-4; 13 candidates ~0.7 %.
    min_contraction : a candidate is identifiable here only when the data shrink each of its
        parameters' prior variance (a plausible size of the effect) by at least this share,
        the user's coefficients re-fitted with it (an effect whose signature the coefficients
        can mimic -- an effective-mass error, lift unloading against C_D0 -- is left with its
        prior).  The share of its signature the coefficients mimic is reported too
        (``information_ratio``).
    ambiguity_margin : the top candidate is claimed only when its delta_elpd exceeds every
        other candidate's (identifiable or not) by at least this much (nats: Akaike weight
        e^2 ~ 7 to 1); otherwise the candidates within the margin explain the gap alike and
        none is supported ("not distinguishable here").
    min_distinct_share : the top candidate is claimed only when, against every other candidate
        that reaches ``support_delta_elpd`` on its own, at least this share of its Fisher
        information (the coefficients refitted) is left once the rival's parameters are fitted
        too (0.1: the variance-inflation-factor rule VIF < 10); below it their signatures are
        one and none is supported ("not distinguishable here").
    min_vuong_z : and against every other candidate that explains part of the gap (delta_elpd > 0),
        the best's per-run gains must beat the rival's by this many standard errors over the
        runs (Vuong's test for non-nested models): a lead that one run makes is not a claim.
        Not asked of a run-level best (``kind = "run"``), whose gain lies in the runs that differ.
    max_refit_effects : leading supported candidates refitted together (forward selection).
    gauss_newton_steps : re-linearisations of the combined refit (nonlinear check).
    """

    support_delta_elpd: float = 5.0
    min_contraction: float = 0.5
    ambiguity_margin: float = 2.0
    min_distinct_share: float = 0.1
    min_vuong_z: float = 2.0
    max_refit_effects: int = 3
    gauss_newton_steps: int = 2


DEFAULT_DIAGNOSIS = DiagnosisConfig()
