"""The ``bayes-roadload`` command line.

Subcommands: ``demo``, ``simulate``, ``fit``, ``import-vbox``, ``sensitivity``, ``cases``, ``models``.
Every command that writes a directory validates its input first and writes nothing when the
input is refused; errors are printed as one line naming the file, column and row.  Exit codes:
0 success, 2 input refused, 3 a NUTS fit that failed its diagnostic gates (outputs written and
flagged).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
from pathlib import Path

EXIT_REFUSED = 2
EXIT_GATES_FAILED = 3


def _cmd_simulate(args) -> int:
    from .data import save_campaign
    from .simulate import simulate_campaign

    campaign = simulate_campaign(args.case, pairs=args.pairs, seed=args.seed, driveline=args.driveline)
    out = save_campaign(campaign, args.out, fmt=args.format)
    n = campaign.runs["run"].nunique()
    print(f"case {args.case}: {n} runs ({args.pairs} pairs), {len(campaign.runs)} samples -> {out}")
    return 0


def _sampler(args):
    from . import config

    return config.SamplerConfig(num_warmup=args.warmup, num_samples=args.draws, num_chains=args.chains,
                                seed=args.seed, progress_bar=not args.no_progress,
                                target_accept=args.target_accept,
                                precondition="none" if args.no_precondition else "laplace")


def _fit_nuts(campaign, args, out: Path):
    from .inference.nuts import fit_nuts
    from .inference.results import format_posterior_table, write_nuts_outputs

    from .inference.results import truth_derived

    fit = fit_nuts(campaign, args.model, pooling=args.pooling, noise=args.noise, robust=args.robust,
                   sampler=_sampler(args))
    summary, diag = write_nuts_outputs(fit, out)
    truth = dict(campaign.truth or {}, **truth_derived(fit.problem, campaign.truth))
    return summary, diag, format_posterior_table(summary, diag, truth or None), truth


def _fit_intervals(campaign, args, out: Path) -> int:
    from .analysis.validity import format_validity, interval_validity
    from .inference.intervals import fit_intervals_nuts, write_interval_outputs
    from .inference.results import format_posterior_table, truth_derived

    if args.method != "nuts":
        raise ValueError("an interval campaign (intervals.csv) is fitted by --method nuts only")
    if args.pooling != "pooled" or args.robust or args.noise != "integrated":
        raise ValueError("an interval campaign has its own likelihood (gate timing, band noise, run effect): "
                         "--pooling, --noise and --robust do not apply")
    model = args.model or "split_f0_f2"
    mode = args.validity or "reject"
    validity = interval_validity(campaign)
    runs = list(validity["run"]) if mode == "report" else list(validity.loc[~validity["rejected"], "run"])
    print(format_validity(validity) + (" (reported only: every run fitted)" if mode == "report" else ""))
    fit = fit_intervals_nuts(campaign, model, sampler=_sampler(args), runs=runs)
    summary, diag = write_interval_outputs(fit, out, validity=validity)
    truth = dict(campaign.truth or {}, **truth_derived(fit.problem, campaign.truth))
    print(format_posterior_table(summary, diag, truth or None))
    print(f"\nwrote {out / 'posterior.nc'}, summary.csv, runs_summary.csv, validity.csv, diagnostics.json")
    return 0 if diag["pass"] else EXIT_GATES_FAILED


def _cmd_fit(args) -> int:
    from .data import load_campaign
    from .inference.lsq import LsqSettings, fit_lsq, format_lsq_table, write_lsq_outputs
    from .inference.spec import load_model_spec

    campaign = load_campaign(args.campaign)
    out = Path(args.out)
    if getattr(campaign, "kind", "traces") == "intervals":
        return _fit_intervals(campaign, args, out)
    spec = load_model_spec(args.model or "four_term")
    if args.validity:
        from .analysis.validity import format_validity, trace_validity

        validity = trace_validity(campaign, args.wind_limits)
        print(format_validity(validity))
        out.mkdir(parents=True, exist_ok=True)
        validity.to_csv(out / "validity.csv", index=False)
        if args.validity == "reject":
            keep = [r for r, bad in zip(validity["run"], validity["rejected"]) if not bad]
            if not keep:
                raise ValueError("every run was rejected by the validity checks (validity.csv)")
            campaign = campaign.subset(keep)
    if args.method == "lsq":
        if args.pooling == "hierarchical":
            raise SystemExit("error: least squares has no hierarchical model; use --method nuts --pooling "
                             "hierarchical, or --method lsq --grouping run for one classical fit per run")
        result = fit_lsq(campaign, spec, grouping=args.grouping,
                         settings=LsqSettings(initial_speed=args.initial_speed))
        write_lsq_outputs(result, out)
        print(format_lsq_table(result, campaign.truth))
        print(f"\nwrote {out / 'summary.csv'}, per_group.csv, fit.json")
        return 0
    args.model = spec
    summary, diag, table, _ = _fit_nuts(campaign, args, out)
    print(table)
    print(f"\nwrote {out / 'posterior.nc'}, summary.csv, runs_summary.csv, diagnostics.json")
    return 0 if diag["pass"] else EXIT_GATES_FAILED


def _cmd_demo(args) -> int:
    from .data import save_campaign
    from .inference.lsq import fit_lsq, write_lsq_outputs
    from .simulate import get_case, simulate_campaign

    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bayes-roadload-demo-"))
    case = get_case(args.case)
    if args.truth_model == "basic":
        case = dataclasses.replace(case, model="basic")
    on = lambda b: "on" if b else "off"  # noqa: E731
    print(f"Simulating {args.pairs} pairs of opposite-direction coastdowns at thesis case {args.case} "
          f"conditions: head wind {case.head_wind_mps:g} m/s, cross wind {case.cross_wind_mps:g} m/s, "
          f"instrument dynamics {on(case.dynamics)}, measurement noise {on(case.measurement_noise)}, "
          f"system noise {on(case.system_noise)}, {case.model} drag model; seed {args.seed}.")
    campaign = simulate_campaign(case, pairs=args.pairs, seed=args.seed)
    save_campaign(campaign, out / "campaign")
    print(f"Fitting model {args.model}: classical per-pair least squares, then NUTS over all runs jointly ...")
    lsq = fit_lsq(campaign, args.model, grouping="pair")
    write_lsq_outputs(lsq, out / "fit_lsq")
    summary, diag, table, truth = _fit_nuts(campaign, args, out / "fit_nuts")
    post = summary.set_index("parameter")
    print()
    print(f"{'quantity':<15}{'truth':>10}   {'least squares: mean +- SE':<27}{'posterior: mean [95 % interval]'}")
    print("-" * 90)
    for name in list(lsq.free) + ["F50_N", "F0_N", "F1_N_per_kph", "F2_N_per_kph2"]:
        t = truth.get(name)
        t_s = f"{t:>10.5g}" if isinstance(t, (int, float)) else f"{'-':>10}"
        m, se = lsq.weighted_mean.get(name, float("nan")), lsq.weighted_se.get(name, float("nan"))
        r = post.loc[name]
        print(f"{name:<15}{t_s}   {m:>11.5g} +- {se:<11.3g}  {r['mean']:>10.5g} [{r['q2.5']:.5g}, {r['q97.5']:.5g}]")
    print()
    print("\n".join(line for line in table.splitlines()[:2] if line.startswith(("!!", "NUTS"))))
    print(f"\nCampaign, least-squares fit (fit_lsq/) and posterior (fit_nuts/) written under {out}")
    return 0 if diag["pass"] else EXIT_GATES_FAILED


def _cmd_import_vbox(args) -> int:
    import json

    from .data import load_campaign, save_campaign
    from .data.vbox import import_vbox

    if args.vehicle is None:
        raise ValueError("the VBOX export does not record the vehicle: pass --vehicle vehicle.toml "
                         "([vehicle] mass_kg, effective_mass_kg, frontal_area_m2; docs/data-format.md)")
    vehicle, _, tunnel, meta = _read_vehicle_file(args.vehicle)
    gates = args.gates
    if gates is not None and len(gates) != len(args.files):
        raise ValueError(f"{len(args.files)} files but {len(gates)} --gates entries: give one per file, "
                         "e.g. --gates 95,90,85,80,75,70 50,45,40,35 (km/h; an interleaved file's groups joined by /)")
    campaign, report = import_vbox(args.files, vehicle, gates=gates, weather=args.weather, meta=meta)
    campaign.tunnel = tunnel
    out = save_campaign(campaign, args.out)
    (out / "import_report.json").write_text(json.dumps(report.to_dict(), indent=2) + "\n")
    load_campaign(out)  # the written campaign reads back under the contract
    print("\n".join(report.lines()))
    print(f"{len(campaign.run_ids)} runs, {len(campaign.intervals)} bands, {len(campaign.pairs())} pairs -> {out} "
          "(intervals.csv, vehicle.toml, import_report.json)")
    return 0


def _read_vehicle_file(path):
    import tomllib

    from .data.campaign import CampaignError, _vehicle_from_toml

    p = Path(path)
    if not p.exists():
        raise CampaignError(f"{p}: missing")
    try:
        doc = tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as e:
        raise CampaignError(f"{p}: not valid TOML ({e})") from e
    return _vehicle_from_toml(doc, str(p))


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


def _add_nuts_options(p: argparse.ArgumentParser, seed: int) -> None:
    from . import config

    d = config.DEFAULT_SAMPLER
    p.add_argument("--warmup", type=int, default=d.num_warmup, help="nuts: warm-up draws per chain")
    p.add_argument("--draws", type=int, default=d.num_samples, help="nuts: draws per chain")
    p.add_argument("--chains", type=int, default=d.num_chains, help="nuts: chains (run in parallel)")
    p.add_argument("--seed", type=int, default=seed)
    p.add_argument("--target-accept", type=float, default=d.target_accept,
                   help="nuts: target acceptance probability; raise it (e.g. 0.95) when a fit reports divergences")
    p.add_argument("--no-progress", action="store_true", help="nuts: no progress bar")
    p.add_argument("--no-precondition", action="store_true",
                   help="nuts: numpyro's default NUTS without the MAP/Laplace start (slow; for comparison)")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bayes-roadload", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)

    d = sub.add_parser("demo", help="simulate a 6-pair campaign at thesis case 14 conditions and fit it "
                                    "by least squares and NUTS, printing truth, estimates and posterior")
    d.add_argument("--case", type=int, default=14)
    d.add_argument("--pairs", type=int, default=6)
    d.add_argument("--model", default="four_term", help="model variant (see `models`)")
    d.add_argument("--truth-model", choices=("basic", "case"), default="basic",
                   help="simulate with the basic drag model (eq. 6.1, the physics of the analysis "
                        "model) or with the case's own (case 14: the full model, eq. 6.2)")
    d.add_argument("--out", default=None, help="directory for the campaign and fits (default: a temp dir)")
    _add_nuts_options(d, seed=1)
    d.set_defaults(func=_cmd_demo, pooling="pooled", noise="integrated", robust=False)

    s = sub.add_parser("simulate", help="simulate a campaign of a thesis table 6.7 case")
    s.add_argument("--case", type=int, required=True, help="1-19, thesis table 6.7 (see `cases`)")
    s.add_argument("--pairs", type=int, default=1, help="number of opposite-direction pairs")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--driveline", action="store_true", help="also log a driveline force channel")
    s.add_argument("--format", choices=("csv", "parquet"), default="csv")
    s.add_argument("--out", required=True)
    s.set_defaults(func=_cmd_simulate)

    f = sub.add_parser("fit", help="fit a campaign (NUTS over all runs jointly, or classical least squares)")
    f.add_argument("campaign")
    f.add_argument("--model", default=None, help="a name in models/ or a TOML path (see `models`); default "
                                                "four_term (speed traces), split_f0_f2 (interval campaigns)")
    f.add_argument("--method", choices=("nuts", "lsq"), default="nuts")
    f.add_argument("--pooling", choices=("pooled", "hierarchical"), default="pooled",
                   help="nuts: one set of coefficients, or run-level AD, BD, CD0 around population means")
    f.add_argument("--noise", choices=("integrated", "white"), default="integrated",
                   help="nuts: residual model ('integrated': white noise plus integrated input noise)")
    f.add_argument("--robust", action="store_true", help="nuts: Student-t innovations (outlier-robust)")
    f.add_argument("--grouping", choices=("pair", "run", "all"), default="pair",
                   help="lsq: fit each pair, each run, or all runs jointly")
    f.add_argument("--initial-speed", choices=("fitted", "measured"), default="fitted",
                   help="lsq: estimate each run's initial speed (honest standard errors), or start "
                        "from the first measured speed as the thesis did")
    f.add_argument("--validity", choices=("reject", "report"), default=None,
                   help="run validity (wind limits, Hampel outliers, partner rejection): reject the flagged runs "
                        "with their partners, or only report them (validity.csv); default: reject for interval "
                        "campaigns, no check for speed traces")
    f.add_argument("--wind-limits", default="gtr_onboard", help="eec | gtr_stationary | gtr_onboard (config.WIND_LIMITS)")
    f.add_argument("--out", required=True)
    _add_nuts_options(f, seed=0)
    f.set_defaults(func=_cmd_fit)

    iv = sub.add_parser("import-vbox", help="import VBOX Coastdown CSV exports (speed-gate interval times) as an "
                                            "interval campaign")
    iv.add_argument("files", nargs="+", metavar="FILE", help="VBOX exports, e.g. the high and the low window")
    iv.add_argument("--gates", nargs="+", default=None,
                    help="gate speeds in km/h, descending, one comma-separated list per FILE (an interleaved file's "
                         "groups joined by '/'); default by band count: 5 -> 95..70, 3 -> 50..35, 10 -> both "
                         "(config.VBOX_DEFAULT_GATES_KPH); checked against each run's time and distance")
    iv.add_argument("--vehicle", default=None, help="vehicle.toml with [vehicle] mass_kg, effective_mass_kg, "
                                                   "frontal_area_m2 (not in the exports)")
    iv.add_argument("--weather", default=None, help="Kestrel weather log (CSV) for temperature and pressure")
    iv.add_argument("--out", required=True, help="campaign directory to write")
    iv.set_defaults(func=_cmd_import_vbox)

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
        return EXIT_REFUSED


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
