"""Every notebook in notebooks/ runs top to bottom with small draw counts."""

import os
import runpy
from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).parents[1] / "notebooks").glob("*.py"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, tmp_path, monkeypatch):
    jupytext = pytest.importorskip("jupytext")
    nb = jupytext.read(path)  # the percent format parses: it opens in Jupyter
    assert nb.cells and nb.cells[0].cell_type == "markdown"
    for k, v in {"BR_PAIRS": "1", "BR_WARMUP": "150", "BR_DRAWS": "150", "BR_OUT": str(tmp_path),
                 "MPLBACKEND": "Agg"}.items():
        monkeypatch.setenv(k, v)
    namespace = runpy.run_path(str(path), run_name="__main__")
    pngs = list(tmp_path.glob("*.png"))
    assert pngs, "the notebook saved no figure"
    if "inside" in namespace:  # 01: the predictive band holds most of the measured speeds
        assert min(namespace["inside"]) > 0.8
