"""Road load at reference conditions: parts at 50 mph and the F0/F1/F2 regression."""

import pytest

from bayes_roadload import config
from bayes_roadload.physics import air_density_kgpm3, simplified_model
from bayes_roadload.physics.roadload import road_load_summary

P = {"AD": 0.0095, "BD": 0.214e-3, "CD0": 0.393, "At": 21.0, "Bt": 2.09, "Ct": -0.02, "Au": 3.24, "Bu": 0.232}


def test_quadratic_model_gives_exact_coefficients():
    m = simplified_model(driveline="polynomial", undriven=True)
    s = road_load_summary(m, P, 1125.0, 1.85)
    mg, rho, kph = 1125.0 * config.GRAVITY_MPS2, float(air_density_kgpm3()), config.KPH_TO_MPS
    assert float(s["F0_N"]) == pytest.approx(mg * 0.0095 + 21.0 + 3.24, rel=1e-9)
    assert float(s["F1_N_per_kph"]) == pytest.approx((mg * 0.214e-3 + 2.09 + 0.232) * kph, rel=1e-9)
    assert float(s["F2_N_per_kph2"]) == pytest.approx((0.5 * rho * 1.85 * 0.393 - 0.02) * kph**2, rel=1e-9)
    v = config.SPEED_50MPH_MPS
    assert float(s["F50_aero_N"]) == pytest.approx(0.5 * rho * v**2 * 1.85 * 0.393, rel=1e-12)
    parts = sum(float(s[f"F50_{p}_N"]) for p in ("tyre", "aero", "driveline", "undriven"))
    assert float(s["F50_N"]) == pytest.approx(parts)


def test_thesis_breakdown_at_50mph_is_of_the_published_order():
    """Thesis section 5 of the reference: 436 N at 50 mph, tyres 35 %, aero 49 %, driveline
    13 %, undriven 2 %.  The coefficients of table 8.3 / 8.12 / 7.10 give the same within a
    few percent (the thesis quotes its own rounding and test-day density)."""
    m = simplified_model(driveline="polynomial", undriven=True)
    s = road_load_summary(m, P, 1125.0, 1.85)
    total = float(s["F50_N"])
    assert total == pytest.approx(436.0, rel=0.05)
    assert float(s["F50_aero_N"]) / total == pytest.approx(0.494, abs=0.03)
    assert float(s["F50_tyre_N"]) / total == pytest.approx(0.354, abs=0.03)


def test_measured_driveline_uses_the_callable():
    m = simplified_model(driveline="measured")
    s = road_load_summary(m, P, 1125.0, 1.85, driveline_curve=(0.0, 0.0, 10.0))
    assert float(s["F50_driveline_N"]) == pytest.approx(10.0)
