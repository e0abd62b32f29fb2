"""Moist-air density (:mod:`bayes_roadload.physics.atmosphere`): the dry limit, the saturation
vapour pressure against the IAPWS steam tables, and the density against a second, separately
written moist-air formula (the independent simulator's, Magnus over water)."""

import jax.numpy as jnp
import numpy as np
import pytest

from bayes_roadload import config
from bayes_roadload.physics.atmosphere import air_density_kgpm3, saturation_vapour_pressure_pa


def test_dry_limit_is_the_ideal_gas_of_dry_air():
    p, t = 98_500.0, 288.0
    dry = p / (config.GAS_CONSTANT_AIR_J_PER_KG_K * t)
    assert air_density_kgpm3(p, t) == pytest.approx(dry, rel=1e-15)
    assert air_density_kgpm3(p, t, 0.0) == pytest.approx(dry, rel=1e-15)


@pytest.mark.parametrize("t_c, p_sv_pa", [(0.01, 611.657), (10.0, 1228.1), (20.0, 2339.3), (30.0, 4246.9)])
def test_saturation_vapour_pressure_matches_the_steam_tables(t_c, p_sv_pa):
    # IAPWS-95 saturation pressures (Wagner & Pruss 2002), to the digits given.  A 0.1 % error
    # in p_sv moves the density by under 2e-5 of itself (x_v <= 4 %, times 0.378), far below
    # the 1e-3 the coefficients are read to, so 0.1 % is a strict bound.
    assert saturation_vapour_pressure_pa(273.15 + t_c) == pytest.approx(p_sv_pa, rel=1e-3)


def test_moist_air_is_lighter_by_the_vapour_that_replaces_it():
    rho = np.array([air_density_kgpm3(100_000.0, 293.15, h) for h in (0.0, 0.25, 0.5, 0.75, 1.0)])
    assert np.all(np.diff(rho) < 0)
    drop = 1.0 - rho / rho[0]
    np.testing.assert_allclose(drop, drop[-1] * np.linspace(0, 1, 5), rtol=1e-12)  # linear in h
    # saturated at 20 C: x_v = f p_sv / p = 1.0040 x 2339 / 1e5; the drop is 0.378 x_v
    assert drop[-1] == pytest.approx(0.37804 * 1.0040 * 2339.3 / 100_000.0, rel=1e-3)


@pytest.mark.parametrize("t_k", [278.15, 293.15, 308.15])
@pytest.mark.parametrize("h", [0.3, 0.6, 0.95])
def test_density_agrees_with_an_independently_written_formula(t_k, h):
    """The independent simulator writes its own moist air (Magnus' vapour pressure, R_v for the
    vapour, R_d 287.058).  Magnus is within 0.4 % of IAPWS over 5-35 C (Alduchov and Eskridge
    1996) and omits the enhancement factor (~0.4 % of x_v); R_d differs by 3e-5.  With x_v at
    most 5.4 % (35 C, 95 %) and 0.378 of it in the density, the two agree to
    3e-5 + 0.378 x 0.054 x 0.008 = 2e-4."""
    from bayes_roadload.simulate.independent.dynamics import moist_air_density

    p = 98_000.0
    ours = air_density_kgpm3(p, t_k, h)
    theirs = float(moist_air_density(p, t_k, h))
    assert ours == pytest.approx(theirs, rel=2e-4)
    # and the humidity's own effect, 0.1-2 % here, is resolved: the formulas agree on it to 3 %
    dry = air_density_kgpm3(p, t_k)
    assert abs(ours - theirs) < 0.03 * abs(ours - dry)


def test_jax_in_gives_jax_out():
    rho = air_density_kgpm3(jnp.asarray([1.0e5, 0.99e5]), 293.2, 0.5)
    assert rho.shape == (2,) and isinstance(rho, type(jnp.asarray(0.0)))
    assert float(rho[0]) == pytest.approx(air_density_kgpm3(1.0e5, 293.2, 0.5), rel=1e-14)
