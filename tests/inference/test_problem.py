"""Every data kind's problem implements the whole Problem protocol, with no dummy fields."""

import dataclasses

import pytest


from bayes_roadload.inference.bayes import FitProblem
from bayes_roadload.inference.distances import DistanceProblem
from bayes_roadload.inference.driveline import DrivelineProblem
from bayes_roadload.inference.intervals import IntervalProblem
from bayes_roadload.inference.problem import PooledRunProblem, Problem
from bayes_roadload.inference.spindown import SpindownProblem
from bayes_roadload.inference.steady import SteadyProblem

PROBLEMS = (FitProblem, IntervalProblem, DistanceProblem, SpindownProblem, SteadyProblem, DrivelineProblem)
MEMBERS = ("numpyro_model", "hessian_runs", "n_observations", "settings", "alternative_coordinates", "postprocess", "derived",
           "truth_values", "kind")
FIELDS = ("spec", "free", "initial", "run_ids", "priors")


@pytest.mark.parametrize("cls", PROBLEMS, ids=lambda c: c.__name__)
def test_every_problem_implements_the_protocol(cls):
    for name in MEMBERS:
        # its own, or from the shared implementation of problem.py, never inherited by chance
        owners = [k for k in cls.__mro__ if name in vars(k)]
        assert owners and (owners[0] is cls or owners[0] is PooledRunProblem), (cls.__name__, name)
    fields = {f.name for f in dataclasses.fields(cls)}
    for name in FIELDS:
        assert name in fields or name in vars(cls), (cls.__name__, name)


@pytest.mark.parametrize("cls", PROBLEMS[1:], ids=lambda c: c.__name__)
def test_no_coastdown_fields_on_other_kinds(cls):
    """The fields only the coastdown model reads are not carried by the other kinds."""
    fields = {f.name for f in dataclasses.fields(cls)}
    assert not fields & {"varying", "noise", "robust", "driveline_curve"}, cls.__name__


def test_problem_is_a_runtime_protocol():
    assert "settings" in dir(Problem) and "hessian_runs" in dir(Problem)


def test_only_a_problem_sampled_in_apparent_coefficients_has_other_coordinates(small_campaign):
    """The speed traces' lag model (apparent coefficients) offers A_D, B_D, C_D0 sampled
    directly, its starting values without the apparent sites; that problem, and the same traces
    without the lag, offer none."""
    from bayes_roadload.inference.bayes import APPARENT_SITES, build_problem, with_apparent

    lag = build_problem(small_campaign, "four_term_tyre_lag")
    values = with_apparent(lag, {"AD": 0.01, "BD": 2e-4, "CD0": 0.35, "tyre_lag_gain_per_mps": 0.005, "KD": 0.5})
    direct, start, what = lag.alternative_coordinates(values)
    assert lag.apparent is not None and direct.apparent is None and "directly" in what
    assert set(start) == set(values) - set(APPARENT_SITES.values()) and start["CD0"] == 0.35
    assert direct.alternative_coordinates(start) is None
    assert build_problem(small_campaign, "four_term").alternative_coordinates({}) is None
