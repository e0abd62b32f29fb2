"""Type B uncertainty in every reported quantity, and the uncertainty budget (GUM 5.1.2).

The test's own uncertainty sources (:mod:`bayes_roadload.data.uncertainty`: declared mass and
rotating inertia, the anemometer's airspeed factor and yaw, speed, temperature and pressure
sensors, the driveline transducer) are not informed by the coastdown: the posterior holds them
fixed at their declared values.  They are marginalised to first order after the fit:

* **sensitivities** ``c_{x,s} = dx/ds`` of every reported quantity x (free coefficients and the
  derived figures) to every source s, when the campaign's source is shifted by ``+-u_s``
  (:meth:`~bayes_roadload.data.uncertainty.UncertaintySource.apply`; what it acts on in each
  kind: :class:`~bayes_roadload.data.uncertainty.TypeBChannels`), as the kind's registry entry
  computes them (:attr:`~bayes_roadload.inference.kinds.KindEntry.type_b`):

  - speed traces with the NUTS fit (``fit``, ``batch``): the change of the posterior mode,
    one Newton step from the fitted MAP per shifted campaign with the noise scales and
    run-effect spreads held, or the shifted MAPs where a step leaves the potential's quadratic
    region (:func:`~bayes_roadload.inference.shift.newton_sensitivities`; within 5 % of each
    quantity's Type B uncertainty of the shifted MAPs refitted, tested).  The priors bound
    what the data hardly identify: the least-squares step moved A_D's Type B sd to 10x the
    posterior step's on the design seeds (``benchmarks/type_b_newton_step.py``);
  - speed traces without a fit (planning's floor): the change of the joint least-squares
    estimate (:func:`~bayes_roadload.inference.lsq.fit_lsq`, one group), by central
    differences of the residuals at the optimum and one Gauss-Newton step
    (:func:`~bayes_roadload.inference.lsq.linear_sensitivities`; ``method="refit"`` refits
    each shifted campaign instead, five to seven times slower at 36 runs; the two agree to a
    few per cent of each source's contribution, tested);
  - intervals, distance-time, spin-down and steady state: central differences of the MAPs of
    the shifted campaigns (:func:`~bayes_roadload.inference.shift.map_sensitivities`; they
    share one compilation of the fit's potential and start at its MAP);
* **draws**: every posterior draw gets ``sum_s c_{x,s} delta_s`` with ``delta_s ~ N(0, u_s^2)``
  drawn once per draw and shared by all quantities (so their correlations through a common
  source are kept) -- the law of propagation of uncertainty (GUM eq. 10) applied draw by draw;
  a source whose true value lies above the analysis' (the humidity where it is not logged: the
  analysis takes dry air; a model constant whose file says ``uncertainty_distribution =
  "above"``) draws ``delta_s ~ U(0, sqrt(12) u_s)`` instead, so that its draws also carry its
  mean, ``c_{x,s} sqrt(3) u_s`` (budget column ``mean_shift``);
* **budget**: the share of each source in the variance of each quantity,
  ``c_{x,s}^2 u_s^2 / (var_data + sum_s c_{x,s}^2 u_s^2)``, and the share of the data (the
  posterior's own variance).  The shares sum to 1.

A model file may give a fixed constant a standard uncertainty (``[parameters.NAME]
uncertainty``, :mod:`bayes_roadload.inference.spec`): that constant is a source too, shifted in
the fitted problem itself (:class:`~bayes_roadload.inference.shift.FixedShift`,
:meth:`~bayes_roadload.inference.problem.Problem.shift_constant`) and carried by the same
steps, keyed by its parameter name; it needs the fit (planning's least-squares floor leaves it
out).  A source the model samples itself (a free ``airspeed_factor`` or ``yaw_factor`` of a
``*_calibrated`` model) is left to the posterior; a source the campaign has nothing for (no
temperature channel, no driveline channel) is not applicable.  First order and independent
sources: a source whose effect is not linear over +-2 u (over [0, sqrt(12) u] for a one-sided
one), or two sources that share an error, are outside this budget.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import pandas as pd

from ..data.uncertainty import SOURCES, source_distribution, standard_uncertainties
from ..inference.kinds import FitOptions, kind_of
from ..inference.lsq import fit_lsq
from ..inference.results import SUMMARY_COLUMNS
from ..inference.shift import campaign_shifts, fixed_shifts
from ..inference.spec import ModelSpec, load_model_spec

SAMPLED_BY_MODEL = {"airspeed_factor_rel": "airspeed_factor", "yaw_factor_rel": "yaw_factor"}
"""Sources that a model can sample itself: source key -> the model's free parameter."""
BUDGET_QUANTITIES = ("AD", "BD", "CD0", "KD", "At", "Bt", "Ct", "F50_N", "F0_N", "F1_N_per_kph", "F2_N_per_kph2",
                     "Au", "Bu", "F50_undriven_N")
"""Quantities whose Type B sensitivities are computed (those the model reports)."""
CONSTANT_SD = 1e-9
"""Standard uncertainty (data and Type B together, in the quantity's units) below which a
quantity is a constant of the model and has no budget.  Rounding leaves such a constant at
~1e-13 and below: F1_N_per_kph of a model without a linear term is the least-squares fit
(``physics.roadload.road_load_summary``) of forces up to ~1e4 N, exact to eps * 1e4 N / 10 km/h
~ 2e-13.  A fitted quantity's uncertainty is above ~1e-6 (AD, the smallest, is ~1e-2 known to
~1 %), so the floor sits three orders of magnitude from either."""

BUDGET_COLUMNS = ("quantity", "source", "standard_uncertainty", "sensitivity", "variance", "variance_share", "note",
                  "mean_shift")


@dataclass
class TypeB:
    """Sensitivities of a campaign's reported quantities to its Type B sources.

    ``u``: source -> standard uncertainty (key's unit); ``sensitivity``: quantity -> source ->
    dx/ds; ``notes``: source -> why it is not propagated ("not applicable", "sampled by the
    model", "switched off"); ``time_s``: the least-squares refits' wall time; ``distribution``:
    model constant -> its distribution where the model file states one
    (:data:`~bayes_roadload.inference.spec.UNCERTAINTY_DISTRIBUTIONS`)."""

    u: dict[str, float]
    sensitivity: dict[str, dict[str, float]]
    notes: dict[str, str] = field(default_factory=dict)
    time_s: float = 0.0
    distribution: dict[str, str] = field(default_factory=dict)

    @property
    def sources(self) -> list[str]:
        return [s for s in self.u if s not in self.notes]

    def distribution_of(self, source: str) -> str:
        """The distribution of ``source``'s error: the model file's for a model constant, else
        the campaign source's (:func:`~bayes_roadload.data.uncertainty.source_distribution`)."""
        return self.distribution.get(source) or source_distribution(source)

    def variances(self, quantity: str) -> dict[str, float]:
        """Source -> the variance (c_s u_s)^2 it gives ``quantity`` (empty: no sensitivity)."""
        return {s: (c * self.u[s]) ** 2 for s, c in self.sensitivity.get(quantity, {}).items()}


def type_b_shifts(campaign, spec: ModelSpec) -> tuple[dict[str, float], dict, dict[str, str]]:
    """The campaign's standard uncertainties ``u``, the shifted campaigns ``source -> (campaign
    shifted by +u, by -u, u)`` of every source that applies, and a note for each that does not
    (switched off, sampled by the model, refused by the campaign's checks, no channel)."""
    u = standard_uncertainties(campaign)
    notes: dict[str, str] = {}
    shifts = {}
    for key, source in SOURCES.items():
        if u[key] <= 0.0:
            notes[key] = "switched off ([uncertainty] = 0)"
            continue
        if SAMPLED_BY_MODEL.get(key) in spec.free:
            notes[key] = f"sampled by the model ({SAMPLED_BY_MODEL[key]} is free)"
            continue
        try:
            plus, minus = source.apply(campaign, u[key]), source.apply(campaign, -u[key])
        except ValueError as e:  # CampaignError: the shifted campaign leaves its checks' ranges
            notes[key] = f"not propagated (the campaign shifted by +-u is refused: {e})"
            continue
        if plus is None or minus is None:
            notes[key] = "not applicable (the campaign has no channel it acts on)"
            continue
        shifts[key] = (plus, minus, u[key])
    return u, shifts, notes


def type_b_sensitivities(campaign, spec: ModelSpec | str, quantities: Sequence[str] = BUDGET_QUANTITIES,
                         method: str = "linear", options: FitOptions = FitOptions(), fit=None) -> TypeB:
    """Central-difference sensitivities of the campaign's estimate (module docstring), as its
    kind computes them (:attr:`~bayes_roadload.inference.kinds.KindEntry.type_b`; ``options``:
    the fit's, e.g. the runs fitted; ``fit``: the NUTS fit, whose problem's compilation and MAP
    the kinds that refit MAPs reuse, and from whose MAP a speed-trace fit's Newton steps
    start).  For speed traces without ``fit``, ``method="linear"`` takes one Gauss-Newton step
    from the unshifted least-squares optimum, ``"refit"`` refits each shifted campaign (two
    least-squares fits per source, all runs); equal to first order in the shifts."""
    if method not in ("linear", "refit"):
        raise ValueError(f"method must be 'linear' or 'refit', not {method!r}")
    entry = kind_of(campaign)
    if entry.type_b is None:
        raise ValueError(f"a {entry.label} campaign has no Type B propagation")
    spec = load_model_spec(spec) if isinstance(spec, str) else spec
    t0 = time.perf_counter()
    u, shifts, notes = type_b_shifts(campaign, spec)
    if spec.uncertainty:
        u.update(spec.uncertainty)
        if fit is not None and fit.map is not None:
            constants, why = fixed_shifts(fit.problem, spec.uncertainty)
            shifts, notes = {**shifts, **constants}, {**notes, **why}
        else:
            notes.update({p: "not propagated (a model constant is shifted in the fit's problem: no fit given)"
                          for p in spec.uncertainty if p not in notes})
    sens: dict[str, dict[str, float]] = {}
    if shifts and (method == "linear" or not entry.lsq):
        rows = entry.type_b(campaign, spec, shifts, options, fit)
    else:
        rows = {}
        refitted = campaign_shifts(shifts)
        notes.update({key: "not propagated (the least-squares refits have no model constants to shift)"
                      for key in shifts if key not in refitted})
        for key, (plus, minus, h) in refitted.items():
            hi, lo = fit_lsq(plus, spec, grouping="all"), fit_lsq(minus, spec, grouping="all")
            rows[key] = {q: (hi.weighted_mean[q] - lo.weighted_mean[q]) / (2.0 * h)
                         for q in hi.weighted_mean if q in lo.weighted_mean}
    for key in shifts:
        if key not in rows:
            notes.setdefault(key, "not propagated (the shifted campaign changes the model's structure, or its fit "
                                  "failed: the log says which)")
            continue
        for q in quantities:
            c = rows[key].get(q)
            if c is None or not math.isfinite(c):
                continue
            sens.setdefault(q, {})[key] = c
    return TypeB(u=u, sensitivity=sens, notes=notes, time_s=time.perf_counter() - t0,
                 distribution=dict(spec.uncertainty_distribution))


def type_b_draws(typeb: TypeB, shape: tuple[int, ...], seed: int = 0) -> dict[str, np.ndarray]:
    """``delta_s`` for every propagated source, one per draw (``shape``): N(0, u_s^2), or
    U(0, sqrt(12) u_s) for a source whose true value lies above the analysis' (distribution
    "above", :meth:`TypeB.distribution_of`: a campaign source's
    :class:`~bayes_roadload.data.uncertainty.UncertaintySource`, or a model file's
    ``uncertainty_distribution``)."""
    rng = np.random.default_rng([seed, 20240])
    return {s: (rng.uniform(0.0, math.sqrt(12.0) * typeb.u[s], shape) if typeb.distribution_of(s) == "above"
                else rng.normal(0.0, typeb.u[s], shape)) for s in typeb.sources}


def mean_shift(typeb: TypeB, quantity: str, source: str) -> float:
    """The mean of the draws ``source`` adds to ``quantity``: c sqrt(3) u for a source above the
    analysis' value, 0 for a normal one."""
    c = typeb.sensitivity.get(quantity, {}).get(source)
    if c is None or typeb.distribution_of(source) != "above":
        return 0.0
    return c * math.sqrt(3.0) * typeb.u[source]


def add_type_b(posterior: dict[str, np.ndarray], typeb: TypeB, seed: int = 0) -> dict[str, np.ndarray]:
    """The draws of every quantity with a sensitivity, plus ``sum_s c_{x,s} delta_s``
    (``posterior``: name -> [chain, draw] array; others are returned unchanged)."""
    if not posterior:
        return {}
    shape = np.shape(next(iter(posterior.values())))[:2]
    deltas = type_b_draws(typeb, shape, seed)
    out = dict(posterior)
    for q, row in typeb.sensitivity.items():
        if q in out and np.ndim(out[q]) == 2:
            out[q] = np.asarray(out[q], float) + sum(c * deltas[s] for s, c in row.items() if s in deltas)
    return out


def budget_table(typeb: TypeB, data_sd: dict[str, float]) -> pd.DataFrame:
    """``budget.csv``: per quantity, a row per source (standard uncertainty, sensitivity, its
    variance c^2 u^2 and share, and ``mean_shift``, the mean its draws add: non-zero for a
    source above the analysis' value, :func:`mean_shift`) and a ``data`` row (the posterior's
    own variance), then a row per source left out with the reason.  A quantity without variance (a constant of the
    model, e.g. F50_undriven_N of a fit without undriven wheels, F1_N_per_kph of one without a
    linear term: total standard uncertainty below :data:`CONSTANT_SD`) has no rows."""
    rows = []
    for q, sd in data_sd.items():
        row = typeb.sensitivity.get(q, {})
        var = typeb.variances(q)
        total = sd**2 + sum(var.values())
        if not total > CONSTANT_SD**2:
            continue
        rows.append({"quantity": q, "source": "data", "standard_uncertainty": math.nan, "sensitivity": math.nan,
                     "variance": sd**2, "variance_share": sd**2 / total, "note": "", "mean_shift": math.nan})
        for s in sorted(var, key=var.get, reverse=True):
            above = typeb.distribution_of(s) == "above"
            rows.append({"quantity": q, "source": s, "standard_uncertainty": typeb.u[s], "sensitivity": row[s],
                         "variance": var[s], "variance_share": var[s] / total,
                         "note": "uniform above the analysis' value" if above else "",
                         "mean_shift": mean_shift(typeb, q, s)})
    for s, why in typeb.notes.items():
        rows.append({"quantity": "", "source": s, "standard_uncertainty": typeb.u[s], "sensitivity": math.nan,
                     "variance": math.nan, "variance_share": math.nan, "note": why, "mean_shift": math.nan})
    return pd.DataFrame(rows, columns=list(BUDGET_COLUMNS))


def budget_record(typeb: TypeB, data_sd: dict[str, float]) -> dict[str, float]:
    """The budget of each quantity of ``data_sd`` as flat columns of a study's record:
    ``{q}_sd_data`` (the posterior's own sd), ``{q}_sd_typeb_{source}`` (|c_s| u_s, the sd its
    draws add; a uniform source's sd is its u as well), ``{q}_signed_typeb_{source}`` (c_s u_s
    with its sign: which way the quantity moves when the source's true value lies above the
    analysis', so a study can read the source made one-sided) and, for a source above the
    analysis' value, ``{q}_mean_shift_{source}`` (:func:`mean_shift`).  With them a study can read which
    sources make its intervals too wide or too narrow: the interval's sd is about
    sqrt(sd_data^2 + sum of the sources' sd^2) (the sources' draws are independent of the
    posterior's)."""
    out: dict[str, float] = {}
    for q, sd in data_sd.items():
        out[f"{q}_sd_data"] = float(sd)
        for s, c in typeb.sensitivity.get(q, {}).items():
            out[f"{q}_sd_typeb_{s}"] = abs(float(c)) * typeb.u[s]
            out[f"{q}_signed_typeb_{s}"] = float(c) * typeb.u[s]
            if typeb.distribution_of(s) == "above":
                out[f"{q}_mean_shift_{s}"] = mean_shift(typeb, q, s)
    return out


def format_budget(budget: pd.DataFrame, quantities: Sequence[str] = ("F50_N", "CD0", "F50_undriven_N"),
                  top: int = 3) -> str:
    """A few lines for the terminal: each quantity's data share and its largest sources (those
    of ``quantities`` the budget has)."""
    lines = ["Uncertainty budget (share of the variance; budget.csv has every source):"]
    for q in quantities:
        g = budget[budget["quantity"] == q]
        if g.empty:
            continue
        parts = [f"{r.source} {100 * r.variance_share:.0f} %" for r in g.head(top + 1).itertuples()]
        shifts = [f"{r.source} shifts it by {r.mean_shift:+.4g}" for r in g.itertuples()
                  if np.isfinite(r.mean_shift) and r.mean_shift != 0.0]
        lines.append(f"  {q}: " + ", ".join(parts) + ("; " + "; ".join(shifts) if shifts else ""))
    return "\n".join(lines)


def add_type_b_to_idata(idata, typeb: TypeB, seed: int = 0) -> list[str]:
    """Add the Type B draws (:func:`add_type_b`) to the posterior group of ``idata`` in place;
    returns the quantities changed.  The group's attribute ``type_b`` names them."""
    post = idata.posterior
    names = [q for q in typeb.sensitivity if q in post and post[q].ndim == 2]
    new = add_type_b({q: post[q].values for q in names}, typeb, seed)
    for q in names:
        post[q] = (post[q].dims, new[q], post[q].attrs)
    post.attrs["type_b"] = ("first-order Type B draws added (analysis.budget): " + ", ".join(names)) if names else ""
    return names


def propagate_type_b(report, campaign, spec: ModelSpec | str, seed: int = 0, options: FitOptions = FitOptions(),
                     fit=None):
    """A fit report with the Type B uncertainty in its draws and summary, and its budget.

    Returns ``(report, budget, typeb)``: the report's posterior draws of every quantity with a
    sensitivity get the Type B draws, its summary rows are recomputed from them (mean, sd,
    quantiles; R-hat and ESS stay the sampler's, the added draws being independent), and
    ``budget`` is :func:`budget_table` with the data's own sd from the summary before."""
    quantities = [q for q in BUDGET_QUANTITIES if q in report.idata.posterior]
    typeb = type_b_sensitivities(campaign, spec, quantities, options=options, fit=fit)
    summary = report.summary.set_index("parameter")
    data_sd = {q: float(summary.loc[q, "sd"]) for q in quantities if q in summary.index}
    changed = add_type_b_to_idata(report.idata, typeb, seed)
    rows = report.summary.copy()
    for q in changed:
        x = np.asarray(report.idata.posterior[q].values, float).ravel()
        lo, mid, hi = np.percentile(x, [2.5, 50.0, 97.5])
        i = rows.index[rows["parameter"] == q]
        rows.loc[i, ["mean", "sd", "q2.5", "q50", "q97.5"]] = [x.mean(), x.std(ddof=1), lo, mid, hi]
    diag = dict(report.diagnostics or {})
    diag["type_b"] = {"sources": typeb.sources, "left_out": typeb.notes, "time_s": round(typeb.time_s, 3),
                      "quantities": changed}
    new = dataclasses.replace(report, summary=rows[list(SUMMARY_COLUMNS)], diagnostics=diag)
    return new, budget_table(typeb, data_sd), typeb
