"""The ``bayes-roadload`` command line.

Subcommands: ``demo``, ``simulate``, ``fit``, ``fit-driveline``, ``report``, ``batch``, ``plan``,
``diagnose``, ``dyno``, ``predict``, ``import-vbox``, ``sensitivity``, ``cases``, ``models``.
Every command that writes a directory validates its input first and writes nothing when the
input is refused; errors are printed as one line naming the file, column and row.  Exit codes:
0 success, 2 input refused, 3 a NUTS fit that failed its diagnostic gates (outputs written and
flagged), 4 a valid campaign whose fit failed in a numerical stage (the stage, the run or
parameter and the remedy printed; the traceback in ``error.log`` in ``--out``), 141 the reader of
the output closed its pipe (as a shell reports a process ended by SIGPIPE).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import shlex
import sys
import tempfile
from pathlib import Path

from . import __version__, console

EXIT_REFUSED = 2
EXIT_GATES_FAILED = 3
EXIT_FIT_FAILED = 4
EXIT_BROKEN_PIPE = 141
COMMON_HELP = {
    "campaign": "campaign directory: runs.csv (or .parquet), intervals.csv, distances.csv, spindown.csv or "
                "steady.csv, with vehicle.toml (docs/data-format.md)",
    "campaigns": "directory searched for campaign directories",
    "out": "output directory",
    "seed": "random seed",
    "method": "nuts: NUTS over all runs jointly; lsq: classical least squares (thesis chapter 5)",
    "case": "thesis table 6.7 case (see `cases`)",
    "pairs": "opposite-direction pairs to simulate",
    "format": "file format of the speed traces",
    "cross_wind": "cross winds (m/s) of the sensitivity table",
}
"""Help of the options that several commands share (set where a command gives none)."""
STANDARD_NAMES = ("gtr15", "j2263", "j1263", "cfr1066", "cfr1037")
"""``--standard`` choices (:data:`bayes_roadload.analysis.standards.STANDARDS`)."""
DYNO_STANDARDS = ("gtr15", "j2263", "j1263")
"""The standards whose result is road-load coefficients, a dynamometer's target."""
WRITES_OUT = ("demo", "simulate", "fit", "fit-driveline", "dyno", "predict", "plan", "diagnose", "import-vbox")
"""Commands whose ``--out`` directory must be empty or new (``--force`` replaces an earlier
output there); ``report`` writes into its fit directory and ``batch`` resumes in its own."""
OUT_MARKER = ".bayes-roadload.json"
"""Written in every ``--out`` directory: the command line, the version and the files written
(what ``--force`` removes before a new run)."""

_output = logging.getLogger(console.OUTPUT_LOGGER)


class Stages:
    """Wall time of a command's stages (``with stages("load"): ...``), written to
    ``diagnostics.json`` ``stages_s`` with the fit's own ``timings_s`` so a slow stage shows."""

    def __init__(self):
        import time

        from ._jax import compile_seconds

        self._clock = time.perf_counter
        self._compile = compile_seconds
        self._compiled_before = compile_seconds()
        self.started = self._clock()
        self.seconds: dict[str, float] = {}

    def __call__(self, name: str):
        import contextlib

        @contextlib.contextmanager
        def timed():
            t0 = self._clock()
            try:
                yield
            finally:
                self.seconds[name] = self.seconds.get(name, 0.0) + self._clock() - t0
        return timed()

    def record(self, diagnostics_file: Path, fit_timings: dict[str, float] | None = None) -> dict[str, float]:
        """Add ``stages_s`` to ``diagnostics_file`` (when it exists): ``imports`` (from the
        package's import to the command's start), the timed stages, the fit's own parts from its
        timings -- ``start`` (the problem built and its start values: the least-squares start,
        and for a hierarchical fit the run effects' linearisation), ``map``, ``warmup`` and
        ``sampling`` (the kept run's; a retried fit's first attempt is ``first_attempt``) and
        ``fit_setup``, the rest of the fit (the posterior's set-up, the draws turned into
        parameters, the gate checks; for a kind without a least-squares start, the problem's
        construction too) -- then ``compile``, the seconds JAX spent tracing, lowering and
        compiling in the whole command (:func:`~bayes_roadload._jax.compile_seconds`; they are
        also inside the stage that first ran each program), and ``total`` (import to now)."""
        from . import IMPORT_STARTED

        stages = {"imports": self.started - IMPORT_STARTED, **self.seconds}
        if fit_timings is not None and "fit" in self.seconds:
            parts = {"start": "start_s", "map": "map_s", "first_attempt": "first_attempt_s", "warmup": "warmup_s",
                     "sampling": "sampling_s"}
            for stage, key in parts.items():
                if key in fit_timings:
                    stages[stage] = fit_timings[key]
            sampled = sum(fit_timings.get(k, 0.0) for k in parts.values())
            stages["fit_setup"] = max(self.seconds["fit"] - sampled, 0.0)
        stages["compile"] = self._compile() - self._compiled_before
        stages["total"] = self._clock() - IMPORT_STARTED
        stages = {k: round(v, 3) for k, v in stages.items()}
        if diagnostics_file.is_file():
            doc = json.loads(diagnostics_file.read_text())
            doc["stages_s"] = stages
            diagnostics_file.write_text(json.dumps(doc, indent=2) + "\n")
        return stages


def echo(text: str = "") -> None:
    """A line of a command's output (standard output through logging: ``--quiet`` silences it)."""
    _output.info(text)


def _no_markers(args) -> None:
    if args.markers is not None or args.timing_sd is not None:
        raise ValueError("--markers / --timing-sd time simulated coastdowns past markers (--kind coastdown)")


def _simulate_spindown(args) -> int:
    from .data.spindown import save_spindown
    from .simulate.spindown import simulate_spindown

    _no_markers(args)
    campaign = simulate_spindown(tests_per_wheel=args.pairs, seed=args.seed)
    out = save_spindown(campaign, args.out)
    echo(f"spin-down: {len(campaign.run_ids)} runs of wheels {', '.join(campaign.wheels)}, "
          f"{len(campaign.runs)} samples -> {out}")
    return 0


def _simulate_steady(args) -> int:
    from .data.steady import save_steady
    from .simulate.steady import simulate_steady

    _no_markers(args)
    campaign = simulate_steady(args.case, pairs=args.pairs, seed=args.seed)
    out = save_steady(campaign, args.out)
    echo(f"steady state: {len(campaign.run_ids)} runs, {len(campaign.runs)} samples -> {out}")
    return 0


def _simulate_coastdown(args) -> int:
    from .data import save_campaign
    from .simulate import simulate_campaign

    if args.case is None:
        raise ValueError("simulate: --case is required for coastdowns (see `cases`)")
    campaign = simulate_campaign(args.case, pairs=args.pairs, seed=args.seed, driveline=args.driveline,
                                 masses_kg=args.masses)
    masses = "" if args.masses is None else f" at {', '.join(f'{m:g}' for m in campaign.meta['masses_kg'])} kg"
    n = campaign.runs["run"].nunique()
    if args.timing_sd is not None and args.markers is None:
        raise ValueError("--timing-sd applies to a distance-time campaign (--markers)")
    if args.markers is not None:
        from .simulate.distances import DEFAULT_TIMING_SD_S, distance_campaign_from_traces

        timing_sd = DEFAULT_TIMING_SD_S if args.timing_sd is None else args.timing_sd
        if args.format != "csv":
            raise ValueError("a distance-time campaign is written as distances.csv (--format csv)")
        markers = _parse_markers(args.markers)
        campaign = distance_campaign_from_traces(campaign, markers, timing_sd_s=timing_sd, seed=args.seed)
        out = save_campaign(campaign, args.out)
        echo(f"case {args.case}: {n} runs ({args.pairs} pairs{masses}) timed past {len(markers)} markers "
              f"({markers[0]:g}-{markers[-1]:g} m, timing sd {timing_sd:g} s) -> {out / 'distances.csv'}")
        return 0
    out = save_campaign(campaign, args.out, fmt=args.format)
    echo(f"case {args.case}: {n} runs ({args.pairs} pairs{masses}), {len(campaign.runs)} samples -> {out}")
    return 0


def _simulate_dyno(args) -> int:
    from .data.dyno import save_dyno
    from .simulate.dyno import simulate_dyno

    _no_markers(args)
    # a mid-size car's set coefficients (N, N/(km/h), N/(km/h)^2) and a dynamometer's own losses
    dyno = simulate_dyno((100.0, 0.5, 0.03), (10.0, 0.1, 0.002), 1500.0, speed_noise_mps=0.02, seed=args.seed)
    out = save_dyno(dyno, args.out)
    echo(f"dynamometer coastdown: {len(dyno.runs)} samples, known parasitic losses in dyno.toml -> {out}")
    return 0


SIMULATIONS = {"coastdown": _simulate_coastdown, "spindown": _simulate_spindown, "steady": _simulate_steady,
               "dyno": _simulate_dyno}
"""``simulate --kind``: what each choice simulates."""


def _cmd_simulate(args) -> int:
    from .simulate.cases import CASES

    if args.case is not None and args.case not in CASES:   # refused (exit 2), not an internal error
        raise ValueError(f"--case {args.case}: the thesis cases (table 6.7) are numbered {min(CASES)}-{max(CASES)}")
    return SIMULATIONS[args.kind](args)


def _parse_markers(values: list[str]) -> list[float]:
    """``--markers``: distances in m, or one ``START:STEP:END`` range (END included)."""
    import numpy as np

    if len(values) == 1 and ":" in values[0]:
        try:
            start, step, end = (float(x) for x in values[0].split(":"))
        except ValueError as e:
            raise ValueError(f"--markers {values[0]!r}: expected START:STEP:END in metres") from e
        if step <= 0 or end <= start:
            raise ValueError(f"--markers {values[0]!r}: need STEP > 0 and END > START")
        return [float(x) for x in np.arange(start, end + 0.5 * step, step)]
    return [float(x) for x in values]


def _sampler(args):
    from . import config

    stated = {} if args.target_accept is None else {"target_accept": args.target_accept,
                                                    "small_campaign_target_accept": None,
                                                    "quiet_trace_target_accept": None}
    return config.SamplerConfig(num_warmup=args.warmup, num_samples=args.draws, num_chains=args.chains,
                                seed=args.seed, progress_bar=console.progress_bars(not args.no_progress),
                                iteration_bars=bool(args.iteration_bars),
                                precondition="none" if args.no_precondition else "laplace",
                                noise_scaled_metric=bool(args.noise_scaled_metric), **stated)


def _fit_options(args, runs=None):
    """The options of ``fit`` a data kind sees (:class:`~bayes_roadload.inference.kinds.FitOptions`)."""
    from .inference.kinds import FitOptions

    return FitOptions(method=args.method, pooling=args.pooling, noise=args.noise, robust=bool(args.robust),
                      validity=args.validity, steady_wind=args.steady_wind, compare=args.compare,
                      undriven=bool(args.undriven), sampler=_sampler(args), runs=runs,
                      type_b=not args.no_type_b)


def _provenance(args, campaign, campaign_path):
    """``fit.json`` / ``posterior.nc`` provenance of a fit of ``campaign`` read from ``campaign_path``."""
    from .data.ambient import ambient_record
    from .output import fit_provenance

    return fit_provenance(getattr(args, "command_line", None), campaign_path,
                          campaign.meta.get("conversions"), ambient_record(campaign))


def _fit_and_write(entry, campaign, spec, options, out: Path, campaign_path=None, provenance=None, stages=None):
    """NUTS fit of a campaign of kind ``entry``, its fit directory (:func:`~bayes_roadload.output.
    write_fit_dir`) and the posterior table against the truth of a simulated campaign."""
    from .analysis.budget import format_budget, propagate_type_b
    from .errors import stage
    from .inference.results import format_posterior_table
    from .output import fit_record, write_fit_dir

    stages = stages or Stages()
    with stages("fit"):
        fit = entry.fit(campaign, spec, options)
    with stages("summaries_and_predictive"):
        report = entry.report(fit, campaign)
        tables = entry.extras(fit, campaign, report.summary, options)
    record = fit_record(fit, campaign_path)
    record["type_b"] = entry.type_b is not None and options.type_b
    if record["type_b"]:
        with stages("type_b"):
            report, budget, _ = propagate_type_b(report, campaign, spec, seed=options.sampler.seed,
                                                 options=options, fit=fit)
        tables = dict(tables, **{"budget.csv": budget})
    with stages("writing"), stage("output"):
        written = write_fit_dir(report, out, record=record, extras=tables, provenance=provenance)
    truth = fit.problem.truth_values(campaign.truth)
    text = format_posterior_table(report.summary, report.diagnostics, truth or None)
    if "budget.csv" in tables:
        text += "\n\n" + format_budget(tables["budget.csv"])
    return fit, report, tables, written, truth, text


def _undriven_values(arg: str) -> tuple[float, float]:
    """``--undriven``: a spin-down fit directory (its summary.csv Au, Bu means) or "Au,Bu" in SI."""
    path = Path(arg)
    if path.is_dir():
        import pandas as pd

        f = path / "summary.csv"
        if not f.is_file():
            raise FileNotFoundError(f"{f}: --undriven takes a spin-down fit's output directory or 'Au,Bu' (N, N s/m)")
        s = pd.read_csv(f).set_index("parameter")
        if not {"Au", "Bu"} <= set(s.index):
            raise ValueError(f"{f}: no Au, Bu rows: not a spin-down fit")
        return float(s.loc["Au", "mean"]), float(s.loc["Bu", "mean"])
    try:
        au, bu = (float(x) for x in arg.split(","))
    except ValueError:
        raise ValueError(f"--undriven {arg!r}: give a spin-down fit directory or 'Au,Bu' in N and N s/m, "
                         "e.g. 3.24,0.232") from None
    return au, bu


def _model_for(args, default: str):
    """The model spec of a fit: ``--model`` (or ``default``), with ``--undriven`` added."""
    from .inference.spec import load_model_spec, with_undriven_wheels

    spec = args.model if not isinstance(args.model, (str, type(None))) else load_model_spec(args.model or default)
    if args.undriven:
        spec = with_undriven_wheels(spec, *_undriven_values(args.undriven))
    return spec


def _add_unit_options(p) -> None:
    """``--speed-unit`` / ``--airspeed-unit`` of a command that loads a speed-trace campaign."""
    p.add_argument("--speed-unit", choices=("mps", "kph", "mph"), default=None,
                   help="speed traces: the unit of the speed column whatever its name says (converted on load and "
                        "recorded in fit.json); default: the column name's (speed_mps, speed_kph, speed_mph)")
    p.add_argument("--airspeed-unit", choices=("mps", "kph", "mph"), default=None,
                   help="speed traces: the unit of the airspeed column, as --speed-unit")


def _load_with_units(path, args):
    """A campaign loaded with the command's ``--speed-unit`` / ``--airspeed-unit``."""
    from .data import load_campaign

    return load_campaign(path, speed_unit=args.speed_unit, airspeed_unit=args.airspeed_unit)


def _load_for_fit(args):
    """The campaign of ``fit``: the spin-down options go to a spin-down campaign only
    (:func:`~bayes_roadload.data.load_campaign` refuses them for other kinds)."""
    from .data import load_campaign

    return load_campaign(args.campaign, wheel_inertia_kgm2=args.wheel_inertia_kgm2,
                         rolling_radius_m=args.rolling_radius_m, speed_unit=args.speed_unit,
                         airspeed_unit=args.airspeed_unit)


def _validity(entry, campaign, args, out: Path):
    """Run validity (``--validity``, or the kind's default): the table, printed and written to
    ``validity.csv``, and the runs to fit (None: all)."""
    from .analysis.validity import format_validity, validity_table

    mode = args.validity or entry.validity_default
    if mode is None:
        return None
    validity = validity_table(campaign, args.wind_limits)
    echo(format_validity(validity) + (" (reported only: every run fitted)" if mode == "report" else ""))
    out.mkdir(parents=True, exist_ok=True)
    validity.to_csv(out / "validity.csv", index=False)
    if mode == "report":
        return list(validity["run"])
    keep = [r for r, bad in zip(validity["run"], validity["rejected"]) if not bad]
    if not keep:
        raise ValueError("every run was rejected by the validity checks (validity.csv)")
    return keep


def _standard_options(args) -> dict:
    """The ``--standard`` options of ``fit`` and ``report`` as keywords of ``run_standard``."""
    return {"rotating_inertia_known": args.rotating_inertia_known, "tyres_in_contact": args.tyres_in_contact,
            "delta_f_spin_n": args.delta_f_spin_n, "delta_f_trr_n": args.delta_f_trr_n}


def _add_standard_options(p) -> None:
    p.add_argument("--rotating-inertia-known", action="store_true",
                   help="with --standard j2263 (cfr1066, cfr1037): the effective mass is measured, not the standard's "
                        "convention (1.03 x test mass; test mass + 56.7 kg per tyre)")
    p.add_argument("--tyres-in-contact", type=int, default=None,
                   help="with --standard cfr1037: tyres on the road, for M_e = M + 56.7 kg per tyre (default: "
                        "vehicle.toml [vehicle] tyres_in_contact)")
    p.add_argument("--delta-f-spin-n", type=float, default=0.0,
                   help="with --standard cfr1037: drive-axle spin loss difference between the high and low speed "
                        "ranges, N (40 CFR 1037.528(h)(5); default 0)")
    p.add_argument("--delta-f-trr-n", type=float, default=0.0,
                   help="with --standard cfr1037: tyre rolling resistance difference between 65 and 15 mi/h, N "
                        "(40 CFR 1037.528(h)(6); default 0)")


def _after_fit(args, out: Path, campaign) -> None:
    """What follows every fit: the standard's result (``--standard``, recorded in ``fit.json``)
    and ``report.html`` / ``report.md`` (unless ``--no-report``)."""
    if args.standard:
        from .analysis.standards import format_standard, run_standard

        record = out / "fit.json"
        if record.is_file():
            meta = json.loads(record.read_text())
            meta["standard"] = args.standard
            record.write_text(json.dumps(meta, indent=2) + "\n")
        if (out / "posterior.nc").is_file():
            result, checks = run_standard(out, args.standard, campaign=campaign, out_dir=out,
                                          **_standard_options(args))
            echo(f"\n{args.standard} result (standard_result.csv, standard_checks.csv):")
            echo(format_standard(result, checks))
        else:
            echo(f"note: --standard {args.standard} needs posterior draws (a NUTS fit); none for --method lsq")
    if not args.no_report:
        from .output.report import render_report

        html_path, _ = render_report(out)
        echo(f"report: {html_path} (and report.md)")


def _cmd_fit(args) -> int:
    from . import config
    from .inference.kinds import check_model, kind_of, resolve_pooling
    from .errors import stage
    from .inference.lsq import LsqSettings, fit_lsq, format_lsq_table, lsq_groups
    from .output import write_lsq_fit_dir

    if args.method == "lsq" and args.pooling == "hierarchical":
        raise ValueError("least squares has no hierarchical model; use --method nuts --pooling "
                         "hierarchical, or --method lsq --grouping run for one classical fit per run")
    stages = Stages()
    with stages("load"):
        campaign = _load_for_fit(args)
    out = Path(args.out)
    entry = kind_of(campaign)
    options = _fit_options(args)
    spec = _model_for(args, entry.default_model(campaign, options))
    entry.check_options(options)
    check_model(entry, spec)
    runs = _validity(entry, campaign, args, out)
    # --pooling auto: decided on the runs that are fitted (after the validity cut)
    options = resolve_pooling(entry, campaign, spec, dataclasses.replace(options, runs=runs))
    n_fitted = len(campaign.run_ids) if runs is None else len(runs)
    pooling_note = None
    if args.pooling == "auto" and options.pooling == "pooled" and args.method == "nuts" \
            and n_fitted > config.AUTO_HIERARCHICAL_MAX_RUNS:
        pooling_note = (f"note: --pooling auto fitted these {n_fitted} runs pooled (over "
                        f"{config.AUTO_HIERARCHICAL_MAX_RUNS} runs): the run-to-run spread is not in the intervals; "
                        "--pooling hierarchical adds it at several times the fit time (docs/calibration.md)")
    if args.method == "lsq":
        if runs is not None and runs != list(campaign.run_ids):
            campaign = campaign.subset(runs)
        lsq_groups(campaign, args.grouping)   # a grouping the campaign cannot take is refused (exit 2)
        with stage("lsq_start"):   # a numerical failure of accepted input: exit 4, not a refusal
            result = fit_lsq(campaign, spec, grouping=args.grouping,
                             settings=LsqSettings(initial_speed=args.initial_speed))
        with stage("output"):
            write_lsq_fit_dir(result, out, provenance=_provenance(args, campaign, args.campaign))
        echo(format_lsq_table(result, campaign.truth))
        for line in entry.input_notes(campaign, spec):
            echo(line)
        if not campaign.has_anemometer and args.grouping != "run":
            echo(f"note: no airspeed logged: this least-squares fit of each {args.grouping} takes still air, and a "
                 "wind that differs between the directions biases shared coefficients (more than each run's own "
                 "fit: --grouping run); the NUTS fit with --model speed_only_wind carries a latent wind per pair")
        echo(f"\nwrote {out / 'summary.csv'}, per_group.csv, fit.json")
        _after_fit(args, out, campaign)
        return 0
    for line in entry.preamble(campaign):
        echo(line)
    fit, report, tables, written, _, table = _fit_and_write(entry, campaign, spec,
                                                            dataclasses.replace(options, runs=runs), out,
                                                            args.campaign, _provenance(args, campaign, args.campaign),
                                                            stages)
    echo(table)
    if not report.diagnostics["pass"] and not _output.isEnabledFor(logging.INFO):  # --quiet: still said
        logging.getLogger("bayes_roadload").warning("the NUTS fit FAILED its diagnostic gates (%s): see %s",
                                                    ", ".join(report.diagnostics.get("failed", [])),
                                                    out / "diagnostics.json")
    fitted = campaign if runs is None else campaign.subset(runs)
    for line in [*entry.notes(fit, campaign, tables), *entry.input_notes(fitted, spec)]:
        echo(line)
    if pooling_note:
        echo(pooling_note)
    written += ["validity.csv"] if runs is not None else []
    echo(f"\nwrote {out / written[0]}, {', '.join(written[1:])}")
    with stages("report"):
        _after_fit(args, out, campaign)
    timed = stages.record(out / "diagnostics.json", fit.timings)
    logging.getLogger("bayes_roadload").info("stages (s): " + ", ".join(f"{k} {v:.1f}" for k, v in timed.items()))
    return 0 if report.diagnostics["pass"] else EXIT_GATES_FAILED


def _cmd_fit_driveline(args) -> int:
    from .errors import stage
    from .inference.driveline import driveline_report, fit_driveline_nuts
    from .inference.kinds import kind_of
    from .inference.results import format_posterior_table
    from .output import fit_record, write_fit_dir

    campaign = _load_with_units(args.campaign, args)
    if kind_of(campaign).driveline_channel is None:
        raise ValueError(f"{args.campaign}: fit-driveline needs a speed-trace campaign (runs.csv) that logs "
                         "driveline_force_n or the two wheel torques (off-load), or a steady-state campaign "
                         "(steady.csv) that logs gearbox_input_force_n (on-load)")
    out = Path(args.out)
    fit = fit_driveline_nuts(campaign, args.model, sampler=_sampler(args))
    report = driveline_report(fit, campaign)
    with stage("output"):
        written = write_fit_dir(report, out, record=fit_record(fit, args.campaign),
                                provenance=_provenance(args, campaign, args.campaign))
    truth = fit.problem.truth_values(campaign.truth)
    echo(format_posterior_table(report.summary, report.diagnostics, truth or None))
    echo(f"\nwrote {out / written[0]}, {', '.join(written[1:])}")
    _after_fit(args, out, campaign)
    return 0 if report.diagnostics["pass"] else EXIT_GATES_FAILED


FAILED_FIT_CONSEQUENCE = "the figures below come from draws that are not trustworthy"
FAILED_SOURCE_CONSEQUENCE = "the plan below draws from a posterior that is not trustworthy"


def _failed_fit_line(which: str, failed, what: str = FAILED_FIT_CONSEQUENCE) -> str:
    """The line that says, before any figure drawn from it, that ``which`` fit failed the gates
    ``failed``, and ``what`` follows for the output."""
    return (f"!! {which} FAILED its diagnostic gates ({', '.join(failed or []) or 'see diagnostics.json'}): "
            f"{what}; refit with more draws (see `fit`)")


def _warn_failed_fit(fit_dir, which: str = "the fit", what: str = FAILED_FIT_CONSEQUENCE,
                     gates: tuple[bool, tuple[str, ...]] | None = None) -> None:
    """Print, before any figure drawn from it, that a fit directory's fit failed its gates
    (``diagnostics.json`` ``pass``, or ``gates``, the ``(passed, failed)`` of a
    :class:`~bayes_roadload.output.FitDir` already read; :func:`_failed_fit_line`)."""
    from .output import fit_gates

    passed, failed = fit_gates(fit_dir) if gates is None else gates
    if not passed:
        echo(_failed_fit_line(f"{which} {fit_dir}", failed, what))


def _cmd_report(args) -> int:
    from .output.report import render_report

    fit_dir = Path(args.fit_dir)
    _warn_failed_fit(fit_dir)
    if args.standard:
        from .analysis.standards import format_standard, run_standard
        from .output import fit_campaign, read_fit_dir

        source = read_fit_dir(fit_dir)
        campaign = fit_campaign(source.record) if source.record.get("campaign") else None
        result, checks = run_standard(fit_dir, args.standard, campaign=campaign, out_dir=fit_dir,
                                      **_standard_options(args))
        echo(format_standard(result, checks))
    html_path, md_path = render_report(fit_dir, campaign=args.campaign)
    echo(f"wrote {html_path}, {md_path} (+ {md_path.parent / 'report_files'})")
    return 0


def _campaign_of_fit(fd):
    """The campaign a read fit directory's ``fit.json`` names (with the units the fit was told)."""
    from .output import fit_campaign

    if not fd.record.get("campaign"):
        raise ValueError(f"{fd.path / 'fit.json'}: no campaign path recorded; refit the campaign with `fit`")
    return fit_campaign(fd.record)


def _cmd_dyno(args) -> int:
    from .analysis.dyno import format_dyno, run_dyno

    _warn_failed_fit(args.target_fit_dir)
    target = args.target_fit_dir
    if args.standard:
        from .analysis.standards import flat_draws, get_standard, mass_scale, standard_coefficients
        from .output import read_fit_dir

        std = get_standard(args.standard)
        fd = read_fit_dir(target)
        vehicle = _campaign_of_fit(fd).vehicle
        scale = mass_scale(std, mass_kg=vehicle.mass_kg, effective_mass_kg=vehicle.effective_mass_kg,
                           rotating_inertia_known=args.rotating_inertia_known,
                           mass_in_running_order_kg=vehicle.mass_in_running_order_kg)
        target = standard_coefficients(flat_draws(fd.samples, fd.path / "posterior.nc"), std, scale)
        terms = {"standard": std.name, "mass_scale": scale, "effective_mass_kg": vehicle.effective_mass_kg * scale,
                 "rotating_inertia_known": bool(args.rotating_inertia_known)}
        echo(f"target: the road load in {std.title}'s terms ({std.temperature_k:g} K, {std.pressure_pa:g} Pa, "
             f"its mass convention M_e {terms['effective_mass_kg']:.1f} kg: the fit's forces x {scale:.4f}); the "
             "adjustment and its acceptance stay GTR 15's")
    result = run_dyno(target, args.dyno_coastdown, tolerance_n=args.tolerance_n, out_dir=args.out,
                      target_terms=terms if args.standard else None)
    echo(format_dyno(result))
    echo(f"\nwrote {Path(args.out) / 'dyno_set.csv'}, dyno_checks.csv, dyno.json")
    return 0


def _cmd_predict(args) -> int:
    from .analysis.predict import format_cycle_work, run_predict
    from .analysis.standards import flat_draws
    from .inference.spec import load_model_spec
    from .output import read_fit_dir

    fd = read_fit_dir(args.fit_dir)
    _warn_failed_fit(args.fit_dir, gates=(fd.passed, fd.failed))
    campaign = _campaign_of_fit(fd)
    fixed = load_model_spec(fd.model).fixed if args.mass_change_kg else {}  # the tyre terms it holds fixed
    draws = flat_draws(fd.samples, fd.path / "posterior.nc")  # the directory's posterior, read once
    pred = run_predict(draws, args.cycle, effective_mass_kg=campaign.vehicle.effective_mass_kg,
                       temperature_k=args.temperature_k, pressure_pa=args.pressure_pa,
                       mass_kg_change=args.mass_change_kg, mass_kg=campaign.vehicle.mass_kg, fixed=fixed,
                       v0_kph=args.v0_kph, power_w=args.power_w, out_dir=args.out)
    echo(format_cycle_work(pred.work, pred.shares, pred.work_mass_changed))
    echo(f"\nwrote the cycle work and the predicted trace in {args.out}")
    return 0


def _diagnose_band_times(campaign, spec, args) -> int:
    from .analysis.diagnose_intervals import diagnose_intervals, write_interval_diagnosis

    diag = diagnose_intervals(campaign, spec, sampler=_sampler(args))
    path = write_interval_diagnosis(diag, args.out)
    gap = diag.result["gap"]
    echo(f"gap of {spec.name} on the band times: residual RMS {gap['band_z_rms']:.2f} predictive sd (floor 1), "
          f"+/- heading difference {gap['heading_z_diff']:.2f} sd, 90 % coverage {gap['coverage_90']:.2f}; "
          f"residuals concentrate by {diag.result['localisation']['where'][0]}")
    for c in diag.candidates:
        d = c["delta_elpd"]
        echo(f"{c['rank']:3d}  {c['effect']:22s} delta_elpd_loo {'-' if d is None else f'{d:9.1f}'}  {c['statement']}")
    echo(f"\nwrote {path}, {Path(args.out) / 'report.md'} (+ plots)")
    return 0


def _diagnose_traces(campaign, spec, args) -> int:
    from .analysis.diagnose import diagnose, write_diagnosis

    diag = diagnose(campaign, spec)
    path = write_diagnosis(diag, args.out)
    gap = diag.result["gap"]
    echo(f"gap of {spec.name}: residual trend {gap['trend_rms_mps']:.4f} m/s (white-noise floor "
          f"{gap['trend_floor_mps']:.4f}), lag-1 autocorrelation {gap['lag1_autocorr']:.2f}; "
          f"residuals concentrate by {diag.result['localisation']['where'][0]}")
    for c in diag.candidates:
        d = c["delta_elpd"]
        echo(f"{c['rank']:3d}  {c['effect']:22s} delta_elpd {'-' if d is None else f'{d:9.1f}'}  {c['statement']}")
    if diag.refit["effects"]:
        echo("refit with " + ", ".join(diag.refit["effects"]) + ": shrink % "
              + ", ".join(f"{k} {v:.0f}" for k, v in diag.refit["shrink_pct"].items() if v is not None))
    echo(f"\nwrote {path}, {Path(args.out) / 'report.md'} (+ plots)")
    return 0


DIAGNOSES = {"traces": _diagnose_traces, "band_times": _diagnose_band_times}
"""The diagnosis families of :attr:`~bayes_roadload.inference.kinds.KindEntry.diagnosis`."""


def _cmd_diagnose(args) -> int:
    from .inference.kinds import kind_of
    from .inference.spec import load_model_spec

    campaign = _load_with_units(args.campaign, args)
    entry = kind_of(campaign)
    if entry.diagnosis is None:
        raise ValueError(f"{args.campaign}: the sim-to-real diagnosis works on coastdowns (speed traces, interval "
                         f"times or distance-time records), not on a {entry.name} campaign")
    spec = load_model_spec(args.model or entry.diagnosis_model)
    return DIAGNOSES[entry.diagnosis](campaign, spec, args)


def _cmd_demo(args) -> int:
    from .analysis.predict import format_cycle_work, run_predict
    from .analysis.standards import format_standard, run_standard
    from .data import save_campaign
    from .output.report import render_report
    from .inference.kinds import KINDS, FitOptions, resolve_pooling
    from .inference.lsq import fit_lsq
    from .output import write_lsq_fit_dir
    from .inference.spec import load_model_spec
    from .simulate import get_case, simulate_campaign

    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bayes-roadload-demo-"))
    case = get_case(args.case)
    if args.truth_model == "basic":
        case = dataclasses.replace(case, model="basic")
    on = lambda b: "on" if b else "off"  # noqa: E731
    echo(f"Simulating {args.pairs} pairs of opposite-direction coastdowns at thesis case {args.case} "
          f"conditions: head wind {case.head_wind_mps:g} m/s, cross wind {case.cross_wind_mps:g} m/s, "
          f"instrument dynamics {on(case.dynamics)}, measurement noise {on(case.measurement_noise)}, "
          f"system noise {on(case.system_noise)}, {case.model} drag model; seed {args.seed}.")
    campaign = simulate_campaign(case, pairs=args.pairs, seed=args.seed)
    save_campaign(campaign, out / "campaign")
    traces = KINDS["traces"]
    lsq_model = args.model or traces.default_model(campaign, FitOptions(method="lsq"))
    nuts_model = args.model or traces.default_model(campaign, FitOptions())
    echo(f"Fitting classical per-pair least squares (model {lsq_model}), then NUTS over all runs jointly "
         f"(model {nuts_model}) ...")
    lsq = fit_lsq(campaign, lsq_model, grouping="pair")
    write_lsq_fit_dir(lsq, out / "fit_lsq", provenance=_provenance(args, campaign, out / "campaign"))
    spec = load_model_spec(nuts_model)
    options = resolve_pooling(traces, campaign, spec, FitOptions(
        pooling=args.pooling, noise=args.noise, robust=bool(args.robust), sampler=_sampler(args)))
    _, report, _, _, truth, table = _fit_and_write(traces, campaign, spec, options, out / "fit_nuts",
                                                   out / "campaign", _provenance(args, campaign, out / "campaign"))
    summary, diag = report.summary, report.diagnostics
    post = summary.set_index("parameter")
    echo("")
    echo(f"{'quantity':<15}{'truth':>10}   {'least squares: mean +- SE':<27}"
          f"{'posterior: mean [95 % interval]':<38}truth inside")
    echo("-" * 102)
    inside: dict[str, bool] = {}
    for name in list(lsq.free) + ["F50_N", "F0_N", "F1_N_per_kph", "F2_N_per_kph2"]:
        t = truth.get(name)
        t_s = f"{t:>10.5g}" if isinstance(t, (int, float)) else f"{'-':>10}"
        m, se = lsq.weighted_mean.get(name, float("nan")), lsq.weighted_se.get(name, float("nan"))
        r = post.loc[name]
        interval = f"{r['mean']:>10.5g} [{r['q2.5']:.5g}, {r['q97.5']:.5g}]"
        flag = ""
        if isinstance(t, (int, float)):
            inside[name] = bool(r["q2.5"] <= t <= r["q97.5"])
            flag = "yes" if inside[name] else "NO"
        echo(f"{name:<15}{t_s}   {m:>11.5g} +- {se:<11.3g}  {interval:<38}{flag}")
    echo("")
    if inside:
        missed = [k for k, ok in inside.items() if not ok]
        echo(f"The posterior 95 % intervals contain the simulated truth for {len(inside) - len(missed)} of "
              f"{len(inside)} quantities" + (f"; they miss it for {', '.join(missed)}." if missed else ".")
              + " (Expected: about 1 in 20 misses; docs/calibration.md measures how often over many campaigns.)")
    echo("\n".join(line for line in table.splitlines()[:2] if line.startswith(("!!", "NUTS"))))
    if "Uncertainty budget" in table:
        echo("\n" + table[table.index("Uncertainty budget"):])
    fit_dir = out / "fit_nuts"
    html_path, _ = render_report(fit_dir)
    echo(f"\nCampaign, least-squares fit (fit_lsq/) and posterior (fit_nuts/, report {html_path.name}) written "
          f"under {out}")
    echo("\nGTR 15 target coefficients (reference conditions of the standard):")
    echo(format_standard(*run_standard(fit_dir, "gtr15", campaign=campaign, out_dir=fit_dir)))
    pred = run_predict(fit_dir, "wltc3b", effective_mass_kg=campaign.vehicle.effective_mass_kg)
    echo(format_cycle_work(pred.work, pred.shares))
    return 0 if diag["pass"] else EXIT_GATES_FAILED


def _plan_population(args, out: Path):
    """The population a plan draws from: a fit directory's posterior, or a NUTS fit of a campaign."""
    from .analysis.planning import population_from_fit, population_from_samples
    from .inference.nuts import fit_nuts
    from .inference.results import trace_report
    from .output import fit_campaign, fit_record, is_fit_dir, read_fit_dir, write_fit_dir

    src = Path(args.source)
    if is_fit_dir(src):
        source = read_fit_dir(src)
        campaign = fit_campaign(source.record)
        _warn_failed_fit(src, "the source fit", FAILED_SOURCE_CONSEQUENCE, gates=(source.passed, source.failed))
        return population_from_samples(source.samples, source.record["free"], source.model, campaign,
                                       source=f"{source.record['pooling']} fit {src}"), campaign
    campaign = _load_with_units(src, args)
    echo(f"Fitting {src} ({campaign.runs['run'].nunique()} runs) with model {args.model}, {args.pooling} "
          "pooling, to draw the future campaigns from ...")
    fit = fit_nuts(campaign, args.model, pooling=args.pooling, sampler=_sampler(args))
    report = trace_report(fit, campaign)
    write_fit_dir(report, out / "fit", record=fit_record(fit, src), provenance=_provenance(args, campaign, src))
    diag = report.diagnostics
    if not diag["pass"]:
        echo(_failed_fit_line(f"the source fit {out / 'fit'}", diag["failed"], FAILED_SOURCE_CONSEQUENCE))
    return population_from_fit(fit, campaign), campaign


DEFAULT_DESIGNS = ("", "extra_mass_kg=300", "cross_wind_factor=2")
"""`plan --identify` designs when none is given: the campaign's pairs once more ("": as tested),
with a weighed ballast, on a windier day (the library's `needs` name these)."""


def _cmd_plan_identify(args) -> int:
    import pandas as pd

    from . import config
    from .analysis.design_identify import DesignChange, identify_designs
    from .output import is_fit_dir

    src = Path(args.source)
    if is_fit_dir(src):
        raise ValueError(f"{src}: --identify scores a design on a campaign (it fits --model itself); give the campaign")
    campaign = _load_with_units(src, args)
    texts = args.design or list(DEFAULT_DESIGNS)
    changes = [DesignChange.parse(t) for t in texts]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    echo(f"Scoring {', '.join(args.identify)} on {src} as tested and under {len(changes)} design(s) "
         f"(model {args.model}; a MAP fit each) ...")
    table = identify_designs(campaign, args.model, args.identify, changes, seed=args.seed)
    table.to_csv(out / "identify.csv", index=False)
    echo(f"\n{'design':<34}{'runs':>5}  {'effect':<22}{'parameter':<24}{'contraction':>11}  {'detectable':>11}")
    for _, r in table.iterrows():
        if pd.isna(r["parameter"]):
            echo(f"{r['design']:<34}{r['runs']:>5}  {r['effect']:<22}{r['note']}")
            continue
        mark = "" if r["identifiable"] else "  (not identifiable)"
        echo(f"{r['design']:<34}{r['runs']:>5}  {r['effect']:<22}{r['parameter']:<24}{r['contraction']:>11.2f}  "
             f"{r['detectable']:>11.3g}{mark}")
    echo("(contraction: share of the candidate's prior variance the design's data remove -- identifiable from "
         f"{config.DEFAULT_DIAGNOSIS.min_contraction:g}; detectable: the smallest size, in the parameter's SI units, "
         "at which `diagnose` is expected to support it)")
    echo(f"\nwrote {out / 'identify.csv'}")
    return 0


def _cmd_plan(args) -> int:
    import math

    import pandas as pd

    from . import config
    from .analysis.batch import batch_client, compilation_cache_dir, run_batch
    from .analysis.planning import (Target, plan_jobs, plan_table, plot_plan, recommend, refit_size, refit_work,
                                    floor_hint, sizes_to_fit, small_size_caveat, type_b_floors, undecided_sizes)
    from .analysis.regulation import regulation_checks

    if args.identify:
        return _cmd_plan_identify(args)
    if args.design:
        raise ValueError("--design scores a design for --identify EFFECT ...; without it `plan` counts pairs")
    targets = [Target.parse(t) for t in (args.target or config.PLAN_TARGETS)]
    if not 0 < args.confidence < 1 or not 0 < args.assurance < 1:
        raise ValueError("--confidence and --assurance are fractions in (0, 1), e.g. 0.95 and 0.8")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    population, campaign = _plan_population(args, out)
    fit_model = args.fit_model or population.model
    if not population.tau:
        echo("note: the source posterior has no run-to-run spreads (pooled fit): future runs are drawn without "
              "run-to-run variation, so the plan counts measurement noise only; fit with --pooling hierarchical "
              "for a plan that includes it")
    pairs = sorted(set(args.pairs))
    if args.simulations < 1:
        raise ValueError("--simulations must be at least 1")
    # campaigns refitted at every simulated size, and the further steps where a target stays undecided
    first = args.simulations if args.all_simulations else max(1, math.ceil(args.simulations / config.PLAN_STEPS))
    if not 0 <= args.confirm <= first:
        raise ValueError(f"--confirm N refits N of the campaigns simulated at every size with NUTS: 0 <= N <= "
                         f"{first} (the first of {config.PLAN_STEPS} steps of --simulations, all of them with "
                         "--all-simulations)")
    quantities = [t.quantity for t in targets]
    floors = None
    if not args.no_type_b:
        # the Type B uncertainty does not shrink with pairs: a target below its floor is not
        # reachable at any size, and is not located by simulation (planning.type_b_floors)
        floors = type_b_floors(population, targets, args.confidence, model=fit_model)
        floors.to_csv(out / "type_b_floors.csv", index=False)
        echo("Type B floor (the declared values' and instruments' uncertainty, [uncertainty]; it does not shrink "
             "with more pairs; type_b_floors.csv):")
        for _, r in floors.iterrows():
            verdict = "" if r["reachable"] else "  NOT REACHABLE at any number of pairs"
            main = f" ({r['main_source']} {100 * r['main_source_share']:.0f} %)" if r["main_source"] else ""
            echo(f"  {r['quantity']:<15}target {r['target']:g} {r['unit']:<6} floor {r['type_b_half_width']:.3g} "
                 f"{r['unit']}{main}{verdict}")
        unreachable = set(floors.loc[~floors["reachable"], "quantity"])
        if unreachable:
            from .inference.spec import load_model_spec

            echo(f"  {floor_hint(floors, load_model_spec(fit_model).uncertainty)}")
        quantities = [q for q in quantities if q not in unreachable]
    # adaptive in two ways: the sizes by bisection on each target's smallest size meeting it
    # (planning.sizes_to_fit; --all-sizes: every size), and the simulations at a size in steps,
    # each after the first only where a target's assurance is still undecided
    # (planning.undecided_sizes; --all-simulations: all at once)
    if quantities:   # else every target is below its Type B floor: nothing is refitted
        echo(f"Population: {population.source}; {population.n_draws} draws; refitting {first} simulated campaigns "
             + (f"at each of {pairs} pairs" if args.all_sizes else
                f"at the sizes among {pairs} pairs that locate each target's smallest passing size (bisection)")
             + f" with {fit_model} ({population.pooling}, MAP + Laplace)"
             + (f", {first} more at a time up to {args.simulations} where a target stays undecided"
                if first < args.simulations else "") + " ...")
    progress = not args.no_progress and _output.isEnabledFor(logging.INFO)
    records = pd.DataFrame()
    simulated: list[int] = []
    rounds = math.ceil(math.log2(len(pairs) + 1))  # bisection over len + 1 outcomes (the last: not reached)
    with batch_client(args.workers, args.scheduler) as client:
        for round_ in range(1, len(pairs) + 1):
            table = plan_table(records, targets, args.confidence) if len(records) else pd.DataFrame()
            todo = [n for n in pairs if n not in simulated] if args.all_sizes else \
                sizes_to_fit(table, pairs, quantities, args.assurance, simulated)
            if not todo:
                break
            if not args.all_sizes:
                echo(f"round {round_} (at most {rounds}): {todo} pairs")
            # the batch door draws a bar on a terminal and plain lines elsewhere; --quiet: neither
            # a new size's programs are compiled by its first refit, then loaded by the other
            # workers from the persistent compilation cache (batch_map's lead)
            new = run_batch(plan_jobs(population, todo, simulations=first, model=fit_model,
                                      confidence=args.confidence, seed=args.seed, type_b=not args.no_type_b),
                            client, progress=progress, weight=refit_work,
                            lead=refit_size if compilation_cache_dir() else None)
            simulated += todo
            done = first
            while done < args.simulations:
                new_table = plan_table(new, targets, args.confidence)
                undecided = undecided_sizes(new_table, args.assurance) if not new_table.empty else []
                if not undecided:
                    break
                upto = min(done + first, args.simulations)
                echo(f"undecided after {done} simulations at {undecided} pairs (a target's assurance within the "
                      f"Wilson 95 % interval of {args.assurance:g}): {upto - done} more at each ...")
                more = run_batch(plan_jobs(population, undecided, simulations=upto, model=fit_model,
                                           confidence=args.confidence, seed=args.seed, first=done,
                                           type_b=not args.no_type_b),
                                 client, progress=progress, weight=refit_work)
                new, done = pd.concat([new, more], ignore_index=True), upto
            records = pd.concat([records, new], ignore_index=True)
        skipped = [n for n in pairs if n not in simulated]
        if skipped and quantities:
            echo(f"not simulated: {skipped} pairs (no target's smallest size can lie there, the assurance taken as "
                  "increasing with pairs; --all-sizes simulates them)")
        records.to_csv(out / "plan_records.csv", index=False)
        if records.empty:  # every target below its Type B floor: nothing to locate
            pd.DataFrame(columns=["quantity", "n_pairs", "median_half_width", "assurance"]).to_csv(out / "plan.csv",
                                                                                                 index=False)
            recommend(pd.DataFrame(), args.assurance, floors=floors).to_csv(out / "recommendation.csv", index=False)
            echo(f"\nno target is reachable at any number of pairs: nothing simulated; wrote {out / 'plan.csv'} (empty), "
                 "recommendation.csv, type_b_floors.csv")
            return 0
        failed = int(records["error"].notna().sum()) if "error" in records else 0
        not_converged = int((~records["gate_pass"].fillna(False).astype(bool)).sum()) if "gate_pass" in records else 0
        table = plan_table(records, targets, args.confidence)
        table.to_csv(out / "plan.csv", index=False)
        rec = recommend(table, args.assurance, floors=floors)
        rec.to_csv(out / "recommendation.csv", index=False)
        plot_plan(table, targets, out / "plan.png", assurance=args.assurance)
        echo(f"\n{'quantity':<15}{'target':>10}  " + "".join(f"{n:>8}" for n in pairs) + "   pairs needed")
        for t in targets:
            rows = table[table["quantity"] == t.quantity].set_index("n_pairs")
            if rows.empty:
                echo(f"{t.quantity:<15}{str(t).split('=')[1]:>10}  not a quantity of model {fit_model}")
                continue
            cells = "".join(f"{rows.loc[n, 'median_half_width']:>8.3g}" if n in rows.index else f"{'-':>8}" for n in pairs)
            r = rec[rec["quantity"] == t.quantity].iloc[0]
            below_floor = not bool(r.get("reachable", True))
            need = f"{int(r['n_pairs'])}" if r["reached"] else \
                ("none (Type B floor)" if below_floor else f"> {int(r['max_pairs_simulated'])}")
            echo(f"{t.quantity:<15}{str(t).split('=')[1]:>10}  {cells}   {need}")
        echo(f"(median {100 * args.confidence:g} % half-width against pairs, in the target's units; pairs needed: "
              f"smallest simulated n with P(half-width <= target) >= {args.assurance:g})")
        caveat = small_size_caveat(rec, population.pooling)
        if caveat:
            echo(caveat)
        if args.confirm:
            _plan_confirm(args, population, fit_model, targets, records, rec, out, progress, client)
        if failed or not_converged:
            echo(f"!! {failed} refits raised (left out of the table), {not_converged} failed their gate (MAP not "
                  "converged, or importance weights with Pareto k > 0.7: the Laplace approximation is poor there; kept, "
                  "see gate_pass_frac in plan.csv)")
        if "pair" in campaign.runs and campaign.runs["pair"].nunique() >= 2:
            reg = regulation_checks(campaign, population.model if args.fit_model is None else fit_model)
            reg.to_csv(out / "regulation.csv", index=False)
            echo("\nRegulation precision on the measured campaign (regulation.csv):")
            for _, r in reg.iterrows():
                verdict = "pass" if r["pass"] else f"FAIL: {r['extra_pairs']} more pairs ({r['extra_pairs_assured']} for " \
                                                   f"{100 * args.assurance:g} % assurance)"
                echo(f"  {r['criterion']:<6} {r['speed_kph']:>6.1f} km/h  n={r['n_pairs']}  precision "
                      f"{r['precision_pct']:.2f} % (limit {r['limit_pct']:g} %)  {verdict}")
        echo(f"\nwrote {out / 'plan.csv'}, recommendation.csv, plan_records.csv, plan.png"
              + (", regulation.csv" if (out / "regulation.csv").exists() else ""))
        return 0



def _plan_confirm(args, population, fit_model, targets, records, rec, out: Path, progress: bool, client) -> None:
    """``plan --confirm N``: NUTS refits of the first N simulated campaigns at each recommended
    size, against their MAP + Laplace refits (:func:`~bayes_roadload.analysis.planning.
    confirm_table`), on the plan's own batch ``client``; writes confirm.csv and says where the
    posterior itself does not meet the target."""
    import dataclasses

    from .analysis.batch import run_batch
    from .analysis.planning import confirm_table, plan_jobs

    sizes = sorted({int(n) for n in rec.loc[rec["reached"].astype(bool), "n_pairs"]})
    if not sizes:
        echo("\n--confirm: no target is reached at a simulated size; nothing to confirm")
        return
    sampler = dataclasses.replace(_sampler(args), progress_bar=False)
    echo(f"\nConfirming with NUTS: {args.confirm} of the simulated campaigns at {sizes} pairs ...")
    jobs = [dataclasses.replace(j, sampler=sampler)
            for j in plan_jobs(population, sizes, simulations=args.confirm, model=fit_model,
                               confidence=args.confidence, seed=args.seed, method="nuts",
                               type_b=not args.no_type_b)]
    nuts = run_batch(jobs, client, progress=progress)
    nuts.to_csv(out / "confirm_records.csv", index=False)
    table = confirm_table(records, nuts, targets, args.confidence, args.assurance)
    table.to_csv(out / "confirm.csv", index=False)
    echo(f"{'quantity':<15}{'pairs':>6}{'campaigns':>10}{'NUTS/Laplace':>14}{'assurance Laplace':>19}"
         f"{'NUTS [95 % interval]':>26}")
    for _, r in table.iterrows():
        flag = "  OPTIMISTIC: by NUTS this size does not meet the target" if r["optimistic"] else ""
        echo(f"{r['quantity']:<15}{int(r['n_pairs']):>6}{int(r['campaigns']):>10}{r['median_ratio']:>14.2f}"
             f"{r['laplace_assurance']:>19.2f}{r['nuts_assurance']:>10.2f} [{r['nuts_assurance_low']:.2f}, "
             f"{r['nuts_assurance_high']:.2f}]{flag}")
    echo("(NUTS/Laplace: median ratio of the half-widths on the same campaigns; below 1 the plan's refits are "
         f"too narrow and its answers optimistic; wrote {out / 'confirm.csv'}, confirm_records.csv)")


def _cmd_import_vbox(args) -> int:
    import json

    from .data import load_campaign, save_campaign
    from .data.campaign import read_vehicle_file
    from .data.vbox import import_vbox

    if args.vehicle is None:
        raise ValueError("the VBOX export does not record the vehicle: pass --vehicle vehicle.toml "
                         "([vehicle] mass_kg, effective_mass_kg, frontal_area_m2; docs/data-format.md)")
    vehicle, _, tunnel, meta = read_vehicle_file(args.vehicle)
    gates = args.gates
    if gates is not None and len(gates) != len(args.files):
        raise ValueError(f"{len(args.files)} files but {len(gates)} --gates entries: give one per file, "
                         "e.g. --gates 95,90,85,80,75,70 50,45,40,35 (km/h; an interleaved file's groups joined by /)")
    campaign, report = import_vbox(args.files, vehicle, gates=gates, weather=args.weather, meta=meta)
    campaign.tunnel = tunnel
    out = save_campaign(campaign, args.out)
    (out / "import_report.json").write_text(json.dumps(report.to_dict(), indent=2) + "\n")
    load_campaign(out)  # the written campaign reads back under the contract
    echo("\n".join(report.lines()))
    echo(f"{len(campaign.run_ids)} runs, {len(campaign.intervals)} bands, {len(campaign.pairs())} pairs -> {out} "
          "(intervals.csv, vehicle.toml, import_report.json)")
    return 0


def _cmd_sensitivity(args) -> int:
    from .analysis.sensitivity import coefficient_sensitivity, format_sensitivity_table

    table = coefficient_sensitivity(cross_winds_mps=tuple(args.cross_wind))
    echo(format_sensitivity_table(table))
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        table.to_csv(args.out, index=False)
    return 0


def _cmd_cases(args) -> int:
    from .simulate import CASES

    echo(f"{'case':>4}  {'description':<24} {'head':>5} {'cross':>5}  dyn  M  S  model")
    for n, c in CASES.items():
        yn = lambda b: "Y" if b else "N"  # noqa: E731
        echo(f"{n:>4}  {c.description:<24} {c.head_wind_mps:>5.1f} {c.cross_wind_mps:>5.1f}   "
              f"{yn(c.dynamics)}   {yn(c.measurement_noise)}  {yn(c.system_noise)}  {c.model}")
    return 0


def _cmd_models(args) -> int:
    from .inference.kinds import KINDS
    from .inference.spec import available_models, load_model_spec

    specs = [load_model_spec(name) for name in available_models()]
    width = max(len(s.name) for s in specs)
    for spec in specs:
        echo(f"{spec.name:<{width}}  free: {', '.join(spec.free)}")
        echo(f"{'':<{width}}  {spec.description}")
        for entry in KINDS.values():
            if spec.name in entry.default_models:
                echo(f"{'':<{width}}  default of `fit` for {entry.label} campaigns: {entry.default_models[spec.name]}")
    return 0


def _add_nuts_options(p: argparse.ArgumentParser, seed: int) -> None:
    from . import config

    d = config.DEFAULT_SAMPLER
    p.add_argument("--warmup", type=int, default=d.num_warmup, help="nuts: warm-up draws per chain")
    p.add_argument("--draws", type=int, default=d.num_samples, help="nuts: draws per chain")
    p.add_argument("--chains", type=int, default=d.num_chains, help="nuts: chains (run in parallel)")
    p.add_argument("--seed", type=int, default=seed)
    p.add_argument("--target-accept", type=float, default=None,
                   help=f"nuts: target acceptance probability for every campaign size; raise it (e.g. 0.95) when a "
                        f"fit reports divergences (default: {d.target_accept}, and "
                        f"{d.small_campaign_target_accept} for campaigns of at most {d.small_campaign_runs} runs "
                        f"and for speed traces logged with less noise than the likelihood's floor)")
    p.add_argument("--noise-scaled-metric", action=argparse.BooleanOptionalAction, default=d.noise_scaled_metric,
                   help="nuts: sample in coordinates whose scale follows the integrated noise's intensity q, the "
                        "same posterior without the funnel one or two pairs leave at small q (default: on; "
                        "--no-noise-scaled-metric samples in the Laplace coordinates alone)")
    p.add_argument("--no-progress", action="store_true", help="nuts: no progress bar")
    p.add_argument("--iteration-bars", action="store_true",
                   help="nuts, on a terminal: numpyro's bars of each chain's iterations instead of the time bar; "
                        "the sampler's program then compiles in every run (JAX does not cache programs with host "
                        "callbacks)")
    p.add_argument("--no-precondition", action="store_true",
                   help="nuts: numpyro's default NUTS without the MAP/Laplace start (slow; for comparison)")


def _add_verbosity(p: argparse.ArgumentParser, default) -> None:
    """``-q/--quiet`` and ``-v/--verbose`` (on the program, and again on every command with
    ``default`` SUPPRESS so that a command's own flag does not reset the program's)."""
    p.add_argument("-q", "--quiet", action="store_true", default=default,
                   help="warnings and errors only: no tables, no progress (the files are written as usual)")
    p.add_argument("-v", "--verbose", action="store_true", default=default,
                   help="also debug messages: stage details and third-party warnings")


def build_parser() -> argparse.ArgumentParser:
    from . import config

    p = argparse.ArgumentParser(prog="bayes-roadload", description="Road load from coastdown tests with honest "
                                "uncertainty: NUTS over all paired runs jointly (docs/method.md).",
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    _add_verbosity(p, False)
    sub = p.add_subparsers(dest="command", required=True)

    d = sub.add_parser("demo", help="simulate a 6-pair campaign at thesis case 14 conditions and fit it "
                                    "by least squares and NUTS, printing truth, estimates and posterior")
    d.add_argument("--case", type=int, default=14)
    d.add_argument("--pairs", type=int, default=6)
    d.add_argument("--model", default=None,
                   help="model variant of both fits (see `models`; default: fit's for speed traces)")
    d.add_argument("--truth-model", choices=("basic", "case"), default="basic",
                   help="simulate with the basic drag model (eq. 6.1, the physics of the analysis "
                        "model) or with the case's own (case 14: the full model, eq. 6.2)")
    d.add_argument("--out", default=None, help="directory for the campaign and fits (default: a temp dir)")
    d.add_argument("--pooling", choices=("auto", "pooled", "hierarchical"), default="auto",
                   help="one set of coefficients for every run, or run-level AD, BD, CD0 around population "
                        "means; auto: as `fit` (hierarchical for 2-12 pairs; docs/calibration.md, test-to-test variation)")
    _add_nuts_options(d, seed=1)
    d.set_defaults(func=_cmd_demo, noise="integrated", robust=False)

    s = sub.add_parser("simulate", help="simulate a campaign of a thesis table 6.7 case")
    s.add_argument("--kind", choices=tuple(SIMULATIONS), default="coastdown",
                   help="coastdown runs (runs.csv), undriven-wheel spin-downs (spindown.csv, thesis table 7.10 "
                        "wheels), steady-state torque tests (steady.csv, the case's winds) or a chassis-dynamometer "
                        "coastdown with known parasitic losses (dyno_coastdown.csv, dyno.toml)")
    s.add_argument("--case", type=int, default=None, help="1-19, thesis table 6.7 (see `cases`); required for "
                                                         "coastdowns, the winds of a steady-state simulation")
    s.add_argument("--pairs", type=int, default=1, help="number of opposite-direction pairs (spindown: tests "
                                                       "per wheel; steady: run pairs per steady speed)")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--driveline", action="store_true", help="also log a driveline force channel")
    s.add_argument("--masses", type=float, nargs="+", default=None, metavar="KG",
                   help="test masses (kg), assigned to the pairs in turn (pair 1 at the first, pair 2 at the "
                        "second, ...); writes a mass_kg column (M_e shifts by the same amount)")
    s.add_argument("--markers", nargs="+", default=None, metavar="M",
                   help="write a distance-time campaign (distances.csv) instead of the speed traces: the times "
                        "each run passes these distances from the start of its coast (m), or START:STEP:END, "
                        "e.g. 100:100:1300")
    s.add_argument("--timing-sd", type=float, default=None,
                   help="with --markers: timing error of one marker passing, s (default 0.02)")
    s.add_argument("--format", choices=("csv", "parquet"), default="csv")
    s.add_argument("--out", required=True)
    s.set_defaults(func=_cmd_simulate)

    f = sub.add_parser("fit", help="fit a campaign (NUTS over all runs jointly, or classical least squares)")
    f.add_argument("campaign")
    f.add_argument("--model", default=None, help="a name in models/ or a TOML path (see `models`); default by data kind: "
                                                "four_term_tyre_lag_admittance_pitch_shapes (speed traces; _heavy_pitch_shapes above 3500 kg; four_term "
                                                "with --method lsq), "
                                                "split_f0_f2 (interval campaigns), three_term (distance-time campaigns), "
                                                "undriven_spindown (spin-downs), four_term with a measured wind or else "
                                                "three_term (steady state)")
    f.add_argument("--method", choices=("nuts", "lsq"), default="nuts")
    f.add_argument("--pooling", choices=("auto", "pooled", "hierarchical"), default="auto",
                   help="nuts: one set of coefficients, or run-level AD, BD, CD0 around population means; auto: "
                        "hierarchical for speed traces of 2 to 12 pairs (docs/calibration.md), else pooled")
    f.add_argument("--noise", choices=("integrated", "reverting", "white"), default="integrated",
                   help="nuts: residual model ('integrated': white noise plus integrated input noise, a random walk; "
                        "'reverting': that error reverting through the model's speed-dependent forces; 'white')")
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
    f.add_argument("--wind-limits", default="gtr_onboard", choices=tuple(config.WIND_LIMITS),
                   help="the wind limits of --validity (config.WIND_LIMITS)")
    f.add_argument("--steady-wind", choices=("auto", "measured", "pair", "still"), default="auto",
                   help="steady state: relative air from the anemometers, a latent along-track wind per "
                        "opposite-direction pair, or still air (auto: measured if logged, else pair)")
    f.add_argument("--compare", default=None, metavar="COASTDOWN_FIT_DIR",
                   help="steady state: a coastdown fit's output directory; writes comparison.csv (thesis table 7.11)")
    f.add_argument("--undriven", default=None, metavar="SPINDOWN_FIT_DIR|Au,Bu",
                   help="add the undriven-wheel loss Au + Bu v as a known term (eq. 2.16): a spin-down fit's output "
                        "directory (posterior means) or 'Au,Bu' in N and N s/m; the tyre terms then exclude it")
    f.add_argument("--wheel-inertia-kgm2", type=float, default=None,
                   help="spin-down: polar moment of inertia of the wheel (kg m^2), if not in vehicle.toml [spindown]")
    f.add_argument("--rolling-radius-m", type=float, default=None,
                   help="spin-down: rolling radius (m), if not in vehicle.toml")
    f.add_argument("--out", required=True)
    _add_nuts_options(f, seed=0)
    f.add_argument("--standard", choices=STANDARD_NAMES, default=None,
                   help="also give the result in a standard's terms (reference conditions, mass convention, units, "
                        "its precision and validity checks): standard_result.csv, standard_checks.csv; recorded in "
                        "fit.json (docs/standards.md)")
    _add_standard_options(f)
    f.add_argument("--no-report", action="store_true", help="do not render report.html / report.md")
    _add_unit_options(f)
    f.add_argument("--no-type-b", action="store_true",
                   help="leave the Type B uncertainty of the declared values and instruments (vehicle.toml "
                        "[uncertainty], docs/calibration.md) out of the intervals and write no budget.csv "
                        "(default: added, every data kind)")
    f.set_defaults(func=_cmd_fit)
    from .analysis.fleet import add_batch_parser

    add_batch_parser(sub, fit_command=main, fit_parser=f)

    fd = sub.add_parser("fit-driveline", help="the driveline loss At + Bt v + Ct v^2 alone: off-load from a "
                                              "coastdown's driveline_force_n (or wheel torques, eq. 5.12), or "
                                              "on-load from a steady-state campaign's gearbox_input_force_n minus "
                                              "its wheel force (section 5.5.2)")
    fd.add_argument("campaign")
    fd.add_argument("--model", default="four_term_driveline",
                    help="model variant whose At, Bt, Ct priors are used (default four_term_driveline)")
    fd.add_argument("--out", required=True)
    _add_unit_options(fd)
    _add_nuts_options(fd, seed=0)
    fd.add_argument("--no-report", action="store_true", help="do not render report.html / report.md")
    fd.set_defaults(func=_cmd_fit_driveline, standard=None, rotating_inertia_known=False, tyres_in_contact=None,
                    delta_f_spin_n=0.0, delta_f_trr_n=0.0)

    r = sub.add_parser("report", help="render report.html (self-contained) and report.md from a fit directory")
    r.add_argument("fit_dir", metavar="FIT_DIR", help="the output directory of `fit` or `fit-driveline`")
    r.add_argument("--campaign", default=None, help="campaign directory for truth and vehicle (default: fit.json's)")
    r.add_argument("--standard", choices=STANDARD_NAMES, default=None,
                   help="also write the standard's result and checks into FIT_DIR (see `fit --standard`)")
    _add_standard_options(r)
    r.set_defaults(func=_cmd_report)

    dy = sub.add_parser("dyno", help="chassis-dynamometer set coefficients from a target road-load fit and a coastdown "
                                     "on the dynamometer (GTR 15 Annex 4 adjustment), the target's posterior carried "
                                     "through, with the tolerance checks")
    dy.add_argument("target_fit_dir", metavar="TARGET_FIT_DIR", help="a NUTS `fit` output directory (the target)")
    dy.add_argument("dyno_coastdown", metavar="DYNO_COASTDOWN", nargs="+",
                    help="directory with dyno_coastdown.csv and dyno.toml (see `simulate --kind dyno`); two or more "
                         "consecutive coastdowns at one setting are regressed together (GTR 15 8.1.3.4.2 accepts a "
                         "setting on two)")
    dy.add_argument("--tolerance-n", type=float, default=10.0, help="load tolerance at the check speeds, N")
    dy.add_argument("--standard", choices=DYNO_STANDARDS, default=None,
                    help="take the target in the standard's terms (its reference conditions and mass convention, "
                         "as `report --standard` gives f0, f1, f2) instead of the fit's own reference road load")
    dy.add_argument("--rotating-inertia-known", action="store_true",
                    help="with --standard: keep the fit's effective mass (measured), not the standard's convention")
    dy.add_argument("--out", required=True, help="directory for dyno_set.csv, dyno_checks.csv, dyno.json")
    dy.set_defaults(func=_cmd_dyno)

    pr = sub.add_parser("predict", help="posterior of the road-load work over a drive cycle (kJ, kJ/km, the share of "
                                        "its uncertainty by parameter) and a predicted speed trace with its band")
    pr.add_argument("fit_dir", metavar="FIT_DIR", help="a NUTS `fit` output directory")
    pr.add_argument("--cycle", default="wltc3b",
                    help="wltc3b | nedc | ftp75 | hwfet (shipped tables, sources in bayes_roadload/cycles/README.md) "
                         "or a CSV with time_s, speed_kph")
    pr.add_argument("--temperature-k", type=float, default=293.15, help="ambient temperature of the predicted trace, K")
    pr.add_argument("--pressure-pa", type=float, default=100000.0, help="ambient pressure of the predicted trace, Pa")
    pr.add_argument("--mass-change-kg", type=float, default=0.0,
                    help="test mass change, kg, of the predicted trace and of a second cycle work "
                         "(cycle_work_mass_changed.csv)")
    pr.add_argument("--v0-kph", type=float, default=120.0, help="start speed of the predicted trace, km/h")
    pr.add_argument("--power-w", type=float, default=0.0,
                    help="constant tractive power of the predicted trace, W (0: a coastdown)")
    pr.add_argument("--out", required=True)
    pr.set_defaults(func=_cmd_predict)

    pl = sub.add_parser("plan", help="how many pairs until each quantity is known to a target: posterior-predictive "
                                     "campaigns refitted by MAP + Laplace")
    pl.add_argument("source", metavar="CAMPAIGN_OR_FIT_DIR",
                    help="a campaign (fitted first with --model, --pooling) or a `fit` output directory")
    _add_unit_options(pl)
    pl.add_argument("--target", action="append", metavar="QUANTITY=VALUE[%]",
                    help="half-width target, repeatable: CD0=1%% (percent of the mean) or F50_N=2 (SI units); "
                         "quantities AD BD CD0 KD At Bt Ct F50_N F50_tyre_N F0_N F2_N_per_kph2 "
                         "(default: AD=1%% BD=5%% CD0=1%% F50_N=0.5%%)")
    pl.add_argument("--confidence", type=float, default=config.PLAN_CONFIDENCE, help="interval level of the half-width")
    pl.add_argument("--assurance", type=float, default=config.PLAN_ASSURANCE,
                    help="recommend the smallest n whose half-width meets the target with this probability")
    pl.add_argument("--pairs", type=int, nargs="+", default=list(config.PLAN_PAIRS),
                    help="campaign sizes (pairs) to simulate")
    pl.add_argument("--simulations", type=int, default=config.PLAN_SIMULATIONS,
                    help="future campaigns per size, at most: a quarter of them at every size, a quarter more at a "
                         "time only at sizes where a target's assurance is still undecided (Wilson 95 %% interval "
                         "around --assurance)")
    pl.add_argument("--confirm", type=int, default=0, metavar="N",
                    help="refit N of the simulated campaigns at each recommended size with NUTS (--warmup, "
                         "--draws, --chains) and compare their half-widths and assurance with the MAP + Laplace "
                         "refits' (confirm.csv); 0: no confirmation")
    pl.add_argument("--all-simulations", action="store_true",
                    help="simulate --simulations campaigns at every size (no adaptive top-up)")
    pl.add_argument("--all-sizes", action="store_true",
                    help="simulate every size of --pairs (default: only the sizes that locate each target's "
                         "smallest size by bisection, the assurance taken as increasing with pairs)")
    pl.add_argument("--no-type-b", action="store_true",
                    help="plan the data's share of the intervals alone: without the Type B uncertainty of the "
                         "declared values and instruments that `fit` adds (which does not shrink with pairs; "
                         "type_b_floors.csv)")
    pl.add_argument("--model", default="three_term", help="model of the source fit when given a campaign")
    pl.add_argument("--pooling", choices=("pooled", "hierarchical"), default="hierarchical",
                    help="source fit: hierarchical gives the run-to-run spreads the future runs vary by")
    pl.add_argument("--fit-model", default=None,
                    help="model the future campaigns are fitted with (default: the source's); e.g. a constrained "
                         "one (three_term, two_term_tyres)")
    pl.add_argument("--workers", type=int, default=None,
                    help="worker processes of a local Dask cluster for the refits (default: one per usable core; "
                         "1: in this process, no cluster)")
    pl.add_argument("--scheduler", default=None, metavar="ADDR",
                    help="address of a running Dask scheduler for the refits, e.g. tcp://10.0.0.5:8786")
    pl.add_argument("--identify", nargs="+", metavar="EFFECT", default=None,
                    help="instead of the pair counts: can a design identify these sim-to-real candidates (library "
                         "names, see `diagnose`)?  Scores the campaign as tested and each --design (MAP fits, the "
                         "candidates linearised as `diagnose` does): contraction, identifiable, the smallest "
                         "detectable size; writes identify.csv (needs a campaign, fitted with --model)")
    pl.add_argument("--design", action="append", metavar="KEY=VALUE[,KEY=VALUE]", default=None,
                    help="with --identify, repeatable: runs added to the campaign as tested -- add_pairs=N (default: "
                         "as many as it has), extra_mass_kg=DM (a weighed ballast), cross_wind_factor=F (a windier "
                         "day); default: add_pairs, extra_mass_kg=300, cross_wind_factor=2")
    pl.add_argument("--out", required=True)
    _add_nuts_options(pl, seed=0)
    pl.set_defaults(func=_cmd_plan, noise="integrated", robust=False)

    g = sub.add_parser("diagnose", help="sim-to-real diagnosis: the gap of a model on a campaign, where it lies, "
                                        "which candidate effect explains it and how far it shrinks (speed traces: "
                                        "one MAP fit, candidates linearised; interval times: candidates refitted "
                                        "with NUTS (--warmup 500 --draws 1000) and compared by PSIS-LOO)")
    g.add_argument("campaign")
    _add_unit_options(g)
    g.add_argument("--model", default=None, help="a name in models/ or a TOML path (see `models`); default "
                                                 "three_term (speed traces), split_f0_f2 (interval times)")
    g.add_argument("--out", required=True, help="directory for diagnosis.json, refit.json, report.md and plots")
    _add_nuts_options(g, seed=11)   # interval campaigns: every candidate is refitted with NUTS
    g.set_defaults(func=_cmd_diagnose, warmup=500, draws=1000, target_accept=0.9)

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
    for name, command in sub.choices.items():  # every option with a help text and its default
        _add_verbosity(command, argparse.SUPPRESS)  # also after the command: `fit ... --quiet`
        if name in WRITES_OUT:
            command.add_argument("--force", action="store_true",
                                 help="write into a non-empty --out: the files an earlier command wrote there are "
                                      "removed first (without it a non-empty --out is refused)")
        command.formatter_class = argparse.ArgumentDefaultsHelpFormatter
        for action in command._actions:
            if action.help is None:
                action.help = COMMON_HELP.get(action.dest.removeprefix("fit_"))  # batch: fit's options
    return p


def _files_under(out: Path) -> set[str]:
    return {str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()} if out.is_dir() else set()


def _input_paths(args) -> list[Path]:
    """The existing files and directories a command's arguments name (other than ``--out``)."""
    found = []
    for key, value in vars(args).items():
        if key == "out":
            continue
        for v in value if isinstance(value, (list, tuple)) else [value]:
            if isinstance(v, (str, Path)) and str(v) and Path(v).exists():
                found.append(Path(v))
    return found


def _claim_out(args) -> tuple[Path, set[str]] | None:
    """Check a command's ``--out`` before it runs (:data:`WRITES_OUT`): a non-empty directory
    is refused unless ``--force``; with ``--force`` the files an earlier command wrote there
    (listed in :data:`OUT_MARKER`) are removed first, other files are left.  Returns the
    directory and the files in it now (None: the command writes no ``--out``)."""
    out = vars(args).get("out")
    if args.command not in WRITES_OUT or out is None:
        return None
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out}: a file, not a directory")
    for given in _input_paths(args):   # --force removes the files an earlier command wrote in --out
        a, b = out.resolve(), given.resolve()
        if b.is_relative_to(a):
            raise ValueError(f"--out {out} {'is' if a == b else 'holds'} the input {given}: give an output "
                             "directory that does not hold the inputs (a subdirectory of an input is fine)")
    present = _files_under(out)
    if present:
        if not args.force:
            raise ValueError(f"--out {out} is not empty ({len(present)} files, e.g. {min(present - {OUT_MARKER}, default=OUT_MARKER)}): give a new "
                             "or empty directory, or --force to replace an earlier output there")
        marker = out / OUT_MARKER
        earlier = json.loads(marker.read_text()).get("written", []) if marker.is_file() else []
        for name in [*earlier, OUT_MARKER, "error.log"]:
            (out / name).unlink(missing_ok=True)
        for d in sorted((p for p in out.rglob("*") if p.is_dir()), key=lambda p: -len(p.parts)):
            if not any(d.iterdir()):
                d.rmdir()
        present = _files_under(out)
    return out, present


def _mark_out(claim: tuple[Path, set[str]] | None, command_line: str) -> None:
    """Write :data:`OUT_MARKER` in the command's ``--out`` (when it wrote anything)."""
    if claim is None:
        return
    out, before = claim
    written = sorted(_files_under(out) - before - {OUT_MARKER})
    if written:
        (out / OUT_MARKER).write_text(json.dumps({"command_line": command_line, "version": __version__,
                                                  "written": written}, indent=2) + "\n")


def _silence_stdout() -> None:
    """Point standard output at the null device, so that the interpreter's flush at exit does not
    fail again on the closed pipe (the Python docs' note on SIGPIPE)."""
    import os

    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except (AttributeError, OSError, ValueError):  # a replaced stdout without a descriptor: nothing to flush
        pass


def main(argv: list[str] | None = None) -> int:
    """Run one command; exit codes as in the module docstring.  A refused input prints one line
    and writes nothing; a failed fit stage or an unexpected error prints one line with the
    stage and remedy, and the traceback goes to ``error.log`` in ``--out`` (never the terminal).
    Output and messages go through :mod:`logging` (:mod:`bayes_roadload.console`:
    ``--quiet`` / ``--verbose``; third-party warnings at DEBUG)."""
    from .data import CampaignError
    from .errors import FitStageError, write_error_log

    args = build_parser().parse_args(argv)
    words = list(sys.argv[1:] if argv is None else argv)
    args.command_line = "bayes-roadload " + shlex.join(str(w) for w in words)
    claim = None
    from ._jax import enable_compilation_cache

    enable_compilation_cache()  # before the first compilation: same-shaped fits reuse compiled code
    try:
        console.configure(console.verbosity_of(args.quiet, args.verbose))
        with console.routed_warnings():
            claim = _claim_out(args)
            try:
                return int(args.func(args) or 0)
            finally:
                _mark_out(claim, args.command_line)
    except BrokenPipeError:
        _silence_stdout()
        return EXIT_BROKEN_PIPE
    except (CampaignError, ValueError, FileNotFoundError) as e:
        print(f"bayes-roadload {args.command}: error: {e}", file=sys.stderr)
        return EXIT_REFUSED
    except FitStageError as e:
        log = write_error_log(vars(args).get("out"), e, argv)  # not every command has --out
        print(f"bayes-roadload {args.command}: error: {e}" + (f" (traceback in {log})" if log else ""), file=sys.stderr)
        return EXIT_FIT_FAILED
    except Exception as e:  # noqa: BLE001 - one line and a log, never a traceback on the terminal
        log = write_error_log(vars(args).get("out"), e, argv)
        print(f"bayes-roadload {args.command}: internal error: {type(e).__name__}: {e}"
              + (f" (traceback in {log}; please report it)" if log else ""), file=sys.stderr)
        return EXIT_FIT_FAILED


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
