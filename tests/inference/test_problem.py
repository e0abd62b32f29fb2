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
MEMBERS = ("numpyro_model", "hessian_runs", "n_observations", "settings", "postprocess", "derived", "truth_values", "kind")
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
