"""Tests of the classical least-squares baseline (thesis chapter 5, eq. 5.15 / 5.16)."""

from __future__ import annotations

import dataclasses
import json
import math

import jax
import numpy as np
import pandas as pd
import pytest

from bayes_roadload import config
from bayes_roadload import thesis
from bayes_roadload.data import Campaign, Vehicle
from bayes_roadload.inference import LsqSettings, fit_lsq, format_lsq_table, load_model_spec, weighted_mean
from bayes_roadload.inference.lsq import SUMMARY_COLUMNS, between_group_spread
from bayes_roadload.output import write_lsq_fit_dir
from bayes_roadload.physics import integrate_batch, make_run, simplified_model, stack_runs
from bayes_roadload.physics.atmosphere import REFERENCE_AIR_DENSITY_KGPM3

TRUTH = dict(thesis.THESIS_COEFFICIENTS)  # AD 0.01, BD 2e-4, CD0 0.4, KD 0.614
TUNNEL = {"KD": 0.614, "CL0": 0.273, "KL": 3.64}
COEFFS = ("AD", "BD", "CD0", "KD")
VEHICLE = {k: thesis.THESIS_VEHICLE[k] for k in ("mass_kg", "effective_mass_kg", "frontal_area_m2")}


def steady_wind_campaign(winds, *, n_samples=401, v0_mps=31.0):
    """Noise-free opposite-direction pairs in a steady wind.

    Each (head, cross) wind gives a pair: the + run sees (head, cross), the - run
    (-head, -cross).  The relative airspeed and yaw of a first integration with the wind
    model become the logged anemometer channels; the logged speed is then re-integrated
    with the *measured-air* analysis model (eq. 6.1: tyres + lift + C_D0 + K_D psi^2) from
    those channels, so the analysis model is exact and a fit can recover the inputs to
    optimiser precision.
    """
    t = np.arange(n_samples) * 0.25
    signs = [(s * h, s * x) for h, x in winds for s in (1.0, -1.0)]
    head = np.array([h for h, _ in signs])
    cross = np.array([x for _, x in signs])
    batch = stack_runs([make_run(t, np.full_like(t, v0_mps), **VEHICLE)] * len(signs))
    p = {**TRUTH, "CL0": TUNNEL["CL0"], "KL": TUNNEL["KL"]}
    v_wind = jax.jit(lambda h, x: integrate_batch(
        simplified_model(lift=True, air="wind"), {**p, "head_wind_mps": h, "cross_wind_mps": x}, batch)[0])
    v = np.asarray(v_wind(head, cross))
    along = v + head[:, None]
    airspeed = np.sqrt(along**2 + cross[:, None] ** 2)
    yaw = np.arctan2(cross[:, None], along)
    logged = stack_runs([make_run(t, v[i], airspeed_mps=airspeed[i], yaw_rad=yaw[i], **VEHICLE)
                         for i in range(len(signs))])
    vm = np.asarray(jax.jit(lambda b: integrate_batch(simplified_model(lift=True, air="measured"), p, b)[0])(logged))
    frames = [pd.DataFrame({"run": i + 1, "pair": i // 2, "direction": 1.0 if i % 2 == 0 else -1.0,
                            "time_s": t, "speed_mps": vm[i], "airspeed_mps": airspeed[i], "yaw_rad": yaw[i]})
              for i in range(len(signs))]
    vehicle = Vehicle(thesis.THESIS_VEHICLE["mass_kg"], thesis.THESIS_VEHICLE["effective_mass_kg"],
                      thesis.THESIS_VEHICLE["frontal_area_m2"])
    return Campaign(pd.concat(frames, ignore_index=True), vehicle, tunnel=dict(TUNNEL), truth=dict(TRUTH))


@pytest.fixture(scope="module")
def clean():
    """Three noise-free pairs: (head, cross) = (2, 2), (3, 3), (0, 3) m/s (cases 2, 3, 5)."""
    return steady_wind_campaign([(2.0, 2.0), (3.0, 3.0), (0.0, 3.0)])


@pytest.fixture(scope="module")
def clean_fits(clean):
    return {g: fit_lsq(clean, "four_term", g) for g in ("run", "pair", "all")}


def test_four_term_recovers_noise_free_inputs(clean_fits):
    # The fit starts from the spec's generic-car values (AD 0.012, BD 1.5e-4, CD0 0.35, KD 0.5:
    # 20-40 % off) and must land on the inputs: the analysis model generated the data, so only
    # the optimiser tolerance (1e-12) limits the recovery.
    result = clean_fits["pair"]
    assert len(result.groups) == 3
    for g in result.groups:
        assert g.success
        for p in COEFFS:
            assert g.estimate[p] == pytest.approx(TRUTH[p], rel=1e-6), (g.label, p)
            assert math.isfinite(g.se[p]) and 0 <= g.se[p] < 1e-6 * TRUTH[p]
        assert g.rms_residual_mps < 1e-9
    for p in COEFFS:
        assert result.weighted_mean[p] == pytest.approx(TRUTH[p], rel=1e-6)


def test_three_term_with_kd_fixed_from_tunnel(clean):
    result = fit_lsq(clean, "three_term", "pair")
    assert result.free == ("AD", "BD", "CD0")
    assert result.fixed["KD"] == TUNNEL["KD"]
    for p in result.free:
        assert result.weighted_mean[p] == pytest.approx(TRUTH[p], rel=1e-6)
    # ... and it can fail: with K_D fixed 50 % too high the fit degrades and A_D absorbs the
    # error (K_D psi^2 q_r A is nearly a constant force in a steady cross-wind, like M g A_D)
    spec = load_model_spec("three_term")
    biased = fit_lsq(clean, dataclasses.replace(spec, fixed={"KD": 0.921}, fallback={}), "pair")
    assert biased.weighted_mean["AD"] < 0.99 * TRUTH["AD"]
    assert min(g.rms_residual_mps for g in biased.groups) > 1e-5


def test_groupings_are_consistent(clean, clean_fits):
    n_runs = len(clean.run_ids)
    assert [len(clean_fits[g].groups) for g in ("run", "pair", "all")] == [n_runs, n_runs // 2, 1]
    assert clean_fits["all"].groups[0].run_ids == tuple(clean.run_ids)
    # the same samples are counted whatever the grouping (with the initial speed fitted, the
    # first sample is a datum too)
    counts = {g: sum(f.n_samples for f in r.groups) for g, r in clean_fits.items()}
    assert counts["run"] == counts["pair"] == counts["all"] == len(clean.runs)
    for p in COEFFS:
        values = [clean_fits[g].weighted_mean[p] for g in ("run", "pair", "all")]
        assert np.allclose(values, TRUTH[p], rtol=1e-6, atol=0), p
    # a single run with no cross-wind variation still pins A_D, B_D, C_D0
    assert clean_fits["run"].per_group["AD"].to_numpy() == pytest.approx(TRUTH["AD"], rel=1e-6)


def test_weighted_mean_matches_hand_computation():
    # eq. 5.15 / 5.16 by hand: weights 1/s^2 = 100, 25, 6.25
    mean, se = weighted_mean([1.0, 2.0, 4.0], [0.1, 0.2, 0.4])
    assert mean == pytest.approx((100 * 1 + 25 * 2 + 6.25 * 4) / 131.25)
    assert se == pytest.approx(131.25**-0.5)
    # unidentified groups (inf SE) get no weight; none identified -> NaN
    assert weighted_mean([1.0, 5.0], [0.1, math.inf]) == pytest.approx((1.0, 0.1))
    assert all(math.isnan(x) for x in weighted_mean([1.0], [math.inf]))
    mean, std, pct = between_group_spread([1.0, 2.0, 3.0])
    assert (mean, std, pct) == pytest.approx((2.0, 1.0, 50.0))


@pytest.fixture(scope="module")
def two_pairs():
    """Noise-free pairs in (2, 2) and (3, 3) m/s winds; noise is added per test."""
    return steady_wind_campaign([(2.0, 2.0), (3.0, 3.0)])


def with_speed_noise(campaign, sigma_mps, seed):
    """The campaign with seeded Gaussian noise on the logged speed (thesis table 6.6)."""
    runs = campaign.runs.copy()
    runs["speed_mps"] += sigma_mps * np.random.default_rng(seed).standard_normal(len(runs))
    return Campaign(runs, campaign.vehicle, tunnel=campaign.tunnel, truth=campaign.truth)


FITTED_V0 = LsqSettings(initial_speed="fitted")


def test_result_combines_groups_by_eq_5_15(two_pairs):
    result = fit_lsq(with_speed_noise(two_pairs, 0.05, 3), "three_term", "pair")
    df = result.per_group
    for p in result.free:
        w = 1.0 / df[f"{p}_se"].to_numpy() ** 2
        assert result.weighted_mean[p] == pytest.approx(np.sum(w * df[p]) / np.sum(w), rel=1e-12)
        assert result.weighted_se[p] == pytest.approx(np.sum(w) ** -0.5, rel=1e-12)
        assert result.between_std[p] == pytest.approx(np.std(df[p], ddof=1), rel=1e-12)


def _z_scores(result):
    return {p: (result.weighted_mean[p] - TRUTH[p]) / result.weighted_se[p] for p in result.free}


def test_truth_within_three_standard_errors_with_noise(two_pairs):
    # 0.05 m/s Gaussian speed noise (thesis table 6.6) on two pairs, all four runs fitted
    # jointly with each run's initial speed estimated.  The residuals are then independent
    # and the estimator close to linear-Gaussian, so z = (estimate - truth) / SE ~ N(0, 1):
    # |z| < 3 has probability 99.7 % per coefficient.  The draw is seeded, so the test is
    # deterministic; SEs too small by 3x or more (as in the next tests) would fail it.
    noisy = with_speed_noise(two_pairs, 0.05, 0)
    result = fit_lsq(noisy, "four_term", "all", settings=FITTED_V0)
    z = _z_scores(result)
    for p in ("AD", "BD", "CD0"):
        assert abs(z[p]) < 3.0, z
        assert result.weighted_se[p] < 0.05 * TRUTH[p]  # and the SEs are informative
    assert result.groups[0].rms_residual_mps == pytest.approx(0.05, rel=0.1)
    # Per-pair fits combined by eq. 5.15 cover the truth as well.
    pairs = fit_lsq(noisy, "three_term", "pair", settings=FITTED_V0)
    assert all(abs(v) < 3.0 for v in _z_scores(pairs).values())


def test_standard_errors_are_calibrated(two_pairs):
    # Over 32 seeds the z-scores of an honest SE have standard deviation 1 and mean 0; the
    # sample std of 32 N(0, 1) draws is 1 +- 0.13 and the mean 0 +- 0.18, so the bounds
    # below (>= 3 of those SDs) fail only for SEs wrong by ~1.5x or more or a bias beyond
    # ~0.6 SE (a missing sigma^2 or wrong degrees of freedom would be caught; the thesis'
    # measured-v0 errors give std(z) ~ 10, see below).  A 200-seed study gave std(z) =
    # 1.00-1.04 for all four coefficients.
    z = np.array([list(_z_scores(fit_lsq(with_speed_noise(two_pairs, 0.05, 100 + k), "four_term", "all",
                                         settings=FITTED_V0)).values()) for k in range(32)])
    assert np.all((0.6 < z.std(axis=0)) & (z.std(axis=0) < 1.5)), z.std(axis=0)
    assert np.all(np.abs(z.mean(axis=0)) < 0.6), z.mean(axis=0)


def test_measured_initial_speed_understates_the_errors(two_pairs):
    # The thesis integrates from the first *measured* speed: its noise shifts the whole
    # calculated trace, the residuals are correlated along the run and sigma^2 (J^T J)^-1
    # is too small.  On the same seeded data as above the truth is then > 3 SE away.
    z = _z_scores(fit_lsq(with_speed_noise(two_pairs, 0.05, 0), "four_term", "all",
                          settings=LsqSettings(initial_speed="measured")))
    assert max(abs(v) for v in z.values()) > 3.0, z


def test_derived_road_load_figures(clean_fits):
    result = clean_fits["pair"]
    m, a, v = thesis.THESIS_VEHICLE["mass_kg"], thesis.THESIS_VEHICLE["frontal_area_m2"], config.SPEED_50MPH_MPS

    def parts(v):  # eq. 6.1 in still air at the reference density: tyres with lift, aero
        qa = 0.5 * REFERENCE_AIR_DENSITY_KGPM3 * a * v**2
        return (m * config.GRAVITY_MPS2 - qa * TUNNEL["CL0"]) * (TRUTH["AD"] + TRUTH["BD"] * v), qa * TRUTH["CD0"]

    tyre, aero = parts(v)
    assert result.weighted_mean["F50_N"] == pytest.approx(tyre + aero, rel=1e-9)
    g = result.groups[0]
    assert g.estimate["F50_tyre_N"] == pytest.approx(tyre, rel=1e-9)
    assert g.estimate["F50_aero_N"] == pytest.approx(aero, rel=1e-9)
    assert g.estimate["F50_driveline_N"] == 0.0
    # F = F0 + F1 v + F2 v^2 (v in km/h): least-squares quadratic through the total over
    # 15-115 km/h; the lift term's small cubic part is projected, so F50 is matched to < 0.5 N
    grid = np.arange(15.0, 120.0, 5.0)
    f2, f1, f0 = np.polyfit(grid, np.sum(parts(grid / 3.6), axis=0), 2)
    got = [result.weighted_mean[k] for k in ("F0_N", "F1_N_per_kph", "F2_N_per_kph2")]
    assert got == pytest.approx([f0, f1, f2], rel=1e-8)
    kph = v * 3.6
    assert f0 + f1 * kph + f2 * kph**2 == pytest.approx(tyre + aero, abs=0.5)
    assert all(math.isfinite(result.weighted_se[k]) for k in result.derived)


def test_unidentified_parameter_is_reported_not_invented():
    # Head wind only: zero yaw, so K_D does not enter the data (thesis table 6.2).
    still_yaw = steady_wind_campaign([(2.0, 0.0)])
    with pytest.warns(RuntimeWarning, match="KD not identified"):
        result = fit_lsq(still_yaw, "four_term", "pair")
    assert result.groups[0].unidentified == ("KD",)
    assert math.isinf(result.groups[0].se["KD"]) and math.isnan(result.weighted_mean["KD"])
    assert result.weighted_mean["AD"] == pytest.approx(TRUTH["AD"], rel=1e-6)


def test_driveline_polynomial_from_speed_only_keeps_the_total(clean):
    # A_t is exactly confounded with A_D (and, through lift, with C_D0 and K_D) when only the
    # speed is fitted: those are reported unidentified, the total road load is still exact.
    with pytest.warns(RuntimeWarning, match="not identified"):
        result = fit_lsq(clean.subset(clean.pairs()[0]), "four_term_driveline", "pair")
    g = result.groups[0]
    assert {"AD", "At"} <= set(g.unidentified)
    ref = fit_lsq(clean.subset(clean.pairs()[0]), "four_term", "pair").groups[0].estimate["F50_N"]
    assert g.estimate["F50_N"] == pytest.approx(ref, rel=1e-6)
    assert math.isfinite(g.se["F50_N"])


def test_outputs(tmp_path, clean_fits, clean):
    result = clean_fits["pair"]
    write_lsq_fit_dir(result, tmp_path)
    summary = pd.read_csv(tmp_path / "summary.csv")
    assert tuple(summary.columns) == SUMMARY_COLUMNS
    assert list(summary["parameter"]) == ["AD", "BD", "CD0", "KD", "F50_N", "F0_N", "F1_N_per_kph", "F2_N_per_kph2"]
    row = summary.set_index("parameter").loc["CD0"]
    assert row["mean"] == pytest.approx(TRUTH["CD0"], rel=1e-6) and row["q50"] == row["mean"]
    assert row["q2.5"] == pytest.approx(row["mean"] - 1.959964 * row["sd"])
    assert summary[["r_hat", "ess_bulk", "ess_tail"]].isna().all().all()
    per_group = pd.read_csv(tmp_path / "per_group.csv")
    for col in ("group", "runs", "AD", "AD_se", "KD", "KD_se", "rms_residual_mps", "n_samples"):
        assert col in per_group
    assert len(per_group) == 3 and per_group["runs"].iloc[0] == "1;2"
    doc = json.loads((tmp_path / "fit.json").read_text())
    assert doc["method"] == "lsq" and doc["model"] == "four_term" and doc["grouping"] == "pair"
    assert doc["weighted_mean"]["KD"] == pytest.approx(TRUTH["KD"], rel=1e-6)
    assert set(doc["between_group"]) == {"mean", "std", "std_pct"}
    assert doc["truth"] == TRUTH
    text = format_lsq_table(result)
    assert "four_term" in text and "CD0" in text and "truth" in text
    assert "truth" not in format_lsq_table(fit_lsq(clean.subset([1]), "three_term", "run"), truth={})


def test_bad_grouping_and_unpaired_campaign(clean):
    with pytest.raises(ValueError, match="grouping"):
        fit_lsq(clean, "four_term", "week")
    single = Campaign(clean.subset([1]).runs.drop(columns="pair"), clean.vehicle, tunnel=clean.tunnel)
    with pytest.raises(ValueError, match="no opposite-direction pairs"):
        fit_lsq(single, "four_term", "pair")


# ----------------------------------------------------------------------------- thesis table 6.8

def _simulate_campaign():
    try:
        from bayes_roadload.simulate import simulate_campaign
    except ImportError as e:  # pragma: no cover - depends on the simulator being present
        pytest.skip(f"bayes_roadload.simulate.simulate_campaign not importable yet ({e})")
    return simulate_campaign


@pytest.mark.parametrize("case", [1, *(pytest.param(c, marks=pytest.mark.slow) for c in (2, 3, 4, 5))])
def test_table_6_8_recovery_cases_1_to_5(case):
    # Thesis table 6.8, 4-term per-pair fits of the noise-free validation cases: A_D
    # 0.00999-0.01000, B_D 1.985-2.000e-4, C_D0 0.4000-0.4005, K_D 0.613-0.678.  The
    # simulator integrates the truth with turbulence frozen along the track and its own
    # step; the analysis sees the logged channels at 4 Hz, so the recovery is limited by
    # that discretisation, not by the optimiser.
    simulate_campaign = _simulate_campaign()
    campaign = simulate_campaign(case, pairs=1, seed=0)
    result = fit_lsq(campaign, "four_term", "pair")
    (g,) = result.groups
    assert g.success
    assert abs(g.estimate["AD"] - 0.01) < 1e-5
    assert abs(g.estimate["BD"] / 2.0e-4 - 1.0) < 0.0075
    assert abs(g.estimate["CD0"] - 0.4) < 5e-4
    assert abs(g.estimate["KD"] - 0.614) < 0.07


def test_campaigns_padded_alike_share_the_compiled_residual(monkeypatch):
    """Two one-pair campaigns of 493 and 498 samples per run pad to one length (512,
    config.LSQ_PAD_SIZES_PER_OCTAVE), so the second fit traces no new residual or Jacobian; the
    padded fit equals the unpadded one (padded samples are masked) to the optimiser's
    reproducibility, far inside a standard error."""
    import warnings

    from bayes_roadload.inference import lsq
    from bayes_roadload.physics.integrate import bucket_length
    from bayes_roadload.simulate import simulate_campaign

    from ..conftest import clean_case

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        one, two = (simulate_campaign(clean_case(), pairs=1, seed=s) for s in (1, 2))
    lengths = [c.to_batch()[0].time_s.shape[-1] for c in (one, two)]
    assert lengths[0] != lengths[1]
    assert bucket_length(lengths[0], config.LSQ_PAD_SIZES_PER_OCTAVE) == bucket_length(lengths[1], config.LSQ_PAD_SIZES_PER_OCTAVE)
    spec = load_model_spec("four_term")
    model, _, free = spec.build(one)
    fun, jac = lsq._compiled(model, free, LsqSettings().integrator, True)
    padded = fit_lsq(one, spec, "all")
    traced = (fun._cache_size(), jac._cache_size())
    assert min(traced) >= 1  # the programs the fit used
    fit_lsq(two, spec, "all")
    assert (fun._cache_size(), jac._cache_size()) == traced
    monkeypatch.setattr(config, "LSQ_PAD_SIZES_PER_OCTAVE", 0)
    assert lsq._lsq_batch(one, spec)[0].time_s.shape[-1] == lengths[0]
    plain = fit_lsq(one, spec, "all")
    g, h = padded.groups[0], plain.groups[0]
    assert g.n_samples == h.n_samples
    for q in ("AD", "BD", "CD0", "KD", "F50_N"):
        assert g.estimate[q] == pytest.approx(h.estimate[q], rel=1e-9, abs=1e-6 * h.se[q])
        assert g.se[q] == pytest.approx(h.se[q], rel=1e-6)


def test_pad_batch_repeats_the_last_sample_and_masks_it():
    from bayes_roadload.physics.integrate import pad_batch

    runs = [make_run(np.arange(n) * 0.5, 30.0 - 0.1 * np.arange(n), airspeed_mps=np.full(n, 31.0),
                     yaw_rad=np.zeros(n), direction=1.0, mass_kg=1500.0, effective_mass_kg=1540.0,
                     frontal_area_m2=2.0) for n in (5, 7)]
    batch = stack_runs(runs)
    out = pad_batch(batch, 10)
    assert out.time_s.shape == (2, 10) and out.mass_kg.shape == (2,)
    np.testing.assert_array_equal(out.mask, np.concatenate([np.asarray(batch.mask), np.zeros((2, 3), bool)], axis=1))
    np.testing.assert_array_equal(np.asarray(out.speed_mps)[:, 7:], np.repeat(np.asarray(batch.speed_mps)[:, -1:], 3, axis=1))
    np.testing.assert_array_equal(np.asarray(out.time_s)[:, :7], np.asarray(batch.time_s))
    one = pad_batch(batch.run(1), 9)  # one run's [N] arrays, its constants scalars
    assert one.time_s.shape == (9,) and np.ndim(one.mass_kg) == 0 and not np.asarray(one.mask)[7:].any()
    assert pad_batch(batch, 7) is batch


def test_a_held_parameter_gives_the_fit_with_it_fixed_through_the_same_programs(two_pairs):
    """``hold``: K_D held 30 % above its estimate is the fit of the others with K_D fixed in the
    spec: the same least-squares problem from the same start, so the same iterates (measured
    bit-identical here; 1e-12 leaves room for the rounding of another compiler) in the
    estimates, the initial-speed offsets, the standard errors and the derived figures'; the
    held parameter keeps its value with standard error 0, and the fit traces no program beyond
    the unheld fit's."""
    from bayes_roadload.inference import lsq

    from ..conftest import with_fixed

    noisy = with_speed_noise(two_pairs, 0.05, 5)
    spec = load_model_spec("four_term")
    free_fit = fit_lsq(noisy, spec, "all", settings=FITTED_V0).groups[0]
    value = 1.3 * free_fit.estimate["KD"]
    model, _, free = spec.build(noisy)
    fun, jac = lsq._compiled(model, free, FITTED_V0.integrator, True)
    traced = (fun._cache_size(), jac._cache_size())
    held = fit_lsq(noisy, spec, "all", hold={"KD": value}, settings=FITTED_V0).groups[0]
    assert (fun._cache_size(), jac._cache_size()) == traced
    fixed = fit_lsq(noisy, with_fixed(spec, {"KD": value}), "all", settings=FITTED_V0).groups[0]
    assert held.estimate["KD"] == value and held.se["KD"] == 0.0
    assert held.estimate["AD"] != pytest.approx(free_fit.estimate["AD"], rel=1e-3)  # the hold moved the others
    for q in ("AD", "BD", "CD0", "F50_N", "F0_N", "F2_N_per_kph2"):
        assert held.estimate[q] == pytest.approx(fixed.estimate[q], rel=1e-12), q
        assert held.se[q] == pytest.approx(fixed.se[q], rel=1e-12), q
    assert held.v0_offset_mps == pytest.approx(fixed.v0_offset_mps, rel=1e-12, abs=1e-15)
    assert held.ssr_m2ps2 == pytest.approx(fixed.ssr_m2ps2, rel=1e-12)
    with pytest.raises(ValueError, match="not free"):
        fit_lsq(noisy, spec, "all", hold={"tyre_lag_gain_per_mps": 0.0})
