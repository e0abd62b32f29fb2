"""Can a test design identify a sim-to-real candidate?  Score the design before driving it.

The diagnosis (:mod:`.diagnose`) says of a candidate effect that a campaign cannot see it
"not identifiable here" or "not supported", with what would identify it (the library's
``needs``).  This module scores such a design on the campaign at hand:

1. the user's model is fitted to the campaign (MAP, :func:`~..inference.nuts.find_map`);
2. each :class:`DesignChange` adds runs to the campaign as tested: its pairs repeated
   (:func:`~.planning.simulate_future`, the model at the MAP through each pair's observed wind,
   with the fitted white and integrated speed noise) at a heavier test mass
   (``extra_mass_kg``, a weighed ballast: the runs' ``mass_kg``), in a stronger cross wind
   (``cross_wind_factor`` times each sample's cross component, the along-track one kept), or
   neither (more pairs of the same);
3. the designed campaign is refitted and every candidate linearised about the fit
   (:func:`.effects.linearise`), as the diagnosis does.

Per candidate and design (:func:`identify_designs`): ``contraction`` of each parameter's prior
(the diagnosis calls it identifiable at ``DiagnosisConfig.min_contraction``),
``information_ratio`` (the share of its signature the model's coefficients cannot mimic) and
``detectable``: the smallest size of the parameter (away from its null, SI) at which the
diagnosis' support is expected, ``sqrt(2 (support_delta_elpd + k / 2) / I_c)`` with ``I_c``
the parameter's Fisher information once the model's coefficients are refitted and ``k`` the
effect's parameters (the expected log-likelihood gain of a true offset theta is
``theta^2 I_c / 2 + k / 2``; its delta_elpd subtracts ``k``).
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd

from .. import config
from ..data.campaign import Campaign
from . import effects as fx

DESIGN_KEYS = ("add_pairs", "extra_mass_kg", "cross_wind_factor")


@dataclass(frozen=True)
class DesignChange:
    """Runs added to the campaign as tested: ``add_pairs`` pairs (None: as many as it has) of
    its own conditions, at test mass + ``extra_mass_kg``, with the cross wind times
    ``cross_wind_factor``."""

    add_pairs: int | None = None
    extra_mass_kg: float = 0.0
    cross_wind_factor: float = 1.0

    def __post_init__(self):
        if self.add_pairs is not None and self.add_pairs < 1:
            raise ValueError("add_pairs must be at least 1")
        if self.cross_wind_factor < 0:
            raise ValueError("cross_wind_factor must be >= 0")

    @classmethod
    def parse(cls, text: str) -> "DesignChange":
        """``"add_pairs=3,extra_mass_kg=300"`` (keys of :data:`DESIGN_KEYS`)."""
        kw: dict[str, Any] = {}
        for part in filter(None, (p.strip() for p in text.split(","))):
            key, sep, val = part.partition("=")
            key = key.strip()
            if not sep or key not in DESIGN_KEYS:
                raise ValueError(f"design {text!r}: {part!r} is not KEY=VALUE with KEY one of {DESIGN_KEYS}")
            try:
                kw[key] = int(val) if key == "add_pairs" else float(val)
            except ValueError:
                raise ValueError(f"design {text!r}: {key} needs a number, not {val!r}") from None
        return cls(**kw)

    @property
    def label(self) -> str:
        parts = [f"+{self.add_pairs} pairs" if self.add_pairs else "+ the pairs again"]
        if self.extra_mass_kg:
            parts.append(f"{self.extra_mass_kg:+g} kg")
        if self.cross_wind_factor != 1.0:
            parts.append(f"cross wind x{self.cross_wind_factor:g}")
        return ", ".join(parts)


def changed_conditions(campaign: Campaign, change: DesignChange) -> Campaign:
    """The campaign's conditions under ``change``: the runs' test mass shifted, each sample's
    cross wind (from the logged airspeed, yaw and speed) scaled and the airspeed and yaw
    recomputed (the speeds are replaced by the simulation)."""
    runs = campaign.runs.copy()
    if change.extra_mass_kg:
        base = runs["mass_kg"] if "mass_kg" in runs else campaign.vehicle.mass_kg
        runs["mass_kg"] = base + change.extra_mass_kg
    if change.cross_wind_factor != 1.0:
        if not {"airspeed_mps", "yaw_rad"} <= set(runs):
            raise ValueError("cross_wind_factor needs the logged airspeed_mps and yaw_rad (a measured wind)")
        a, psi = runs["airspeed_mps"].to_numpy(), runs["yaw_rad"].to_numpy()
        rel, cross = a * np.cos(psi), a * np.sin(psi) * change.cross_wind_factor
        runs["airspeed_mps"] = np.hypot(rel, cross)
        runs["yaw_rad"] = np.clip(np.arctan2(cross, rel), -config.MAX_LOGGED_YAW_RAD, config.MAX_LOGGED_YAW_RAD)
    return dataclasses.replace(campaign, runs=runs)


def designed_campaign(campaign: Campaign, fit_values: Mapping[str, Any], free: Sequence[str], model: str,
                      change: DesignChange, seed: int = 0) -> Campaign:
    """The campaign as tested plus the runs of ``change`` simulated from the fit (module
    docstring, step 2); run ids become strings, the added ones prefixed ``d``."""
    from .planning import Population, simulate_future

    n_pairs = campaign.runs["pair"].nunique() if "pair" in campaign.runs else 0
    if not n_pairs:
        raise ValueError("scoring a design needs opposite-direction pairs (the `pair` column)")
    sigma = float(np.mean(np.asarray(fit_values["sigma_mps"], float)))
    q = float(np.asarray(fit_values.get("q_mps_per_sqrt_s", 0.0)))
    pop = Population(model=model, means={k: np.array([float(np.asarray(fit_values[k]))]) for k in free}, tau={},
                     sigma_mps=np.array([sigma]), q_mps_per_sqrt_s=np.array([q]),
                     conditions=changed_conditions(campaign, change), source="MAP")
    future = simulate_future(pop, change.add_pairs or n_pairs, seed)
    obs = campaign.runs.copy()
    add = future.runs.copy()
    obs["run"] = obs["run"].astype(str)
    add["run"] = "d" + add["run"].astype(str)
    if pd.api.types.is_numeric_dtype(obs["pair"]):
        add["pair"] = add["pair"] + int(obs["pair"].max())
    else:  # text pair ids: the added pairs prefixed ``d``, as their runs
        add["pair"] = "d" + add["pair"].astype(str)
    if "mass_kg" in add and "mass_kg" not in obs:
        obs["mass_kg"] = campaign.vehicle.mass_kg
    runs = pd.concat([obs, add], ignore_index=True)
    meta = {k: v for k, v in (campaign.meta or {}).items() if k != "pad_to_samples"}
    return dataclasses.replace(campaign, runs=runs, meta=meta)


def _fit(campaign: Campaign, model: str):
    from ..inference.bayes import build_problem
    from ..inference.nuts import find_map, prepare_problem

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        problem, init = prepare_problem(build_problem(campaign, model), campaign)
        fit = find_map(problem, init)
    return problem, fit


def score_candidates(lin: fx.Linearisation, library: Mapping[str, fx.Effect], effects: Sequence[str],
                     settings: config.DiagnosisConfig = config.DEFAULT_DIAGNOSIS) -> list[dict[str, Any]]:
    """Per candidate of ``effects`` and parameter: contraction, information ratio and the
    detectable size (module docstring) on the linearised campaign ``lin``; a candidate the
    campaign cannot score (no measured air, a run effect) says why."""
    rows = []
    for name in effects:
        e = library[name]
        why = lin.available.get(name)
        if why is None and e.per_run:
            why = "a run-to-run effect: more runs identify it (plan's pair counts)"
        if why is None and name not in lin.effects:
            why = "not scored on this model"
        if why is not None:
            rows.append({"effect": name, "parameter": None, "note": why})
            continue
        ident = fx.identifiability(lin, name, library, settings.support_delta_elpd)
        for p, v in ident.items():
            rows.append({"effect": name, "parameter": p, "contraction": v["contraction"],
                         "information_ratio": v["information_ratio"], "detectable": v["detectable"],
                         "prior_sd": e.prior_sd[p], "identifiable": v["contraction"] >= settings.min_contraction,
                         "note": ""})
    return rows


def identify_designs(campaign: Campaign, model: str, effects: Sequence[str], changes: Sequence[DesignChange], *,
                     library: Mapping[str, fx.Effect] | None = None, seed: int = 0,
                     settings: config.DiagnosisConfig = config.DEFAULT_DIAGNOSIS) -> pd.DataFrame:
    """Score ``effects`` (library names) on the campaign as tested and under each design change
    (module docstring).  One row per (design, effect, parameter): ``design``, ``runs``,
    ``contraction``, ``information_ratio``, ``detectable`` (SI units of the parameter),
    ``identifiable``, ``note``."""
    library = fx.load_library() if library is None else library
    unknown = [e for e in effects if e not in library]
    if unknown:
        raise ValueError(f"unknown candidate effect(s) {unknown}: one of {list(library)}")
    library = {e: library[e] for e in effects}   # each candidate is scored alone: the others' columns unused
    problem, fit = _fit(campaign, model)
    designs = [("as tested", campaign, problem, fit)]
    for change in changes:
        camp = designed_campaign(campaign, fit.constrained, problem.free, problem.spec.name, change, seed)
        designs.append((change.label, camp, *_fit(camp, model)))
    out = []
    for label, camp, prob, f in designs:
        lin = fx.linearise(prob, f.constrained, library, prob.spec.resolve_admittance(camp))
        for row in score_candidates(lin, library, effects, settings):
            out.append({"design": label, "runs": int(prob.n_runs), **row})
    return pd.DataFrame.from_records(out)
