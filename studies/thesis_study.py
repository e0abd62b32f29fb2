"""The thesis' simulation study, tables 6.8 and 6.9: classical per-pair fits of the 19 cases.

Every case of table 6.7 (:mod:`bayes_roadload.simulate.cases`) is simulated and fitted pair by
pair with :func:`~bayes_roadload.inference.lsq.fit_lsq`, with the 4-term analysis (``four_term``:
A_D, B_D, C_D0, K_D free; table 6.8) and the 3-term analysis (``three_term``: K_D fixed; table
6.9).  ``three_term`` fixes K_D at the campaign's ``[tunnel]`` K_D (fallback 0.614); the
simulator writes ``tunnel.KD`` = its true K_D, 0.614 rad^-2 (table 6.3), so K_D is fixed at the
published 0.614 and at the truth.  The results are set beside the published ones
(:data:`PUBLISHED`, :data:`PUBLISHED_CASES`), and the between-pair spread of cases 14-19 is
compared with the thesis' test-to-test spread over several seeds, with its standard error.

Layout of the study
-------------------
* One pair per case, as in the thesis (``pairs`` > 1 gives several independent pairs per case).
* Common random numbers: the simulator draws each run's wind and noise from (seed, run), so the
  cases of one seed share their wind and differ only by what table 6.7 changes (case 7 is case 2
  plus the dynamics).  Cases 15, 17 and 19 repeat the conditions of 14, 16 and 18: with the same
  draws they would be the same pair, so a repeated case takes the next ``pairs`` pairs of the
  same seed (:func:`replicate_index`); the six pairs of cases 14-19 are then independent, like
  the thesis' six runs.
* The work of one (case, seed, pairs, analysis) is the pure function :func:`fit_case`, mapped
  over :class:`CaseJob` s by an optional executor (anything with ``Executor.map``, as in
  :func:`bayes_roadload.analysis.batch.run_batch`).

Where ours differs from the published figures
---------------------------------------------
Measured with the defaults (``initial_speed="fitted"``): seed 0 with one pair per case, 10 pairs
per case for the per-pair scatter, 20 seeds x 6 pairs for the spreads; :func:`markdown` generates
the full list.

* Cases 1-6 (noise-free): the simulator integrates frozen turbulence at 0.01 s and the analysis
  sees it at 4 Hz, which limits the recovery: worst errors over 10 pairs per case A_D 0.11 %,
  B_D 0.35 %, C_D0 0.045 %, K_D 0.603-0.631, against the thesis' 0.1 %, 0.75 %, 0.125 %,
  0.613-0.678.  The thesis' B_D never exceeds 2.000e-4; ours does, by 0.03-0.12 % on average.
* Cases 7, 8 (instrument and vehicle dynamics): the thesis' C_D0 is 0.60 / 0.73 % high, ours
  -0.05 / +0.01 % (10-pair means).  Varied on seed 0: a cup distance constant of 4.5 m instead
  of 1.5 m moves C_D0 from 0.3997 / 0.3999 to 0.3988 / 0.3990 (a lagging cup reads high while
  the car slows), an admittance length of 0.3 m instead of 4.5 m to 0.3995 / 0.3995.  None of
  these gives the thesis' sign; the cause is not found.
* Case 9 (measurement noise): our 4-term K_D is 0.626 with a per-pair sd of 0.089 and A_D
  -0.12 % with sd 0.50 %; the thesis' pair (K_D 0.143, A_D +3.8 %) lies 5.4 and 7.9 sd away.
  Integrating from the first measured speed, as the thesis did (``initial_speed="measured"``),
  the per-pair sd grows to 0.40 in K_D and 1.15 % in A_D (means 0.780, -0.58 %): the thesis'
  K_D is then 1.6 sd from ours, its A_D 3.8 sd.  Our K_D is not pulled down by the noise.
* Cases 11, 12 ("comp", eq. 6.2): C_D0 -0.95 / -0.85 % where the thesis has +0.25 / +0.18 %.
  The pitch term is a reconstruction (lever l_p = 0.55 m, nose down under deceleration, so the
  drag falls as the car slows and the fit lowers C_D0).  On seed 0 without it
  (``pitch_gain = 0``) C_D0 is +0.07 / +0.15 %, with the opposite sign (nose up) +1.05 /
  +1.15 %: the thesis' figures are close to the no-pitch ones.
* Case 13 (C_D(psi) from the tunnel table): K_D 0.40 with a per-pair sd of 0.27 (seed 0's
  pair: 0.079) and C_D0 +0.75 % against the thesis' 0.654 and +0.12 %.  The term interpolates
  the table linearly and holds it beyond +-25 deg.  On seed 0's pair the yaw reaches 52 deg
  (median 8.4 deg, 90th percentile 24.7 deg), and the table adds 0.0147 to C_D on average
  (weighted by dynamic pressure) against 0.0110 for 0.614 psi^2; the fit puts the 0.0037 into
  C_D0 (+0.0039) and lowers K_D for the flat ends.  The thesis' C_D(psi) evidently followed
  K_D psi^2 more closely.
* Cases 14-19: one pair each scatters, so compare spreads (:func:`spread_table`).  Over 120
  pairs C_D0 is 1.19 % low and B_D 2.05 % high (thesis' six pairs +0.10 %, +3.37 %): the pitch
  term again (without it, 10 seeds: C_D0 +0.01 %, B_D -0.16 %).  In the pure cross-wind cases
  18, 19 it puts B_D +6.5 % and C_D0 -1.7 % (3-term, noise free, no dynamics; +0.07 %,
  +0.17 % without it).
* Spreads (20 seeds): 4-term A_D 1.11 +- 0.12 %, B_D 5.39 +- 0.64 %, C_D0 0.83 +- 0.10 %
  (0.74, 0.95, 0.76 x published).  3-term A_D 0.81 +- 0.08 %, C_D0 0.87 +- 0.10 % (1.31, 1.52
  x).  3-term B_D 5.58 +- 0.63 % against 2.21 % (2.5 x; one seed in 20 below it).  Fixing K_D
  cut the thesis' B_D spread 2.6-fold and leaves ours unchanged (5.39 -> 5.58 %).  Most of
  ours comes from the pure cross-wind cases 18 and 19, whose per-pair B_D sd is 7-9 % against
  3-4 % in 14-17 (3-term spread over 14-17 alone: 1.87 +- 0.22 %).  It is per-pair noise, not the pitch bias: without
  pitch the spread is 5.21 +- 0.75 % (10 seeds).  On six pairs of case 18 (seed 0, 3-term) the
  per-pair B_D sd is 6.4 % with both noises, 5.2 % with measurement noise alone, 4.7 % with
  system noise alone, 0.24 % without noise or dynamics.  Likely reason: with no head wind both
  runs of a pair meet the same relative air, so nothing separates B_D v from C_D0 q_r as the
  head/tail pairs of 14-17 do.  The thesis' own 3-term B_D of cases 18, 19 (2.046, 2.062) lies within
  0.6 per-pair sd of our means.
* 4-term K_D spread: 15.5 +- 2.0 % against 40.8 % (0.38 x; 19 of 20 seeds below it).  Our K_D
  sensitivity at 3 m/s cross wind is 1.4 x the thesis' (table 6.2,
  :mod:`~bayes_roadload.analysis.sensitivity`), which explains a factor of about 1.4 of the 2.6;
  the rest is not found.
* The thesis' method (``initial_speed="measured"``) does not give its spreads: 4-term A_D
  3.5 %, B_D 15 %, C_D0 2.4 %, K_D 78 % (2.2-2.7 x published), 3-term 2.6, 17.5, 2.7 % (4-8 x).
  The default, fitted initial speeds, comes closer.
"""

from __future__ import annotations

import functools
import math
import time
import warnings
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

import numpy as np
import pandas as pd

from bayes_roadload.inference.lsq import LsqSettings, between_group_spread, fit_lsq
from bayes_roadload.simulate import CASES, SimulationCase, get_case, simulate_campaign

PARAMETERS = ("AD", "BD", "CD0", "KD")
"""The coefficients of tables 6.8 and 6.9 (SI: B_D in s/m)."""

ANALYSES = {"4-term": "four_term", "3-term": "three_term"}
"""Analysis label of the thesis -> model variant (``models/*.toml``) fitted by least squares."""

FREE = {"4-term": ("AD", "BD", "CD0", "KD"), "3-term": ("AD", "BD", "CD0")}
"""The coefficients each analysis estimates."""

# --------------------------------------------------------------------------- published figures

PUBLISHED = {
    "4-term": {
        "table": "6.8",
        "cases_1_6_range": {"AD": (0.00999, 0.01000), "BD": (1.985e-4, 2.000e-4),
                            "CD0": (0.4000, 0.4005), "KD": (0.613, 0.678)},
        "case_10": {"AD": 0.01008, "BD": 1.973e-4, "CD0": 0.4014, "KD": 0.434},
        "case_9": {"AD": 0.01038, "BD": 1.963e-4, "CD0": 0.4016, "KD": 0.143},
        "spread_14_19_pct": {"AD": 1.5, "BD": 5.7, "CD0": 1.1, "KD": 40.8},
    },
    "3-term": {
        "table": "6.9",
        "KD_fixed": 0.614,
        "spread_14_19_pct": {"AD": 0.62, "BD": 2.21, "CD0": 0.57},
    },
}
"""The published recoveries (ROADLOAD_MODEL.md section 4), per analysis, with the thesis table
they come from: the 4-term range over the noise-free validation cases 1-6; cases 9 (measurement
noise) and 10 (system noise); the test-to-test spread over the six pairs of cases 14-19 (sample
standard deviation in % of the mean); the 3-term analysis' fixed K_D.  (Section 4 labels the
row 0.01008 / 1.973 / 0.4014 / 0.434 "case 10 (measurement noise)"; in table 6.8 that row is
case 10, which table 6.7 and the simulator make the system-noise case.  The thesis text, whose
case numbers run one ahead of its tables there, attributes the 3.8 % A_D error and the K_D four
times too low, i.e. the case-9 row, to measurement noise.)"""

_T68 = """
1  0.00999 2.000 0.4000 0.678 | 0.01000 2.000 0.4000
2  0.00999 1.998 0.4001 0.643 | 0.01000 1.997 0.4001
3  0.00999 1.985 0.4005 0.631 | 0.01001 1.982 0.4006
4  0.01000 2.000 0.4000 0.616 | 0.01000 2.000 0.4000
5  0.01000 2.000 0.4000 0.613 | 0.01000 2.000 0.4000
6  0.00999 1.986 0.4005 0.628 | 0.01001 1.987 0.4006
7  0.01005 1.989 0.4024 0.585 | 0.01004 1.992 0.4023
8  0.01010 1.968 0.4029 0.588 | 0.01005 1.975 0.4027
9  0.01038 1.963 0.4016 0.143 | 0.01011 1.985 0.4015
10 0.01008 1.973 0.4014 0.434 | 0.01000 1.979 0.4013
11 0.00998 2.003 0.4010 0.644 | 0.01000 2.002 0.4010
12 0.00990 2.066 0.4007 0.669 | 0.00999 2.029 0.4015
13 0.01001 1.997 0.4005 0.654 | 0.01000 1.996 0.4003
14 0.01016 1.960 0.4041 0.244 | 0.00998 1.975 0.4036
15 0.01010 2.090 0.3996 0.404 | 0.01001 2.085 0.3998
16 0.00981 2.103 0.3967 0.796 | 0.00987 2.091 0.3978
17 0.01017 1.890 0.3944 0.693 | 0.01003 2.009 0.3989
18 0.00988 2.184 0.4045 0.489 | 0.00997 2.046 0.4021
19 0.01010 2.177 0.4032 0.864 | 0.01004 2.062 0.3983
"""


def _parse_tables(text: str) -> dict[tuple[str, int], dict[str, float]]:
    out = {}
    for line in text.strip().splitlines():
        four, three = line.split("|")
        case, ad, bd, cd0, kd = four.split()
        out[("4-term", int(case))] = {"AD": float(ad), "BD": float(bd) * 1e-4, "CD0": float(cd0),
                                     "KD": float(kd)}
        ad, bd, cd0 = three.split()
        out[("3-term", int(case))] = {"AD": float(ad), "BD": float(bd) * 1e-4, "CD0": float(cd0),
                                     "KD": PUBLISHED["3-term"]["KD_fixed"]}
    return out


PUBLISHED_CASES: dict[tuple[str, int], dict[str, float]] = _parse_tables(_T68)
"""Every case's published estimates, (analysis, case) -> {AD, BD (s/m), CD0, KD}: thesis table
6.8 (4-term) and 6.9 (3-term, K_D fixed 0.614), one pair per case.  Their sample standard
deviations over cases 14-19 reproduce the published spreads (AD 1.52 %, BD 5.74 %, CD0 1.05 %,
KD 41.6 % against 1.5, 5.7, 1.1, 40.8; 3-term 0.620, 2.209, 0.573 % against 0.62, 2.21,
0.57)."""

PUBLISHED_ROUNDING = {"AD": 0.5e-5, "BD": 0.5e-7, "CD0": 0.5e-4, "KD": 0.5e-3}
"""Half a unit of the last digit printed in tables 6.8 / 6.9 (SI): a value within this of the
published range is inside it as printed."""

VALIDATION_CASES = tuple(range(1, 7))
"""The noise-free validation cases whose published values are compared as one range."""


def published_range(analysis: str, case: int, parameter: str) -> tuple[float, float]:
    """The published interval an estimate of ``parameter`` is compared with (SI).

    Cases 1-6 (noise-free validation, differing only in the wind) as one range: the 4-term
    range of :data:`PUBLISHED` and the span of table 6.9 for 3-term.  Other cases: the case's
    own published value (low = high).  NaN when the thesis gives none.
    """
    if case in VALIDATION_CASES:
        if analysis == "4-term":
            return PUBLISHED["4-term"]["cases_1_6_range"][parameter]
        values = [PUBLISHED_CASES[(analysis, c)][parameter] for c in VALIDATION_CASES]
        return min(values), max(values)
    value = PUBLISHED_CASES.get((analysis, case), {}).get(parameter, math.nan)
    return value, value


# --------------------------------------------------------------------------- one case

def replicate_index(case: int) -> int:
    """How many lower-numbered cases of table 6.7 have exactly the conditions of ``case``
    (0 for most; 1 for 15, 17, 19, which repeat 14, 16, 18)."""
    sc = get_case(case)
    key = _conditions(sc)
    return sum(1 for n, other in CASES.items() if n < sc.number and _conditions(other) == key)


def _conditions(sc: SimulationCase) -> tuple:
    return (sc.head_wind_mps, sc.cross_wind_mps, sc.dynamics, sc.measurement_noise, sc.system_noise,
            sc.model, sc.spatial_beta)


def _campaign(case: int, seed: int, pairs: int):
    """The simulated pairs of a case: pairs k P + 1 ... (k + 1) P of the seed, k its
    :func:`replicate_index`."""
    return _simulated(case, seed, pairs)[0]


@functools.lru_cache(maxsize=4)
def _simulated(case: int, seed: int, pairs: int) -> tuple[Any, tuple[str, ...]]:
    """:func:`_campaign` and the simulator's warning messages, cached so that both analyses
    of a case fit the same data without simulating it twice."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        k = replicate_index(case)
        campaign = simulate_campaign(case, pairs * (k + 1), seed)
    if k:
        campaign = campaign.subset([r for p in campaign.pairs()[k * pairs:] for r in p])
    return campaign, tuple(str(w.message) for w in caught if not issubclass(w.category, DeprecationWarning))


@dataclass(frozen=True)
class CaseJob:
    """One unit of the study: a case, a seed, a number of pairs and an analysis (picklable)."""

    case: int
    seed: int = 0
    pairs: int = 1
    analysis: str = "4-term"
    initial_speed: str = "fitted"


def fit_case(case: int, seed: int = 0, pairs: int = 1, analysis: str = "4-term",
             initial_speed: str = "fitted") -> list[dict[str, Any]]:
    """Simulate ``pairs`` pairs of a table 6.7 case and fit each pair by least squares.

    A pure function of its arguments (the simulation is seeded), so it can run anywhere.

    Parameters
    ----------
    case : int
        Case number of table 6.7 (1-19).
    seed : int
        Simulation seed.
    pairs : int
        Pairs simulated (the thesis: 1).  Repeated cases (15, 17, 19) take the next pairs of
        the seed (:func:`replicate_index`).
    analysis : {"4-term", "3-term"}
        The thesis analysis (:data:`ANALYSES`).
    initial_speed : {"fitted", "measured"}
        :class:`~bayes_roadload.inference.lsq.LsqSettings` ``initial_speed``: each run's
        initial speed estimated with the coefficients (the package default), or every run
        integrated from its first measured speed (the thesis' program).

    Returns
    -------
    list of dict
        One record per pair: ``case, description, analysis, model, seed, pair`` (1..pairs),
        ``runs``, the estimates ``AD, BD, CD0, KD`` (SI; K_D the fixed value in the 3-term
        analysis, ``KD_free`` False), their errors ``P_err_pct`` against the nominal truth
        (``P_truth``), the published value ``P_published`` (tables 6.8 / 6.9) and range
        ``P_published_low`` / ``_high`` (:func:`published_range`), ``P_outside_pct``: how far
        outside that range, beyond the printed rounding, the estimate lies, in % of the truth
        (0 inside), ``published_table``, ``noisy`` (the case has measurement or system noise),
        ``success``, ``rms_residual_mps``, ``fit_time_s`` (wall time of the job -- simulation
        unless cached, compilation, fits -- shared equally among its pairs) and ``warnings``
        (the simulator's and the fit's messages).
    """
    if analysis not in ANALYSES:
        raise ValueError(f"analysis must be one of {tuple(ANALYSES)}, not {analysis!r}")
    sc = get_case(case)
    t0 = time.perf_counter()
    campaign, sim_warnings = _simulated(sc.number, int(seed), int(pairs))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = fit_lsq(campaign, ANALYSES[analysis], grouping="pair",
                         settings=LsqSettings(initial_speed=initial_speed))
    elapsed = time.perf_counter() - t0
    messages = "; ".join(dict.fromkeys(sim_warnings + tuple(
        str(w.message) for w in caught if not issubclass(w.category, DeprecationWarning))))
    truth = campaign.truth
    rows = []
    for i, g in enumerate(result.groups, start=1):
        row: dict[str, Any] = {"case": sc.number, "description": sc.description, "analysis": analysis,
                               "model": result.model_name, "initial_speed": initial_speed,
                               "seed": int(seed), "pair": i,
                               "runs": g.label}
        for p in PARAMETERS:
            value = g.estimate[p] if p in result.free else result.fixed[p]
            row[p] = float(value)
        row["KD_free"] = "KD" in result.free
        for p in PARAMETERS:
            t = float(truth[p])
            row[f"{p}_truth"] = t
            row[f"{p}_err_pct"] = 100.0 * (row[p] - t) / t
        for p in PARAMETERS:
            low, high = published_range(analysis, sc.number, p)
            row[f"{p}_published"] = PUBLISHED_CASES.get((analysis, sc.number), {}).get(p, math.nan)
            row[f"{p}_published_low"], row[f"{p}_published_high"] = low, high
            row[f"{p}_outside_pct"] = _outside_pct(row[p], low, high, PUBLISHED_ROUNDING[p], row[f"{p}_truth"])
        row.update(published_table=PUBLISHED[analysis]["table"],
                   noisy=bool(sc.measurement_noise or sc.system_noise), success=g.success,
                   rms_residual_mps=g.rms_residual_mps, fit_time_s=elapsed / len(result.groups),
                   warnings=messages)
        rows.append(row)
    return rows


def _outside_pct(value: float, low: float, high: float, rounding: float, truth: float) -> float:
    """Signed distance of ``value`` beyond [low - rounding, high + rounding] in % of ``truth``
    (0 inside, NaN without a published range)."""
    if not (math.isfinite(low) and math.isfinite(high)):
        return math.nan
    if value > high + rounding:
        return 100.0 * (value - high) / truth
    if value < low - rounding:
        return 100.0 * (value - low) / truth
    return 0.0


def run_case_job(job: CaseJob) -> list[dict[str, Any]]:
    """:func:`fit_case` of a :class:`CaseJob` (the function an executor maps)."""
    return fit_case(job.case, job.seed, job.pairs, job.analysis, job.initial_speed)


def study_fits(cases: Iterable[int] = range(1, 20), seeds: Iterable[int] = (0,), pairs: int = 1, *,
               analyses: Sequence[str] = tuple(ANALYSES), initial_speed: str = "fitted",
               executor: Any | None = None) -> pd.DataFrame:
    """Per-pair fits of every (seed, case, analysis): the records of :func:`fit_case`, in
    that order, one row per pair.  ``executor``: anything with ``map(fn, iterable)``
    (``concurrent.futures.ProcessPoolExecutor`` with a "spawn" context, a Dask executor);
    None runs the jobs in this process."""
    jobs = [CaseJob(int(c), int(s), int(pairs), a, initial_speed)
            for s in seeds for c in cases for a in analyses]
    mapped = map(run_case_job, jobs) if executor is None else executor.map(run_case_job, jobs)
    return pd.DataFrame.from_records([row for rows in mapped for row in rows])


def case_table(cases: Iterable[int] = range(1, 20), seed: int = 0, pairs: int = 1, *,
               initial_speed: str = "fitted", executor: Any | None = None) -> pd.DataFrame:
    """Tables 6.8 and 6.9 reproduced: every case simulated (``pairs`` pairs, one in the
    thesis) and fitted per pair with the 4-term and 3-term analyses (``initial_speed`` and
    ``executor`` as :func:`fit_case` and :func:`study_fits`).

    Returns
    -------
    pandas.DataFrame
        One row per case x analysis x pair (columns of :func:`fit_case`).
    """
    return study_fits(cases, (seed,), pairs, initial_speed=initial_speed, executor=executor)


# --------------------------------------------------------------------------- spreads

SPREAD_CASES = tuple(range(14, 20))
"""The combined cases over which the thesis computed its test-to-test spread."""


def spread_table(cases: Iterable[int] = SPREAD_CASES, seeds: Iterable[int] = range(10), pairs: int = 1, *,
                 initial_speed: str = "fitted", executor: Any | None = None,
                 fits: pd.DataFrame | None = None) -> pd.DataFrame:
    """The between-pair spread of cases 14-19 beside the published test-to-test spread.

    For every seed the cases' pairs (6 pairs for one pair per case, as in the thesis) give one
    sample standard deviation in % of their mean per coefficient
    (:func:`~bayes_roadload.inference.lsq.between_group_spread`), the thesis' statistic.  Six
    pairs make it uncertain by ~1 / sqrt(2 (n - 1)) = 32 % of itself, so it is repeated over
    ``seeds`` and summarised with its standard error.

    Parameters
    ----------
    cases, seeds, pairs, initial_speed, executor : as :func:`study_fits`.
    fits : DataFrame, optional
        Records of :func:`study_fits` to use instead of fitting (rows of other cases ignored).

    Returns
    -------
    pandas.DataFrame
        One row per analysis and coefficient (4-term AD, BD, CD0, KD; 3-term AD, BD, CD0):
        ``published_pct`` and ``published_table``; ``published_se_pct`` (normal-theory
        sampling error of a 6-pair std, published / sqrt(2 (n - 1)); the published figure is one
        such draw); ``first_seed_pct`` (our spread for the first seed, the thesis' layout);
        ``mean_pct`` (mean over seeds of the per-seed spread), ``se_pct`` (its standard error,
        std over seeds / sqrt(n_seeds)), ``min_pct``, ``max_pct``; ``pooled_pct`` (std over all
        pairs of all seeds in % of their mean); ``difference_pct`` = mean - published,
        ``ratio`` = mean / published, ``z`` = difference / sqrt(se^2 + published_se^2);
        ``published_quantile``: fraction of seeds whose spread is below the published one
        (where the thesis' draw falls among ours); ``mean_estimate`` (mean over all pairs, SI)
        and ``published_mean`` (plain mean of the thesis' six pairs), and their errors against
        the truth ``mean_err_pct``, ``published_mean_err_pct``; ``n_seeds``, ``n_pairs`` (per
        seed).
    """
    cases = tuple(int(c) for c in cases)
    seeds = tuple(int(s) for s in seeds)
    if fits is None:
        fits = study_fits(cases, seeds, pairs, initial_speed=initial_speed, executor=executor)
    fits = fits[fits["case"].isin(cases) & fits["seed"].isin(seeds)]
    rows = []
    for analysis in ANALYSES:
        sub = fits[fits["analysis"] == analysis]
        if sub.empty:
            continue
        for p in FREE[analysis]:
            per_seed = np.array([between_group_spread(g[p].to_numpy())[2]
                                 for _, g in sub.groupby("seed", sort=True)])
            n_pairs = int(sub.groupby("seed").size().iloc[0])
            published = PUBLISHED[analysis]["spread_14_19_pct"][p]
            pub_se = published / math.sqrt(2.0 * (len(SPREAD_CASES) - 1))
            mean = float(np.mean(per_seed))
            se = float(np.std(per_seed, ddof=1) / math.sqrt(per_seed.size)) if per_seed.size > 1 else math.nan
            published_avg = np.mean([PUBLISHED_CASES[(analysis, c)][p] for c in SPREAD_CASES])
            truth = float(sub[f"{p}_truth"].iloc[0])
            rows.append({
                "analysis": analysis, "parameter": p, "published_pct": published,
                "published_table": PUBLISHED[analysis]["table"], "published_se_pct": pub_se,
                "first_seed_pct": float(per_seed[0]), "mean_pct": mean, "se_pct": se,
                "min_pct": float(per_seed.min()), "max_pct": float(per_seed.max()),
                "pooled_pct": between_group_spread(sub[p].to_numpy())[2],
                "difference_pct": mean - published, "ratio": mean / published,
                "z": (mean - published) / math.hypot(se if math.isfinite(se) else 0.0, pub_se),
                "published_quantile": float(np.mean(per_seed < published)),
                "mean_estimate": float(sub[p].mean()), "published_mean": float(published_avg),
                "mean_err_pct": 100.0 * (float(sub[p].mean()) / truth - 1.0),
                "published_mean_err_pct": 100.0 * (float(published_avg) / truth - 1.0),
                "n_seeds": int(per_seed.size), "n_pairs": n_pairs})
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------- report

_SCALE = {"AD": (1.0, "{:.5f}"), "BD": (1e4, "{:.3f}"), "CD0": (1.0, "{:.4f}"), "KD": (1.0, "{:.3f}")}
"""Display of each coefficient as in tables 6.8 / 6.9 (B_D x 1e4)."""


def _fmt(p: str, x: float) -> str:
    if x is None or not math.isfinite(x):
        return "-"
    scale, fmt = _SCALE[p]
    return fmt.format(x * scale)


def _published_cell(p: str, low: float, high: float) -> str:
    if not math.isfinite(low):
        return "-"
    return _fmt(p, low) if low == high else f"{_fmt(p, low)}-{_fmt(p, high)}"


def _case_summary(case_df: pd.DataFrame) -> pd.DataFrame:
    """Mean (and std) over pairs of each case and analysis."""
    rows = []
    for (analysis, case), g in case_df.groupby(["analysis", "case"], sort=False):
        row = {"analysis": analysis, "case": case, "description": g["description"].iloc[0],
               "noisy": bool(g["noisy"].iloc[0]), "n": len(g), "KD_free": bool(g["KD_free"].iloc[0])}
        for p in PARAMETERS:
            x = g[p].to_numpy(float)
            row[p] = float(np.mean(x))
            row[f"{p}_sd"] = float(np.std(x, ddof=1)) if len(x) > 1 else math.nan
            row[f"{p}_truth"] = float(g[f"{p}_truth"].iloc[0])
            row[f"{p}_published"] = float(g[f"{p}_published"].iloc[0])
            row[f"{p}_low"] = float(g[f"{p}_published_low"].iloc[0])
            row[f"{p}_high"] = float(g[f"{p}_published_high"].iloc[0])
            row[f"{p}_outside_pct"] = _outside_pct(row[p], row[f"{p}_low"], row[f"{p}_high"],
                                                   PUBLISHED_ROUNDING[p], row[f"{p}_truth"])
        rows.append(row)
    return pd.DataFrame(rows)


def markdown(case_df: pd.DataFrame, spread_df: pd.DataFrame | None = None) -> str:
    """Markdown tables of the study beside the published figures, and a generated paragraph
    listing every case and coefficient outside the published range and by how much.

    Parameters
    ----------
    case_df : records of :func:`case_table` (several pairs per case are averaged; their
        standard deviation is then shown and used to judge the noisy cases).
    spread_df : the result of :func:`spread_table` (optional).

    Returns
    -------
    str
        Per analysis a table ``case | winds | ours | published | ours - published (% of
        truth)``, the spread table (ours beside published with its standard error) and the
        paragraph.
    """
    summary = _case_summary(case_df)
    out = []
    for analysis in ANALYSES:
        s = summary[summary["analysis"] == analysis]
        if s.empty:
            continue
        table = PUBLISHED[analysis]["table"]
        params = PARAMETERS if analysis == "4-term" else FREE[analysis]
        n = int(s["n"].max())
        out.append(f"**{analysis} analysis, ours (mean of {n} pair{'s' if n > 1 else ''} per case) "
                   f"beside thesis table {table}** (B_D x 1e4 s/m; difference = ours - published, "
                   "% of the truth, 0 within the published range as printed; cases 1-6 compared "
                   "with the range over 1-6)"
                   + (f"; K_D fixed at {PUBLISHED['3-term']['KD_fixed']}" if analysis == "3-term" else "")
                   + "\n")
        head = ["case", "head/cross m/s"]
        for p in params:
            head += [f"{p} ours", f"{p} thesis", f"{p} diff %"]
        out.append("| " + " | ".join(head) + " |")
        out.append("|" + "---|" * len(head))
        for _, r in s.iterrows():
            sc = get_case(int(r["case"]))
            cells = [f"{int(r['case'])} {r['description']}", f"{sc.head_wind_mps:g}/{sc.cross_wind_mps:g}"]
            for p in params:
                ours = _fmt(p, r[p])
                if n > 1 and math.isfinite(r[f"{p}_sd"]):
                    ours += f" ± {_fmt(p, r[f'{p}_sd'])}"
                cells += [ours, _published_cell(p, r[f"{p}_low"], r[f"{p}_high"]),
                          f"{r[f'{p}_outside_pct']:+.2f}" if math.isfinite(r[f"{p}_outside_pct"]) else "-"]
            out.append("| " + " | ".join(cells) + " |")
        out.append("")
    if spread_df is not None and not spread_df.empty:
        n_seeds, n_pairs = int(spread_df["n_seeds"].iloc[0]), int(spread_df["n_pairs"].iloc[0])
        out.append(f"**Between-pair spread over cases 14-19 (std in % of the mean; {n_pairs} pairs "
                   f"per seed, {n_seeds} seeds)** beside the published test-to-test spread; the "
                   "published figure is itself one 6-pair std, uncertain by ~32 % of itself\n")
        out.append("| analysis | coefficient | published % (table) | ours, first seed % | ours, mean over "
                   "seeds % ± SE | range over seeds % | ours - published % | ours / published | "
                   "seeds below published | mean error ours / thesis % |")
        out.append("|---|---|---|---|---|---|---|---|---|---|")
        for _, r in spread_df.iterrows():
            out.append(f"| {r['analysis']} | {r['parameter']} | {r['published_pct']:g} ({r['published_table']}) | "
                       f"{_num(r['first_seed_pct'])} | {_num(r['mean_pct'])} ± {_num(r['se_pct'])} | "
                       f"{_num(r['min_pct'])}-{_num(r['max_pct'])} | {_num(r['difference_pct'], '{:+.2f}')} | "
                       f"{_num(r['ratio'])} | {round(r['published_quantile'] * r['n_seeds'])}/{int(r['n_seeds'])} | "
                       f"{_num(r['mean_err_pct'], '{:+.2f}')} / {_num(r['published_mean_err_pct'], '{:+.2f}')} |")
        out.append("")
    out.append(_paragraph(summary, spread_df))
    return "\n".join(out) + "\n"


Z_NOISY = 3.0
"""A noisy case's published pair is called outside our results when it lies more than this many
of our per-pair standard deviations from our mean over pairs (needs ``pairs`` > 1)."""


def _paragraph(summary: pd.DataFrame, spread_df: pd.DataFrame | None) -> str:
    """The generated text: every case / coefficient outside the published range."""
    parts = []
    for analysis in ANALYSES:
        s = summary[summary["analysis"] == analysis]
        if s.empty:
            continue
        exact, noisy, far = [], [], []
        n_checked = 0
        for _, r in s.iterrows():
            for p in FREE[analysis]:
                d = r[f"{p}_outside_pct"]
                if not math.isfinite(d):
                    continue
                n_checked += 1
                if d == 0.0:
                    continue
                text = (f"case {int(r['case'])} {p} {_fmt(p, r[p])}/"
                        f"{_published_cell(p, r[f'{p}_low'], r[f'{p}_high'])} ({d:+.2f} %")
                if not r["noisy"]:
                    exact.append((abs(d), text + ")"))
                    continue
                noisy.append((abs(d), text + ")"))
                sd = r[f"{p}_sd"]
                if math.isfinite(sd) and sd > 0:
                    z = (r[f"{p}_published"] - r[p]) / sd
                    if abs(z) > Z_NOISY:
                        far.append((abs(z), text + f", {z:+.1f} sd)"))
        inside = n_checked - len(exact) - len(noisy)
        line = (f"{analysis} (table {PUBLISHED[analysis]['table']}): {inside} of {n_checked} case x "
                "coefficient values inside the published range as printed.")
        if exact:
            line += (" Noise-free cases outside it (no measurement or system noise, turbulence only; "
                     "ours/published, difference in % of the truth, largest first): "
                     + "; ".join(t for _, t in sorted(exact, reverse=True)) + ".")
        n_pairs = int(s["n"].max())
        if noisy and n_pairs > 1:
            line += (f" Noisy cases (9, 10, 14-19; the thesis' figure is one random pair): {len(noisy)} "
                     f"values differ from the published pair; it lies more than {Z_NOISY:g} of our "
                     f"per-pair sd ({n_pairs} pairs) from our mean for "
                     + ("; ".join(t for _, t in sorted(far, reverse=True)) if far else "none") + ".")
        elif noisy:
            line += (" Noisy cases outside it (one pair each, like the thesis': compare the spreads): "
                     + "; ".join(t for _, t in sorted(noisy, reverse=True)) + ".")
        parts.append(line)
    if spread_df is not None and not spread_df.empty:
        items = [f"{r['analysis']} {r['parameter']} {r['mean_pct']:.2f} ± {_num(r['se_pct'])} % against "
                 f"{r['published_pct']:g} % (x{r['ratio']:.2f}, z = {r['z']:+.1f})"
                 for _, r in spread_df.iterrows()]
        parts.append("Spreads over cases 14-19, mean over seeds ± SE against the published: "
                     + "; ".join(items) + ". z counts the difference in units of the combined "
                     "standard error of our mean and of the published 6-pair figure (32 % of it).")
    return "\n\n".join(parts)


def _num(x: float, fmt: str = "{:.2f}") -> str:
    return fmt.format(x) if x is not None and math.isfinite(x) else "-"
