"""The ``bayes-roadload`` command line.

Subcommands: ``demo``, ``simulate``, ``fit``, ``sensitivity``, ``cases``, ``models``.
Every command that writes a directory validates its input first and writes nothing when the
input is refused; errors are printed as one line naming the file, column and row.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path


def _cmd_simulate(args) -> int:
    from .data import save_campaign
    from .simulate import simulate_campaign

    campaign = simulate_campaign(args.case, pairs=args.pairs, seed=args.seed, driveline=args.driveline)
    out = save_campaign(campaign, args.out, fmt=args.format)
    n = campaign.runs["run"].nunique()
    print(f"case {args.case}: {n} runs ({args.pairs} pairs), {len(campaign.runs)} samples -> {out}")
    return 0


def _cmd_fit(args) -> int:
    from .data import load_campaign
    from .inference.lsq import fit_lsq, format_lsq_table, write_lsq_outputs
    from .inference.spec import load_model_spec

    if args.method != "lsq":
        print("bayes-roadload fit: --method nuts is not available yet; use --method lsq", file=sys.stderr)
        return 2
    campaign = load_campaign(args.campaign)
    spec = load_model_spec(args.model)
    from .inference.lsq import LsqSettings

    result = fit_lsq(campaign, spec, grouping=args.grouping, settings=LsqSettings(initial_speed=args.initial_speed))
    write_lsq_outputs(result, args.out)
    print(format_lsq_table(result, campaign.truth))
    print(f"\nwrote {Path(args.out) / 'summary.csv'}, per_group.csv, fit.json")
    return 0


def _cmd_demo(args) -> int:
    from .data import save_campaign
    from .inference.lsq import fit_lsq, format_lsq_table, write_lsq_outputs
    from .inference.spec import load_model_spec
    from .simulate import simulate_campaign

    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bayes-roadload-demo-"))
    print(f"Simulating thesis case {args.case} ({args.pairs} pairs of opposite-direction coastdowns, "
          f"seed {args.seed}) ...")
    campaign = simulate_campaign(args.case, pairs=args.pairs, seed=args.seed)
    save_campaign(campaign, out / "campaign")
    for model in ("four_term", "three_term"):
        print(f"\nClassical per-pair least squares, model {model} (thesis section 5):")
        result = fit_lsq(campaign, load_model_spec(model), grouping="pair")
        write_lsq_outputs(result, out / f"fit_lsq_{model}")
        print(format_lsq_table(result, campaign.truth))
    print(f"\nCampaign and fits written under {out}")
    return 0


def _cmd_sensitivity(args) -> int:
    from .analysis.sensitivity import coefficient_sensitivity, format_sensitivity_table

    table = coefficient_sensitivity(cross_winds_mps=tuple(args.cross_wind))
    print(format_sensitivity_table(table))
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        table.to_csv(args.out, index=False)
    return 0


def _cmd_cases(args) -> int:
    from .simulate import CASES

    print(f"{'case':>4}  {'description':<24} {'head':>5} {'cross':>5}  dyn  M  S  model")
    for n, c in CASES.items():
        yn = lambda b: "Y" if b else "N"  # noqa: E731
        print(f"{n:>4}  {c.description:<24} {c.head_wind_mps:>5.1f} {c.cross_wind_mps:>5.1f}   "
              f"{yn(c.dynamics)}   {yn(c.measurement_noise)}  {yn(c.system_noise)}  {c.model}")
    return 0


def _cmd_models(args) -> int:
    from .inference.spec import available_models, load_model_spec

    for name in available_models():
        spec = load_model_spec(name)
        print(f"{name:<22} free: {', '.join(spec.free):<28} {spec.description}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bayes-roadload", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)

    d = sub.add_parser("demo", help="simulate thesis case 14 and fit it, printing truth vs estimate")
    d.add_argument("--case", type=int, default=14)
    d.add_argument("--pairs", type=int, default=6)
    d.add_argument("--seed", type=int, default=1)
    d.add_argument("--out", default=None, help="directory for the campaign and fits (default: a temp dir)")
    d.set_defaults(func=_cmd_demo)

    s = sub.add_parser("simulate", help="simulate a campaign of a thesis table 6.7 case")
    s.add_argument("--case", type=int, required=True, help="1-19, thesis table 6.7 (see `cases`)")
    s.add_argument("--pairs", type=int, default=1, help="number of opposite-direction pairs")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--driveline", action="store_true", help="also log a driveline force channel")
    s.add_argument("--format", choices=("csv", "parquet"), default="csv")
    s.add_argument("--out", required=True)
    s.set_defaults(func=_cmd_simulate)

    f = sub.add_parser("fit", help="fit a campaign")
    f.add_argument("campaign")
    f.add_argument("--model", default="four_term", help="a name in models/ or a TOML path (see `models`)")
    f.add_argument("--method", choices=("lsq", "nuts"), default="lsq")
    f.add_argument("--grouping", choices=("pair", "run", "all"), default="pair",
                   help="lsq: fit each pair, each run, or all runs jointly")
    f.add_argument("--initial-speed", choices=("fitted", "measured"), default="fitted",
                   help="lsq: estimate each run's initial speed (honest standard errors), or start "
                        "from the first measured speed as the thesis did")
    f.add_argument("--out", required=True)
    f.set_defaults(func=_cmd_fit)

    se = sub.add_parser("sensitivity", help="coefficient sensitivities (thesis tables 6.1, 6.2)")
    se.add_argument("--cross-wind", type=float, nargs="+", default=[0.0, 1.0, 2.0, 3.0])
    se.add_argument("--out", default=None, help="CSV file to write")
    se.set_defaults(func=_cmd_sensitivity)

    c = sub.add_parser("cases", help="list the simulation cases of thesis table 6.7")
    c.set_defaults(func=_cmd_cases)
    m = sub.add_parser("models", help="list the model variants in models/")
    m.set_defaults(func=_cmd_models)
    return p


def main(argv: list[str] | None = None) -> int:
    from .data import CampaignError

    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (CampaignError, ValueError, FileNotFoundError) as e:
        print(f"bayes-roadload {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
