"""Simulation-based calibration (SBC; Talts et al. 2018) of the NUTS fit.

Each campaign's true coefficients are drawn from the priors of the model that then fits it
(:class:`PriorDrawnCampaign`), the campaign is simulated with the measurement noise of thesis
table 6.6 on every logged channel (speed 0.05 m/s, airspeed 0.05 m/s, yaw 0.01 rad, driveline
force 1 N), and fitted with NUTS through the batch door
(:func:`bayes_roadload.analysis.batch.run_batch`).  If the posterior is calibrated, the
fraction of posterior draws below the truth is uniform over campaigns, for every parameter: the
rank histograms are flat (:func:`rank_histograms`, chi-square test in :func:`sbc_tests`) and
the central intervals cover at their level (:func:`bayes_roadload.analysis.batch.coverage_summary`).

The simulation is not the fitted likelihood: it integrates the truth at 100 Hz through frozen
turbulence and logs noisy channels at 4 Hz, while the model integrates the noisy logged inputs
and approximates what that does to the speed by the integrated-noise residual.  So this checks
the calibration of the analysis of realistic data, which is the claim that matters, and it can
fail for reasons exact SBC could not (see the negative control).  The integrated noise's
intensity q is a parameter of the likelihood that two pairs hardly identify, so SBC needs it
drawn from its prior too: ``random_force=True`` adds a random force of intensity q ~ the prior
of ``q_mps_per_sqrt_s`` to the simulation (:class:`PriorDrawnCampaign`).  Without it the only
integrated noise is the sensors' (q ~ 5e-4 m/s/sqrt(s), low in that prior), and the study is a
frequentist check at one fixed nuisance value, where the averaging over q's wide posterior
makes the intervals conservative (``docs/calibration.md``).

Ranks use every post-warm-up draw of both chains (``rank_draws`` of them).  Correlated draws
make the rank a Monte-Carlo estimate of the posterior CDF at the truth with standard error
~ sqrt(p (1 - p) / ESS): at most 0.016 for the ~1000 effective draws of a default fit and 0.035
at the gates' floor of 200, small against the 0.1-wide bins of the histograms, so no thinning
is needed for them.

Negative control: :class:`WrongEffectiveMass` hands the fit a vehicle whose effective mass is
off by a factor (default +5 %): the fitted forces scale with it, every coefficient's posterior
shifts, and the same test must fail.

Example
-------
>>> jobs = sbc_jobs(100) + sbc_jobs(50, control_factor=1.05)        # doctest: +SKIP
>>> with batch_client(workers=2) as client:                            # doctest: +SKIP
...     records = run_batch(jobs, client)
>>> sbc_tests(records)                                                 # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np
import pandas as pd

from .. import config
from ..data.campaign import Campaign
from .batch import FitJob, coverage_summary, record_z, successful

SBC_MODEL = "four_term_driveline_informative"
"""Model that draws the truths and fits them (``models/four_term_driveline_informative.toml``)."""
SBC_PARAMETERS = ("AD", "BD", "CD0", "KD", "At", "Bt", "F50_N")
"""Parameters whose calibration the study reports (Ct is drawn and fitted too)."""
SBC_SAMPLER = config.DEFAULT_SAMPLER
"""Sampler of the SBC fits: the default (300 + 1000 draws, 2 chains, target acceptance 0.95 on
campaigns of few runs by :func:`~bayes_roadload.inference.nuts.campaign_sampler`, one logged
retry after a failed gate), so that the study calibrates the fit as ``fit`` runs it.  With
2 x 500 draws and no retry 2 of 6 two-pair fits failed the R-hat gate
(``benchmarks/records/sbc/exact_timing_6fits.json``)."""
SBC_BINS = 10
SBC_ALPHA = 0.01
"""Family-wise level of the uniformity test of one study arm (Bonferroni over its parameters)."""
COEFFICIENTS = ("AD", "BD", "CD0", "KD")
DRIVELINE = ("At", "Bt", "Ct")


def sbc_case():
    """Case 2 winds (2 m/s head, 2 m/s cross: K_D is identified), the basic drag model with lift,
    no instrument dynamics, measurement noise on, no system noise."""
    from ..simulate import get_case

    return dataclasses.replace(get_case(2), number=0, description="SBC", dynamics=False,
                               measurement_noise=True, system_noise=False, model="basic")


def draw_from_prior(model: str, seed: int) -> dict[str, float]:
    """One draw of every free parameter of ``model`` from its prior (numpyro's own sampler)."""
    import jax

    from ..inference.spec import load_model_spec

    spec = load_model_spec(model)
    keys = jax.random.split(jax.random.PRNGKey(seed), len(spec.free))
    missing = [p for p in spec.free if p not in spec.priors]
    if missing:
        raise ValueError(f"model {spec.name!r} has no prior for {', '.join(missing)}: SBC needs one")
    return {p: float(spec.priors[p].to_numpyro().sample(k)) for p, k in zip(spec.free, keys)}


def extra_physics(model: str, drawn: dict[str, float]) -> tuple[tuple, dict[str, float]]:
    """The drag terms of ``model`` whose parameters are drawn but are not the case's own
    coefficients or driveline (e.g. the tyre thermal lag of ``four_term_tyre_lag``), as the
    simulator's ``extra_terms``, and their parameters: the drawn values and the model's fixed
    ones (e.g. the lag's time constant).  Raises when a drawn parameter belongs to no term."""
    from ..inference.spec import load_model_spec
    from ..physics.terms import TERMS

    spec = load_model_spec(model)
    rest = {k: v for k, v in drawn.items() if k not in COEFFICIENTS and k not in DRIVELINE}
    terms, params = [], {}
    for name in spec.terms:
        term = TERMS[name]
        own = set(term.defaults) & set(rest)
        if own:
            terms.append(term())
            params.update({k: rest[k] for k in own})
            params.update({k: float(v) for k, v in spec.fixed.items() if k in term.defaults})
    unknown = set(rest) - set(params)
    if unknown:
        raise ValueError(f"cannot simulate drawn {', '.join(sorted(unknown))}: no term of model {spec.name!r} has it")
    return tuple(terms), params


def with_drawn_truth(settings: Any, drawn: dict[str, float], model: str | None = None, **changes: Any) -> Any:
    """Simulation ``settings`` whose true coefficients (A_D, B_D, C_D0, K_D) and driveline
    (A_t, B_t, C_t) are those of ``drawn`` (:func:`draw_from_prior`), other values kept; with
    ``model``, the drawn parameters of its further terms as extra physics (:func:`extra_physics`);
    ``changes`` replace further settings."""
    if model is not None:
        terms, params = extra_physics(model, drawn)
        present = {t.name for t in settings.extra_terms}
        changes = {"extra_terms": tuple(settings.extra_terms) + tuple(t for t in terms if t.name not in present),
                   "extra_params": {**settings.extra_params, **params}, **changes}
    return dataclasses.replace(
        settings, **changes,
        coefficients={**settings.coefficients, **{k: v for k, v in drawn.items() if k in COEFFICIENTS}},
        driveline_params={**settings.driveline_params, **{k: v for k, v in drawn.items() if k in DRIVELINE}})


@dataclass(frozen=True)
class PriorDrawnCampaign:
    """A picklable recipe: true coefficients drawn from ``model``'s priors, then a simulated
    campaign (:func:`bayes_roadload.simulate.simulate_campaign`, driveline channel logged).

    A draw whose simulation fails or warns (a run that does not slow down in time, relative air
    turning round) is replaced by the next draw of the same seed; ``meta["prior_draws"]`` counts
    the draws used (1 for almost every campaign with the informative priors; a redraw truncates
    the prior, so the study reports how often it happened).

    Parameters
    ----------
    seed : int
        Seed of the prior draw (and of the simulation).
    pairs : int
    model : str
        Model file whose priors are drawn from (its free parameters must be among A_D, B_D,
        C_D0, K_D, A_t, B_t, C_t).
    case : SimulationCase, optional
        Default :func:`sbc_case`.
    settings : SimulationSettings, optional
        Default: thesis chapter 6 (table 6.6 noise).
    max_draws : int
    random_force : bool
        Also draw the intensity q of a random force (the simulator's
        ``random_force_mps_per_sqrt_s``) from the fitting model's prior of
        ``q_mps_per_sqrt_s`` (:data:`bayes_roadload.config.NOISE_PRIORS`, Gamma(2)), recorded
        in ``truth["q_mps_per_sqrt_s"]``: every parameter of the likelihood that the data
        cannot pin down is then drawn from its prior, as SBC requires.  Without it the only
        integrated noise is the one the inputs' sensor noise makes (q ~ 5e-4 m/s/sqrt(s), the
        prior's 2.5 % quantile), a frequentist check at one fixed nuisance value.
    """

    seed: int
    pairs: int = 1
    model: str = SBC_MODEL
    case: Any = None
    settings: Any = None
    max_draws: int = 20
    random_force: bool = False

    def __call__(self) -> Campaign:
        from ..simulate import SimulationSettings, simulate_campaign

        base = self.settings or SimulationSettings()
        case = self.case or sbc_case()
        extra: dict[str, float] = {}
        if self.random_force:
            q = float(np.random.default_rng([self.seed, 7919]).gamma(2.0, config.NOISE_PRIORS["q_mps_per_sqrt_s"] / 2.0))
            base = dataclasses.replace(base, random_force_mps_per_sqrt_s=q)
            extra["q_mps_per_sqrt_s"] = q
        last: Exception | None = None
        for attempt in range(self.max_draws):
            drawn = draw_from_prior(self.model, self.seed * 1000 + attempt)
            settings = with_drawn_truth(base, drawn, self.model)
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("error", RuntimeWarning)
                    campaign = simulate_campaign(case, self.pairs, self.seed, driveline=True, settings=settings)
            except (ValueError, RuntimeWarning) as exc:
                last = exc
                continue
            campaign.truth.update(extra)
            campaign.meta["prior_draws"] = attempt + 1
            campaign.meta["sbc_model"] = self.model
            return campaign
        raise RuntimeError(f"no simulable prior draw in {self.max_draws} tries (last: {last})")


@dataclass(frozen=True)
class ModelDrawnCampaign:
    """A picklable recipe for exact SBC: a campaign drawn from the fitted model's own joint
    distribution, so that uniform ranks test the computation (sampler, likelihood, gradients)
    and nothing else.

    The inputs (sample times, airspeed and yaw readings, air density, directions, vehicle) and
    the true coefficients come from a :class:`PriorDrawnCampaign` of the same seed (its truth is
    a draw from the model's priors).  The speed traces are then replaced by a draw of the
    model's likelihood (:mod:`bayes_roadload.physics.residuals`) with the noise parameters drawn
    from their priors (:data:`bayes_roadload.config.NOISE_PRIORS`):

        q ~ Gamma(2, mean q_prior),  sigma_r ~ Gamma(2, mean sigma_prior),
        v_r,k = v_model,r,k(theta, v0_r) + delta_r,k + e_r,k,
        delta_r,k = delta_r,k-1 + N(0, q^2 dt_k),  delta_r,0 = 0,
        e_r,k ~ N(0, sigma_r^2 + floor^2)   (config.SPEED_NOISE_FLOOR_MPS),

    (for a model whose forces read the logged speed, the tyre thermal lag, ``v_model`` is
    integrated with that input from the drawn speed itself: :func:`drawn_speed`),
    with ``v0_r`` the template's first logged speed (the fit's prior of ``v0_mps`` is centred
    on the first sample: data-dependent, so the ranks of ``v0_mps`` are not part of the test);
    and the logged driveline force, when the model fits it, by
    ``F_k = A_t + B_t v_k + C_t v_k^2 + N(0, sigma_d^2)``, sigma_d ~ HalfNormal(sigma_d_prior),
    at the new logged speeds (:func:`~bayes_roadload.inference.bayes.driveline_log_likelihood`).
    ``truth`` then also holds q, the sigmas and sigma_d.  The pooled, integrated-noise
    likelihood is the one drawn from (the default analysis).

    Probes of one campaign (``benchmarks/sbc_cd0_probe.py``): ``replicate`` > 0 draws new
    noise (and noise scales) for the same template and truth (a calibration check conditional
    on the coefficients); ``noise`` "white" or "walk" keeps only that part of the noise (q and
    the sigmas are still drawn, and recorded, as for "both"); ``template_model`` takes the
    inputs and truth from another model's prior-drawn campaign (its extra parameters, e.g. the
    tyre-lag gain, shape the template's simulated speed, airspeed and run lengths only).
    """

    seed: int
    pairs: int = 1
    model: str = SBC_MODEL
    case: Any = None
    settings: Any = None
    replicate: int = 0
    noise: str = "both"
    template_model: str | None = None

    def __post_init__(self) -> None:
        if self.noise not in ("both", "white", "walk"):
            raise ValueError(f"noise must be 'both', 'white' or 'walk', not {self.noise!r}")

    def __call__(self) -> Campaign:
        from ..inference.bayes import build_problem

        template_model = self.template_model or self.model
        template = PriorDrawnCampaign(self.seed, pairs=self.pairs, model=template_model, case=self.case,
                                      settings=self.settings)()
        problem = build_problem(template, self.model)
        truth = {p: float(template.truth[p]) for p in problem.free}
        b = problem.batch
        first = np.asarray(b.speed_mps)[:, 0]
        rng = np.random.default_rng([self.seed, 5381, self.replicate] if self.replicate else [self.seed, 5381])
        q = rng.gamma(2.0, config.NOISE_PRIORS["q_mps_per_sqrt_s"] / 2.0)
        sigma = rng.gamma(2.0, config.NOISE_PRIORS["sigma_speed_mean_mps"] / 2.0, problem.n_runs)
        sigma_eff = np.sqrt(sigma**2 + config.SPEED_NOISE_FLOOR_MPS**2)  # the likelihood's noise
        runs = template.runs.copy()
        t_all = np.asarray(b.time_s)
        mask = np.asarray(b.mask, bool)
        noise = np.zeros(mask.shape)  # [R, N] delta + e of each logged sample
        rows = [np.flatnonzero((runs["run"] == rid).to_numpy()) for rid in problem.run_ids]
        for r, rid in enumerate(problem.run_ids):
            n = int(mask[r].sum())
            if n != rows[r].size:
                raise ValueError(f"run {rid!r}: {rows[r].size} rows against {n} batch samples")
            dt = np.diff(t_all[r, :n], prepend=t_all[r, 0])
            walk = np.cumsum(rng.normal(0.0, 1.0, n) * q * np.sqrt(dt))
            white = rng.normal(0.0, sigma_eff[r], n)
            noise[r, :n] = (walk if self.noise != "white" else 0.0) + (white if self.noise != "walk" else 0.0)
        logged = drawn_speed(problem, {**truth, "v0_mps": first}, noise)
        speed = runs["speed_mps"].to_numpy(float).copy()
        for r in range(problem.n_runs):
            speed[rows[r]] = logged[r, :rows[r].size]
        runs["speed_mps"] = speed
        extra: dict[str, Any] = {"q_mps_per_sqrt_s": float(q),
                                 "sigma_mps": [float(x) for x in sigma]}
        # the model's fixed constants are the draw's (drawn_speed integrates with problem.fixed):
        # where the template's truth states another value (e.g. the tyre's v^2 coefficient, 0 in
        # the project's simulator, held at its J2452 mean by the default), the truth of the road
        # load (inference.problem.road_load_truth) must read the value the data were drawn with
        extra.update({k: float(v) for k, v in problem.fixed.items()
                      if k in template.truth and isinstance(v, (int, float))})
        if problem.driveline_channel:
            p = {**problem.fixed, **truth}
            sigma_d = abs(rng.normal(0.0, config.NOISE_PRIORS["sigma_driveline_n"]))
            runs["driveline_force_n"] = (p["At"] + p["Bt"] * speed + p["Ct"] * speed**2
                                         + rng.normal(0.0, sigma_d, speed.size))
            extra["sigma_driveline_n"] = float(sigma_d)
        meta = dict(template.meta, sbc="exact", replicate=self.replicate, noise=self.noise,
                    template_model=template_model)
        return Campaign(runs, template.vehicle, template.anemometer, template.tunnel,
                        dict(template.truth, **extra), meta)


DRAWN_SPEED_TOLERANCE_MPS = 1e-9
"""Convergence of :func:`drawn_speed`'s fixed point (m/s, largest change of a sample)."""


def drawn_speed(problem, params: dict, noise: np.ndarray, max_iter: int = 50) -> np.ndarray:
    """[R, N] logged speeds ``v = v_model(theta, v0; v) + noise`` that the likelihood reads as
    drawn from itself.  A model whose forces read the logged speed (the tyre thermal lag's
    lagged speed drop, :func:`~bayes_roadload.physics.integrate.lagged_speed_drop`) integrates
    ``v_model`` with that input computed from the logged speed, so the draw is the fixed point
    of ``v <- v_model(theta, v0; v) + noise``, iterated from ``problem``'s logged speeds (a
    contraction: the lag's force changes by ~M g A_D G_T per m/s of the drop, about a tenth of a
    m/s of speed per m/s over a run).  Other models take one step."""
    import jax.numpy as jnp

    from ..inference.bayes import integrated_speed

    mask = np.asarray(problem.batch.mask, bool)
    speed = np.asarray(problem.batch.speed_mps, float)
    for _ in range(max_iter if problem.model.lag_time_constant else 1):
        current = dataclasses.replace(problem, batch=problem.batch._replace(speed_mps=jnp.asarray(speed)))
        new = np.where(mask, np.asarray(integrated_speed(current, params)) + noise, speed)
        change = float(np.max(np.abs(new - speed)[mask]))
        speed = new
        if change < DRAWN_SPEED_TOLERANCE_MPS:
            break
    else:
        if problem.model.lag_time_constant:
            raise RuntimeError(f"the drawn speed did not converge in {max_iter} iterations (last change {change:.2g} m/s)")
    return speed


@dataclass(frozen=True)
class WrongEffectiveMass:
    """A picklable wrapper of a campaign factory that mis-states the vehicle's effective mass by
    ``factor`` (the negative control of SBC: a deliberately mis-specified analysis)."""

    factory: Callable[[], Campaign]
    factor: float = 1.05

    def __call__(self) -> Campaign:
        c = self.factory()
        vehicle = dataclasses.replace(c.vehicle, effective_mass_kg=c.vehicle.effective_mass_kg * self.factor)
        meta = dict(c.meta, effective_mass_factor=self.factor)
        return dataclasses.replace(c, vehicle=vehicle, meta=meta)


def sbc_jobs(n_campaigns: int, *, seed0: int = 0, pairs: int = 1, model: str = SBC_MODEL,
             sampler: config.SamplerConfig = SBC_SAMPLER, control_factor: float | None = None,
             settings: Any = None, exact: bool = False, random_force: bool = False) -> list[FitJob]:
    """The fit jobs of one SBC arm: ``n_campaigns`` prior-drawn campaigns (seeds ``seed0``...),
    fitted with ``model``; with ``control_factor`` the negative control (effective mass
    mis-stated by that factor); ``exact`` draws the speed traces from the model's own
    likelihood (:class:`ModelDrawnCampaign`) instead of the simulator; ``random_force`` (simulator
    only) draws the simulator's random force from the prior of q (:class:`PriorDrawnCampaign`).
    Tags: ``arm`` ("calibrated" or "wrong_mass", prefixed ``exact_`` for exact SBC and ``sim_``
    for the simulator with the random force) and ``mass_factor``."""
    if exact and random_force:
        raise ValueError("random_force applies to the simulator arm, not to exact SBC")
    prefix = "exact_" if exact else "sim_" if random_force else ""
    arm = prefix + ("calibrated" if control_factor is None else "wrong_mass")
    jobs = []
    for i in range(int(n_campaigns)):
        seed = seed0 + i
        factory: Callable[[], Campaign] = (
            ModelDrawnCampaign(seed, pairs=pairs, model=model, settings=settings) if exact
            else PriorDrawnCampaign(seed, pairs=pairs, model=model, settings=settings, random_force=random_force))
        if control_factor is not None:
            factory = WrongEffectiveMass(factory, float(control_factor))
        # type_b=False: the campaigns' declared values are exact, and SBC checks the posterior of the
        # model as sampled (the Type B part is checked on the independent simulator, analysis.calibration)
        jobs.append(FitJob(f"sbc-{arm}-{seed}", factory, model=model, type_b=False,
                           sampler=dataclasses.replace(sampler, seed=seed),
                           tags={"arm": arm, "mass_factor": 1.0 if control_factor is None else float(control_factor)}))
    return jobs


def _ok(records: pd.DataFrame) -> pd.DataFrame:
    """The records without errors, with an ``arm`` column ("all" when the study has none); the
    arms of a model other than :data:`SBC_MODEL` carry its name (``exact_calibrated
    four_term_tyre_lag_driveline_informative``), so that studies of several models read together
    stay apart."""
    ok = successful(records)
    ok = ok if "arm" in ok else ok.assign(arm="all")
    if "model" in ok and len(ok):
        other = ok["model"].notna() & (ok["model"] != SBC_MODEL)
        ok = ok.assign(arm=ok["arm"].where(~other, ok["arm"] + " " + ok["model"].astype(str)))
    return ok


def rank_fractions(records: pd.DataFrame, parameters: Sequence[str] = SBC_PARAMETERS) -> pd.DataFrame:
    """Long table ``arm, parameter, u``: u = (rank + 0.5) / (rank_draws + 1), the normalised rank of
    the truth among the posterior draws (uniform on (0, 1) under calibration)."""
    rows = []
    ok = _ok(records)
    for _, r in ok.iterrows():
        for p in parameters:
            rank = r.get(f"{p}_rank")
            if rank is None or (isinstance(rank, float) and math.isnan(rank)):
                continue
            rows.append({"arm": r["arm"], "parameter": p,
                         "u": (float(rank) + 0.5) / (float(r["rank_draws"]) + 1.0)})
    return pd.DataFrame(rows, columns=["arm", "parameter", "u"])


def rank_histograms(records: pd.DataFrame, parameters: Sequence[str] = SBC_PARAMETERS,
                    bins: int = SBC_BINS) -> pd.DataFrame:
    """Counts of the normalised ranks in ``bins`` equal bins: one row per arm and parameter,
    columns ``bin0 ... bin{bins-1}`` and ``n``."""
    u = rank_fractions(records, parameters)
    rows = []
    for (arm, p), g in u.groupby(["arm", "parameter"], sort=False):
        counts = np.histogram(g["u"].to_numpy(), bins=bins, range=(0.0, 1.0))[0]
        rows.append({"arm": arm, "parameter": p, "n": int(counts.sum()),
                     **{f"bin{i}": int(c) for i, c in enumerate(counts)}})
    return pd.DataFrame(rows)


Z_SD_RESAMPLES = 2000
"""Bootstrap resamples of :func:`z_sd_interval`."""


def z_sd_interval(z: np.ndarray, level: float = 0.95, resamples: int = Z_SD_RESAMPLES,
                  seed: int = 0) -> tuple[float, float]:
    """Percentile-bootstrap ``level`` interval of sd(z) over the fits (campaigns resampled with
    replacement, a fixed seed so that the tables reproduce).  It is the sampling uncertainty of
    the sd(z) an arm of n fits measures: about sd(z) (1 +- 1.96 sqrt((kappa - 1) / (4 n))) for z
    of kurtosis kappa (sqrt(1 / (2 n)) relative for normal z), so a target such as sd(z) in
    [0.9, 1.1] is missed with confidence only when the interval lies outside it.  NaN for
    fewer than 3 fits."""
    z = np.asarray(z, float)
    z = z[np.isfinite(z)]
    if z.size < 3:
        return math.nan, math.nan
    return _bootstrap_interval(lambda zs: zs.std(axis=1, ddof=1), (z,), level, resamples, seed)


def _bootstrap_interval(statistic, arrays: tuple[np.ndarray, ...], level: float, resamples: int,
                        seed: int) -> tuple[float, float]:
    """Percentile-bootstrap ``level`` interval of ``statistic`` (applied to the arrays resampled
    together, one resample per row) over fits resampled with replacement, fixed seed."""
    n = arrays[0].size
    idx = np.random.default_rng(seed).integers(0, n, (resamples, n))
    boot = statistic(*(a[idx] for a in arrays))
    tail = 0.5 * (1.0 - level)
    lo, hi = np.quantile(boot, [tail, 1.0 - tail])
    return float(lo), float(hi)


def variance_ratio(error: np.ndarray, sd: np.ndarray, level: float = 0.95, resamples: int = Z_SD_RESAMPLES,
                   seed: int = 0) -> tuple[float, float, float]:
    """The mean squared error of the posterior means over the mean posterior variance,
    mean((mean - truth)^2) / mean(sd^2), with its percentile-bootstrap ``level`` interval (fits
    resampled with replacement, fixed seed).  By the law of total variance,
    E[(E[theta | y] - theta)^2] = E[Var(theta | y)] when the truths are drawn from the prior and
    the posterior is exact, whatever its shape: 1 for a calibrated arm, below 1 for posteriors
    too wide.  Unlike sd(z) it does not assume Gaussian posteriors (a truncated prior, a skewed
    posterior).  NaN for fewer than 3 fits."""
    e2, v = np.asarray(error, float) ** 2, np.asarray(sd, float) ** 2
    ok = np.isfinite(e2) & np.isfinite(v)
    e2, v = e2[ok], v[ok]
    if e2.size < 3:
        return math.nan, math.nan, math.nan
    lo, hi = _bootstrap_interval(lambda e, w: e.mean(axis=1) / w.mean(axis=1), (e2, v), level, resamples, seed)
    return float(e2.mean() / v.mean()), lo, hi


VARIANCE_RATIO_NULL_DRAWS = 20000
"""Monte Carlo replications of :func:`variance_ratio_null_p`."""


def variance_ratio_null_p(error: np.ndarray, sd: np.ndarray, draws: int = VARIANCE_RATIO_NULL_DRAWS,
                          seed: int = 0) -> tuple[float, float, float]:
    """The :func:`variance_ratio` of the fits and its two-sided Monte Carlo p under exact Gaussian
    posteriors with these fits' own sds: each replication draws every fit's error from
    N(0, sd_i^2), so the null keeps the arm's mix of wide and narrow posteriors, which a
    bootstrap of the ratio or a normal approximation of its mean misses (both reject an exact
    arm too often: the squared errors are skewed).  Returns (ratio, p_low, p_two_sided):
    p_low the share of replications at or below the ratio, p_two_sided twice the smaller tail
    (at most 1).  NaN for fewer than 3 fits."""
    e2, v = np.asarray(error, float) ** 2, np.asarray(sd, float) ** 2
    ok = np.isfinite(e2) & np.isfinite(v)
    e2, v = e2[ok], v[ok]
    if e2.size < 3:
        return math.nan, math.nan, math.nan
    ratio = float(e2.mean() / v.mean())
    rng = np.random.default_rng(seed)
    null = np.empty(draws)
    for start in range(0, draws, 1000):  # blocks: [1000, fits] at a time
        k = min(1000, draws - start)
        null[start:start + k] = (rng.standard_normal((k, v.size)) ** 2 * v).mean(axis=1) / v.mean()
    low, high = float(np.mean(null <= ratio)), float(np.mean(null >= ratio))
    return ratio, low, min(1.0, 2.0 * min(low, high))


def sbc_tests(records: pd.DataFrame, parameters: Sequence[str] = SBC_PARAMETERS, bins: int = SBC_BINS,
              alpha: float = SBC_ALPHA, levels: Sequence[float] = (0.5, 0.9, 0.95)) -> pd.DataFrame:
    """Uniformity and coverage of every arm and parameter.

    Returns one row per arm and parameter: ``n`` campaigns, ``chi2`` and ``p_value`` of
    Pearson's chi-square test of the rank histogram against uniform (``bins - 1`` degrees of
    freedom; scipy.stats.chisquare), ``coverage50`` / ``coverage90`` / ``coverage95`` of the
    central intervals, ``z_sd`` (sd over campaigns of (mean - truth) / sd) with its bootstrap
    95 % interval ``z_sd_low``, ``z_sd_high`` (:func:`z_sd_interval`), ``var_ratio`` with
    ``var_ratio_low``, ``var_ratio_high`` (:func:`variance_ratio`), ``uniform``
    (p_value >= alpha / number of parameters: Bonferroni within the arm) and ``arm_pass`` (every
    parameter of the arm uniform).  Requires ``n >= 5 bins`` for the chi-square approximation
    to be fair; with fewer campaigns ``p_value`` is still computed but flagged by ``n``.
    """
    from scipy.stats import chisquare

    hist = rank_histograms(records, parameters, bins)
    ok = _ok(records)
    cov = coverage_summary(ok, by=("arm",), quantities=list(parameters), levels=levels)
    rows = []
    for _, h in hist.iterrows():
        counts = np.asarray([h[f"bin{i}"] for i in range(bins)], float)
        res = chisquare(counts)
        row = {"arm": h["arm"], "parameter": h["parameter"], "n": int(h["n"]),
               "chi2": float(res.statistic), "p_value": float(res.pvalue)}
        c = cov[(cov["arm"] == h["arm"]) & (cov["quantity"] == h["parameter"])]
        for lv in levels:
            sel = c[np.isclose(c["level"], lv)]
            row[f"coverage{100 * lv:g}"] = float(sel["coverage"].iloc[0]) if len(sel) else math.nan
        row["z_sd"] = float(c["z_sd"].iloc[0]) if len(c) else math.nan
        arm = ok[(ok["arm"] == h["arm"]) & ok[f"{h['parameter']}_truth"].notna()]
        row["z_sd_low"], row["z_sd_high"] = z_sd_interval(record_z(arm, h["parameter"]).to_numpy())
        q = h["parameter"]
        row["var_ratio"], row["var_ratio_low"], row["var_ratio_high"] = variance_ratio(
            (arm[f"{q}_mean"] - arm[f"{q}_truth"]).to_numpy(float), arm[f"{q}_sd"].to_numpy(float))
        rows.append(row)
    out = pd.DataFrame(rows)
    if out.empty:
        return out
    k = out.groupby("arm")["parameter"].transform("count")
    out["uniform"] = out["p_value"] >= alpha / k
    out["arm_pass"] = out.groupby("arm")["uniform"].transform("all")
    return out


MIN_GROUP = 5
"""Fewest fits in a group of :func:`z_sd_by_truth_q` (sd(z) of fewer is mostly noise)."""


def z_sd_by_truth_q(records: pd.DataFrame, parameters: Sequence[str] = SBC_PARAMETERS,
                    groups: int = 3) -> pd.DataFrame:
    """sd(z) of every parameter in ``groups`` equal-count groups of the true integrated-noise
    intensity (``q_mps_per_sqrt_s_truth``, recorded by the simulator arm with its random force),
    per arm: does the calibration depend on how well q is identified?  One row per arm and
    group: ``q_low``, ``q_high`` (the group's range of true q), ``n`` and one column per
    parameter.  Groups hold at least ``MIN_GROUP`` fits (an arm with fewer has no row);
    empty when no record states the truth of q."""
    ok = _ok(records)
    if "q_mps_per_sqrt_s_truth" not in ok:
        return pd.DataFrame()
    ok = ok[ok["q_mps_per_sqrt_s_truth"].notna()]
    rows = []
    for arm, g in ok.groupby("arm", sort=False):
        n_groups = min(groups, len(g) // MIN_GROUP)
        if n_groups < 1:
            continue
        g = g.copy()  # defragmented: the records are wide
        g["q_group"] = pd.qcut(g["q_mps_per_sqrt_s_truth"], n_groups, labels=False)
        cov = coverage_summary(g, by=("q_group",), quantities=list(parameters), levels=(0.95,))
        for k, c in cov.groupby("q_group"):
            q = g.loc[g["q_group"] == k, "q_mps_per_sqrt_s_truth"]
            rows.append({"arm": arm, "q_low": float(q.min()), "q_high": float(q.max()), "n": int(q.size),
                         **{r["quantity"]: float(r["z_sd"]) for _, r in c.iterrows()}})
    return pd.DataFrame(rows)


MIN_PAIRED = 20
"""Fewest shared seeds for :func:`paired_arms` to compare two arms."""


def paired_arms(records: pd.DataFrame, parameters: Sequence[str] = ("CD0",),
                arms: Sequence[tuple[str, str]] | None = None, seed: int = 0) -> pd.DataFrame:
    """Arms that drew the same campaigns, compared seed by seed.

    Two arms fitted the same draws, but for their models' extra terms, when their campaigns come
    from the same seeds with the same truth and the same noise: e.g. the exact arms of two
    models with the same priors for A_D, B_D, C_D0, K_D (:class:`ModelDrawnCampaign` draws the
    truth and the noise from the seed).  ``arms``: the pairs of arm names the caller knows to be
    drawn so; None pairs any two arms whose records both state the drawn noise intensity
    ``q_mps_per_sqrt_s_truth``.  Either way the seeds compared are those of both arms with the
    same truth of the parameter and, where both state it, the same drawn q (1e-9 relative),
    and a pair needs :data:`MIN_PAIRED` of them.  One row per such pair and
    parameter: ``n`` shared seeds, ``corr_z`` (correlation of their z), ``mean_z2_a``,
    ``mean_z2_b`` (mean z^2 over the shared seeds, 1 for a calibrated arm), ``diff_z2`` (b less a)
    with its paired-bootstrap 95 % interval ``diff_low``, ``diff_high`` (:data:`Z_SD_RESAMPLES`,
    fixed ``seed``), and ``sd_ratio`` (median ratio of b's posterior sd to a's): is b's excess
    over a a property of b's model on the same data?"""
    ok = _ok(records)
    if "seed" not in ok or ok.empty:
        return pd.DataFrame()
    by_arm = {arm: g.drop_duplicates("seed").set_index("seed") for arm, g in ok.groupby("arm", sort=False)}
    q = "q_mps_per_sqrt_s_truth"
    if arms is None:
        named = [arm for arm, g in by_arm.items() if q in g and g[q].notna().all()]
        arms = [(x, y) for i, x in enumerate(named) for y in named[i + 1:]]
    rows = []
    rng = np.random.default_rng(seed)
    for arm_a, arm_b in arms:
        if arm_a not in by_arm or arm_b not in by_arm:
            continue
        a, b = by_arm[arm_a], by_arm[arm_b]
        shared = a.index.intersection(b.index)
        for p in parameters:
            if f"{p}_truth" not in a or f"{p}_truth" not in b:
                continue
            same = shared
            for col, stated in ((f"{p}_truth", False), (q, True)):
                if col in a and col in b:
                    ta, tb = a.loc[same, col].astype(float), b.loc[same, col].astype(float)
                    unstated = (ta.isna() | tb.isna()).to_numpy() if stated else False
                    same = same[np.isclose(ta, tb, rtol=1e-9, atol=0.0) | unstated]
            if same.size < MIN_PAIRED:
                continue
            za, zb = record_z(a.loc[same], p).to_numpy(), record_z(b.loc[same], p).to_numpy()
            d = zb**2 - za**2
            boot = d[rng.integers(0, d.size, (Z_SD_RESAMPLES, d.size))].mean(axis=1)
            lo, hi = np.quantile(boot, [0.025, 0.975])
            rows.append({"arm_a": arm_a, "arm_b": arm_b, "parameter": p, "n": int(same.size),
                         "corr_z": float(np.corrcoef(za, zb)[0, 1]), "mean_z2_a": float(np.mean(za**2)),
                         "mean_z2_b": float(np.mean(zb**2)), "diff_z2": float(d.mean()),
                         "diff_low": float(lo), "diff_high": float(hi),
                         "sd_ratio": float(np.median(b.loc[same, f"{p}_sd"].astype(float)
                                                     / a.loc[same, f"{p}_sd"].astype(float)))})
    return pd.DataFrame(rows)


def sbc_markdown(records: pd.DataFrame, tests: pd.DataFrame | None = None,
                 parameters: Sequence[str] = SBC_PARAMETERS, bins: int = SBC_BINS,
                 paired: Sequence[tuple[str, str]] | None = None) -> str:
    """Markdown tables of an SBC study: per arm and parameter the rank histogram, the
    chi-square test and the interval coverage; then the gate pass rate and the redraw count,
    sd(z) by the true q, and the arms fitted to the same draws (:func:`paired_arms`, ``paired``
    as its ``arms``)."""
    tests = sbc_tests(records, parameters, bins) if tests is None else tests
    hist = rank_histograms(records, parameters, bins)
    ok = _ok(records)
    lines = ["| arm | parameter | n | rank histogram (10 bins) | chi2 | p | cov. 50 % | cov. 90 % | cov. 95 % | z sd (95 % CI) "
             "| MSE / mean var (95 % CI) | uniform |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for _, t in tests.iterrows():
        h = hist[(hist["arm"] == t["arm"]) & (hist["parameter"] == t["parameter"])].iloc[0]
        counts = " ".join(str(int(h[f"bin{i}"])) for i in range(bins))
        lines.append(f"| {t['arm']} | {t['parameter']} | {t['n']} | {counts} | {t['chi2']:.1f} | "
                     f"{t['p_value']:.3g} | {t['coverage50']:.2f} | {t['coverage90']:.2f} | "
                     f"{t['coverage95']:.2f} | {t['z_sd']:.2f} ({t['z_sd_low']:.2f}-{t['z_sd_high']:.2f}) | "
                     f"{t['var_ratio']:.2f} ({t['var_ratio_low']:.2f}-{t['var_ratio_high']:.2f}) | "
                     f"{'yes' if t['uniform'] else '**no**'} |")
    lines.append("")
    for arm, g in ok.groupby("arm", sort=False):
        failed = int((~g["gate_pass"].astype(bool)).sum())
        retried = int((g["retries"] > 0).sum()) if "retries" in g else 0
        redraws = int((g["prior_draws"] > 1).sum()) if "prior_draws" in g else 0
        verdict = tests[tests["arm"] == arm]["arm_pass"]
        lines.append(f"- **{arm}**: {len(g)} fits, {retried} retried once after a failed gate, "
                     f"{failed} failed a diagnostic gate in the end, "
                     f"{redraws} prior draws replaced; ranks uniform for every parameter at family-wise "
                     f"{100 * SBC_ALPHA:g} %: **{'yes' if bool(verdict.all()) else 'no'}**.")
    n_err = int(records["error"].notna().sum()) if "error" in records else 0
    if n_err:
        lines.append(f"- {n_err} jobs ended in an error and are not counted.")
    by_q = z_sd_by_truth_q(records, parameters)
    if not by_q.empty:
        lines += ["", "sd(z) by the true intensity q of the random force (m/s/sqrt(s)), in thirds of the arm's fits:", "",
                  "| arm | true q | n | " + " | ".join(parameters) + " |",
                  "|---|---|---|" + "---|" * len(parameters)]
        for _, r in by_q.iterrows():
            lines.append(f"| {r['arm']} | {r['q_low']:.4f}-{r['q_high']:.4f} | {r['n']} | "
                         + " | ".join(f"{r[p]:.2f}" for p in parameters) + " |")
    paired = paired_arms(records, arms=paired)
    if not paired.empty:
        lines += ["", "Arms fitted to the same draws (shared seeds, equal truths; z^2 averages 1 when calibrated; "
                  "difference b - a with its paired-bootstrap 95 % interval):", "",
                  "| arm a | arm b | parameter | shared seeds | corr(z) | mean z^2 a | mean z^2 b | b - a (95 % CI) | posterior sd b / a |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for _, r in paired.iterrows():
            lines.append(f"| {r['arm_a']} | {r['arm_b']} | {r['parameter']} | {r['n']} | {r['corr_z']:.3f} | "
                         f"{r['mean_z2_a']:.2f} | {r['mean_z2_b']:.2f} | {r['diff_z2']:+.2f} "
                         f"({r['diff_low']:+.2f} to {r['diff_high']:+.2f}) | {r['sd_ratio']:.3f} |")
    return "\n".join(lines) + "\n"
