"""Peer samplers side by side on the same coastdown posterior: min bulk ESS per second.

The same campaign (default: 18 pairs at thesis case 14 conditions, basic drag model, model
four_term, pooled, integrated noise) is sampled by

* ``ours``: :func:`bayes_roadload.inference.nuts.run_nuts` with its default settings (MAP,
  Laplace whitening ``x = x_MAP + L u``, numpyro NUTS);
* ``blackjax_window``: BlackJAX NUTS with its window adaptation, on our JAX log density in
  numpyro's unconstrained space;
* ``ours_diag``: ours with a diagonal instead of a dense metric in the whitened coordinates;
* ``blackjax_meads``: BlackJAX generalised HMC with MEADS adaptation, same density, and
  ``blackjax_meads_whitened`` on our whitened coordinates;
* ``blackjax_chees``: BlackJAX ChEES-HMC (jittered trajectory lengths adapted across chains,
  with its diagonal metric estimated from the ensemble), and ``blackjax_chees_whitened`` on our
  whitened coordinates;
* ``nutpie``: nutpie on the same JAX log density (``nutpie.from_pyfunc``);
* ``stan_default``: Stan (PyStan) with its default adaptation, on the same unconstrained space;
* ``stan_whitened``: Stan on the MAP-whitened coordinates ``u`` of ours.

The Stan program (:data:`STAN_PROGRAM`) is the same model: the stride-2 RK4 of
:mod:`bayes_roadload.physics.integrate` on the same time grid and its continuous extension at
the middle sample, the same priors and the local-level likelihood of
:func:`bayes_roadload.physics.residuals.local_level_loglik` (Kalman filter).  The equation of
motion of the basic model with measured air is affine in the speed and in the coefficients,
a(t, v) = alpha(t) + beta(t) v with alpha, beta affine in (AD, BD, CD0, KD); the script evaluates
our JAX acceleration at the RK4 stage points for unit coefficient vectors and passes that basis
as data (checked to reproduce the acceleration at random coefficients), so the force law itself
is ours, not a transcription.  Before any timing the Stan log density is compared with ours
(differences between points agree to rounding: Stan drops constants).

Each record holds wall time including compilation (and the common LSQ start; the MAP for the
whitened samplers), compile time where separable, process CPU time (children included),
min bulk ESS over the coefficients and noise parameters (arviz), max R-hat, divergences, mean
leapfrog steps per draw and min ESS per wall second.  Records go to
``benchmarks/records/peers/``; ``docs/performance.md``'s peers section is regenerated between
marker comments.  Run (peers venv, ``pip install -e ".[peers]"``)::

    python benchmarks/peers.py --timeout-s 420      # the reference: 18 pairs, default draws
    python benchmarks/peers.py --timeout-s 420 --only stan_whitened   # rerun one sampler
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import resource
import signal
import subprocess
import sys
import time
import traceback
import warnings
from pathlib import Path

import arviz as az
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from bayes_roadload import config
from bayes_roadload.inference.bayes import build_problem
from bayes_roadload.inference.nuts import (find_map, laplace_cholesky, prepare_problem, run_nuts,
                                           unconstrained_posterior)
from bayes_roadload.physics import integrate as integ
from bayes_roadload.simulate import get_case, simulate_campaign


ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "benchmarks" / "records" / "peers"
DOC = ROOT / "docs" / "performance.md"
BEGIN, END = "<!-- peers:begin (benchmarks/peers.py) -->", "<!-- peers:end -->"
COEFFS = ("AD", "BD", "CD0", "KD")

STAN_PROGRAM = """
data {
  int<lower=1> R;                 // runs
  int<lower=2> N;                 // padded samples per run
  int<lower=1> G;                 // stride-2 RK4 steps per run
  int<lower=1> K;                 // free coefficients
  int<lower=1> D;                 // unconstrained dimension
  array[R] int<lower=1, upper=N> n_obs;
  matrix[R, N] y;                 // measured speed (m/s)
  matrix[R, N] dt;                // time step before each sample (s), 0 at the first
  array[R, G] real h;             // RK4 step lengths (s)
  array[R, G, 2, 3] real w;       // RK4 continuous-extension weights (middle, end sample)
  array[R, G, 3] vector[K + 1] alpha_basis;  // alpha at the 3 stage points: [1, theta] . basis
  array[R, G, 3] vector[K + 1] beta_basis;
  vector[K] prior_loc;
  vector[K] prior_scale;
  array[K] int<lower=0, upper=1> positive;    // coefficient truncated from below: low + s softplus(x)
  vector[K] low;                  // its lower bound
  vector[K] soft_scale;           // its softplus scale s (spec.soft_lower_truncated_normal)
  vector[R] v0_loc;
  real v0_scale;
  real sigma_rate;                // Gamma(2, rate) prior of each run's speed noise
  real sigma_floor;               // the likelihood's white noise is sqrt(sigma^2 + floor^2)
  real q_rate;
  // layout of the unconstrained vector x (numpyro's ravel order) and its affine map x = shift + L u
  array[K] int idx_coef;
  int idx_q;
  array[R] int idx_v0;
  array[R] int idx_sigma;
  vector[D] shift;
  matrix[D, D] L;
}
parameters {
  vector[D] u;
}
model {
  vector[D] x = shift + L * u;
  vector[K] theta;
  vector[K + 1] one_theta;
  real q = exp(x[idx_q]);
  target += x[idx_q];                               // Jacobian of exp
  for (k in 1:K) {
    if (positive[k] == 1) {
      theta[k] = low[k] + soft_scale[k] * log1p_exp(x[idx_coef[k]]);
      target += log(soft_scale[k]) + log_inv_logit(x[idx_coef[k]]);   // Jacobian of the softplus
    } else {
      theta[k] = x[idx_coef[k]];
    }
  }
  theta ~ normal(prior_loc, prior_scale);           // truncation constants are constant
  q ~ gamma(2, q_rate);
  one_theta[1] = 1;
  one_theta[2:(K + 1)] = theta;
  for (r in 1:R) {
    real v0 = x[idx_v0[r]];
    real sigma = exp(x[idx_sigma[r]]);
    vector[N] speed;
    target += x[idx_sigma[r]];
    v0 ~ normal(v0_loc[r], v0_scale);
    sigma ~ gamma(2, sigma_rate);
    {
      real v = v0;
      int j = 1;
      speed[1] = v0;
      for (g in 1:G) {
        real a1 = dot_product(one_theta, alpha_basis[r, g, 1]);
        real b1 = dot_product(one_theta, beta_basis[r, g, 1]);
        real a2 = dot_product(one_theta, alpha_basis[r, g, 2]);
        real b2 = dot_product(one_theta, beta_basis[r, g, 2]);
        real a4 = dot_product(one_theta, alpha_basis[r, g, 3]);
        real b4 = dot_product(one_theta, beta_basis[r, g, 3]);
        real hh = h[r, g];
        real k1 = a1 + b1 * v;
        real k2 = a2 + b2 * (v + 0.5 * hh * k1);
        real k3 = a2 + b2 * (v + 0.5 * hh * k2);
        real k4 = a4 + b4 * (v + hh * k3);
        real mid = v + hh * (w[r, g, 1, 1] * k1 + w[r, g, 1, 2] * (k2 + k3) + w[r, g, 1, 3] * k4);
        real fin = v + hh * (w[r, g, 2, 1] * k1 + w[r, g, 2, 2] * (k2 + k3) + w[r, g, 2, 3] * k4);
        if (j + 1 <= N) speed[j + 1] = mid;
        if (j + 2 <= N) speed[j + 2] = fin;
        j += 2;
        v = fin;
      }
    }
    {  // local-level (white + integrated noise) likelihood: Kalman filter over the real samples
      real m = 0;
      real p = 0;
      real var_e = square(sigma) + square(sigma_floor);
      for (i in 1:n_obs[r]) {
        real p_pred = p + square(q) * dt[r, i];
        real s = p_pred + var_e;
        real innov = y[r, i] - speed[i] - m;
        real gain = p_pred / s;
        target += -0.5 * (log(s) + square(innov) / s);
        m += gain * innov;
        p = (1 - gain) * p_pred;
      }
    }
  }
}
"""


# ----------------------------------------------------------------------------------------------
# the campaign and our log density

@dataclasses.dataclass
class Setup:
    campaign: object
    problem: object
    post: object
    map_result: object
    setup_s: float       # problem build and LSQ start (every sampler needs it)
    map_s: float         # MAP and Laplace (ours and the whitened peers)
    logdensity: object   # flat unconstrained x -> log density (jitted)
    flat0: np.ndarray    # LSQ start, flat unconstrained
    flat_map: np.ndarray
    chol: np.ndarray


def build_setup(pairs: int) -> Setup:
    case = dataclasses.replace(get_case(14), model="basic")
    campaign = simulate_campaign(case, pairs=pairs, seed=1)
    t0 = time.perf_counter()
    problem, init = prepare_problem(build_problem(campaign, "four_term"), campaign)
    post = unconstrained_posterior(problem, init)
    t1 = time.perf_counter()
    m = find_map(problem, {}, posterior=post)
    t2 = time.perf_counter()
    flat_map = np.asarray(ravel_pytree(m.z)[0])
    chol = laplace_cholesky(np.asarray(m.cov))  # ours' whitening, for the whitened peers too
    unravel = post.unravel
    logdensity = jax.jit(lambda x: -post.potential_fn(unravel(x)))
    return Setup(campaign, problem, post, m, t1 - t0, t2 - t1, logdensity, post.flat0, flat_map, chol)


def layout(setup: Setup) -> dict[str, np.ndarray]:
    """Index (1-based, Stan) of every site in the flat unconstrained vector."""
    z0 = setup.post.z0
    idx = {k: np.asarray(v) for k, v in setup.post.unravel(jnp.arange(setup.flat0.size, dtype=float)).items()}
    assert set(z0) == set(COEFFS) | {"v0_mps", "sigma_mps", "q_mps_per_sqrt_s"}, sorted(z0)
    return {k: (v.astype(int) + 1) for k, v in idx.items()}


# ----------------------------------------------------------------------------------------------
# Stan data: the acceleration basis at the RK4 stage points

def acceleration_basis(problem) -> tuple[np.ndarray, np.ndarray, tuple]:
    """alpha, beta [R, G, 3, K + 1] such that a(t, v) = [1, theta] . (alpha + v beta) at the
    three stage points of every stride-2 step (start, half step, end), from our JAX
    acceleration; and the schedule (t0, h, ua, um, uc, w)."""
    model, batch = problem.model, problem.batch
    if not (model.speed_affine and config.DEFAULT_INTEGRATOR.stride == 2):
        raise SystemExit("the Stan transcription needs a speed-affine model and the stride-2 integrator")
    schedule = integ.stride2_schedule(np.asarray(batch.time_s), integ._inputs(batch))
    t0, h, ua, um, uc, w = (np.asarray(x) for x in schedule)

    def coefficients(theta):
        p = model.complete(dict(problem.fixed, **{k: theta[i] for i, k in enumerate(COEFFS)}))

        def at(r, t, uu):
            run = batch.run(r)

            def acc(v):
                c = integ._conditions(model, p, run, v, jnp.zeros_like(v), t, uu.T)
                return model.acceleration_mps2(p, c, run.effective_mass_kg)

            a0 = acc(jnp.zeros_like(t))
            return a0, acc(jnp.ones_like(t)) - a0

        out_a, out_b = [], []
        for r in range(batch.n_runs):
            stages = [at(r, t0[r], ua[r]), at(r, t0[r] + 0.5 * h[r], um[r]), at(r, t0[r] + h[r], uc[r])]
            out_a.append(np.stack([np.asarray(s[0]) for s in stages], axis=-1))
            out_b.append(np.stack([np.asarray(s[1]) for s in stages], axis=-1))
        return np.stack(out_a), np.stack(out_b)  # [R, G, 3]

    k = len(COEFFS)
    a0, b0 = coefficients(np.zeros(k))
    cols_a, cols_b = [a0], [b0]
    for i in range(k):
        e = np.zeros(k)
        e[i] = 1.0
        ai, bi = coefficients(e)
        cols_a.append(ai - a0)
        cols_b.append(bi - b0)
    alpha, beta = np.stack(cols_a, axis=-1), np.stack(cols_b, axis=-1)
    rng = np.random.default_rng(0)
    theta = np.array([0.01, 2e-4, 0.4, 0.6]) * (1.0 + 0.5 * rng.standard_normal(k))
    at, bt = coefficients(theta)
    one = np.concatenate([[1.0], theta])
    for want, basis in ((at, alpha), (bt, beta)):
        got = basis @ one
        assert np.allclose(got, want, rtol=1e-9, atol=1e-12 * np.abs(want).max()), "acceleration not affine in the coefficients"
    return alpha, beta, (t0, h, ua, um, uc, w)


def stan_data(setup: Setup, whitened: bool) -> dict:
    problem = setup.problem
    alpha, beta, (t0, h, _, _, _, w) = acceleration_basis(problem)
    b = problem.batch
    time_s, mask = np.asarray(b.time_s), np.asarray(b.mask)
    r, n = time_s.shape
    dt = np.diff(time_s, axis=1, prepend=time_s[:, :1])
    idx = layout(setup)
    d = setup.flat0.size
    priors = [problem.priors[k] for k in COEFFS]
    for k, p in zip(COEFFS, priors):  # the Stan program writes these two kinds only
        if p.dist != "normal" or p.high is not None:
            raise ValueError(f"{k}: the Stan program has normal priors, optionally truncated from below; got {p}")
    return {
        "R": r, "N": n, "G": h.shape[1], "K": len(COEFFS), "D": d,
        "n_obs": mask.sum(axis=1).astype(int).tolist(),
        "y": np.asarray(b.speed_mps), "dt": dt, "h": h, "w": w,
        "alpha_basis": alpha, "beta_basis": beta,
        "prior_loc": np.array([p.loc for p in priors]), "prior_scale": np.array([p.scale for p in priors]),
        "positive": [int(p.low is not None) for p in priors],
        "low": np.array([p.low if p.low is not None else 0.0 for p in priors]),
        "soft_scale": np.array([p.softplus_fraction * p.scale for p in priors]),
        "v0_loc": np.asarray(b.speed_mps)[:, 0], "v0_scale": config.NOISE_PRIORS["v0_scale_mps"],
        "sigma_rate": 2.0 / config.NOISE_PRIORS["sigma_speed_mean_mps"], "sigma_floor": config.SPEED_NOISE_FLOOR_MPS,
        "q_rate": 2.0 / config.NOISE_PRIORS["q_mps_per_sqrt_s"],
        "idx_coef": [int(idx[k]) for k in COEFFS], "idx_q": int(idx["q_mps_per_sqrt_s"]),
        "idx_v0": idx["v0_mps"].tolist(), "idx_sigma": idx["sigma_mps"].tolist(),
        "shift": setup.flat_map if whitened else np.zeros(d),
        "L": setup.chol if whitened else np.eye(d),
    }


# ----------------------------------------------------------------------------------------------
# timing and diagnostics

def cpu_seconds() -> float:
    """CPU seconds of this process and its children (live ones through psutil when present)."""
    own = time.process_time() + resource.getrusage(resource.RUSAGE_CHILDREN).ru_utime + resource.getrusage(resource.RUSAGE_CHILDREN).ru_stime
    try:
        import psutil
        for c in psutil.Process().children(recursive=True):
            try:
                t = c.cpu_times()
                own += t.user + t.system
            except psutil.Error:
                pass
    except ImportError:
        pass
    return own


def constrained_draws(setup: Setup, x: np.ndarray) -> dict[str, np.ndarray]:
    """[chain, draw, D] flat unconstrained draws -> constrained sites [chain, draw, ...]."""
    f = jax.jit(jax.vmap(jax.vmap(lambda xi: setup.post.postprocess_fn(setup.post.unravel(xi)))))
    return {k: np.asarray(v) for k, v in f(jnp.asarray(x)).items()}


def diagnose(name: str, samples: dict, steps: np.ndarray, divergent: np.ndarray, wall: float, cpu: float,
             compile_s: float | None, extra: dict) -> dict:
    keep = {k: v for k, v in samples.items() if k in (*COEFFS, "sigma_mps", "q_mps_per_sqrt_s")}
    idata = az.from_dict(posterior=keep)
    ess = az.ess(idata, method="bulk")
    rhat = az.rhat(idata)
    min_ess = float(min(float(np.min(ess[k].values)) for k in keep))
    min_ess_coef = float(min(float(np.min(ess[k].values)) for k in COEFFS))
    max_rhat = float(max(float(np.max(rhat[k].values)) for k in keep))
    means = {k: float(np.mean(samples[k])) for k in COEFFS}
    return dict({
        "sampler": name, "wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
        "compile_s": None if compile_s is None else round(compile_s, 2),
        "chains": int(steps.shape[0]), "draws_per_chain": int(steps.shape[1]),
        "min_ess_bulk": round(min_ess, 1), "min_ess_bulk_coefficients": round(min_ess_coef, 1),
        "max_r_hat": round(max_rhat, 4), "divergences": int(np.sum(divergent)),
        "mean_leapfrog_steps": round(float(np.mean(steps)), 1),
        "min_ess_per_s": round(min_ess / wall, 3), "posterior_means": means,
    }, **extra)


# ----------------------------------------------------------------------------------------------
# the samplers

def run_ours(setup: Setup, args, mass_matrix: str = config.DEFAULT_SAMPLER.mass_matrix) -> dict:
    sampler = config.SamplerConfig(num_warmup=args.warmup, num_samples=args.draws, num_chains=args.chains,
                                   mass_matrix=mass_matrix)
    c0, t0 = cpu_seconds(), time.perf_counter()
    fit = run_nuts(setup.problem, sampler=sampler, map_result=setup.map_result, posterior=setup.post)
    wall = time.perf_counter() - t0 + setup.setup_s + setup.map_s
    cpu = cpu_seconds() - c0
    return diagnose("ours" if mass_matrix == config.DEFAULT_SAMPLER.mass_matrix else f"ours_{mass_matrix}", fit.samples, fit.stats["num_steps"], fit.stats["diverging"], wall, cpu, None,
                    {"warmup": args.warmup, "includes": "LSQ start + MAP/Laplace + numpyro NUTS (compile inside)",
                     "map_s": round(setup.map_s, 2), "setup_s": round(setup.setup_s, 2)})


def start_points(setup: Setup, chains: int, seed: int) -> np.ndarray:
    """The LSQ start with a small jitter per chain (default-adaptation peers)."""
    rng = np.random.default_rng(seed)
    return setup.flat0[None, :] + 0.01 * setup.post.scale[None, :] * rng.standard_normal((chains, setup.flat0.size))


def run_blackjax_window(setup: Setup, args) -> dict:
    import blackjax

    warm = args.peer_warmup
    key = jax.random.PRNGKey(args.seed)
    c0, t0 = cpu_seconds(), time.perf_counter()
    starts = jnp.asarray(start_points(setup, args.chains, args.seed))

    @jax.jit
    def one_chain(key, x0):
        k1, k2 = jax.random.split(key)
        adapt = blackjax.window_adaptation(blackjax.nuts, setup.logdensity)
        (state, params), _ = adapt.run(k1, x0, num_steps=warm)
        kernel = blackjax.nuts(setup.logdensity, **params).step

        def body(state, k):
            state, info = kernel(k, state)
            return state, (state.position, info.num_integration_steps, info.is_divergent)

        _, out = jax.lax.scan(body, state, jax.random.split(k2, args.draws))
        return out

    keys = jax.random.split(key, args.chains)
    # chains in parallel over the CPU devices when there are enough (as ours), else vectorised
    run_chains = jax.pmap(one_chain) if jax.local_device_count() >= args.chains > 1 else jax.vmap(one_chain)
    out = jax.block_until_ready(run_chains(keys, starts))
    outs = [tuple(o[c] for o in out) for c in range(args.chains)]
    wall = time.perf_counter() - t0 + setup.setup_s
    cpu = cpu_seconds() - c0
    x = np.stack([np.asarray(o[0]) for o in outs])
    return diagnose("blackjax_window", constrained_draws(setup, x), np.stack([np.asarray(o[1]) for o in outs]),
                    np.stack([np.asarray(o[2]) for o in outs]), wall, cpu, None,
                    {"warmup": warm, "includes": "LSQ start + window adaptation (diagonal) + NUTS, chains pmapped/vmapped (compile inside)"})


def _ensemble_density(setup: Setup, args, whitened: bool):
    """Log density, chain starts and warm-up length of the ensemble samplers (MEADS, ChEES):
    on numpyro's unconstrained space from jittered least-squares starts, or on ours' whitened
    coordinates ``x = x_MAP + L u`` from standard-normal draws."""
    warm = args.warmup if whitened else args.peer_warmup
    shift, chol = jnp.asarray(setup.flat_map), jnp.asarray(setup.chol)
    if whitened:
        logdensity = jax.jit(lambda u: setup.logdensity(shift + chol @ u))
        starts = jnp.asarray(np.random.default_rng(args.seed).standard_normal((args.meads_chains, setup.flat0.size)))
    else:
        logdensity = setup.logdensity
        starts = jnp.asarray(start_points(setup, args.meads_chains, args.seed))
    return logdensity, starts, warm


def _ensemble_run(name: str, setup: Setup, args, whitened: bool, kernel, state, key, c0: float, t0: float,
                  warm: int, includes: str, note: str) -> dict:
    """``args.draws`` transitions of ``kernel`` on every chain at once (vmapped), then the
    record: leapfrog steps per draw from the transition's ``num_integration_steps`` where the
    kernel reports it (generalised HMC takes one step per transition)."""

    @jax.jit
    def sample(state, key):
        def body(state, k):
            state, info = jax.vmap(kernel)(jax.random.split(k, args.meads_chains), state)
            steps = getattr(info, "num_integration_steps", jnp.ones(args.meads_chains))
            return state, (state.position, info.is_divergent, steps)

        return jax.lax.scan(body, state, jax.random.split(key, args.draws))[1]

    x, div, steps = jax.block_until_ready(sample(state, key))
    wall = time.perf_counter() - t0 + setup.setup_s + (setup.map_s if whitened else 0.0)
    cpu = cpu_seconds() - c0
    x = np.swapaxes(np.asarray(x), 0, 1)
    if whitened:
        x = np.asarray(setup.flat_map)[None, None, :] + np.einsum("cdj,ij->cdi", x, np.asarray(setup.chol))
    return diagnose(name, constrained_draws(setup, x), np.swapaxes(np.asarray(steps, float), 0, 1),
                    np.swapaxes(np.asarray(div), 0, 1), wall, cpu, None,
                    {"warmup": warm, "includes": ("LSQ start + MAP/Laplace + " if whitened else "LSQ start + ")
                     + f"{includes}, {args.meads_chains} chains vectorised (compile inside)", "note": note})


def run_blackjax_meads(setup: Setup, args, whitened: bool = False) -> dict:
    import blackjax

    k1, k2 = jax.random.split(jax.random.PRNGKey(args.seed))
    c0, t0 = cpu_seconds(), time.perf_counter()
    logdensity, starts, warm = _ensemble_density(setup, args, whitened)
    adapt = blackjax.meads_adaptation(logdensity, args.meads_chains)
    (state, params), _ = jax.block_until_ready(adapt.run(k1, starts, num_steps=warm))
    kernel = blackjax.ghmc(logdensity, **params).step
    return _ensemble_run("blackjax_meads_whitened" if whitened else "blackjax_meads", setup, args, whitened, kernel,
                         state, k2, c0, t0, warm, "MEADS adaptation + GHMC",
                         "GHMC takes one leapfrog step per transition; ESS counts all chains' draws")


ENSEMBLE = ("blackjax_meads", "blackjax_chees")
"""Samplers that run ``--meads-chains`` chains (their adaptation works across chains)."""

CHEES_STEP_SIZE = 0.1
CHEES_LEARNING_RATE = 0.025
"""ChEES-HMC's starting step size and the Adam learning rate of its trajectory length (the
values of BlackJAX's documented example)."""


def run_blackjax_chees(setup: Setup, args, whitened: bool = False) -> dict:
    """ChEES-HMC (Hoffman, Radul and Sountsov 2021): jittered-length HMC whose step size and
    trajectory length are adapted across the chains (``blackjax.chees_adaptation``; on the
    unwhitened density with its ensemble-estimated diagonal metric), then
    ``blackjax.dynamic_hmc`` with the adapted parameters."""
    import blackjax
    import optax

    k1, k2 = jax.random.split(jax.random.PRNGKey(args.seed))
    c0, t0 = cpu_seconds(), time.perf_counter()
    logdensity, starts, warm = _ensemble_density(setup, args, whitened)
    adapt = blackjax.chees_adaptation(logdensity, args.meads_chains,
                                      mass_matrix_estimation=None if whitened else "diagonal")
    (state, params), _ = jax.block_until_ready(
        adapt.run(k1, starts, CHEES_STEP_SIZE, optax.adam(CHEES_LEARNING_RATE), num_steps=warm))
    kernel = blackjax.dynamic_hmc(logdensity, **params).step
    return _ensemble_run("blackjax_chees_whitened" if whitened else "blackjax_chees", setup, args, whitened, kernel,
                         state, k2, c0, t0, warm,
                         "ChEES adaptation + jittered-length HMC" + ("" if whitened else " (diagonal metric)"),
                         "ESS counts all chains' draws")


def run_nutpie(setup: Setup, args) -> dict:
    import nutpie

    d = setup.flat0.size
    c0, t0 = cpu_seconds(), time.perf_counter()
    value_and_grad = jax.jit(jax.value_and_grad(setup.logdensity))
    jax.block_until_ready(value_and_grad(jnp.asarray(setup.flat0)))
    compile_s = time.perf_counter() - t0

    def make_logp_fn():
        def logp(x, **unused):
            v, g = value_and_grad(jnp.asarray(x))
            return float(v), np.asarray(g, dtype=np.float64)
        return logp

    def make_expand_fn(*unused, **kw):
        def expand(x, **unused):
            return {"x": np.asarray(x, dtype=np.float64)}
        return expand

    model = nutpie.compiled_pyfunc.from_pyfunc(d, make_logp_fn, make_expand_fn, ["float64"], [(d,)], ["x"],
                                               make_initial_point_fn=lambda seed: start_points(setup, 1, seed)[0])
    trace = nutpie.sample(model, draws=args.draws, tune=args.peer_warmup, chains=args.chains, cores=min(args.chains, 2),
                          seed=args.seed, progress_bar=False)
    wall = time.perf_counter() - t0 + setup.setup_s
    cpu = cpu_seconds() - c0
    x = np.asarray(trace.posterior["x"].values)
    stats = trace.sample_stats
    return diagnose("nutpie", constrained_draws(setup, x), np.asarray(stats["n_steps"].values),
                    np.asarray(stats["diverging"].values), wall, cpu, compile_s,
                    {"warmup": args.peer_warmup, "includes": "LSQ start + jit of value_and_grad + nutpie (diagonal mass from gradients)"})


def stan_check(setup: Setup, posterior, data) -> dict:
    """Stan's log density against ours at the LSQ start, the MAP and two Laplace draws:
    differences from the first point must agree (Stan drops normalising constants)."""
    rng = np.random.default_rng(3)
    pts = [setup.flat0, setup.flat_map] + [setup.flat_map + setup.chol @ rng.standard_normal(setup.flat0.size) for _ in range(2)]
    ours = np.array([float(setup.logdensity(jnp.asarray(p))) for p in pts])
    lin = np.linalg.solve(data["L"], np.stack([p - data["shift"] for p in pts]).T).T
    stan = np.array([posterior.log_prob(list(map(float, u)), adjust_transform=True) for u in lin])
    diff = (stan - stan[0]) - (ours - ours[0])
    return {"points": len(pts), "max_abs_difference_of_differences": float(np.max(np.abs(diff))),
            "ours": ours.round(6).tolist(), "stan": stan.round(6).tolist()}


def run_stan(setup: Setup, args, whitened: bool) -> dict:
    import stan

    name = "stan_whitened" if whitened else "stan_default"
    warm = args.warmup if whitened else args.peer_warmup
    data = stan_data(setup, whitened)
    c0, t0 = cpu_seconds(), time.perf_counter()
    posterior = stan.build(STAN_PROGRAM, data=data, random_seed=args.seed)
    compile_s = time.perf_counter() - t0
    check = stan_check(setup, posterior, data)
    if check["max_abs_difference_of_differences"] > 1e-6 * max(1.0, np.max(np.abs(check["ours"]))):
        raise RuntimeError(f"Stan's log density differs from ours: {check}")
    t1 = time.perf_counter()
    if whitened:
        rng = np.random.default_rng(args.seed)
        inits = [{"u": rng.standard_normal(setup.flat0.size).tolist()} for _ in range(args.chains)]
    else:
        inits = [{"u": x.tolist()} for x in start_points(setup, args.chains, args.seed)]
    fit = posterior.sample(num_chains=args.chains, num_samples=args.draws, num_warmup=warm, init=inits)
    sample_s = time.perf_counter() - t1
    wall = time.perf_counter() - t0 - (t1 - t0 - compile_s) + setup.setup_s + (setup.map_s if whitened else 0.0)
    cpu = cpu_seconds() - c0
    u = np.asarray(fit["u"])  # [D, draws * chains], the chains one after another
    draws = u.T.reshape(args.chains, args.draws, -1)
    x = data["shift"][None, None, :] + np.einsum("cdj,ij->cdi", draws, data["L"])
    steps = np.asarray(fit["n_leapfrog__"]).reshape(args.chains, args.draws)
    div = np.asarray(fit["divergent__"]).reshape(args.chains, args.draws)
    return diagnose(name, constrained_draws(setup, x), steps, div, wall, cpu, compile_s,
                    {"warmup": warm, "sample_s": round(sample_s, 2), "log_density_check": check,
                     "includes": ("LSQ start + " + ("MAP/Laplace + " if whitened else "") +
                                  "Stan C++ compile (httpstan cache cleared first unless --stan-warm-cache) + sampling; "
                                  "the log-density check is not counted")})


# ----------------------------------------------------------------------------------------------

SAMPLERS = {
    "ours": run_ours,
    "ours_diag": lambda s, a: run_ours(s, a, mass_matrix="diag"),  # Stan's diagonal metric, in our whitened space
    "blackjax_window": run_blackjax_window,
    "blackjax_meads": run_blackjax_meads,
    "blackjax_meads_whitened": lambda s, a: run_blackjax_meads(s, a, whitened=True),
    "blackjax_chees": run_blackjax_chees,
    "blackjax_chees_whitened": lambda s, a: run_blackjax_chees(s, a, whitened=True),
    "nutpie": run_nutpie,
    "stan_default": lambda s, a: run_stan(s, a, whitened=False),
    "stan_whitened": lambda s, a: run_stan(s, a, whitened=True),
}


def machine() -> dict:
    return {"cpu_count": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
            "jax": jax.__version__, "load_average_1_5_15": [round(x, 2) for x in os.getloadavg()]}


def render(records: list[dict], meta: dict) -> str:
    ours = next((r for r in records if r.get("sampler") == "ours" and "error" not in r), None)
    lines = [BEGIN, "## Peers", "",
             f"Generated by `benchmarks/peers.py` ({meta['date']}): {meta['pairs']} pairs ({2 * meta['pairs']} runs) at "
             f"thesis case 14 conditions, basic drag model, model four_term pooled, integrated noise; "
             f"{meta['chains']} chains x {meta['draws']} draws for every sampler (MEADS and ChEES run "
             f"{meta['meads_chains']} chains, as their cross-chain adaptation needs).  Min ESS is the min bulk ESS (arviz) over AD, BD, CD0, KD, "
             "the per-run noise sigma and q; ESS/s divides it by the wall time including compilation and the "
             "common LSQ start (and the MAP for the whitened samplers).  Process CPU s: the sampler's whole process "
             "(imports, set-up, compilation, sampling, children included).  Each sampler runs in its own process "
             "(cold compilation caches) under a time limit of "
             f"{meta['timeout_s']:.0f} s; default-adaptation peers start from the least-squares start (jittered), "
             "ours and whitened Stan from draws of the Laplace approximation.", "",
             f"Machine: {meta['machine']['cpu_count']} cores, {meta['machine']['platform']}; 1-min load average "
             f"{meta['load_before'][0]} before and {meta['load_after'][0]} after the latest run (`--only` reruns "
             "some samplers: each row is that sampler's latest record; load: the 1-min load average when its "
             "process started, where recorded)."]
    loads = [r["load_average_1min_at_start"] for r in records if "load_average_1min_at_start" in r]
    if max([meta["load_before"][0], meta["load_after"][0], *loads]) > 2:
        lines += ["", "**Wall times were measured under load** (the machine was shared; load average above 2 on "
                      "2 cores): compare the CPU seconds too, and rerun on a quiet machine for the record."]
    lines += ["", "| sampler | warm-up | wall s | process CPU s | compile s | min ESS | ESS/s | vs ours | max R-hat | divergences | steps/draw | load |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in records:
        load = r.get("load_average_1min_at_start", "")
        if "error" in r:
            bound = r.get("min_ess_per_s_upper_bound")
            if bound and r["sampler"].startswith(ENSEMBLE):  # all chains' draws, not --chains'
                bound = round(meta["meads_chains"] * meta["draws"] / r.get("timeout_s", meta["timeout_s"]), 3)
            vs = "" if ours is None or not bound else f">= {ours['min_ess_per_s'] / bound:.1f}x"
            ess = "" if not bound else f"<= {bound}"
            lines.append(f"| {r['sampler']} | | not run: {r['error']} | {r.get('process_cpu_s', '')} | | | {ess} | {vs} "
                         f"| | | | {load} |")
            continue
        vs = "" if ours is None else f"{ours['min_ess_per_s'] / max(r['min_ess_per_s'], 1e-12):.1f}x"
        lines.append(f"| {r['sampler']} | {r['warmup']} | {r['wall_s']} | {r.get('process_cpu_s', r['cpu_s'])} | {r['compile_s'] if r['compile_s'] is not None else '-'} | "
                     f"{r['min_ess_bulk']} | {r['min_ess_per_s']} | {vs} | {r['max_r_hat']:.4g} | {r['divergences']} | "
                     f"{r['mean_leapfrog_steps']} | {load} |")
    lines += ["", "\"vs ours\" is ours' ESS/s over the peer's (above 1: ours is faster); for a sampler stopped at "
              "the time limit, its ESS/s is at most all its draws over the limit, so ours leads by at least the "
              "ratio shown.  Stan's log density is checked against ours before timing (records: "
              "`log_density_check`).  Records: `benchmarks/records/peers/`.", END]
    return "\n".join(lines) + "\n"


def write_doc(block: str) -> None:
    DOC.parent.mkdir(parents=True, exist_ok=True)
    text = DOC.read_text() if DOC.exists() else "# Performance\n\n"
    if BEGIN in text and END in text:
        head, rest = text.split(BEGIN, 1)
        text = head + block + rest.split(END, 1)[1].lstrip("\n")
    else:
        text = text.rstrip("\n") + "\n\n" + block
    DOC.write_text(text)


def run_worker(name: str, args) -> dict:
    """One sampler in this process: set-up (its own compilation), sampling, record."""
    setup = build_setup(args.pairs)
    load = os.getloadavg()[0]
    try:
        rec = SAMPLERS[name](setup, args)
    except Exception as exc:  # noqa: BLE001  (a peer that cannot run is reported, not hidden)
        traceback.print_exc()
        rec = {"sampler": name, "error": f"{type(exc).__name__}: {str(exc).splitlines()[0][:200] if str(exc) else ''}"}
    rec.update(pairs=args.pairs, load_average_1min_at_start=round(load, 2), unconstrained_dim=int(setup.flat0.size),
               samples_per_run_mean=round(float(np.asarray(setup.problem.batch.mask).sum(axis=1).mean()), 1))
    return rec


def stored_records(pairs: int) -> list[dict]:
    """Every sampler's latest record at this campaign size (``--only`` reruns some)."""
    return [json.loads(f.read_text()) for n in SAMPLERS if (f := RECORDS / f"pairs{pairs}_{n}.json").exists()]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=18)
    ap.add_argument("--chains", type=int, default=config.DEFAULT_SAMPLER.num_chains)
    ap.add_argument("--warmup", type=int, default=config.DEFAULT_SAMPLER.num_warmup, help="ours and whitened Stan")
    ap.add_argument("--peer-warmup", type=int, default=1000, help="default-adaptation peers (their default length)")
    ap.add_argument("--draws", type=int, default=config.DEFAULT_SAMPLER.num_samples)
    ap.add_argument("--meads-chains", type=int, default=8, help="chains of the ensemble samplers (MEADS, ChEES)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", nargs="+", choices=list(SAMPLERS), default=list(SAMPLERS))
    ap.add_argument("--timeout-s", type=float, default=3600.0,
                    help="per sampler; one that does not finish is recorded as such")
    ap.add_argument("--stan-warm-cache", action="store_true", help="keep httpstan's compiled-model cache")
    ap.add_argument("--no-doc", action="store_true")
    ap.add_argument("--render-only", action="store_true", help="regenerate the doc from the stored records")
    ap.add_argument("--worker", choices=list(SAMPLERS), help=argparse.SUPPRESS)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    if args.worker:
        print("RECORD " + json.dumps(run_worker(args.worker, args)), flush=True)
        return
    if args.render_only:
        write_doc(render(stored_records(args.pairs), json.loads((RECORDS / f"pairs{args.pairs}_meta.json").read_text())))
        return
    if not args.stan_warm_cache and any(s.startswith("stan") for s in args.only):
        try:
            import httpstan.cache
            import httpstan.models
            httpstan.cache.delete_model_directory(httpstan.models.calculate_model_name(STAN_PROGRAM))
        except Exception:  # noqa: BLE001  (no cached model, or no httpstan)
            pass
    load_before = [round(x, 2) for x in os.getloadavg()]
    RECORDS.mkdir(parents=True, exist_ok=True)
    records = []
    passthrough = [a for a in sys.argv[1:] if a not in ("--no-doc",)]
    for name in args.only:
        print(f"[peers] {name} ...", file=sys.stderr, flush=True)
        # each sampler in its own process: cold compilation caches, a time limit, CPU time of its tree
        cmd = [sys.executable, __file__, *passthrough, "--worker", name]
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        load = round(os.getloadavg()[0], 2)
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
        try:
            stdout, stderr = proc.communicate(timeout=args.timeout_s)
            lines = [ln for ln in stdout.splitlines() if ln.startswith("RECORD ")]
            rec = json.loads(lines[-1][7:]) if lines else {
                "sampler": name, "error": f"worker exited {proc.returncode}: {stderr.strip().splitlines()[-1][:200] if stderr.strip() else ''}"}
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)  # the worker and its samplers' processes (Stan's chains)
            proc.communicate()
            chains = args.meads_chains if name.startswith(ENSEMBLE) else args.chains
            rec = {"sampler": name, "error": f"did not finish within {args.timeout_s:.0f} s", "timeout_s": args.timeout_s,
                   "min_ess_per_s_upper_bound": round(chains * args.draws / args.timeout_s, 3)}
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        rec.setdefault("load_average_1min_at_start", load)
        rec.update(pairs=args.pairs, process_wall_s=round(time.perf_counter() - t0, 2),
                   process_cpu_s=round((r1.ru_utime + r1.ru_stime) - (r0.ru_utime + r0.ru_stime), 2))
        records.append(rec)
        print(json.dumps(rec), file=sys.stderr, flush=True)
        (RECORDS / f"pairs{args.pairs}_{name}.json").write_text(json.dumps(rec, indent=2) + "\n")
    meta = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "pairs": args.pairs, "chains": args.chains,
            "draws": args.draws, "warmup": args.warmup, "peer_warmup": args.peer_warmup,
            "meads_chains": args.meads_chains, "timeout_s": args.timeout_s, "machine": machine(),
            "load_before": load_before, "load_after": [round(x, 2) for x in os.getloadavg()]}
    (RECORDS / f"pairs{args.pairs}_meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    if not args.no_doc:  # every sampler's latest record at this campaign size (--only reruns some)
        write_doc(render(stored_records(args.pairs), meta))
    print(json.dumps({"meta": meta, "records": records}, indent=2))


if __name__ == "__main__":
    main()
