"""Microfacet distributions: normalisation, Smith identities, samplers, grazing gradients."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import erf as sp_erf

from appearance_jax import testing
from appearance_jax.core.frame import spherical_direction
from appearance_jax.core.quadrature import sphere_rule
from appearance_jax.core.vec import Vec3, dot
from appearance_jax.microfacet import distribution as md

ROUGH = [(0.05, 0.05), (0.3, 0.3), (1.0, 1.0), (0.1, 0.5)]


@pytest.fixture(scope="module")
def hemi():
    # Gauss-Legendre in cos(theta) resolves the alpha = 0.05 peak (width ~ 1e-3 in cos)
    return sphere_rule(600, 400, hemisphere=True)


@pytest.mark.parametrize("kind", md.KINDS)
@pytest.mark.parametrize("ax,ay", ROUGH)
def test_projected_normal_area_is_one(kind, ax, ay, hemi):
    m, wt = hemi
    integral = float(jnp.sum(md.D(kind, m, ax, ay) * m.z * wt))
    assert abs(integral - 1.0) < 1e-7


@pytest.mark.parametrize("kind", md.KINDS)
@pytest.mark.parametrize("ax,ay", ROUGH)
def test_weak_white_furnace(kind, ax, ay, hemi):
    """int G1(w, m) |w.m| D(m) dm = |w.z| (Heitz 2014), also for w below the horizon
    (Walter's generalised chi), and projected_area = int max(0, w.m) D(m) dm."""
    m, wt = hemi
    for theta, phi in [(0.0, 0.0), (0.6, 0.4), (1.35, 2.0), (math.pi - 1.0, -1.0)]:
        w = spherical_direction(theta, phi)
        g = md.G1(kind, w, m, ax, ay) * jnp.abs(dot(w, m)) * md.D(kind, m, ax, ay)
        assert abs(float(jnp.sum(g * wt)) - abs(float(w.z))) < 2e-6 * max(1.0, 1.0 / ax)
        pv = float(jnp.sum(md.pdf_visible(kind, w, m, ax, ay) * wt))
        assert abs(pv - 1.0) < 2e-6 * max(1.0, 1.0 / ax)
        if w.z > 0:
            area = float(jnp.sum(jnp.maximum(dot(w, m), 0.0) * md.D(kind, m, ax, ay) * wt))
            assert abs(area - float(md.projected_area(kind, w, ax, ay))) < 2e-6 * max(1.0, 1.0 / ax)


def test_lambda_closed_forms():
    """Lambda against independent scalar formulas (numpy/scipy), isotropic and anisotropic."""
    for theta, phi, ax, ay in [(0.3, 0.0, 0.2, 0.2), (1.2, 0.7, 0.5, 0.1), (1.5, 2.5, 1.0, 0.3)]:
        w = spherical_direction(theta, phi)
        a2 = (ax * math.cos(phi)) ** 2 + (ay * math.sin(phi)) ** 2  # projected roughness^2
        t = math.tan(theta)
        ggx = (-1.0 + math.sqrt(1.0 + a2 * t * t)) / 2.0
        a = 1.0 / (math.sqrt(a2) * t)
        beck = (sp_erf(a) - 1.0) / 2.0 + math.exp(-a * a) / (2.0 * a * math.sqrt(math.pi))
        assert float(md.smith_lambda("ggx", w, ax, ay)) == pytest.approx(ggx, rel=1e-12)
        assert float(md.smith_lambda("beckmann", w, ax, ay)) == pytest.approx(beck, rel=1e-10, abs=1e-15)
        # Lambda is even in w.z
        wb = Vec3(w.x, w.y, -w.z)
        assert float(md.smith_lambda("ggx", wb, ax, ay)) == pytest.approx(ggx, rel=1e-12)


@pytest.mark.parametrize("kind", md.KINDS)
def test_g2_forms(kind):
    ax, ay = 0.4, 0.25
    m = Vec3(jnp.asarray(0.1), jnp.asarray(0.05), jnp.asarray(math.sqrt(1 - 0.0125)))
    for ti, pi_, to, po in [(0.4, 0.1, 1.1, 2.0), (1.3, 0.0, 0.2, 3.0), (0.0, 0.0, 0.9, 1.0)]:
        wi = spherical_direction(ti, pi_)
        wo = spherical_direction(to, po)
        li = float(md.smith_lambda(kind, wi, ax, ay))
        lo = float(md.smith_lambda(kind, wo, ax, ay))
        corr = float(md.G2(kind, wi, wo, m, ax, ay))
        sep = float(md.G2(kind, wi, wo, m, ax, ay, correlated=False))
        assert corr == pytest.approx(1.0 / (1.0 + li + lo), rel=1e-12)
        assert sep == pytest.approx(1.0 / ((1.0 + li) * (1.0 + lo)), rel=1e-12)
        assert corr >= sep - 1e-15
        # transmission: height-correlated = int_0^1 u^Li (1-u)^Lo du (Beta function)
        wt = Vec3(wo.x, wo.y, -wo.z)
        mt = Vec3(m.x, m.y, m.z)
        # make wt see the back of m: choose m nearly normal so wt.m < 0
        beta_ref = quad(lambda u: u**li * (1 - u) ** lo, 0.0, 1.0, epsabs=0, epsrel=1e-12, limit=200)[0]
        got = float(md.G2(kind, wi, wt, mt, ax, ay))
        assert got == pytest.approx(beta_ref, rel=1e-8)
    # chi: wo behind the microfacet -> 0
    wi = spherical_direction(0.3, 0.0)
    wo = spherical_direction(0.3, math.pi)
    m_bad = Vec3(jnp.asarray(0.99), jnp.asarray(0.0), jnp.asarray(math.sqrt(1 - 0.99**2)))
    assert float(md.G2(kind, wi, wo, m_bad, ax, ay)) == 0.0


def _moments(v: Vec3):
    return [v.x, v.y, v.z, v.x * v.x, v.x * v.y, v.z * v.z]


@pytest.mark.parametrize("kind", md.KINDS)
def test_sample_visible_moments_and_histogram(kind):
    """Sample moments and a (cos theta_m, phi_m) histogram against pdf_visible quadrature.

    z-scores use the estimator's standard error; 5 sigma over ~90 comparisons per kind.
    """
    n = 100_000
    m_q, wt = sphere_rule(400, 256, hemisphere=True)
    u1, u2 = jax.random.uniform(jax.random.PRNGKey(3), (2, n), dtype=jnp.float64)
    for (ax, ay), (theta, phi) in [((0.3, 0.3), (0.7, 0.3)), ((0.1, 0.5), (1.4, 2.0)),
                                   ((1.0, 1.0), (0.0, 0.0)), ((0.6, 0.2), (math.pi - 1.2, 1.0))]:
        w = spherical_direction(theta, phi)
        wn = Vec3(*(jnp.full(n, c) for c in w))
        ms = md.sample_visible(kind, wn, ax, ay, u1, u2)
        assert bool(jnp.all(ms.z >= 0))
        p = md.pdf_visible(kind, w, m_q, ax, ay)
        for g_s, g_q in zip(_moments(ms), _moments(m_q)):
            ref = float(jnp.sum(g_q * p * wt))
            se = float(jnp.std(g_s)) / math.sqrt(n)
            assert abs(float(jnp.mean(g_s)) - ref) < 5 * se + 1e-12
        # histogram: 4 bins in cos(theta_m) x 4 in phi_m
        ct_edges = np.array([0.0, 0.7, 0.9, 0.97, 1.0 + 1e-12])
        ph_edges = np.linspace(-math.pi, math.pi, 5)
        ph_s = np.arctan2(np.asarray(ms.y), np.asarray(ms.x))
        ph_q = np.arctan2(np.asarray(m_q.y), np.asarray(m_q.x))
        counts, _, _ = np.histogram2d(np.asarray(ms.z), ph_s, [ct_edges, ph_edges])
        probs, _, _ = np.histogram2d(np.asarray(m_q.z), ph_q, [ct_edges, ph_edges], weights=np.asarray(p * wt))
        assert abs(probs.sum() - 1.0) < 1e-5
        sd = np.sqrt(n * probs * (1 - probs)) + 1.0
        assert np.all(np.abs(counts - n * probs) < 5 * sd)


@pytest.mark.parametrize("kind", md.KINDS)
def test_sample_normal_moments(kind):
    n = 100_000
    ax, ay = 0.2, 0.6
    m_q, wt = sphere_rule(400, 256, hemisphere=True)
    u1, u2 = jax.random.uniform(jax.random.PRNGKey(5), (2, n), dtype=jnp.float64)
    ms = md.sample_normal(kind, ax, ay, u1, u2)
    p = md.pdf_normal(kind, m_q, ax, ay)
    assert float(jnp.sum(p * wt)) == pytest.approx(1.0, abs=1e-6)
    for g_s, g_q in zip(_moments(ms), _moments(m_q)):
        ref = float(jnp.sum(g_q * p * wt))
        se = float(jnp.std(g_s)) / math.sqrt(n)
        assert abs(float(jnp.mean(g_s)) - ref) < 5 * se + 1e-12


def test_isotropic_default_and_errors():
    w = spherical_direction(0.5, 0.3)
    for kind in md.KINDS:
        assert float(md.smith_lambda(kind, w, 0.3)) == float(md.smith_lambda(kind, w, 0.3, 0.3))
    with pytest.raises(ValueError, match="kind"):
        md.D("phong", w, 0.3)


@pytest.mark.parametrize("kind", md.KINDS)
def test_grazing_and_below_horizon(kind):
    """Zero values with finite gradients at grazing and below the horizon."""
    ax = 0.3

    def vec(a):
        return Vec3(a[0], a[1], a[2])

    up = jnp.array([0.0, 0.0, 1.0])
    graz = jnp.array([0.8, 0.6, 0.0])
    below = jnp.array([0.6, 0.0, -0.8])
    # D vanishes for m on or below the horizon
    assert float(md.D(kind, vec(graz), ax)) == 0.0
    assert float(md.D(kind, vec(below), ax)) == 0.0
    # grazing w: G1 = 0, pdf_visible = 0
    assert float(md.G1(kind, vec(graz), vec(up), ax)) == 0.0
    assert float(md.pdf_visible(kind, vec(graz), vec(up), ax)) == 0.0
    # below-horizon w sees the back of the facets only (Walter's chi+((w.m)(w.n)))
    assert float(md.G1(kind, vec(below), vec(up), ax)) > 0.0
    # a steep facet tilted towards w shows w its front only from above: w.m > 0, w.z < 0
    assert float(md.G1(kind, vec(below), vec(jnp.array([0.9, 0.0, math.sqrt(0.19)])), ax)) == 0.0
    fns = {
        "D": lambda w, m, a: md.D(kind, vec(m), a, 0.5 * a),
        "lambda": lambda w, m, a: md.smith_lambda(kind, vec(w), a, 0.5 * a),
        "G1": lambda w, m, a: md.G1(kind, vec(w), vec(m), a, 0.5 * a),
        "G2": lambda w, m, a: md.G2(kind, vec(w), Vec3(0.0, 0.6, 0.8), vec(m), a, 0.5 * a),
        "G2t": lambda w, m, a: md.G2(kind, vec(w), Vec3(0.0, 0.6, -0.8), vec(m), a, 0.5 * a),
        "pdf_visible": lambda w, m, a: md.pdf_visible(kind, vec(w), vec(m), a, 0.5 * a),
        "sample_visible": lambda w, m, a: jnp.sum(md.sample_visible(kind, vec(w), a, 0.5 * a, 0.3, 0.7).to_array()),
    }
    # all 9 (w, m) combinations at once; the functions are element-wise, so the gradient of
    # the sum holds each element's gradient
    W = jnp.stack([w for w in (up, graz, below) for _ in range(3)], axis=1)
    M = jnp.stack([m for _ in range(3) for m in (up, graz, below)], axis=1)

    @jax.jit
    def all_grads(w, m, a):  # one compilation for all functions
        return {name: jax.grad(lambda w, m, a: jnp.sum(fn(w, m, a)), argnums=(0, 1, 2))(w, m, a)
                for name, fn in fns.items()}

    for name, grads in all_grads(W, M, ax).items():
        assert all(bool(jnp.all(jnp.isfinite(g))) for g in grads), name


@pytest.mark.parametrize("kind", md.KINDS)
def test_sample_visible_gradient_matches_finite_differences(kind):
    """d m / d alpha through the sampler (reparameterisation; Beckmann: implicit Newton step)."""
    w = spherical_direction(0.9, 0.4)

    def f(a):
        m = md.sample_visible(kind, w, a, 0.7 * a, 0.37, 0.81)
        return m.x + 2.0 * m.y + 3.0 * m.z

    testing.assert_gradients(f, 0.35, rtol=1e-5, name=f"sample_visible[{kind}]")
