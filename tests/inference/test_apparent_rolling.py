"""The tyre-lag model's apparent rolling coefficients (:func:`~bayes_roadload.inference.bayes.
apparent_coefficients`): an exact change of the sampled coordinates, not of the posterior."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpyro.infer.util import log_density

from bayes_roadload.inference.bayes import (
    APPARENT_SITES,
    LAG_GAIN,
    apparent_coefficients,
    build_problem,
    coastdown_model,
    lag_line,
    rolling_from_apparent,
    with_apparent,
)
from bayes_roadload.inference.nuts import _site_scales, initial_values
from bayes_roadload.physics import make_run, stack_runs

LAG_MODEL = "four_term_tyre_lag"


def test_the_map_and_its_inverse_and_jacobian():
    """AD', BD' from AD, BD and back; the log-determinant against JAX's Jacobian."""
    line = (27.0, 0.8)
    AD, BD, gain = 0.011, 1.7e-4, 0.004
    ad, bd = apparent_coefficients(AD, BD, gain, line)
    back = rolling_from_apparent(ad, bd, gain, line)
    assert float(back[0]) == pytest.approx(AD, rel=1e-13)
    assert float(back[1]) == pytest.approx(BD, rel=1e-12)
    jac = jax.jacfwd(lambda x: jnp.stack(apparent_coefficients(x[0], x[1], gain, line)))(jnp.array([AD, BD]))
    assert float(back[2]) == pytest.approx(np.log(abs(np.linalg.det(np.asarray(jac)))), rel=1e-12)
    # the rolling loss at speeds on the line L = c - b v is AD' + BD' v + BD G b v^2
    v = np.linspace(5.0, 30.0, 7)
    lag = line[0] - line[1] * v
    np.testing.assert_allclose((AD + BD * v) * (1 - gain * lag), ad + bd * v + BD * gain * line[1] * v**2, rtol=1e-12)


def test_the_line_of_a_steady_deceleration_without_cooling():
    """Runs from 30 m/s with an infinite time constant: L = 30 - v exactly, so c = 30, b = 1,
    whatever each run's deceleration and length (the padding of the shorter is left out)."""
    t = np.arange(0.0, 150.0, 0.5)
    vehicle = {"mass_kg": 1500.0, "effective_mass_kg": 1540.0, "frontal_area_m2": 2.2}
    batch = stack_runs([make_run(t, 30.0 - 0.1 * t, **vehicle), make_run(t[:200], 30.0 - 0.05 * t[:200], **vehicle)])
    c, b = lag_line(batch, 1e12)
    assert c == pytest.approx(30.0, rel=1e-6) and b == pytest.approx(1.0, rel=1e-6)
    # a finite time constant follows part of the drop: less is left, the line is flatter
    assert 0.0 < lag_line(batch, 300.0)[1] < 1.0


def test_the_lag_model_samples_the_apparent_coefficients(small_campaign):
    """The sites are AD_apparent, BD_apparent; the log density differs from the one in A_D, B_D
    by -log s^2 (the change of variables), A_D and B_D are deterministic sites; the start
    holds the apparent values of the start's A_D, B_D, and they are scaled as A_D, B_D are."""
    prob = build_problem(small_campaign, LAG_MODEL)
    assert prob.apparent is not None
    init = initial_values(prob, small_campaign)
    assert set(APPARENT_SITES.values()) <= set(init)
    ad, bd = apparent_coefficients(init["AD"], init["BD"], init[LAG_GAIN], prob.apparent)
    assert init["AD_apparent"] == pytest.approx(ad) and init["BD_apparent"] == pytest.approx(bd)
    plain = dataclasses.replace(prob, apparent=None)
    values = {k: jnp.asarray(v) for k, v in init.items()}
    new, trace = log_density(coastdown_model, (prob,), {}, values)
    old, _ = log_density(coastdown_model, (plain,), {}, {k: v for k, v in values.items()
                                                          if k not in APPARENT_SITES.values()})
    s = 1.0 - init[LAG_GAIN] * prob.apparent[0]
    assert float(new - old) == pytest.approx(-2.0 * np.log(s), rel=1e-9, abs=1e-9)
    assert trace["AD"]["type"] == "deterministic" and trace["AD_apparent"]["type"] == "sample"
    assert float(trace["BD"]["value"]) == pytest.approx(init["BD"], rel=1e-10)
    scales = _site_scales(prob, {k: values[k] for k in ("AD_apparent", "BD_apparent", "BD")})
    assert float(scales["BD_apparent"]) == float(scales["BD"]) != 1.0


def test_models_without_the_lag_keep_their_sites(small_campaign):
    prob = build_problem(small_campaign, "four_term")
    assert prob.apparent is None
    init = initial_values(prob, small_campaign)
    assert not set(APPARENT_SITES.values()) & set(init)
    assert with_apparent(prob, init) is init
