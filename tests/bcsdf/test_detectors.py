"""bcsdf.detectors (Padrón 2025 Eq. 5.2; spec seed-000 M20, D6): normalisations against independent
quadrature (scipy), the wrapped sum against the plain Gaussian where wrapping is negligible, the
samplers' histograms against their densities (tolerances from the binomial standard error), and
named errors for bad widths."""

import math

import jax
import numpy as np
import pytest
from scipy.integrate import quad

from appearance_jax.bcsdf import detectors as D


@pytest.mark.parametrize("beta", [0.01, 0.12, 1.0, 1.5])
def test_wrapped_azimuthal_integrates_to_one_and_is_periodic(beta):
    x = np.linspace(-math.pi, math.pi, 40001)[:-1]  # the periodic trapezoid rule is spectrally exact
    g = np.asarray(D.azimuthal(x, beta))
    assert g.sum() * (2 * math.pi / x.size) == pytest.approx(1.0, abs=1e-10)
    np.testing.assert_allclose(np.asarray(D.azimuthal(x + 2 * math.pi, beta)), g, rtol=1e-9, atol=1e-300)
    np.testing.assert_allclose(np.asarray(D.azimuthal(-x, beta)), g, rtol=1e-9, atol=1e-300)


def test_azimuthal_is_the_gaussian_where_wrapping_is_negligible():
    """beta_n = 0.12 (Padrón's Fig. 5.7 [T:1069]): at 0.3 rad the other periods add < 1e-300."""
    v = float(D.azimuthal(0.3, 0.12))
    assert v == pytest.approx(math.exp(-0.3 ** 2 / (2 * 0.12 ** 2)) / (math.sqrt(2 * math.pi) * 0.12), rel=1e-13)
    # a wide lobe: the wrapped density at pi is twice the one-sided tail of the plain Gaussian there
    w = float(D.azimuthal(math.pi, 1.0))
    one = math.exp(-math.pi ** 2 / 2) / math.sqrt(2 * math.pi)
    assert w == pytest.approx(2 * one + 2 * math.exp(-(3 * math.pi) ** 2 / 2) / math.sqrt(2 * math.pi), rel=1e-12)


@pytest.mark.parametrize("kind", ["gaussian_cos", "deon"])
@pytest.mark.parametrize("Theta, beta", [(0.0, 0.13), (0.7, 0.01), (-1.2, 0.5), (1.5, 1.0)])
def test_normalised_longitudinal_factors_integrate_to_one_with_cos(kind, Theta, beta):
    f = lambda t: float(D.longitudinal(t, Theta, beta, kind)) * math.cos(t)  # noqa: E731
    pts = [min(max(Theta, -1.5707), 1.5707)]
    total = quad(f, -math.pi / 2, math.pi / 2, points=pts, limit=400, epsabs=1e-12)[0]
    assert total == pytest.approx(1.0, abs=2e-6 if kind == "deon" else 1e-9)


def test_the_literal_gaussian_loses_energy_through_cos():
    """Without normalisation the lobe at Theta carries Z(Theta, beta) = cos(Theta) exp(-beta^2/2) (the
    untruncated integral; the cases keep 4.8 widths from the poles, where the cut tails are < 1e-6)."""
    for Theta, beta in ((0.0, 0.13), (0.6, 0.2)):
        z = quad(lambda t: float(D.longitudinal(t, Theta, beta)) * math.cos(t), -math.pi / 2, math.pi / 2,
                 points=[Theta], limit=200)[0]
        assert z == pytest.approx(float(D.cos_normaliser(Theta, beta)), rel=1e-10)
        assert z == pytest.approx(math.cos(Theta) * math.exp(-beta ** 2 / 2), rel=5e-6)


def test_deon_and_normalised_gaussian_agree_for_narrow_lobes():
    t = np.linspace(0.3 - 0.15, 0.3 + 0.15, 31)
    a = np.asarray(D.longitudinal(t, 0.3, 0.05, "gaussian_cos"))
    b = np.asarray(D.longitudinal(t, 0.3, 0.05, "deon"))
    assert np.max(np.abs(a - b)) < 0.03 * a.max()
    assert t[np.argmax(b)] == pytest.approx(0.3, abs=0.011)


def _histogram_z(samples, density, lo, hi, bins=40):
    counts, edges = np.histogram(samples, bins=bins, range=(lo, hi))
    n = samples.size
    p = np.array([quad(density, a, b)[0] for a, b in zip(edges[:-1], edges[1:])])
    se = np.sqrt(np.maximum(n * p * (1 - p), 1.0))
    return (counts - n * p) / se, p.sum()


@pytest.mark.parametrize("Phi, beta", [(0.4, 0.12), (3.0, 1.2)])
def test_azimuthal_sampler_matches_its_density(Phi, beta):
    u = np.asarray(jax.random.uniform(jax.random.PRNGKey(1), (200000,)))
    phi, dens = (np.asarray(v) for v in D.sample_azimuthal(u, Phi, beta))
    assert np.all((phi >= -math.pi) & (phi < math.pi))
    np.testing.assert_allclose(dens, np.asarray(D.azimuthal(phi - Phi, beta)), rtol=1e-12)
    z, mass = _histogram_z(phi, lambda x: float(D.azimuthal(x - Phi, beta)), -math.pi, math.pi)
    assert mass == pytest.approx(1.0, abs=1e-8)
    assert np.max(np.abs(z)) < 4.5 and np.mean(z ** 2) < 1.0 + 5 * math.sqrt(2 / z.size)


@pytest.mark.parametrize("Theta, beta", [(0.2, 0.13), (1.3, 0.6)])
def test_longitudinal_sampler_is_the_truncated_gaussian(Theta, beta):
    u = np.asarray(jax.random.uniform(jax.random.PRNGKey(2), (200000,)))
    th, dens = (np.asarray(v) for v in D.sample_longitudinal(u, Theta, beta))
    assert np.all(np.abs(th) <= math.pi / 2)
    mass = quad(lambda t: float(D.gaussian(t - Theta, beta)), -math.pi / 2, math.pi / 2)[0]
    np.testing.assert_allclose(dens, np.asarray(D.gaussian(th - Theta, beta)) / mass, rtol=1e-9)
    z, total = _histogram_z(th, lambda t: float(D.gaussian(t - Theta, beta)) / mass, -math.pi / 2, math.pi / 2)
    assert total == pytest.approx(1.0, abs=1e-8)
    assert np.max(np.abs(z)) < 4.5 and np.mean(z ** 2) < 1.0 + 5 * math.sqrt(2 / z.size)

def test_truncation_cdfs_are_the_normal_cdf_at_both_ends():
    """Phi((-+pi/2 - Theta) / beta) against scipy's normal CDF, for lobes inside, at and beyond the ends."""
    from scipy.stats import norm
    Theta = np.array([[-1.7, -0.3, 0.0], [0.4, 1.5, 2.0]])
    beta = np.array([0.05, 0.3, 1.2])
    a, b = D.truncation_cdfs(Theta, beta)
    np.testing.assert_allclose(np.asarray(a), norm.cdf((-0.5 * math.pi - Theta) / beta), rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(np.asarray(b), norm.cdf((0.5 * math.pi - Theta) / beta), rtol=1e-12, atol=1e-300)
    assert np.asarray(a).shape == Theta.shape



@pytest.mark.parametrize("call", [
    lambda: D.azimuthal(0.1, 0.0), lambda: D.gaussian(0.1, -0.2), lambda: D.longitudinal(0.1, 0.2, float("nan")),
    lambda: D.sample_azimuthal(0.5, 0.0, -1.0), lambda: D.sample_longitudinal(0.5, 0.0, 0.0),
])
def test_bad_widths_are_named(call):
    with pytest.raises(ValueError, match="beta = "):
        call()


def test_unknown_kind_is_named():
    with pytest.raises(ValueError, match="kind = 'cauchy'"):
        D.longitudinal(0.1, 0.2, 0.1, "cauchy")
