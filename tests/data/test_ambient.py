"""The ambient columns every kind may log (:mod:`bayes_roadload.data.ambient`): the logged
humidity reaches the fits' air density, a fraction in the percent column is refused naming the
file, column and row, and its hygrometer is a Type B source."""

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.data import CampaignError, load_campaign
from bayes_roadload.data.ambient import HUMIDITY_COLUMN, air_density
from bayes_roadload.data.uncertainty import SOURCES
from bayes_roadload.physics.atmosphere import air_density_kgpm3

from .test_intervals import split_campaign
from .test_traces import runs_frame, write


def test_logged_humidity_sets_each_samples_density(tmp_path):
    df = runs_frame()
    df["temperature_k"] = 298.0
    df["pressure_pa"] = 99_000.0
    df[HUMIDITY_COLUMN] = np.where(df["run"] == 1, 40.0, 80.0)
    batch, ids = load_campaign(write(tmp_path, df)).to_batch()
    rho = np.asarray(batch.air_density_kgpm3)
    assert rho[0, 0] == pytest.approx(air_density_kgpm3(99_000.0, 298.0, 0.40), rel=1e-12)
    assert rho[1, 0] == pytest.approx(air_density_kgpm3(99_000.0, 298.0, 0.80), rel=1e-12)
    assert rho[1, 0] < rho[0, 0] < air_density_kgpm3(99_000.0, 298.0)


def test_without_humidity_the_air_is_dry():
    t = pd.DataFrame({"temperature_k": [290.0], "pressure_pa": [101_000.0]})
    assert air_density(t)[0] == pytest.approx(101_000.0 / (287.05 * 290.0), rel=1e-14)


@pytest.mark.parametrize("values, message", [
    (0.55, r"runs\.csv.*column 'relative_humidity_pct', row 1: every value is at most 1.*multiply by 100"),
    (120.0, r"runs\.csv.*column 'relative_humidity_pct', row 1: value 120 outside \[0, 100\]"),
])
def test_a_humidity_that_is_not_a_percentage_is_refused(tmp_path, values, message):
    df = runs_frame()
    df[HUMIDITY_COLUMN] = values
    with pytest.raises(CampaignError, match=message):
        load_campaign(write(tmp_path, df))


def test_a_humidity_column_without_its_unit_is_refused(tmp_path):
    df = runs_frame()
    df["humidity"] = 55.0
    with pytest.raises(CampaignError, match=r"humidity.*relative_humidity_pct \(percent, 0-100\)"):
        load_campaign(write(tmp_path, df))


def test_interval_campaigns_take_it_per_run(tmp_path):
    from bayes_roadload.data import save_campaign
    from bayes_roadload.inference.intervals import build_interval_problem

    c = split_campaign()
    c.intervals[HUMIDITY_COLUMN] = c.intervals["run"].map({1: 30.0, 2: 50.0, 3: 70.0, 4: 90.0})
    back = load_campaign(save_campaign(c, tmp_path / "c"))
    bands = build_interval_problem(back).bands
    per_run = pd.Series(np.asarray(bands.air_density_kgpm3)).groupby(back.intervals["run"].to_numpy()).first()
    np.testing.assert_allclose(per_run.to_numpy(), [air_density_kgpm3(100_000.0, 293.2, h) for h in (0.3, 0.5, 0.7, 0.9)],
                               rtol=1e-12)
    changed = c.intervals.copy()
    changed.loc[changed.index[0], HUMIDITY_COLUMN] = 31.0   # within run 1
    with pytest.raises(CampaignError, match=HUMIDITY_COLUMN):
        type(c)(changed, c.vehicle)


def test_the_hygrometer_is_a_type_b_source_where_humidity_is_logged(tmp_path):
    """Its default is +-3 % read as rectangular; a shift near saturation stays a valid campaign."""
    df = runs_frame()
    df[HUMIDITY_COLUMN] = 60.0
    c = load_campaign(write(tmp_path, df))
    s = SOURCES[HUMIDITY_COLUMN]
    assert s.default == pytest.approx(3.0 / np.sqrt(3.0))
    shifted = s.apply(c, 2.0)
    assert (shifted.runs[HUMIDITY_COLUMN] - c.runs[HUMIDITY_COLUMN]).to_numpy() == pytest.approx(2.0)
    (tmp_path / "near").mkdir()
    near = load_campaign(write(tmp_path / "near", runs_frame().assign(relative_humidity_pct=99.0)))
    up, down = s.apply(near, s.default), s.apply(near, -s.default)   # kept inside the contract's 0-100 %
    assert up.runs[HUMIDITY_COLUMN].max() == 100.0 and down.runs[HUMIDITY_COLUMN].iloc[0] == pytest.approx(99.0 - s.default)
    (tmp_path / "dry").mkdir()
    assert s.apply(load_campaign(write(tmp_path / "dry", runs_frame())), 2.0) is None


def test_the_air_line_says_where_the_unlogged_humidity_goes():
    """The line ``fit`` prints: logged humidity -> moist air at its mean; temperature and
    pressure logged without it -> dry air, the humidity in the Type B budget (the source that
    applies there); no ambient columns -> dry reference air, the humidity's bias stated."""
    from bayes_roadload.data.ambient import ambient_line

    base = {"air_density_kgpm3": 1.2}
    moist = ambient_line({**base, "temperature_k": 295.0, "pressure_pa": 99000.0, HUMIDITY_COLUMN: 55.0})
    assert "moist air at 55 %" in moist and "unlogged" not in moist
    dry = ambient_line({**base, "temperature_k": 295.0, "pressure_pa": 99000.0, HUMIDITY_COLUMN: None})
    assert "dry air" in dry and "relative_humidity_unlogged_pct" in dry
    reference = ambient_line({**base, "temperature_k": None, "pressure_pa": None, HUMIDITY_COLUMN: None})
    assert "reference temperature" in reference and "C_D0 that much low" in reference
    assert "relative_humidity_unlogged_pct" not in reference
