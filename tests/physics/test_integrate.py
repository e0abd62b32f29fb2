"""The RK4 integrator: closed form (appendix D), order of convergence, padding, gradients."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from bayes_roadload import config
from bayes_roadload.physics import (
    air_density_kgpm3,
    full_model,
    integrate_batch,
    integrate_run,
    make_run,
    quadratic_coastdown_speed,
    quadratic_coastdown_time,
    simplified_model,
    stack_runs,
)

M, ME, AREA = 1100.0, 1130.0, 1.85
VEHICLE = {"mass_kg": M, "effective_mass_kg": ME, "frontal_area_m2": AREA}
RHO = float(air_density_kgpm3())
COEF = {"AD": 0.01, "BD": 2.0e-4, "CD0": 0.4, "KD": 0.614}


def quadratic_abc(p=COEF):
    return M * config.GRAVITY_MPS2 * p["AD"], M * config.GRAVITY_MPS2 * p["BD"], 0.5 * RHO * AREA * p["CD0"]


def test_make_run_needs_the_vehicle():
    """No default vehicle: a run without its mass, effective mass and area is refused."""
    t = np.arange(0.0, 1.0, 0.25)
    with pytest.raises(TypeError, match="mass_kg"):
        make_run(t, np.full_like(t, 30.0))
    run = make_run(t, np.full_like(t, 30.0), **VEHICLE)
    assert (float(run.mass_kg), float(run.effective_mass_kg), float(run.frontal_area_m2)) == (M, ME, AREA)


def test_closed_form_appendix_d():
    """Still air, F = a + b v + c v^2: RK4 at the thesis' 4 Hz matches appendix D to < 1e-9."""
    t = np.arange(0.0, 110.0, 0.25)
    run = make_run(t, np.full_like(t, 31.3), **VEHICLE)
    v, s = integrate_run(simplified_model(air="still"), COEF, run)
    a, b, c = quadratic_abc()
    exact = quadratic_coastdown_speed(t, 31.3, a, b, c, ME)
    rel = np.max(np.abs(np.asarray(v) - exact) / exact)
    assert rel < 1e-9, rel
    # and the time form of appendix D inverts the speed form
    back = quadratic_coastdown_time(exact, 31.3, a, b, c, ME)
    np.testing.assert_allclose(back, t, atol=1e-8)
    # distance is the integral of speed: trapezoid on the exact speed agrees to O(dt^2)
    trap = np.concatenate([[0.0], np.cumsum(0.5 * (exact[1:] + exact[:-1]) * 0.25)])
    np.testing.assert_allclose(s, trap, rtol=1e-4)


@pytest.mark.parametrize("stride", [pytest.param(1, marks=pytest.mark.slow), 2])  # 2: the default integrator
def test_fourth_order_convergence(stride):
    """Max error over the run falls as h^4 with the RK4 step h (full nonlinear model, steady
    wind, pitch), whether a step spans one sample interval or two."""
    model = full_model(air="wind")
    p = dict(COEF, head_wind_mps=2.0, cross_wind_mps=3.0)
    t_end = 96.0
    fine = np.arange(0.0, t_end + 0.1, 0.25)
    v_ref = np.asarray(integrate_run(model, p, make_run(fine, np.full_like(fine, 31.0), **VEHICLE), 31.0,
                                     IntegratorConfig_(64))[0])[::16]  # every 4 s
    errors = []
    for h in (4.0, 2.0, 1.0, 0.5):
        dt = h / stride
        t = np.arange(0.0, t_end + dt / 2, dt)
        v = np.asarray(integrate_run(model, p, make_run(t, np.full_like(t, 31.0), **VEHICLE), 31.0,
                                     config.IntegratorConfig(stride=stride))[0])
        errors.append(np.max(np.abs(v[:: int(4.0 / dt)] - v_ref)))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    # RK4: halving dt divides the error by ~16 (order 4).  Measured 3.89, 3.95, 3.98; the
    # band 3.7-4.3 fails for a 3rd- or 5th-order scheme.
    assert np.all((orders > 3.7) & (orders < 4.3)), (errors, orders)


def IntegratorConfig_(substeps):
    return config.IntegratorConfig(substeps=substeps)


def test_substeps_agree_with_finer_grid():
    t = np.arange(0.0, 20.0, 0.25)
    run = make_run(t, np.full_like(t, 30.0), **VEHICLE)
    model = simplified_model(air="still")
    coarse = integrate_run(model, COEF, run, integrator=IntegratorConfig_(4))[0]
    fine_t = np.arange(0.0, 20.0 - 0.25 + 1e-9, 0.0625)
    fine = integrate_run(model, COEF, make_run(fine_t, np.full_like(fine_t, 30.0), **VEHICLE))[0]
    np.testing.assert_allclose(coarse, fine[::4], rtol=1e-12)


def test_inputs_interpolated_at_half_steps():
    """A yaw ramp is exactly linear, so RK4 with interpolated inputs equals RK4 on a grid
    twice as fine that is given the ramp values at the half steps."""
    model = simplified_model()
    t = np.arange(0.0, 30.0, 0.5)
    yaw = 0.02 * t
    v = np.full_like(t, 30.0)
    run = make_run(t, v, airspeed_mps=v, yaw_rad=yaw, **VEHICLE)
    a = integrate_run(model, COEF, run)[0]
    tf = np.arange(0.0, 29.5 + 1e-9, 0.25)
    b = integrate_run(model, COEF, make_run(tf, np.full_like(tf, 30.0), airspeed_mps=np.full_like(tf, 30.0),
                                            yaw_rad=0.02 * tf, **VEHICLE), integrator=IntegratorConfig_(1))[0]
    # the coarse run holds 2 RK4 stages at the midpoint; the fine run 1 step per half: both
    # integrate the same smooth forcing, agreement to RK4 accuracy at these step sizes
    np.testing.assert_allclose(a, b[::2], rtol=1e-9)


def test_padding_and_per_run_parameters():
    """Padded runs of unequal length give the same speeds as unpadded single runs, and a
    parameter of shape [R] is applied per run."""
    model = simplified_model(air="still")
    t1, t2 = np.arange(0.0, 50.0, 0.25), np.arange(0.0, 80.0, 0.25)
    r1 = make_run(t1, np.full_like(t1, 25.0), direction=1.0, **VEHICLE)
    r2 = make_run(t2, np.full_like(t2, 31.0), direction=-1.0, **VEHICLE)
    batch = stack_runs([r1, r2])
    assert batch.time_s.shape == (2, t2.size)
    assert int(batch.mask[0].sum()) == t1.size and bool(batch.mask[1].all())
    ad = jnp.array([0.010, 0.012])
    vb, _ = integrate_batch(model, dict(COEF, AD=ad), batch)
    v1 = integrate_run(model, dict(COEF, AD=0.010), r1)[0]
    v2 = integrate_run(model, dict(COEF, AD=0.012), r2)[0]
    np.testing.assert_allclose(vb[0, : t1.size], v1, rtol=1e-13)
    np.testing.assert_allclose(vb[1], v2, rtol=1e-13)
    # padded samples hold the last value (dt = 0)
    np.testing.assert_allclose(vb[0, t1.size:], v1[-1], rtol=1e-13)


@pytest.mark.parametrize("name", ["AD", "BD", "CD0", "KD"])
def test_gradient_matches_finite_differences(name):
    """d(sum of squared speed residuals)/d(parameter) by autodiff vs central differences."""
    model = simplified_model()
    t = np.arange(0.0, 60.0, 0.25)
    rng = np.random.default_rng(3)
    yaw = 0.1 * np.sin(0.2 * t) + 0.01 * rng.standard_normal(t.size)
    v_meas = np.asarray(quadratic_coastdown_speed(t, 31.0, *quadratic_abc(), ME)) + 0.05 * rng.standard_normal(t.size)
    run = make_run(t, v_meas, airspeed_mps=v_meas + 2.0, yaw_rad=yaw, **VEHICLE)
    scale = config.PARAMETER_SCALES[name]

    def loss(x):
        v, _ = integrate_run(model, dict(COEF, **{name: x * scale}), run)
        return jnp.sum((v - run.speed_mps) ** 2)

    x0 = COEF[name] / scale * 1.03
    g = float(jax.grad(loss)(x0))
    h = 1e-5
    fd = (float(loss(x0 + h)) - float(loss(x0 - h))) / (2 * h)
    assert abs(g - fd) <= 1e-6 * max(abs(fd), 1e-3), (g, fd)


def test_batch_is_jittable_and_differentiable():
    model = simplified_model()
    t = np.arange(0.0, 20.0, 0.25)
    batch = stack_runs([make_run(t, np.full_like(t, 30.0), yaw_rad=0.05, **VEHICLE),
                        make_run(t[:50], np.full(50, 28.0), **VEHICLE)])
    f = jax.jit(lambda cd: integrate_batch(model, dict(COEF, CD0=cd), batch)[0].sum())
    assert np.isfinite(f(0.4))
    assert float(jax.grad(f)(0.4)) < 0.0  # more drag, lower speeds


def test_forward_sensitivity_gradient_equals_reverse_mode():
    """Same values, and the same gradient with respect to shared, per-run and initial-speed
    inputs, as reverse-mode through the scan."""
    from bayes_roadload.physics import integrate_batch_forward_sensitivity

    model = simplified_model()
    rng = np.random.default_rng(5)
    runs = []
    for n, d in ((80, 1.0), (60, -1.0), (90, 1.0)):
        t = np.arange(n) * 0.25
        runs.append(make_run(t, 30.0 - 0.2 * t + 0.05 * rng.standard_normal(n), airspeed_mps=32.0 - 0.2 * t,
                             yaw_rad=0.05 * np.sin(t), direction=d, **VEHICLE))
    batch = stack_runs(runs)
    fixed = {"KD": 0.614}
    weights = jnp.asarray(rng.standard_normal(batch.time_s.shape)) * batch.mask

    def loss_fs(ad, cd, v0):
        v = integrate_batch_forward_sensitivity(model, fixed, {"AD": ad, "CD0": cd}, batch, v0)
        return jnp.sum(weights * v**2)

    def loss_rev(ad, cd, v0):
        v = integrate_batch(model, dict(fixed, AD=ad, CD0=cd), batch, v0)[0]
        return jnp.sum(weights * v**2)

    ad, cd, v0 = 0.01, jnp.array([0.40, 0.41, 0.39]), jnp.array([30.0, 29.5, 30.2])
    np.testing.assert_allclose(loss_fs(ad, cd, v0), loss_rev(ad, cd, v0), rtol=1e-14)
    g1 = jax.grad(loss_fs, argnums=(0, 1, 2))(ad, cd, v0)
    g2 = jax.grad(loss_rev, argnums=(0, 1, 2))(ad, cd, v0)
    for a, b in zip(g1, g2):
        np.testing.assert_allclose(a, b, rtol=1e-9)


@pytest.mark.parametrize("n_samples", [200, 201])
def test_two_interval_steps_keep_every_input(n_samples):
    """One RK4 step per two sample intervals (the fit's default) integrates a noisy logged
    input as one step per sample does: with a force linear in the input (a measured driveline
    force with 30 N noise) they agree at every sample, middle samples included (measured
    6e-6 m/s, 1/5000 of a typical speed noise), for odd and even numbers of intervals.
    Taking the middle sample's input at the half step instead (Simpson weights) is off by
    0.036 m/s on the same run."""
    rng = np.random.default_rng(4)
    t = np.arange(n_samples) * 0.25
    drive = 40.0 + rng.normal(0.0, 30.0, t.size)
    run = make_run(t, np.full_like(t, 30.0), driveline_force_n=drive, **VEHICLE)
    model = simplified_model(driveline="measured", air="still")
    one = np.asarray(integrate_run(model, COEF, run, integrator=config.IntegratorConfig(stride=1))[0])
    two = np.asarray(integrate_run(model, COEF, run, integrator=config.IntegratorConfig(stride=2))[0])
    assert two.shape == one.shape
    assert np.max(np.abs(two - one)) < 5e-5, np.max(np.abs(two - one))


@pytest.mark.slow  # a cross-check kept out of the default run's 10 minutes
def test_linear_equation_of_motion_is_solved_in_parallel_with_the_same_result():
    """With measured air the thesis' terms (tyres, lift unloading, aero with yaw, side-force
    slip, pitch attitude, measured driveline, undriven wheels) make the deceleration affine in
    the speed; the parallel solution (cumulative sums of the RK4 steps' affine maps) equals the
    step-by-step scan to rounding, for speed and distance, odd and even sample counts, and
    its gradient too.  A quadratic driveline polynomial is not affine and keeps the scan."""
    rng = np.random.default_rng(6)
    model = full_model(driveline="measured", undriven=True)
    assert model.speed_affine
    assert not full_model(driveline="polynomial").speed_affine
    assert not simplified_model(air="still").speed_affine
    runs = []
    for n in (301, 300):
        t = np.arange(n) * 0.25
        air = 30.0 - 0.08 * t + rng.normal(0, 0.3, n)
        runs.append(make_run(t, 31.0 - 0.08 * t, airspeed_mps=air, yaw_rad=rng.normal(0.05, 0.05, n),
                             driveline_force_n=40 + rng.normal(0, 20, n), **VEHICLE))
    batch = stack_runs(runs)
    seq = config.IntegratorConfig(stride=2, parallel=False)
    par = config.IntegratorConfig(stride=2, parallel=True)
    p = dict(COEF, Au=5.0, Bu=0.5)
    v_seq, s_seq = integrate_batch(model, p, batch, integrator=seq)
    v_par, s_par = integrate_batch(model, p, batch, integrator=par)
    np.testing.assert_allclose(v_par, v_seq, rtol=1e-12, atol=1e-11)
    np.testing.assert_allclose(s_par, s_seq, rtol=1e-11, atol=1e-9)

    def loss(cfg):
        return lambda c: jnp.sum(integrate_batch(model, dict(p, CD0=c), batch, integrator=cfg)[0] ** 2)

    assert float(jax.grad(loss(par))(0.4)) == pytest.approx(float(jax.grad(loss(seq))(0.4)), rel=1e-10)


@pytest.mark.slow
def test_the_stage_coefficients_are_computed_once_in_the_compiled_gradient():
    """The parallel solution holds the runs' stage coefficients in one conditional
    (``integrate._hold``) so that XLA does not copy the force terms' arithmetic into every
    fused loop of the gradient: the compiled gradient keeps that conditional (were XLA to
    fold it, the speed-up would silently go), and the batch equals each run solved on its
    own to rounding, values and gradient."""
    rng = np.random.default_rng(3)
    model = full_model(driveline="measured")
    t = np.arange(200) * 0.25
    runs = [make_run(t, 31.0 - 0.08 * t, airspeed_mps=30.0 - 0.08 * t + rng.normal(0, 0.3, t.size),
                     yaw_rad=rng.normal(0.05, 0.05, t.size), driveline_force_n=40 + rng.normal(0, 20, t.size),
                     **VEHICLE) for _ in range(3)]
    batch = stack_runs(runs)

    def held(c):
        return jnp.sum(integrate_batch(model, dict(COEF, CD0=c), batch)[0] ** 2)

    def one_by_one(c):
        return sum(jnp.sum(integrate_run(model, dict(COEF, CD0=c), run)[0] ** 2) for run in runs)

    assert " conditional(" in jax.jit(jax.grad(held)).lower(0.4).compile().as_text()
    assert float(held(0.4)) == pytest.approx(float(one_by_one(0.4)), rel=1e-13)
    assert float(jax.grad(held)(0.4)) == pytest.approx(float(jax.grad(one_by_one)(0.4)), rel=1e-10)


def test_a_trajectory_past_standstill_continues_at_the_forces_of_standstill():
    """Still air (drag quadratic in the ground speed): past v = 0 the speed goes on falling at
    the deceleration of standstill, a(0) = -M g A_D / M_e, with no runaway (a quadratic drag in
    the negative speed would reach -inf), the distance never goes backwards, and the speed at
    the end keeps its gradient in the parameters: holding a stopped vehicle at zero made it
    exactly 0 there, a flat region joined to the moving one by a kink, on which NUTS' step size
    collapsed."""
    from bayes_roadload.physics.model import DragModel, StillAir
    from bayes_roadload.physics.terms import AeroDrag, TyreRolling

    model = DragModel(terms=(TyreRolling(), AeroDrag()), air=StillAir())
    t = np.arange(0.0, 400.0, 0.25)
    run = make_run(t, np.full(t.shape, 3.0), **VEHICLE)
    p = {"AD": 0.02, "BD": 2e-4, "CD0": 0.4, "KD": 0.6}
    v, s = integrate_run(model, p, run, 3.0)
    v = np.asarray(v)
    assert np.all(np.isfinite(v)) and v[200] < 0.5
    stopped = v < 0.0
    assert stopped[-1] and not stopped[0]
    a0 = -M * config.GRAVITY_MPS2 * p["AD"] / ME          # TyreRolling at v = 0: M g (A_D + B_D 0)
    after = np.flatnonzero(stopped)[1:]
    np.testing.assert_allclose(np.diff(v)[after - 1] / 0.25, a0, rtol=1e-9)
    assert np.all(np.diff(np.asarray(s)) >= 0.0)  # distance never goes backwards
    end = jax.grad(lambda ad: integrate_run(model, dict(p, AD=ad), run, 3.0)[0][-1])(0.02)
    # d v_end / d A_D: -g M / M_e per second after the crossing, plus the earlier crossing
    assert float(end) < -M * config.GRAVITY_MPS2 / ME * (t[-1] - t[np.flatnonzero(stopped)[0]])


@pytest.mark.parametrize("model_name", ["four_term_driveline", "speed_only_wind"])
def test_reversion_rate_is_the_integrators_own_decay_of_a_speed_error(model_name):
    """kappa = -d(dv/dt)/dv along the trajectory (logged inputs held) is the linearised
    equation of motion: exp(-int kappa), as the product of the factors phi_k, equals the
    integrator's own sensitivity of the speed to the initial speed (forward-mode JVP) up to
    the trapezoid rule on a smooth kappa (the two agree to ~1e-6 in log; bound 1e-4).  With a
    measured airspeed only the tyres' B_D and the driveline feed back (kappa ~ 0.003 /s); with
    the relative air computed from the speed the aerodynamic force does too (kappa up to ~10x)."""
    from bayes_roadload.inference.bayes import build_problem, run_parameters
    from bayes_roadload.physics.integrate import reversion_rate
    from bayes_roadload.physics.residuals import reversion_factors
    from bayes_roadload.simulate import simulate_campaign

    campaign = simulate_campaign(2, pairs=1, seed=0, driveline=True)
    problem = build_problem(campaign, model_name)
    values = {k: jnp.asarray(float(campaign.truth[k])) for k in problem.free if k in campaign.truth}
    if problem.latent_wind:
        values["head_wind_mps"] = jnp.asarray([2.0])  # case 2: 2 m/s head wind on the + run
    params = run_parameters(problem, values)
    v0 = jnp.asarray(problem.batch.speed_mps)[:, 0]
    speed, sensitivity = jax.jvp(lambda x: integrate_batch(problem.model, params, problem.batch, x)[0],
                                 (v0,), (jnp.ones_like(v0),))
    kappa = np.asarray(reversion_rate(problem.model, params, problem.batch, speed))
    mask = np.asarray(problem.batch.mask)
    assert np.all(kappa[mask] > 0)
    phi = np.asarray(reversion_factors(problem.batch.time_s, problem.batch.mask, jnp.asarray(kappa)))
    np.testing.assert_allclose(np.log(np.cumprod(phi, axis=1))[mask], np.log(np.asarray(sensitivity))[mask], atol=1e-4)
    assert np.all(kappa[~mask] == 0.0)
