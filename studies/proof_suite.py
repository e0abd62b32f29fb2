"""The proof suite of the sim-to-real diagnosis (:func:`bayes_roadload.analysis.diagnose.diagnose`).

Campaigns are simulated at thesis case 9 conditions (:data:`PROOF_CASE`) with one candidate
effect of ``models/effects/library.toml`` present, and diagnosed with an analysis model that
withholds it (:func:`withheld_campaign`); null controls have no effect.  :class:`Distorted`
distorts a campaign's logged channels or stated vehicle (calibration and mass errors),
:class:`DiagnoseJob` sends a diagnosis through the batch door
(:func:`bayes_roadload.analysis.batch.run_batch`) and :func:`withheld_effect_jobs` builds the
suite.  Run by ``benchmarks/sim_to_real_study.py``.
"""

from __future__ import annotations

import dataclasses
import time
import tomllib
import traceback
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

from bayes_roadload import config
from bayes_roadload.analysis import effects as fx
from bayes_roadload.analysis.batch import SimulatedCampaign
from bayes_roadload.analysis.diagnose import Diagnosis, diagnose
from bayes_roadload.analysis.pooling import CombinedCampaign
from bayes_roadload.data.campaign import Campaign
from bayes_roadload.inference.spec import load_model_spec
from bayes_roadload.physics import effects as pe
from bayes_roadload.physics.terms import Gradient, PitchAttitude
from bayes_roadload.simulate import SimulationSettings, get_case


@dataclass(frozen=True)
class Distorted:
    """A picklable campaign factory distorting another's logged channels or stated vehicle:
    ``airspeed_scale`` x airspeed reading, yaw reading = (true yaw - ``yaw_offset_rad``) /
    ``yaw_factor`` (so true = yaw_factor x reading + offset), stated effective mass x
    ``effective_mass_factor``.  A run whose distorted yaw reading leaves
    ``|yaw| <= config.MAX_LOGGED_YAW_RAD`` ends before that sample, as a simulated run does.
    The truth records the distortion."""

    factory: Callable[[], Campaign]
    airspeed_scale: float = 1.0
    yaw_factor: float = 1.0
    yaw_offset_rad: float = 0.0
    effective_mass_factor: float = 1.0

    def __call__(self) -> Campaign:
        c = self.factory()
        runs = c.runs.copy()
        runs["airspeed_mps"] = runs["airspeed_mps"] * self.airspeed_scale
        runs["yaw_rad"] = (runs["yaw_rad"] - self.yaw_offset_rad) / self.yaw_factor
        over = (runs["yaw_rad"].abs() > config.MAX_LOGGED_YAW_RAD).astype(int)
        runs = runs[over.groupby(runs["run"], sort=False).cummax() == 0].reset_index(drop=True)
        vehicle = dataclasses.replace(c.vehicle, effective_mass_kg=c.vehicle.effective_mass_kg * self.effective_mass_factor)
        truth = dict(c.truth or {}, airspeed_scale=self.airspeed_scale, yaw_factor=self.yaw_factor,
                     yaw_offset_rad=self.yaw_offset_rad, effective_mass_factor=self.effective_mass_factor)
        return dataclasses.replace(c, runs=runs, vehicle=vehicle, truth=truth)


PROOF_CASE = 9
"""The suite's base conditions: thesis case 9 (2 m/s head and cross wind with Dryden
turbulence, table 6.6 measurement noise, the "basic" drag model with lift), which
``three_term`` fits correctly specified but for the input noise."""


PROOF_DESIGNS = ("standard", "identifying")
"""The proof suite's campaign designs (``[proof]`` of ``models/effects/library.toml``)."""


def proof_design(name: str = "identifying", path=fx.LIBRARY_PATH) -> dict[str, Any]:
    """The ``[proof.NAME]`` table of the library ("standard" is case 9 as it is: empty)."""
    if name not in PROOF_DESIGNS:
        raise ValueError(f"unknown proof design {name!r}: one of {PROOF_DESIGNS}")
    if name == "standard":
        return {}
    doc = tomllib.loads(Path(path).read_text())
    design = dict(doc.get("proof", {}).get(name, {}))
    unknown = set(design) - {"pairs", "head_wind_mps", "cross_wind_mps", "masses_kg", "start_speeds_mps",
                             "size_factor"}
    if unknown:
        raise ValueError(f"{path}: [proof.{name}]: unknown keys {sorted(unknown)}")
    for e in design.get("size_factor", {}):
        if e not in fx.EFFECT_NAMES:
            raise ValueError(f"{path}: [proof.{name}.size_factor]: {e!r} is not an effect of the library")
    return design


def withheld_campaign(effect: str | None, seed: int, pairs: int = 3,
                      design: str = "standard") -> tuple[Callable[[], Campaign], Any]:
    """A campaign factory with ``effect`` present (None: the null control) and the analysis
    model that withholds it (``three_term``; for ``aero_lift`` ``three_term`` without its
    tunnel lift).

    ``design="standard"``: thesis case 9 conditions, ``pairs`` pairs, the effect at a plausible
    size (README, docs/sim_to_real.md): gradient 0.1 %, tyre loss 10 % higher at the start
    decaying over 40 s, airspeed readings 3 % high, the thesis' vane factor 0.869 and a 0.02
    rad offset, the thesis' lift, side-force slip (K_S 2.4, C_y 25 kN/rad) and pitch (K_alpha
    0.9, l_p 0.55 m, k_p 60 kN m/rad), C_t 0.03 N s^2/m^2, tyre X 3e-4 (v / 20 m/s)^4, 2 m/s of
    unrecorded wind change along the track, the cup, vane and admittance dynamics of table 6.5,
    run-to-run offsets of 4 % / 20 % / 4 % (the thesis' track spreads) and an effective mass
    stated 3 % high.  ``design="identifying"``: the campaign of ``[proof.identifying]`` in the
    library (its pairs, winds, test masses and start speeds; ``pairs`` is ignored) with the
    effect ``size_factor`` times the plausible size."""
    plan = proof_design(design)
    f = float(plan.get("size_factor", {}).get(effect, 1.0)) if effect else 1.0
    case = get_case(PROOF_CASE)
    case = dataclasses.replace(case, head_wind_mps=float(plan.get("head_wind_mps", case.head_wind_mps)),
                               cross_wind_mps=float(plan.get("cross_wind_mps", case.cross_wind_mps)))
    settings = SimulationSettings()
    model: Any = "three_term"
    extra = {
        "track_gradient": ((Gradient(),), {"grade_rad": 0.001 * f}),
        "tyre_temperature": ((pe.TyreTemperatureTransient(),), {"tyre_transient": 0.1 * f, "tyre_time_constant_s": 40.0}),
        "side_force_slip": ((pe.SideSlipDrag(),), {"side_slip_coeff_per_n": f * 2.4**2 / (4 * 25_000.0)}),
        "pitch_attitude": ((PitchAttitude(),), {"Kalpha": 0.9 * f, "pitch_gain": 1100.0 * 0.55 / 60e3}),
        "driveline_quadratic": ((pe.DrivelineQuadratic(),), {"Ct": 0.03 * f}),
        "tyre_speed_exponent": ((pe.TyreSpeedPower(),), {"tyre_power_coeff": 3e-4 * f, "tyre_speed_exponent": 4.0}),
        "spatial_wind": ((pe.SpatialWind(),), {"wind_gradient_mps": 2.0 * f}),
    }
    if effect in extra:
        terms, params = extra[effect]
        settings = dataclasses.replace(settings, extra_terms=terms, extra_params=params)
    elif effect == "anemometer_dynamics":
        case = dataclasses.replace(case, dynamics=True)
        s = settings.sensors
        settings = dataclasses.replace(settings, sensors=dataclasses.replace(
            s, cup_distance_constant_m=s.cup_distance_constant_m * f))
    elif effect == "run_to_run_variation":
        case = dataclasses.replace(case, system_noise=True)
        settings = dataclasses.replace(settings, system_noise_mode="per_run",
                                       system_noise_std={"AD": 4e-4 * f, "BD": 4e-5 * f, "CD0": 0.016 * f})
    elif effect == "aero_lift":
        model = dataclasses.replace(load_model_spec("three_term"), name="three_term_no_lift", lift="none")
        full = dict(settings.full_model_params)
        full.update(CL0=full["CL0"] * f, KL=full["KL"] * f)
        settings = dataclasses.replace(settings, full_model_params=full)
    elif effect not in (None, "airspeed_calibration", "yaw_calibration", "mass_error"):
        raise ValueError(f"unknown effect {effect!r}")
    n_pairs = int(plan.get("pairs", pairs))
    masses = tuple(float(m) for m in plan["masses_kg"]) if "masses_kg" in plan else None
    starts = [float(v) for v in plan.get("start_speeds_mps", [settings.start_speed_mps])]
    parts = []
    for i, v0 in enumerate(starts):
        k = n_pairs // len(starts) + (1 if i < n_pairs % len(starts) else 0)
        if k:
            parts.append(SimulatedCampaign(case, pairs=k, seed=seed + 7919 * i,
                                           settings=dataclasses.replace(settings, start_speed_mps=v0),
                                           masses_kg=masses))
    factory: Callable[[], Campaign] = parts[0] if len(parts) == 1 else CombinedCampaign(tuple(parts))
    if effect == "airspeed_calibration":
        factory = Distorted(factory, airspeed_scale=1.0 + 0.03 * f)
    elif effect == "yaw_calibration":
        factory = Distorted(factory, yaw_factor=1.0 - 0.131 * f, yaw_offset_rad=0.02 * f)
    elif effect == "mass_error":
        factory = Distorted(factory, effective_mass_factor=1.0 + 0.03 * f)
    return factory, model


@dataclass(frozen=True)
class DiagnoseJob:
    """A diagnosis for the batch door (:func:`bayes_roadload.analysis.batch.run_batch`):
    ``run()`` builds the campaign, diagnoses it and returns a flat record."""

    name: str
    campaign_factory: Callable[[], Campaign] | Campaign
    model: Any = "three_term"
    tags: Mapping[str, Any] = field(default_factory=dict)

    def run(self) -> dict[str, Any]:
        rec: dict[str, Any] = {"name": self.name, "model": str(getattr(self.model, "name", self.model)), "error": None}
        rec.update(self.tags)
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                campaign = self.campaign_factory if isinstance(self.campaign_factory, Campaign) else self.campaign_factory()
                rec["time_simulate_s"] = time.perf_counter() - t0
                d = diagnose(campaign, self.model)
            rec.update(diagnosis_record(d))
        except Exception as exc:  # noqa: BLE001 - one failed job must not end the batch
            rec["error"] = f"{type(exc).__name__}: {exc}"
            rec["traceback"] = traceback.format_exc(limit=8)
        rec["time_total_s"] = time.perf_counter() - t0
        return rec


def diagnosis_record(d: Diagnosis) -> dict[str, Any]:
    """A flat record of a diagnosis: the top-ranked supported effect (``"none"``), the
    supported and not-identifiable effects, the rules' fingerprints (library and thresholds
    SHA-256), every candidate's delta_elpd, the gap before and after the combined refit and its
    shrink, timings."""
    rec: dict[str, Any] = {"top": d.top or "none",
                           "supported": ",".join(c["effect"] for c in d.candidates if c["supported"]),
                           "not_identifiable": ",".join(c["effect"] for c in d.candidates
                                                        if not c["identifiable"] and not c["unavailable"]),
                           "not_distinguishable": ",".join(c["effect"] for c in d.candidates if c.get("ambiguous_with")),
                           "refit_effects": ",".join(d.refit["effects"]),
                           "rules_library_sha256": d.result["rules"]["library_sha256"],
                           "rules_thresholds_sha256": d.result["rules"]["thresholds_sha256"]}
    for c in d.candidates:
        rec[f"delta_elpd_{c['effect']}"] = c["delta_elpd"]
        rec[f"delta_lopo_{c['effect']}"] = c.get("delta_lopo_lpd")
    for k, v in d.result["gap"].items():
        rec[f"before_{k}"] = v
    for k, v in d.refit["gap_after"].items():
        rec[f"after_{k}"] = v
    for k, v in d.refit["shrink_pct"].items():
        rec[f"shrink_{k}"] = v
    top = d.candidates[0] if d.candidates else None
    if top is not None:
        for k, v in top["shrink_pct"].items():
            rec[f"top_shrink_{k}"] = v
    rec.update({f"time_{k}": v for k, v in d.timings.items()})
    return rec


def withheld_effect_jobs(effects=fx.EFFECT_NAMES, seeds=(1,), pairs: int = 3, nulls: int = 0,
                         design: str = "standard") -> list[DiagnoseJob]:
    """The proof suite: one job per (effect, seed) and ``nulls`` null controls (seeds 1000+),
    ordered seed by seed with the nulls spread over the rounds, so that a suite stopped early
    has every arm about equally often; campaigns of ``design`` (:func:`withheld_campaign`)."""
    jobs = []
    per_round = -(-nulls // max(len(seeds), 1)) if nulls else 0
    made = 0
    for seed in seeds:
        for effect in effects:
            factory, model = withheld_campaign(effect, seed, pairs, design)
            jobs.append(DiagnoseJob(f"{effect}-s{seed}", factory, model,
                                    tags={"true_effect": effect, "seed": seed, "pairs": pairs, "design": design}))
        for _ in range(min(per_round, nulls - made)):
            factory, model = withheld_campaign(None, 1000 + made, pairs, design)
            jobs.append(DiagnoseJob(f"null-s{1000 + made}", factory, model,
                                    tags={"true_effect": "null", "seed": 1000 + made, "pairs": pairs,
                                          "design": design}))
            made += 1
    return jobs
