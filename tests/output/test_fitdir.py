"""The one fit-directory writer and its reader."""

import json
from types import SimpleNamespace

import arviz as az
import numpy as np
import pandas as pd
import pytest

from bayes_roadload.inference.results import SUMMARY_COLUMNS, FitReport
from bayes_roadload.output import FIT_FILES, fit_gates, fit_record, is_fit_dir, read_fit_dir, write_fit_dir


def _report(runs: bool) -> FitReport:
    rng = np.random.default_rng(0)
    idata = az.from_dict(posterior={"AD": rng.normal(size=(2, 10)), "v0_mps": rng.normal(size=(2, 10, 3))},
                         coords={"run": ["1", "2", "3"]}, dims={"v0_mps": ["run"]})
    summary = pd.DataFrame([{c: (0.5 if c != "parameter" else "AD") for c in SUMMARY_COLUMNS}])
    table = pd.DataFrame([{c: (0.1 if c != "parameter" else "v0_mps[1]") for c in SUMMARY_COLUMNS}])
    return FitReport(idata=idata, summary=summary, runs=table if runs else None, diagnostics={"pass": False, "failed": ["rhat", "ess_bulk"]})


def _fit(tmp_path):
    spec = SimpleNamespace(name="three_term", source=str(tmp_path / "none.toml"))
    problem = SimpleNamespace(kind="traces", spec=spec, free=("AD",),
                              settings=lambda: {"pooling": "hierarchical", "noise": "white", "robust": True})
    return SimpleNamespace(problem=problem)


@pytest.mark.parametrize("runs", [True, False])
def test_write_fit_dir_writes_the_contract_files(tmp_path, runs):
    out = tmp_path / "fit"
    extra = pd.DataFrame({"parameter": ["AD"], "estimate": [0.01]})
    written = write_fit_dir(_report(runs), out, record=fit_record(_fit(tmp_path), tmp_path),
                            extras={"classical.csv": extra})
    expected = [f for f in FIT_FILES if runs or f != "runs_summary.csv"] + ["classical.csv"]
    assert written == expected
    assert sorted(p.name for p in out.iterdir()) == sorted(expected)
    assert tuple(pd.read_csv(out / "summary.csv").columns) == SUMMARY_COLUMNS
    pd.testing.assert_frame_equal(pd.read_csv(out / "classical.csv"), extra)


def test_fit_record_and_read_back(tmp_path):
    out = tmp_path / "fit"
    write_fit_dir(_report(True), out, record=fit_record(_fit(tmp_path), tmp_path / "campaign"))
    record = json.loads((out / "fit.json").read_text())
    from bayes_roadload import __version__

    prov = record.pop("provenance")
    assert prov == {"package_version": __version__, "command_line": None, "campaign_sha256": None, "conversions": []}
    assert record == {"kind": "traces", "model": "three_term", "model_file": str(tmp_path / "none.toml"),
                      "free": ["AD"], "pooling": "hierarchical", "noise": "white", "robust": True,
                      "undriven": None, "campaign": str((tmp_path / "campaign").resolve())}
    assert is_fit_dir(out) and not is_fit_dir(tmp_path)
    back = read_fit_dir(out)
    assert back.record == dict(record, provenance=prov) and back.passed is False
    assert back.failed == ("rhat", "ess_bulk") == fit_gates(out)[1]
    (out / "diagnostics.json").unlink()   # as a least-squares fit directory: no gates, none failed
    assert fit_gates(out) == (True, ()) and read_fit_dir(out).passed
    assert back.model == "three_term"   # the model file does not exist: its name
    assert back.samples["v0_mps"].shape == (2, 10, 3)


def test_read_fit_dir_refuses_a_directory_without_fit_json(tmp_path):
    out = tmp_path / "fit"
    write_fit_dir(_report(True), out)
    with pytest.raises(ValueError, match="fit.json"):
        read_fit_dir(out)


def test_fit_campaign_loads_with_the_units_the_fit_was_told(tmp_path):
    """A campaign whose speed column names no unit loads only with ``--speed-unit``; a fit record
    of it holds that option in its conversions, and ``fit_campaign`` (what ``predict``,
    ``report --standard``, ``plan`` read) loads it with the same unit."""
    from bayes_roadload.data import CampaignError, load_campaign
    from bayes_roadload.output import fit_campaign

    from ..data.test_traces import runs_frame, write

    df = runs_frame()
    df = df.assign(speed=df.pop("speed_mps") * 3.6)          # km/h in a column that names no unit
    d = write(tmp_path, df)
    with pytest.raises(CampaignError, match="--speed-unit"):
        load_campaign(d)
    told = load_campaign(d, speed_unit="kph")
    record = {"campaign": str(d), "provenance": {"conversions": told.meta["conversions"]}}
    back = fit_campaign(record)
    np.testing.assert_allclose(back.runs["speed_mps"], told.runs["speed_mps"])
    np.testing.assert_allclose(back.runs["speed_mps"].iloc[0], 30.0)
    with pytest.raises(CampaignError, match="--speed-unit"):
        fit_campaign({"campaign": str(d), "provenance": {"conversions": []}})
