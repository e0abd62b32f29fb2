"""Is the data of an exact-SBC campaign as likely at its truth as the likelihood says it should be?

For each ``--seeds`` campaign of the tyre-lag default's exact SBC arm
(:class:`~bayes_roadload.analysis.sbc.ModelDrawnCampaign`, 2 pairs, the records
``benchmarks/records/sbc/lag_exact_part*.csv``), the fit of the study (NUTS, pooled, integrated
noise, default sampler) is repeated and the campaign's log likelihood
(:func:`~bayes_roadload.inference.bayes.run_log_likelihood` plus the driveline channel's) is
evaluated at the truth -- the coefficients, each run's initial speed and noise, the integrated
noise's intensity q and the driveline noise it was drawn with -- and at every 10th posterior
draw.  Under the exact likelihood twice the gap between the maximum likelihood and the truth's
is about chi-square with as many degrees of freedom as the likelihood has parameters (18 here:
8 coefficients, 4 initial speeds, 4 speed noises, q, the driveline noise), so the gap of the
best draw (a lower bound of that one) is about 9 nats on average, above 17 in 1 % of campaigns
and above 21 in 0.1 %.  Also recorded: the speed log likelihood at the true coefficients with
q scaled (its profile in q), and the posterior of q and C_D0 against their truths.

The committed records: ``--seeds 124 46 0 1 2``, then ``--seeds 3 4`` (124 and 46: the
arm's largest |z| of C_D0; 0-4: not chosen)::

    python benchmarks/sbc_truth_likelihood.py --seeds 124 46 0 1 2 \\
        --records benchmarks/records/sbc/truth_likelihood.jsonl

``--noise-only`` (no fit, :func:`drawn_noise_profile`): the residual at the truth against the
noise the draw added, and the q profile of that noise alone::

    python benchmarks/sbc_truth_likelihood.py --noise-only --seeds 46 24 124 16 0 1 2 3 4 \\
        --records benchmarks/records/sbc/drawn_noise_profile.jsonl
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

MODEL = "four_term_tyre_lag_driveline_informative"
Q_FACTORS = (0.25, 0.5, 0.75, 1.0, 1.5)


def truth_likelihood(seed: int, pairs: int = 2, every: int = 10, model: str = MODEL) -> dict:
    """The record of one campaign (module docstring)."""
    import jax.numpy as jnp

    from bayes_roadload.analysis.sbc import ModelDrawnCampaign, PriorDrawnCampaign
    from bayes_roadload.inference.bayes import build_problem, driveline_log_likelihood, run_log_likelihood
    from bayes_roadload.inference.nuts import fit_nuts
    from bayes_roadload.inference.results import diagnostics, summary_table, to_inference_data

    campaign = ModelDrawnCampaign(seed, pairs=pairs, model=model)()
    # the initial speeds the draw started from: the template's first logged speeds (ModelDrawnCampaign)
    first = np.asarray(PriorDrawnCampaign(seed, pairs=pairs, model=model)().to_batch()[0].speed_mps)[:, 0]
    problem = dataclasses.replace(build_problem(campaign, model), apparent=None)  # A_D, B_D, C_D0 directly
    t = campaign.truth
    truth = {k: jnp.asarray(t[k]) for k in problem.free}
    truth.update(v0_mps=jnp.asarray(first), sigma_mps=jnp.asarray(t["sigma_mps"]),
                 q_mps_per_sqrt_s=jnp.asarray(t["q_mps_per_sqrt_s"]))

    def loglik(sample: dict, sigma_d: float) -> tuple[float, float]:
        speed = float(run_log_likelihood(problem, sample).sum())
        drive = float(driveline_log_likelihood(problem, sample, sigma_d)) if problem.driveline_channel else 0.0
        return speed, drive

    sigma_d = float(t.get("sigma_driveline_n", 1.0))
    at_truth = loglik(truth, sigma_d)
    profile = {f"{f:g}": loglik(dict(truth, q_mps_per_sqrt_s=jnp.asarray(t["q_mps_per_sqrt_s"] * f)), sigma_d)[0]
               for f in Q_FACTORS}
    t0 = time.perf_counter()
    fit = fit_nuts(campaign, model, pooling="pooled", noise="integrated")
    draws = {k: np.asarray(v).reshape(-1, *np.shape(v)[2:]) for k, v in fit.samples.items()}
    sites = list(problem.free) + ["v0_mps", "sigma_mps", "q_mps_per_sqrt_s"]
    at_draws = np.array([loglik({k: jnp.asarray(draws[k][i]) for k in sites},
                                float(draws["sigma_driveline_n"][i]) if "sigma_driveline_n" in draws else sigma_d)
                         for i in range(0, draws["CD0"].shape[0], every)])
    best = int(np.argmax(at_draws.sum(axis=1)))
    out = {"seed": seed, "pairs": pairs, "model": model, "time_fit_s": round(time.perf_counter() - t0, 1),
           "loglik_truth_speed": at_truth[0], "loglik_truth_driveline": at_truth[1],
           "loglik_best_draw_speed": float(at_draws[best, 0]), "loglik_best_draw_driveline": float(at_draws[best, 1]),
           "loglik_median_draw": float(np.median(at_draws.sum(axis=1))),
           "best_draw_minus_truth": float(at_draws[best].sum() - sum(at_truth)),
           "q_profile_speed_loglik_at_true_coefficients": profile}
    for name in ("CD0", "q_mps_per_sqrt_s", "tyre_lag_gain_per_mps"):
        x = draws[name]
        out[name] = {"truth": float(t[name]), "mean": float(x.mean()), "sd": float(x.std()),
                     "q2.5": float(np.quantile(x, 0.025)), "q97.5": float(np.quantile(x, 0.975)),
                     "z": float((x.mean() - t[name]) / x.std()), "share_below_truth": float((x < t[name]).mean())}
    out["corr_log_q_CD0"] = float(np.corrcoef(np.log(draws["q_mps_per_sqrt_s"]), draws["CD0"])[0, 1])
    idata = to_inference_data(fit, predictive=False)
    out["gates_passed"] = bool(diagnostics(fit, idata, summary_table(fit, idata))["pass"])
    return out


def drawn_noise_profile(seed: int, pairs: int = 2, model: str = MODEL) -> dict:
    """``--noise-only``: is the residual at the truth the noise the draw added, and how likely is
    that noise under its own q?  Draws the campaign as :func:`truth_likelihood` does, keeping the
    noise :class:`~bayes_roadload.analysis.sbc.ModelDrawnCampaign` adds (white plus integrated),
    and records the largest difference between the fit's residual at the truth and that noise,
    and the q profiles (factors :data:`Q_FACTORS` of the true q, the drawn sigmas held) of the
    residual's and of the noise's own log likelihood
    (:func:`~bayes_roadload.physics.residuals.local_level_loglik`).  No fit."""
    import jax.numpy as jnp

    from bayes_roadload import config
    from bayes_roadload.analysis import sbc
    from bayes_roadload.inference.bayes import build_problem, speed_residuals
    from bayes_roadload.physics.residuals import local_level_loglik

    kept: dict = {}
    drawn_speed = sbc.drawn_speed

    def keeping(problem, params, noise, *args, **kwargs):
        kept["noise"] = np.array(noise)
        return drawn_speed(problem, params, noise, *args, **kwargs)

    sbc.drawn_speed = keeping
    try:
        campaign = sbc.ModelDrawnCampaign(seed, pairs=pairs, model=model)()
    finally:
        sbc.drawn_speed = drawn_speed
    first = np.asarray(sbc.PriorDrawnCampaign(seed, pairs=pairs, model=model)().to_batch()[0].speed_mps)[:, 0]
    problem = dataclasses.replace(build_problem(campaign, model), apparent=None)
    t = campaign.truth
    truth = {k: jnp.asarray(t[k]) for k in problem.free}
    truth.update(v0_mps=jnp.asarray(first), sigma_mps=jnp.asarray(t["sigma_mps"]),
                 q_mps_per_sqrt_s=jnp.asarray(t["q_mps_per_sqrt_s"]))
    residual = np.asarray(speed_residuals(problem, truth))
    b = problem.batch
    mask = np.asarray(b.mask, bool)
    sigma = np.sqrt(np.asarray(t["sigma_mps"]) ** 2 + config.SPEED_NOISE_FLOOR_MPS ** 2)

    def profile(x: np.ndarray) -> dict[str, float]:
        return {f"{f:g}": float(sum(local_level_loglik(jnp.asarray(x[r]), b.time_s[r], b.mask[r], sigma[r],
                                                       t["q_mps_per_sqrt_s"] * f) for r in range(x.shape[0])))
                for f in Q_FACTORS}

    noise, res = profile(kept["noise"]), profile(residual)
    return {"seed": seed, "pairs": pairs, "model": model, "noise_only": True,
            "max_abs_residual_minus_noise_mps": float(np.max(np.abs(residual - kept["noise"])[mask])),
            "q_truth": float(t["q_mps_per_sqrt_s"]), "sigma_mps": [float(x) for x in sigma],
            "q_profile_noise_loglik": noise, "q_profile_residual_loglik": res,
            "q_factor_best_noise": float(max(noise, key=noise.get))}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", required=True)
    p.add_argument("--records", type=Path, required=True, help="JSON lines, one per seed (appended)")
    p.add_argument("--noise-only", action="store_true",
                   help="no fit: the residual at the truth against the drawn noise (drawn_noise_profile)")
    p.add_argument("--model", default=MODEL, help="the SBC arm's model (default: the tyre-lag arm's)")
    a = p.parse_args()
    import jax

    a.records.parent.mkdir(parents=True, exist_ok=True)
    for seed in a.seeds:
        rec = drawn_noise_profile(seed, model=a.model) if a.noise_only else truth_likelihood(seed, model=a.model)
        # each campaign has its own shapes: without this, one process reached the kernel's limit
        # of memory mappings on the sixth seed (LLVM: "Cannot allocate memory")
        jax.clear_caches()
        rec["date"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
        with a.records.open("a") as f:
            f.write(json.dumps(rec) + "\n")
        print(json.dumps(rec))


if __name__ == "__main__":
    main()
