"""The registry of data kinds."""

import pytest

from bayes_roadload.data import Campaign, DistanceCampaign, IntervalCampaign, SpindownCampaign, SteadyCampaign
from bayes_roadload.inference.kinds import KINDS, FitOptions, kind_of
from bayes_roadload.inference.spec import available_models


def test_every_campaign_class_has_one_entry():
    classes = {Campaign: "traces", IntervalCampaign: "intervals", DistanceCampaign: "distances",
               SpindownCampaign: "spindown", SteadyCampaign: "steady"}
    assert {e.campaign_type: name for name, e in KINDS.items()} == classes
    for name, entry in KINDS.items():
        assert entry.name == name


def test_kind_of_refuses_an_unknown_campaign():
    with pytest.raises(ValueError, match="registered data kind"):
        kind_of(object())


def test_default_models_are_model_files():
    models = set(available_models())
    for name, entry in KINDS.items():
        if name != "steady":   # depends on the campaign's anemometers (tests/test_cli.py)
            assert entry.default_model(None, FitOptions()) in models, name
        if entry.diagnosis is not None:
            assert entry.diagnosis_model in models, name
        # the defaults `bayes-roadload models` lists are model files, the campaign-free default among them
        assert entry.default_models and set(entry.default_models) <= models, name
        if name != "steady":
            assert entry.default_model(None, FitOptions()) in entry.default_models, name


@pytest.mark.parametrize("name", ["intervals", "distances", "spindown", "steady"])
def test_kinds_with_their_own_likelihood_refuse_trace_options(name):
    check = KINDS[name].check_options
    check(FitOptions())   # the defaults apply to every kind
    with pytest.raises(ValueError, match="nuts only"):
        check(FitOptions(method="lsq"))
    with pytest.raises(ValueError, match="--robust"):
        check(FitOptions(robust=True))
    with pytest.raises(ValueError, match="--noise"):
        check(FitOptions(noise="white"))


def test_only_speed_traces_take_least_squares_and_any_option():
    assert [n for n, e in KINDS.items() if e.lsq] == ["traces"]
    KINDS["traces"].check_options(FitOptions(method="lsq", pooling="hierarchical", noise="white", robust=True))
    # a spin-down campaign has a hierarchical pooling of its own; the others refuse it
    KINDS["spindown"].check_options(FitOptions(pooling="hierarchical"))
    with pytest.raises(ValueError, match="--pooling"):
        KINDS["distances"].check_options(FitOptions(pooling="hierarchical"))


def test_auto_pooling_is_hierarchical_for_nuts_fits_of_speed_traces(small_campaign):
    """``--pooling auto``: run-level coefficients where the hierarchical model applies (NUTS,
    2 to 12 pairs, AD / BD / CD0 free, no robust noise, no latent wind), pooled otherwise and
    for the other kinds; an explicit choice is kept."""
    import dataclasses

    from bayes_roadload.inference.kinds import KINDS, FitOptions, resolve_pooling
    from bayes_roadload.inference.spec import load_model_spec

    traces = KINDS["traces"]
    spec = load_model_spec("four_term")
    assert FitOptions().pooling == "auto"
    assert resolve_pooling(traces, small_campaign, spec, FitOptions()).pooling == "hierarchical"
    assert resolve_pooling(traces, small_campaign, spec, FitOptions(method="lsq")).pooling == "pooled"
    assert resolve_pooling(traces, small_campaign, spec, FitOptions(robust=True)).pooling == "pooled"
    assert resolve_pooling(traces, small_campaign, spec, FitOptions(pooling="pooled")).pooling == "pooled"
    one_run = small_campaign.subset([small_campaign.run_ids[0]])
    assert resolve_pooling(traces, one_run, spec, FitOptions()).pooling == "pooled"
    from bayes_roadload import config

    many = list(range(config.AUTO_HIERARCHICAL_MAX_RUNS + 1))  # the runs to fit, as --validity gives them
    assert resolve_pooling(traces, small_campaign, spec, FitOptions(runs=many)).pooling == "pooled"
    assert resolve_pooling(traces, small_campaign, spec, FitOptions(runs=many[:-1])).pooling == "hierarchical"
    one_pair = list(range(config.AUTO_HIERARCHICAL_MIN_RUNS - 1))
    assert resolve_pooling(traces, small_campaign, spec, FitOptions(runs=one_pair)).pooling == "pooled"
    assert resolve_pooling(traces, small_campaign, spec, FitOptions(runs=one_pair + [9])).pooling == "hierarchical"
    speed_only = dataclasses.replace(small_campaign,
                                     runs=small_campaign.runs.drop(columns=["airspeed_mps", "yaw_rad"]))
    assert resolve_pooling(traces, speed_only, load_model_spec("speed_only_wind"), FitOptions()).pooling == "pooled"
    for name in ("intervals", "distances", "spindown", "steady"):
        assert KINDS[name].default_pooling(small_campaign, spec, FitOptions()) == "pooled"


def test_speed_traces_default_to_the_tyre_lag_for_nuts_only():
    """The Bayesian default carries the tyre lag's gain with its prior; least squares, which
    has no prior to hold that weakly identified gain, fits a model without it."""
    from bayes_roadload.inference.spec import load_model_spec

    traces = KINDS["traces"]
    gain = "tyre_lag_gain_per_mps"
    nuts = load_model_spec(traces.default_model(None, FitOptions(method="nuts")))
    lsq = load_model_spec(traces.default_model(None, FitOptions(method="lsq")))
    assert gain in nuts.free and gain in nuts.priors
    assert gain not in lsq.free and "tyre_thermal_lag" not in lsq.terms


def test_the_heavy_variant_differs_from_the_light_one_by_its_priors_only():
    """``four_term_tyre_lag_j2452_heavy`` has the light variant's terms and free parameters and
    a truck's C_D0 and K_D priors, each more than one light sd above the light centre."""
    from bayes_roadload.inference.spec import load_model_spec

    light, heavy = load_model_spec("four_term_tyre_lag_j2452"), load_model_spec("four_term_tyre_lag_j2452_heavy")
    assert light.terms == heavy.terms and set(light.free) == set(heavy.free)
    assert "tyre_speed_squared" in light.terms and "tyre_quadratic_s2_per_m2" in light.priors
    for name in ("CD0", "KD"):
        assert heavy.priors[name].loc > light.priors[name].loc + light.priors[name].scale


def test_the_speed_trace_default_takes_a_heavy_vehicles_priors_above_3500_kg():
    """``fit``'s Bayesian default for speed traces: the admittance model with the pitch term, its
    heavy variant for a test mass above GTR 15's light-duty limit; the two differ in priors and
    C_R's value only."""
    import dataclasses

    from bayes_roadload import config
    from bayes_roadload.inference.spec import load_model_spec
    from bayes_roadload.simulate import simulate_campaign

    traces = KINDS["traces"]
    c = simulate_campaign(1, pairs=1, seed=0)
    heavy_c = dataclasses.replace(c, vehicle=dataclasses.replace(
        c.vehicle, mass_kg=config.HEAVY_DUTY_MASS_KG + 1.0, effective_mass_kg=config.HEAVY_DUTY_MASS_KG + 100.0))
    light = load_model_spec(traces.default_model(c, FitOptions()))
    heavy = load_model_spec(traces.default_model(heavy_c, FitOptions()))
    assert light.name == "four_term_tyre_lag_admittance_pitch_shapes"
    assert heavy.name == "four_term_tyre_lag_admittance_heavy_pitch_shapes"
    assert traces.default_model(heavy_c, FitOptions(method="lsq")) == "four_term"
    # every variant the default takes is one `bayes-roadload models` marks as a default
    assert {light.name, heavy.name, "four_term"} == set(traces.default_models)
    assert light.terms == heavy.terms and light.free == heavy.free
    assert light.admittance == heavy.admittance == "auto"
    for name in ("CD0", "KD"):
        assert heavy.priors[name].loc > light.priors[name].loc + light.priors[name].scale
    assert heavy.fixed["tyre_quadratic_s2_per_m2"] < light.fixed["tyre_quadratic_s2_per_m2"]


def test_a_speed_trace_fit_in_still_air_for_want_of_an_anemometer_says_so(small_campaign):
    """The default model reads the anemometer when the campaign logs it, else takes still air:
    the second says so after the table and names the model that fits a latent wind; a model that
    estimates the wind (``speed_only_wind``), reads the anemometer, or takes still air by its own
    choice on a campaign that logs one (``split_f0_f2``: ``air = "still"``) does not get it."""
    import dataclasses
    from types import SimpleNamespace

    from bayes_roadload.inference.spec import load_model_spec

    notes = KINDS["traces"].notes
    speed_only = dataclasses.replace(small_campaign, runs=small_campaign.runs.drop(columns=["airspeed_mps", "yaw_rad"]))

    def said(campaign, model):
        fit = SimpleNamespace(problem=SimpleNamespace(spec=load_model_spec(model)))
        return any("takes still air" in line and "speed_only_wind" in line for line in notes(fit, campaign, {}))

    assert said(speed_only, "four_term")
    assert not said(speed_only, "speed_only_wind")
    assert not said(small_campaign, "four_term")
    assert load_model_spec("split_f0_f2").air == "still" and not said(small_campaign, "split_f0_f2")
