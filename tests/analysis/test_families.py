"""Candidate families: a shape parameter profiled over its prior grid (effects.fit_shapes) on a
campaign of the project's simulator whose shape is known (the tyre candidate made a family here:
the shipped library has none)."""

import dataclasses
import math
import warnings

import numpy as np
import pytest

from bayes_roadload.analysis import effects as fx
from bayes_roadload.analysis.batch import SimulatedCampaign
from bayes_roadload.inference.bayes import build_problem
from bayes_roadload.inference.nuts import find_map, prepare_problem
from bayes_roadload.physics import effects as pe
from bayes_roadload.simulate.campaign import SimulationSettings
from bayes_roadload.simulate.cases import get_case

TRUE_TAU_S = 160.0


@pytest.fixture(scope="module")
def tyre_transient_linearisation():
    """Thesis case 7 (no measurement noise), 1 pair, with a tyre transient of 20 % decaying
    over 160 s that three_term withholds: the model's linearisation and the shaped one."""
    settings = dataclasses.replace(SimulationSettings(), extra_terms=(pe.TyreTemperatureTransient(),),
                                   extra_params={"tyre_transient": 0.2, "tyre_time_constant_s": TRUE_TAU_S})
    campaign = SimulatedCampaign(get_case(7), pairs=1, seed=1, settings=settings)()
    lib = fx.load_library()
    # the tyre candidate as a family over its time constant (the shipped library has none)
    lib["tyre_temperature"] = dataclasses.replace(lib["tyre_temperature"], shape={
        "tyre_time_constant_s": fx.shape_grid("test", "tyre_time_constant_s", {"low": 20.0, "high": 1280.0, "points": 7})})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        problem, init = prepare_problem(build_problem(campaign, "three_term"), campaign)
        fit = find_map(problem, init)
    lin = fx.linearise(problem, fit.constrained, lib)
    shaped, shapes = fx.fit_shapes(lin, lib)
    return lib, lin, shaped, shapes


def test_the_profiled_time_constant_is_within_one_grid_step_of_the_truth(tyre_transient_linearisation):
    """The grid doubles tau from point to point; the gains are those of a Gauss-Newton step at
    the model's fit, where A_D and B_D have absorbed part of a slow transient, so the profile
    is resolved to a grid step, not to the point."""
    lib, lin, shaped, shapes = tyre_transient_linearisation
    grid = lib["tyre_temperature"].shape["tyre_time_constant_s"]
    fam = shapes["tyre_temperature"]
    best = fam["values"]["tyre_time_constant_s"]
    assert abs(math.log2(best / TRUE_TAU_S)) <= 1.0 + 1e-9
    gains = [p["loglik_gain"] for p in fam["profile"]]
    assert [p["tyre_time_constant_s"] for p in fam["profile"]] == list(grid)
    assert gains[grid.index(best)] == max(gains)
    # the default shape (40 s) explains less than the profiled one
    assert gains[grid.index(best)] > gains[grid.index(40.0)]
    # the shaped linearisation sits at the chosen shape and scores it as the profile did
    j = shaped.columns.index("tyre_time_constant_s")
    assert np.all(shaped.x[:, j] == best) and shaped.values["tyre_time_constant_s"] == best
    sol = fx.fit_effects(shaped, ("tyre_temperature",), lib)
    base = fx.fit_effects(shaped, (), lib)
    assert sol.loglik_gain - base.loglik_gain == pytest.approx(max(gains), rel=1e-6)


def test_a_shape_leaves_every_other_candidate_unchanged(tyre_transient_linearisation):
    """At the null a shape moves no speed: the signatures of the other candidates and of the
    model's coefficients are the same before and after profiling."""
    lib, lin, shaped, _ = tyre_transient_linearisation
    keep = [j for j, c in enumerate(lin.columns) if c not in ("tyre_transient", "tyre_power_coeff")]
    assert np.allclose(shaped.residual, lin.residual)
    assert np.allclose(shaped.gram[np.ix_(range(lin.n_runs), keep, keep)], lin.gram[np.ix_(range(lin.n_runs), keep, keep)],
                       rtol=1e-9, atol=1e-12)
    for name in ("track_gradient", "run_to_run_variation", "spatial_wind"):
        assert fx.fit_effects(shaped, (name,), lib).loglik_gain == pytest.approx(
            fx.fit_effects(lin, (name,), lib).loglik_gain, rel=1e-9)
