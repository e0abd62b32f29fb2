"""Standard results (reference conditions, units, mass convention, CdA) and checks."""

import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from bayes_roadload.analysis.standards import (STANDARDS, get_standard, run_standard, standard_checks,
                                               standard_result, to_us_units)
from bayes_roadload.data.campaign import Campaign, Vehicle

R = 287.05
RHO_REF = 100_000.0 / (R * 293.2)  # project reference: 100 kPa, 293.2 K


def _draws(n=4001, seed=0):
    rng = np.random.default_rng(seed)
    return {"F0_N": rng.normal(100.0, 3.0, n), "F1_N_per_kph": rng.normal(0.5, 0.05, n),
            "F2_N_per_kph2": rng.normal(0.03, 0.001, n)}


def test_us_units_by_hand():
    """1 lbf = 4.44822 N, 1 mph = 1.609344 km/h: 100 N = 22.4809 lbf; 0.5 N/(km/h) =
    0.804672/4.44822 = 0.180898 lbf/mph; 0.03 N/(km/h)^2 = 0.0776996/4.44822 = 0.0174676."""
    a, b, c = to_us_units(100.0, 0.5, 0.03)
    assert a == pytest.approx(22.4809, abs=1e-4)
    assert b == pytest.approx(0.180898, abs=1e-6)
    assert c == pytest.approx(0.0174676, abs=1e-7)


def test_gtr15_coefficients_by_hand():
    """GTR 15: 20 C, 100 kPa.  Tyre factor 1 - 0.0086 (293.15 - 293.2) = 1.00043 on f0, f1;
    density ratio 293.2/293.15 on f2; no mass rescaling."""
    d = _draws()
    res = standard_result(d, "gtr15").set_index("quantity")
    tyre = 1 - 0.0086 * (293.15 - 293.2)
    assert res.loc["f0", "mean"] == pytest.approx(d["F0_N"].mean() * tyre, rel=1e-12)
    assert res.loc["f1", "mean"] == pytest.approx(d["F1_N_per_kph"].mean() * tyre, rel=1e-12)
    assert res.loc["f2", "mean"] == pytest.approx(d["F2_N_per_kph2"].mean() * 293.2 / 293.15, rel=1e-12)
    assert res.loc["f0", "q2.5"] == pytest.approx(np.quantile(d["F0_N"] * tyre, 0.025), rel=1e-12)
    assert res.loc["f0", "unit"] == "N"


def test_j2263_reference_conditions_and_mass_convention_by_hand():
    """J2263: 20 C, 98.21 kPa, lbf and mph, M_e = 1.03 M.  With M = 1100 kg and the fit's
    M_e = 1130 kg every force scales by 1.03*1100/1130 = 1.0026549; f2 by rho(98.21 kPa, 293.15 K)
    / rho_ref = 0.9821 * 293.2/293.15."""
    d = _draws()
    res = standard_result(d, "j2263", mass_kg=1100.0, effective_mass_kg=1130.0).set_index("quantity")
    scale = 1.03 * 1100.0 / 1130.0
    tyre = 1 - 0.0086 * (293.15 - 293.2)
    aero = 0.9821 * 293.2 / 293.15
    assert res.loc["A", "mean"] == pytest.approx(d["F0_N"].mean() * tyre * scale / 4.44822, rel=1e-12)
    assert res.loc["B", "mean"] == pytest.approx(d["F1_N_per_kph"].mean() * tyre * scale * 1.609344 / 4.44822,
                                                 rel=1e-12)
    assert res.loc["C", "mean"] == pytest.approx(d["F2_N_per_kph2"].mean() * aero * scale * 1.609344**2 / 4.44822,
                                                 rel=1e-12)
    assert res.loc["C", "unit"] == "lbf/mph^2"
    known = standard_result(d, "j2263", rotating_inertia_known=True).set_index("quantity")
    assert res.loc["A", "mean"] / known.loc["A", "mean"] == pytest.approx(scale, rel=1e-12)


def test_mass_convention_needs_the_masses():
    with pytest.raises(ValueError, match="1.03"):
        standard_result(_draws(), "j2263")


def _two_term_by_hand(lo_kph, hi_kph, n=200):
    """alpha, beta of v ~ alpha + beta v^2 over n equally spaced speeds, from the 2 x 2 normal
    equations [n, S2; S2, S4] [alpha, beta] = [S1, S3] by Cramer's rule."""
    v = [lo_kph + (hi_kph - lo_kph) * i / (n - 1) for i in range(n)]
    s1, s2, s3, s4 = (sum(x**k for x in v) for k in (1, 2, 3, 4))
    det = n * s4 - s2 * s2
    return (s1 * s4 - s2 * s3) / det, (n * s3 - s2 * s1) / det


def test_cda_by_hand():
    """40 CFR 1066.310 reports A = A_m, B = 0, C = D_adj: the road load at the standard's
    conditions (F2 scaled to the reference density 1.17 kg/m^3, F0 and F1 to the tyres at
    20 C), F0' + F1' v + F2' v^2, is refitted as A + C v^2 over 15-70 mph: C = F2' + beta F1'
    (beta from the normal equations above); CdA = 2 C 3.6^2 / 1.17 (times the mass scaling,
    here 1)."""
    d = {k: np.full(11, v) for k, v in (("F0_N", 100.0), ("F1_N_per_kph", 0.5), ("F2_N_per_kph2", 0.03))}
    d["CD0"] = np.full(11, 0.35)
    d["KD"] = np.full(11, 0.6)
    res = standard_result(d, "cfr1066", rotating_inertia_known=True, frontal_area_m2=2.0, yaw_deg=4.5)
    res = res.set_index("quantity")
    alpha, beta = _two_term_by_hand(15 * 1.609344, 70 * 1.609344)
    tyre = 1.0 - 0.0086 * (293.15 - 293.2)  # the project's reference is 293.2 K
    c_kph = 0.03 * 1.17 / RHO_REF + beta * 0.5 * tyre
    assert res.loc["CdA_zero_yaw", "mean"] == pytest.approx(2 * c_kph * 12.96 / 1.17, rel=1e-9)
    # CdA(psi) = A (CD0 + KD psi^2) = 2 (0.35 + 0.6 (4.5 pi/180)^2) = 0.707401
    assert res.loc["CdA_yaw_4.5deg", "mean"] == pytest.approx(2 * (0.35 + 0.6 * math.radians(4.5) ** 2), rel=1e-12)
    assert res.loc["C", "mean"] == pytest.approx(c_kph * 1.609344**2 / 4.44822, rel=1e-9)
    assert res.loc["B", "mean"] == 0.0
    # A = F0' + alpha F1'
    assert res.loc["A", "mean"] == pytest.approx((100.0 + alpha * 0.5) * tyre / 4.44822, rel=1e-9)
    # the two-term curve is the best A + C v^2 through the three-term one: F - (A + C v^2) has
    # no component along 1 or v^2 over the range (the residual is orthogonal to both)
    v = np.linspace(15 * 1.609344, 70 * 1.609344, 200)
    resid = 0.5 * v - (alpha + beta * v**2) * 0.5
    assert abs(resid.sum()) < 1e-6 * v.size and abs((resid * v**2).sum()) < 1e-6 * (v**2).sum()
    # the standard's yaw (+-4.5 deg wind-averaged) is the default
    default = standard_result(d, "cfr1066", rotating_inertia_known=True, frontal_area_m2=2.0)
    assert "CdA_yaw_4.5deg" in set(default["quantity"])


def test_unknown_standard_is_refused():
    with pytest.raises(ValueError, match="gtr15"):
        get_standard("iso9999")
    assert set(STANDARDS) == {"gtr15", "j2263", "j1263", "cfr1066", "cfr1037"}


def _run(run, pair, direction, decel, head_mps=0.0, v0=35.0, dt=0.5):
    t = np.arange(0.0, (v0 - 4.0) / decel, dt)
    v = v0 - decel * t
    return pd.DataFrame({"run": run, "pair": pair, "direction": direction, "time_s": t, "speed_mps": v,
                         "airspeed_mps": v + head_mps, "yaw_rad": 0.0, "temperature_k": 290.0})


def _campaign(decels, head_mps=0.0):
    runs = pd.concat([_run(i + 1, i // 2 + 1, 1 if i % 2 == 0 else -1, d, head_mps) for i, d in enumerate(decels)],
                     ignore_index=True)
    return Campaign(runs, Vehicle(mass_kg=1500.0, frontal_area_m2=2.0, effective_mass_kg=1540.0))


def test_gtr15_checks_count_pairs_and_precision():
    """Three pairs at 0.50/0.52, 0.49/0.51, 0.50/0.50 m/s^2: 3 runs each way, 3 pairs (>= 3), and the
    precision at 50 km/h = t(0.975, 2) s / (sqrt 3 mean) of the pairs' harmonic-mean band times."""
    decels = [0.50, 0.52, 0.49, 0.51, 0.50, 0.50]
    chk = standard_checks(_campaign(decels), "gtr15").set_index("rule")
    assert chk.loc["runs in direction +1", "value"] == 3 and chk.loc["runs in direction -1", "value"] == 3
    # with on-board anemometry GTR 15 (EU 2017/1151 Sub-Annex 4, 4.3.2.4) asks for 5 pairs
    row = chk.loc["opposite-direction pairs (on-board anemometry)"]
    assert (row["value"], row["limit"], row["pass"]) == (3, 5, False)
    no_anemometer = _campaign(decels)
    no_anemometer.runs = no_anemometer.runs.drop(columns=["airspeed_mps", "yaw_rad"])
    stationary = standard_checks(no_anemometer, "gtr15").set_index("rule")
    assert stationary.loc["opposite-direction pairs", "limit"] == 3 and stationary.loc["opposite-direction pairs", "pass"]
    # speed logged every 0.5 s: 2 Hz against 3.1(a)'s 10 Hz
    assert chk.loc["recording rate (slowest run)", "value"] == pytest.approx(2.0)
    assert not chk.loc["recording rate (slowest run)", "pass"]
    pair_t = [2.0 / (decels[i] / (10 / 3.6) + decels[i + 1] / (10 / 3.6)) for i in (0, 2, 4)]
    expected = stats.t.ppf(0.975, 2) * np.std(pair_t, ddof=1) / math.sqrt(3) / np.mean(pair_t) * 100
    row = chk.loc["statistical precision at 50 km/h"]
    assert row["value"] == pytest.approx(expected, rel=1e-9)
    assert row["pass"] == (expected <= 3.0)


def test_j1263_wind_limit_by_hand():
    """Head-wind 5 m/s = 18 km/h > 16 km/h: fails; 4 m/s = 14.4 km/h passes; ambient 290 K in 5-35 C."""
    decels = [0.5, 0.5]
    windy = standard_checks(_campaign(decels, head_mps=5.0), "j1263").set_index("rule")
    assert windy.loc["mean wind speed (worst run)", "value"] == pytest.approx(5.0, abs=1e-9)
    assert not windy.loc["mean wind speed (worst run)", "pass"]
    calm = standard_checks(_campaign(decels, head_mps=4.0), "j1263").set_index("rule")
    assert calm.loc["mean wind speed (worst run)", "pass"]
    assert calm.loc["mean cross-wind (worst run)", "value"] == pytest.approx(0.0, abs=1e-12)
    assert calm.loc["ambient temperature min", "pass"] and calm.loc["ambient temperature max", "pass"]


def test_gtr15_onboard_wind_limits_by_hand():
    """The on-board limits of config.WIND_LIMITS["gtr_onboard"] (7 m/s mean, 4 m/s cross): a
    steady 7.5 m/s head wind fails, 6.5 m/s passes; no cross-wind (yaw 0)."""
    windy = standard_checks(_campaign([0.5, 0.5], head_mps=7.5), "gtr15").set_index("rule")
    row = windy.loc["mean wind speed (worst run)"]
    assert row["value"] == pytest.approx(7.5, abs=1e-9) and row["limit"] == 7.0 and not row["pass"]
    calm = standard_checks(_campaign([0.5, 0.5], head_mps=6.5), "gtr15").set_index("rule")
    assert calm.loc["mean wind speed (worst run)", "pass"]
    assert calm.loc["mean cross-wind (worst run)", "limit"] == 4.0 and calm.loc["mean cross-wind (worst run)", "pass"]


def test_gtr15_rotating_mass_estimate_by_hand(tmp_path):
    """GTR 15 2.5.1: with the mass in running order stated, M_e = TM + 0.03 (MRO + 25 kg): a
    1500 kg test mass, 1400 kg in running order, fitted with M_e = 1540 kg, rescales every
    coefficient by (1500 + 0.03 x 1425) / 1540; a measured rotating inertia keeps the fit's M_e;
    without the mass in running order nothing is rescaled."""
    d = _draws()
    plain = standard_result(d, "gtr15", mass_kg=1500.0, effective_mass_kg=1540.0).set_index("quantity")
    est = standard_result(d, "gtr15", mass_kg=1500.0, effective_mass_kg=1540.0,
                          mass_in_running_order_kg=1400.0).set_index("quantity")
    scale = (1500.0 + 0.03 * (1400.0 + 25.0)) / 1540.0
    for q in ("f0", "f1", "f2"):
        assert est.loc[q, "mean"] == pytest.approx(plain.loc[q, "mean"] * scale, rel=1e-12)
    kept = standard_result(d, "gtr15", mass_kg=1500.0, effective_mass_kg=1540.0, mass_in_running_order_kg=1400.0,
                           rotating_inertia_known=True).set_index("quantity")
    assert kept.loc["f0", "mean"] == pytest.approx(plain.loc["f0", "mean"], rel=1e-12)
    # from vehicle.toml through run_standard, recorded in standard.json
    c = _campaign([0.5, 0.5])
    c.vehicle = Vehicle(mass_kg=1500.0, frontal_area_m2=2.0, effective_mass_kg=1540.0, mass_in_running_order_kg=1400.0)
    res, _ = run_standard(d, "gtr15", campaign=c, out_dir=tmp_path)
    assert res.set_index("quantity").loc["f0", "mean"] == pytest.approx(est.loc["f0", "mean"], rel=1e-12)
    import json
    assert json.loads((tmp_path / "standard.json").read_text())["effective_mass_kg_standard"] == \
        pytest.approx(1500.0 + 0.03 * 1425.0)


def test_cfr1066_requires_eight_runs_each_way():
    chk = standard_checks(_campaign([0.5] * 6), "cfr1066").set_index("rule")
    assert chk.loc["runs in direction +1", "limit"] == 8
    assert not chk.loc["runs in direction +1", "pass"]


def test_run_standard_writes_its_files(tmp_path):
    c = _campaign([0.50, 0.52, 0.49, 0.51, 0.50, 0.50])
    res, chk = run_standard(_draws(), "j2263", campaign=c, out_dir=tmp_path)
    assert (tmp_path / "standard_result.csv").is_file() and (tmp_path / "standard.json").is_file()
    # masses from the campaign's vehicle: scale 1.03 * 1500 / 1540
    direct = standard_result(_draws(), "j2263", mass_kg=1500.0, effective_mass_kg=1540.0)
    np.testing.assert_allclose(res["mean"], direct["mean"], rtol=1e-12)


def _ranged_campaign(ranges_kph):
    """One run per (start, end) km/h range, alternating directions, decelerating at 0.5 m/s^2."""
    frames = []
    for i, (hi, lo) in enumerate(ranges_kph):
        v = np.arange(hi, lo - 1e-9, -1.8) / 3.6  # 0.5 m/s^2 at 1 s steps
        v[-1] = lo / 3.6
        frames.append(pd.DataFrame({"run": i + 1, "pair": i // 2 + 1, "direction": 1 if i % 2 == 0 else -1,
                                    "time_s": np.arange(v.size, dtype=float), "speed_mps": v}))
    return Campaign(pd.concat(frames, ignore_index=True),
                    Vehicle(mass_kg=1500.0, frontal_area_m2=2.0, effective_mass_kg=1540.0))


def test_j2263_speed_range_may_be_covered_by_split_runs_by_hand():
    """J2263 115 -> 15 km/h: split runs 118 -> 60 and 65 -> 12 km/h cover it (no gap); 118 -> 70 and
    60 -> 12 leave 70 - 60 = 10 km/h uncovered; one run 110 -> 20 misses both ends (5 + 5 km/h)."""
    ok = standard_checks(_ranged_campaign([(118.0, 60.0), (65.0, 12.0)]), "j2263").set_index("rule")
    gap_rule = "speed range 115 -> 15 km/h not covered by any run"
    assert ok.loc["start speed (highest run)", "value"] == pytest.approx(118.0)
    assert ok.loc["end speed (lowest run)", "value"] == pytest.approx(12.0)
    assert ok.loc[gap_rule, "value"] == pytest.approx(0.0, abs=1e-9) and ok.loc[gap_rule, "pass"]
    gap = standard_checks(_ranged_campaign([(118.0, 70.0), (60.0, 12.0)]), "j2263").set_index("rule")
    assert gap.loc[gap_rule, "value"] == pytest.approx(10.0) and not gap.loc[gap_rule, "pass"]
    short = standard_checks(_ranged_campaign([(110.0, 20.0), (110.0, 20.0)]), "j2263").set_index("rule")
    assert not short.loc["start speed (highest run)", "pass"] and not short.loc["end speed (lowest run)", "pass"]
    assert short.loc[gap_rule, "value"] == pytest.approx(10.0)


def test_cfr1066_speed_range_is_asked_of_every_run_by_hand():
    """40 CFR 1066.310: every run from 70 mph (112.654 km/h) or above to 15 mph (24.140 km/h) or
    below; one run of two starting at 110 km/h fails the start check, with its figure."""
    chk = standard_checks(_ranged_campaign([(115.0, 20.0), (110.0, 20.0)]), "cfr1066").set_index("rule")
    start = chk.loc["start speed (lowest run)"]
    assert start["limit"] == pytest.approx(70 * 1.609344) and start["value"] == pytest.approx(110.0)
    assert not start["pass"]
    end = chk.loc["end speed (highest run)"]
    assert end["limit"] == pytest.approx(15 * 1.609344) and end["value"] == pytest.approx(20.0) and end["pass"]
