"""Where a fit's divergent draws sit: thesis case C at ``--pairs`` pairs (one by default), the
model ``--model`` (``four_term`` unless given) and the default likelihood, no retry, at a given target acceptance; per coordinate the mean
percentile of the divergent draws among all draws and the share below the 10th percentile.  For
every positive site sampled through numpyro's log transform (noise scales, run-to-run spreads)
the record also holds the skewness of its log draws and their sd over the Laplace sd
(``log_shape``), and with ``--profile`` the potential energy along that log coordinate from the
MAP, the other coordinates held at the MAP (``profile``: offsets -8..8 in log units).

    python benchmarks/divergence_probe.py --case 9 --target-accept 0.8
    python benchmarks/divergence_probe.py --case 18 --target-accept 0.8 0.9 0.95
    python benchmarks/divergence_probe.py --case 1 --pairs 6 --pooling hierarchical \
        --target-accept 0.8 0.9 --sampler-seeds 0 1 --profile

Records (JSON lines): ``benchmarks/records/gates/divergence_probe.jsonl``, with the commit.  The
figures of docs/method.md 4.5 and docs/calibration.md's gate section came from this probe: those
"before" the softplus for truncated priors were measured at commit 0fd1b39 (exp transform).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload import config  # noqa: E402
from bayes_roadload.inference.nuts import fit_nuts  # noqa: E402
from bayes_roadload.simulate import simulate_campaign  # noqa: E402

RECORDS = ROOT / "benchmarks" / "records" / "gates" / "divergence_probe.jsonl"


def probe(case: int, target_accept: float, seed: int = 0, noise: str = "integrated", pairs: int = 1,
          pooling: str = "pooled", sampler_seed: int = 0, profile: bool = False, model: str = "four_term",
          noise_scaled_metric: bool = False) -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        campaign = simulate_campaign(case, pairs=pairs, seed=seed)
        sampler = dataclasses.replace(config.DEFAULT_SAMPLER, retry=False, target_accept=target_accept,
                                      small_campaign_target_accept=None, quiet_trace_target_accept=None,
                                      seed=sampler_seed, noise_scaled_metric=noise_scaled_metric)
        fit = fit_nuts(campaign, model, sampler=sampler, noise=noise, pooling=pooling)
    div = np.asarray(fit.stats["diverging"]).reshape(-1)
    where = {}
    for name, value in fit.samples.items():
        a = np.asarray(value)
        a = a.reshape(a.shape[0] * a.shape[1], -1)
        for j in range(a.shape[1]):
            pct = (np.argsort(np.argsort(a[:, j])) + 0.5) / a.shape[0]
            where[f"{name}[{j}]"] = {"mean_pct": float(pct[div].mean()) if div.any() else None,
                                     "below_p10": float(np.mean(pct[div] < 0.1)) if div.any() else None}
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    rec = {"case": case, "seed": seed, "pairs": pairs, "pooling": pooling, "sampler_seed": sampler_seed, "model": model,
           "noise_scaled_metric": noise_scaled_metric,
           "noise": noise, "target_accept": target_accept, "commit": commit,
           "divergences": int(div.sum()), "steps_per_draw": float(np.mean(fit.stats["num_steps"])),
           "divergent_draws": where, "log_shape": log_shape(fit)}
    if profile:
        rec["profile"] = log_profiles(fit.problem, fit.map)
    return rec


def _log_sites(z_map: dict, constrained: dict) -> list[str]:
    """Sites whose unconstrained value is the log of the constrained one (numpyro's exp
    transform of a positive support), read off the MAP: exp(z) equals the constrained value."""
    return [k for k, z in z_map.items() if k in constrained and np.shape(constrained[k]) == np.shape(z)
            and np.allclose(np.exp(np.asarray(z, float)), np.asarray(constrained[k], float), rtol=1e-9, atol=0.0)]


def log_shape(fit) -> dict:
    """Per positive site and element: skewness of the log draws, and their sd over the Laplace
    sd of that coordinate at the MAP."""
    import jax.numpy as jnp
    from jax.flatten_util import ravel_pytree

    z = fit.map.z
    sd_map = np.sqrt(np.diag(fit.map.cov))
    # each site's positions in the flat vector, in ravel_pytree's own order (a leaf is row-major)
    ids = {k: i for i, k in enumerate(z)}
    flat_id = np.asarray(ravel_pytree({k: jnp.full(np.shape(v), float(ids[k])) for k, v in z.items()})[0])
    out = {}
    for k in _log_sites(z, fit.map.constrained):
        a = np.log(np.asarray(fit.samples[k]))
        a = a.reshape(a.shape[0] * a.shape[1], -1)
        for j, i in enumerate(np.flatnonzero(flat_id == ids[k])):
            x = a[:, j]
            skew = float(np.mean((x - x.mean()) ** 3) / x.std() ** 3)
            out[f"{k}[{j}]"] = {"skew": round(skew, 3), "sd_over_laplace": round(float(x.std() / sd_map[i]), 3)}
    return out


def log_profiles(problem, map_result) -> dict:
    """Potential energy (minus its value at the MAP) along each positive site's log coordinate
    (first element of a per-run site), every other coordinate at the MAP."""
    import jax

    from bayes_roadload.inference.nuts import unconstrained_posterior

    post = unconstrained_posterior(problem, map_result.constrained)
    u = jax.jit(post.potential_fn)
    u0 = float(u(map_result.z))
    grid = [-8, -6, -4, -3, -2, -1, -0.5, 0.5, 1, 2, 3, 4, 5, 6, 7, 8]
    out = {}
    for k in _log_sites(map_result.z, map_result.constrained):
        vals = []
        for d in grid:
            z = dict(map_result.z)
            z[k] = z[k].at[0].add(d) if np.ndim(z[k]) else z[k] + d
            vals.append(round(float(u(z)) - u0, 4))
        out[k] = {"offsets": grid, "potential": vals}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", type=int, required=True)
    ap.add_argument("--target-accept", type=float, nargs="+", default=[0.8])
    ap.add_argument("--noise", default="integrated", choices=("integrated", "white"))
    ap.add_argument("--pairs", type=int, default=1)
    ap.add_argument("--pooling", default="pooled", choices=("pooled", "hierarchical"))
    ap.add_argument("--sampler-seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--model", default="four_term", help="model variant (default four_term, as the records before the option)")
    ap.add_argument("--noise-scaled-metric", action="store_true", help="SamplerConfig.noise_scaled_metric on")
    ap.add_argument("--profile", action="store_true", help="the potential along each positive site's log coordinate")
    a = ap.parse_args(argv)
    RECORDS.parent.mkdir(parents=True, exist_ok=True)
    first = True
    for ta in a.target_accept:
        for sampler_seed in a.sampler_seeds:
            rec = probe(a.case, ta, noise=a.noise, pairs=a.pairs, pooling=a.pooling, sampler_seed=sampler_seed,
                        profile=a.profile and first, model=a.model,
                        noise_scaled_metric=a.noise_scaled_metric)
            first = False
            with RECORDS.open("a") as f:
                f.write(json.dumps(rec) + "\n")
            print(f"case {a.case}, {a.pairs} pairs {a.pooling}, sampler seed {sampler_seed} at {ta}: "
                  f"{rec['divergences']} divergences, {rec['steps_per_draw']:.1f} steps per draw", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
