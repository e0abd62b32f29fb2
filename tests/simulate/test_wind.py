"""Dryden wind: spectra, FFT synthesis and the generated field (thesis section 6.2.2)."""

import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.signal import welch

from bayes_roadload.simulate import wind

L = 30.0
DX = 0.25
COMPONENTS = ("longitudinal", "lateral")


@pytest.mark.parametrize("component", COMPONENTS)
def test_psd_integrates_to_variance_and_matches_closed_form_cdf(component):
    sigma = 1.7
    f = lambda om: wind.dryden_psd(om, sigma, L, component)  # noqa: E731
    total, _ = quad(f, 0.0, np.inf, limit=500)
    assert total == pytest.approx(sigma**2, rel=1e-6)
    for om in (0.01, 0.05, 0.3):
        part, _ = quad(f, 0.0, om, limit=200)
        assert wind.dryden_cumulative_variance(om, sigma, L, component) == pytest.approx(part, rel=1e-8)


def test_psd_shapes():
    # Phi_u(0) = 2 L sigma^2 / pi, Phi_v(0) = L sigma^2 / pi; Phi_v peaks at L Omega = 1/sqrt(3)
    assert wind.dryden_psd_longitudinal(0.0, 1.0, L) == pytest.approx(2 * L / math.pi)
    assert wind.dryden_psd_lateral(0.0, 1.0, L) == pytest.approx(L / math.pi)
    om = np.linspace(0.0, 0.2, 20001)
    assert om[np.argmax(wind.dryden_psd_lateral(om, 1.0, L))] * L == pytest.approx(1 / math.sqrt(3), abs=1e-3)
    with pytest.raises(ValueError):
        wind.dryden_psd(0.1, 1.0, L, "vertical")


def _realisations(component, n_real, n_points, seed):
    rng = np.random.default_rng(seed)
    return [wind.synthesize_turbulence(n_points, DX, 1.0, L, component, rng) for _ in range(n_real)]


@pytest.mark.parametrize("component", COMPONENTS)
def test_synthesised_standard_deviation(component):
    # 20 fields of 8192 m = 273 L each.  The sample variance of one field has a relative
    # standard error of about sqrt(2 L / length) = 6 %, so the pooled variance of 20 fields is
    # within ~1.4 % (std ~0.7 %) of sigma^2: a 10 % tolerance on the std is > 10 sigma away.
    fields = _realisations(component, 20, 2**15, seed=11)
    std = math.sqrt(np.mean([np.mean(x**2) for x in fields]))
    assert std == pytest.approx(1.0, rel=0.10)
    assert abs(std - 1.0) < 0.03  # what we actually expect given the sampling error above


def _band_ratios(fields, target_component):
    """Welch PSD pooled over realisations / Dryden target, summed over bins in bands of L*Omega."""
    psd = np.mean([welch(x, fs=1.0 / DX, nperseg=4096)[1] for x in fields], axis=0)
    freq = welch(fields[0], fs=1.0 / DX, nperseg=4096)[0]
    omega = 2 * math.pi * freq                 # rad/m
    phi = psd / (2 * math.pi)                  # per cycle/m -> per rad/m
    target = wind.dryden_psd(omega, 1.0, L, target_component)
    out = {}
    for lo, hi in ((0.3, 1.0), (1.0, 3.0), (3.0, 10.0), (10.0, 30.0)):
        m = (omega * L >= lo) & (omega * L < hi)
        out[(lo, hi)] = phi[m].sum() / target[m].sum()
    return out


@pytest.mark.parametrize("component", COMPONENTS)
def test_synthesised_spectrum_matches_dryden(component):
    # 40 fields of 16384 m, Welch segments of 1024 m (Omega resolution 0.18 / L): ~1250
    # segment averages per bin, i.e. ~3 % per-bin error, and the lowest band pools 4 bins
    # (~2 %).  Hann-window leakage on this smooth spectrum is < 1 %.  10 % is > 4 sigma.
    fields = _realisations(component, 40, 2**16, seed=5)
    ratios = _band_ratios(fields, component)
    for band, r in ratios.items():
        assert r == pytest.approx(1.0, rel=0.10), (band, r)
    # the test discriminates: the other component's spectrum is off by far more than 10 % in
    # the lowest band (Phi_v / Phi_u -> 1/2 at Omega -> 0, and 1.06 vs 0.5 around L Omega = 0.6)
    other = "lateral" if component == "longitudinal" else "longitudinal"
    wrong = _band_ratios(fields, other)[(0.3, 1.0)]
    assert abs(wrong - 1.0) > 0.2


def test_mean_profile_is_linear_with_beta():
    x = np.array([0.0, 1250.0, 2500.0])
    np.testing.assert_allclose(wind.mean_wind_profile(x, 3.0, 0.5, 2500.0), [2.25, 3.0, 3.75])
    np.testing.assert_allclose(wind.mean_wind_profile(x, 3.0, 0.0, 2500.0), [3.0, 3.0, 3.0])


def test_field_without_turbulence_is_the_mean_profile():
    f = wind.generate_wind_field(2.0, 3.0, np.random.default_rng(0), track_length_m=2500.0,
                                 margin_m=500.0, spatial_beta=0.5, turbulence_ratio=0.0)
    assert f.start_m == -500.0 and f.end_m >= 3000.0
    np.testing.assert_allclose(f.along_mps, wind.mean_wind_profile(f.position_m, 2.0, 0.5, 2500.0))
    np.testing.assert_allclose(f.cross_mps, wind.mean_wind_profile(f.position_m, 3.0, 0.5, 2500.0))
    wa, wc = f.at(1250.0)
    assert (float(wa), float(wc)) == pytest.approx((2.0, 3.0))


def test_field_turbulence_is_ratio_times_mean():
    # sigma = 0.4 x mean per component (table 6.4): 0.8 m/s in-line, 1.2 m/s cross.  30 fields
    # of 3500 m = 117 L: the std of one field scatters by ~6.5 %, pooled ~1.2 %.
    rng = np.random.default_rng(3)
    fa, fc = [], []
    for _ in range(30):
        f = wind.generate_wind_field(2.0, 3.0, rng, track_length_m=2500.0, margin_m=500.0)
        fa.append(f.along_mps - 2.0)
        fc.append(f.cross_mps - 3.0)
    assert math.sqrt(np.mean(np.square(fa))) == pytest.approx(0.8, rel=0.05)
    assert math.sqrt(np.mean(np.square(fc))) == pytest.approx(1.2, rel=0.05)
    # no mean wind in a component -> no turbulence in it ("component" reference)
    f = wind.generate_wind_field(0.0, 3.0, rng, track_length_m=2500.0, margin_m=0.0)
    assert np.all(f.along_mps == 0.0)
    assert wind.turbulence_sigmas(0.0, 3.0, 0.4, "total") == pytest.approx((1.2, 1.2))


def test_synthesis_is_reproducible_and_validates():
    a = wind.synthesize_turbulence(1000, DX, 1.0, L, "lateral", np.random.default_rng(1))
    b = wind.synthesize_turbulence(1000, DX, 1.0, L, "lateral", np.random.default_rng(1))
    np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError):
        wind.synthesize_turbulence(2, DX, 1.0, L, "lateral", np.random.default_rng(1))
    with pytest.raises(ValueError):
        wind.synthesize_turbulence(100, DX, -1.0, L, "lateral", np.random.default_rng(1))
