"""The registry of data kinds: how a campaign of each kind is fitted and reported.

One :class:`KindEntry` per kind in :data:`KINDS`; :func:`kind_of` finds a campaign's entry by
its class.  The command line (``fit``, ``fit-driveline``, ``diagnose``) and the fit-directory
writer (:mod:`bayes_roadload.output`) look everything kind-specific up here: the default model,
which options apply (and the message refusing the others), the fit, its report (posterior,
summary, per-run rows, gates) and the extra tables of its fit directory, the lines printed
around the posterior table, the driveline channel and the diagnosis family.

Adding a data kind: its campaign class (``bayes_roadload/data``), its problem
(:class:`~bayes_roadload.inference.problem.Problem`) and fit function, and one entry here
(``docs/architecture.md``).
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np
import pandas as pd

from .. import config
from ..data import Campaign, DistanceCampaign, IntervalCampaign, SpindownCampaign, SteadyCampaign
from .distances import DEFAULT_MODEL as DISTANCE_DEFAULT_MODEL
from .distances import build_distance_problem, distance_report
from .bayes import HIERARCHICAL_PARAMETERS, problem_like, run_effect_means, run_sensitivities
from .driveline import off_load_channel, on_load_channel
from .intervals import build_interval_problem, interval_report
from .lsq import linear_sensitivities
from .nuts import NutsFit, fit_nuts, sample_problem
from .problem import Problem
from .results import FitReport, trace_report
from .spec import ModelSpec
from .shift import SharedData, Shifts, campaign_shifts, map_sensitivities, newton_sensitivities
from .spindown import build_spindown_problem, spindown_extras, spindown_report
from .steady import build_steady_problem, compare_with_coastdown, resolve_wind, steady_extras, steady_report

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FitOptions:
    """The options of ``bayes-roadload fit`` that reach a kind (defaults: the command's).

    ``runs``: the run ids to fit (after validity rejection), None for all; ``compare``: a
    coastdown fit directory a steady-state fit is compared with; ``undriven``: ``--undriven``
    was given; ``type_b``: add the Type B uncertainty where the kind has it (``--no-type-b``);
    ``pooling``: "auto" (the kind's default, :func:`resolve_pooling`), "pooled" or "hierarchical"."""

    method: str = "nuts"
    pooling: str = "auto"
    noise: str = "integrated"
    robust: bool = False
    validity: str | None = None
    steady_wind: str = "auto"
    compare: str | None = None
    undriven: bool = False
    sampler: config.SamplerConfig = config.DEFAULT_SAMPLER
    runs: list | None = None
    type_b: bool = True


@dataclass(frozen=True)
class KindEntry:
    """Everything kind-specific about fitting a campaign.

    Attributes
    ----------
    name : the kind (``diagnostics.json`` ``kind``, ``fit.json`` ``kind``).
    label : how messages name a campaign of the kind ("spin-down").
    campaign_type : the campaign class (:func:`kind_of`).
    default_model : (campaign, options) -> model variant name of ``fit`` without ``--model``.
    default_models : every variant ``default_model`` returns -> when it does (shown by
        ``bayes-roadload models``).
    check_options : raises ValueError naming the options that do not apply to the kind.
    fit : (campaign, spec, options) -> :class:`~bayes_roadload.inference.nuts.NutsFit`.
    report : (fit, campaign) -> :class:`~bayes_roadload.inference.results.FitReport`.
    extras : (fit, campaign, summary, options) -> {file name: table} written beside it.
    preamble, notes : lines printed before / after the posterior table.
    input_notes : (campaign, spec) -> lines on the inputs the model reads from the campaign
        beyond its data file (a track survey), printed after the table of either method
        (NUTS after ``notes``, least squares after its table).
    validity_default : the ``--validity`` mode without the option ("reject"), None when no
        run validity check applies unless asked for.
    lsq : the classical least-squares fit applies (``--method lsq``).
    driveline_channel : campaign -> the measured driveline loss
        (:class:`~bayes_roadload.inference.driveline.DrivelineChannel`) of ``fit-driveline``,
        None when the kind has none.
    diagnosis : the sim-to-real diagnosis family of ``diagnose`` ("traces": one MAP fit with
        linearised candidates; "band_times": candidates refitted by NUTS), None when none
        applies; ``diagnosis_model`` its default model.
    default_pooling : (campaign, spec, options) -> the pooling of ``--pooling auto``.
    lagged_speed_drop : the kind's integrator supplies the channels it derives from a measured
        speed trace and its readings: the lagged speed drop, which terms naming a
        ``lag_time_constant`` (the tyre thermal lag) read, and the air felt after the
        admittance, which terms naming a ``felt_air_length`` read (:func:`check_model`).
    type_b : (campaign, spec, shifts, options, fit) -> source -> quantity -> sensitivity: how the
        Type B uncertainty of the test's declared values and instruments reaches the kind's
        figures (:mod:`bayes_roadload.analysis.budget`, which adds it to the draws and writes
        ``budget.csv``; ``shifts`` as :data:`~bayes_roadload.inference.shift.Shifts`): for
        speed traces Newton steps of the fit's posterior mode
        (:func:`~bayes_roadload.inference.shift.newton_sensitivities`), or without a fit the
        least-squares step of :func:`~bayes_roadload.inference.lsq.linear_sensitivities`; the
        MAPs of the shifted campaigns
        (:func:`~bayes_roadload.inference.shift.map_sensitivities`, sharing the compilation of
        ``fit``'s problem when the fit is given) for the kinds fitted through their ``problem``;
        None when the kind has none.
    problem : (campaign, spec, options) -> the kind's
        :class:`~bayes_roadload.inference.problem.Problem`, for the kinds whose fit is
        :func:`~bayes_roadload.inference.nuts.sample_problem` on it; None for speed traces
        (:func:`~bayes_roadload.inference.nuts.fit_nuts` prepares its own).
    """

    name: str
    label: str
    campaign_type: type
    default_model: Callable[[Any, FitOptions], str]
    check_options: Callable[[FitOptions], None]
    fit: Callable[[Any, ModelSpec, FitOptions], NutsFit]
    report: Callable[[NutsFit, Any], FitReport]
    extras: Callable[[NutsFit, Any, pd.DataFrame, FitOptions], dict[str, pd.DataFrame]] = \
        lambda fit, campaign, summary, options: {}
    preamble: Callable[[Any], list[str]] = lambda campaign: []
    notes: Callable[[NutsFit, Any, dict], list[str]] = lambda fit, campaign, extras: []
    input_notes: Callable[[Any, ModelSpec], list[str]] = lambda campaign, spec: []
    validity_default: str | None = None
    lsq: bool = False
    driveline_channel: Callable[[Any], Any] | None = None
    diagnosis: str | None = None
    diagnosis_model: str | None = None
    type_b: Callable[[Any, ModelSpec, Shifts, FitOptions, NutsFit | None], dict[str, dict[str, float]]] | None = None
    problem: Callable[[Any, ModelSpec, FitOptions], Problem] | None = None
    default_pooling: Callable[[Any, ModelSpec, FitOptions], str] = lambda campaign, spec, options: "pooled"
    lagged_speed_drop: bool = False
    default_models: Mapping[str, str] = field(default_factory=dict)


def check_model(entry: KindEntry, spec: ModelSpec) -> None:
    """Refuse a model whose terms need what the kind's data cannot give: a term reading the
    lagged speed drop (``lag_time_constant``) or the felt air (``felt_air_length``) needs a
    measured speed trace."""
    from ..physics.terms import TERMS

    if entry.lagged_speed_drop:
        return
    reads = [(t, "follows the tyre temperature along a measured speed trace") for t in spec.terms
             if t in TERMS and TERMS[t].lag_time_constant]
    reads += [(t, "filters the wind of a measured speed trace and its anemometer readings") for t in spec.terms
              if t in TERMS and TERMS[t].felt_air_length]
    if reads:
        term, what = reads[0]
        raise ValueError(f"model {spec.name!r}: the term {term!r} {what}, which a {entry.label} campaign does "
                         "not have; use a model without it (bayes-roadload models)")


def traces_default_model(campaign, o: FitOptions) -> str:
    """``fit`` without ``--model`` on speed traces: for the Bayesian fit, the thesis' 4-term
    analysis with the tyre temperature lagging the falling speed, the tyre's v^2 loss at its
    SAE J2452 mean (C_R's spread carried in the Type B budget), the vehicle's aerodynamic
    admittance when the campaign states the vehicle's length, the drag change of the body's
    pitch under deceleration (thesis eq. 2.33-2.35; K_alpha's spread in the budget), and the
    yaw drag's levelling and the tyre lag's time constant held at their centres with their
    spreads in the budget (``four_term_tyre_lag_admittance_pitch_shapes``), with a heavy
    vehicle's priors above :data:`~bayes_roadload.config.HEAVY_DUTY_MASS_KG` test mass
    (``four_term_tyre_lag_admittance_heavy_pitch_shapes``); the plain 4-term analysis for least
    squares (which has no prior to hold the lag's weakly identified gain); without a campaign
    (None), the light-duty name.  Chosen by measurement (docs/calibration.md, *The shapes in the
    budget*, *The pitch under deceleration*, *The vehicle's aerodynamic admittance* and *C_R's
    spread in the budget*): on the independent simulator's campaigns the anemometer's gusts read
    as the body's attenuate K_D and C_D0, and the admittance takes most of that bias away; a
    coast decelerates hardest at its highest speeds, where the nose dips most, and a model
    without the pitch reads that drag change as C_D0 too low and B_D too high; a quadratic yaw
    drag read off a drag that levels off gives a K_D below its zero-yaw curvature, which the
    levelling's spread in the budget covers."""
    if o.method == "lsq":
        return "four_term"
    heavy = campaign is not None and campaign.vehicle.mass_kg > config.HEAVY_DUTY_MASS_KG
    return ("four_term_tyre_lag_admittance_heavy_pitch_shapes" if heavy
            else "four_term_tyre_lag_admittance_pitch_shapes")


def traces_default_pooling(campaign, spec: ModelSpec, o: FitOptions) -> str:
    """``--pooling auto`` for speed traces: hierarchical (run-level AD, BD, CD0) for a NUTS fit
    of :data:`~bayes_roadload.config.AUTO_HIERARCHICAL_MIN_RUNS` (two pairs) to
    :data:`~bayes_roadload.config.AUTO_HIERARCHICAL_MAX_RUNS` runs whose model frees
    any of them, pooled otherwise (least squares, robust noise, a latent wind per pair:
    combinations the hierarchical model does not have; larger campaigns, whose hierarchical fit
    takes many times the pooled one's time -- ``--pooling hierarchical`` still fits them).  Measured
    in docs/calibration.md (test-to-test variation): the pooled model claims a precision the
    runs' scatter contradicts (thesis case 14, 3 pairs: F50_N rms z 4.0 pooled, 1.7
    hierarchical; the demo's 95 % intervals hold the truth for 6 of 8 quantities pooled, 8 of 8
    hierarchical)."""
    latent_wind = spec.resolve_air(campaign) == "wind" and "head_wind_mps" in spec.free
    varying = any(p in spec.free for p in HIERARCHICAL_PARAMETERS)
    runs = len(o.runs) if o.runs is not None else len(campaign.run_ids)
    if o.method == "nuts" and not o.robust and not latent_wind and varying \
            and config.AUTO_HIERARCHICAL_MIN_RUNS <= runs <= config.AUTO_HIERARCHICAL_MAX_RUNS:
        return "hierarchical"
    return "pooled"


def resolve_pooling(entry: "KindEntry", campaign, spec: ModelSpec, o: FitOptions) -> FitOptions:
    """``o`` with ``pooling="auto"`` replaced by the kind's default (:attr:`KindEntry.default_pooling`)."""
    if o.pooling != "auto":
        return o
    return dataclasses.replace(o, pooling=entry.default_pooling(campaign, spec, o))


# ----------------------------------------------------------------------------- option checks

def _nuts_only(label: str, *, pooling: bool = False) -> Callable[[FitOptions], None]:
    """Refuse ``--method lsq`` and the trace-likelihood options for a kind with its own
    likelihood (``pooling``: the kind has a hierarchical pooling of its own)."""
    def check(o: FitOptions) -> None:
        if o.method != "nuts":
            raise ValueError(f"a {label} campaign is fitted by --method nuts only")
        if (o.pooling not in ("auto", "pooled") and not pooling) or o.robust or o.noise != "integrated" or o.validity:
            raise ValueError(f"a {label} campaign has its own likelihood: "
                             + ("" if pooling else "--pooling, ") + "--noise, --robust and --validity do not apply")
    return check


def _check_traces(o: FitOptions) -> None:
    return None


def _check_intervals(o: FitOptions) -> None:
    if o.method != "nuts":
        raise ValueError("an interval campaign (intervals.csv) is fitted by --method nuts only")
    if o.pooling not in ("auto", "pooled") or o.robust or o.noise != "integrated":
        raise ValueError("an interval campaign has its own likelihood (gate timing, band noise, run effect): "
                         "--pooling, --noise and --robust do not apply")


def _check_spindown(o: FitOptions) -> None:
    _nuts_only("spin-down", pooling=True)(o)
    if o.undriven:
        raise ValueError("--undriven feeds a spin-down result into coastdown or steady-state fits; a spin-down "
                         "campaign is what gives it")


def _check_steady(o: FitOptions) -> None:
    _nuts_only("steady-state")(o)
    if o.compare and not (Path(o.compare) / "summary.csv").is_file():
        raise FileNotFoundError(f"{Path(o.compare) / 'summary.csv'}: --compare takes the output directory of a "
                                "coastdown `fit`")


# ----------------------------------------------------------------------------- fits

def _fit_traces(campaign, spec, o: FitOptions) -> NutsFit:
    if o.runs is not None and list(o.runs) != list(campaign.run_ids):
        campaign = campaign.subset(o.runs)
    pooling = resolve_pooling(KINDS["traces"], campaign, spec, o).pooling
    return fit_nuts(campaign, spec, pooling=pooling, noise=o.noise, robust=o.robust, sampler=o.sampler)


def _intervals_problem(campaign, spec, o: FitOptions) -> Problem:
    return build_interval_problem(campaign, spec, runs=o.runs)


def _distances_problem(campaign, spec, o: FitOptions) -> Problem:
    return build_distance_problem(campaign, spec, runs=o.runs)


def _spindown_problem(campaign, spec, o: FitOptions) -> Problem:
    return build_spindown_problem(campaign, spec, pooling=resolve_pooling(KINDS["spindown"], campaign, spec, o).pooling)


def _steady_problem(campaign, spec, o: FitOptions) -> Problem:
    return build_steady_problem(campaign, spec, wind=resolve_wind(campaign, o.steady_wind))


def _sampled(build: Callable[[Any, ModelSpec, FitOptions], Problem]) -> Callable[[Any, ModelSpec, FitOptions], NutsFit]:
    """The fit of a kind fitted through its problem: MAP, Laplace whitening, NUTS and gates."""
    def fit(campaign, spec, o: FitOptions) -> NutsFit:
        problem = build(campaign, spec, o)
        return sample_problem(problem, problem.initial, o.sampler, campaign.truth)
    return fit


# ----------------------------------------------------------------------------- Type B sensitivities

def _traces_type_b(campaign, spec, shifts: Shifts, o: FitOptions, fit: NutsFit | None = None
                   ) -> dict[str, dict[str, float]]:
    """On the fitted runs: with the NUTS fit and its MAP, one Newton step of the posterior mode
    per shifted campaign, the noise scales and run-effect spreads held at the MAP
    (:func:`~bayes_roadload.inference.shift.newton_sensitivities`; the
    shifted problems built as the fit's, :func:`~bayes_roadload.inference.bayes.problem_like`,
    their run effects linearised where the MAP puts each run; a model constant's
    :class:`~bayes_roadload.inference.shift.FixedShift` is the fitted problem itself); without,
    or should that fail (logged), the least-squares step
    (:func:`~bayes_roadload.inference.lsq.linear_sensitivities`), which has no model constants."""
    if o.runs is not None and list(o.runs) != list(campaign.run_ids):
        campaign = campaign.subset(o.runs)
        shifts = {k: (p.subset(o.runs), m.subset(o.runs), h) for k, (p, m, h) in shifts.items()}
    if fit is not None and fit.map is not None:
        try:
            return newton_sensitivities(_shifted_trace_problems(fit.problem, fit.map, campaign), shifts,
                                        (fit.problem, fit.map), held=fit.problem.scale_sites)
        except Exception as e:  # noqa: BLE001 - the budget falls back, the fit does not stop here
            log.warning("Type B from the posterior failed (%s: %s); the least-squares step instead",
                        type(e).__name__, e)
    return linear_sensitivities(campaign, spec, campaign_shifts(shifts))[1]


def _shifted_trace_problems(problem, mode, campaign) -> Callable[[Any], Any]:
    """campaign -> its problem built as the fitted ``problem``
    (:func:`~bayes_roadload.inference.bayes.problem_like`), a hierarchical problem's run effects
    linearised where the MAP ``mode`` puts each run (its conditional-mean run effects), by one
    compilation of the run sensitivities shared by every campaign of the fitted one's shape
    (:class:`~bayes_roadload.inference.shift.SharedData`)."""
    if not problem.varying:
        return lambda c: problem_like(problem, c)
    means = run_effect_means(problem, mode.constrained)
    shared = SharedData(problem_like(problem, campaign)).compile(_run_sensitivities_of_own_batch)

    def sensitivities(p, base, v0, batch):
        jac = shared(p, base, v0)
        return run_sensitivities(p, base, v0, batch) if jac is None else jac
    return lambda c: problem_like(problem, c, mode.constrained, means, sensitivities)


def _run_sensitivities_of_own_batch(p, base, v0):
    """The run sensitivities of ``p`` on its own batch (:func:`~bayes_roadload.inference.bayes.
    run_sensitivities`): one function object, so that every same-shaped campaign of a process
    reuses its compilation (:meth:`~bayes_roadload.inference.shift.SharedData.compile`)."""
    return run_sensitivities(p, base, v0, p.batch)


def _map_type_b(build: Callable[[Any, ModelSpec, FitOptions], Problem]):
    """The MAPs of the shifted campaigns (:func:`~bayes_roadload.inference.shift.map_sensitivities`)."""
    def type_b(campaign, spec, shifts: Shifts, o: FitOptions, fit: NutsFit | None = None
               ) -> dict[str, dict[str, float]]:
        base = (fit.problem, fit.map) if fit is not None and fit.map is not None else None
        return map_sensitivities(lambda c: build(c, spec, o), shifts, base)
    return type_b


def _through_problem(build: Callable[[Any, ModelSpec, FitOptions], Problem]) -> dict[str, Any]:
    """The members of a kind fitted through its problem ``build``: the problem, its fit
    (:func:`_sampled`) and its Type B sensitivities (:func:`_map_type_b`)."""
    return {"problem": build, "fit": _sampled(build), "type_b": _map_type_b(build)}


# ----------------------------------------------------------------------------- printing and extras

def _air_notes(fit, campaign, extras) -> list[str]:
    """The air the fit took (:func:`~bayes_roadload.data.ambient.ambient_line`), printed after
    the posterior table (a failed gate stays the first line) by every kind whose model has an
    aerodynamic force."""
    from ..data.ambient import ambient_line, ambient_record

    return [ambient_line(ambient_record(campaign))]


def _trace_air_notes(fit, campaign, extras) -> list[str]:
    """:func:`_air_notes`, and, when the model took still air for want of an anemometer, that it
    did and which model estimates the wind instead."""
    lines = _air_notes(fit, campaign, extras)
    if not campaign.has_anemometer and fit.problem.spec.resolve_air(campaign) == "still":
        lines.append("note: no anemometer logged (airspeed_mps, yaw_rad): the fit takes still air, and a wind that "
                     "differs between the directions biases the coefficients; --model speed_only_wind fits a latent "
                     "wind per pair")
    return lines


GRADE_TERMS = ("gradient", "gradient_profile")
"""Terms of a model file that carry the track's grade themselves (fitted, not surveyed)."""


def _survey_lines(campaign, spec: ModelSpec) -> list[str]:
    """The track survey the fit read (``track.csv``: stations, stretch, the RMS grade at the
    logged positions), or, for runs that log their position without one and a model without a
    grade term of its own (:data:`GRADE_TERMS`), that the grade is not in the model."""
    if campaign.has_track_survey:
        from ..data.track import grade_at

        t = campaign.track
        rms = float(np.sqrt(np.mean(grade_at(t, campaign.runs["position_m"].to_numpy(float)) ** 2)))
        return [f"track survey: {len(t)} stations over {t['position_m'].iloc[0]:g} to {t['position_m'].iloc[-1]:g} m, "
                f"RMS grade {100 * rms:.3f} % at the logged positions: the fit adds its force (surveyed_gradient, eq. 2.1)"]
    if "position_m" in campaign.runs and not any(t in spec.terms for t in GRADE_TERMS):
        return ["no track survey (track.csv): the grade along the track is not in the model "
                "(40 CFR 1066.310 has a grade above 0.02 % enter the analysis)"]
    return []


def _speed_coverage_lines(campaign) -> list[str]:
    """When no run passes through the 50 mph of ``F50_N``
    (:data:`~bayes_roadload.config.SPEED_50MPH_MPS`), a note that the figure is the model's
    speed law carried between or beyond the runs' speeds (its interval says how far the data
    constrain it; the coefficients' split between speed-independent and v^2 terms rests on the
    speeds the runs span)."""
    ref = config.SPEED_50MPH_MPS
    spans = campaign.runs.groupby("run", sort=False)["speed_mps"].agg(["min", "max"])
    if ((spans["min"] <= ref) & (spans["max"] >= ref)).any():
        return []
    kph = 1.0 / config.KPH_TO_MPS
    return [f"note: no run passes through F50_N's {ref * kph:.1f} km/h (the runs logged "
            f"{spans['min'].min() * kph:.0f}-{spans['max'].max() * kph:.0f} km/h): its value is the model's speed "
            "law carried to that speed"]


def _trace_input_lines(campaign, spec: ModelSpec) -> list[str]:
    """The inputs' notes of a speed-trace fit: the track survey (:func:`_survey_lines`) and the
    speed coverage (:func:`_speed_coverage_lines`)."""
    return [*_survey_lines(campaign, spec), *_speed_coverage_lines(campaign)]


def _distance_preamble(campaign) -> list[str]:
    masses = sorted(set(campaign.masses_kg().values()))
    return [f"{len(campaign.run_ids)} runs at {', '.join(f'{m:g}' for m in masses)} kg, "
            f"{len(campaign.markers)} marker passings"]


def _spindown_notes(fit, campaign, extras) -> list[str]:
    lines = ["\nAgainst thesis table 7.10 (A_u = 3.24 N, B_u = 0.232 N s/m):"]
    for _, r in extras["table_7_10.csv"].iterrows():
        lines.append(f"  {r['parameter']}: {r['mean']:.4g} [{r['q2.5']:.4g}, {r['q97.5']:.4g}]  thesis "
                     f"{r['thesis_table_7_10']:.4g} +- {r['thesis_sd']:.3g}  ({r['difference_pct']:+.1f} %)")
    return lines


def _steady_extras(fit, campaign, summary, o: FitOptions) -> dict[str, pd.DataFrame]:
    out = steady_extras(fit, campaign, summary)
    if o.compare:
        out["comparison.csv"] = compare_with_coastdown(summary, pd.read_csv(Path(o.compare) / "summary.csv"))
    return out


def _steady_notes(fit, campaign, extras) -> list[str]:
    lines = [f"relative air: {fit.problem.wind}; acceleration: {campaign.accel_source}"]
    if "comparison.csv" in extras:
        lines.append("\nsteady state against coastdown (thesis table 7.11: steady AD +12 %, BD -11 %, CD0 +4.9 %):")
        for _, r in extras["comparison.csv"].iterrows():
            lines.append(f"  {r['parameter']:<6} coastdown {r['coastdown_mean']:.4g} +- {r['coastdown_sd']:.2g}   "
                         f"steady {r['steady_mean']:.4g} +- {r['steady_sd']:.2g}   {r['difference_pct']:+.1f} % "
                         f"({r['difference_z']:+.1f} sd)")
    return lines


def _steady_default_model(campaign, o: FitOptions) -> str:
    return "four_term" if resolve_wind(campaign, o.steady_wind) == "measured" else "three_term"


# ----------------------------------------------------------------------------- the registry

KINDS: dict[str, KindEntry] = {e.name: e for e in (
    KindEntry("traces", "speed-trace", Campaign, traces_default_model, _check_traces, _fit_traces,
              trace_report, lsq=True, driveline_channel=off_load_channel, diagnosis="traces",
              diagnosis_model="three_term", type_b=_traces_type_b, default_pooling=traces_default_pooling,
              lagged_speed_drop=True, notes=_trace_air_notes, input_notes=_trace_input_lines,
              default_models={"four_term_tyre_lag_admittance_pitch_shapes":
                                  f"Bayesian fit up to {config.HEAVY_DUTY_MASS_KG:g} kg test mass",
                              "four_term_tyre_lag_admittance_heavy_pitch_shapes":
                                  f"Bayesian fit above {config.HEAVY_DUTY_MASS_KG:g} kg test mass",
                              "four_term": "least squares (--method lsq)"}),
    KindEntry("intervals", "interval", IntervalCampaign, lambda c, o: "split_f0_f2", _check_intervals,
              report=interval_report, validity_default="reject", diagnosis="band_times", notes=_air_notes,
              diagnosis_model="split_f0_f2", default_models={"split_f0_f2": "always"},
              **_through_problem(_intervals_problem)),
    KindEntry("distances", "distance-time", DistanceCampaign, lambda c, o: DISTANCE_DEFAULT_MODEL,
              _nuts_only("distance-time"), report=distance_report, preamble=_distance_preamble, notes=_air_notes,
              diagnosis="band_times", diagnosis_model=DISTANCE_DEFAULT_MODEL, default_models={DISTANCE_DEFAULT_MODEL: "always"},
              **_through_problem(_distances_problem)),
    KindEntry("spindown", "spin-down", SpindownCampaign, lambda c, o: "undriven_spindown", _check_spindown,
              report=spindown_report, extras=lambda f, c, s, o: spindown_extras(f, c, s), notes=_spindown_notes,
              default_models={"undriven_spindown": "always"}, **_through_problem(_spindown_problem)),
    KindEntry("steady", "steady-state", SteadyCampaign, _steady_default_model, _check_steady,
              report=steady_report, extras=_steady_extras, driveline_channel=on_load_channel,
              notes=lambda f, c, e: _steady_notes(f, c, e) + _air_notes(f, c, e),
              default_models={"four_term": "measured wind", "three_term": "no measured wind"},
              **_through_problem(_steady_problem)),
)}
"""kind name -> :class:`KindEntry`, one line per data kind."""


def kind_of(campaign) -> KindEntry:
    """The registry entry of a campaign (by its class)."""
    for entry in KINDS.values():
        if isinstance(campaign, entry.campaign_type):
            return entry
    raise ValueError(f"{type(campaign).__name__} is not a campaign of a registered data kind "
                     f"({', '.join(KINDS)})")
