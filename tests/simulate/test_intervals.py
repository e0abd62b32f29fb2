"""Gate crossings of simulated speed traces against the interval physics."""

import dataclasses
import warnings

import numpy as np

from bayes_roadload.inference.intervals import build_interval_problem, model_band_times
from bayes_roadload.simulate import get_case, simulate_campaign
from bayes_roadload.simulate.intervals import gate_crossing_times, interval_campaign_from_traces


def test_gate_crossing_of_a_straight_line():
    t = np.arange(0, 20, 0.25)
    v = 30.0 - 0.4 * t
    np.testing.assert_allclose(gate_crossing_times(t, v, [28.0, 25.0, 1.0]), [5.0, 12.5, np.nan])


def test_noise_free_traces_give_the_model_interval_times():
    case = dataclasses.replace(get_case(1), head_wind_mps=0.0, cross_wind_mps=0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        c = simulate_campaign(case, pairs=2, seed=3)
    ic = interval_campaign_from_traces(c)
    assert sorted(ic.intervals["window"].unique()) == ["50-35kph", "95-70kph"]
    assert ic.intervals.groupby("window")["run"].nunique().to_dict() == {"50-35kph": 2, "95-70kph": 2}
    problem = build_interval_problem(ic, "three_term")
    truth = {k: c.truth[k] for k in problem.free}
    t = np.asarray(model_band_times(problem, truth)["time_s"])
    # RK4 at 4 Hz and a local line through 9 samples: agreement to ~1 ms on 3-15 s bands
    np.testing.assert_allclose(t, np.asarray(problem.observed_s), atol=2e-3)
