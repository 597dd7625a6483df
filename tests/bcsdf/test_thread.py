"""Sadeghi's thread BCSDF (Eqs. 5.6-5.11, Sadeghi 2011): spec seed-002 K2 regression values,
K3 structure, reciprocity, units, decisions D-C1/D-C2, gradients (forward mode) vs finite differences."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import testing
from appearance_jax.bcsdf import thread
from appearance_jax.core.vec import Vec3, cross, normalize
from appearance_jax.optics.fresnel import fresnel_dielectric

D = math.pi / 180.0
# compiled once per shape (op by op, each primitive of them compiles separately)
_fresnel = jax.jit(lambda c, eta: fresnel_dielectric(c, eta)[0])
_gaussian = jax.jit(thread.gaussian)

LINEN = thread.linen()
POLY_FLAT = thread.Params(eta=1.539, albedo=tuple(0.035 * np.array([1.0, 0.37, 0.30])), k_d=0.1, gamma_s=2.5,
                          gamma_v=5.0)
POLY_TWISTED = thread.Params(eta=1.539, albedo=tuple(0.2 * np.array([1.0, 0.37, 0.30])), k_d=0.7, gamma_s=30.0,
                             gamma_v=60.0)
ARGS = np.array([(30, -30, 0), (0, 0, 0), (60, -60, 0), (30, -10, 0), (30, -30, 90)], float) * D
# spec seed-002 §3.4 K2 (library defaults: radians, half-difference theta_d, longitudinal volume Fresnel)
K2 = {
    "linen": (LINEN, [(0.1339, 0.2583, 0.2997), (0.0936, 0.1746, 0.2016), (0.8236, 1.4095, 1.6048),
                      (0.0848, 0.1781, 0.2092), (0.1427, 0.2670, 0.3085)]),
    "poly_flat": (POLY_FLAT, [(0.6721, 0.6071, 0.5999), (0.4793, 0.4369, 0.4322), (3.9779, 3.6739, 3.6401),
                              (0.0130, 0.0049, 0.0040), (0.6911, 0.6261, 0.6189)]),
    "poly_twisted": (POLY_TWISTED, [(0.1613, 0.0896, 0.0816), (0.1086, 0.0618, 0.0566), (0.8241, 0.4884, 0.4511),
                                    (0.1276, 0.0705, 0.0642), (0.1629, 0.0912, 0.0832)]),
}


@pytest.mark.parametrize("name", list(K2))
def test_k2_regression_values(name):
    p, want = K2[name]
    got = np.asarray(thread.eval_angles(p, ARGS[:, 0], ARGS[:, 1], ARGS[:, 2]))
    np.testing.assert_allclose(got, np.array(want), atol=6e-5, rtol=0)


def test_k2_linen_surface_term():
    assert float(thread.surface_term(LINEN, 30 * D, -30 * D, 0.0)) == pytest.approx(0.0693, abs=5e-5)


def test_gamma_is_in_degrees_and_gaussian_unit_area():
    # D-C3: g(gamma, 0) = 1 / (sqrt(2 pi) gamma_rad), and g integrates to 1 over radians
    x = np.linspace(-2.0, 2.0, 4001)
    g = np.asarray(_gaussian(12.0 * D, x))
    assert g[2000] == pytest.approx(1.0 / (math.sqrt(2 * math.pi) * 12.0 * D), rel=1e-12)
    assert np.trapezoid(g, x) == pytest.approx(1.0, rel=1e-8)


def test_k3_structure():
    p = LINEN
    # the surface lobe of a smooth (flat) thread peaks at theta_r = -theta_i (theta_h = 0), no cuticle-like
    # shift (the rising Fresnel factor moves the maximum of a wide lobe by ~2 deg: Linen at 30 deg)
    tr = np.linspace(-80, 80, 1601) * D
    for ti in (10.0, 30.0, 50.0):
        fs = np.asarray(thread.surface_term(POLY_FLAT, ti * D, tr, 0.0))
        assert abs(tr[np.argmax(fs)] / D + ti) < 0.5
        F = np.asarray(_fresnel(jnp.asarray(np.cos((ti * D - tr) / 2)), 1.539))
        assert abs(tr[np.argmax(fs / F)] / D + ti) < 0.051
    # f_rs / (F_r(eq 5.8 angle) cos(phi_d / 2)) = g(gamma_s, theta_h), independent of phi_d
    phi = np.linspace(-3.0, 3.0, 13)
    fs = np.asarray(thread.surface_term(p, 40 * D, -20 * D, phi))
    c58 = math.cos(30 * D) * np.cos(phi / 2)
    F = np.asarray(_fresnel(jnp.asarray(c58), 1.46))
    ratio = fs / (F * np.cos(phi / 2))
    np.testing.assert_allclose(ratio, float(_gaussian(12 * D, 10 * D)), rtol=1e-10)
    # k_d = 1: f_rv = F A / (cos ti + cos tr)
    ti, trr = 40 * D, -10 * D
    q = p.replace(k_d=1.0)
    F2 = (1 - _fresnel(math.cos(ti), 1.46)) * (1 - _fresnel(math.cos(trr), 1.46))
    want = float(F2) / (math.cos(ti) + math.cos(trr)) * np.asarray(q.albedo)
    np.testing.assert_allclose(np.asarray(thread.volume_term(q, ti, trr, 0.7)), want, rtol=1e-10)
    # k_d = 0: the volume lobe is a Gaussian of std gamma_v in theta_h (times the smooth F / (cos + cos))
    q = p.replace(k_d=0.0)
    th_h = np.array([0.0, 10.0, 20.0]) * D
    ti = 20 * D + th_h
    trr = -20 * D + th_h  # theta_i + theta_r = 2 theta_h, fixed difference
    v = np.asarray(thread.volume_term(q, ti, trr, 0.0))[:, 1]
    F2 = np.array([(1 - _fresnel(math.cos(a), 1.46)) * (1 - _fresnel(math.cos(b), 1.46)) for a, b in zip(ti, trr)])
    lobe = v * (np.cos(ti) + np.cos(trr)) / F2 / float(np.asarray(q.albedo)[1])
    np.testing.assert_allclose(lobe, np.asarray(_gaussian(24 * D, th_h)), rtol=1e-10)


def _random_frame_dirs(key, n):
    k1, k2, k3 = jax.random.split(jax.random.key(key), 3)
    t = normalize(Vec3(*jax.random.normal(k1, (3, n))))
    a = normalize(Vec3(*jax.random.normal(k2, (3, n))))
    nn = normalize(cross(cross(t, a), t))
    v = cross(t, nn)
    d = jax.random.normal(k3, (6, n))
    return t, nn, v, normalize(Vec3(*d[:3])), normalize(Vec3(*d[3:]))


@pytest.mark.parametrize("opts", [dict(), pytest.param(dict(theta_d="full", volume_fresnel="eq58"),
                                                         marks=pytest.mark.slow)])
def test_reciprocity(opts):
    p = LINEN.replace(**opts)
    t, n, v, wi, wo = _random_frame_dirs(0, 256)
    a = np.asarray(thread.eval(p, t, n, v, wi, wo))
    b = np.asarray(thread.eval(p, t, n, v, wo, wi))
    assert np.all(np.isfinite(a)) and a.max() > 0.1
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-14)


@pytest.mark.slow
def test_frame_form_equals_angle_form():
    t, n, v, wi, wo = _random_frame_dirs(1, 64)
    from appearance_jax.core.vec import dot

    th_i, th_r = np.arcsin(np.asarray(dot(wi, t))), np.arcsin(np.asarray(dot(wo, t)))
    ph_i = np.arctan2(np.asarray(dot(wi, v)), np.asarray(dot(wi, n)))
    ph_r = np.arctan2(np.asarray(dot(wo, v)), np.asarray(dot(wo, n)))
    a = np.asarray(thread.eval(POLY_TWISTED, t, n, v, wi, wo))
    b = np.asarray(thread.eval_angles(POLY_TWISTED, th_i, th_r, ph_i - ph_r))
    np.testing.assert_allclose(a, b, rtol=1e-10)


def test_literal_theta_d_singularity_is_finite():
    # D-C1 "full": cos^2(theta_i - theta_r) = 0 on the specular cone at 45 deg: 0, never inf/NaN
    p = LINEN.replace(theta_d="full")
    f = np.asarray(thread.eval_angles(p, 45 * D, -45 * D, 0.0))
    assert np.all(np.isfinite(f)) and np.all(f == 0.0)
    near = np.asarray(thread.eval_angles(p, 44 * D, -44 * D, 0.0))
    half = np.asarray(thread.eval_angles(LINEN, 44 * D, -44 * D, 0.0))
    assert np.all(near > 100 * half)  # the literal form blows up next to the cone


def test_volume_fresnel_option_changes_only_the_volume_term():
    p2 = LINEN.replace(volume_fresnel="eq58")
    a = (40 * D, -10 * D, 2.0)
    assert float(thread.surface_term(p2, *a)) == float(thread.surface_term(LINEN, *a))
    assert not np.allclose(np.asarray(thread.volume_term(p2, *a)), np.asarray(thread.volume_term(LINEN, *a)))


def test_gradients_forward_mode_vs_finite_differences():
    args = (jnp.asarray(ARGS[:, 0] + 0.05), jnp.asarray(ARGS[:, 1] - 0.03), jnp.asarray(ARGS[:, 2] + 0.2))
    p0 = LINEN
    w = jnp.asarray(np.random.default_rng(0).uniform(size=(5, 3)))

    @jax.jit
    def fn(x):
        q = thread.Params(eta=x[0], albedo=x[1:4], k_d=x[4], gamma_s=x[5], gamma_v=x[6])
        return jnp.sum(w * thread.eval_angles.kernel(q, *args))

    x0 = jnp.array([1.46, 0.06, 0.24, 0.3, 0.3, 12.0, 24.0])
    r = testing.assert_gradients(fn, x0, step=1e-6 / 24.0, rtol=1e-6, atol=1e-9, elementwise=True, name="thread")
    assert np.all(np.abs(r.ad[0]) > 1e-6)  # every parameter matters here
    del p0


def test_bad_parameter_is_named():
    with pytest.raises(ValueError, match=r"thread.Params.k_d = 1.5 is outside the valid range \[0, 1\]"):
        thread.eval_angles(thread.Params(k_d=1.5), 0.1, 0.2, 0.3)
    with pytest.raises(ValueError, match=r"gamma_s = 0 .*\(0, 90\]"):
        thread.eval_angles(thread.Params(gamma_s=0.0), 0.1, 0.2, 0.3)


def test_registered_model_is_the_thread_in_the_fiber_frame():
    """``cloth_thread`` (thread.MODEL) evaluates in the fiber frame of bcsdf: x = tangent,
    theta from the normal plane and phi = atan2(w.z, w.y) (core.frame.fiber_angles)."""
    from appearance_jax import registry
    from appearance_jax.core.frame import fiber_angles

    m = registry.get("cloth_thread")
    assert m is thread.MODEL and m.kind == "bcsdf" and m.reciprocal
    _, _, _, wi, wo = _random_frame_dirs(2, 256)  # the size of test_reciprocity's draws (same op programs)
    th_i, ph_i = (np.asarray(a) for a in fiber_angles(wi))
    th_r, ph_r = (np.asarray(a) for a in fiber_angles(wo))
    a = np.asarray(m.eval(POLY_TWISTED, wi, wo))
    b = np.asarray(thread.eval_angles(POLY_TWISTED, th_i, th_r, ph_i - ph_r))
    np.testing.assert_allclose(a, b, rtol=1e-10)
