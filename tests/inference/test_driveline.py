"""The driveline loss from the wheel-torque channel alone (eq. 5.12)."""

import warnings

import arviz as az
import pandas as pd
import pytest

from bayes_roadload import config
from bayes_roadload.inference.driveline import build_driveline_problem, fit_driveline_nuts
from bayes_roadload.inference.results import SUMMARY_COLUMNS, _rows, diagnostics
from bayes_roadload.simulate import simulate_campaign


def test_refused_without_a_driveline_channel(small_campaign):
    with pytest.raises(ValueError, match="no driveline_force_n"):
        build_driveline_problem(small_campaign)


@pytest.mark.slow
def test_driveline_coefficients_recovered_from_the_channel():
    """One pair of case 9 with the driveline channel (1 N noise): measured At 21.03 +- 0.19
    (truth 21.0), Bt 2.094 +- 0.025 (2.09), Ct -0.0203 +- 0.0007 (-0.02), sigma 1.006 (1.0); ~14 s."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        camp = simulate_campaign(9, pairs=1, seed=2, driveline=True)
    fit = fit_driveline_nuts(camp, sampler=config.SamplerConfig(seed=1))
    idata = az.from_dict(posterior=fit.samples, sample_stats={"diverging": fit.stats["diverging"].astype(bool),
                                                              "energy": fit.stats["energy"]})
    s = _rows(idata, ["At", "Bt", "Ct", "sigma_driveline_n"])
    assert diagnostics(fit, idata, s, runs=pd.DataFrame(columns=list(SUMMARY_COLUMNS)))["pass"]
    s = s.set_index("parameter")
    for name in ("At", "Bt", "Ct"):
        assert abs(s.loc[name, "mean"] - camp.truth[name]) < 3 * s.loc[name, "sd"], name
    assert abs(s.loc["sigma_driveline_n", "mean"] - 1.0) < 3 * s.loc["sigma_driveline_n", "sd"]


def test_on_load_loss_of_a_steady_campaign_is_gearbox_input_minus_wheel_force():
    """Section 5.5.2: the on-load driveline loss is the difference of the two torques, fitted by
    the same model as the off-load channel; refused when the gearbox input is not logged."""
    import numpy as np

    from bayes_roadload.simulate.steady import SteadySettings, simulate_steady

    short = SteadySettings(duration_s=5.0)
    c = simulate_steady(9, pairs=1, seed=1, settings=short)
    p = build_driveline_problem(c)
    expected = c.runs["gearbox_input_force_n"] - c.runs["tractive_force_n"]
    np.testing.assert_allclose(np.asarray(p.force_n), expected.to_numpy())
    # table 7.9: 36.3 N, no speed term, 10 N noise: the least-squares start within 4 of its SEs
    (_, _, _), cov = np.polyfit(c.runs["speed_mps"], expected, 2, cov=True)
    assert abs(p.initial["At"] - 36.3) < 4 * np.sqrt(cov[2, 2]) and abs(p.initial["Bt"]) < 4 * np.sqrt(cov[1, 1])
    with pytest.raises(ValueError, match="gearbox_input_force_n"):
        build_driveline_problem(simulate_steady(9, pairs=1, seed=1, gearbox_input=False, settings=short))
