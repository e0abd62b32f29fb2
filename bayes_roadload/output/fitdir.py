"""The fit directory: one writer and one reader for the fits of every data kind (NUTS, and the
classical least squares through the same writer).

A fit directory holds

``posterior.nc``
    ArviZ InferenceData (:func:`bayes_roadload.inference.results.inference_data`).
``summary.csv``
    ``parameter, mean, sd, q2.5, q50, q97.5, r_hat, ess_bulk, ess_tail``.
``runs_summary.csv``
    per-run rows, for the kinds that have them.
``diagnostics.json``
    the sampler diagnostics and gates (``pass``).
``fit.json``
    what the fit was: ``kind``, ``model``, ``model_file``, ``free``, ``pooling``, ``noise``,
    ``robust``, ``undriven`` (the known undriven-wheel loss, or null) and ``campaign`` (the
    campaign directory, or null): what ``plan`` needs to rebuild it; and ``provenance``
    (:func:`fit_provenance`: package version, command line, the campaign's content hash, the unit
    conversions made on load).

``posterior.nc`` carries the provenance as attributes of every group, and every variable its
``units`` (:func:`variable_units`).
extra tables
    per kind (:attr:`~bayes_roadload.inference.kinds.KindEntry.extras`), e.g. ``validity.csv``,
    ``table_7_10.csv``, ``classical.csv``, ``comparison.csv``.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import arviz as az
import numpy as np
import pandas as pd

from .. import __version__, config
from ..data import campaign_sha256
from ..inference.lsq import LsqResult, lsq_record
from ..inference.nuts import NutsFit
from ..inference.results import FitReport

FIT_FILES = ("posterior.nc", "summary.csv", "runs_summary.csv", "diagnostics.json", "fit.json")
"""The files every writer of :func:`write_fit_dir` may write, in the order they are listed."""


def fit_record(fit: NutsFit, campaign_path: str | os.PathLike | None = None) -> dict[str, Any]:
    """The content of ``fit.json`` (module docstring)."""
    p = fit.problem
    settings = p.settings()
    return {"kind": p.kind, "model": p.spec.name, "model_file": p.spec.source, "free": list(p.free),
            "pooling": settings["pooling"], "noise": settings["noise"], "robust": bool(settings["robust"]),
            "undriven": settings.get("undriven"),
            "campaign": None if campaign_path is None else str(Path(campaign_path).resolve())}


_SUFFIX_UNITS = (("_mps_per_sqrt_s", "m/s/sqrt(s)"), ("_N_per_kph2", "N/(km/h)^2"), ("_N_per_kph", "N/(km/h)"), ("_N", "N"), ("_mps2", "m/s^2"),
                 ("_mps", "m/s"), ("_kph", "km/h"), ("_kg", "kg"), ("_kgm2", "kg m^2"), ("_rad", "rad"),
                 ("_deg", "deg"), ("_m", "m"), ("_s", "s"), ("_k", "K"), ("_pa", "Pa"))


def variable_units(name: str) -> str:
    """The units of a posterior variable: a contract parameter's
    (:data:`~bayes_roadload.config.PARAMETER_UNITS`), a run-to-run spread ``tau_X`` in X's units,
    a standardised run offset ``z_X`` dimensionless, otherwise the unit its name's suffix
    states (``F50_N``: N, ``sigma_mps``: m/s, ``F2_N_per_kph2``: N/(km/h)^2); "unknown" when
    neither says."""
    if name in config.PARAMETER_UNITS:
        return config.PARAMETER_UNITS[name]
    head, _, rest = name.partition("_")
    if head == "tau" and rest in config.PARAMETER_UNITS:
        return config.PARAMETER_UNITS[rest]
    if head == "z" and rest:
        return "-"
    for suffix, unit in _SUFFIX_UNITS:
        if name.endswith(suffix):
            return unit
    return "unknown"


def fit_provenance(command_line: str | None = None, campaign: str | os.PathLike | None = None,
               conversions: list | None = None, ambient: dict | None = None) -> dict[str, Any]:
    """Where a fit came from: ``package_version``, ``command_line`` (or null), ``campaign_sha256``
    (:func:`~bayes_roadload.data.campaign_sha256` of the campaign directory, or null), the
    unit ``conversions`` made on load (:mod:`bayes_roadload.data.units`) and, when given, the
    ``ambient`` air the fit took (:func:`~bayes_roadload.data.ambient.ambient_record`)."""
    out = {"package_version": __version__, "command_line": command_line,
           "campaign_sha256": campaign_sha256(campaign) if campaign is not None and Path(campaign).is_dir() else None,
           "conversions": list(conversions or [])}
    if ambient is not None:
        out["ambient"] = dict(ambient)
    return out


def _annotate(idata: az.InferenceData, prov: dict[str, Any]) -> None:
    """Units on every variable and the provenance on every group of ``idata`` (in place;
    netCDF attributes are strings and numbers: conversions as JSON)."""
    attrs = {"package": "bayes-roadload", "package_version": prov.get("package_version", __version__),
             "command_line": prov.get("command_line") or "", "campaign_sha256": prov.get("campaign_sha256") or "",
             "unit_conversions": json.dumps(prov.get("conversions", []))}
    for group in idata.groups():
        ds = idata[group]
        ds.attrs.update(attrs)
        for var in ds.data_vars:
            ds[var].attrs["units"] = variable_units(str(var))


def write_fit_dir(report: FitReport, out_dir: str | os.PathLike, *, record: dict | None = None,
                  extras: dict[str, pd.DataFrame] | None = None, provenance: dict | None = None) -> list[str]:
    """Write a fit directory: ``posterior.nc`` (when the report has draws; units and provenance
    as attributes), ``summary.csv``, ``runs_summary.csv`` (when the report has per-run rows),
    ``diagnostics.json`` (when it has gates), ``fit.json`` (``record``, when given:
    :func:`fit_record`, :func:`~bayes_roadload.inference.lsq.lsq_record`, with ``provenance``
    added) and the ``extras`` tables.  Returns the names of the files written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    prov = provenance if provenance is not None else fit_provenance()
    if record is not None:
        record = dict(record, provenance=prov)
    written = []
    if report.idata is not None:
        _annotate(report.idata, prov)
        report.idata.to_netcdf(str(out / "posterior.nc"))
        written.append("posterior.nc")
    report.summary.to_csv(out / "summary.csv", index=False, float_format=report.float_format)
    written.append("summary.csv")
    if report.runs is not None:
        report.runs.to_csv(out / "runs_summary.csv", index=False, float_format=report.float_format)
        written.append("runs_summary.csv")
    if report.diagnostics is not None:
        (out / "diagnostics.json").write_text(json.dumps(report.diagnostics, indent=2) + "\n")
        written.append("diagnostics.json")
    if record is not None:
        (out / "fit.json").write_text(json.dumps(record, indent=2) + "\n")
        written.append("fit.json")
    for name, table in (extras or {}).items():
        table.to_csv(out / name, index=False, float_format=report.float_format)
        written.append(name)
    return written


def write_lsq_fit_dir(result: LsqResult, out_dir: str | os.PathLike, provenance: dict | None = None) -> list[str]:
    """The fit directory of a classical least-squares fit through :func:`write_fit_dir`:
    ``summary.csv`` (weighted means, eq. 5.15, and standard errors, eq. 5.16, in the columns
    of every summary; the MCMC columns empty), ``per_group.csv`` and ``fit.json``
    (:func:`~bayes_roadload.inference.lsq.lsq_record`, with ``provenance``)."""
    report = FitReport(idata=None, summary=result.summary(), runs=None, diagnostics=None, float_format="%.10g")
    return write_fit_dir(report, out_dir, record=lsq_record(result), extras={"per_group.csv": result.per_group},
                         provenance=provenance)


@dataclass
class FitDir:
    """A fit directory read back (:func:`read_fit_dir`).

    Attributes
    ----------
    path : the directory.
    record : ``fit.json``.
    samples : posterior draws, site -> [chain, draw, ...] array.
    passed : the fit passed its gates (``diagnostics.json`` ``pass``; True when absent).
    failed : the gates it failed (``diagnostics.json`` ``failed``), in the file's order.
    """

    path: Path
    record: dict[str, Any]
    samples: dict[str, np.ndarray]
    passed: bool
    failed: tuple[str, ...] = ()

    @property
    def model(self) -> str:
        """The model file when it still exists, else the model name."""
        f = self.record.get("model_file")
        return f if f and Path(f).is_file() else self.record["model"]


def fit_campaign(record: dict):
    """The campaign a fit record (``fit.json``) names, loaded with the unit options its
    provenance records: a ``--speed-unit`` / ``--airspeed-unit`` the fit was given
    (``provenance.conversions``, ``stated_by``), so that later commands read the same data."""
    from ..data import load_campaign
    from ..data.units import SPEED_CHANNELS, SPEED_UNIT_NAMES

    code = {name: unit for unit, name in SPEED_UNIT_NAMES.items()}
    options = {f"{stem}_unit": code[c["unit"]]
               for c in (record.get("provenance") or {}).get("conversions", [])
               for stem in SPEED_CHANNELS if c.get("stated_by") == f"--{stem}-unit"}
    return load_campaign(record["campaign"], **options)


def is_fit_dir(path: str | os.PathLike) -> bool:
    """``path`` holds a ``posterior.nc``."""
    return (Path(path) / "posterior.nc").is_file()


def fit_gates(path: str | os.PathLike) -> tuple[bool, tuple[str, ...]]:
    """Whether the fit in directory ``path`` passed its gates, and the gates it failed, from its
    ``diagnostics.json`` (``pass``, ``failed``); a directory without one (a least-squares fit)
    passed."""
    f = Path(path) / "diagnostics.json"
    diag = json.loads(f.read_text()) if f.is_file() else {}
    return bool(diag.get("pass", True)), tuple(diag.get("failed") or ())


def read_fit_dir(path: str | os.PathLike) -> FitDir:
    """Read a fit directory written by :func:`write_fit_dir`; refuses one without ``fit.json``
    or without the campaign path in it."""
    src = Path(path)
    meta_file = src / "fit.json"
    if not meta_file.is_file():
        raise ValueError(f"{src}: a fit directory needs the fit.json written by `bayes-roadload fit` (model, "
                         "campaign); refit the campaign or give the campaign directory")
    record = json.loads(meta_file.read_text())
    if record.get("method") == "lsq":
        raise ValueError(f"{src}: a least-squares fit (--method lsq) has no posterior draws; this command "
                         "needs a fit of `bayes-roadload fit` with --method nuts (the default)")
    if not record.get("campaign"):
        raise ValueError(f"{meta_file}: no campaign path recorded; give the campaign directory instead")
    post = az.from_netcdf(str(src / "posterior.nc")).posterior
    samples = {k: post[k].values for k in post.data_vars}
    passed, failed = fit_gates(src)
    return FitDir(path=src, record=record, samples=samples, passed=passed, failed=failed)
