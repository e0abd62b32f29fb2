"""Physical constants and the package's numerical settings.

Physical constants and the reference conditions of the thesis (Passmore 1990, section 2.2.1.3),
the parameter names of the data contract with their units and O(1) scales, the data
importers' plausibility limits, and the settings of the integrator, of the samplers, of the
quality gates and of the estimators and checks whose settings more than one module shares.
A constant used by one module only is defined in that module; the thesis' published values are
in :mod:`bayes_roadload.thesis`.  Importing this module has no side effects (JAX is configured
by :mod:`bayes_roadload._jax`).
"""

from __future__ import annotations

from dataclasses import dataclass

from ._jax import share_programs

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
    "yaw_saturation_per_rad2": "rad^-2",
    "yaw_levelling_per_rad2": "rad^-2",
    "yaw_knee_rad": "rad",
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
    "tyre_lag_gain_per_mps": "s/m",
    "tyre_quadratic_s2_per_m2": "s^2/m^2",
    "tyre_lag_time_constant_s": "s",
    "grade_rad": "rad",
    "grade_scale": "-",
    "airspeed_factor": "-",
    "yaw_factor": "-",
    "head_wind_mps": "m/s",
    "cross_wind_mps": "m/s",
    # candidate effects of the sim-to-real diagnosis (physics/effects.py)
    "tyre_transient": "-",
    "tyre_time_constant_s": "s",
    "tyre_level": "-",
    "tyre_power_coeff": "-",
    "tyre_speed_exponent": "-",
    "side_slip_coeff_per_n": "1/N",
    "cup_lag_m": "m",
    "admittance_gain": "-",
    "admittance_length_m": "m",
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
    "yaw_saturation_per_rad2": 4.0,
    "yaw_levelling_per_rad2": 1.0,
    "yaw_knee_rad": 0.35,
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
    "tyre_lag_gain_per_mps": 0.005,
    "tyre_quadratic_s2_per_m2": 1e-6,
    "tyre_lag_time_constant_s": 400.0,
    "grade_rad": 0.001,
    "grade_scale": 1.0,
    "airspeed_factor": 1.0,
    "yaw_factor": 1.0,
    "head_wind_mps": 1.0,
    "cross_wind_mps": 1.0,
    "tyre_transient": 0.1,
    "tyre_time_constant_s": 10.0,
    "tyre_level": 0.01,
    "tyre_power_coeff": 1e-3,
    "tyre_speed_exponent": 1.0,
    "side_slip_coeff_per_n": 1e-4,
    "cup_lag_m": 1.0,
    "admittance_gain": 1.0,
    "admittance_length_m": 10.0,
    "mass_error_kg": 10.0,
    "wind_gradient_mps": 1.0,
    "yaw_offset_rad": 0.01,
}
"""Typical magnitude of each parameter: optimisers and samplers work on ``value / scale`` so
that every unknown is O(1)."""

# --- data validation limits -----------------------------------------------------------------
MAX_SPEED_MPS = 100.0
STANDSTILL_MPS = 0.2
"""A speed-trace sample at or below this speed (0.72 km/h) is a vehicle at rest, and its run is
refused (:func:`bayes_roadload.data.traces.validate_runs`): eq. 5.4 describes a rolling vehicle,
and the integrator continues a trajectory below zero at the forces of standstill
(:func:`bayes_roadload.physics.integrate.integrate_run`).  Coastdown speed ranges end far above
it (SAE J2263, GTR 15: 15 km/h); a run simulated down to 0.5 m/s with the thesis' speed noise
(0.05 m/s) stays above it by 6 sd."""
MIN_RUN_SAMPLES = 10
MASS_RANGE_KG = (0.5, 60_000.0)
AREA_RANGE_M2 = (0.001, 15.0)

# --- reporting --------------------------------------------------------------------------------
MPH_TO_MPS = 0.44704
KPH_TO_MPS = 1.0 / 3.6
SPEED_50MPH_MPS = 50.0 * MPH_TO_MPS
ROADLOAD_FIT_SPEEDS_KPH = tuple(float(v) for v in range(15, 120, 5))
"""Speeds (km/h) at which F = F0 + F1 v + F2 v^2 is fitted through the still-air road load."""

# --- speed-gate interval times (data.vbox, inference.intervals, simulate.intervals) -------------
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

# --- distance-time records (data.distances, inference.distances, simulate.distances) ----------
MIN_DISTANCE_MARKERS = 3
"""Fewest markers a distance-time run may pass: its speed at the first marker is unknown, so two
markers (one segment time) only determine that speed."""
DISTANCE_SEGMENT_SPEED_RANGE_MPS = (0.1, MAX_SPEED_MPS)
"""Accepted mean speed between two consecutive markers of a run (m/s); outside it the units are
wrong (km or mm in ``distance_m``, ms in ``time_s``)."""
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
        divergences; the demo (6 pairs) passes every gate with 0 divergences.
    small_campaign_runs, small_campaign_target_accept : campaigns of at most
        ``small_campaign_runs`` runs are sampled at ``small_campaign_target_accept`` (when it is
        higher; None: never).  One or two pairs barely identify the integrated noise q, and
        where q is small the coefficients' conditional posterior narrows faster than a step
        size adapted to the bulk (a funnel): thesis case 18 at one pair gave 12 divergences in
        2000 draws at 0.8, 27 at 0.9 and 0 at 0.95 (14.96 leapfrog steps per draw against
        12.1).  ``--target-accept`` sets the acceptance of every campaign size.
    quiet_trace_target_accept : target acceptance (when higher) of a fit whose MAP puts the
        speed noise ``sigma_mps`` of the median run below the likelihood's floor
        (:data:`SPEED_NOISE_FLOOR_MPS`; None: never).  Below the floor the likelihood hardly
        sees ``sigma_mps``, and the noise scales' posteriors (``sigma_mps``, q) meet a
        likelihood that is Gaussian in the scale: in numpyro's log coordinate a wall whose
        curvature grows as e^(2 log q), where a step size adapted to the bulk diverges now
        and then (thesis case 1 at 6 pairs, hierarchical: see docs/calibration.md, "The sampler
        and its gates").  ``--target-accept`` turns it off.
    max_tree_depth : NUTS tree-depth limit (2^depth - 1 leapfrog steps).
    precondition : "laplace" (default) runs NUTS on coordinates whitened by the Laplace
        covariance at the MAP, chains starting from Laplace draws; "none" is numpyro's default
        NUTS (diagonal mass adaptation from a random start), kept for the benchmark.
    mass_matrix : mass matrix adapted during warm-up in the Laplace-whitened coordinates:
        "dense" (also corrects rotations the Laplace approximation gets wrong), "diag" (only
        scales) or "identity" (trust the Laplace fit).  "auto" (default) is dense up to
        ``DENSE_MASS_MAX_DIM`` unconstrained dimensions; above, diagonal for a hierarchical
        fit and the identity for the others (:func:`bayes_roadload.inference.nuts.mass_matrix`).
        numpyro estimates the mass matrix from warm-up windows of 25, 50, 100 ... draws, and a
        dense estimate from fewer draws than dimensions is rank-deficient (its regularisation
        then gives some directions ~1e-4 of their variance and the trees saturate: measured on
        18 pairs, 77 dimensions).  On the pooled cold-start reference a diagonal one from the
        last window of 100 draws spread the adapted inverse masses over 0.50-1.61 in
        coordinates the Laplace fit whitens exactly at the MAP, and gave 113 min-ESS per 1000
        gradients against 164 with the identity (``benchmarks/sampler_geometry.py``);
        on thesis cases 1-19 at six pairs (hierarchical) the identity passed every gate first
        time in 17 of 19 fits against 19 of 19 with the diagonal, its trees no shorter.
    seed : PRNG seed.
    progress_bar : show the sampler's progress on a terminal: a bar of the time so far (and of
        the time left for continued chains), drawn by a thread beside the compiled program.
    iteration_bars : with ``progress_bar``, numpyro's bars of each chain's iterations instead.
        They are drawn by host callbacks inside the program, and JAX keeps programs with host
        callbacks out of its persistent compilation cache: the sampler then compiles again in
        every process (a 2-pair fit started warm on a terminal: 72 s with them, 59 s with the
        time bar; ``benchmarks/terminal_cache.py``, docs/performance.md).
    heartbeat_s : without a progress bar, log a plain line at INFO every ``heartbeat_s``
        seconds while warm-up and sampling run (one compiled program that reports nothing
        until it ends: a 500-pair fit ran 39 min without a line), with the time so far; 0: none.
        A thread beside the program, not a callback inside it: the program, what it samples
        and its entry in JAX's persistent compilation cache (which skips programs with host
        callbacks) stay as they are.
    retry : when the first run fails a gate, remedy it once: when only R-hat or ESS failed,
        the same chains continue for as many draws again (the first draws kept, warm-up not
        repeated: :data:`bayes_roadload.inference.nuts.CONTINUED_GATES`); otherwise the sampler
        runs anew with the remedy for that gate (:func:`bayes_roadload.inference.nuts.remedy`):
        twice the warm-up and the draws, and after divergences target acceptance 0.99.  The
        retry, why, whether it ``continued`` and the first attempt's time are recorded in
        ``diagnostics.json`` (``retries``); the gates are then those of all the draws kept.  Only
        fits with at least the default warm-up and draws retry: fewer is a quick look whose
        ESS gates are expected to fail, and a retry would spend the time it was meant to save.
    noise_scaled_metric : with the Laplace preconditioning, let the whitened coordinates other
        than the integrated noise's intensity q shrink as q falls and widen as it rises
        (:func:`bayes_roadload.inference.nuts.noise_scaled_coordinates`): where one or two pairs
        barely bound q from below, the coefficients' conditional posterior narrows as q falls
        (the funnel above), and a step size adapted to the bulk diverges in that tail.  The
        change of coordinates is exact (its Jacobian is in the potential): the posterior is the
        same.  On by default: thesis cases 1-19 at one pair passed every gate first time in
        19 of 19 fits against 14 of 19 without (docs/calibration.md, "The vehicle's
        aerodynamic admittance and a heavy vehicle's priors"); a problem without exactly one
        q (interval times, steady states, a noise intensity per run) is sampled in the
        Laplace coordinates.
    coordinates : "auto" (default): a problem is sampled in its own coordinates, and in its
        alternative ones (:meth:`bayes_roadload.inference.problem.Problem.alternative_coordinates`;
        the tyre-lag model: A_D, B_D, C_D0 directly instead of the apparent coefficients) from the
        start only where its MAP's Laplace approximation reaches a wall
        (:data:`MAX_BEYOND_SUPPORT_SHARE`) or on the retry after divergences; "alternative": in
        the alternative coordinates from the start wherever the problem has them (the same
        posterior, from their own MAP: with ``precondition = "laplace"`` only; a design option,
        measured by ``benchmarks/coordinates_study.py``).
    """

    num_warmup: int = 300
    num_samples: int = 1000
    num_chains: int = 2
    target_accept: float = 0.8
    small_campaign_runs: int = 4
    small_campaign_target_accept: float | None = 0.95
    quiet_trace_target_accept: float | None = 0.95
    max_tree_depth: int = 10
    precondition: str = "laplace"
    mass_matrix: str = "auto"
    seed: int = 0
    progress_bar: bool = False
    iteration_bars: bool = False
    heartbeat_s: float = 60.0
    retry: bool = True
    posterior_predictive_draws: int = 200
    noise_scaled_metric: bool = True
    coordinates: str = "auto"

    def __post_init__(self):
        if self.precondition not in ("laplace", "none"):
            raise ValueError("precondition must be 'laplace' or 'none'")
        if self.mass_matrix not in ("auto", "diag", "dense", "identity"):
            raise ValueError("mass_matrix must be 'auto', 'diag', 'dense' or 'identity'")
        if self.coordinates not in ("auto", "alternative"):
            raise ValueError("coordinates must be 'auto' or 'alternative'")
        if self.coordinates == "alternative" and self.precondition != "laplace":
            raise ValueError("coordinates 'alternative' start from the Laplace MAP: give precondition 'laplace'")
        if min(self.num_warmup, self.num_samples, self.num_chains) < 1:
            raise ValueError("num_warmup, num_samples and num_chains must be positive")
        if not self.heartbeat_s >= 0.0:
            raise ValueError("heartbeat_s must be 0 (none) or a positive number of seconds")


HEAVY_DUTY_MASS_KG = 3500.0
"""Test mass (kg) above which ``fit``'s default speed-trace model takes a heavy vehicle's priors:
the upper limit of GTR 15's light-duty scope (vehicles of 40 CFR 1037 and rigid trucks above it)."""

AUTO_HIERARCHICAL_MIN_RUNS = 4
"""``--pooling auto`` is hierarchical from this many runs (two pairs) on: with one pair the
run-to-run spreads are informed by two runs only (their posterior is their prior) and the
hierarchical fit failed its gates first time on thesis cases 9, 14 and 15 (divergences, R-hat;
benchmarks/records/gates/gate_rate_hierarchical_one_pair.csv, docs/calibration.md)."""
AUTO_HIERARCHICAL_MAX_RUNS = 24
"""``--pooling auto`` is hierarchical up to this many runs (12 pairs: the calibration study's
range) and pooled above: the hierarchical fit of 36 runs ran for more than 8 minutes on a
2-core machine against 95 s pooled (docs/calibration.md, benchmarks/cold_start.py)."""

SHARED_PAD_SIZES_PER_OCTAVE = 8
"""Run lengths per doubling that campaigns are padded to when programs are shared (below)."""

PAD_SIZES_PER_OCTAVE = SHARED_PAD_SIZES_PER_OCTAVE if share_programs() else 0
"""With ``BAYES_ROADLOAD_SHARE_PROGRAMS=1`` (:mod:`bayes_roadload._jax`) a campaign's runs are
padded (masked samples) to the next of :data:`SHARED_PAD_SIZES_PER_OCTAVE` lengths per doubling
(:func:`~bayes_roadload.physics.integrate.bucket_length`: 493 and 498 samples both to 512), so
that campaigns of the same number of runs and nearly the same length share compiled programs,
at less than 1/8 (about 6 % on average) more likelihood work.  0 (the default): runs are padded
to the longest run only."""

LSQ_PAD_SIZES_PER_OCTAVE = 8
"""The least-squares fit pads its runs to the next of this many lengths per doubling (less than
1/8 more samples; :func:`~bayes_roadload.inference.lsq._lsq_batch`) whatever
``BAYES_ROADLOAD_SHARE_PROGRAMS`` says: its residual and Jacobian take the data as arguments,
so same-shaped campaigns then share their compilation (padded samples are masked: the
estimates of a one-pair campaign padded from 493 to 512 samples agreed to 1e-13)."""

LSQ_START_MAX_JACOBIAN_BYTES = 512e6
"""Largest dense Jacobian (8 bytes x padded samples x (free coefficients + runs)) for which the
Bayesian fits' least-squares start fits every run's initial speed jointly with the
coefficients (``LsqSettings(initial_speed="fitted")``); above it the start keeps the measured
first speeds and fits the coefficients alone (:func:`bayes_roadload.inference.nuts.
start_lsq_settings`).  The fitted speeds' Jacobian grows as the square of the campaign: 385 MB
at 162 pairs (the fit peaked at 4.7 GB), 3.6 GB at 500 pairs, where its forward-mode
evaluation took the process past 23 GB in under a minute and the system killed it."""

PARALLEL_CHAIN_GROWTH_BYTES = 27.0
"""Resident memory that numpyro's parallel chains (one XLA device per chain) gain per
observation (:attr:`~bayes_roadload.inference.problem.Problem.n_observations`) per iteration of
each chain, held until the sampler's program ends: 1.3 MB per chain iteration at 54 pairs
(48,769 samples), measured by ``benchmarks/memory_timeline.py`` and the scaling study
(docs/performance.md, section *Memory*).  Sequential chains do not grow."""

PARALLEL_CHAIN_MEMORY_FRACTION = 0.25
"""Parallel chains are used while their projected growth (:data:`PARALLEL_CHAIN_GROWTH_BYTES` x
observations x chains x iterations) stays within this fraction of the machine's memory; above
it the chains run one after the other (:func:`bayes_roadload.inference.nuts.chain_method`):
about 1.7x the sampling time, memory flat.  With the defaults on 24 GB, from about 90 pairs of
450-sample runs."""

DENSE_MASS_MAX_DIM = 20
"""Largest number of unconstrained dimensions for which ``mass_matrix="auto"`` adapts a dense
mass matrix (numpyro's first warm-up window has 25 draws); above it ``"auto"`` adapts a diagonal
one for a hierarchical fit and keeps the Laplace whitening as the metric (``"identity"``) for the
others."""


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
    "sigma_mps": 0.1,          # half-normal scale of the speed measurement noise, per run (spin-downs)
    "sigma_speed_mean_mps": 0.05,  # mean of the Gamma(2) prior of a speed trace's noise, per run
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
MAX_BEYOND_SUPPORT_SHARE = 1e-3
"""A fit is sampled in its problem's alternative coordinates from the start when this share or
more of its MAP's Laplace approximation maps beyond a coefficient's prior support in the sampled
ones (:meth:`bayes_roadload.inference.problem.Problem.beyond_support`): there the potential jumps
to infinity, and NUTS diverges whatever its step (the eco-car GNSS traces: 28-88 divergences in
2000 draws at target acceptance 0.95 and 0.99 in the tyre-lag model's apparent coefficients,
none with A_D, B_D, C_D0 sampled directly)."""
SPEED_NOISE_FLOOR_MPS = 1e-3
"""m/s: the speed noise of the likelihood is sqrt(sigma_mps^2 + floor^2).  A logged speed is
never exact: a 0.01 km/h resolution alone is 0.0008 m/s of quantisation noise (resolution /
sqrt 12).  Without the floor a noise-free or finely resolved trace drives sigma_mps towards 0,
where the likelihood's curvature in log sigma changes by orders of magnitude (a funnel: hundreds
of divergences on the thesis' noise-free cases 7-13); with it the likelihood is flat there and
sigma_mps follows its prior."""
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


# Steady-state torque tests (bayes_roadload.data.steady, inference.steady)
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

# MAP + Laplace fits of studies (bayes_roadload.inference.laplace)
LAPLACE_DRAWS = 2000
"""Draws per MAP + Laplace fit (proposals of the importance-sampling correction)."""

LAPLACE_PROPOSAL_DF = 5
"""Degrees of freedom of the multivariate-t proposal around the MAP (heavier tails than the
Gaussian, so that the importance weights of a right-skewed posterior stay bounded)."""

LAPLACE_PROPOSAL_FAMILY = "t"
"""Family of the importance-sampling proposal: "t" (multivariate t, ``LAPLACE_PROPOSAL_DF``) or
"normal" (``benchmarks/laplace_proposals.py`` compares them against NUTS)."""

LAPLACE_PROPOSAL_INFLATION = (1.5, 2.0)
"""Scale factors of the proposal's covariance tried in turn while the Pareto k is above
``LAPLACE_GOOD_PARETO_K`` (the best proposal is kept).  The posterior is wider than the Laplace
approximation (the spreads' right tail; on one pair, pooled, the coefficients' posterior sd is
~2x the Laplace sd: k 0.81 at 1.0, 0.63 at 2.0), so the Laplace scale itself is not tried:
in ``benchmarks/laplace_proposals.py``'s records the sequence 1.0/1.5/2.0 kept 1.0 in 1 of 26
refits at 2-12 pairs, and 1.5/2.0 failed the k gate in 0 of 14 tyre-lag refits at 6 and 12
pairs (1.0/1.5/2.0: 3 of 14) with 3000 posterior evaluations on average against 5000-5700
(docs/planning.md section 9; there also: both give 6-pair tyre-lag intervals ~0.85 of NUTS')."""

LAPLACE_PROPOSAL_COMBINE = "sequential"
"""How the proposals of ``LAPLACE_PROPOSAL_INFLATION`` are used: "sequential" (in turn while the
Pareto k is above ``LAPLACE_GOOD_PARETO_K``, the best kept) or "mixture" (one set of draws of
their equal-weight mixture; ``laplace._mixture_draws``)."""

LAPLACE_GOOD_PARETO_K = 0.5
"""Pareto k below which the first proposal is accepted without trying wider ones."""

LAPLACE_MAX_PARETO_K = 0.7
"""A Laplace fit whose importance weights have a Pareto k above this fails its gate (PSIS,
Vehtari et al. 2024: the corrected estimates are then unreliable)."""


# Test planning (bayes_roadload.analysis.planning, the simulator and the plan command)
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

PLAN_STEPS = 4
"""`plan` simulates a size's campaigns in this many equal steps (10 at a time of the default 40):
after each step a size where every target's assurance is decided -- its Wilson 95 % interval
excludes the required assurance (:func:`~bayes_roadload.analysis.planning.undecided_sizes`) --
gets no more; a size far from a target is then settled by its first 10 refits."""

PLAN_SMALL_SIZE_CAVEAT_PAIRS = 3
"""`plan` warns when a hierarchical plan recommends this many pairs or fewer: there the Laplace
refits' intervals are narrower than NUTS' (median 0.75 of NUTS' half-width at 2 pairs,
docs/planning.md sections 3 and 9), so the answer is optimistic."""


# Sim-to-real diagnosis (bayes_roadload.analysis.diagnose, diagnose_intervals)
@dataclass(frozen=True)
class DiagnosisConfig:
    """Thresholds of the sim-to-real diagnosis.

    support_delta_elpd : a candidate is *supported* when adding it raises the estimated
        expected log predictive density (gain in maximised log likelihood minus the parameters
        it adds, Akaike) by at least this much (nats): odds of e^5 ~ 150 to 1.  For one added
        parameter under no effect the gain is chi^2_1 / 2 - 1, so a single null candidate
        passes with probability P(chi^2_1 > 12) = 5e-4; 14 candidates ~0.7 %.
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
    min_rival_share : Vuong's test is asked only against a rival whose delta_elpd is at least
        this share of the best's.  A rival below it explains too little of the gap to be
        another explanation of it: to a best of 10 nats, a rival of +0.5 and one of -0.5 are
        alike, and only the first used to stop the claim.  Noticed on the confirmatory seeds of
        the rules 4fe5e3a4 (cup-lag campaigns 801, 802, 804 at 6 pairs, held back by rivals at
        0.16-0.19 of the best's gain; those seeds are design seeds since) and set at one
        quarter on that rules' design seeds (101-105, nulls 2000-2019; docs/sim_to_real.md):
        of their campaigns held back as not distinguishable, the one whose rivals all sat
        below a quarter was a cup-lag campaign ranked first by 15.5 nats against 2.0 and 0.8;
        every other, the held-back null included, had a rival at 0.55 of the best's gain or
        more.
    min_input_lag1 : a candidate whose signature reads a logged channel's fluctuations
        (``resolved_inputs`` in the library: the yaw term's scale) is identifiable here only when
        that reading resolves them: the lag-1 autocorrelation of its deviation from a 20 s
        moving average (:func:`bayes_roadload.analysis.gap.input_resolution`) reaches this
        value.  Below it most of the fluctuation changes from one sample to the next (a low
        logging rate in gusty air): each sample then stands for a step's yaw drag it does not
        measure, and the yaw term misfits as if the vane's factor were off.  Set at one half on
        the independent design's seen seeds (docs/sim_to_real.md): the three null campaigns
        that claimed a vane factor read 0.20-0.36 (1-2 Hz), the 42 other nulls and yaw-term
        arms inspected 0.49-0.98, the vane-calibration arm itself 0.59-0.96.
    max_refit_effects : leading supported candidates refitted together (forward selection).
    gauss_newton_steps : re-linearisations of the combined refit (nonlinear check).
    """

    support_delta_elpd: float = 5.0
    min_contraction: float = 0.5
    ambiguity_margin: float = 2.0
    min_distinct_share: float = 0.1
    min_vuong_z: float = 2.0
    min_rival_share: float = 0.25
    min_input_lag1: float = 0.5
    max_refit_effects: int = 3
    gauss_newton_steps: int = 2


DEFAULT_DIAGNOSIS = DiagnosisConfig()
