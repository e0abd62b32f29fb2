"""The sampler's geometry on the cold-start reference campaign: leapfrog steps per draw, the
adapted step size and metric, and min bulk ESS per 1000 gradient evaluations, for the softness
of the softplus coordinate of a truncated prior whose posterior reaches its bound
(``spec.SOFTPLUS_FRACTION_AT_BOUND``, applied by ``nuts.soften_bounds``: K_D in calm air; 0.05,
the default softness, is the coordinate before the bound was widened) and the mass matrix
adapted in the Laplace-whitened coordinates (``SamplerConfig.mass_matrix``).

The campaign is ``benchmarks/cold_start.py``'s: 18 pairs (36 runs) from the independent
simulator in calm air, ``four_term``, pooled, 2 chains x (300 + 1000) draws, one process, the
variants one after the other (each its own problem and MAP, since the softness changes the
unconstrained coordinates).  ESS per gradient does not depend on the machine's load; the wall
times do, and are recorded only to show the order of magnitude.

    python benchmarks/sampler_geometry.py [--variants 0.05:diag 0.3:identity ...] [--docs]

(a variant is SOFTNESS_AT_BOUND:METRIC, or ``gaussian``: NUTS on a standard Gaussian of the
reference's 77 dimensions, the steps per draw of a perfect whitening).

Records (JSON lines, with the commit): ``benchmarks/records/performance/sampler_geometry.jsonl``;
``--docs`` regenerates the section of ``docs/performance.md`` from them.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from doc_sections import replace_section  # noqa: E402
from gradient_cost import commit_of  # noqa: E402

RECORDS = ROOT / "benchmarks" / "records" / "performance" / "sampler_geometry.jsonl"
DOC = ROOT / "docs" / "performance.md"
BEGIN, END = "<!-- sampler_geometry: begin -->", "<!-- sampler_geometry: end -->"
DEFAULT_VARIANTS = ("0.05:diag", "0.05:identity", "0.3:diag", "0.3:identity", "1.0:identity")
REPORTED = ("AD", "BD", "CD0", "KD", "q_mps_per_sqrt_s", "sigma_mps", "v0_mps")


def run_variant(camp, softness: float, mass: str) -> dict:
    """Fit the campaign with the softness at the bound and the mass matrix given; the adapted
    step size and inverse mass matrix are read from numpyro's last state."""
    import arviz as az
    import numpyro.infer

    import bayes_roadload.inference.nuts as nuts
    from bayes_roadload import config

    made = []

    class CaptureMCMC(numpyro.infer.MCMC):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            made.append(self)

    original, nuts.MCMC = nuts.MCMC, CaptureMCMC
    original_softness, nuts.SOFTPLUS_FRACTION_AT_BOUND = nuts.SOFTPLUS_FRACTION_AT_BOUND, softness
    try:
        t0 = time.perf_counter()
        fit = nuts.fit_nuts(camp, "four_term", pooling="pooled",
                            sampler=dataclasses.replace(config.DEFAULT_SAMPLER, mass_matrix=mass, retry=False))
        wall = time.perf_counter() - t0
        problem = fit.problem
    finally:
        nuts.MCMC = original
        nuts.SOFTPLUS_FRACTION_AT_BOUND = original_softness
    state = made[-1].last_state.adapt_state
    inv_mass = np.asarray(state.inverse_mass_matrix)
    steps = np.asarray(fit.stats["num_steps"], float)
    ess = {}
    for k in REPORTED:
        a = np.asarray(fit.samples[k])
        ess[k] = float(np.nanmin(az.ess(az.convert_to_dataset({k: a}), method="bulk")[k].values))
    rhat = max(float(np.nanmax(az.rhat(az.convert_to_dataset({k: np.asarray(fit.samples[k])}))[k].values))
               for k in REPORTED)
    min_ess = min(ess.values())
    widened = sorted(k for k, v in problem.priors.items() if getattr(v, "softness", None) is not None)
    return {"softness_at_bound": softness, "widened": widened, "mass_matrix": mass, "steps_per_draw": float(steps.mean()),
            "step_size": [float(x) for x in np.atleast_1d(np.asarray(state.step_size))],
            "inverse_mass_range": [float(inv_mass.min()), float(inv_mass.max())],
            "divergences": int(np.sum(fit.stats["diverging"])), "min_ess_bulk": min_ess,
            "ess_bulk": {k: round(v) for k, v in ess.items()}, "max_r_hat": rhat,
            "ess_per_1000_gradients": 1000.0 * min_ess / float(steps.sum()),
            "warmup_s": fit.timings["warmup_s"], "sampling_s": fit.timings["sampling_s"], "wall_s": wall}


def gaussian_reference(n: int = 77) -> dict:
    """numpyro's NUTS on an n-dimensional standard Gaussian with the fit's draws, target
    acceptance and an adapted diagonal metric: the steps per draw of a perfectly whitened
    posterior of the reference's dimension (the row ``gaussian``)."""
    import jax
    import jax.numpy as jnp
    from numpyro.infer import MCMC, NUTS

    from bayes_roadload import config

    s = config.DEFAULT_SAMPLER
    mcmc = MCMC(NUTS(potential_fn=lambda u: 0.5 * jnp.sum(u**2), target_accept_prob=s.target_accept),
                num_warmup=s.num_warmup, num_samples=s.num_samples, num_chains=1, progress_bar=False)
    rows = []
    for chain in range(s.num_chains):
        t0 = time.perf_counter()
        mcmc.run(jax.random.PRNGKey(chain), init_params=jnp.zeros(n), extra_fields=("num_steps",))
        steps = np.asarray(mcmc.get_extra_fields()["num_steps"], float)
        rows.append((float(mcmc.last_state.adapt_state.step_size), steps, time.perf_counter() - t0))
    steps = np.concatenate([r[1] for r in rows])
    return {"softness_at_bound": None, "widened": [], "mass_matrix": f"gaussian ({n} dimensions)",
            "steps_per_draw": float(steps.mean()), "step_size": [r[0] for r in rows],
            "inverse_mass_range": [float("nan"), float("nan")], "divergences": 0, "min_ess_bulk": float("nan"),
            "ess_bulk": {}, "max_r_hat": float("nan"), "ess_per_1000_gradients": float("nan"),
            "warmup_s": 0.0, "sampling_s": sum(r[2] for r in rows), "wall_s": sum(r[2] for r in rows)}


def _num(x, fmt: str) -> str:
    """``x`` formatted, or '-' where the row has no such number (NaN)."""
    return "-" if x is None or x != x else format(x, fmt)


def _mass_range(pair) -> str:
    low, high = pair
    return "-" if low != low else f"{low:.2f}-{high:.2f}"


def markdown(rows: list[dict]) -> str:
    lines = ["", "Generated by `python benchmarks/sampler_geometry.py --docs` from "
             "`benchmarks/records/performance/sampler_geometry.jsonl`: the cold-start reference campaign "
             "(18 pairs, calm air, `four_term`, pooled; 77 unconstrained dimensions), 2 chains x (300 + 1000) draws, "
             "min bulk ESS over A_D, B_D, C_D0, K_D, q, sigma and v0.  Softness at the bound: the softplus scale, "
             "as a fraction of the prior's scale, of the parameters whose posterior reaches its bound (column "
             "'widened'; 0.05 is every other truncated prior's); metric: the mass matrix adapted in the "
             "Laplace-whitened coordinates.  ESS per 1000 gradients does not depend on the machine's load; the seconds do "
             "(the other core was busy for some rows).", "",
             "| date (UTC) | commit | softness at the bound | widened | metric | leapfrog steps per draw | step size | adapted inverse mass (min-max) "
             "| divergences | min bulk ESS | ESS per 1000 gradients | max R-hat | warm-up + sampling (s) |",
             "|" + "---|" * 13]
    for r in rows:
        soft = "-" if r["softness_at_bound"] is None else f"{r['softness_at_bound']:g}"
        lines.append(f"| {r['date']} | {r['commit']} | {soft} | {', '.join(r['widened']) or '-'} | "
                     f"{r['mass_matrix']} | "
                     f"{r['steps_per_draw']:.1f} | {'/'.join(f'{x:.2f}' for x in r['step_size'])} | "
                     f"{_mass_range(r['inverse_mass_range'])} | "
                     f"{r['divergences']} | {_num(r['min_ess_bulk'], '.0f')} | {_num(r['ess_per_1000_gradients'], '.0f')} | "
                     f"{_num(r['max_r_hat'], '.4f')} | {r['warmup_s'] + r['sampling_s']:.0f} |")
    return "\n".join(lines + ["", ""])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--variants", nargs="+", default=list(DEFAULT_VARIANTS),
                    help="SOFTNESS:METRIC pairs (metric one of dense, diag, identity), or 'gaussian'")
    ap.add_argument("--docs", action="store_true", help="regenerate the docs section from the records only")
    args = ap.parse_args()
    if not args.docs:
        from cold_start import REFERENCE_SEED, campaign

        from bayes_roadload.data import load_campaign

        with tempfile.TemporaryDirectory(prefix="sampler_geometry_") as tmp:
            path, _ = campaign(18, Path(tmp), 4.0, REFERENCE_SEED)
            camp = load_campaign(path)
            for v in args.variants:
                if v == "gaussian":
                    result = gaussian_reference()
                else:
                    softness, mass = v.split(":")
                    result = run_variant(camp, float(softness), mass)
                rec = {"date": time.strftime("%Y-%m-%d %H:%M", time.gmtime()), "commit": commit_of(ROOT), **result}
                print(json.dumps(rec), flush=True)
                RECORDS.parent.mkdir(parents=True, exist_ok=True)
                with RECORDS.open("a") as f:
                    f.write(json.dumps(rec) + "\n")
    rows = [json.loads(line) for line in RECORDS.read_text().splitlines() if line.strip()]
    replace_section(DOC, BEGIN, END, markdown(rows), heading="## The sampler's geometry")


if __name__ == "__main__":
    main()
