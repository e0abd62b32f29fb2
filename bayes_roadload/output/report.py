"""The report of a fit: ``report.html`` (self-contained) and ``report.md`` from a fit directory.

:func:`render_report` reads only the files a ``fit`` wrote (``summary.csv``, ``diagnostics.json``,
``fit.json``, ``posterior.nc``, ``runs_summary.csv``, ``validity.csv`` and the tables of a kind:
``classical.csv``, ``per_group.csv``, ``table_7_10.csv``, ``comparison.csv``, ``budget.csv``,
``standards*.csv``), plus the campaign's ``truth.json`` and ``vehicle.toml`` when ``fit.json``
names a campaign directory that still exists.  Every section appears only when its inputs exist,
so one renderer serves every data kind and both methods (NUTS and least squares):

1. header: model, kind, method, campaign, pooling, draws, package version;
2. the diagnostic gates first, each with its value, threshold and remedy (a failed fit opens
   with a red banner);
3. the posterior table (``summary.csv``, with the truth when the campaign has one);
4. trace and rank plots of the free parameters (ArviZ);
5. pair plots of the drag coefficients (AD-BD-CD0, CD0-KD; At-Bt-Ct, Au-Bu for the channel fits);
6. the road-load curve F(v) with its 50 % and 95 % posterior bands beside the classical result;
7. per-run residuals, observed minus the posterior-mean prediction, with the 50 % and 95 %
   posterior-predictive bands (every fit whose ``posterior.nc`` holds a posterior predictive);
8. validity flags (``validity.csv``) and the other tables of the fit directory.

The HTML embeds its images as base64 PNG and has no script; ``report.md`` refers to the same
PNG files written to ``report_files/`` beside it.
"""

from __future__ import annotations

import base64
import dataclasses
import datetime as _dt
import html
import io
import json
import math
import os
import tomllib
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import arviz as az  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from .. import __version__, config  # noqa: E402
from ..data.campaign import read_vehicle_file  # noqa: E402
from ..inference.results import REMEDIES  # noqa: E402
from ..analysis.regulation import GTR_REFERENCE_SPEEDS_KPH  # noqa: E402
from ..physics.atmosphere import REFERENCE_AIR_DENSITY_KGPM3  # noqa: E402

HTML_NAME = "report.html"
MD_NAME = "report.md"
FILES_DIR = "report_files"

KPH_PER_MPS = 3.6
DERIVED_PREFIXES = ("F50_", "F0_N", "F1_N_per_kph", "F2_N_per_kph2")
"""Summary rows that are functions of the free parameters (not sampled; no trace plot)."""

PAIR_GROUPS = (("AD", "BD", "CD0"), ("CD0", "KD"), ("At", "Bt", "Ct"), ("Au", "Bu"))
"""Coefficient groups drawn as pair plots, each over its members in the posterior (two or more)."""

NOISE_FREE_PREDICTION = {"speed_mps": "speed_integrated_mps"}
"""Observed quantity -> its noise-free posterior prediction (the centre of the residuals)."""

MAX_TRACE_PARAMETERS = 8
MAX_RESIDUAL_RUNS = 12

TABLE_TITLES = {
    "runs_summary.csv": "Per-run quantities (runs_summary.csv)",
    "per_group.csv": "Classical least squares per group (per_group.csv)",
    "classical.csv": "Classical analysis (classical.csv)",
    "table_7_10.csv": "Against thesis table 7.10 (table_7_10.csv)",
    "comparison.csv": "Steady state against coastdown (comparison.csv)",
    "budget.csv": "Uncertainty budget (budget.csv)",
}
"""Titles of the known tables of a fit directory; other CSV files appear under their file name."""

GATE_VALUES = {
    "divergences": ("divergences", "max_divergences", "<="),
    "r_hat": ("max_r_hat", "max_r_hat", "<="),
    "ess_bulk": ("min_ess_bulk", "min_ess_bulk", ">="),
    "ess_tail": ("min_ess_tail", "min_ess_tail", ">="),
    "bfmi": ("bfmi", "min_bfmi", ">="),
    "tree_depth": ("tree_depth_limit_hits_fraction", "max_tree_depth_hits_fraction", "<="),
}
"""Gate -> (its value in diagnostics.json, its threshold in ``thresholds``, the passing relation)."""


def fmt(x) -> str:
    """A number as the report prints it everywhere (5 significant digits; '-' when missing)."""
    if x is None or (isinstance(x, str) and not x.strip()):
        return "-"
    if isinstance(x, (bool, np.bool_)):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    try:
        v = float(x)
    except (TypeError, ValueError):
        return str(x)
    if not math.isfinite(v):
        return "-"
    return f"{v:.5g}"


# ----------------------------------------------------------------------------- the document model

@dataclasses.dataclass(frozen=True)
class Figure:
    """A PNG image of the report: ``name`` is its file stem in ``report_files/``."""

    name: str
    title: str
    png: bytes
    caption: str = ""


@dataclasses.dataclass(frozen=True)
class Table:
    """A table of the report; ``flag`` marks rows to highlight (e.g. rejected runs)."""

    frame: pd.DataFrame
    flag: tuple[bool, ...] | None = None


@dataclasses.dataclass(frozen=True)
class Text:
    """A paragraph; ``alert`` prints it as a red banner."""

    text: str
    alert: bool = False


@dataclasses.dataclass
class Section:
    """One section: an ``id`` (HTML anchor), a title and its blocks in order."""

    id: str
    title: str
    blocks: list = dataclasses.field(default_factory=list)


@dataclasses.dataclass
class FitDirectory:
    """What a fit directory holds, read once."""

    path: Path
    summary: pd.DataFrame | None
    diagnostics: dict | None
    fit: dict
    idata: az.InferenceData | None
    campaign_dir: Path | None
    truth: dict
    vehicle: object | None

    @property
    def method(self) -> str:
        return str(self.fit.get("method") or (self.diagnostics or {}).get("method")
                   or ("nuts" if self.idata is not None else "lsq"))

    @property
    def kind(self) -> str:
        return str(self.fit.get("kind") or (self.diagnostics or {}).get("kind") or "traces")

    def posterior_has(self, *names: str) -> bool:
        return self.idata is not None and hasattr(self.idata, "posterior") and all(
            n in self.idata.posterior for n in names)


def _read_json(path: Path) -> dict | None:
    return json.loads(path.read_text()) if path.is_file() else None


def _flat_truth(doc: dict) -> dict[str, float]:
    """Scalar truth values, with per-element dicts flattened to ``name[key]`` rows."""
    out = {}
    for k, v in doc.items():
        if isinstance(v, bool):
            continue
        if isinstance(v, (int, float)):
            out[k] = float(v)
        elif isinstance(v, dict):
            out.update({f"{k}[{e}]": float(x) for e, x in v.items()
                        if isinstance(x, (int, float)) and not isinstance(x, bool)})
    return out


def read_fit_directory(fit_dir: str | os.PathLike, campaign: str | os.PathLike | None = None) -> FitDirectory:
    """Read the files of a fit directory (and its campaign's truth and vehicle when reachable).

    Parameters
    ----------
    fit_dir : the output directory of ``bayes-roadload fit``.
    campaign : the campaign directory; default: the ``campaign`` entry of ``fit.json``.
    """
    path = Path(fit_dir)
    if not path.is_dir():
        raise FileNotFoundError(f"{path}: not a directory (give the output directory of `bayes-roadload fit`)")
    summary_file = path / "summary.csv"
    if not summary_file.is_file():
        raise FileNotFoundError(f"{summary_file}: missing; a fit directory holds at least summary.csv")
    summary = pd.read_csv(summary_file)
    fit = _read_json(path / "fit.json") or {}
    diag = _read_json(path / "diagnostics.json")
    idata = az.from_netcdf(str(path / "posterior.nc")) if (path / "posterior.nc").is_file() else None
    cdir = Path(campaign) if campaign is not None else (Path(fit["campaign"]) if fit.get("campaign") else None)
    if cdir is not None and not cdir.is_dir():
        cdir = None
    truth = {}
    if cdir is not None and (cdir / "truth.json").is_file():
        truth = _flat_truth(json.loads((cdir / "truth.json").read_text()))
    elif isinstance(fit.get("truth"), dict):
        truth = _flat_truth(fit["truth"])
    vehicle = None
    if cdir is not None and (cdir / "vehicle.toml").is_file():
        # spin-down campaigns describe wheels ([spindown]), not a vehicle
        if "vehicle" in tomllib.loads((cdir / "vehicle.toml").read_text()):
            vehicle = read_vehicle_file(cdir / "vehicle.toml")[0]
    return FitDirectory(path, summary, diag, fit, idata, cdir, truth, vehicle)


# ----------------------------------------------------------------------------- figures

def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def _sampled_scalars(fd: FitDirectory) -> list[str]:
    """Free scalar parameters to trace: ``fit.json``'s ``free`` or the non-derived summary rows."""
    post = fd.idata.posterior
    names = list(fd.fit.get("free") or [])
    if not names:
        names = [p for p in fd.summary["parameter"] if "[" not in p and not p.startswith(DERIVED_PREFIXES)]
    names += [p for p in fd.summary["parameter"] if p.startswith("tau_") or p in ("q_mps_per_sqrt_s",
                                                                                  "sigma_driveline_n")]
    seen, out = set(), []
    for n in names:
        if n in post and set(post[n].dims) == {"chain", "draw"} and n not in seen and np.ptp(post[n].values) > 0:
            seen.add(n)
            out.append(n)
    return out[:MAX_TRACE_PARAMETERS]


def trace_figures(fd: FitDirectory) -> list[Figure]:
    """Trace and rank plots of the free parameters."""
    names = _sampled_scalars(fd)
    if not names:
        return []
    axes = az.plot_trace(fd.idata, var_names=names, compact=True, show=False,
                         figsize=(10, 1.8 * len(names)))
    trace = Figure("trace", "Trace plots", _png(np.ravel(axes)[0].figure),
                   "left: posterior density per chain; right: the draws in order (no trend, chains overlapping)")
    if fd.idata.posterior.sizes["chain"] < 2:
        return [trace]
    axes = az.plot_rank(fd.idata, var_names=names, show=False, figsize=(10, 2.2 * math.ceil(len(names) / 3)))
    rank = Figure("rank", "Rank plots", _png(np.ravel(axes)[0].figure),
                  "rank histograms per chain: flat when the chains sample the same distribution")
    return [trace, rank]


def pair_figures(fd: FitDirectory) -> list[Figure]:
    """Pair plots of the coefficient groups of :data:`PAIR_GROUPS`, each over the members that the
    posterior samples (at least two)."""
    out, drawn = [], []
    post = fd.idata.posterior
    for full in PAIR_GROUPS:
        group = tuple(g for g in full if g in post and set(post[g].dims) == {"chain", "draw"}
                      and np.ptp(post[g].values) > 0)
        if len(group) < 2 or any(set(group) <= d for d in drawn):
            continue
        drawn.append(set(group))
        axes = az.plot_pair(fd.idata, var_names=list(group), kind="scatter", marginals=True, show=False,
                            scatter_kwargs={"alpha": 0.3, "s": 4},
                            figsize=(2.6 * len(group), 2.6 * len(group)))
        out.append(Figure("pair_" + "_".join(group), "Pair plot " + " - ".join(group),
                          _png(np.ravel(axes)[0].figure), "posterior draws, all chains"))
    return out


@dataclasses.dataclass(frozen=True)
class Curve:
    """A road-load curve F(v) [N] of speed v [km/h]: its draws [draws, speeds] or one line."""

    label: str
    speeds_kph: np.ndarray
    draws: np.ndarray


def _posterior_curve(fd: FitDirectory, speeds_kph: np.ndarray) -> tuple[str, np.ndarray] | None:
    """The posterior draws of F(v): F0 + F1 v + F2 v^2 (v in km/h, reference conditions), else the
    driveline loss At + Bt v + Ct v^2 or the undriven-wheel loss Au + Bu v (v in m/s)."""
    if fd.idata is None:
        return None
    post = fd.idata.posterior
    v = speeds_kph[None, :]
    if fd.posterior_has("F0_N", "F1_N_per_kph", "F2_N_per_kph2"):
        c = [post[k].values.reshape(-1, 1) for k in ("F0_N", "F1_N_per_kph", "F2_N_per_kph2")]
        return "road load at reference conditions", c[0] + c[1] * v + c[2] * v**2
    w = v / KPH_PER_MPS
    if fd.posterior_has("At", "Bt", "Ct"):
        c = [post[k].values.reshape(-1, 1) for k in ("At", "Bt", "Ct")]
        return "driveline loss", c[0] + c[1] * w + c[2] * w**2
    if fd.posterior_has("Au", "Bu"):
        c = [post[k].values.reshape(-1, 1) for k in ("Au", "Bu")]
        return "undriven-wheel loss", c[0] + c[1] * w
    return None


def _coefficient_curve(row, speeds_kph: np.ndarray, vehicle) -> np.ndarray | None:
    """One curve F(v) from a row of named coefficients (F0/F1/F2; At/Bt/Ct; Au/Bu; AD/BD/CD0 with
    the vehicle at the reference air density)."""
    v, w = speeds_kph, speeds_kph / KPH_PER_MPS
    get = lambda k: float(row[k]) if k in row and pd.notna(row[k]) else None  # noqa: E731
    f = [get(k) for k in ("F0_N", "F1_N_per_kph", "F2_N_per_kph2")]
    if None not in f:
        return f[0] + f[1] * v + f[2] * v**2
    t = [get(k) for k in ("At", "Bt", "Ct")]
    if None not in t:
        return t[0] + t[1] * w + t[2] * w**2
    u = [get(k) for k in ("Au", "Bu")]
    if None not in u:
        return u[0] + u[1] * w
    d = [get(k) for k in ("AD", "BD", "CD0")]
    if None not in d and vehicle is not None:
        mg = vehicle.mass_kg * config.GRAVITY_MPS2
        return d[0] * mg + d[1] * mg * w + d[2] * 0.5 * REFERENCE_AIR_DENSITY_KGPM3 * vehicle.frontal_area_m2 * w**2
    return None


def classical_curves(fd: FitDirectory, speeds_kph: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """The classical results as curves: a least-squares fit's weighted mean and its groups, the
    ``classical.csv`` of a kind (long ``parameter, estimate`` rows or one row per group with a
    ``total`` row)."""
    out = []
    if fd.method == "lsq":
        mean = fd.summary.set_index("parameter")["mean"]
        c = _coefficient_curve(mean, speeds_kph, fd.vehicle)
        if c is not None:
            out.append(("least squares, weighted mean (eq. 5.15)", c))
    per_group = fd.path / "per_group.csv"
    if per_group.is_file():
        for _, row in pd.read_csv(per_group).iterrows():
            c = _coefficient_curve(row, speeds_kph, fd.vehicle)
            if c is not None:
                out.append(("least squares per group", c))
    classical = fd.path / "classical.csv"
    if classical.is_file():
        table = pd.read_csv(classical)
        if {"parameter", "estimate"} <= set(table.columns):
            c = _coefficient_curve(table.set_index("parameter")["estimate"], speeds_kph, fd.vehicle)
            if c is not None:
                out.append(("classical analysis (classical.csv)", c))
        elif "wheel" in table.columns and (table["wheel"].astype(str) == "total").any():
            row = table[table["wheel"].astype(str) == "total"].iloc[0]
            c = _coefficient_curve(row, speeds_kph, fd.vehicle)
            if c is not None:
                out.append(("classical analysis, vehicle total (classical.csv)", c))
    return out


def _speed_range_kph(fd: FitDirectory) -> np.ndarray:
    """Speeds to draw F(v) over: up to the largest observed speed, else to 130 km/h."""
    top = 130.0
    if fd.idata is not None and hasattr(fd.idata, "observed_data") and "speed_mps" in fd.idata.observed_data:
        top = float(np.nanmax(fd.idata.observed_data["speed_mps"].values)) * KPH_PER_MPS
    return np.linspace(0.0, max(top, 20.0), 120)


def road_load_figure(fd: FitDirectory) -> tuple[Figure | None, pd.DataFrame | None]:
    """F(v) with the 50 % and 95 % posterior bands and the classical curves, and a table of
    both at the reference speeds of the GTR (20-130 km/h) within the drawn range."""
    speeds = _speed_range_kph(fd)
    post = _posterior_curve(fd, speeds)
    classical = classical_curves(fd, speeds)
    if post is None and not classical:
        return None, None
    fig, (ax, dx) = plt.subplots(2, 1, figsize=(7.5, 7.0), sharex=True, height_ratios=(3, 2))
    centre = None
    if post is not None:
        label, draws = post
        q = np.percentile(draws, [2.5, 25.0, 50.0, 75.0, 97.5], axis=0)
        centre = q[2]
        for a, c in ((ax, 0.0), (dx, centre)):
            a.fill_between(speeds, q[0] - c, q[4] - c, color="tab:blue", alpha=0.2, label="95 % posterior band")
            a.fill_between(speeds, q[1] - c, q[3] - c, color="tab:blue", alpha=0.4, label="50 % posterior band")
            a.plot(speeds, q[2] - c, color="tab:blue", lw=1.5, label=f"posterior median, {label}")
    groups = 0
    for label, c in classical:
        for a, ref in ((ax, 0.0), (dx, centre)):
            if ref is None:
                continue
            if label.startswith("least squares per group"):
                a.plot(speeds, c - ref, color="tab:orange", lw=0.6, alpha=0.5,
                       label="least squares per group" if groups == 0 else None)
            else:
                a.plot(speeds, c - ref, color="black", lw=1.2, ls="--", label=label)
        groups += label.startswith("least squares per group")
    ax.set_ylabel("F(v) [N]")
    ax.legend(fontsize=8)
    if centre is not None:
        dx.set_ylabel("F - posterior median [N]")
    else:
        dx.set_visible(False)
    for a in (ax, dx):
        a.grid(alpha=0.3)
    (dx if centre is not None else ax).set_xlabel("speed v [km/h]")
    ax.tick_params(labelbottom=True)
    figure = Figure("road_load", "Road load F(v)", _png(fig),
                    "posterior median with 50 % and 95 % bands beside the classical result; below, "
                    "the same as differences from the posterior median")
    ref = np.array([s for s in GTR_REFERENCE_SPEEDS_KPH if s <= speeds[-1]])
    rows = {"speed_kph": ref}
    if post is not None and ref.size:
        _, d = _posterior_curve(fd, ref)
        q = np.percentile(d, [2.5, 50.0, 97.5], axis=0)
        rows.update({"posterior_q2.5_N": q[0], "posterior_q50_N": q[1], "posterior_q97.5_N": q[2]})
    main = [(lbl, c) for lbl, c in classical_curves(fd, ref) if not lbl.startswith("least squares per group")]
    if main and ref.size:
        rows["classical_N"] = main[0][1]
    table = pd.DataFrame(rows) if ref.size and len(rows) > 1 else None
    return figure, table


def _residual_pairs(fd: FitDirectory) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray, str]]:
    """(observed name, observed [run, k], centre [run, k], predictive [n, run, k], x label) for each
    observed quantity with a posterior predictive of the same name."""
    idata = fd.idata
    if idata is None or not hasattr(idata, "posterior_predictive") or not hasattr(idata, "observed_data"):
        return []
    out = []
    for name in idata.observed_data.data_vars:
        if name not in idata.posterior_predictive:
            continue
        obs = idata.observed_data[name]
        if obs.ndim != 2:
            continue
        rep = idata.posterior_predictive[name].stack(n=("chain", "draw")).transpose("n", *obs.dims).values
        centre_name = NOISE_FREE_PREDICTION.get(name)
        if centre_name in idata.posterior_predictive:
            centre = idata.posterior_predictive[centre_name].mean(("chain", "draw")).transpose(*obs.dims).values
        else:
            centre = np.nanmean(rep, axis=0)
        out.append((name, obs.values, centre, rep, obs.dims[1]))
    return out


def residual_figures(fd: FitDirectory) -> list[Figure]:
    """Per run: observed minus the posterior-mean prediction, with the 50 % and 95 % bands of
    the posterior-predictive replicates about the same centre."""
    figures = []
    for name, obs, centre, rep, axis in _residual_pairs(fd):
        runs = [str(r) for r in fd.idata.observed_data[name].coords[fd.idata.observed_data[name].dims[0]].values]
        n = min(len(runs), MAX_RESIDUAL_RUNS)
        cols = min(n, 3)
        rows = math.ceil(n / cols)
        fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 2.4 * rows), squeeze=False, sharey=True)
        time = None
        if hasattr(fd.idata, "constant_data") and "time_s" in fd.idata.constant_data \
                and fd.idata.constant_data["time_s"].shape == obs.shape:
            time = fd.idata.constant_data["time_s"].values
        for i in range(rows * cols):
            ax = axes.flat[i]
            if i >= n:
                ax.set_visible(False)
                continue
            ok = np.isfinite(obs[i]) & np.isfinite(centre[i])
            x = (time[i] if time is not None else np.arange(obs.shape[1]))[ok]
            q = np.nanpercentile(rep[:, i, :][:, ok] - centre[i][ok], [2.5, 25.0, 75.0, 97.5], axis=0)
            ax.fill_between(x, q[0], q[3], color="tab:blue", alpha=0.2, lw=0)
            ax.fill_between(x, q[1], q[2], color="tab:blue", alpha=0.4, lw=0)
            ax.plot(x, obs[i][ok] - centre[i][ok], ".", ms=2 if ok.sum() > 50 else 5, color="black")
            ax.axhline(0.0, color="grey", lw=0.6)
            ax.set_title(f"run {runs[i]}", fontsize=9)
            ax.tick_params(labelsize=7)
            if time is None:
                ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
        axes.flat[0].set_ylabel(f"{name}: observed - predicted", fontsize=8)
        axes.flat[min(n, rows * cols) - 1].set_xlabel("time [s]" if time is not None else axis, fontsize=8)
        fig.tight_layout()
        more = f" (the first {n} of {len(runs)} runs)" if len(runs) > n else ""
        figures.append(Figure(f"residuals_{name}", f"Residuals per run: {name}", _png(fig),
                              "observed minus posterior-mean prediction (dots) with the 50 % and 95 % "
                              "posterior-predictive bands" + more))
    return figures


# ----------------------------------------------------------------------------- sections

def header_table(fd: FitDirectory) -> pd.DataFrame:
    """Model, kind, method, campaign, pooling, draws and versions, as ``item, value`` rows."""
    d = fd.diagnostics or {}
    rows = [("fit directory", str(fd.path.resolve())),
            ("model", fd.fit.get("model") or d.get("model") or "-"),
            ("data kind", fd.kind),
            ("method", fd.method),
            ("campaign", str(fd.campaign_dir) if fd.campaign_dir else (fd.fit.get("campaign") or "-"))]
    if fd.fit.get("free"):
        rows.append(("free parameters", ", ".join(fd.fit["free"])))
    pooling = fd.fit.get("pooling") or d.get("pooling") or fd.fit.get("grouping")
    if pooling:
        rows.append(("pooling" if "grouping" not in fd.fit else "grouping", str(pooling)))
    if d.get("chains") is not None:
        rows.append(("draws", f"{d['chains']} chains x {d.get('draws_per_chain', '-')} draws"))
    if fd.fit.get("n_groups") is not None:
        rows.append(("groups", str(fd.fit["n_groups"])))
    rows.append(("bayes-roadload", __version__))
    rows.append(("rendered", _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")))
    return pd.DataFrame(rows, columns=["item", "value"])


def gate_table(diag: dict) -> pd.DataFrame:
    """One row per gate of ``diagnostics.json``: value, threshold, pass, remedy."""
    thresholds = diag.get("thresholds", {})
    rows = []
    for gate, ok in diag.get("gates", {}).items():
        value_key, limit_key, rel = GATE_VALUES.get(gate, (gate, gate, ""))
        value = diag.get(value_key)
        if isinstance(value, list):
            value = min(value) if value else None
        limit = thresholds.get(limit_key)
        rows.append({"gate": gate, "value": fmt(value), "required": f"{rel} {fmt(limit)}" if limit is not None else "-",
                     "result": "PASS" if ok else "FAIL", "remedy": "" if ok else REMEDIES.get(gate, "")})
    return pd.DataFrame(rows, columns=["gate", "value", "required", "result", "remedy"])


def gates_section(fd: FitDirectory) -> Section:
    """The diagnostic gates, with a red banner and the remedies when any failed."""
    s = Section("gates", "Diagnostic gates")
    d = fd.diagnostics
    if d is None:
        if fd.method == "lsq":
            ok = fd.fit.get("all_converged")
            s.blocks.append(Text("Least squares: no sampler gates. Every group's optimiser converged: "
                                 f"{fmt(ok) if ok is not None else '-'}.", alert=ok is False))
        else:
            s.blocks.append(Text("No diagnostics.json in the fit directory: the gates are unknown.", alert=True))
        return s
    failed = list(d.get("failed") or [g for g, ok in d.get("gates", {}).items() if not ok])
    if failed:
        s.blocks.append(Text("FIT FAILED ITS DIAGNOSTIC GATES: " + ", ".join(failed)
                             + ". The posterior below is NOT reliable; remedies in the table.", alert=True))
    else:
        s.blocks.append(Text("Every diagnostic gate passed."))
    if d.get("map_converged") is False:
        s.blocks.append(Text("The MAP optimisation before sampling did not converge (diagnostics.json, map).",
                             alert=True))
    table = gate_table(d)
    s.blocks.append(Table(table, tuple(table["result"] == "FAIL")))
    return s


def posterior_table(fd: FitDirectory) -> pd.DataFrame:
    """``summary.csv`` formatted, with ``truth`` and ``in 95 %`` columns when the truth is known."""
    cols = [c for c in fd.summary.columns if c != "parameter" and fd.summary[c].notna().any()]
    rows = []
    for _, r in fd.summary.iterrows():
        row = {"parameter": r["parameter"], **{c: fmt(r[c]) for c in cols}}
        if fd.truth:
            t = fd.truth.get(r["parameter"])
            row["truth"] = fmt(t)
            if t is not None and {"q2.5", "q97.5"} <= set(r.index) and pd.notna(r["q2.5"]) and pd.notna(r["q97.5"]):
                row["in 95 %"] = "yes" if r["q2.5"] <= t <= r["q97.5"] else "NO"
            else:
                row["in 95 %"] = "-"
        rows.append(row)
    return pd.DataFrame(rows)


def validity_section(fd: FitDirectory) -> Section | None:
    """``validity.csv``: every run's checks, rejected runs highlighted."""
    f = fd.path / "validity.csv"
    if not f.is_file():
        return None
    v = pd.read_csv(f)
    s = Section("validity", "Validity flags")
    flag = tuple(v["rejected"].astype(bool)) if "rejected" in v else None
    if flag is not None:
        s.blocks.append(Text(f"{sum(flag)} of {len(v)} runs rejected (highlighted)."))
    s.blocks.append(Table(v.map(fmt), flag))
    return s


BUDGET_SOURCES_SHOWN = 5
"""Type B sources the budget figure names (those with the largest share of any quantity's
variance); the others are drawn together."""


def budget_parts(budget: pd.DataFrame) -> tuple[list[str], list[tuple[str, np.ndarray]]]:
    """The quantities of ``budget.csv`` (in its order) and the parts of their variance the budget
    figure draws, each (label, share per quantity): the data's own share (the posterior's
    variance before the Type B draws), the :data:`BUDGET_SOURCES_SHOWN` Type B sources with the
    largest share of any quantity, and the other sources together.  Rows without a quantity
    (sources left out, with the reason) are not drawn."""
    rows = budget[budget["quantity"].fillna("").astype(str).str.len().gt(0) & budget["variance_share"].notna()]
    if rows.empty:
        return [], []
    quantities = list(dict.fromkeys(rows["quantity"]))
    shares = rows.pivot_table(index="quantity", columns="source", values="variance_share", aggfunc="sum",
                              fill_value=0.0).reindex(quantities).fillna(0.0)
    sources = [c for c in shares.max().sort_values(ascending=False, kind="stable").index if c != "data"]
    named, rest = sources[:BUDGET_SOURCES_SHOWN], sources[BUDGET_SOURCES_SHOWN:]
    parts = [("data (the posterior's own)", shares["data"].to_numpy(float) if "data" in shares
              else np.zeros(len(quantities)))]
    parts += [(s, shares[s].to_numpy(float)) for s in named]
    if rest:
        parts.append((f"{len(rest)} other sources", shares[rest].sum(axis=1).to_numpy(float)))
    return quantities, parts


def budget_figure(budget: pd.DataFrame) -> Figure | None:
    """Each quantity's variance split by its sources as stacked bars (:func:`budget_parts`);
    None when the budget has no quantity rows."""
    quantities, parts = budget_parts(budget)
    if not quantities:
        return None
    fig, ax = plt.subplots(figsize=(8.0, 0.45 * len(quantities) + 1.2))
    y = np.arange(len(quantities))
    left = np.zeros(len(quantities))
    colours = plt.get_cmap("tab10").colors
    for i, (label, v) in enumerate(parts):
        ax.barh(y, v, left=left, color=colours[i % len(colours)], label=label, edgecolor="white", linewidth=0.5)
        for yi, (l0, w) in enumerate(zip(left, v)):
            if w >= 0.08:
                ax.text(l0 + w / 2, yi, f"{100 * w:.0f} %", ha="center", va="center", fontsize=8, color="white")
        left += v
    ax.set_yticks(y, quantities)
    ax.invert_yaxis()
    ax.set_xlim(0.0, 1.0)
    ax.xaxis.set_major_formatter(matplotlib.ticker.PercentFormatter(1.0))
    ax.set_xlabel("share of the variance")
    ax.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8, frameon=False)
    return Figure("budget", "Uncertainty budget", _png(fig),
                  "each quantity's variance by source: the data's own (the posterior before the Type B draws) and "
                  "each Type B source's c^2 u^2 (budget.csv); a large source share means the interval's width is "
                  "that source's declared uncertainty, which more runs do not reduce")


def table_sections(fd: FitDirectory) -> list[Section]:
    """The other tables of the fit directory: the known ones in a fixed order, then the rest
    (``budget.csv`` with its figure, :func:`budget_figure`)."""
    skip = {"summary.csv", "validity.csv"}
    files = [fd.path / n for n in TABLE_TITLES if (fd.path / n).is_file()]
    files += sorted(p for p in fd.path.glob("*.csv") if p.name not in skip and p.name not in TABLE_TITLES)
    out = []
    for f in files:
        t = pd.read_csv(f)
        title = TABLE_TITLES.get(f.name) or (f"Standards' results ({f.name})" if f.name.startswith("standards")
                                             else f.name)
        blocks: list = [Table(t.map(fmt))]
        if f.name == "budget.csv" and (fig := budget_figure(t)) is not None:
            blocks.insert(0, fig)
        out.append(Section("table-" + f.stem.replace("_", "-"), title, blocks))
    return out


def build_sections(fd: FitDirectory) -> list[Section]:
    """Every section the fit directory has the inputs for, in reading order."""
    sections = [Section("header", "Fit", [Table(header_table(fd))]), gates_section(fd)]
    post = Section("posterior", "Posterior" if fd.method != "lsq" else "Estimates (least squares)",
                   [Table(posterior_table(fd))])
    if fd.method == "lsq":
        post.blocks.insert(0, Text("mean: weighted mean over groups (eq. 5.15); sd: its standard error "
                                   "(eq. 5.16); q2.5 / q97.5: normal 95 % bounds."))
    sections.append(post)
    if fd.idata is not None and hasattr(fd.idata, "posterior"):
        figs = trace_figures(fd)
        if figs:
            sections.append(Section("trace", "Trace and rank plots", list(figs)))
        figs = pair_figures(fd)
        if figs:
            sections.append(Section("pairs", "Pair plots", list(figs)))
    fig, table = road_load_figure(fd)
    if fig is not None:
        blocks = [fig] + ([Table(table.map(fmt))] if table is not None else [])
        if table is not None and "classical_N" not in table:
            blocks.append(Text("No classical result in this fit directory (classical.csv, per_group.csv): "
                               "`bayes-roadload fit --method lsq` gives the least-squares one."))
        sections.append(Section("road-load", "Road load F(v)", blocks))
    if fd.idata is not None:
        figs = residual_figures(fd)
        if figs:
            sections.append(Section("residuals", "Residuals per run", list(figs)))
        else:
            sections.append(Section("residuals", "Residuals per run", [Text(
                "posterior.nc holds no posterior predictive of an observed quantity: no residual plot.")]))
    v = validity_section(fd)
    if v is not None:
        sections.append(v)
    sections.extend(table_sections(fd))
    return sections


# ----------------------------------------------------------------------------- rendering

CSS = """
body { font-family: sans-serif; max-width: 1100px; margin: 1em auto; padding: 0 1em; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.85em; }
th, td { border: 1px solid #ccc; padding: 2px 6px; text-align: right; }
th { background: #f0f0f0; } td:first-child, th:first-child { text-align: left; }
tr.flag td { background: #fdd; color: #900; }
p.alert { background: #c00; color: white; font-weight: bold; padding: 0.6em; }
figure { margin: 0.5em 0 1.5em; } figcaption { font-size: 0.85em; color: #555; }
img { max-width: 100%; }
"""


def _html_table(t: Table) -> str:
    f = t.frame
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in f.columns)
    body = []
    for i, (_, row) in enumerate(f.iterrows()):
        cls = ' class="flag"' if t.flag is not None and t.flag[i] else ""
        body.append(f"<tr{cls}>" + "".join(f"<td>{html.escape(str(x))}</td>" for x in row) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def to_html(sections: list[Section], title: str) -> str:
    """The self-contained HTML page (images as data URIs, no script)."""
    parts = [f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{html.escape(title)}</title>"
             f"<style>{CSS}</style></head><body><h1>{html.escape(title)}</h1>"]
    parts.append("<nav>" + " | ".join(f'<a href="#{s.id}">{html.escape(s.title)}</a>' for s in sections) + "</nav>")
    for s in sections:
        parts.append(f'<section id="{s.id}"><h2>{html.escape(s.title)}</h2>')
        for b in s.blocks:
            if isinstance(b, Text):
                cls = ' class="alert"' if b.alert else ""
                parts.append(f"<p{cls}>{html.escape(b.text)}</p>")
            elif isinstance(b, Table):
                parts.append(_html_table(b))
            elif isinstance(b, Figure):
                data = base64.b64encode(b.png).decode("ascii")
                parts.append(f'<figure><img alt="{html.escape(b.title)}" src="data:image/png;base64,{data}">'
                             f"<figcaption>{html.escape(b.title)}: {html.escape(b.caption)}</figcaption></figure>")
        parts.append("</section>")
    parts.append("</body></html>\n")
    return "\n".join(parts)


def _md_cell(x) -> str:
    return str(x).replace("|", "\\|").replace("\n", " ")


def to_markdown(sections: list[Section], title: str, files_dir: str = FILES_DIR) -> str:
    """The Markdown report; figures refer to ``files_dir/<name>.png``."""
    lines = [f"# {title}", ""]
    for s in sections:
        lines += [f"## {s.title}", ""]
        for b in s.blocks:
            if isinstance(b, Text):
                lines += [f"**{b.text}**" if b.alert else b.text, ""]
            elif isinstance(b, Table):
                f = b.frame
                lines.append("| " + " | ".join(_md_cell(c) for c in f.columns) + " |")
                lines.append("|" + "---|" * len(f.columns))
                for i, (_, row) in enumerate(f.iterrows()):
                    cells = [_md_cell(x) for x in row]
                    if b.flag is not None and b.flag[i]:
                        cells = [f"**{c}**" for c in cells]
                    lines.append("| " + " | ".join(cells) + " |")
                lines.append("")
            elif isinstance(b, Figure):
                lines += [f"![{b.title}]({files_dir}/{b.name}.png)", "", f"*{b.title}: {b.caption}*", ""]
    return "\n".join(lines)


def render_report(fit_dir: str | os.PathLike, *, campaign: str | os.PathLike | None = None) -> tuple[Path, Path]:
    """Write ``report.html`` and ``report.md`` (with ``report_files/*.png``) into a fit directory.

    Parameters
    ----------
    fit_dir : the output directory of ``bayes-roadload fit`` (any data kind, NUTS or ``--method lsq``).
    campaign : the campaign directory for the truth and the vehicle; default: ``fit.json``'s
        ``campaign`` entry (the sections that need it are left out when it is not reachable).

    Returns
    -------
    The paths of ``report.html`` and ``report.md``.
    """
    fd = read_fit_directory(fit_dir, campaign)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", matplotlib.MatplotlibDeprecationWarning)  # raised inside ArviZ's plots
        sections = build_sections(fd)
    model = fd.fit.get("model") or (fd.diagnostics or {}).get("model") or "?"
    title = f"bayes-roadload report: {model}, {fd.kind}, {fd.method}"
    files = fd.path / FILES_DIR
    files.mkdir(exist_ok=True)
    for s in sections:
        for b in s.blocks:
            if isinstance(b, Figure):
                (files / f"{b.name}.png").write_bytes(b.png)
    html_path, md_path = fd.path / HTML_NAME, fd.path / MD_NAME
    html_path.write_text(to_html(sections, title), encoding="utf-8")
    md_path.write_text(to_markdown(sections, title), encoding="utf-8")
    return html_path, md_path
