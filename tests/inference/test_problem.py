"""Every data kind's problem implements the whole Problem protocol, with no dummy fields."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest


from bayes_roadload.inference.bayes import FitProblem
from bayes_roadload.inference.distances import DistanceProblem
from bayes_roadload.inference.driveline import DrivelineProblem
from bayes_roadload.inference.intervals import IntervalProblem
from bayes_roadload.inference.problem import PooledRunProblem, Problem
from bayes_roadload.inference.spindown import SpindownProblem
from bayes_roadload.inference.steady import SteadyProblem

PROBLEMS = (FitProblem, IntervalProblem, DistanceProblem, SpindownProblem, SteadyProblem, DrivelineProblem)
MEMBERS = ("numpyro_model", "hessian_runs", "n_observations", "settings", "alternative_coordinates", "shift_constant",
           "postprocess", "derived", "truth_values", "kind")
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


def test_a_constant_shift_moves_that_constant_only(small_campaign):
    """``shift_constant`` moves one fixed constant and keeps everything else; a name the problem
    does not fix gives None; a problem sampled in its apparent coefficients whose lag time
    constant moves gets that time constant's line (``bayes.lag_line``)."""
    from bayes_roadload.inference.bayes import build_problem, lag_line

    lag = build_problem(small_campaign, "four_term_tyre_lag")
    moved = lag.shift_constant("tyre_lag_time_constant_s", 100.0)
    assert moved.fixed == dict(lag.fixed, tyre_lag_time_constant_s=lag.fixed["tyre_lag_time_constant_s"] + 100.0)
    assert moved.apparent == lag_line(lag.batch, 500.0) != lag.apparent
    assert moved.batch is lag.batch and moved.free == lag.free
    assert lag.shift_constant("AD", 0.001) is None   # free, not fixed
    assert lag.shift_constant("At", 1.0) is None     # not a parameter of this problem


def test_a_shifted_campaigns_problem_keeps_the_fitted_problems_coordinates(small_campaign):
    """The Type B step compiles the fitted problem's potential once and evaluates the shifted
    campaigns' problems with it (``shift.SharedData``): ``problem_like`` must build them in the
    same coordinates, a softplus widened at its bound (``nuts.soften_bounds``) included, or
    every shifted campaign is "another structure" and fitted on its own."""
    import numpy as np

    from bayes_roadload.inference.bayes import build_problem, problem_like
    from bayes_roadload.inference.nuts import find_map, initial_values
    from bayes_roadload.inference.shift import potential_program

    problem = build_problem(small_campaign, "four_term")
    problem = dataclasses.replace(problem, priors={**problem.priors,
                                                   "KD": dataclasses.replace(problem.priors["KD"], softness=0.3)})
    heavier = dataclasses.replace(small_campaign, vehicle=dataclasses.replace(
        small_campaign.vehicle, mass_kg=small_campaign.vehicle.mass_kg + 10.0))
    shifted = problem_like(problem, heavier)
    assert shifted.priors == problem.priors
    m = find_map(problem, initial_values(problem, small_campaign))
    program = potential_program(problem, m.z)
    assert program.data_of(shifted) is not None
    assert program.data_of(build_problem(heavier, "four_term")) is None   # the default coordinates differ
    assert np.isfinite(program.fg(program.data_of(shifted), np.zeros(program.scale.size))[0])


def test_the_truth_keeps_the_simulators_constants_not_the_analysis_assumptions(small_campaign):
    """A model that holds a constant at an assumed value (C_R = 1e-6 s^2/m^2 in
    ``four_term_tyre_lag_j2452_mean``) is scored against the simulator's road load, whose truth
    states C_R = 0: the truth's F0, F1, F2 are those of the model without the term, not the
    assumption's (which would move F2 by C_R M g / 3.6^2)."""
    from bayes_roadload.inference.bayes import build_problem

    assert small_campaign.truth["tyre_quadratic_s2_per_m2"] == 0.0
    plain = build_problem(small_campaign, "four_term_tyre_lag").truth_values(small_campaign.truth)
    mean = build_problem(small_campaign, "four_term_tyre_lag_j2452_mean")
    assert mean.fixed["tyre_quadratic_s2_per_m2"] == 1e-6
    scored = mean.truth_values(small_campaign.truth)
    for q in ("F0_N", "F1_N_per_kph", "F2_N_per_kph2", "F50_N"):
        assert scored[q] == pytest.approx(plain[q], rel=1e-9), q
    assumed = dict(small_campaign.truth, tyre_quadratic_s2_per_m2=1e-6)
    shift = mean.truth_values(assumed)["F2_N_per_kph2"] - scored["F2_N_per_kph2"]
    from bayes_roadload.config import GRAVITY_MPS2
    assert shift == pytest.approx(1e-6 * mean.mass_kg * GRAVITY_MPS2 / 3.6**2, rel=1e-6)


def test_the_laplace_share_beyond_a_support_of_the_apparent_coefficients(small_campaign):
    """``beyond_support`` maps Laplace draws of the apparent sites and the lag gain to A_D, B_D,
    C_D0 (``coefficients_from_apparent``) and counts those outside the priors' supports: none
    with C_D0' far above kappa B_D G_T, about half when C_D0' equals it (the derived C_D0 then
    straddles its bound at 0, with a spread small enough for the map to be linear), and 0 for
    the same traces sampled directly."""
    from numpyro.distributions.transforms import biject_to

    from bayes_roadload.inference.bayes import APPARENT_SITES, LAG_GAIN, build_problem

    lag = build_problem(small_campaign, "four_term_tyre_lag")
    c, b, kappa = lag.apparent
    bd, gain = 2e-4, 0.005

    def z_of(cd0_apparent):
        values = {"AD_apparent": 0.01, "BD_apparent": bd, "CD0_apparent": cd0_apparent, LAG_GAIN: gain}
        support = {s: lag.priors[n].to_numpyro().support for n, s in APPARENT_SITES.items()}
        support[LAG_GAIN] = lag.priors[LAG_GAIN].to_numpyro().support
        return {s: float(biject_to(support[s]).inv(jnp.asarray(v))) for s, v in values.items()}

    sites = sorted([*APPARENT_SITES.values(), LAG_GAIN])
    cov = np.diag([1e-16 if s != "CD0_apparent" else 1e-10 for s in sites])   # ravel order: sorted
    assert lag.beyond_support(z_of(0.35), cov) == 0.0
    s = 1.0 - gain * c
    at_bound = kappa * ((bd - 0.01 / s * gain * b) / s) * gain   # C_D0' at which the derived C_D0 is 0
    assert 0.45 <= lag.beyond_support(z_of(at_bound), cov) <= 0.55
    direct, _, _ = lag.alternative_coordinates({})
    assert direct.beyond_support(z_of(at_bound), cov) == 0.0


def test_the_first_attempts_coordinates_follow_the_wall_share_or_the_samplers_choice(small_campaign, monkeypatch):
    """``start_coordinates``: the problem's own coordinates below the wall share, its alternative
    ones at or above it (with the share said) or whenever the sampler asks for them
    (``coordinates = "alternative"``); a problem without alternative coordinates keeps its own
    either way."""
    from types import SimpleNamespace

    from bayes_roadload import config
    from bayes_roadload.inference.bayes import build_problem, with_apparent
    from bayes_roadload.inference.nuts import start_coordinates

    lag = build_problem(small_campaign, "four_term_tyre_lag")
    values = with_apparent(lag, {"AD": 0.01, "BD": 2e-4, "CD0": 0.35, "tyre_lag_gain_per_mps": 0.005, "KD": 0.5})
    at_map = SimpleNamespace(constrained=values, z={}, cov=np.zeros((0, 0)))
    share = {"value": 0.0}
    monkeypatch.setattr(FitProblem, "beyond_support", lambda self, z, cov: share["value"])
    auto, alternative = config.DEFAULT_SAMPLER, dataclasses.replace(config.DEFAULT_SAMPLER, coordinates="alternative")
    assert start_coordinates(lag, at_map, auto) == (None, "")
    share["value"] = config.MAX_BEYOND_SUPPORT_SHARE
    other, why = start_coordinates(lag, at_map, auto)
    assert other[0].apparent is None and "beyond a support" in why and why.startswith("0.1 %")
    share["value"] = 0.0
    other, why = start_coordinates(lag, at_map, alternative)
    assert other[0].apparent is None and "directly" in other[2] and "alternative" in why
    plain = build_problem(small_campaign, "four_term")
    assert start_coordinates(plain, SimpleNamespace(constrained={}, z={}, cov=None), alternative) == (None, "")
    with pytest.raises(ValueError, match="coordinates"):
        dataclasses.replace(config.DEFAULT_SAMPLER, coordinates="direct")
    with pytest.raises(ValueError, match="precondition"):  # they start from the Laplace MAP
        dataclasses.replace(config.DEFAULT_SAMPLER, coordinates="alternative", precondition="none")
