"""With BAYES_ROADLOAD_SHARE_PROGRAMS=1, campaigns of the same shapes lower to the same compiled
programs (bayes_roadload._jax, physics.integrate.bucket_length): the data are arguments of the
programs, not constants."""

import warnings

import jax
import numpy as np
import pytest

from bayes_roadload import config
from bayes_roadload.inference.bayes import build_problem
from bayes_roadload.inference.nuts import initial_values, unconstrained_posterior
from bayes_roadload.physics.integrate import bucket_length
from bayes_roadload.simulate import simulate_campaign

from ..conftest import clean_case


@pytest.mark.parametrize("per_octave", [4, 8, 16])
def test_bucket_length_is_the_next_size_of_the_octave_and_pads_less_than_its_share(per_octave):
    for n in range(1, 5000):
        b = bucket_length(n, per_octave)
        assert b >= n
        assert b == n or (b - n) * per_octave < n  # less than 1/per_octave of padding
        if n > per_octave:  # m * 2**k with per_octave <= m < 2 per_octave
            k = (b // per_octave).bit_length() - 1
            assert b % 2**k == 0 and per_octave <= b // 2**k < 2 * per_octave
        assert bucket_length(b, per_octave) == b  # a bucket's own length is kept
    assert bucket_length(493, 0) == 493


def _potential(campaign):
    """The potential at the prior centres (``start={}``: no least-squares start, which these
    tests do not need)."""
    problem = build_problem(campaign, "four_term")
    return unconstrained_posterior(problem, initial_values(problem, campaign, start={}))


SAME_PROGRAM = """
import warnings
warnings.simplefilter("ignore")
from bayes_roadload import config  # before JAX: it sets JAX's options
import jax
from bayes_roadload.inference.bayes import build_problem
from bayes_roadload.inference.nuts import initial_values, unconstrained_posterior
from bayes_roadload.simulate import simulate_campaign
from tests.conftest import clean_case

texts, values = [], []
for seed in (1, 2):
    c = simulate_campaign(clean_case(), pairs=1, seed=seed)
    problem = build_problem(c, "four_term")
    post = unconstrained_posterior(problem, initial_values(problem, c, start={}))
    lowered = jax.jit(post.potential_fn).lower(post.z0)
    texts.append(lowered.as_text(debug_info=False))
    values.append(float(lowered.compile()(post.z0)))
print(config.PAD_SIZES_PER_OCTAVE, texts[0] == texts[1], values[0] != values[1])
"""


@pytest.mark.parametrize("share", ["1", pytest.param("", marks=pytest.mark.slow)])  # "": the default's own program texts, ~12 s
def test_two_campaigns_of_one_bucket_lower_to_one_program_when_sharing(share):
    """Seeds 1 and 2 (longest runs 493 and 498 samples): with BAYES_ROADLOAD_SHARE_PROGRAMS=1
    their potentials lower to the same program text (data as arguments, both padded to 512);
    by default they do not (the data are constants of the program)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_")}
    env["BAYES_ROADLOAD_SHARE_PROGRAMS"] = share
    root = Path(__file__).resolve().parents[2]
    env["PYTHONPATH"] = os.pathsep.join([str(root), env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-c", SAME_PROGRAM], env=env, capture_output=True, text=True, timeout=600,
                         cwd=root)
    assert out.returncode == 0, out.stderr[-2000:]
    pad, same, different_data = out.stdout.split()
    assert different_data == "True"
    assert (pad, same) == ((str(config.SHARED_PAD_SIZES_PER_OCTAVE), "True") if share else ("0", "False"))


@pytest.fixture(scope="module")
def campaigns():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return {s: simulate_campaign(clean_case(), pairs=1, seed=s) for s in (1, 2)}


def test_the_two_seeds_fall_in_one_bucket(campaigns):
    lengths = {s: c.runs.groupby("run").size().max() for s, c in campaigns.items()}
    assert lengths[1] != lengths[2]
    assert len({bucket_length(n, config.SHARED_PAD_SIZES_PER_OCTAVE) for n in lengths.values()}) == 1


def test_padding_to_a_longer_length_leaves_the_density_unchanged(campaigns):
    camp = campaigns[1]
    post = _potential(camp)
    longer = type(camp)(camp.runs, camp.vehicle, camp.anemometer, camp.tunnel, camp.truth,
                        dict(camp.meta, pad_to_samples=1024))
    assert longer.to_batch()[0].time_s.shape[-1] == 1024 != post.problem.batch.time_s.shape[-1]
    padded = _potential(longer)
    z = post.z0
    assert np.isclose(float(jax.jit(padded.potential_fn)(z)), float(jax.jit(post.potential_fn)(z)), rtol=1e-12, atol=0)


def _data_sum(p):
    """A function of every data leaf of a problem (``shift._data_leaves``)."""
    import jax.numpy as jnp

    from bayes_roadload.inference.shift import _data_leaves

    leaves: list = []
    _data_leaves(p, leaves)
    return sum(jnp.sum(jnp.asarray(x, float)) for x in leaves)


def test_problems_of_one_structure_share_one_compiled_program_and_each_keeps_its_own_data(small_campaign):
    """A study's refits and a fleet's same-shaped campaigns build a new problem each; their
    potential (``shift.potential_program``) and other shared functions (``SharedData.compile``)
    are compiled once per process for a structure, the data going in as arguments.  The shared
    program must give each problem its own potential -- the value of a program compiled for that
    problem alone, to rounding -- not the first problem's; a problem of another structure gets a
    program of its own."""
    import dataclasses

    from bayes_roadload.inference.shift import PotentialProgram, SharedData, _compiled, potential_program

    problem = build_problem(small_campaign, "four_term")
    heavier = dataclasses.replace(small_campaign, vehicle=dataclasses.replace(
        small_campaign.vehicle, mass_kg=small_campaign.vehicle.mass_kg + 10.0))
    other = build_problem(heavier, "four_term")
    post = unconstrained_posterior(problem, initial_values(problem, small_campaign, start={}))
    program = potential_program(problem, post.z0)
    assert program.accepts(other)                       # the same structure, other data
    y = post.flat0 / program.scale
    program.fg(program.data_of(other), y)
    compiled = program.fg_compiled._cache_size()
    assert potential_program(other, post.z0) is program
    u_shared, g_shared = (np.asarray(a) for a in program.fg(program.data_of(other), y))
    own = PotentialProgram(other, post.z0)
    u_own, g_own = (np.asarray(a) for a in own.fg(own.data_of(other), y))
    np.testing.assert_allclose(u_shared, u_own, rtol=1e-12)
    np.testing.assert_allclose(g_shared, g_own, rtol=1e-9, atol=1e-9 * np.max(np.abs(g_own)))
    assert not np.isclose(u_shared, float(program.fg(program.data_of(problem), y)[0]), rtol=1e-9)
    assert program.fg_compiled._cache_size() == compiled   # no new compilation for `other`

    jitted = _compiled(SharedData(problem), _data_sum)
    assert _compiled(SharedData(other), _data_sum) is jitted
    call = SharedData(problem).compile(_data_sum)
    assert float(call(other)) == pytest.approx(float(_data_sum(other)), rel=1e-12)
    assert float(call(other)) != pytest.approx(float(_data_sum(problem)), rel=1e-9)

    three = build_problem(small_campaign, "three_term")
    post3 = unconstrained_posterior(three, initial_values(three, small_campaign, start={}))
    assert not program.accepts(three)
    assert potential_program(three, post3.z0) is not program
