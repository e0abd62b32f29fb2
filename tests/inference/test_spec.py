"""Tests of the model-variant files (``models/*.toml``) and their resolution against campaigns."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.thesis import THESIS_COEFFICIENTS, THESIS_DRIVELINE, THESIS_TUNNEL_TABLE
from bayes_roadload.data import Anemometer, Campaign, Vehicle
from bayes_roadload.inference import ModelSpecError, available_models, load_model_spec
from bayes_roadload.inference.spec import MODELS_DIR, Prior, without_free
from bayes_roadload.physics import MeasuredAir, StillAir

REQUIRED = ("four_term", "four_term_driveline", "three_term", "tunnel_table", "two_term_tyres")
TUNNEL = {"KD": 0.58, "CL0": 0.273, "KL": 3.64,
          "yaw_deg": [-20.0, 0.0, 20.0], "cd": [0.47, 0.40, 0.47]}


def make_campaign(*, anemometer=True, driveline=False, tunnel=TUNNEL, factors=(1.08, 0.87)):
    """Two 20-sample runs (no integration needed: specs only look at the channels)."""
    t = np.arange(20) * 0.25
    frames = []
    for run, d in ((1, 1.0), (2, -1.0)):
        df = pd.DataFrame({"run": run, "direction": d, "time_s": t, "speed_mps": 30.0 - 0.5 * t})
        if anemometer:
            df["airspeed_mps"], df["yaw_rad"] = 31.0 - 0.5 * t, 0.05 * d
        if driveline:
            df["driveline_force_n"] = 40.0
        frames.append(df)
    return Campaign(pd.concat(frames, ignore_index=True), Vehicle(1100.0, 1130.0, 1.85),
                    anemometer=Anemometer(*factors), tunnel=None if tunnel is None else dict(tunnel))


def test_required_model_files_exist_and_load():
    assert set(REQUIRED) <= set(available_models())
    for name in REQUIRED:
        spec = load_model_spec(name)
        assert spec.name == name
        assert spec.description
        # every free parameter has a weakly informative prior and a start value
        assert set(spec.priors) == set(spec.free) == set(spec.initial)
        for p, prior in spec.priors.items():
            d = prior.to_numpyro()
            assert math.isfinite(float(d.log_prob(prior.center))), (name, p)
            # weakly informative: the thesis' value is within 2 prior scales of the centre
            thesis = {**THESIS_COEFFICIENTS, **THESIS_DRIVELINE}[p]
            assert abs(thesis - prior.loc) <= 2 * prior.scale, (name, p)


def test_free_and_fixed_parameters_of_each_variant():
    assert load_model_spec("four_term").free == ("AD", "BD", "CD0", "KD")
    assert load_model_spec("four_term_driveline").free == ("AD", "BD", "CD0", "KD", "At", "Bt", "Ct")
    assert load_model_spec("four_term_driveline").driveline == "polynomial"
    three = load_model_spec("three_term")
    assert three.free == ("AD", "BD", "CD0") and three.fixed == {"KD": "tunnel"}
    assert three.fallback == {"KD": 0.614}
    two = load_model_spec("two_term_tyres")
    assert two.free == ("AD", "BD") and two.fixed == {"CD0": "tunnel", "KD": "tunnel"}
    assert two.fallback == {"CD0": 0.39, "KD": 0.614}
    table = load_model_spec("tunnel_table")
    assert "aero_drag_table" in table.terms and table.free == ("AD", "BD", "CD0")


def test_explicit_path_and_missing_name(tmp_path):
    spec = load_model_spec(MODELS_DIR / "four_term.toml")
    assert spec.name == "four_term"
    with pytest.raises(ModelSpecError, match="not found.*four_term"):
        load_model_spec("five_term")


@pytest.mark.parametrize("name", REQUIRED)
def test_every_variant_builds_against_a_campaign(name):
    spec = load_model_spec(name)
    model, fixed, free = spec.build(make_campaign())
    assert free == spec.free
    assert set(free).isdisjoint(fixed)
    assert set(free) | set(fixed) == set(model.parameter_names)
    assert isinstance(model.air, MeasuredAir)
    assert (fixed["airspeed_factor"], fixed["yaw_factor"]) == (1.08, 0.87)
    # lift unloading (thesis eq. 6.1) with C_L0 / K_L from the campaign's tunnel table
    assert "lift_unloading" in model.term_names
    assert (fixed["CL0"], fixed["KL"]) == (0.273, 3.64)


def test_tunnel_values_fallbacks_and_tables():
    _, fixed, _ = load_model_spec("three_term").build(make_campaign())
    assert fixed["KD"] == 0.58  # from the campaign's [tunnel]
    model, fixed, _ = load_model_spec("three_term").build(make_campaign(tunnel=None))
    assert fixed["KD"] == 0.614  # the fallback
    assert "lift_unloading" not in model.term_names  # no tunnel C_L: no lift term
    _, fixed, _ = load_model_spec("two_term_tyres").build(make_campaign())
    assert fixed["CD0"] == 0.39  # the tunnel table gives no CD0 here
    _, fixed, _ = load_model_spec("two_term_tyres").build(make_campaign(tunnel={**TUNNEL, "CD0": 0.401}))
    assert fixed["CD0"] == 0.401
    model, _, _ = load_model_spec("tunnel_table").build(make_campaign())
    (term,) = [t for t in model.terms if t.name == "aero_drag_table"]
    assert term.yaw_deg == (-20.0, 0.0, 20.0) and term.cd == (0.47, 0.40, 0.47)
    model, _, _ = load_model_spec("tunnel_table").build(make_campaign(tunnel=None))
    (term,) = [t for t in model.terms if t.name == "aero_drag_table"]
    assert list(term.cd) == THESIS_TUNNEL_TABLE["cd"]


def test_auto_driveline_and_air():
    spec = load_model_spec("four_term")
    model, fixed, _ = spec.build(make_campaign(driveline=True))
    assert "driveline_measured" in model.term_names
    model, fixed, _ = spec.build(make_campaign(anemometer=False))
    assert isinstance(model.air, StillAir) and "airspeed_factor" not in fixed
    assert not any(t.startswith("driveline") for t in model.term_names)
    model, _, _ = load_model_spec("four_term_driveline").build(make_campaign(driveline=True))
    assert "driveline_polynomial" in model.term_names and "driveline_measured" not in model.term_names


# ----------------------------------------------------------------------------- refusals

GOOD = """
[model]
terms = ["tyre_rolling", "aero_drag"]
lift = "none"
[parameters.AD]
free = true
prior = { dist = "normal", loc = 0.01, scale = 0.01 }
[parameters.KD]
fixed = 0.614
"""


def _write(tmp_path, text, name="bad.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_a_good_file_loads(tmp_path):
    spec = load_model_spec(_write(tmp_path, GOOD, "mine.toml"))
    assert spec.name == "mine" and spec.free == ("AD",) and spec.fixed == {"KD": 0.614}
    assert spec.priors["AD"] == Prior("normal", 0.01, 0.01) and spec.initial == {"AD": 0.01}
    assert spec.uncertainty == {}
    with_u = load_model_spec(_write(tmp_path, GOOD.replace("fixed = 0.614", "fixed = 0.614\nuncertainty = 0.2"),
                                    "mine_u.toml"))
    assert with_u.uncertainty == {"KD": 0.2} and with_u.fixed == {"KD": 0.614}
    assert with_u.uncertainty_distribution == {}  # normal about the fixed number
    above = load_model_spec(_write(tmp_path, GOOD.replace(
        "fixed = 0.614", 'fixed = 0.614\nuncertainty = 0.2\nuncertainty_distribution = "above"'), "mine_a.toml"))
    assert above.uncertainty_distribution == {"KD": "above"}


@pytest.mark.parametrize("edit, key, message", [
    (('"aero_drag"]', '"aero_drag", "aero_drift"]'), "[model] terms", "unknown drag term 'aero_drift'"),
    (('"aero_drag"]', '"aero_drag", "lift_unloading"]'), "[model] terms", "controlled by [model] lift"),
    (("[parameters.KD]", "[parameters.XD]"), "[parameters.XD]", "unknown parameter"),
    (("fixed = 0.614", "fixed = 0.614\nfree = true"), "[parameters.KD]", "both free and fixed"),
    (('dist = "normal"', 'dist = "cauchy"'), "[parameters.AD] prior.dist", "unknown distribution 'cauchy'"),
    (("scale = 0.01 }", "scale = -0.01 }"), "[parameters.AD] prior.scale", "must be positive"),
    ((", scale = 0.01 }", " }"), "[parameters.AD] prior.scale", "required by a normal prior"),
    (("scale = 0.01 }", "scale = 0.01, df = 3 }"), "[parameters.AD] prior.df", "not a parameter of a normal prior"),
    (("[parameters.KD]", "[parameters.At]\nfree = true\n[parameters.KD]"), "[parameters.At]", "not used by the model's terms"),
    (('lift = "none"', 'lift = "wing"'), "[model] lift", "choose one of tunnel, none"),
    (('lift = "none"', 'lift = "none"\ndriveline = "gearbox"'), "[model] driveline", "choose one of"),
    (('lift = "none"', 'lift = "none"\ncolour = "red"'), "[model] colour", "unknown key"),
    (("fixed = 0.614", 'fixed = "wind tunnel"'), "[parameters.KD]", "neither a finite number nor \"tunnel\""),
    (("fixed = 0.614", "fixed = 0.614\nprior = { dist = \"half_normal\", scale = 1.0 }"), "[parameters.KD]", "needs free = true"),
    (("fixed = 0.614", "free = false"), "[parameters.KD]", "say free = true or fixed"),
    (("[model]", "[modle]\n[model]"), "[modle]", "unknown table"),
    (("fixed = 0.614", "fixed = 0.614\nuncertainty = -0.1"), "[parameters.KD].uncertainty", "standard uncertainty >= 0"),
    (("fixed = 0.614", 'fixed = "tunnel"\nfallback = 0.6\nuncertainty = 0.1'), "[parameters.KD].uncertainty",
     "only for a parameter fixed at a number"),
    (("free = true\nprior", "free = true\nuncertainty = 0.001\nprior"), "[parameters.AD].uncertainty",
     "only for a parameter fixed at a number"),
    (("fixed = 0.614", 'fixed = 0.614\nuncertainty = "0.1"'), "[parameters.KD] uncertainty", "not a finite number"),
    (("fixed = 0.614", 'fixed = 0.614\nuncertainty_distribution = "above"'), "[parameters.KD].uncertainty_distribution",
     "only beside an uncertainty"),
    (("fixed = 0.614", 'fixed = 0.614\nuncertainty = 0.1\nuncertainty_distribution = "below"'),
     "[parameters.KD].uncertainty_distribution", "one of normal, above"),
])
def test_bad_specs_are_refused_naming_file_and_key(tmp_path, edit, key, message):
    old, new = edit
    assert old in GOOD
    path = _write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(ModelSpecError) as err:
        load_model_spec(path)
    text = str(err.value)
    assert str(path) in text, text
    assert key in text, text
    assert message in text, text


def test_refusals_at_build_time_name_the_key(tmp_path):
    measured = _write(tmp_path, GOOD.replace('lift = "none"', 'lift = "none"\ndriveline = "measured"'))
    with pytest.raises(ModelSpecError, match=r"bad\.toml.*driveline = \"measured\".*driveline_force_n"):
        load_model_spec(measured).build(make_campaign())
    tunnel = _write(tmp_path, GOOD.replace("fixed = 0.614", 'fixed = "tunnel"'), "tunnel.toml")
    spec = load_model_spec(tunnel)
    assert spec.build(make_campaign())[1]["KD"] == 0.58
    with pytest.raises(ModelSpecError, match=r"tunnel\.toml.*\[parameters\.KD\].*no fallback"):
        spec.build(make_campaign(tunnel=None))
    air = _write(tmp_path, GOOD.replace('lift = "none"', 'lift = "none"\nair = "measured"'), "air.toml")
    with pytest.raises(ModelSpecError, match=r"air\.toml.*air = \"measured\""):
        load_model_spec(air).build(make_campaign(anemometer=False))


def test_not_toml(tmp_path):
    with pytest.raises(ModelSpecError, match=r"bad\.toml: not valid TOML"):
        load_model_spec(_write(tmp_path, "[model\nterms = 3"))


def test_lower_truncated_normal_keeps_its_density_and_samples_through_a_scaled_softplus():
    """A normal prior truncated from below has numpyro's TruncatedNormal density (checked
    against scipy's truncnorm); its bijection is y = low + s softplus(x) with s = 0.05 x scale:
    inverse round trip, slope within 5 % of s from 3 s above the bound (sigmoid(3) = 0.953)."""
    import jax.numpy as jnp
    from numpyro.distributions.transforms import biject_to
    from scipy import stats

    from bayes_roadload.inference.spec import SOFTPLUS_FRACTION, Prior

    loc, scale, low = 0.6, 1.0, 0.1
    d = Prior("normal", loc, scale, low).to_numpyro()
    y = np.linspace(0.1001, 4.0, 50)
    expected = stats.truncnorm.logpdf(y, (low - loc) / scale, np.inf, loc=loc, scale=scale)
    np.testing.assert_allclose(np.asarray(d.log_prob(jnp.asarray(y))), expected, rtol=1e-10)
    t = biject_to(d.support)
    s = SOFTPLUS_FRACTION * scale
    x = jnp.linspace(-8.0, 60.0, 200)
    np.testing.assert_allclose(np.asarray(t(x)), low + s * np.logaddexp(0.0, np.asarray(x)), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(t.inv(t(x))), np.asarray(x), atol=1e-9)
    import jax

    slope = np.asarray(jax.vmap(jax.grad(lambda u: t(u)))(x))
    above = np.asarray(t(x)) >= low + 3 * s
    assert np.all(slope[above] >= 0.95 * s) and np.all(slope <= s * (1 + 1e-12))


def test_a_posterior_piled_against_its_bound_is_no_wall_at_the_softness_for_it():
    """K_D's prior N(0.6, 1) cut at 0 alone (its posterior in calm air), in its softplus
    coordinate: the largest curvature of the potential over the central 99.9 % of the mass,
    times the coordinate's variance, is 1 for a Gaussian; a leapfrog step of one standard
    deviation is stable while it is below 4 (step^2 x curvature < 4).  The softness for a
    posterior that reaches its bound stays below; the default softness, which keeps ridges
    straight away from the bound, does not (the reason for the two)."""
    import jax
    import jax.numpy as jnp
    from numpyro.distributions.transforms import biject_to

    from bayes_roadload.inference.spec import SOFTPLUS_FRACTION, SOFTPLUS_FRACTION_AT_BOUND

    def wall(softness):
        d = Prior("normal", 0.6, 1.0, 0.0, softness=softness).to_numpyro()
        t = biject_to(d.support)
        assert float(t(jnp.asarray(0.0))) == pytest.approx(np.log(2.0) * (softness or SOFTPLUS_FRACTION))

        def potential(x):
            y = t(x)
            return -(d.log_prob(y) + t.log_abs_det_jacobian(x, y))

        x = jnp.linspace(-80.0, 80.0, 32001)
        p = np.exp(-np.asarray(jax.vmap(potential)(x)))
        p /= p.sum()
        mean = float((np.asarray(x) * p).sum())
        var = float(((np.asarray(x) - mean) ** 2 * p).sum())
        cdf = np.cumsum(p)
        inside = slice(int(np.searchsorted(cdf, 0.0005)), int(np.searchsorted(cdf, 0.9995)))
        curvature = np.asarray(jax.vmap(jax.grad(jax.grad(potential)))(x[inside]))
        return float(curvature.max() * var)

    assert wall(SOFTPLUS_FRACTION_AT_BOUND) < 4.0
    assert wall(None) > 4.0


def test_softplus_keeps_a_linear_ridge_straight_where_exp_bends_it():
    """The geometry the softplus is for: a tight ridge a + k = 1 (a trades linearly with k, like
    A_D with K_D on one pair) and k ~ N(0.6, 0.12), 3 sd inside 5 s of the bound.  The sampler's whitened coordinates are
    straight lines through the mode (the Laplace approximation): 3 sd along the ridge's
    direction the potential should rise by 4.5.  Through the softplus the ridge is straight in
    (a, x) and it rises by 4.5 to 5 %; through exp (x = log k) the ridge is curved, the straight
    line leaves it and the potential rises more than tenfold."""
    import jax
    import jax.numpy as jnp
    from numpyro.distributions.transforms import biject_to

    from bayes_roadload.inference.spec import Prior

    soft = biject_to(Prior("normal", 0.6, 1.0, 0.0).to_numpyro().support)

    def rise_at_3_sd(to_k, x0):
        def potential(z):
            k = to_k(z[1])
            return 0.5 * ((z[0] + k - 1.0) / 0.001) ** 2 + 0.5 * ((k - 0.6) / 0.12) ** 2

        mode = jnp.array([0.4, x0])
        eigval, eigvec = np.linalg.eigh(np.linalg.inv(np.asarray(jax.hessian(potential)(mode))))
        step = 3.0 * np.sqrt(eigval[-1]) * eigvec[:, -1]
        return max(float(potential(mode + step) - potential(mode)), float(potential(mode - step) - potential(mode)))

    assert rise_at_3_sd(soft, float(soft.inv(0.6))) == pytest.approx(4.5, rel=0.05)
    assert rise_at_3_sd(jnp.exp, float(np.log(0.6))) > 45.0


def test_the_pitch_variant_slows_the_coast_and_leaves_the_steady_road_load():
    """``four_term_tyre_lag_admittance_pitch`` is the default's model with the pitch term
    (eq. 2.33-2.35): the same free parameters, K_alpha held at 0.9 with its 0.5 a Type B
    source beside C_R's; decelerating, its drag changes by q_r A K_alpha pitch_gain dv/dt, so
    dv/dt = -F_0 / (M_e + q_r A K_alpha pitch_gain) (eq. 5.4 solved for the implicit term); at
    constant speed (the figures F0/F1/F2, F50) nothing changes."""
    import jax.numpy as jnp

    from bayes_roadload import config
    from bayes_roadload.inference.lsq import roadload_figures
    from bayes_roadload.physics.terms import Conditions

    base, pitch = load_model_spec("four_term_tyre_lag_admittance"), load_model_spec("four_term_tyre_lag_admittance_pitch")
    campaign = make_campaign(tunnel={"CL0": 0.273, "KL": 3.64})
    (mb, fb, free_b), (mp, fp, free_p) = base.build(campaign), pitch.build(campaign)
    assert free_p == free_b and set(mp.term_names) - set(mb.term_names) == {"pitch_attitude"}
    assert fp["Kalpha"] == 0.9 and fp["pitch_gain"] == 0.0103
    assert pitch.uncertainty == {**base.uncertainty, "Kalpha": 0.5}
    coef = {**fb, "AD": 0.012, "BD": 1.5e-4, "CD0": 0.38, "KD": 0.6, "tyre_lag_gain_per_mps": 0.005}
    vehicle = {"mass_kg": 1100.0, "frontal_area_m2": 1.85}
    steady_b = np.asarray(roadload_figures(mb, coef, **vehicle))
    steady_p = np.asarray(roadload_figures(mp, {**coef, **fp, **coef}, **vehicle))
    np.testing.assert_allclose(steady_p, steady_b, rtol=1e-12)

    c = Conditions(**{k: jnp.asarray(v, float) for k, v in dict(
        speed_mps=30.0, airspeed_mps=31.0, yaw_rad=0.05, driveline_force_n=0.0, position_m=0.0, distance_m=0.0,
        time_s=5.0, accel_mps2=0.0, direction=1.0, air_density_kgpm3=1.2,
        temperature_k=config.REFERENCE_TEMPERATURE_K, mass_kg=1100.0, frontal_area_m2=1.85).items()})
    m_e = 1130.0
    a_b = float(mb.acceleration_mps2(coef, c, m_e))
    a_p = float(mp.acceleration_mps2({**coef, **fp, **coef}, c, m_e))
    q_area = 0.5 * 1.2 * 31.0**2 * 1.85
    assert a_p == pytest.approx(a_b * m_e / (m_e + q_area * 0.9 * 0.0103), rel=1e-12)
    assert a_b < a_p < 0.0  # the dip under deceleration lowers the drag: a slower coast


@pytest.mark.parametrize("parent", ["four_term_tyre_lag_admittance_pitch", "four_term_tyre_lag_admittance_heavy_pitch"])
def test_the_shapes_variant_samples_its_parents_posterior_and_budgets_the_shapes(parent):
    """``<parent>_shapes`` holds the yaw drag's levelling at none (L_psi = 0, knee 20 deg) and
    the tyre lag's time constant at 400 s, and carries both spreads as model constants' Type B
    sources: the same free parameters and priors as its parent, the same acceleration at every
    yaw (the levelling term vanishes at L_psi = 0), and the parent's sources plus the two; a
    levelling L_psi > 0 lowers the drag at yaw (eq. 2.31 with the levelling term), so the
    budget's shift of that constant moves the modelled coast."""
    import jax.numpy as jnp

    from bayes_roadload import config
    from bayes_roadload.physics.terms import Conditions

    base, shapes = load_model_spec(parent), load_model_spec(parent + "_shapes")
    campaign = make_campaign(tunnel={"CL0": 0.273, "KL": 3.64})
    (mb, fb, free_b), (ms, fs, free_s) = base.build(campaign), shapes.build(campaign)
    assert free_s == free_b and shapes.priors == base.priors
    assert set(ms.term_names) ^ set(mb.term_names) == {"aero_drag", "aero_drag_levelling"}
    assert fs == {**fb, "yaw_levelling_per_rad2": 0.0, "yaw_knee_rad": 0.349}
    heavy = "heavy" in parent
    assert shapes.uncertainty == {**base.uncertainty, "tyre_lag_time_constant_s": 200.0,
                                  "yaw_levelling_per_rad2": 3.0 if heavy else 1.0}
    coef = {**fb, "AD": 0.012, "BD": 1.5e-4, "CD0": 0.38, "KD": 0.6, "tyre_lag_gain_per_mps": 0.005}
    m_e = 1130.0
    for yaw in (0.0, 0.1, 0.3):
        c = Conditions(**{k: jnp.asarray(v, float) for k, v in dict(
            speed_mps=30.0, airspeed_mps=31.0, yaw_rad=yaw, driveline_force_n=0.0, position_m=0.0,
            distance_m=0.0, time_s=5.0, accel_mps2=0.0, direction=1.0, air_density_kgpm3=1.2,
            temperature_k=config.REFERENCE_TEMPERATURE_K, mass_kg=1100.0, frontal_area_m2=1.85).items()})
        a_b = float(mb.acceleration_mps2(coef, c, m_e))
        assert float(ms.acceleration_mps2({**coef, **fs, **coef}, c, m_e)) == pytest.approx(a_b, rel=1e-12)
        levelled = float(ms.acceleration_mps2({**coef, **fs, **coef, "yaw_levelling_per_rad2": 1.0}, c, m_e))
        if yaw > 0.0:
            assert a_b < levelled < 0.0


def test_without_free_drops_a_parameter_everywhere_and_fixes_it_where_told():
    spec = load_model_spec("four_term_tyre_lag")
    gain = "tyre_lag_gain_per_mps"
    assert gain in spec.free and gain in spec.priors
    held = without_free(spec, (gain,), fixed={gain: 0.004}, name="held")
    assert gain not in held.free and gain not in held.priors and gain not in held.initial
    assert held.fixed[gain] == 0.004 and held.name == "held"
    assert held.free == tuple(p for p in spec.free if p != gain)
    assert gain not in spec.fixed and gain in spec.free  # the original is untouched
    dropped = without_free(spec, (gain,))
    assert gain not in dropped.free and gain not in dropped.fixed and dropped.name == spec.name
    with pytest.raises(ModelSpecError, match="not free"):
        without_free(spec, ("no_such_parameter",))
