"""Every notebook in notebooks/ runs top to bottom with small draw counts on its own example,
and on a user's fit directory (``BR_FIT_DIR``; the two that refit are ``slow``), and converts
to a valid .ipynb with a ``parameters`` cell."""

import os
import runpy
from pathlib import Path

import pandas as pd
import pytest

NOTEBOOKS = sorted((Path(__file__).parents[1] / "notebooks").glob("*.py"))
SMALL = {"BR_PAIRS": "1", "BR_WARMUP": "150", "BR_DRAWS": "150", "BR_PLAN_SIMULATIONS": "2",
         "BR_PLAN_PAIRS": "1 2", "MPLBACKEND": "Agg"}


def run_notebook(path, out, monkeypatch, fit_dir=None):
    for k, v in dict(SMALL, BR_OUT=str(out)).items():
        monkeypatch.setenv(k, v)
    if fit_dir is None:
        monkeypatch.delenv("BR_FIT_DIR", raising=False)
    else:
        monkeypatch.setenv("BR_FIT_DIR", str(fit_dir))
    return runpy.run_path(str(path), run_name="__main__")


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, tmp_path, monkeypatch):
    jupytext = pytest.importorskip("jupytext")
    nb = jupytext.read(path)  # the percent format parses: it opens in Jupyter
    assert nb.cells and nb.cells[0].cell_type == "markdown"
    namespace = run_notebook(path, tmp_path, monkeypatch)
    pngs = list(tmp_path.glob("*.png"))
    assert pngs, "the notebook saved no figure"
    if "inside" in namespace:  # 01: the predictive band holds most of the measured speeds
        assert min(namespace["inside"]) > 0.8


@pytest.fixture(scope="module")
def user_fit(cli_nuts_fit):
    """A user's fit directory: `simulate` then `fit` through the command line (two pairs, pooled;
    the run's shared fit, ``tests/conftest.py``)."""
    return cli_nuts_fit.fit_dir


# on a user's fit, 03 refits simulated campaigns (as `plan` does: tests/test_cli.py) and 04
# diagnoses the campaign (as `diagnose` does: tests/analysis/test_diagnose.py); both run with -m slow
USER_FIT_SLOW = ("03_test_planning", "04_sim_to_real")


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if p.stem in USER_FIT_SLOW else p
                                  for p in NOTEBOOKS], ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs_on_a_user_fit(path, user_fit, tmp_path, monkeypatch):
    ns = run_notebook(path, tmp_path, monkeypatch, fit_dir=user_fit)
    summary = pd.read_csv(user_fit / "summary.csv").set_index("parameter")
    assert ns["FIT_DIR"] == str(user_fit)
    assert ns["mine" if "mine" in ns else "summary"] is not None
    if path.stem.startswith("01"):  # the analysis read the user's draws, not a new fit
        assert "fit" not in ns
        assert ns["samples"]["CD0"].mean() == pytest.approx(summary.loc["CD0", "mean"], rel=1e-9)
        assert (tmp_path / "road_load.png").is_file()
    elif path.stem.startswith("02"):
        assert ns["mine"].loc["CD0", "posterior mean"] == pytest.approx(summary.loc["CD0", "mean"], rel=1e-12)
        assert (tmp_path / "validation_your_fit.png").is_file()
    elif path.stem.startswith("03"):
        assert set(ns["mine"]["n_pairs"]) == {1, 2} and (tmp_path / "planning_your_fit.png").is_file()
    else:
        assert len(ns["mine"].candidates) > 0 and (tmp_path / "sim_to_real_your_campaign.png").is_file()


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_ipynb_from_the_percent_source(path):
    """`jupytext --to ipynb notebooks/*.py` (notebooks/README.md): a valid notebook whose
    parameters cell is tagged for papermill."""
    jupytext = pytest.importorskip("jupytext")
    nbformat = pytest.importorskip("nbformat")
    nb = nbformat.reads(jupytext.writes(jupytext.read(path), fmt="ipynb"), as_version=4)
    nbformat.validate(nb)
    tagged = [c for c in nb.cells if "parameters" in c.metadata.get("tags", [])]
    assert len(tagged) == 1 and "FIT_DIR" in tagged[0].source
