"""Tabulated phase function (phase/tabulated.py) against closed forms (Rayleigh, HG, Mie)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.core.frame import spherical_direction
from appearance_jax.phase import henyey_greenstein as hg
from appearance_jax.phase import mie, tabulated


def _dirs(cos_t):
    """wi fixed, wo at scattering angle theta (cos theta = -(wi . wo))."""
    theta = np.arccos(cos_t)
    wi = spherical_direction(jnp.full(theta.shape, 0.4), jnp.full(theta.shape, 0.3))
    # wo = -wi rotated by theta about an axis perpendicular to wi
    d = -np.stack([np.asarray(c) for c in wi], -1)
    ax = np.cross(d, [0.0, 0.0, 1.0])
    ax /= np.linalg.norm(ax, axis=-1, keepdims=True)
    wo = d * np.cos(theta)[:, None] + np.cross(ax, d) * np.sin(theta)[:, None]
    return wi, jnp.asarray(wo)


def test_rayleigh_closed_form():
    th = np.linspace(0.0, np.pi, 721)
    p = tabulated.Params(values=5.0 * (1.0 + np.cos(th) ** 2))  # any scale: the model normalises
    cos_t = np.linspace(-1.0, 1.0, 57)
    wi, wo = _dirs(cos_t)
    f = np.asarray(tabulated.eval(p, wi, wo))[:, 0]
    ref = 3.0 / (16.0 * np.pi) * (1.0 + cos_t ** 2)
    # linear interpolation in theta: error <= h^2/8 max|f''| ~ 2e-6 relative at h = 0.25 deg
    np.testing.assert_allclose(f, ref, rtol=1e-5)


def test_normalisation_exact_for_any_table():
    rng = np.random.default_rng(3)
    v = rng.uniform(0.0, 2.0, size=(37, 2))
    p = tabulated.Params(values=v)
    x, w = np.polynomial.legendre.leggauss(400)
    # integrate bin by bin in theta (the interpolant is linear in theta): exact to rounding
    edges = np.linspace(0.0, np.pi, 37)
    total = np.zeros(2)
    for a, b in zip(edges[:-1], edges[1:]):
        th = 0.5 * (b - a) * x + 0.5 * (a + b)
        wi, wo = _dirs(np.cos(th))
        f = np.asarray(tabulated.eval(p, wi, wo))
        total += 2 * np.pi * 0.5 * (b - a) * np.sum(f * (w * np.sin(th))[:, None], axis=0)
    np.testing.assert_allclose(total, 1.0, atol=1e-12)


def test_reproduces_hg_and_mie():
    th = np.linspace(0.0, np.pi, 2001)
    g = 0.6
    cos_t = np.linspace(-1.0, 0.999, 41)
    wi, wo = _dirs(cos_t)
    p = tabulated.Params(values=np.asarray(hg.hg_value(g, -np.cos(th))))  # hg_value takes wi . wo
    ref = np.asarray(hg.eval(hg.Params(g=g), wi, wo))[:, 0]
    np.testing.assert_allclose(np.asarray(tabulated.eval(p, wi, wo))[:, 0], ref, rtol=1e-4)
    m = mie.Params(radius_um=0.5, wavelength_nm=(650.0, 450.0), n_particle=1.5)
    pm = tabulated.Params(values=np.asarray(mie.phase_function(m, jnp.cos(jnp.asarray(th)))))
    ref = np.asarray(mie.eval(m, wi, wo))
    np.testing.assert_allclose(np.asarray(tabulated.eval(pm, wi, wo)), ref, rtol=2e-4)


def test_sampling_weights_and_pdf():
    p = tabulated.MODEL.presets["two_lobes_rgb"]
    n = 200000
    wi = spherical_direction(jnp.full((n,), 0.7), jnp.zeros(n))
    wo, w, pdf = tabulated.sample(p, wi, jax.random.key(7))
    w = np.asarray(w)
    # E[f / pdf] = integral of f = 1 per band (the harness's furnace, by sampling), within 4 sigma
    se = w.std(axis=0) / np.sqrt(n)
    assert np.all(np.abs(w.mean(axis=0) - 1.0) < 4 * se + 1e-12), (w.mean(axis=0), se)
    np.testing.assert_allclose(np.asarray(tabulated.pdf(p, wi, wo)), np.asarray(pdf), rtol=1e-10)


def test_bad_inputs():
    with pytest.raises(ValueError, match=">= 2 angles"):
        tabulated.Params(values=[1.0])
    with pytest.raises(ValueError, match="zero everywhere"):
        tabulated.Params(values=np.zeros(10))
    with pytest.raises(ValueError, match="values"):
        tabulated.Params(values=-np.ones(10))
    with pytest.raises(ValueError, match="shape"):
        tabulated.Params(values=np.ones((4, 3, 2)))
