"""Type B sensitivities of a speed-trace fit from the posterior, against the least-squares step
(:func:`bayes_roadload.inference.lsq.linear_sensitivities`, what a campaign without a fit --
planning's floor -- still uses) and, with ``--refit``, against the shifted MAPs refitted.

For a campaign of the independent simulator (design seeds, every effect, Type B errors) and a
model (hierarchical, as ``fit``'s default pooling at these sizes): the MAP of the prepared
problem with its Laplace covariance (:func:`bayes_roadload.inference.nuts.find_map`); for each
Type B source the campaign shifted by +-u, its problem built as the fitted one and linearised
where the MAP puts each run; then what ``fit`` does
(:func:`bayes_roadload.inference.shift.newton_sensitivities`): one Newton step of the mode with
the noise scales and run-effect spreads held, kept where the potential is quadratic over it,
else the shifted MAPs; central differences.  One JSON line per (seed, pairs, model): the Type B
standard uncertainty ``sqrt(sum_s (c_s u_s)^2)`` of each quantity each way, the truth, and the
times.

    python benchmarks/type_b_newton_step.py --models four_term_tyre_lag --refit \
        > benchmarks/records/type_b_newton_step.jsonl

``--lsq-only`` records the least-squares step alone, e.g. for a model whose coefficient least
squares hardly identifies::

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

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.analysis.budget import type_b_shifts  # noqa: E402
from bayes_roadload.inference.bayes import build_problem  # noqa: E402
from bayes_roadload.inference.kinds import _shifted_trace_problems  # noqa: E402
from bayes_roadload.inference.lsq import linear_sensitivities  # noqa: E402
from bayes_roadload.inference.nuts import find_map, prepare_problem  # noqa: E402
from bayes_roadload.inference.shift import map_sensitivities, newton_sensitivities  # noqa: E402
from bayes_roadload.inference.spec import load_model_spec  # noqa: E402
from bayes_roadload.simulate.independent import simulate_independent  # noqa: E402

QUANTITIES = ("AD", "BD", "CD0", "KD", "F50_N", "F0_N", "F1_N_per_kph", "F2_N_per_kph2")


def fitted_mode(campaign, spec, pooling="hierarchical"):
    """The prepared problem and its MAP, as ``fit`` makes them before sampling."""
    problem, init = prepare_problem(build_problem(campaign, spec, pooling=pooling), campaign)
    return problem, find_map(problem, init)


def posterior_sensitivities(campaign, problem, mode, shifts, how="newton"):
    """Source -> quantity -> dx/ds from the posterior, the shifted problems built as ``fit``
    builds them (``inference.kinds._shifted_trace_problems``): ``how="newton"`` is what ``fit``
    uses (``inference.shift.newton_sensitivities``: a Newton step of the mode with the noise
    scales held, or the shifted MAPs where a step leaves the quadratic region); ``"refit"`` the
    shifted MAPs optimised from the fitted one (its check); and the seconds spent."""
    t0 = time.perf_counter()
    build = _shifted_trace_problems(problem, mode, campaign)
    if how == "newton":
        rows = newton_sensitivities(build, shifts, (problem, mode), held=problem.scale_sites)
    else:
        rows = map_sensitivities(build, shifts, (problem, mode))
    return rows, time.perf_counter() - t0


def type_b_sd(rows, u):
    return {q: math.sqrt(sum((row[q] * u[s]) ** 2 for s, row in rows.items() if q in row)) for q in QUANTITIES}


def contribution_error(rows, reference, u):
    """Quantity -> max over sources of |c_s - c_ref,s| u_s / u_b, u_b the reference's Type B sd."""
    u_b = type_b_sd(reference, u)
    return {q: max(abs(rows.get(s, {}).get(q, math.nan) - reference[s][q]) * u[s] for s in reference) / u_b[q]
            if u_b[q] > 0 else math.nan for q in QUANTITIES}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[100, 101, 102, 103, 104, 105])
    ap.add_argument("--pairs", type=int, nargs="+", default=[3])
    ap.add_argument("--models", nargs="+", default=["four_term_tyre_lag", "four_term_tyre_lag_saturating"])
    ap.add_argument("--lsq-only", action="store_true", help="the least-squares step alone")
    ap.add_argument("--refit", action="store_true", help="also each shifted MAP optimised (the Newton step's check)")
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
                    t0 = time.perf_counter()
                    problem, mode = fitted_mode(campaign, spec)
                    rec["time_map_s"] = time.perf_counter() - t0
                    rows = {}
                    for how in ("newton", "refit") if args.refit else ("newton",):
                        rows[how], t = posterior_sensitivities(campaign, problem, mode, shifts, how)
                        rec.update({f"sources_{how}": len(rows[how]), f"type_b_sd_{how}": type_b_sd(rows[how], u),
                                    f"time_{how}_s": t})
                    if args.refit:   # the test's reading: the largest contribution's error, share of u_b
                        rec["newton_error_share"] = contribution_error(rows["newton"], rows["refit"], u)
                        rec["lsq_error_share"] = contribution_error(lsq_rows, rows["refit"], u)
                print(json.dumps(rec), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
