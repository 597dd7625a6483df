import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.core import frame
from appearance_jax.core.special import safe_acos, safe_asin, safe_atan2, safe_sqrt
from appearance_jax.core.vec import Vec3, cross, dot, norm, normalize, vec3


def random_unit(key, n, hemisphere=False):
    v = jax.random.normal(key, (3, n))
    v = v / jnp.linalg.norm(v, axis=0)
    if hemisphere:
        v = v.at[2].set(jnp.abs(v[2]))
    return Vec3(*v)


def test_vec3_arithmetic_and_pytree():
    a, b = vec3([1.0, 0.0], [2.0, 1.0], [3.0, 0.0]), vec3(1.0, 1.0, 1.0)
    np.testing.assert_allclose((a + b).to_array(), [[2, 3, 4], [1, 2, 1]])
    np.testing.assert_allclose((a - b).z, [2.0, -1.0])
    np.testing.assert_allclose((2.0 * a).y, [4.0, 2.0])
    np.testing.assert_allclose((a / 2.0).x, [0.5, 0.0])
    np.testing.assert_allclose(dot(a, b), [6.0, 1.0])
    c = cross(vec3(1.0, 0.0, 0.0), vec3(0.0, 1.0, 0.0))
    np.testing.assert_allclose(c.to_array(), [0, 0, 1])
    # pytree: survives jit and tree_map, gradients flow
    out = jax.jit(lambda v: v * 3.0)(a)
    assert isinstance(out, Vec3)
    g = jax.grad(lambda v: dot(v, v).sum())(a)
    np.testing.assert_allclose(g.to_array(), 2 * a.to_array())
    np.testing.assert_allclose(Vec3.from_array(a.to_array()).to_array(), a.to_array())


def test_normalize_zero_vector_is_finite():
    z = vec3(0.0, 0.0, 0.0)
    n = normalize(z)
    assert np.all(np.asarray(n.to_array()) == 0)
    g = jax.grad(lambda x: normalize(Vec3(x, x, x)).x)(0.0)
    assert np.isfinite(g)
    np.testing.assert_allclose(norm(vec3(3.0, 4.0, 0.0)), 5.0)


def test_safe_functions_have_finite_gradients_at_edges():
    for f, x in [(safe_sqrt, 0.0), (safe_sqrt, -1.0), (safe_acos, 1.0), (safe_acos, -1.0),
                 (safe_asin, 1.0), (safe_asin, -1.0)]:
        assert np.isfinite(jax.grad(f)(x)), f
    assert np.isfinite(jax.grad(lambda y: safe_atan2(y, 0.0))(0.0))
    np.testing.assert_allclose(safe_acos(1.0 + 1e-7), 0.0)
    np.testing.assert_allclose(jax.grad(safe_sqrt)(4.0), 0.25)
    np.testing.assert_allclose(jax.grad(safe_acos)(0.5), -1 / np.sqrt(0.75))


def test_spherical_round_trip():
    th = jnp.linspace(0.01, np.pi - 0.01, 7)
    ph = jnp.linspace(-3.0, 3.0, 7)
    t2, p2 = frame.spherical_angles(frame.spherical_direction(th, ph))
    np.testing.assert_allclose(t2, th, atol=1e-12)
    np.testing.assert_allclose(p2, ph, atol=1e-12)


def test_orthonormal_basis_is_orthonormal_right_handed():
    n = random_unit(jax.random.PRNGKey(0), 500)
    s, t = frame.orthonormal_basis(n)
    for a, b in [(s, t), (s, n), (t, n)]:
        np.testing.assert_allclose(dot(a, b), 0.0, atol=1e-12)
    for a in (s, t):
        np.testing.assert_allclose(dot(a, a), 1.0, atol=1e-12)
    np.testing.assert_allclose(dot(cross(s, t), n), 1.0, atol=1e-12)
    f = frame.Frame.from_normal(n)
    v = random_unit(jax.random.PRNGKey(1), 500)
    np.testing.assert_allclose(f.to_world(f.to_local(v)).to_array(), v.to_array(), atol=1e-12)
    np.testing.assert_allclose(f.to_local(n).z, 1.0, atol=1e-12)


def test_reflect_and_refract_obey_snell_and_tir():
    n = vec3(0.0, 0.0, 1.0)
    w = random_unit(jax.random.PRNGKey(2), 1000, hemisphere=True)
    r = frame.reflect(w, n)
    np.testing.assert_allclose(r.z, w.z, atol=1e-12)
    np.testing.assert_allclose(r.x, -w.x, atol=1e-12)
    eta = 1.5
    wt, ok = frame.refract(w, n, eta)
    assert bool(jnp.all(ok))
    np.testing.assert_allclose(dot(wt, wt), 1.0, atol=1e-12)
    assert bool(jnp.all(wt.z < 0))
    # Snell: sin_i = eta sin_t, in the same plane of incidence (opposite tangential direction)
    np.testing.assert_allclose(frame.sin_theta(w), eta * frame.sin_theta(wt), atol=1e-12)
    np.testing.assert_allclose(w.x * wt.y - w.y * wt.x, 0.0, atol=1e-12)
    # from inside (dense -> rare): TIR beyond the critical angle
    crit = np.arcsin(1 / eta)
    th = jnp.array([crit - 1e-3, crit + 1e-3])
    wi = frame.spherical_direction(th, 0.0)
    _, ok = frame.refract(wi, n, 1 / eta)
    assert list(np.asarray(ok)) == [True, False]


def test_half_diff_round_trip():
    key = jax.random.PRNGKey(3)
    wi = random_unit(key, 300, hemisphere=True)
    wo = random_unit(jax.random.PRNGKey(4), 300, hemisphere=True)
    th, ph, td, pd = frame.to_half_diff(wi, wo)
    wi2, wo2 = frame.from_half_diff(th, ph, td, pd)
    np.testing.assert_allclose(wi2.to_array(), wi.to_array(), atol=1e-9)
    np.testing.assert_allclose(wo2.to_array(), wo.to_array(), atol=1e-9)
    # theta_d is the angle between wi and h
    h = frame.half_vector(wi, wo)
    np.testing.assert_allclose(jnp.cos(td), dot(wi, h), atol=1e-9)


def test_fiber_angles_round_trip():
    th = jnp.linspace(-1.4, 1.4, 9)
    ph = jnp.linspace(-3.0, 3.0, 9)
    w = frame.fiber_direction(th, ph)
    np.testing.assert_allclose(w.x, jnp.sin(th), atol=1e-12)
    t2, p2 = frame.fiber_angles(w)
    np.testing.assert_allclose(t2, th, atol=1e-12)
    np.testing.assert_allclose(p2, ph, atol=1e-12)


def test_in_plane_convention_mirror_and_retro():
    th = jnp.deg2rad(jnp.array([10.0, 45.0, 70.0]))
    wi, wo = frame.in_plane_directions(th, th)  # theta_o = theta_i: mirror
    np.testing.assert_allclose(frame.reflect(wi, vec3(0.0, 0.0, 1.0)).to_array(), wo.to_array(), atol=1e-12)
    wi, wo = frame.in_plane_directions(th, -th)  # theta_o = -theta_i: retro-reflection
    np.testing.assert_allclose(wi.to_array(), wo.to_array(), atol=1e-12)


def test_polar_and_azimuth_helpers():
    th, ph = jnp.array([0.3, 1.2, 0.0]), jnp.array([0.7, -2.0, 1.0])
    w = frame.spherical_direction(th, ph)
    np.testing.assert_allclose(frame.tan2_theta(w), jnp.tan(th) ** 2, rtol=1e-12)
    c, s = frame.cos_sin_phi(w)
    np.testing.assert_allclose(c[:2], jnp.cos(ph[:2]), atol=1e-12)
    np.testing.assert_allclose(s[:2], jnp.sin(ph[:2]), atol=1e-12)
    assert float(c[2]) == 1.0 and float(s[2]) == 0.0  # the pole: azimuth defined as 0
    assert float(frame.tan2_theta(vec3(1.0, 0.0, 0.0))) >= 1e30  # grazing: large, finite
    down = vec3(0.0, 0.0, -1.0)
    assert list(np.asarray(frame.same_hemisphere(w, down))) == [False, False, False]
    assert list(np.asarray(frame.same_hemisphere(w, w))) == [True, True, True]
