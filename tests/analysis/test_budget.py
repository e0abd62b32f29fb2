"""First-order Type B propagation and the uncertainty budget (:mod:`bayes_roadload.analysis.budget`)."""

from __future__ import annotations

import numpy as np
import pytest

from bayes_roadload.analysis.budget import (TypeB, add_type_b, budget_table, format_budget,
                                            type_b_sensitivities)
from bayes_roadload.data.uncertainty import SOURCES
from bayes_roadload.inference.lsq import fit_lsq
from bayes_roadload.simulate import simulate_campaign


@pytest.fixture(scope="module")
def clean():
    """Case 1: no noise, no dynamics; the analysis model (basic physics) is exact but for lift."""
    return simulate_campaign(1, pairs=1, seed=0)


def test_mass_sensitivity_matches_the_hand_calculation(clean):
    """The equation of motion M_e dv/dt = -F: with the declared mass (and so M_e) off by dm,
    the fitted forces scale by (M_e + dm) / M_e, so dF50/dM = F50 / M_e.  The least-squares
    refits recover it up to the central difference's second-order error ((u/M_e)^2 ~ 1e-5)
    and the fit's own tolerance: 1 % is generous."""
    typeb = type_b_sensitivities(clean, "four_term", ["F50_N", "CD0"])
    estimate = fit_lsq(clean, "four_term", grouping="all").weighted_mean
    f50, cd0 = estimate["F50_N"], estimate["CD0"]
    assert typeb.sensitivity["F50_N"]["mass_kg"] == pytest.approx(f50 / clean.vehicle.effective_mass_kg, rel=0.01)
    # C_D0 scales with the force and with 1 / factor^2 (true airspeed = factor x reading)
    assert typeb.sensitivity["CD0"]["airspeed_factor_rel"] == pytest.approx(-2.0 * cd0, rel=0.05)
    assert "temperature_k" in typeb.notes and "temperature_k" not in typeb.sources


def test_linear_sensitivities_agree_with_the_refits():
    """One Gauss-Newton step from the optimum (the default) against refitting each shifted
    campaign, on a noisy campaign with wind and yaw (case 9, 2 pairs).  The step leaves out the
    residual-weighted curvature of the residuals (Gauss-Newton), so the two differ where the
    dependence is not linear -- the yaw offset through K_D psi^2 -- and by the refits' tolerance
    elsewhere.  What matters to the budget is c u: each source's contribution may differ by at
    most 5 % of the quantity's Type B standard uncertainty (sqrt of the sum of (c u)^2)."""
    import math
    import warnings

    quantities = ["F50_N", "F0_N", "AD", "CD0", "KD"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        campaign = simulate_campaign(9, pairs=2, seed=3)
        linear = type_b_sensitivities(campaign, "four_term", quantities)
        refit = type_b_sensitivities(campaign, "four_term", quantities, method="refit")
    assert set(linear.sources) == set(refit.sources) and len(linear.sources) >= 5
    for q in quantities:
        row = refit.sensitivity[q]
        u_b = math.sqrt(sum((c * refit.u[k]) ** 2 for k, c in row.items()))
        for key, c in row.items():
            assert abs(linear.sensitivity[q][key] - c) * refit.u[key] <= 0.05 * u_b, (q, key, linear.sensitivity[q][key], c)
    with pytest.raises(ValueError, match="linear"):
        type_b_sensitivities(campaign, "four_term", quantities, method="newton")


def test_budget_shares_sum_to_one_and_a_switched_off_source_has_none(clean):
    clean.meta["uncertainty"] = {"yaw_factor_rel": 0.0}
    try:
        typeb = type_b_sensitivities(clean, "four_term", ["F50_N"])
    finally:
        del clean.meta["uncertainty"]
    assert "yaw_factor_rel" in typeb.notes and "switched off" in typeb.notes["yaw_factor_rel"]
    budget = budget_table(typeb, {"F50_N": 0.5})
    rows = budget[budget["quantity"] == "F50_N"]
    assert rows["variance_share"].sum() == pytest.approx(1.0)
    assert "yaw_factor_rel" not in set(rows["source"])
    data = rows[rows["source"] == "data"].iloc[0]
    assert data["variance"] == pytest.approx(0.25)
    assert "F50_N: data" in format_budget(budget)


def test_added_draws_have_the_propagated_variance():
    """var(x + sum c_s delta_s) = var(x) + sum c_s^2 u_s^2 for independent draws; 40000 draws
    estimate a variance to 1.4 % (sd of a sample variance: sqrt(2 / n)): 5 % tolerance."""
    typeb = TypeB(u={"mass_kg": 4.0, "airspeed_factor_rel": 0.005},
                  sensitivity={"F50_N": {"mass_kg": 0.3, "airspeed_factor_rel": 200.0}})
    rng = np.random.default_rng(1)
    x = rng.normal(400.0, 1.0, (4, 10000))
    out = add_type_b({"F50_N": x, "other": x}, typeb, seed=3)
    expected = 1.0 + (0.3 * 4.0) ** 2 + (200.0 * 0.005) ** 2
    assert np.var(out["F50_N"]) == pytest.approx(expected, rel=0.05)
    assert out["other"] is x
    assert np.mean(out["F50_N"]) == pytest.approx(400.0, abs=5 * np.sqrt(expected / x.size))
    assert set(typeb.sources) == {"mass_kg", "airspeed_factor_rel"} <= set(SOURCES)
