"""SGGX distribution helpers (Heitz et al. 2015; seed-000 spec M14)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import testing
from appearance_jax.core.quadrature import sphere_rule
from appearance_jax.core.vec import Vec3, dot
from appearance_jax.microfacet import sggx

CASES = ((1.0, 0.0), (0.5, 0.4), (0.2, 1.1))


def _dirs(n, key):
    return testing.random_directions(key, n, "sphere")


def test_flake_matrix_is_q_diag_qt():
    alpha, theta = 0.3, 0.7
    c, s = math.cos(theta), math.sin(theta)
    Q = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])  # R_x(theta): columns w1, w2, w3
    ref = Q @ np.diag([alpha**2, alpha**2, 1.0]) @ Q.T
    S = sggx.flake_matrix(alpha, theta)
    np.testing.assert_allclose(S.to_array(), ref, atol=1e-15)
    np.testing.assert_allclose(Q[:, 2], [0.0, -s, c])
    w3 = sggx.mean_normal(theta)
    np.testing.assert_allclose([w3.x, w3.y, w3.z], Q[:, 2], atol=1e-15)
    np.testing.assert_allclose(S.det(), alpha**4, rtol=1e-13)
    np.testing.assert_allclose(S.adjugate().to_array(), np.linalg.inv(ref) * alpha**4, atol=1e-14)


def test_identity_is_isotropic():
    m = _dirs(100, 0)
    S = sggx.identity()
    np.testing.assert_allclose(sggx.D(S, m), 1 / math.pi, rtol=1e-14)
    np.testing.assert_allclose(sggx.projected_area(S, m), 1.0, rtol=1e-14)
    np.testing.assert_allclose(sggx.flake_D(1.0, sggx.mean_normal(0.3), m), 1 / math.pi, rtol=1e-14)


@pytest.mark.parametrize("alpha,theta", CASES + ((0.05, 0.3),))
def test_generic_equals_closed_form_and_dense(alpha, theta):
    m, w = _dirs(200, 1), _dirs(200, 2)
    S = sggx.flake_matrix(alpha, theta)
    w3 = sggx.mean_normal(theta)
    np.testing.assert_allclose(sggx.D(S, m), sggx.flake_D(alpha, w3, m), rtol=1e-10)
    np.testing.assert_allclose(sggx.projected_area(S, w), sggx.flake_projected_area(alpha, w3, w), rtol=1e-12)
    Sd = np.asarray(S.to_array())
    M = np.stack([np.asarray(c) for c in m], -1)
    q = np.einsum("ni,ij,nj->n", M, np.linalg.inv(Sd), M)
    dense = 1 / (math.pi * math.sqrt(np.linalg.det(Sd)) * q**2)
    np.testing.assert_allclose(sggx.D(S, m), dense, rtol=1e-9)


@pytest.mark.parametrize("alpha,theta", CASES)
def test_projected_area_identity_and_total_area(alpha, theta):
    """int max(0, w.m) D dm = sigma(w); int |w.m| D = 2 sigma; int D = closed-form total area."""
    m, wq = sphere_rule(400, 400)
    S = sggx.flake_matrix(alpha, theta)
    d = np.asarray(sggx.D(S, m)) * np.asarray(wq)
    ws = _dirs(5, 3)
    for i in range(5):
        w = Vec3(*(c[i] for c in ws))
        c = np.asarray(dot(w, m))
        sig = float(sggx.projected_area(S, w))
        np.testing.assert_allclose(np.sum(np.maximum(c, 0) * d), sig, rtol=2e-4)
        np.testing.assert_allclose(np.sum(np.abs(c) * d), 2 * sig, rtol=2e-4)
    np.testing.assert_allclose(np.sum(d), float(sggx.flake_total_area(alpha)), rtol=2e-4)


def test_total_area_values():
    np.testing.assert_allclose(sggx.flake_total_area(0.5), 2.76, atol=5e-4)  # spec M14
    np.testing.assert_allclose(sggx.flake_total_area(1.0), 4.0, rtol=1e-12)
    np.testing.assert_allclose(sggx.flake_total_area(0.9999999), 4.0, rtol=1e-6)
    assert abs(float(sggx.flake_total_area(1e-3)) - 2.0) < 2e-5
    a = np.array([0.1, 0.05, 0.01])
    assert np.all(np.diff(np.asarray(sggx.flake_total_area(a))) < 0)  # decreasing towards 2
    # max_w sigma = 1 along w3, min alpha in the flake plane
    S = sggx.flake_matrix(0.2, 0.5)
    np.testing.assert_allclose(sggx.projected_area(S, sggx.mean_normal(0.5)), 1.0, rtol=1e-14)
    np.testing.assert_allclose(sggx.projected_area(S, Vec3(1.0, 0.0, 0.0)), 0.2, rtol=1e-14)


@pytest.mark.parametrize("alpha,theta", CASES)
def test_visible_normal_pdf_integrates_to_one(alpha, theta):
    m, wq = sphere_rule(400, 400)
    S = sggx.flake_matrix(alpha, theta)
    ws = _dirs(4, 4)
    wi = ws.map(lambda a: a[:, None])
    tot = np.sum(np.asarray(sggx.visible_normal_pdf(S, wi, m.map(lambda a: a[None]))) * np.asarray(wq), axis=1)
    np.testing.assert_allclose(tot, 1.0, rtol=2e-4)


@pytest.mark.parametrize("alpha,theta", ((0.5, 0.4), (0.15, 1.0)))
def test_sampled_normals_follow_visible_pdf(alpha, theta):
    """Histogram of c = m.w3 of sampled normals vs the visible-normal pdf (per-bin z-test)."""
    n = 2**17
    S = sggx.flake_matrix(alpha, theta)
    w3 = sggx.mean_normal(theta)
    wi1 = Vec3(0.48, 0.6, 0.64)
    wi = wi1.map(lambda a: jnp.full((n,), a))
    u1, u2 = jax.random.uniform(jax.random.key(5), (2, n), jnp.float64)
    m = sggx.sample_visible_normal(S, wi, u1, u2)
    np.testing.assert_allclose(dot(m, m), 1.0, atol=1e-12)
    assert float(jnp.min(dot(wi, m))) >= -1e-12
    # expected bin probabilities by quadrature of the visible-normal pdf
    q, wq = sphere_rule(600, 600)
    pq = np.asarray(sggx.visible_normal_pdf(S, wi1, q)) * np.asarray(wq)
    cq, cs = np.asarray(dot(q, w3)), np.asarray(dot(m, w3))
    # second coordinate: the azimuth about w3 (a 2D histogram in (c, phi))
    def phi(v):
        return np.arctan2(np.asarray(v.x), np.asarray(dot(v, Vec3(0.0, math.cos(theta), math.sin(theta)))))
    edges_c, edges_p = np.linspace(-1, 1, 11), np.linspace(-math.pi, math.pi, 9)
    exp, _, _ = np.histogram2d(cq, phi(q), [edges_c, edges_p], weights=pq)
    obs, _, _ = np.histogram2d(cs, phi(m), [edges_c, edges_p])
    np.testing.assert_allclose(exp.sum(), 1.0, rtol=1e-3)
    p = obs / n
    se = np.sqrt(np.maximum(exp * (1 - exp), 1e-12) / n)
    z = np.abs(p - exp) / se
    assert np.all((z < 5.0) | (exp < 1e-6)), np.max(z)


def test_sampler_gradient_finite_and_jittable():
    wi = _dirs(16, 6)
    u = jax.random.uniform(jax.random.key(7), (2, 16), jnp.float64)

    def f(alpha, theta):
        m = sggx.sample_visible_normal(sggx.flake_matrix(alpha, theta), wi, u[0], u[1])
        return jnp.sum(m.x + 2 * m.y + 3 * m.z)

    r = testing.assert_gradients(jax.jit(lambda x: f(*x)), (0.3, 0.5), rtol=1e-5, name="sggx sampler")
    assert all(np.isfinite(a[0]) and a[0] != 0 for a in r.ad)


def test_small_alpha_is_finite():
    a = sggx.ALPHA_MIN
    S = sggx.flake_matrix(a, 0.2)
    w3 = sggx.mean_normal(0.2)
    np.testing.assert_allclose(sggx.D(S, w3), 1 / (math.pi * a * a), rtol=1e-6)
    wi = _dirs(64, 8)
    u = jax.random.uniform(jax.random.key(9), (2, 64), jnp.float64)
    m = sggx.sample_visible_normal(S, wi, u[0], u[1])
    assert np.all(np.isfinite(np.asarray(m.to_array())))
    # nearly flat flakes: the visible normal is (anti-)aligned with w3 to within ~alpha
    assert np.all(np.abs(np.asarray(dot(m, w3))) > 1 - 1e-3)
