"""benchmarks/calibration_study.py's readings of records: ``--with`` parsed and refused, and
``--rescale``'s table naming the campaigns it reads."""

import numpy as np
import pandas as pd
import pytest

from .conftest import benchmark_script


@pytest.fixture(scope="module")
def study():
    with benchmark_script("calibration_study") as module:
        yield module


def test_with_specs_are_parsed_and_bad_ones_refused(study):
    assert study.parse_also(["tyre=0.54", "lev=1:above"]) == {"tyre": (0.54, None), "lev": (1.0, "above")}
    assert study.parse_also(None) == {}
    for bad, why in (("=0.5", "name the source"), ("tyre=x", "SOURCE=F"), ("tyre=1:up", "above or below")):
        with pytest.raises(SystemExit, match=why):
            study.parse_also([bad])
    with pytest.raises(SystemExit, match="given twice"):
        study.parse_also(["tyre=1", "tyre=0.5"])


def test_rescale_table_reads_each_factor_and_refuses_a_misspelt_source(study):
    """Two quantities carry the source on 6 and 4 campaigns: the header counts "4-6" of the 6 fits,
    and each factor's row follows ``budget_rescaled``."""
    n = 6
    rec = pd.DataFrame({"seed": np.arange(n), "pairs": 3, "error": np.nan, "gate_pass": True,
                        "CD0_truth": 0.0, "CD0_mean": np.linspace(-1, 1, n), "CD0_sd": np.sqrt(2.0),
                        "CD0_sd_data": 1.0, "CD0_sd_typeb_tyre": 1.0,
                        "AD_truth": 0.0, "AD_mean": np.linspace(-1, 1, n), "AD_sd": np.sqrt(2.0),
                        "AD_sd_data": 1.0, "AD_sd_typeb_tyre": [1.0] * 4 + [np.nan] * 2})
    text = study.rescaled_markdown(rec, "tyre=1,0")
    assert "the 4-6 of the 6 fits" in text
    rows = [line for line in text.splitlines() if line.startswith("| CD0 |")]
    assert [r.split("|")[4].strip() for r in rows] == ["1", "0"]
    z_sd = float(rows[1].split("|")[6])
    assert z_sd == pytest.approx(np.std(np.linspace(-1, 1, n), ddof=1), abs=0.005)   # sd 1 at factor 0
    with pytest.raises(SystemExit, match="tyres: no quantity's records carry"):
        study.rescaled_markdown(rec, "tyre=1", also={"tyres": (0.0, None)})
    with pytest.raises(SystemExit, match="finite number >= 0"):
        study.rescaled_markdown(rec, "tyre=-1")
