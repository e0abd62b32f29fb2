"""Bayesian fit of undriven-wheel spin-downs (thesis section 5.6, eq. 5.13-5.14).

Data: a :class:`~bayes_roadload.data.spindown.SpindownCampaign`, the tread speed of each
wheel decelerating freely off the ground.  Model (every run of every wheel jointly):

    y_ri ~ Normal(v(t_ri; v0_r, A_w(r), B_w(r), m_w(r)), sigma_r)

with ``v`` the closed form of eq. 5.13 (:func:`~bayes_roadload.physics.spindown.spindown_speed_mps`),
``m_w = I_w / R_r^2`` of the run's wheel, one ``A_w, B_w`` per wheel (sites ``Au_wheel``,
``Bu_wheel`` on a ``wheel`` axis, priors per wheel from the model file
``models/undriven_spindown.toml``), each run's release speed ``v0_mps`` ~ Normal(first sample,
0.5 m/s) and noise ``sigma_mps`` ~ half-normal(0.1 m/s) (``config.NOISE_PRIORS``).  The
vehicle's undriven-wheel loss (eq. 2.16) is the sum over its undriven wheels: ``Au = sum
A_w``, ``Bu = sum B_w`` (deterministic sites).  When fewer wheels were tested than the vehicle
has (``[spindown] undriven_wheels``), the sum is scaled by undriven / tested (the untested
wheels taken as the mean of the tested ones; the summary says so).

``pooling="hierarchical"``: every run r has its own ``Au_run ~ N(A_w(r), tau_Au_wheel)``,
``Bu_run ~ N(B_w(r), tau_Bu_wheel)`` (centred: each spin-down pins its own A, B much more tightly
than tests scatter), the test-to-test scatter of thesis table 7.10 (4.8 % in A_u); the per-wheel
``A_w, B_w`` are then the wheel's mean over tests and their posterior includes that scatter.
Spreads: Gamma(2) priors with means ``config.SPINDOWN_TAU_PRIOR_MEANS``, shared by the wheels.

Sampling goes through the same MAP -> Laplace whitening -> NUTS -> gates as every fit
(:func:`~bayes_roadload.inference.nuts.sample_problem`).  :func:`classical_spindown` is the
thesis' analysis (eq. 5.14 interval drags and a least-squares line per wheel), kept as a
baseline.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist
import pandas as pd

from .. import config
from ..thesis import THESIS_UNDRIVEN, THESIS_UNDRIVEN_SD
from ..physics.spindown import equivalent_mass_kg, spindown_interval_drag_n, spindown_speed_mps
from .nuts import sample_problem
from .results import FitReport, channel_report
from .spec import ModelSpec, Prior, load_model_spec

WHEEL_SITES = ("Au_wheel", "Bu_wheel")
TOTALS = ("Au", "Bu")


@dataclass(frozen=True, eq=False)
class SpindownProblem:
    """Everything the spin-down model needs, padded to [R, N] (``mask`` marks real samples)."""

    spec: ModelSpec
    priors: dict[str, Prior]
    time_s: Any
    speed_mps: Any
    mask: Any
    first_speed_mps: Any
    wheel_index: Any
    equivalent_mass_kg: Any
    wheels: tuple[str, ...]
    run_ids: tuple
    undriven_wheels: int
    initial: dict[str, Any] = field(default_factory=dict)
    free: tuple[str, ...] = WHEEL_SITES
    pooling: str = "pooled"

    kind = "spindown"

    @property
    def n_observations(self) -> int:
        """Padded samples of every wheel's runs."""
        return int(np.size(self.mask))

    @property
    def n_runs(self) -> int:
        return len(self.run_ids)

    @property
    def hessian_runs(self) -> int:
        # 0: every coordinate is treated as shared by the finite-difference Hessian (the
        # per-wheel sites couple the runs of one wheel; the problems are small)
        return 0

    def alternative_coordinates(self, values: dict[str, Any]) -> None:
        """None: one set of coordinates (:class:`~.problem.Problem`)."""
        return None

    def beyond_support(self, z: dict[str, Any], cov: np.ndarray) -> float:
        """0: every sampled coordinate maps into its support (:class:`~.problem.Problem`)."""
        return 0.0

    def shift_constant(self, name: str, delta: float) -> None:
        """None: no fixed drag-model constants (:meth:`~.problem.Problem.shift_constant`)."""
        return None

    def settings(self) -> dict[str, Any]:
        return {"pooling": self.pooling, "noise": "white", "robust": False}

    def postprocess(self, samples: dict[str, Any], seed: int) -> dict[str, Any]:
        return {}

    def derived(self, samples: dict[str, Any]) -> dict[str, Any]:
        return spindown_derived(samples)

    def truth_values(self, truth: dict | None) -> dict[str, float]:
        """Scalar truths, the per-wheel ``Au_wheel[w]``, ``Bu_wheel[w]`` and ``F50_undriven_N``."""
        truth = truth or {}
        flat = {k: v for k, v in truth.items() if isinstance(v, (int, float))}
        for site in WHEEL_SITES:
            flat.update({f"{site}[{w}]": v for w, v in truth.get(site, {}).items()})
        if {"Au", "Bu"} <= set(flat):
            flat["F50_undriven_N"] = flat["Au"] + flat["Bu"] * config.SPEED_50MPH_MPS
        return flat

    @property
    def n_wheels(self) -> int:
        return len(self.wheels)

    @property
    def total_scale(self) -> float:
        """undriven wheels / wheels tested: the factor from the tested wheels' sum to the vehicle's."""
        return self.undriven_wheels / self.n_wheels

    @property
    def numpyro_model(self):
        return spindown_model


def build_spindown_problem(campaign, spec: ModelSpec | str = "undriven_spindown", *,
                           pooling: str = "pooled") -> SpindownProblem:
    """The spin-down problem of a campaign with the per-wheel priors of ``spec``; ``pooling``
    "hierarchical" gives every run its own A, B around its wheel's (module docstring)."""
    if pooling not in ("pooled", "hierarchical"):
        raise ValueError(f"pooling must be 'pooled' or 'hierarchical', not {pooling!r}")
    spec = load_model_spec(spec) if isinstance(spec, str) else spec
    missing = [p for p in ("Au", "Bu") if p not in spec.priors]
    if missing:
        raise ValueError(f"model {spec.name!r} gives no prior for {', '.join(missing)}: use undriven_spindown")
    wheels = tuple(campaign.wheels)
    groups = list(campaign.runs.groupby("run", sort=False))
    n = max(len(g) for _, g in groups)
    r = len(groups)
    t = np.zeros((r, n))
    v = np.zeros((r, n))
    mask = np.zeros((r, n), bool)
    widx = np.zeros(r, int)
    mass = np.zeros(r)
    for i, (_, g) in enumerate(groups):
        k = len(g)
        t[i, :k] = g["time_s"].to_numpy()
        v[i, :k] = g["wheel_speed_mps"].to_numpy()
        t[i, k:] = t[i, k - 1]
        v[i, k:] = v[i, k - 1]
        mask[i, :k] = True
        w = str(g["wheel"].iloc[0])
        widx[i] = wheels.index(w)
        mass[i] = float(equivalent_mass_kg(campaign.wheel_inertia_kgm2[w], campaign.rolling_radius_m))
    aw, bw = classical_wheel_estimates(t, v, mask, widx, mass, len(wheels))
    lo = spec.priors["Au"].low
    aw = np.maximum(aw, (lo if lo is not None else -np.inf) + 1e-3)
    initial = {"Au_wheel": jnp.asarray(aw), "Bu_wheel": jnp.asarray(bw), "v0_mps": jnp.asarray(v[:, 0]),
               "sigma_mps": jnp.full(r, 0.05)}
    if pooling == "hierarchical":
        a_r, b_r = classical_run_estimates(t, v, mask, mass)
        initial.update({"tau_Au_wheel": config.SPINDOWN_TAU_PRIOR_MEANS["Au"],
                        "tau_Bu_wheel": config.SPINDOWN_TAU_PRIOR_MEANS["Bu"],
                        "Au_run": jnp.asarray(a_r), "Bu_run": jnp.asarray(b_r)})
    return SpindownProblem(spec=spec, priors={"Au": spec.priors["Au"], "Bu": spec.priors["Bu"]},
                           time_s=jnp.asarray(t), speed_mps=jnp.asarray(v), mask=jnp.asarray(mask),
                           first_speed_mps=jnp.asarray(v[:, 0]), wheel_index=jnp.asarray(widx),
                           equivalent_mass_kg=jnp.asarray(mass), wheels=wheels,
                           run_ids=tuple(campaign.run_ids), undriven_wheels=int(campaign.undriven_wheels),
                           initial=initial, pooling=pooling)


def classical_run_estimates(t, v, mask, mass) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 5.14 and a least-squares line for every run on its own: (A_r, B_r) ([R] each)."""
    a, b = np.zeros(len(mass)), np.zeros(len(mass))
    for i in range(len(mass)):
        k = int(np.asarray(mask)[i].sum())
        f, s = spindown_interval_drag_n(np.asarray(t)[i, :k], np.asarray(v)[i, :k], float(mass[i]))
        b[i], a[i] = np.polyfit(np.asarray(s), np.asarray(f), 1)
    return a, b


def classical_wheel_estimates(t, v, mask, widx, mass, n_wheels) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 5.14 interval drags of every run of each wheel and a least-squares line through them:
    (A_w, B_w) per wheel ([W] each)."""
    aw, bw = np.zeros(n_wheels), np.zeros(n_wheels)
    for w in range(n_wheels):
        f_all, s_all = [], []
        for i in np.flatnonzero(np.asarray(widx) == w):
            k = int(np.asarray(mask)[i].sum())
            f, s = spindown_interval_drag_n(np.asarray(t)[i, :k], np.asarray(v)[i, :k], float(mass[i]))
            f_all.append(np.asarray(f))
            s_all.append(np.asarray(s))
        bw[w], aw[w] = np.polyfit(np.concatenate(s_all), np.concatenate(f_all), 1)
    return aw, bw


def spindown_model(problem: SpindownProblem) -> None:
    """numpyro model of the spin-down speeds (module docstring)."""
    w = problem.n_wheels
    r = problem.first_speed_mps.shape[0]
    with numpyro.plate("wheel", w):
        aw = numpyro.sample("Au_wheel", problem.priors["Au"].to_numpyro())
        bw = numpyro.sample("Bu_wheel", problem.priors["Bu"].to_numpyro())
    numpyro.deterministic("Au", problem.total_scale * jnp.sum(aw))
    numpyro.deterministic("Bu", problem.total_scale * jnp.sum(bw))
    a_run, b_run = aw[problem.wheel_index], bw[problem.wheel_index]
    if problem.pooling == "hierarchical":
        means = config.SPINDOWN_TAU_PRIOR_MEANS
        tau_a = numpyro.sample("tau_Au_wheel", dist.Gamma(2.0, 2.0 / means["Au"]))
        tau_b = numpyro.sample("tau_Bu_wheel", dist.Gamma(2.0, 2.0 / means["Bu"]))
        # centred: each run's spin-down pins its own A, B far more tightly (sd ~0.003 N) than they
        # scatter between tests, the regime where the centred form has no funnel (the non-centred
        # one diverged and hit the tree-depth limit on 6 runs)
        with numpyro.plate("run_effect", r):
            a_run = numpyro.sample("Au_run", dist.Normal(a_run, tau_a))
            b_run = numpyro.sample("Bu_run", dist.Normal(b_run, tau_b))
    with numpyro.plate("run", r):
        v0 = numpyro.sample("v0_mps", dist.Normal(problem.first_speed_mps, config.NOISE_PRIORS["v0_scale_mps"]))
        sigma = numpyro.sample("sigma_mps", dist.HalfNormal(config.NOISE_PRIORS["sigma_mps"]))
    model = spindown_speed_mps(problem.time_s, v0[:, None], a_run[:, None], b_run[:, None],
                               problem.equivalent_mass_kg[:, None])
    numpyro.sample("wheel_speed_mps", dist.Normal(model, sigma[:, None]).mask(problem.mask), obs=problem.speed_mps)


def spindown_log_likelihood(problem: SpindownProblem, sample: dict[str, Any]) -> jnp.ndarray:
    """Log-likelihood of the logged speeds given a sample (for tests and model comparison)."""
    model = spindown_speed_mps(problem.time_s, sample["v0_mps"][:, None],
                               sample["Au_wheel"][problem.wheel_index][:, None],
                               sample["Bu_wheel"][problem.wheel_index][:, None], problem.equivalent_mass_kg[:, None])
    lp = dist.Normal(model, sample["sigma_mps"][:, None]).log_prob(problem.speed_mps)
    return jnp.sum(jnp.where(problem.mask, lp, 0.0))


def fit_spindown_nuts(campaign, spec: ModelSpec | str = "undriven_spindown", *, pooling: str = "pooled",
                      sampler: config.SamplerConfig = config.DEFAULT_SAMPLER):
    """MAP, Laplace whitening, NUTS and gates (:func:`~bayes_roadload.inference.nuts.sample_problem`)
    on the spin-down model.  Returns a :class:`~bayes_roadload.inference.nuts.NutsFit`."""
    problem = build_spindown_problem(campaign, spec, pooling=pooling)
    return sample_problem(problem, problem.initial, sampler, campaign.truth)


def spindown_derived(samples: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The undriven-wheel loss at 50 mph, ``F50_undriven_N`` = Au + Bu v, per draw."""
    return {"F50_undriven_N": np.asarray(samples["Au"]) + np.asarray(samples["Bu"]) * config.SPEED_50MPH_MPS}


def classical_spindown(campaign) -> pd.DataFrame:
    """The thesis' analysis (eq. 5.14 and a least-squares line, section 5.6) per wheel, with
    the lines' standard errors, and the vehicle totals: columns ``wheel, Au, Au_se, Bu, Bu_se``
    (per-wheel rows are that wheel's A_w, B_w; the row ``total`` is the vehicle's)."""
    rows = []
    total_scale = campaign.undriven_wheels / len(campaign.wheels)
    for w in campaign.wheels:
        sub = campaign.runs[campaign.runs["wheel"] == w]
        m = float(equivalent_mass_kg(campaign.wheel_inertia_kgm2[w], campaign.rolling_radius_m))
        f_all, s_all = [], []
        for _, g in sub.groupby("run", sort=False):
            f, s = spindown_interval_drag_n(g["time_s"].to_numpy(), g["wheel_speed_mps"].to_numpy(), m)
            f_all.append(np.asarray(f))
            s_all.append(np.asarray(s))
        (b, a), cov = np.polyfit(np.concatenate(s_all), np.concatenate(f_all), 1, cov=True)
        rows.append({"wheel": w, "Au": a, "Au_se": float(np.sqrt(cov[1, 1])), "Bu": b, "Bu_se": float(np.sqrt(cov[0, 0]))})
    df = pd.DataFrame(rows)
    rows.append({"wheel": "total", "Au": total_scale * df["Au"].sum(), "Au_se": total_scale * np.sqrt((df["Au_se"]**2).sum()),
                 "Bu": total_scale * df["Bu"].sum(), "Bu_se": total_scale * np.sqrt((df["Bu_se"]**2).sum())})
    return pd.DataFrame(rows)


def table_7_10_comparison(summary: pd.DataFrame, truth: dict | None = None) -> pd.DataFrame:
    """Posterior Au, Bu (mean, 95 % interval) beside thesis table 7.10 (A_u = 3.24 N,
    B_u = 0.232 N s/m, with the table's standard deviations) and, for a simulation, the truth."""
    s = summary.set_index("parameter")
    rows = []
    for k in TOTALS:
        thesis = THESIS_UNDRIVEN[k]
        row = {"parameter": k, "mean": s.loc[k, "mean"], "q2.5": s.loc[k, "q2.5"], "q97.5": s.loc[k, "q97.5"],
               "thesis_table_7_10": thesis, "thesis_sd": THESIS_UNDRIVEN_SD[k],
               "difference_pct": 100.0 * (s.loc[k, "mean"] - thesis) / thesis}
        if truth and isinstance(truth.get(k), (int, float)):
            row["truth"] = truth[k]
            row["truth_in_95"] = bool(s.loc[k, "q2.5"] <= truth[k] <= s.loc[k, "q97.5"])
        rows.append(row)
    return pd.DataFrame(rows)


def spindown_report(fit, campaign=None, *, gates: config.Gates = config.DEFAULT_GATES) -> FitReport:
    """The report of a spin-down fit: summary (Au, Bu, Au_wheel[w], Bu_wheel[w], the spreads
    of a hierarchical fit, F50_undriven_N), per-run rows (v0_mps, sigma_mps, and Au_run, Bu_run
    when hierarchical) and the gates."""
    p = fit.problem
    observed = np.where(np.asarray(p.mask), np.asarray(p.speed_mps), np.nan)
    hier = p.pooling == "hierarchical"
    names = list(TOTALS) + list(WHEEL_SITES) + (["tau_Au_wheel", "tau_Bu_wheel"] if hier else [])
    run_sites = ("v0_mps", "sigma_mps") + (("Au_run", "Bu_run") if hier else ())
    return channel_report(
        fit, names, kind="spindown", observed={"wheel_speed_mps": observed}, run_sites=run_sites,
        dims={"Au_wheel": ["wheel"], "Bu_wheel": ["wheel"], "v0_mps": ["run"], "sigma_mps": ["run"],
              "Au_run": ["run"], "Bu_run": ["run"],
              "wheel_speed_mps": ["run", "sample"]},
        coords={"wheel": list(p.wheels), "run": [str(r) for r in p.run_ids]}, gates=gates,
        extra={"wheels": list(p.wheels), "undriven_wheels": p.undriven_wheels, "pooling": p.pooling,
               "totals_scaled_from_tested_wheels": p.total_scale != 1.0})


def spindown_extras(fit, campaign, summary: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """The extra tables of a spin-down fit directory: ``table_7_10.csv``
    (:func:`table_7_10_comparison`) and ``classical.csv`` (:func:`classical_spindown`)."""
    return {"table_7_10.csv": table_7_10_comparison(summary, fit.truth),
            "classical.csv": classical_spindown(campaign)}
