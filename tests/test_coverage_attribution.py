"""benchmarks/coverage_attribution.py: the z-scores of the records, the ranking of the drawn
properties by correlation, and the check that a replayed campaign is the record's."""

import numpy as np
import pandas as pd
import pytest

from .conftest import benchmark_script


@pytest.fixture(scope="module")
def attribution():
    with benchmark_script("coverage_attribution") as module:
        yield module


def test_z_is_the_error_over_the_posterior_sd(attribution):
    rec = pd.DataFrame({"KD_mean": [1.0, 2.0], "KD_truth": [1.5, 1.0], "KD_sd": [0.25, 0.5],
                        "AD_mean": [0.01, 0.02], "AD_truth": [0.01, 0.01], "AD_sd": [0.001, 0.002]})
    z = attribution.z_scores(rec)
    assert list(z.columns) == ["AD", "KD"]  # the order of calibration.QUANTITIES, only those held
    np.testing.assert_allclose(z["KD"], [-2.0, 2.0])
    np.testing.assert_allclose(z["AD"], [0.0, 5.0])


def test_the_property_that_drives_z_ranks_first_and_constants_are_skipped(attribution):
    rng = np.random.default_rng(3)
    driver, noise = rng.normal(size=40), rng.normal(size=40)
    table = pd.DataFrame({"KD": -2.0 * driver, "veh_k4_over_kd": driver, "err_mass_rel": noise,
                          "veh_constant": np.ones(40), "other": driver})  # "other": not a drawn property
    top = attribution.correlations(table, ["KD"], top=5)
    assert top.iloc[0]["property"] == "veh_k4_over_kd" and top.iloc[0]["r"] == pytest.approx(-1.0)
    assert set(top["property"]) == {"veh_k4_over_kd", "err_mass_rel"}


def test_halves_split_at_the_median(attribution):
    table = pd.DataFrame({"KD": [-3.0, -1.0, 0.0, 2.0], "veh_k4_per_rad4": [-4.0, -3.0, -1.0, -0.5]})
    row = attribution.halves(table, ["KD"], ["veh_k4_per_rad4"]).iloc[0]
    # median -2: the two campaigns above it (-1, -0.5) have z 0 and 2, the two below -3 and -1
    assert (row["n_above"], row["mean_z_above"], row["mean_z_below"]) == (2, 1.0, -2.0)


@pytest.mark.slow  # simulates a campaign (~10-40 s); the script's own runs take this path for every record
def test_a_replay_that_is_not_the_records_campaign_is_refused(attribution):
    with pytest.raises(RuntimeError, match="seed 5: the simulated AD"):
        attribution.drawn_properties(5, 1, {"AD": -1.0, "BD": 0.0, "CD0": 0.0, "KD": 0.0})
