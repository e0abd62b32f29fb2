"""The tyre-lag model's apparent coefficients (:func:`~bayes_roadload.inference.bayes.
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
    coefficients_from_apparent,
    with_apparent,
)
from bayes_roadload.inference.nuts import _site_scales, initial_values
from bayes_roadload.physics import make_run, stack_runs

LAG_MODEL = "four_term_tyre_lag"


def test_the_map_and_its_inverse_and_jacobian():
    """AD', BD', CD0' from AD, BD, CD0 and back; the log-determinant against JAX's Jacobian;
    the rolling loss on the line is AD' + BD' v plus a v^2 term that CD0' carries."""
    line = (27.0, 0.8, 9000.0)
    AD, BD, CD0, gain = 0.011, 1.7e-4, 0.35, 0.004
    apparent = apparent_coefficients(AD, BD, CD0, gain, line)
    back = coefficients_from_apparent(*apparent, gain, line)
    for x, y in zip(back[:3], (AD, BD, CD0)):
        assert float(x) == pytest.approx(y, rel=1e-12)
    jac = jax.jacfwd(lambda x: jnp.stack(apparent_coefficients(x[0], x[1], x[2], gain, line)))(jnp.array([AD, BD, CD0]))
    assert float(back[3]) == pytest.approx(np.log(abs(np.linalg.det(np.asarray(jac)))), rel=1e-12)
    v = np.linspace(5.0, 30.0, 7)
    lag = line[0] - line[1] * v
    np.testing.assert_allclose((AD + BD * v) * (1 - gain * lag),
                               apparent[0] + apparent[1] * v + BD * gain * line[1] * v**2, rtol=1e-12)
    # CD0' - CD0 is that v^2 term as a drag coefficient: kappa B_D G_T
    assert apparent[2] - CD0 == pytest.approx(line[2] * BD * gain, rel=1e-12)


def test_the_line_of_a_steady_deceleration_without_cooling():
    """Runs from 30 m/s with an infinite time constant: L = 30 - v exactly, so c = 30, b = 1,
    whatever each run's deceleration and length (the padding of the shorter is left out)."""
    t = np.arange(0.0, 150.0, 0.5)
    vehicle = {"mass_kg": 1500.0, "effective_mass_kg": 1540.0, "frontal_area_m2": 2.2}
    batch = stack_runs([make_run(t, 30.0 - 0.1 * t, **vehicle), make_run(t[:200], 30.0 - 0.05 * t[:200], **vehicle)])
    c, b, kappa = lag_line(batch, 1e12)
    assert c == pytest.approx(30.0, rel=1e-6) and b == pytest.approx(1.0, rel=1e-6)
    # kappa = b M g / (rho A / 2): the drag coefficient of a v^2 force per unit weight
    rho = float(np.mean(np.asarray(batch.air_density_kgpm3)[np.asarray(batch.mask)]))
    assert kappa == pytest.approx(b * 1500.0 * 9.81 / (0.5 * rho * 2.2), rel=1e-9)
    # a finite time constant follows part of the drop: less is left, the line is flatter
    assert 0.0 < lag_line(batch, 300.0)[1] < 1.0


def test_the_lag_model_samples_the_apparent_coefficients(small_campaign):
    """The sites are AD_apparent, BD_apparent, CD0_apparent; the log density differs from the
    one in A_D, B_D, C_D0 by -log s^2 (the change of variables), the coefficients are
    deterministic sites; the start holds the apparent values of the start's coefficients, and
    they are scaled as the coefficients are."""
    prob = build_problem(small_campaign, LAG_MODEL)
    assert prob.apparent is not None
    init = initial_values(prob, small_campaign)
    assert set(APPARENT_SITES.values()) <= set(init)
    expected = apparent_coefficients(init["AD"], init["BD"], init["CD0"], init[LAG_GAIN], prob.apparent)
    for site, value in zip(APPARENT_SITES.values(), expected):
        assert init[site] == pytest.approx(value, rel=1e-12)
    plain = dataclasses.replace(prob, apparent=None)
    values = {k: jnp.asarray(v) for k, v in init.items()}
    new, trace = log_density(coastdown_model, (prob,), {}, values)
    old, _ = log_density(coastdown_model, (plain,), {}, {k: v for k, v in values.items()
                                                          if k not in APPARENT_SITES.values()})
    s = 1.0 - init[LAG_GAIN] * prob.apparent[0]
    assert float(new - old) == pytest.approx(-2.0 * np.log(s), rel=1e-9, abs=1e-9)
    for name, site in APPARENT_SITES.items():
        assert trace[name]["type"] == "deterministic" and trace[site]["type"] == "sample"
        assert float(trace[name]["value"]) == pytest.approx(init[name], rel=1e-10)
    scales = _site_scales(prob, {k: values[k] for k in ("AD_apparent", "BD_apparent", "BD")})
    assert float(scales["BD_apparent"]) == float(scales["BD"]) != 1.0


def test_models_without_the_lag_keep_their_sites(small_campaign):
    prob = build_problem(small_campaign, "four_term")
    assert prob.apparent is None
    init = initial_values(prob, small_campaign)
    assert not set(APPARENT_SITES.values()) & set(init)
    assert with_apparent(prob, init) is init
