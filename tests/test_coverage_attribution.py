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


@pytest.mark.slow  # simulates a campaign twice, as the refusal above
def test_the_humidity_is_read_as_the_dry_air_densitys_error(attribution):
    """``air_density_dry_over_moist_rel``: the analysis' dry-air density over the moist air's,
    less one.  Water vapour (R_v = 461.5 J/(kg K)) displaces dry air (R_d = 287.06) at the same
    pressure, so with vapour pressure e the ratio is 1 / (1 - (e / p)(1 - R_d / R_v)); the
    tolerance is the analysis' R = 287.05 against the simulator's 287.058 (3e-5)."""
    from bayes_roadload.simulate.independent import simulate_independent

    camp = simulate_independent(5, pairs=1)
    meta = camp.truth["meta"]
    props = attribution.drawn_properties(5, 1, {q: float(camp.truth[q]) for q in ("AD", "BD", "CD0", "KD")})
    rh, t_c = meta["relative_humidity"], meta["temperature0_k"] - 273.15
    assert props["air_relative_humidity"] == rh
    share = rh * 610.94 * np.exp(17.625 * t_c / (t_c + 243.04)) / meta["pressure0_pa"] * (1.0 - 287.058 / 461.495)
    assert props["air_density_dry_over_moist_rel"] == pytest.approx(1.0 / (1.0 - share) - 1.0, abs=5e-5)
    assert props["air_density_dry_over_moist_rel"] >= -5e-5  # dry air is never the lighter


def test_the_dry_air_z_is_the_density_error_over_the_posterior_sd(attribution):
    """A coefficient of the dynamic pressure read with a density too large by 1 + e reads low
    by e / (1 + e) of its truth; in posterior sds that is the expected z, matched by seed."""
    table = pd.DataFrame({"seed": [2, 1], "air_density_dry_over_moist_rel": [0.01, 0.0]})
    records = pd.DataFrame({"seed": [1, 2], "CD0_truth": [0.3, 0.4], "CD0_sd": [0.01, 0.02],
                            "KD_truth": [1.0, 2.0], "KD_sd": [0.5, 0.4]})
    out = attribution.dry_air_z(table, records)
    assert out["CD0_z_dry_air"].tolist() == pytest.approx([-(0.01 / 1.01) * 0.4 / 0.02, 0.0])
    assert out["KD_z_dry_air"].tolist() == pytest.approx([-(0.01 / 1.01) * 2.0 / 0.4, 0.0])
    assert "CD0_z_dry_air" not in table  # the caller's table is left as it was
