"""The candidate library and the linear algebra of the linearised candidate scoring."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from bayes_roadload import config
from bayes_roadload.analysis import effects as fx
from bayes_roadload.physics import TERMS


def test_library_has_exactly_the_contract_effects_with_known_parameters():
    lib = fx.load_library()
    assert tuple(lib) == fx.EFFECT_NAMES
    for e in lib.values():
        assert e.kind in fx.KINDS and e.needs
        assert all(t in TERMS for t in e.terms)
        assert all(p in config.PARAMETER_UNITS and sd > 0 for p, sd in e.prior_sd.items())


def test_candidates_of_the_anemometer_reading_need_a_logged_airspeed():
    """Without measured air (a speed-only campaign) the cup lag, like the airspeed and yaw
    calibrations, has no reading to act on: not applicable, never scored."""
    from bayes_roadload.physics.model import model_from_names

    lib = fx.load_library()
    still = model_from_names(["tyre_rolling", "aero_drag"], air="still")
    measured = model_from_names(["tyre_rolling", "aero_drag"], air="measured")
    _, still_available = fx.super_model(still, lib)
    _, measured_available = fx.super_model(measured, lib)
    for name in ("anemometer_dynamics", "aero_admittance", "airspeed_calibration", "yaw_calibration"):
        assert "needs logged airspeed_mps" in still_available[name]
        assert measured_available[name] is None
    assert still_available["track_gradient"] is None


def test_library_refuses_unknown_names(tmp_path):
    bad = tmp_path / "lib.toml"
    bad.write_text('[effects.tyre_pressure]\nterms = []\nkind = "term"\nparameters.AD = { prior_sd = 1.0 }\n')
    with pytest.raises(ValueError, match="not an effect of the contract"):
        fx.load_library(bad)


def fake_linearisation(rng, runs=5, n=60, k_shared=3, k_own=2):
    """White unit-variance noise: gram = J^T J, score = J^T r per run."""
    jac = rng.standard_normal((runs, n, k_shared + k_own))
    truth_shared = rng.standard_normal(k_shared)
    truth_own = rng.standard_normal((runs, k_own))
    resid = np.stack([jac[i] @ np.concatenate([truth_shared, truth_own[i]]) for i in range(runs)])
    resid += rng.standard_normal(resid.shape)
    gram = np.einsum("rnk,rnl->rkl", jac, jac)
    score = np.einsum("rnk,rn->rk", jac, resid)
    return SimpleNamespace(gram=gram, score=score, residual=resid, jacobian=jac, n_runs=runs,
                           columns=tuple(f"c{j}" for j in range(k_shared + k_own))), resid, jac


def test_solve_equals_the_joint_least_squares_fit():
    rng = np.random.default_rng(4)
    lin, resid, jac = fake_linearisation(rng)
    runs, n, k = jac.shape
    shared, own = [0, 1, 2], [3, 4]
    sol = fx.solve(lin, shared, own)
    # the same problem as one big least squares: [shared | run-block-diagonal own]
    big = np.zeros((runs * n, 3 + 2 * runs))
    for i in range(runs):
        big[i * n:(i + 1) * n, :3] = jac[i][:, shared]
        big[i * n:(i + 1) * n, 3 + 2 * i:5 + 2 * i] = jac[i][:, own]
    coef, *_ = np.linalg.lstsq(big, resid.ravel(), rcond=None)
    np.testing.assert_allclose(sol.beta, coef[:3], rtol=1e-9)
    np.testing.assert_allclose(sol.gamma, coef[3:].reshape(runs, 2), rtol=1e-9)
    # log likelihood gain of white unit noise: (|r|^2 - |r - J x|^2) / 2
    gain = 0.5 * (resid.ravel() @ resid.ravel() - np.sum((resid.ravel() - big @ coef) ** 2))
    assert sol.loglik_gain == pytest.approx(gain, rel=1e-9)
    # leave-out sums: the gains of the kept runs at the shared step
    assert sum(fx.run_loglik_gain(sol, i) for i in range(runs)) == pytest.approx(sol.loglik_gain, rel=1e-9)


def test_ridge_pulls_a_shared_step_towards_zero():
    rng = np.random.default_rng(5)
    lin, _, _ = fake_linearisation(rng)
    free = fx.solve(lin, [0, 1, 2], [3, 4])
    tight = fx.solve(lin, [0, 1, 2], [3, 4], prior_precision=np.array([0.0, 0.0, 1e8]))
    assert abs(tight.beta[2]) < 1e-3 * abs(free.beta[2])
    assert tight.loglik_gain < free.loglik_gain


def test_conditional_ratio_is_what_a_columns_signature_keeps_of_its_own():
    rng = np.random.default_rng(11)
    n = 4000
    base = rng.standard_normal(n)
    a = rng.standard_normal(n)
    twin = a + 0.05 * rng.standard_normal(n)      # a's signature again, up to 0.25 % of its variance
    other = rng.standard_normal(n)                # nothing in common with a
    x = np.column_stack([base, a, twin, other])
    info = x.T @ x
    # alone with the coefficients a keeps (almost) all of its information ...
    assert fx._conditional_ratio(info, 1, [0]) == pytest.approx(1.0, abs=0.01)
    # ... with its twin fitted too it keeps 1 - R^2 = 0.05^2 / (1 + 0.05^2)
    assert fx._conditional_ratio(info, 1, [0, 2]) == pytest.approx(0.0025, rel=0.15)
    # an unrelated column takes nothing
    assert fx._conditional_ratio(info, 1, [0, 3]) == pytest.approx(1.0, abs=0.01)


def test_kinematic_conflict_penalises_a_factor_the_two_sources_disagree_on():
    kin = {"factor": 1.00, "se": 0.004}
    # agreeing sources: nothing lost; the dynamics unidentified (sd = inf): nothing lost
    assert fx.kinematic_conflict({"estimate": 1.00, "sd": 0.01}, kin) == 0.0
    assert fx.kinematic_conflict(None, kin) == 0.0
    assert fx.kinematic_conflict({"estimate": 0.9, "sd": math.inf}, kin) == 0.0
    # 3 % apart with a combined sd of 0.005: (0.03 / 0.005)^2 / 2 = 18 nats
    assert fx.kinematic_conflict({"estimate": 0.97, "sd": 0.003}, kin) == pytest.approx(18.0)


def test_birge_ratio_is_one_for_noise_and_sees_offsets_the_marginals_hide():
    """The runs' coefficient vectors against their covariances: ~1 when they differ by their
    noise only; a run-to-run offset along the direction the runs pin down (A_D, C_D0 ~0.99
    correlated within a run) is seen by the full covariance though each coefficient's
    marginal spread stays within its own wide variance."""
    from bayes_roadload.analysis.effects import birge_ratio

    rng = np.random.default_rng(5)
    runs, corr = 400, 0.99
    cov = np.array([[1.0, corr], [corr, 1.0]])
    est = rng.multivariate_normal([0.0, 0.0], cov, size=runs)
    ratio, p = birge_ratio(est, np.broadcast_to(cov, (runs, 2, 2)))
    dof = (runs - 1) * 2
    assert abs(ratio - 1.0) < 3.0 / np.sqrt(2.0 * dof) and p > 0.001
    # offsets of 0.3 marginal sd along (1, -1): the direction whose variance is 1 - corr = 0.01
    off = est + 0.3 * np.outer(rng.standard_normal(runs), [1.0, -1.0])
    ratio_off, p_off = birge_ratio(off, np.broadcast_to(cov, (runs, 2, 2)))
    marginal = off.std(axis=0, ddof=1)
    assert np.all(marginal < 1.1)                       # each coefficient: within its marginal sd
    assert ratio_off > 2.0 and p_off < 1e-6             # jointly: far outside the noise


def test_fit_noise_recovers_the_local_level_noise_it_was_drawn_from():
    """Residuals drawn from the fit's own noise model (white sigma per run plus an integrated
    error of intensity q): the refitted levels are within 4 of their standard errors (from the
    likelihood's curvature at the optimum, in log space) of the truth, and no worse a fit than
    the truth or the start."""
    import jax.numpy as jnp

    rng = np.random.default_rng(7)
    runs, n, dt = 4, 400, 0.1
    sigma = np.array([0.04, 0.05, 0.06, 0.05])
    q = 0.02
    t = np.tile(np.arange(n) * dt, (runs, 1))
    walk = np.cumsum(np.concatenate([np.zeros((runs, 1)), q * np.sqrt(dt) * rng.standard_normal((runs, n - 1))], axis=1),
                     axis=1)
    resid = walk + sigma[:, None] * rng.standard_normal((runs, n))
    mask = np.ones((runs, n), bool)
    lin = SimpleNamespace(batch=SimpleNamespace(time_s=t, mask=mask), sigma_mps=np.full(runs, 0.2), q=0.2,
                          noise_fns=None)
    s_hat, q_hat = fx.fit_noise(lin, resid)
    theta = jnp.asarray(np.concatenate([np.log(s_hat), [np.log(q_hat)]]))
    objective, value_and_grad, _ = fx.noise_objective(lin)
    r = jnp.asarray(resid)
    # the curvature by central differences of the exact gradient (the likelihood's custom
    # gradient is reverse-mode only)
    grad = lambda th: np.asarray(value_and_grad(jnp.asarray(th), r)[1])  # noqa: E731
    h = 1e-4
    hess = np.stack([(grad(theta + h * e) - grad(theta - h * e)) / (2 * h) for e in np.eye(theta.size)])
    se = np.sqrt(np.diag(np.linalg.inv(0.5 * (hess + hess.T))))
    truth = np.concatenate([np.log(sigma), [np.log(q)]])
    assert np.all(np.abs(np.asarray(theta) - truth) < 4 * se)
    at = lambda th: float(objective(jnp.asarray(th), r))  # noqa: E731
    assert at(theta) <= at(truth) + 1e-9 and at(theta) < at(np.log(np.r_[lin.sigma_mps, lin.q]))


def test_a_one_parameter_effect_may_declare_its_physical_sign(tmp_path):
    """``sign`` in the library: the cup lags the air (a positive distance), the admittance's
    filter takes gust energy out (a positive gain); an estimate of the other sign is flagged; a sign on a multi-parameter effect
    or an unknown sign word is refused."""
    lib = fx.load_library()
    assert lib["anemometer_dynamics"].sign == {"cup_lag_m": 1}
    assert lib["aero_admittance"].sign == {"admittance_gain": 1}
    assert lib["anemometer_dynamics"].against_sign({"cup_lag_m": -4.0}) == {"cup_lag_m": -4.0}
    assert lib["anemometer_dynamics"].against_sign({"cup_lag_m": 1.5}) == {}
    assert lib["aero_admittance"].against_sign({"admittance_gain": -0.5}) == {"admittance_gain": -0.5}
    assert lib["track_gradient"].against_sign({"grade_rad": -0.01}) == {}
    head = '[effects.track_gradient]\nterms = ["gradient"]\nkind = "term"\n'
    bad = tmp_path / "lib.toml"
    bad.write_text(head + 'parameters.grade_rad = { prior_sd = 0.005, sign = "upward" }\n')
    with pytest.raises(ValueError, match="not one of"):
        fx.load_library(bad)
    bad.write_text('[effects.yaw_calibration]\nterms = []\nkind = "air"\n'
                   'parameters.yaw_factor = { prior_sd = 0.2, null = "model" }\n'
                   'parameters.yaw_offset_rad = { prior_sd = 0.05, sign = "positive" }\n')
    with pytest.raises(ValueError, match="one-parameter term effect"):
        fx.load_library(bad)


def test_a_family_declares_its_shape_grid_and_each_run_amplitudes(tmp_path):
    """``shape.P`` in the library: P must be a fixed parameter of a term effect; the grid spaces
    ``points`` values from ``low`` to ``high`` (log or linear, ends included); ``each_run`` is for
    term effects only.  The one shipped family is the admittance, over its filter's length (a
    log grid 2-32 m); the one each run's is a form of another candidate's effect (each run's
    tyre level)."""
    lib = fx.load_library()
    assert {n: e.shape for n, e in lib.items() if e.shape} == {
        "aero_admittance": {"admittance_length_m": (2.0, 4.0, 8.0, 16.0, 32.0)}}
    assert [e.name for e in lib.values() if e.each_run] == ["tyre_start_temperature"]
    assert lib["tyre_start_temperature"].per_run and lib["tyre_start_temperature"].cause == "tyre_temperature"
    assert not lib["tyre_temperature"].per_run and lib["run_to_run_variation"].run_coefficients
    head = ('[effects.tyre_temperature]\nterms = ["tyre_temperature_transient"]\nkind = "term"\n'
            'parameters.tyre_transient = { prior_sd = 0.2 }\n')
    bad = tmp_path / "lib.toml"
    bad.write_text(head + 'shape.tyre_time_constant_s = { low = 20.0, high = 100.0, points = 3 }\n')
    with pytest.raises(ValueError, match="a shape is a fixed parameter"):
        fx.load_library(bad)
    fixed = 'fixed = { tyre_time_constant_s = 40.0 }\n'
    for spec, match in (("{ low = 0.0, high = 100.0, points = 3 }", "log grid needs low > 0"),
                        ("{ low = 50.0, high = 20.0, points = 3 }", "low < high"),
                        ("{ low = 20.0, high = 100.0, points = 1 }", "at least 2 points"),
                        ("{ low = 20.0, high = 100.0, points = 3, scale = \"cubic\" }", "not one of"),
                        ("{ low = 20.0, points = 3 }", "needs numbers")):
        bad.write_text(head + fixed + f"shape.tyre_time_constant_s = {spec}\n")
        with pytest.raises(ValueError, match=match):
            fx.load_library(bad)
    bad.write_text('[effects.yaw_calibration]\nterms = []\nkind = "air"\neach_run = true\n'
                   'parameters.yaw_offset_rad = { prior_sd = 0.05 }\n')
    with pytest.raises(ValueError, match="each_run is for a term effect"):
        fx.load_library(bad)
    ok = tmp_path / "ok.toml"
    ok.write_text(head + fixed + 'each_run = true\n'
                  'shape.tyre_time_constant_s = { low = 10.0, high = 30.0, points = 3, scale = "linear" }\n')
    each = fx.load_library(ok)["tyre_temperature"]
    assert each.shape == {"tyre_time_constant_s": (10.0, 20.0, 30.0)}
    assert each.each_run and each.per_run and not each.run_coefficients
    ok.write_text(head + fixed + 'shape.tyre_time_constant_s = { low = 20.0, high = 1280.0, points = 7 }\n')
    tau = fx.load_library(ok)["tyre_temperature"].shape["tyre_time_constant_s"]
    assert tau[0] == 20.0 and tau[-1] == 1280.0 and len(tau) == 7 and 40.0 in tau   # rounded, not 40.000...01
    assert np.allclose(np.diff(np.log(tau)), math.log(2.0))


def test_added_parameters_count_each_run_amplitudes_and_shapes():
    """delta_elpd charges a family one parameter per shape, an each-run effect one per run, a
    run-coefficient effect one per run and coefficient less the shared one."""
    import dataclasses

    lib = fx.load_library()
    grid = {"tyre_time_constant_s": (20.0, 40.0, 80.0)}
    lib = dict(lib, tyre_temperature=dataclasses.replace(lib["tyre_temperature"], shape=grid),
               tyre_speed_exponent=dataclasses.replace(lib["tyre_speed_exponent"],
                                                       shape={"tyre_speed_exponent": (2.0, 4.0)}))
    each = dict(lib, tyre_temperature=dataclasses.replace(lib["tyre_temperature"], each_run=True))
    lin = SimpleNamespace(n_runs=6, effects={"tyre_temperature": ("tyre_transient",),
                                             "tyre_speed_exponent": ("tyre_power_coeff",),
                                             "track_gradient": ("grade_rad",),
                                             "run_to_run_variation": ("AD", "BD", "CD0")})
    assert fx.n_added_parameters(lin, ("tyre_temperature",), lib) == 1 + 1
    assert fx.n_added_parameters(lin, ("tyre_temperature",), each) == 6 + 1
    assert fx.n_added_parameters(lin, ("tyre_speed_exponent",), lib) == 1 + 1
    assert fx.n_added_parameters(lin, ("track_gradient",), lib) == 1
    assert fx.n_added_parameters(lin, ("run_to_run_variation",), lib) == 3 * 5


def test_the_rules_fingerprint_sees_a_family_but_not_the_unused_option():
    """Declaring a shape grid or each_run changes the library's SHA-256 (an option left unused
    does not); the shipped library hashes as the rules frozen in
    docs/sim_to_real/frozen_rules.json."""
    import dataclasses

    from bayes_roadload.analysis.diagnose import rules_fingerprint

    lib = fx.load_library()
    base = rules_fingerprint(lib)["library_sha256"]
    tyre = lib["tyre_temperature"]
    shaped = dict(lib, tyre_temperature=dataclasses.replace(tyre, shape={"tyre_time_constant_s": (20.0, 40.0)}))
    each = dict(lib, tyre_temperature=dataclasses.replace(tyre, each_run=True))
    hashes = {base, rules_fingerprint(shaped)["library_sha256"], rules_fingerprint(each)["library_sha256"]}
    assert len(hashes) == 3
    # the cause left at its default is not hashed: a library without the key hashes as before
    plain = dict(lib, tyre_temperature=dataclasses.replace(tyre, form_of=""))
    assert rules_fingerprint(plain)["library_sha256"] == base
    # the shipped rules are the ones frozen for the sim-to-real proof suite
    import json
    from pathlib import Path

    frozen = Path(__file__).resolve().parents[2] / "docs" / "sim_to_real" / "frozen_rules.json"
    assert json.loads(frozen.read_text())["library_sha256"] == base


@pytest.mark.slow  # a cross-check kept out of the default run's 10 minutes
def test_the_linearisation_keeps_the_values_the_users_model_holds_for_a_candidates_terms():
    """A model with the pitch term holds K_alpha and the pitch gain fixed; the pitch candidate
    is then a change of those values, so the linearisation point (every candidate at its null)
    is the user's fit: the super-model's speeds there are the model's own, not those of a model
    without pitch."""
    import jax.numpy as jnp

    from bayes_roadload.analysis.batch import SimulatedCampaign
    from bayes_roadload.inference.bayes import build_problem
    from bayes_roadload.inference.nuts import initial_values
    from bayes_roadload.physics.integrate import integrate_batch
    from bayes_roadload.simulate.cases import get_case

    campaign = SimulatedCampaign(get_case(1), pairs=1, seed=0)()
    problem = build_problem(campaign, "four_term_tyre_lag_admittance_pitch")
    assert problem.fixed["Kalpha"] == 0.9 and problem.fixed["pitch_gain"] == 0.0103
    init = initial_values(problem, campaign)
    model, available, values, effects, _ = fx.linearisation_point(problem, init, fx.load_library())
    assert available["pitch_attitude"] is None and effects["pitch_attitude"] == ("Kalpha",)
    assert values["Kalpha"] == 0.9 and values["pitch_gain"] == 0.0103
    v0 = jnp.asarray(init["v0_mps"])
    own = {k: jnp.asarray(v) for k, v in {**problem.fixed, **{p: init[p] for p in problem.free}}.items()}
    base = np.asarray(integrate_batch(problem.model, own, problem.batch, v0)[0])
    at_null = np.asarray(integrate_batch(model, {k: jnp.asarray(v) for k, v in values.items()}, problem.batch, v0)[0])
    mask = np.asarray(problem.batch.mask)
    np.testing.assert_allclose(np.where(mask, at_null, 0.0), np.where(mask, base, 0.0), rtol=0, atol=1e-9)
    # the library's null (K_alpha 0) is a model without pitch: a different trace
    no_pitch = np.asarray(integrate_batch(problem.model, {**own, "Kalpha": jnp.asarray(0.0)}, problem.batch, v0)[0])
    assert np.max(np.abs(np.where(mask, no_pitch - base, 0.0))) > 1e-3


def test_a_model_with_the_admittance_makes_the_filter_candidate_not_applicable():
    """A model that reads the felt air already (``admittance = "auto"`` with the vehicle's
    length) would have the admittance candidate filter it a second time: not applicable, and
    said why; the same problem without the model's filter keeps the candidate."""
    from bayes_roadload.analysis.batch import SimulatedCampaign
    from bayes_roadload.inference.bayes import build_problem
    from bayes_roadload.simulate.cases import get_case

    campaign = SimulatedCampaign(get_case(1), pairs=1, seed=0)()
    problem = build_problem(campaign, "four_term_tyre_lag_admittance_pitch")
    length = problem.spec.resolve_admittance(campaign)
    assert length > 0.0
    init = problem.initial  # availability reads no fitted value: the model's starting values serve
    library = fx.load_library()
    _, available, _, effects, _ = fx.linearisation_point(problem, init, library, length)
    assert "applies the vehicle's admittance already" in available["aero_admittance"]
    assert "aero_admittance" not in effects and available["anemometer_dynamics"] is None
    _, available, _, effects, _ = fx.linearisation_point(problem, init, library)
    assert available["aero_admittance"] is None and effects["aero_admittance"] == ("admittance_gain",)
