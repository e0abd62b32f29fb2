"""Candidate families: a shape parameter profiled over its prior grid (effects.fit_shapes) on a
campaign of the project's simulator whose shape is known (the tyre candidate made a family here:
the shipped library has none)."""

import dataclasses
import math
import warnings
from types import SimpleNamespace

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
TAU_GRID = {"low": 20.0, "high": 1280.0, "points": 7}


def family_library():
    """The shipped library with the tyre candidate a family over its time constant."""
    lib = fx.load_library()
    lib["tyre_temperature"] = dataclasses.replace(lib["tyre_temperature"], shape={
        "tyre_time_constant_s": fx.shape_grid("test", "tyre_time_constant_s", TAU_GRID)})
    return lib


def linear_transient(amplitude: float, runs: int = 2, n: int = 200, sigma: float = 0.01):
    """A linearisation of an analytic speed model, v = v0 + s t + a (tau / 100 s) (1 - exp(-t / tau)),
    at a = 0 (columns: the slope s as the model's coefficient ``AD``, the amplitude as the tyre
    candidate's ``tyre_transient``, tau as its shape, v0), its data noise-free with amplitude
    ``amplitude`` and tau = TRUE_TAU_S."""
    t = np.tile(np.arange(n, dtype=float), (runs, 1))
    cols = ("AD", "tyre_transient", "tyre_time_constant_s", "v0_mps")

    def speed(x):
        s, a, tau, v0 = (np.asarray(x)[:, i][:, None] for i in range(4))
        shape = (tau / 100.0) * (1.0 - np.exp(-t / tau))
        y = v0 + s * t + a * shape
        dshape = (1.0 - np.exp(-t / tau)) / 100.0 - (tau / 100.0) * np.exp(-t / tau) * t / tau**2
        jac = np.stack([t, np.broadcast_to(shape, t.shape), a * dshape, np.ones_like(t)], axis=-1)
        return y, jac

    truth = np.column_stack([np.full(runs, -0.1), np.full(runs, amplitude), np.full(runs, TRUE_TAU_S), np.full(runs, 30.0)])
    batch = SimpleNamespace(time_s=t, mask=np.ones_like(t, bool), speed_mps=speed(truth)[0])
    lin = fx.Linearisation(columns=cols, base=("AD",), effects={"tyre_temperature": ("tyre_transient",)},
                           available={"tyre_temperature": None}, values={"AD": -0.1, "tyre_transient": 0.0,
                                                                         "tyre_time_constant_s": 40.0},
                           jacobian=np.zeros(0), residual=np.zeros(0), gram=np.zeros(0), score=np.zeros(0),
                           loglik=np.zeros(0), sigma_mps=np.full(runs, sigma), q=0.0, model=None, batch=batch,
                           run_ids=tuple(range(runs)), speed_fn=speed)
    x0 = truth.copy()
    x0[:, 1], x0[:, 2] = 0.0, 40.0
    return fx.relinearise(lin, x0)


def test_the_profile_finds_the_shape_of_a_noise_free_transient_and_keeps_the_fixed_one_without():
    """On an analytic model the grid point of the true time constant gains the most (the gain
    falls off on both sides of it), the shaped linearisation sits there; without a transient
    nothing gains and the family keeps its fixed shape."""
    lib = family_library()
    shaped, shapes = fx.fit_shapes(linear_transient(0.5), lib)
    fam = shapes["tyre_temperature"]
    gains = {p["tyre_time_constant_s"]: p["loglik_gain"] for p in fam["profile"]}
    assert fam["values"] == {"tyre_time_constant_s": TRUE_TAU_S}
    assert gains[80.0] < gains[TRUE_TAU_S] > gains[320.0] and gains[TRUE_TAU_S] > 100.0
    assert np.all(shaped.x[:, 2] == TRUE_TAU_S) and shaped.values["tyre_time_constant_s"] == TRUE_TAU_S
    flat = linear_transient(0.0)
    same, none = fx.fit_shapes(flat, lib)
    assert same is flat  # nothing moved: the input linearisation, not a new evaluation of it
    assert none["tyre_temperature"]["values"] == {"tyre_time_constant_s": 40.0}
    assert max(p["loglik_gain"] for p in none["tyre_temperature"]["profile"]) < 1e-6


@pytest.fixture(scope="module")
def tyre_transient_linearisation():
    """Thesis case 7 (no measurement noise), 1 pair, with a tyre transient of 20 % decaying
    over 160 s that three_term withholds: the model's linearisation and the shaped one."""
    settings = dataclasses.replace(SimulationSettings(), extra_terms=(pe.TyreTemperatureTransient(),),
                                   extra_params={"tyre_transient": 0.2, "tyre_time_constant_s": TRUE_TAU_S})
    campaign = SimulatedCampaign(get_case(7), pairs=1, seed=1, settings=settings)()
    lib = family_library()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        problem, init = prepare_problem(build_problem(campaign, "three_term"), campaign)
        fit = find_map(problem, init)
    lin = fx.linearise(problem, fit.constrained, lib)
    shaped, shapes = fx.fit_shapes(lin, lib)
    return lib, lin, shaped, shapes


@pytest.mark.slow   # a MAP fit of a simulated campaign (~25 s); the analytic test above is the fast one
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


@pytest.mark.slow
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
