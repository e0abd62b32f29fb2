"""Type B sensitivities of a speed-trace fit from the posterior instead of least squares: one
Newton step of the posterior mode per shifted campaign, against the least-squares step that
``fit`` uses (:func:`bayes_roadload.inference.lsq.linear_sensitivities`).

For a campaign of the independent simulator (design seeds, every effect, Type B errors) and a
model (hierarchical, as ``fit``'s default pooling at these sizes): the MAP of the prepared
problem with its Laplace covariance ``Sigma`` (:func:`bayes_roadload.inference.nuts.find_map`);
for each Type B source the campaign shifted by +-u, its problem linearised at that MAP, the
gradient ``g`` of its potential at the MAP (one compilation shared by all shifted campaigns,
:class:`bayes_roadload.inference.shift.SharedPotential`), the step ``dz = -Sigma g`` (implicit
function theorem at the mode: the posterior's own curvature, priors included), every quantity
at ``z_MAP + dz``, and central differences.  One JSON line per (seed, pairs, model): the Type B
standard uncertainty ``sqrt(sum_s (c_s u_s)^2)`` of each quantity both ways, the truth, and the
times.

    python benchmarks/type_b_newton_step.py --models four_term_tyre_lag \
        > benchmarks/records/type_b_newton_step.jsonl

``--lsq-only`` records the least-squares step alone (what ``fit`` uses), e.g. for a model whose
coefficient least squares hardly identifies::

    python benchmarks/type_b_newton_step.py --lsq-only > benchmarks/records/type_b_lsq_step.jsonl
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import warnings
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from numpyro.infer.util import constrain_fn

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.analysis.budget import type_b_shifts  # noqa: E402
from bayes_roadload.inference.bayes import build_problem, linearise_run_effects, run_effect_means  # noqa: E402
from bayes_roadload.inference.lsq import linear_sensitivities  # noqa: E402
from bayes_roadload.inference.nuts import find_map, prepare_problem  # noqa: E402
from bayes_roadload.inference.shift import SharedPotential, quantities_at  # noqa: E402
from bayes_roadload.inference.spec import load_model_spec  # noqa: E402
from bayes_roadload.simulate.independent import simulate_independent  # noqa: E402

QUANTITIES = ("AD", "BD", "CD0", "KD", "F50_N", "F0_N", "F1_N_per_kph", "F2_N_per_kph2")


def newton_step_sensitivities(campaign, spec, shifts, pooling="hierarchical"):
    """Source -> quantity -> dx/ds from one Newton step of the posterior mode (module
    docstring), and the seconds spent (MAP, steps)."""
    t0 = time.perf_counter()
    problem, init = prepare_problem(build_problem(campaign, spec, pooling=pooling), campaign)
    mode = find_map(problem, init)
    t_map = time.perf_counter() - t0
    means = run_effect_means(problem, mode.constrained) if problem.varying else None
    shared = SharedPotential(problem, mode)
    x0 = shared.y0 * shared.scale
    t1 = time.perf_counter()
    out = {}
    for key, (plus, minus, h) in shifts.items():
        values = []
        for shifted_campaign in (plus, minus):
            shifted = build_problem(shifted_campaign, spec, pooling=pooling)
            if problem.varying:
                shifted = linearise_run_effects(shifted, mode.constrained, means)
            grad_y = shared.gradient_at_start(shifted)
            if grad_y is None:
                break
            dx = -np.asarray(mode.cov) @ (grad_y / shared.scale)
            z = shared.unravel(jnp.asarray(x0 + dx))
            constrained = constrain_fn(shifted.numpyro_model, (shifted,), {}, z, return_deterministic=True)
            values.append(quantities_at(shifted, constrained))
        if len(values) == 2:
            out[key] = {q: (values[0][q] - values[1][q]) / (2.0 * h) for q in values[0] if q in values[1]}
    return out, t_map, time.perf_counter() - t1


def type_b_sd(rows, u):
    return {q: math.sqrt(sum((row[q] * u[s]) ** 2 for s, row in rows.items() if q in row)) for q in QUANTITIES}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[100, 101, 102, 103, 104, 105])
    ap.add_argument("--pairs", type=int, nargs="+", default=[3])
    ap.add_argument("--models", nargs="+", default=["four_term_tyre_lag", "four_term_tyre_lag_saturating"])
    ap.add_argument("--lsq-only", action="store_true", help="the least-squares step alone")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    for pairs in args.pairs:
        for seed in args.seeds:
            campaign = simulate_independent(seed, pairs=pairs)
            for name in args.models:
                spec = load_model_spec(name)
                u, shifts, _ = type_b_shifts(campaign, spec)
                t0 = time.perf_counter()
                _, lsq_rows = linear_sensitivities(campaign, spec, shifts)
                t_lsq = time.perf_counter() - t0
                rec = {"seed": seed, "pairs": pairs, "model": name,
                       "truth": {q: campaign.truth.get(q) for q in QUANTITIES}, "sources": len(shifts),
                       "type_b_sd_lsq": type_b_sd(lsq_rows, u), "time_lsq_s": t_lsq}
                if not args.lsq_only:
                    newton_rows, t_map, t_steps = newton_step_sensitivities(campaign, spec, shifts)
                    rec.update(sources_newton=len(newton_rows), type_b_sd_newton=type_b_sd(newton_rows, u),
                               time_map_s=t_map, time_steps_s=t_steps)
                print(json.dumps(rec), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
