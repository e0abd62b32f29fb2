"""Pooling: all pairs fitted jointly against one pair at a time (thesis recommendation 12).

The thesis fitted every pair of coastdowns on its own and combined the pairs afterwards (eq.
5.15, 5.16); its recommendation 12 is to analyse coastdowns in groups.  This study fits the
combined cases 14-19 of table 6.7 (every disturbance on: anemometer and vehicle dynamics,
measurement and system noise, the full drag model) both ways:

* one pair at a time: the classical per-pair least squares
  (:func:`bayes_roadload.inference.lsq.fit_lsq`, ``grouping="pair"``), whose between-pair
  spread is the thesis' test-to-test figure (table 6.8) and whose per-pair K_D interval is
  what a single test can say about K_D;
* jointly: one NUTS fit of all pairs (:func:`~bayes_roadload.inference.nuts.fit_nuts` through
  :func:`~bayes_roadload.analysis.batch.run_batch`), repeated over independent campaigns
  (seeds) so that the scatter of the joint estimate is measured, not only its posterior sd.

and measures how K_D's identifiability grows with the yaw the wind produces
(:func:`yaw_jobs`): K_D multiplies psi^2 in C_D(psi) = C_D0 + K_D psi^2, so without
cross-wind the data say nothing about it and its posterior is its prior.

Campaigns are built by picklable recipes (:class:`CombinedCampaign` of
:class:`~bayes_roadload.analysis.batch.SimulatedCampaign`), so the jobs travel to workers.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
import pandas as pd

from .. import config
from ..data.campaign import Campaign
from .batch import FitJob, SimulatedCampaign, successful

COMBINED_CASES = (14, 15, 16, 17, 18, 19)
POOLING_PARAMETERS = ("AD", "BD", "CD0", "KD")
POOLING_SAMPLER = config.DEFAULT_SAMPLER
NOMINAL = ("AD", "BD", "CD0", "KD")


@dataclass(frozen=True)
class CombinedCampaign:
    """A picklable recipe for one campaign made of several: the parts' runs renumbered 1..N
    (pairs likewise) in order, the vehicle, anemometer and tunnel of the first part (all parts
    must share the vehicle), the truth's nominal coefficients (they must agree) and every run's
    own coefficients under its new id.  ``meta["cases"]`` lists the parts' cases."""

    parts: tuple

    def __call__(self) -> Campaign:
        campaigns = [p() if not isinstance(p, Campaign) else p for p in self.parts]
        if not campaigns:
            raise ValueError("CombinedCampaign needs at least one part")
        first = campaigns[0]
        frames, per_run, cases = [], {}, []
        run_offset = pair_offset = 0
        for c in campaigns:
            if c.vehicle != first.vehicle:
                raise ValueError("the parts of a combined campaign must share the vehicle")
            runs = c.runs.copy()
            ids = {r: i + 1 + run_offset for i, r in enumerate(c.run_ids)}
            runs["run"] = runs["run"].map(ids)
            if "pair" in runs:
                pair_ids = {p: i + 1 + pair_offset for i, p in enumerate(pd.unique(runs["pair"]))}
                runs["pair"] = runs["pair"].map(pair_ids)
                pair_offset += len(pair_ids)
            for old, new in ids.items():
                own = ((c.truth or {}).get("per_run") or {}).get(str(old))
                if own is not None:
                    per_run[str(new)] = own
            run_offset += len(ids)
            cases.append(c.meta.get("case"))
            frames.append(runs)
        truth = None
        if all(c.truth for c in campaigns):
            truth = {}
            for k in NOMINAL:
                values = {float(c.truth[k]) for c in campaigns if k in c.truth}
                if len(values) > 1:
                    raise ValueError(f"the parts' true {k} differ ({sorted(values)}): not one vehicle")
                if values:
                    truth[k] = values.pop()
            truth.update({k: v for k, v in first.truth.items() if k not in truth and k != "per_run"
                          and isinstance(v, (int, float))})
            truth["per_run"] = per_run
        meta = {"cases": cases, "seed": first.meta.get("seed"), "pairs": pair_offset,
                "generator": "bayes_roadload.analysis.pooling.CombinedCampaign"}
        return Campaign(pd.concat(frames, ignore_index=True), first.vehicle, first.anemometer, first.tunnel,
                        truth, meta)


def combined_cases(seed: int, pairs_per_case: int = 1, cases: Sequence[int] = COMBINED_CASES,
                   settings: Any = None) -> CombinedCampaign:
    """Cases 14-19 (or ``cases``), ``pairs_per_case`` pairs each, one campaign; part ``i`` uses
    seed ``1000 seed + i`` so the parts are independent."""
    return CombinedCampaign(tuple(SimulatedCampaign(c, pairs=pairs_per_case, seed=1000 * seed + i, settings=settings)
                                  for i, c in enumerate(cases)))


def pooling_jobs(seeds: Sequence[int], pairs_per_case: Sequence[int] = (1, 4), model: str = "four_term",
                 sampler: config.SamplerConfig = POOLING_SAMPLER) -> list[FitJob]:
    """One joint NUTS fit per seed and campaign size (tags ``study="pooling"``,
    ``pairs_per_case``, ``campaign_seed``)."""
    return [FitJob(f"pooling-{k}x6-seed{s}", combined_cases(s, k), model=model,
                   sampler=dataclasses.replace(sampler, seed=s),
                   tags={"study": "pooling", "pairs_per_case": int(k), "campaign_seed": int(s)})
            for k in pairs_per_case for s in seeds]


def per_pair_fits(seeds: Sequence[int], pairs_per_case: int = 1, model: str = "four_term",
                  executor: Any | None = None, cases: Sequence[int] = COMBINED_CASES) -> pd.DataFrame:
    """The classical per-pair least-squares fits of the same campaigns
    (:func:`combined_cases`): one row per pair with its estimates and standard errors (``P``,
    ``P_se``), the campaign seed and the case."""
    jobs = [(s, pairs_per_case, model, tuple(cases)) for s in seeds]
    frames = list(map(_per_pair_one, jobs) if executor is None else executor.map(_per_pair_one, jobs))
    return pd.concat(frames, ignore_index=True)


def _per_pair_one(job: tuple) -> pd.DataFrame:
    from ..inference.lsq import fit_lsq

    seed, k, model, cases = job
    campaign = combined_cases(seed, k, cases)()
    res = fit_lsq(campaign, model, grouping="pair")
    pair_case = {}
    cases = campaign.meta["cases"]
    for i, case in enumerate(cases):
        for j in range(k):
            pair_case[i * k + j + 1] = case
    rows = []
    for g in res.groups:
        pair = int(campaign.runs.loc[campaign.runs["run"] == g.run_ids[0], "pair"].iloc[0])
        row = {"campaign_seed": seed, "pair": pair, "case": pair_case.get(pair), "success": g.success}
        for p in res.free:
            row[p] = g.estimate[p]
            row[f"{p}_se"] = g.se[p]
        rows.append(row)
    return pd.DataFrame(rows)


def _pct(x: np.ndarray) -> float:
    x = np.asarray(x, float)
    return float(100.0 * x.std(ddof=1) / abs(x.mean())) if x.size > 1 else math.nan


def pooling_table(records: pd.DataFrame, per_pair: pd.DataFrame,
                  parameters: Sequence[str] = POOLING_PARAMETERS) -> pd.DataFrame:
    """One row per analysis and parameter.

    * ``one pair (LSQ)``: ``spread_pct`` = between-pair standard deviation in % of the mean
      (all pairs of all seeds), ``half_width_95`` = median over pairs of 1.96 SE (the interval
      one test gives), ``in95`` = fraction of pairs whose +-1.96 SE interval holds the truth;
    * ``joint NUTS, n pairs``: ``spread_pct`` = standard deviation of the posterior means over
      the independent campaigns (seeds), in % of their mean, ``half_width_95`` = median half
      width of the 95 % posterior interval, ``in95`` = fraction of campaigns whose interval holds
      the truth;
    * ``expected_spread_pct``: the single-pair spread / sqrt(pairs), what averaging independent
      pairs would give.
    """
    rows = []
    ok = successful(records)
    truth = {p: float(ok[f"{p}_truth"].iloc[0]) for p in parameters if f"{p}_truth" in ok and len(ok)}
    single = {}
    for p in parameters:
        good = per_pair[per_pair["success"] & np.isfinite(per_pair[f"{p}_se"])]
        hw = 1.959964 * good[f"{p}_se"]
        inside = (good[p] - hw <= truth.get(p, math.nan)) & (truth.get(p, math.nan) <= good[p] + hw)
        single[p] = _pct(per_pair[p])
        rows.append({"analysis": "one pair (LSQ)", "pairs": 1, "campaigns": int(len(per_pair)), "parameter": p,
                     "mean": float(per_pair[p].mean()), "spread_pct": single[p],
                     "expected_spread_pct": single[p], "half_width_95": float(np.median(hw)) if len(hw) else math.nan,
                     "in95": float(inside.mean()) if len(good) else math.nan,
                     "unidentified_pairs": int(len(per_pair) - len(good))})
    for k, g in ok.groupby("pairs_per_case", sort=True):
        n_pairs = int(k) * len(COMBINED_CASES)
        for p in parameters:
            hw = 0.5 * (g[f"{p}_q97.5"] - g[f"{p}_q2.5"])
            rows.append({"analysis": f"joint NUTS, {n_pairs} pairs", "pairs": n_pairs, "campaigns": int(len(g)),
                         "parameter": p, "mean": float(g[f"{p}_mean"].mean()), "spread_pct": _pct(g[f"{p}_mean"]),
                         "expected_spread_pct": single[p] / math.sqrt(n_pairs),
                         "half_width_95": float(hw.median()), "in95": float(g[f"{p}_in95"].astype(bool).mean()),
                         "unidentified_pairs": 0})
    return pd.DataFrame(rows)


def yaw_jobs(cross_winds_mps: Sequence[float] = (0.0, 1.0, 2.0, 3.0, 4.0), seeds: Sequence[int] = (0, 1),
             pairs: int = 3, base_case: int = 18, model: str = "four_term",
             sampler: config.SamplerConfig = POOLING_SAMPLER) -> list[FitJob]:
    """K_D against the yaw: case ``base_case`` conditions (18: no head wind, every disturbance
    on) with the mean cross wind varied; one joint NUTS fit of ``pairs`` pairs per wind and
    seed (tags ``study="yaw"``, ``cross_wind_mps``, ``campaign_seed``)."""
    from ..simulate import get_case

    base = get_case(base_case)
    jobs = []
    for w in cross_winds_mps:
        case = dataclasses.replace(base, number=100 + int(round(10 * w)), description=f"cross wind {w:g} m/s",
                                   cross_wind_mps=float(w))
        for s in seeds:
            jobs.append(FitJob(f"yaw-{w:g}-seed{s}", SimulatedCampaign(case, pairs=pairs, seed=s), model=model,
                               sampler=dataclasses.replace(sampler, seed=s),
                               tags={"study": "yaw", "cross_wind_mps": float(w), "campaign_seed": int(s)}))
    return jobs


def yaw_table(records: pd.DataFrame, model: str = "four_term") -> pd.DataFrame:
    """K_D's posterior against the mean |yaw|: one row per cross wind (means over seeds) with
    ``mean_abs_yaw_deg``, ``KD_mean``, ``KD_sd``, ``KD_half_width_95`` and ``contraction`` =
    1 - posterior variance / prior variance (0: the data say nothing, 1: fully determined; the
    prior sd is that of the model file's prior as sampled, truncation included: 0.72 for
    four_term's normal(0.6, 1) truncated at 0)."""
    import jax

    from ..inference.spec import load_model_spec

    prior = load_model_spec(model).priors.get("KD")
    prior_sd = (float(np.std(np.asarray(prior.to_numpyro().sample(jax.random.PRNGKey(0), (200_000,)))))
                if prior is not None else math.nan)
    ok = successful(records)
    rows = []
    for w, g in ok.groupby("cross_wind_mps", sort=True):
        rows.append({"cross_wind_mps": float(w), "fits": int(len(g)),
                     "mean_abs_yaw_deg": float(np.degrees(g["mean_abs_yaw_rad"].mean())),
                     "KD_mean": float(g["KD_mean"].mean()), "KD_sd": float(g["KD_sd"].mean()),
                     "KD_half_width_95": float((0.5 * (g["KD_q97.5"] - g["KD_q2.5"])).mean()),
                     "KD_in95": float(g["KD_in95"].astype(bool).mean()),
                     "contraction": float(1.0 - (g["KD_sd"] ** 2).mean() / prior_sd**2)})
    return pd.DataFrame(rows)


def _fmt(x: float, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return f"{x:.{digits}g}"


def pooling_markdown(table: pd.DataFrame, yaw: pd.DataFrame | None = None) -> str:
    """Markdown of :func:`pooling_table` (and :func:`yaw_table`)."""
    lines = ["| analysis | campaigns | parameter | mean | spread (std %) | 1/sqrt(n) of one pair (%) | 95 % half width | truth in 95 % |",
             "|---|---|---|---|---|---|---|---|"]
    for _, r in table.iterrows():
        lines.append(f"| {r['analysis']} | {int(r['campaigns'])} | {r['parameter']} | {_fmt(r['mean'], 4)} | "
                     f"{_fmt(r['spread_pct'], 2)} | {_fmt(r['expected_spread_pct'], 2)} | "
                     f"{_fmt(r['half_width_95'], 3)} | {_fmt(r['in95'], 2)} |")
    if yaw is not None and len(yaw):
        lines += ["", "| cross wind (m/s) | fits | mean abs yaw (deg) | KD mean | KD sd | KD 95 % half width | truth in 95 % | contraction |",
                  "|---|---|---|---|---|---|---|---|"]
        for _, r in yaw.iterrows():
            lines.append(f"| {r['cross_wind_mps']:g} | {int(r['fits'])} | {r['mean_abs_yaw_deg']:.2f} | "
                         f"{_fmt(r['KD_mean'])} | {_fmt(r['KD_sd'])} | {_fmt(r['KD_half_width_95'])} | "
                         f"{_fmt(r['KD_in95'], 2)} | {_fmt(r['contraction'], 2)} |")
    return "\n".join(lines) + "\n"
