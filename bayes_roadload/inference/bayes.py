"""numpyro models of a coastdown campaign: all runs fitted jointly.

The drag model, which parameters are free, fixed or given priors, come from a model variant
(``models/*.toml``, :mod:`.spec`).  Two poolings:

``pooled``
    One set of coefficients (AD, BD, CD0, KD, and At, Bt, Ct when the driveline is modelled)
    for every run.
``hierarchical``
    Run-level AD, BD, CD0 (those of them that are free) around population means, with
    population spreads ``tau_AD, tau_BD, tau_CD0`` in each parameter's own units: the thesis'
    "system noise" and its test-to-test spread (table 8.3).  ``AD_run = AD + delta_AD,r``
    with ``delta_r ~ N(0, diag(tau^2))``.  The run effects are integrated out instead of
    sampled: a run's speed trace responds to its small deviations through the sensitivities
    ``J_r = d v_r / d(AD, BD, CD0)`` at the run's own reference coefficients ``theta + d_r``
    (first order: ``v_r(theta + delta_r) = v_r(theta + d_r) + J_r (delta_r - d_r)``), so
    ``delta_r`` is Gaussian given
    everything else and its integral is exact (:func:`~bayes_roadload.physics.residuals.
    local_level_loglik_effects`).  NUTS then samples the population parameters and spreads
    only, with the geometry of the pooled model: the funnel between tau and the run-level
    coefficients that made centred and non-centred sampling of 3 x R extra unknowns
    impractically slow is gone.  ``AD_run`` etc. are drawn afterwards from their exact
    conditional posterior given each draw (:func:`draw_run_effects`).  The references are
    found by one re-linearisation (:func:`~bayes_roadload.inference.nuts.prepare_problem`): first
    ``d_r = 0`` around the joint least-squares fit, then ``d_r`` = the run effects'
    conditional means at the MAP (:func:`run_effect_means`), so the expansion error is second
    order in a run's posterior uncertainty, not in its offset from the mean (measured: with
    8 % offsets in AD expanded about the mean, run-level AD z-scores spread with sd ~2).

Every run has its own initial speed ``v0_mps`` and speed noise ``sigma_mps``.  The residual
between measured and integrated speed is white measurement noise plus an integrated
(random-walk) error ``q_mps_per_sqrt_s`` shared by the runs: the sensor noise on the measured
inputs (airspeed, yaw, driveline force) and unmodelled forces are integrated by the equation of
motion, so a likelihood with independent residuals gives intervals that are too narrow
(:mod:`bayes_roadload.physics.residuals`).  ``noise="reverting"`` lets that error revert
through the model's own speed-dependent forces (:func:`_residuals_and_reversion`: the
linearised equation of motion, since the truth's rolling and driveline losses follow the true
speed and the model's its own); ``noise="white"`` drops the integrated part;
``robust=True`` scores the innovations with a Student-t (``student_df``).

Priors of the coefficients are those of the model file (physical units); a free parameter
without one gets a wide normal around its default (``10 x`` its typical scale).  Nuisance
priors (:data:`bayes_roadload.config.NOISE_PRIORS`, ``TAU_PRIOR_SCALES``): ``sigma_mps``
Gamma(2) with mean 0.05 m/s (vanishes at 0), the likelihood's speed noise being
sqrt(sigma_mps^2 + 0.001^2) (``config.SPEED_NOISE_FLOOR_MPS``: no logged speed is exact, and
the floor keeps noise-free traces out of a funnel in log sigma); ``v0_mps`` normal(first sample, 0.5 m/s); ``q_mps_per_sqrt_s`` Gamma(2) with
mean 0.005 m/s/sqrt(s) (vanishes at 0: inputs are never noise-free, and a boundary-avoiding
prior removes the funnel at q -> 0, Chung et al. 2013); ``tau_*`` Gamma(2) with means 10 %,
25 %, 5 % of typical AD, BD, CD0 (likewise boundary-avoiding); ``student_df`` Gamma(2, 0.1);
``airspeed_calibration_sd`` Gamma(2) with mean 0.01 (below).

Speed only: a latent wind per pair
----------------------------------
Without an anemometer (GNSS or CAN speed) a model file with ``air = "wind"`` and
``head_wind_mps`` free (``models/speed_only_wind.toml``) gets one along-track wind per
opposite-direction pair, ``head_wind_mps[k]`` (prior from the file), met as a head wind by the
pair's run of direction +1 and as a tail wind by the other (:func:`latent_wind_pairs`,
:func:`free_parameters`).  The pairing identifies it: the wind's force (about rho C_D A v w)
changes sign between the two runs while the road load does not.  A run without a partner gets a
wind of its own, identified only through the shape of its trace and the prior.

Anemometer calibration (thesis section 4.7.3)
---------------------------------------------
When a model file frees ``airspeed_factor`` (true airspeed = factor x reading,
``models/*_calibrated.toml``) the speed traces alone hardly identify it: the aerodynamic force
goes as C_D0 (factor x reading)^2, so C_D0 and factor^2 trade (a 1 % error in the factor is a
2 % error in C_D0 and K_D, thesis 6.6).  The model then adds the thesis' track calibration from
the opposite-direction pairs (the campaign's ``pair`` column; runs without a partner contribute
nothing): for pair k the ratio :func:`airspeed_pair_ratios`

    r_k = [mean_+(v) + mean_-(v)] / [mean_+(a cos(yaw_factor psi)) + mean_-(a cos(yaw_factor psi))]

(``v`` ground speed, ``a`` airspeed reading, ``psi`` yaw reading, ``mean_+/-`` over each run's
samples) is observed as ``r_k ~ Normal(airspeed_factor, airspeed_calibration_sd)``.  The along-
track component of the relative air is v + d w_a (d the direction, w_a the along-track wind),
so the along-track wind cancels between the directions and r_k estimates the factor; the
turbulence that does not average out over a run makes the scatter ``airspeed_calibration_sd``,
a nuisance with a Gamma(2) prior of mean ``config.NOISE_PRIORS["airspeed_calibration_sd"]``
(0.01: measured 0.0078 per pair on simulated campaigns at 2 m/s head and cross wind, and the
thesis' table 4.1 spread of 0.0063 over groups of 3 pairs is ~0.011 per pair; with few pairs the
prior matters, and vanishing at 0 it leaves no funnel there).  Estimated with the coefficients,
the posterior of the factor and C_D0 carries the calibration's uncertainty.  Measured over 100
simulated pairs (25 seeds x 4 pairs, 2 m/s head and cross wind with Dryden turbulence),
r_k / factor: 1.0004 +- 0.0008 (standard error) on the clean campaign of ``tests/conftest.py``,
0.9987 +- 0.0008 on case 15 (cup and vane dynamics: the cup lags the decelerating airspeed and
reads high).  Two alternatives are biased, and were not taken: the plain ratio of mean ground
speed to mean airspeed reading (the thesis' formula, whose mean yaw cancels on the track) reads
v_r = sqrt((v + d w_a)^2 + w_c^2) > v + d w_a under cross wind: 0.9866 (clean), 0.9850 (case
15); and means pooled over the pair's samples weight the longer (tail-wind) run more, so the
along-track wind no longer cancels: 1.0136, 1.0119.  When
``yaw_factor`` is free too its draw enters the cosine.  Robust (Student-t) noise applies to
the speed innovations only; the calibration stays Gaussian.  Hierarchical pooling keeps one
factor for every run (it is the instrument's, not the run's).
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist

from .. import config
from .. import thesis
from ..data.campaign import Campaign
from ..physics.integrate import (
    RunBatch,
    integrate_batch,
    integrate_batch_forward_sensitivity,
    lagged_speed_drop,
    reversion_rate,
)
from ..physics.model import DragModel
from ..physics.residuals import (
    local_level_effects_posterior,
    local_level_loglik,
    local_level_loglik_batch,
    local_level_loglik_effects,
    reversion_factors,
    reverting_loglik_batch,
)
from .problem import shifted_constant, road_load_draws, road_load_truth
from .spec import ModelSpec, Prior, load_model_spec

POOLINGS = ("pooled", "hierarchical")
NOISE_SITES = ("q_mps_per_sqrt_s", "student_df", "sigma_driveline_n", "airspeed_calibration_sd")
"""The nuisance sites besides the per-run ``sigma_mps`` that a speed-trace problem may sample."""
NOISE_MODELS = ("integrated", "white", "reverting")
"""Speed-residual likelihoods: white noise plus an integrated error that is a random walk
(``integrated``, the default), that reverts to zero through the model's speed-dependent forces
(``reverting``), or white noise alone."""
HIERARCHICAL_PARAMETERS = ("AD", "BD", "CD0")
"""Coefficients that vary from run to run in the hierarchical model (when free)."""


@dataclass(frozen=True, eq=False)
class FitProblem:
    """Everything a Bayesian fit of one campaign needs, resolved once.

    Attributes
    ----------
    spec : the model variant.
    model : the drag model built for this campaign.
    fixed : values of every parameter that is not free (SI).
    free : names of the free parameters.
    priors : free parameter -> prior (physical units).
    batch : the campaign's runs, padded.
    run_ids : run ids in batch order.
    pooling, noise, robust : see the module docstring.
    mass_kg, frontal_area_m2 : the vehicle (for the derived road load).
    driveline_curve : (c2, c1, c0) of a measured driveline loss against speed (zeros if none).
    initial : starting values of the free parameters (SI).
    gradients : "forward" differentiates the ODE by forward sensitivities (fast reverse-mode
        gradients for NUTS, :func:`~bayes_roadload.physics.integrate_batch_forward_sensitivity`);
        "reverse" by reverse mode through the scan (needed for Hessians, used by the MAP).
    run_jacobian : hierarchical only: [R, N, k] sensitivities of each run's speed to the k
        varying coefficients, at each run's reference coefficients (:func:`linearise_run_effects`).
    run_offsets : hierarchical only: [R, k] each run's reference offset from the population
        values (zero at first, then the run effects' conditional means at the MAP).
    calibration_pairs : ((i, j), ...) batch indices of the opposite-direction pairs whose
        airspeed ratios calibrate a free ``airspeed_factor`` (:func:`airspeed_pair_ratios`);
        empty when the factor is fixed.  ``initial`` then also holds a start for
        ``airspeed_calibration_sd``.
    wind_pair_index : speed-only campaigns with ``air = "wind"`` and ``head_wind_mps`` free:
        [R] index of each run's opposite-direction pair (:func:`latent_wind_pairs`); the
        along-track wind of pair k, ``head_wind_mps[k]``, is a head wind for the pair's run of
        direction +1 and a tail wind for the other.  None otherwise.
    apparent : (c, b, kappa) of :func:`lag_line` when the tyre-lag gain, A_D, B_D and C_D0 are
        all free: NUTS and the MAP then sample the apparent coefficients ``AD_apparent``,
        ``BD_apparent``, ``CD0_apparent`` instead (:func:`apparent_coefficients`); None
        otherwise.
    driveline_channel : the driveline loss is the polynomial A_t + B_t v + C_t v^2 and the
        campaign logs ``driveline_force_n``: the logged force is fitted too
        (:func:`driveline_log_likelihood`), with its noise ``sigma_driveline_n``.
    """

    spec: ModelSpec
    model: DragModel
    fixed: dict[str, float]
    free: tuple[str, ...]
    priors: dict[str, Prior]
    batch: RunBatch
    run_ids: tuple
    pooling: str = "pooled"
    noise: str = "integrated"
    robust: bool = False
    mass_kg: float = thesis.THESIS_VEHICLE["mass_kg"]
    frontal_area_m2: float = thesis.THESIS_VEHICLE["frontal_area_m2"]
    driveline_curve: tuple[float, float, float] = (0.0, 0.0, 0.0)
    initial: dict[str, Any] = field(default_factory=dict)
    gradients: str = "forward"
    run_jacobian: Any = None
    run_offsets: Any = None
    calibration_pairs: tuple[tuple[int, int], ...] = ()
    driveline_channel: bool = False
    wind_pair_index: Any = None
    apparent: tuple[float, float, float] | None = None

    @property
    def latent_wind(self) -> bool:
        """Speed only, no anemometer: a latent along-track wind per opposite-direction pair
        (``head_wind_mps`` [pairs], :func:`latent_wind_pairs`)."""
        return self.wind_pair_index is not None

    @property
    def n_runs(self) -> int:
        return len(self.run_ids)

    @property
    def scale_sites(self) -> tuple[str, ...]:
        """The sites that scale the likelihood rather than place it: the run-effect spreads
        ``tau_*``, the speed noise and the other nuisance sites (:data:`NOISE_SITES`: the
        integrated noise's intensity, the Student-t degrees of freedom, the driveline channel's
        noise, the airspeed calibration's scatter; a site the problem does not sample holds
        nothing).  The Type B Newton step holds them at the MAP
        (:meth:`~bayes_roadload.inference.shift.SharedPotential.newton_step`)."""
        return tuple(f"tau_{n}" for n in self.varying) + ("sigma_mps",) + NOISE_SITES

    @property
    def integrated_noise(self) -> bool:
        """The residual has an integrated error of intensity ``q_mps_per_sqrt_s``."""
        return self.noise in ("integrated", "reverting")

    kind = "traces"

    @property
    def numpyro_model(self):
        return coastdown_model

    @property
    def hessian_runs(self) -> int:
        return self.n_runs

    @property
    def n_observations(self) -> int:
        """Padded samples of every run (``batch.mask``)."""
        return int(np.size(self.batch.mask))

    def settings(self) -> dict[str, Any]:
        """pooling, noise, robust; with undriven wheels (eq. 2.16) their known ``Au``, ``Bu``."""
        out: dict[str, Any] = {"pooling": self.pooling, "noise": self.noise, "robust": self.robust}
        if "undriven_wheels" in self.spec.terms:
            out["undriven"] = {k: self.fixed[k] for k in ("Au", "Bu")}
        return out

    def shift_constant(self, name: str, delta: float) -> "FitProblem | None":
        """The problem with a fixed constant moved (:meth:`~.problem.Problem.shift_constant`);
        a problem sampled in its apparent coefficients gets the line of its new lag time
        constant (:func:`lag_line`), so that its coordinates stay those of :attr:`apparent`."""
        out = shifted_constant(self, name, delta)
        if out is not None and self.apparent is not None and name == self.model.lag_time_constant:
            out = dataclasses.replace(out, apparent=lag_line(self.batch, out.fixed[name]))
        return out

    def alternative_coordinates(self, values: dict[str, Any]) -> tuple["FitProblem", dict[str, Any], str] | None:
        """A problem sampled in its apparent coefficients (:attr:`apparent`) has the direct
        coordinates A_D, B_D, C_D0 as its alternative (the same posterior: the densities differ
        by the Jacobian of :func:`coefficients_from_apparent`); ``values`` lose the apparent
        sites.  None for a problem sampled directly."""
        if self.apparent is None:
            return None
        direct = dataclasses.replace(self, apparent=None)
        start = {k: v for k, v in values.items() if k not in APPARENT_SITES.values()}
        return direct, start, "A_D, B_D, C_D0 sampled directly instead of the apparent coefficients"

    def beyond_support(self, z: dict[str, Any], cov: np.ndarray) -> float:
        """The share of :data:`BEYOND_SUPPORT_DRAWS` draws of the Laplace approximation at which
        A_D, B_D or C_D0, derived from the apparent coefficients and the lag gain
        (:func:`coefficients_from_apparent`), leaves its prior's support; 0 for a problem
        sampled directly (its transforms map into the supports).  The apparent sites carry the
        coefficients' supports, but C_D0 = CD0' - kappa B_D G_T does not stay in C_D0's where
        kappa = b M g / (rho A / 2) is large and C_D0 weakly fixed: on a 78 kg eco-car (kappa
        2433) with speed traces only, the wall at C_D0 = 0 lay inside the sampled space and the
        first attempt diverged 28-88 times in 2000 draws at any target acceptance."""
        if self.apparent is None:
            return 0.0
        from numpyro.distributions.transforms import biject_to

        from .nuts import _coordinate_names  # nuts imports this module

        sites = [*APPARENT_SITES.values(), LAG_GAIN]
        names = _coordinate_names(z)
        if not set(sites) <= set(names):  # a site per run (hierarchical): names carry an index
            return 0.0
        at = [names.index(s) for s in sites]
        mean = np.array([float(np.asarray(z[s])) for s in sites])
        draws = np.random.default_rng(0).multivariate_normal(mean, np.asarray(cov)[np.ix_(at, at)],
                                                             BEYOND_SUPPORT_DRAWS, method="cholesky")
        priors = {n: self.priors[n].to_numpyro() for n in APPARENT_SITES}
        apparent = [np.asarray(biject_to(priors[n].support)(jnp.asarray(draws[:, j])))
                    for j, n in enumerate(APPARENT_SITES)]
        gain = np.asarray(biject_to(self.priors[LAG_GAIN].to_numpyro().support)(jnp.asarray(draws[:, 3])))
        *values, _ = coefficients_from_apparent(*apparent, gain, self.apparent)
        outside = np.zeros(BEYOND_SUPPORT_DRAWS, bool)
        for name, value in zip(APPARENT_SITES, values):
            outside |= ~np.asarray(priors[name].support(jnp.asarray(value)), bool)
        return float(outside.mean())

    def postprocess(self, samples: dict[str, np.ndarray], seed: int) -> dict[str, np.ndarray]:
        """The run-level coefficients of a hierarchical fit (:func:`draw_run_effects`)."""
        return draw_run_effects(self, samples, seed=seed)

    def derived(self, samples: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Road load at reference conditions (:func:`~.problem.road_load_draws`; the hierarchical
        model's population-mean coefficients), with the measured driveline loss."""
        return road_load_draws(self, samples, driveline_curve=self.driveline_curve)

    def truth_values(self, truth: dict | None) -> dict[str, float]:
        return dict(truth or {}, **road_load_truth(self, truth, driveline_curve=self.driveline_curve))

    @property
    def calibrated(self) -> bool:
        """The free ``airspeed_factor`` is calibrated by paired-run airspeed ratios."""
        return "airspeed_factor" in self.free and len(self.calibration_pairs) > 0

    @property
    def varying(self) -> tuple[str, ...]:
        """Free parameters that vary by run (hierarchical pooling)."""
        if self.pooling != "hierarchical":
            return ()
        return tuple(p for p in HIERARCHICAL_PARAMETERS if p in self.free)


def default_prior(name: str, model: DragModel) -> Prior:
    """A wide normal around the model default, for a free parameter without a prior."""
    scale = 10.0 * config.PARAMETER_SCALES.get(name, 1.0)
    return Prior(dist="normal", loc=float(model.defaults.get(name, 0.0)), scale=scale)


def measured_driveline_curve(campaign: Campaign) -> tuple[float, float, float]:
    """Least-squares quadratic (c2, c1, c0) of the logged driveline force against speed."""
    if not campaign.has_driveline:
        return (0.0, 0.0, 0.0)
    v = campaign.runs["speed_mps"].to_numpy(float)
    f = campaign.runs["driveline_force_n"].to_numpy(float)
    c2, c1, c0 = np.polyfit(v, f, 2)
    return (float(c2), float(c1), float(c0))


def calibration_pairs(campaign: Campaign, run_ids=None) -> tuple[tuple[int, int], ...]:
    """Opposite-direction pairs for the airspeed calibration, as indices into ``run_ids``.

    Pairs come from the campaign's ``pair`` column (two runs sharing a pair id); without that
    column there are none (consecutive runs are not assumed to be opposite).  When the
    ``direction`` column is logged a pair whose two runs do not have opposite directions is
    left out with a warning (its wind would not cancel).  A run without a partner is in no pair.

    Parameters
    ----------
    campaign : the campaign.
    run_ids : run ids in batch order (default: ``campaign.run_ids``, the order of
        :meth:`~bayes_roadload.data.Campaign.to_batch`).

    Returns
    -------
    tuple of (int, int)
        Batch indices of the two runs of each pair.
    """
    if "pair" not in campaign.runs:
        return ()
    index = {r: i for i, r in enumerate(campaign.run_ids if run_ids is None else run_ids)}
    directions = campaign.directions()
    pairs = []
    for a, b in campaign.pairs():
        if a not in index or b not in index:
            continue
        if "direction" in campaign.runs and directions[a] == directions[b]:
            warnings.warn(f"runs {a!r} and {b!r} share a pair id but not opposite directions: left out of "
                          "the airspeed calibration", RuntimeWarning, stacklevel=2)
            continue
        pairs.append((index[a], index[b]))
    return tuple(pairs)


def airspeed_pair_ratios(batch: RunBatch, pairs, yaw_factor: Any = 1.0) -> jnp.ndarray:
    """[K] calibration ratios of the airspeed factor, one per opposite-direction pair.

    ``r_k = [mean_i(v) + mean_j(v)] / [mean_i(a cos(yaw_factor psi)) + mean_j(a cos(yaw_factor psi))]``
    for the pair's runs i, j: ground speed ``v`` (``speed_mps``), airspeed reading ``a``
    (``airspeed_mps``), yaw reading ``psi`` (``yaw_rad``), means over each run's real samples.
    True airspeed times cos(true yaw) is the along-track relative air v + d w_a, so with
    true = factor x reading the along-track wind (+ for one run, - for the other) cancels in
    the sum and r_k estimates the factor (thesis section 4.7.3, with the cosine: see the
    module docstring for why neither the plain airspeed ratio nor sample-pooled means).

    Parameters
    ----------
    batch : the padded runs (:meth:`~bayes_roadload.data.Campaign.to_batch`).
    pairs : sequence of (i, j) batch indices (:func:`calibration_pairs`).
    yaw_factor : true yaw = yaw_factor x yaw reading (a number or a traced value).

    Returns
    -------
    jnp.ndarray
        [K] ratios (dimensionless); empty for no pairs.
    """
    idx = jnp.asarray(np.asarray(pairs, dtype=int).reshape(-1, 2))
    mask = jnp.asarray(batch.mask, float)
    n = mask.sum(axis=1)
    along = jnp.asarray(batch.airspeed_mps) * jnp.cos(yaw_factor * jnp.asarray(batch.yaw_rad))
    mean_v = (jnp.asarray(batch.speed_mps) * mask).sum(axis=1) / n
    mean_a = (along * mask).sum(axis=1) / n
    return mean_v[idx].sum(axis=1) / mean_a[idx].sum(axis=1)


def latent_wind_pairs(campaign: Campaign, run_ids) -> np.ndarray:
    """[R] pair index of each run for the latent along-track wind: the campaign's pairs
    (:meth:`~bayes_roadload.data.Campaign.pairs`), a run without a partner on its own."""
    index = {r: i for i, r in enumerate(run_ids)}
    out = np.full(len(run_ids), -1)
    k = 0
    for pair in campaign.pairs():
        if all(r in index for r in pair):
            out[[index[r] for r in pair]] = k
            k += 1
    for i in np.flatnonzero(out < 0):
        out[i] = k
        k += 1
    return out


LAG_GAIN = "tyre_lag_gain_per_mps"
BEYOND_SUPPORT_DRAWS = 4000
"""Draws of the Laplace approximation by which :meth:`FitProblem.beyond_support` measures the
share behind a support's wall (a share of 0.1 % is then 4 draws)."""
APPARENT_SITES = {"AD": "AD_apparent", "BD": "BD_apparent", "CD0": "CD0_apparent"}
"""Sample sites of the apparent coefficients (:func:`apparent_coefficients`)."""


def lag_line(batch: RunBatch, time_constant_s: float) -> tuple[float, float, float]:
    """(c, b, kappa): the least-squares line ``L ~ c - b v`` through every real sample of the
    campaign's lagged speed drop L (:func:`~bayes_roadload.physics.integrate.lagged_speed_drop`
    of the logged speed, time constant ``time_constant_s``) against the logged speed v, and
    ``kappa = b M g / (rho A / 2)`` (mean test weight and air density of the campaign): the
    drag coefficient that a rolling term ``B_D G_T b v^2`` per unit weight adds."""
    lag = np.asarray(jax.vmap(lagged_speed_drop, in_axes=(0, 0, None))(
        jnp.asarray(batch.time_s), jnp.asarray(batch.speed_mps), time_constant_s))
    mask = np.asarray(batch.mask, bool)
    v, y = np.asarray(batch.speed_mps)[mask], lag[mask]
    slope, intercept = np.polyfit(v, y, 1)
    weight = float(np.mean(np.asarray(batch.mass_kg, float))) * config.GRAVITY_MPS2
    rho = float(np.mean(np.asarray(batch.air_density_kgpm3)[mask]))
    area = float(np.mean(np.asarray(batch.frontal_area_m2, float)))
    return float(intercept), float(-slope), float(-slope * weight / (0.5 * rho * area))


def apparent_coefficients(AD, BD, CD0, gain, line: tuple[float, float, float]):
    """The coefficients a coastdown without the tyre lag would read:
    ``AD' = AD s``, ``BD' = BD s + AD G_T b``, ``CD0' = CD0 + kappa BD G_T``, ``s = 1 - G_T c``.

    With the lagged speed drop close to the line ``L ~ c - b v`` (:func:`lag_line`) the rolling
    loss of :class:`~bayes_roadload.physics.terms.TyreThermalLag` per unit weight,
    ``(A_D + B_D v)(1 - G_T L)``, is ``AD' + BD' v + B_D G_T b v^2``, and its v^2 part is a drag
    coefficient ``kappa B_D G_T``: the speed traces fix AD', BD', CD0' about as well as they fix
    A_D, B_D, C_D0 without the lag and leave G_T to its prior and what the lag's curvature
    tells.  In (A_D, B_D, C_D0, G_T) that weak direction is curved (products of G_T with the
    coefficients); in (AD', BD', CD0', G_T) it is nearly straight.  The map is exact whatever
    the line: it only chooses the coordinates."""
    c, b, kappa = line
    s = 1.0 - gain * c
    return AD * s, BD * s + AD * gain * b, CD0 + kappa * BD * gain


def coefficients_from_apparent(AD_apparent, BD_apparent, CD0_apparent, gain, line: tuple[float, float, float]):
    """The inverse of :func:`apparent_coefficients`: (A_D, B_D, C_D0,
    log |d(AD', BD', CD0') / d(A_D, B_D, C_D0)|), the Jacobian being triangular with
    determinant s^2."""
    c, b, kappa = line
    s = 1.0 - gain * c
    AD = AD_apparent / s
    BD = (BD_apparent - AD * gain * b) / s
    return AD, BD, CD0_apparent - kappa * BD * gain, 2.0 * jnp.log(s)


def with_apparent(problem: FitProblem, values: dict[str, Any]) -> dict[str, Any]:
    """``values`` (constrained, with A_D, B_D, C_D0 and the lag gain) with the apparent sites
    added when the problem samples them (:attr:`FitProblem.apparent`)."""
    if problem.apparent is None:
        return values
    apparent = apparent_coefficients(*(float(values[k]) for k in APPARENT_SITES), float(values[LAG_GAIN]),
                                     problem.apparent)
    return dict(values, **dict(zip(APPARENT_SITES.values(), apparent)))


def build_problem(campaign: Campaign, spec: ModelSpec | str = "four_term", *, pooling: str = "pooled",
                  noise: str = "integrated", robust: bool = False) -> FitProblem:
    """Resolve a model variant against a campaign.

    A free ``airspeed_factor`` needs the measured relative air (refused otherwise, with the
    reason) and is calibrated by the campaign's opposite-direction pairs
    (:func:`calibration_pairs`, module docstring); without any pair a warning says that only
    the coastdown dynamics and the prior then inform it.
    """
    if pooling not in POOLINGS:
        raise ValueError(f"pooling must be one of {POOLINGS}, not {pooling!r}")
    if noise not in NOISE_MODELS:
        raise ValueError(f"noise must be one of {NOISE_MODELS}, not {noise!r}")
    if pooling == "hierarchical" and robust:
        raise ValueError("the hierarchical model integrates the run effects out with a Gaussian likelihood: "
                         "it cannot be combined with robust (Student-t) noise; use --pooling pooled --robust")
    if noise == "reverting" and robust:
        raise ValueError("the reverting residual has a Gaussian likelihood: it cannot be combined with robust "
                         "(Student-t) noise")
    spec = load_model_spec(spec) if isinstance(spec, str) else spec
    if "airspeed_factor" in spec.free and spec.resolve_air(campaign) != "measured":
        raise ValueError(f"model {spec.name!r} frees airspeed_factor (true airspeed = factor x reading), but "
                         f"the relative air resolves to {spec.resolve_air(campaign)!r}: the campaign must log "
                         "airspeed_mps and yaw_rad (and the model file use air = \"auto\" or \"measured\")")
    model, fixed, free = spec.build(campaign)
    priors = {p: spec.priors.get(p) or default_prior(p, model) for p in free}
    batch, run_ids = spec.to_batch(campaign)
    initial = {p: float(spec.initial.get(p, priors[p].center)) for p in free}
    pairs: tuple[tuple[int, int], ...] = ()
    if "airspeed_factor" in free:
        pairs = calibration_pairs(campaign, run_ids)
        if pairs:
            initial["airspeed_calibration_sd"] = config.NOISE_PRIORS["airspeed_calibration_sd"]
        else:
            warnings.warn(f"model {spec.name!r} frees airspeed_factor but the campaign has no opposite-direction "
                          "pairs (`pair` column): no calibration observations; the factor is informed only by "
                          "its prior and the coastdown dynamics, where C_D0 and factor^2 trade", RuntimeWarning,
                          stacklevel=2)
    channel = "driveline_polynomial" in model.term_names and campaign.has_driveline
    if channel:
        initial["sigma_driveline_n"] = config.NOISE_PRIORS["sigma_driveline_n"]
    wind_pairs = None
    if spec.resolve_air(campaign) == "wind" and "head_wind_mps" in free:
        if pooling != "pooled":
            raise ValueError("a latent wind per pair is available with --pooling pooled only")
        wind_pairs = latent_wind_pairs(campaign, run_ids)
        initial["head_wind_mps"] = np.zeros(int(wind_pairs.max()) + 1)
    apparent = None
    if model.lag_time_constant and {*APPARENT_SITES, LAG_GAIN} <= set(free):
        tau = fixed.get(model.lag_time_constant, initial.get(model.lag_time_constant))
        apparent = lag_line(batch, float(tau))
    return FitProblem(spec=spec, model=model, fixed={k: float(v) for k, v in fixed.items()}, free=tuple(free),
                      priors=priors, batch=batch, run_ids=tuple(run_ids), pooling=pooling, noise=noise,
                      robust=robust, mass_kg=campaign.vehicle.mass_kg,
                      frontal_area_m2=campaign.vehicle.frontal_area_m2,
                      driveline_curve=measured_driveline_curve(campaign), initial=initial,
                      calibration_pairs=pairs, driveline_channel=channel, wind_pair_index=wind_pairs,
                      apparent=apparent)


def free_parameters(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> dict[str, jnp.ndarray]:
    """The free drag-model parameters of one draw: shape [] (shared) or [R] (per run: the
    run-level coefficients of a hierarchical draw, when ``sample`` holds them; the latent
    along-track wind of each run's pair, signed by its direction)."""
    out = {n: sample.get(f"{n}_run", sample[n]) if n in problem.varying else sample[n] for n in problem.free}
    if problem.latent_wind:
        out["head_wind_mps"] = (jnp.asarray(problem.batch.direction)
                                * jnp.asarray(sample["head_wind_mps"])[jnp.asarray(problem.wind_pair_index)])
    return out


def run_parameters(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> dict[str, jnp.ndarray]:
    """Every drag-model parameter of one draw (fixed ones included)."""
    params = {k: jnp.asarray(v) for k, v in problem.fixed.items()}
    params.update(free_parameters(problem, sample))
    return params


def integrated_speed(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> jnp.ndarray:
    """[R, N] speed integrated from each run's initial speed for one draw."""
    if problem.gradients == "forward":
        return integrate_batch_forward_sensitivity(problem.model, problem.fixed, free_parameters(problem, sample),
                                                   problem.batch, sample["v0_mps"])
    return integrate_batch(problem.model, run_parameters(problem, sample), problem.batch, sample["v0_mps"])[0]


def speed_residuals(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> jnp.ndarray:
    """[R, N] measured minus integrated speed for one draw."""
    return problem.batch.speed_mps - integrated_speed(problem, sample)


def speed_noise(sample: dict[str, jnp.ndarray]) -> jnp.ndarray:
    """[R] the likelihood's white speed noise: sqrt(sigma_mps^2 + floor^2), the floor
    :data:`bayes_roadload.config.SPEED_NOISE_FLOOR_MPS` (no logged speed is exact)."""
    return jnp.sqrt(sample["sigma_mps"] ** 2 + config.SPEED_NOISE_FLOOR_MPS**2)


def run_log_likelihood(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> jnp.ndarray:
    """[R] log-likelihood of each run's speed trace for one draw (hierarchical: with the run
    effects integrated out, at the population values)."""
    resid, phi = _residuals_and_reversion(problem, sample)
    q = sample.get("q_mps_per_sqrt_s", jnp.zeros(()))
    sigma = speed_noise(sample)
    b = problem.batch
    if phi is not None and not problem.varying:
        return reverting_loglik_batch(resid, b.time_s, b.mask, sigma, q, phi)
    if problem.robust:
        df = sample["student_df"]
        return jax.vmap(lambda r, t, m, s: local_level_loglik(r, t, m, s, q, df))(resid, b.time_s, b.mask, sigma)
    if problem.varying:
        return local_level_loglik_effects(resid, b.time_s, b.mask, sigma, q, _design(problem),
                                          _effect_var(problem, sample), phi)
    return local_level_loglik_batch(resid, b.time_s, b.mask, sigma, q)


def _residuals_and_reversion(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> tuple[jnp.ndarray, Any]:
    """The residuals the likelihood scores ([R, N]; hierarchical: :func:`effect_residuals`)
    and, for ``noise="reverting"``, the factors phi ([R, N],
    :func:`~bayes_roadload.physics.residuals.reversion_factors`) of the integrated error's
    reversion at the rate :func:`~bayes_roadload.physics.integrate.reversion_rate` along the
    model's trajectory (hierarchical: each run's at its reference coefficients); else None."""
    if problem.noise != "reverting":
        return (effect_residuals(problem, sample) if problem.varying else speed_residuals(problem, sample)), None
    response = _offset_response(problem) if problem.varying else 0.0  # first: it names a missing linearisation
    at = _shifted(problem, sample) if problem.varying else sample
    speed = integrated_speed(problem, at)
    return problem.batch.speed_mps - speed + response, reversion_along(problem, at, speed)


def reversion_along(problem: FitProblem, sample: dict[str, jnp.ndarray], speed: jnp.ndarray) -> jnp.ndarray:
    """[R, N] factors phi (:func:`~bayes_roadload.physics.residuals.reversion_factors`) of the
    integrated error's reversion at the rate
    :func:`~bayes_roadload.physics.integrate.reversion_rate` along ``speed``, the trajectory
    of ``sample``'s coefficients."""
    b = problem.batch
    return reversion_factors(b.time_s, b.mask, reversion_rate(problem.model, run_parameters(problem, sample), b, speed))


def _design(problem: FitProblem) -> jnp.ndarray:
    if problem.run_jacobian is None:
        raise ValueError("the hierarchical model needs its run sensitivities: call linearise_run_effects(problem, "
                         "initial_values(problem, campaign)) first (fit_nuts does)")
    return jnp.asarray(problem.run_jacobian)


def _effect_var(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> jnp.ndarray:
    return jnp.stack([sample[f"tau_{n}"] ** 2 for n in problem.varying])


def population_sample(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> dict[str, jnp.ndarray]:
    """``sample`` with the run-level coefficients dropped."""
    return {k: v for k, v in sample.items() if not (k.endswith("_run") and k[:-4] in problem.varying)}


def effect_residuals(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> jnp.ndarray:
    """[R, N] residuals that the run effects delta_r explain linearly in the hierarchical
    model: ``y_r - v_r(theta + d_r) + J_r d_r``, with ``d_r`` the run's reference offset
    (:func:`linearise_run_effects`), so that ``y_r ~ v_r(theta + d_r) + J_r (delta_r - d_r)``:
    the first-order expansion is taken at each run's own coefficients, and its error is
    second order in the run's posterior uncertainty, not in its offset from the mean."""
    response = _offset_response(problem)  # first: it names the missing linearisation
    return speed_residuals(problem, _shifted(problem, sample)) + response


def _offset_response(problem: FitProblem) -> jnp.ndarray:
    """[R, N] J_r d_r: each run's first-order response to its reference offset."""
    return jnp.einsum("rnk,rk->rn", _design(problem), jnp.asarray(problem.run_offsets))


def _shifted(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> dict[str, jnp.ndarray]:
    """``sample`` (population values) with each run's coefficients at its reference offset."""
    sample = population_sample(problem, sample)
    offsets = jnp.asarray(problem.run_offsets)
    shifted = dict(sample)
    for i, name in enumerate(problem.varying):
        shifted[f"{name}_run"] = sample[name] + offsets[:, i]
    return shifted


def run_sensitivities(problem: FitProblem, base: dict[str, Any], v0_mps: Any, batch: RunBatch) -> jnp.ndarray:
    """[R, N, k] sensitivities ``d v_r / d(varying)`` of ``batch``'s speed traces at per-run
    parameter values ``base`` ([R] each) and initial speeds ``v0_mps``, zero on padding (pure
    JAX: :mod:`.laplace` compiles it with the batch as an argument)."""
    def speeds(values):
        return integrate_batch(problem.model, dict(problem.fixed, **values), batch, v0_mps)[0]

    cols = []
    for name in problem.varying:
        tangent = {n: jnp.full(problem.n_runs, 1.0 if n == name else 0.0) for n in base}
        cols.append(jax.jvp(speeds, (base,), (tangent,))[1])
    return jnp.where(jnp.asarray(batch.mask)[..., None], jnp.stack(cols, axis=-1), 0.0)


def run_effect_reference(problem: FitProblem, reference: dict[str, Any], offsets: Any = None) -> tuple[dict, np.ndarray]:
    """Per-run parameter values ``reference + offsets[r]`` ([R] each) of the varying
    coefficients and the offsets [R, k] (zero by default), for :func:`run_sensitivities`."""
    r, k = problem.n_runs, len(problem.varying)
    offsets = np.zeros((r, k)) if offsets is None else np.asarray(offsets, float).reshape(r, k)
    base = {n: jnp.full(r, float(reference[n])) for n in problem.free}
    for i, n in enumerate(problem.varying):
        base[n] = base[n] + offsets[:, i]
    return base, offsets


def linearise_run_effects(problem: FitProblem, reference: dict[str, Any], offsets: Any = None,
                          sensitivities: Callable[..., Any] | None = None) -> FitProblem:
    """The hierarchical ``problem`` with its run sensitivities ``J_r = d v_r / d(varying)``
    evaluated at each run's coefficients ``reference + offsets[r]`` (``reference``:
    constrained values of the free coefficients and ``v0_mps``, e.g.
    :func:`~bayes_roadload.inference.nuts.initial_values`; ``offsets`` [R, k], default zero,
    e.g. :func:`run_effect_means` at a first MAP) by ``sensitivities`` (default
    :func:`run_sensitivities`, same arguments; e.g. a compilation shared by many campaigns).
    A no-op for pooled fits."""
    if not problem.varying:
        return problem
    base, offsets = run_effect_reference(problem, reference, offsets)
    jac = (sensitivities or run_sensitivities)(problem, base, jnp.asarray(reference["v0_mps"], float), problem.batch)
    return dataclasses.replace(problem, run_jacobian=np.asarray(jac), run_offsets=offsets)


def problem_like(problem: FitProblem, campaign: Campaign, reference: dict[str, Any] | None = None,
                 offsets: Any = None, sensitivities: Callable[..., Any] | None = None) -> FitProblem:
    """``campaign``'s problem built as ``problem`` was: the same model variant, pooling, noise,
    likelihood, gradients and sampled coordinates (the same apparent coefficients, or A_D, B_D,
    C_D0 directly: :attr:`FitProblem.apparent`, the line of ``problem`` kept whatever
    ``campaign``'s own would be; the softplus coordinates of its truncated priors,
    ``Prior.softness``), a hierarchical problem's run effects linearised at
    ``reference`` and ``offsets`` when given (:func:`linearise_run_effects`, ``sensitivities``
    as there).  A shifted campaign's problem then differs from ``problem`` in its data only (the
    Type B steps of :mod:`~bayes_roadload.inference.shift`)."""
    out = build_problem(campaign, problem.spec, pooling=problem.pooling, noise=problem.noise, robust=problem.robust)
    priors = {k: dataclasses.replace(v, softness=problem.priors[k].softness) if k in problem.priors else v
              for k, v in out.priors.items()}
    out = dataclasses.replace(out, gradients=problem.gradients, apparent=problem.apparent, priors=priors)
    if not out.varying or reference is None:
        return out
    return linearise_run_effects(out, reference, offsets, sensitivities)


def _effects_posterior(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Conditional posterior mean [R, k] and covariance [R, k, k] of the run effects at one draw."""
    b = problem.batch
    resid, phi = _residuals_and_reversion(problem, sample)
    return local_level_effects_posterior(resid, b.time_s, b.mask, speed_noise(sample),
                                         sample.get("q_mps_per_sqrt_s", jnp.zeros(())), _design(problem),
                                         _effect_var(problem, sample), phi)


def run_effect_means(problem: FitProblem, sample: dict[str, Any]) -> np.ndarray:
    """[R, k] conditional posterior means of the run effects delta_r at one parameter point
    (e.g. the MAP): where to re-linearise each run."""
    return np.asarray(_effects_posterior(problem, {k: jnp.asarray(v) for k, v in sample.items()})[0])


def draw_run_effects(problem: FitProblem, samples: dict[str, np.ndarray], seed: int = 0,
                     batch_size: int = 64) -> dict[str, np.ndarray]:
    """Draws of the run-level coefficients ``{name}_run`` ([chain, draw, run]) from their
    exact conditional posterior given each posterior draw of the hierarchical model (the run
    effects are integrated out while sampling; see the module docstring)."""
    if not problem.varying:
        return {}
    shape = np.shape(samples[problem.free[0]])[:2]
    flat = {k: jnp.asarray(np.reshape(v, (-1,) + np.shape(v)[2:])) for k, v in population_sample(problem, samples).items()}
    keys = jax.random.split(jax.random.PRNGKey(seed), int(np.prod(shape)))

    def one(args):
        sample, key = args
        mean, cov = _effects_posterior(problem, sample)
        k = len(problem.varying)
        chol = jnp.linalg.cholesky(cov + 1e-30 * jnp.eye(k))
        delta = mean + jnp.einsum("rkl,rl->rk", chol, jax.random.normal(key, mean.shape))
        return jnp.stack([sample[n] + delta[:, i] for i, n in enumerate(problem.varying)])

    out = np.asarray(jax.jit(lambda xs: jax.lax.map(one, xs, batch_size=batch_size))((flat, keys)))
    return {f"{n}_run": out[:, i].reshape(shape + (problem.n_runs,)) for i, n in enumerate(problem.varying)}


def driveline_log_likelihood(problem: FitProblem, sample: dict[str, jnp.ndarray], sigma_n) -> jnp.ndarray:
    """Log likelihood of the logged driveline force under the modelled loss: every real sample
    ``F_i ~ Normal(A_t + B_t v_i + C_t v_i^2, sigma_driveline_n)``, v_i the logged speed (its
    0.05 m/s noise moves the loss by ~0.1 N, far below the channel's noise).  Without it the
    driveline polynomial would be identified by the speed trace alone, where A_t trades with
    M g A_D and B_t with M g B_D (the least-squares baseline reports them unidentified)."""
    p = {**problem.fixed, **sample}
    b = problem.batch
    v = b.speed_mps
    loss = p["At"] + p["Bt"] * v + p["Ct"] * v**2
    logp = dist.Normal(loss, sigma_n).log_prob(b.driveline_force_n)
    return jnp.sum(jnp.where(b.mask, logp, 0.0))


def _sample_apparent(problem: FitProblem, sample: dict[str, jnp.ndarray]) -> None:
    """A_D, B_D, C_D0 through the apparent coefficients (:func:`apparent_coefficients`): sites
    ``AD_apparent``, ``BD_apparent``, ``CD0_apparent`` with the supports of the coefficients'
    priors, the coefficients deterministic, and their priors' density with the Jacobian
    ``-log s^2`` as a factor, so that the posterior is that of the model file's priors."""
    priors = {n: problem.priors[n].to_numpyro() for n in APPARENT_SITES}
    raw = [numpyro.sample(site, dist.ImproperUniform(priors[n].support, (), ())) for n, site in APPARENT_SITES.items()]
    *values, log_det = coefficients_from_apparent(*raw, sample[LAG_GAIN], problem.apparent)
    log_prior = 0.0
    for name, value in zip(APPARENT_SITES, values):
        sample[name] = numpyro.deterministic(name, value)
        log_prior = log_prior + priors[name].log_prob(value)
    numpyro.factor("coefficient_prior", log_prior - log_det)


def coastdown_model(problem: FitProblem) -> None:
    """The numpyro model (see the module docstring).  Sample sites use the contract names."""
    r = problem.n_runs
    sample: dict[str, jnp.ndarray] = {}
    for name in problem.free:
        if problem.apparent is not None and name in APPARENT_SITES:
            continue
        if problem.latent_wind and name == "head_wind_mps":
            # one along-track wind per opposite-direction pair (speed only, no anemometer)
            with numpyro.plate("wind_pair", int(np.max(problem.wind_pair_index)) + 1):
                sample[name] = numpyro.sample(name, problem.priors[name].to_numpyro())
            continue
        sample[name] = numpyro.sample(name, problem.priors[name].to_numpyro())
    if problem.apparent is not None:
        _sample_apparent(problem, sample)
    for name in problem.varying:
        # Gamma(2): no mass piling at tau = 0, so the joint mode (the MAP the sampler is
        # whitened at) is not degenerate (Chung et al. 2013).  The run effects themselves
        # are integrated out in the likelihood (module docstring).
        sample[f"tau_{name}"] = numpyro.sample(f"tau_{name}", dist.Gamma(2.0, 2.0 / config.TAU_PRIOR_SCALES[name]))
    first = problem.batch.speed_mps[:, 0]
    with numpyro.plate("run", r):
        sample["v0_mps"] = numpyro.sample("v0_mps", dist.Normal(first, config.NOISE_PRIORS["v0_scale_mps"]))
        # Gamma(2): a logged speed always carries some noise (resolution, sensor), and a prior
        # that vanishes at 0 keeps noise-free or finely resolved traces from a funnel in
        # log sigma, where the integrated noise q takes over the residual
        sample["sigma_mps"] = numpyro.sample(
            "sigma_mps", dist.Gamma(2.0, 2.0 / config.NOISE_PRIORS["sigma_speed_mean_mps"]))
    if problem.integrated_noise:
        # Gamma(2) vanishes at 0: measured inputs are never noise-free, and the boundary-avoiding
        # prior removes the funnel at q -> 0 where the coefficients' posterior narrows
        sample["q_mps_per_sqrt_s"] = numpyro.sample(
            "q_mps_per_sqrt_s", dist.Gamma(2.0, 2.0 / config.NOISE_PRIORS["q_mps_per_sqrt_s"]))
    if problem.robust:
        sample["student_df"] = numpyro.sample("student_df", dist.Gamma(2.0, config.NOISE_PRIORS["student_df_rate"]))
    numpyro.factor("speed_loglik", run_log_likelihood(problem, sample).sum())
    if problem.driveline_channel:
        sigma_d = numpyro.sample("sigma_driveline_n", dist.HalfNormal(config.NOISE_PRIORS["sigma_driveline_n"]))
        numpyro.factor("driveline_loglik", driveline_log_likelihood(problem, sample, sigma_d))
    if problem.calibrated:
        # the paired-run airspeed calibration (module docstring); Gamma(2): no funnel at 0
        s_cal = numpyro.sample("airspeed_calibration_sd",
                               dist.Gamma(2.0, 2.0 / config.NOISE_PRIORS["airspeed_calibration_sd"]))
        yaw_factor = sample.get("yaw_factor", problem.fixed.get("yaw_factor", 1.0))
        ratios = airspeed_pair_ratios(problem.batch, problem.calibration_pairs, yaw_factor)
        with numpyro.plate("pair", len(problem.calibration_pairs)):
            numpyro.sample("airspeed_pair_ratio", dist.Normal(sample["airspeed_factor"], s_cal), obs=ratios)
