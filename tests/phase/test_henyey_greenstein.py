"""Henyey-Greenstein (Eq. C.2, Padrón 2025; seed-000 spec M12 and its checks §6)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import testing
from appearance_jax.core.frame import orthonormal_basis, spherical_direction
from appearance_jax.core.quadrature import gauss_legendre
from appearance_jax.core.vec import Vec3, dot
from appearance_jax.phase import henyey_greenstein as hg

GS = (-0.9, -0.5, 0.0, 0.3, 0.8, 0.95)


def textbook(g, cos_prop):
    """HG in the propagation convention: cos_prop = d . wo with d = -wi (1 + g^2 - 2 g cos)."""
    return (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * cos_prop) ** 1.5)


def _wi(n=6, key=0):
    return testing.random_directions(key, n, "sphere")


def test_isotropic_value_and_shape():
    wi, wo = _wi(), _wi(key=1)
    f = hg.eval(hg.Params(), wi, wo)
    assert f.shape == (6, 1)
    np.testing.assert_allclose(f, 1 / (4 * np.pi), rtol=1e-15)
    f = hg.eval(hg.Params(g=(0.1, 0.2, 0.3)), wi, wo)
    assert f.shape == (6, 3)


@pytest.mark.parametrize("g", GS)
def test_matches_textbook_form_in_propagation_convention(g):
    wi, wo = _wi(200), _wi(200, key=2)
    f = np.asarray(hg.eval(hg.Params(g=g), wi, wo))[:, 0]
    np.testing.assert_allclose(f, textbook(g, np.asarray(dot(-wi, wo))), rtol=1e-13)


@pytest.mark.parametrize("g", (0.3, 0.8, -0.5))
def test_forward_peak_convention(g):
    """g > 0 peaks at wo = -wi (forward), g < 0 at wo = wi; values (1 +- g) / (4 pi (1 -+ g)^2)."""
    wi = spherical_direction(jnp.array(0.7), jnp.array(1.1))
    p = hg.Params(g=g)
    fwd, back = float(hg.eval(p, wi, -wi)[0]), float(hg.eval(p, wi, wi)[0])
    np.testing.assert_allclose(fwd, (1 + g) / (4 * np.pi * (1 - g) ** 2), rtol=1e-14)
    np.testing.assert_allclose(back, (1 - g) / (4 * np.pi * (1 + g) ** 2), rtol=1e-14)
    others = np.asarray(hg.eval(p, Vec3(*(jnp.broadcast_to(c, (2000,)) for c in wi)), _wi(2000, key=3)))
    peak = fwd if g > 0 else back
    assert np.all(others < peak) and max(fwd, back) == peak


@pytest.mark.parametrize("g", GS)
def test_normalisation_mean_cosine_and_legendre_moments(g):
    """int f = 1, <d . wo> = g, and the Legendre moments int P_l(d . wo) f = g^l (l = 2, 3).

    Integrated with 400 Gauss-Legendre nodes in mu = d . wo about each random wi.
    """
    wi = _wi(4)
    mu, w = gauss_legendre(400, -1.0, 1.0)
    d = -wi
    # directions at polar cosine mu about d (azimuth irrelevant: f depends on mu only)
    s, t = orthonormal_basis(d)
    st = np.sqrt(1 - mu**2)
    wo = Vec3(*(jnp.asarray(np.asarray(a)[:, None] * st + np.asarray(c)[:, None] * mu)
                for a, c in zip(s, d)))
    wib = wi.map(lambda a: jnp.broadcast_to(a[:, None], (4, 400)))
    f = np.asarray(hg.eval(hg.Params(g=g), wib, wo))[..., 0]
    m = np.asarray(dot(d.map(lambda a: a[:, None]), wo))
    P2, P3 = 0.5 * (3 * m**2 - 1), 0.5 * (5 * m**3 - 3 * m)
    for h, expect in ((1.0, 1.0), (m, g), (P2, g**2), (P3, g**3)):
        np.testing.assert_allclose(2 * np.pi * np.sum(f * h * w, axis=1), expect, atol=1e-9)


@pytest.mark.parametrize("g", (-0.7, 0.0, 0.5, 0.9))
def test_sampled_mean_cosine(g):
    n = 2**16
    wi = Vec3(*(jnp.full((n,), c) for c in (0.0, 0.6, 0.8)))
    wo, weight, pdf = hg.sample(hg.Params(g=g), wi, jax.random.key(4))
    np.testing.assert_allclose(weight, 1.0, rtol=1e-14)  # pdf = f for a single band
    np.testing.assert_allclose(pdf, hg.pdf(hg.Params(g=g), wi, wo), rtol=1e-14)
    np.testing.assert_allclose(dot(wo, wo), 1.0, atol=1e-14)
    c = np.asarray(dot(-wi, wo))
    se = c.std() / math.sqrt(n)
    assert abs(c.mean() - g) < 4.5 * se  # 4.5 sigma: p ~ 7e-6 per case


def test_inversion_matches_textbook_formula():
    """The cancellation-free form equals (1 + g^2 - ((1 - g^2) / (1 - g + 2 g xi))^2) / (2 g)."""
    xi = np.linspace(0.0, 1.0, 1001)
    for g in (-0.95, -0.3, 0.01, 0.4, 0.95):
        mu, st = hg.sample_cos(jnp.asarray(g), jnp.asarray(xi))
        ref = (1 + g * g - ((1 - g * g) / (1 - g + 2 * g * xi)) ** 2) / (2 * g)
        np.testing.assert_allclose(mu, ref, atol=5e-14)
        np.testing.assert_allclose(st, np.sqrt(np.maximum(1 - ref**2, 0)), atol=2e-7)
    mu, _ = hg.sample_cos(jnp.asarray(0.0), jnp.asarray(xi))
    np.testing.assert_allclose(mu, 2 * xi - 1, atol=1e-15)


def test_inversion_gradient_is_finite_and_exact_at_g0():
    """d mu / d g at g = 0 is 3 (1 - a^2) / 2 with a = 2 xi - 1 (Taylor expansion of the inversion)."""
    xi = jnp.linspace(0.0, 1.0, 101)
    dmu = jax.vmap(jax.grad(lambda g, x: hg.sample_cos(g, x)[0]), (None, 0))(0.0, xi)
    a = 2 * np.asarray(xi) - 1
    np.testing.assert_allclose(dmu, 1.5 * (1 - a * a), atol=1e-12)


@pytest.mark.parametrize("g", (-0.7, 0.0, 0.3, 0.9))
def test_chi2_sampler(g):
    testing.assert_chi2(hg.MODEL, hg.Params(g=g), key=5, n_samples=2**17, n_wi=2, n_tests=4)


def test_band_valued_g_samples_the_band_mean():
    p = hg.Params(g=(-0.2, 0.3, 0.6))
    wi, n = _wi(1), 4096
    wib = wi.map(lambda a: jnp.broadcast_to(a, (n,)))
    wo, weight, pdf = hg.sample(p, wib, jax.random.key(6))
    f = hg.eval(p, wib, wo)
    np.testing.assert_allclose(pdf, hg.eval(hg.Params(g=np.mean([-0.2, 0.3, 0.6])), wib, wo)[:, 0], rtol=1e-14)
    np.testing.assert_allclose(weight, f / pdf[:, None], rtol=1e-14)
    testing.assert_white_furnace(hg.MODEL, p, key=6, lossless=True, n_theta=64, n_phi=16)


@pytest.mark.parametrize("g", (-0.5, 0.0, 0.5))
def test_gradients_eval_and_sampled_directions(g):
    wi, wo = _wi(32), _wi(32, key=7)
    testing.assert_gradients(lambda p: jnp.sum(hg.eval(p, wi, wo) ** 2), hg.Params(g=g))
    u = tuple(jax.random.uniform(k, (32,), jnp.float64) for k in jax.random.split(jax.random.key(8)))

    def sampled(p):
        wo_s, weight, pdf = hg.sample(p, wi, u)
        return jnp.sum(wo_s.x + 2 * wo_s.y - wo_s.z) + jnp.sum(jnp.log(pdf))

    r = testing.assert_gradients(sampled, hg.Params(g=g))
    assert np.all(np.isfinite(r.ad[0])) and abs(r.ad[0][0]) > 0


def test_traced_parameters_under_jit():
    wi, wo = _wi(8), _wi(8, key=9)
    f = jax.jit(lambda g: hg.eval(hg.Params(g=g), wi, wo))(0.4)
    np.testing.assert_allclose(f, hg.eval(hg.Params(g=0.4), wi, wo), rtol=1e-15)


@pytest.mark.parametrize("bad", (1.0, -1.0, 1.5, float("nan"), (0.2, 1.0, 0.1)))
def test_bad_parameters_raise(bad):
    wi, wo = _wi(2), _wi(2, key=1)
    with pytest.raises(ValueError, match=r"Params\.g = .*\(-1, 1\)"):
        hg.eval(hg.Params(g=bad), wi, wo)
    with pytest.raises(ValueError, match=r"Params\.g"):
        hg.sample(hg.Params(g=bad), wi, jax.random.key(0))
