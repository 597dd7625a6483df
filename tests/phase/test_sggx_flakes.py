"""Specular SGGX microflake phase function (Eq. 4.10, Padrón 2025; seed-000 spec M14)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import testing
from appearance_jax.core.vec import Vec3, dot
from appearance_jax.phase import sggx_flakes as sf


def _dirs(n, key):
    return testing.random_directions(key, n, "sphere")


def _rot_x(w: Vec3, theta):
    c, s = math.cos(theta), math.sin(theta)
    return Vec3(w.x, c * w.y - s * w.z, s * w.y + c * w.z)


def test_isotropic_limit_and_shape():
    wi, wo = _dirs(50, 0), _dirs(50, 1)
    f = sf.eval(sf.Params(alpha=1.0, theta=0.7), wi, wo)
    assert f.shape == (50, 1)
    np.testing.assert_allclose(f, 1 / (4 * math.pi), rtol=1e-13)
    np.testing.assert_allclose(sf.sigma(sf.Params(alpha=1.0), wi), 1.0, rtol=1e-14)


def test_presets_from_table_a1():
    p = sf.MODEL.presets
    assert set(p) == {"dewy1", "dewy2", "matte1", "matte2"}
    np.testing.assert_allclose([p["dewy2"].alpha, p["dewy2"].theta], [0.002, math.radians(5.5)])
    np.testing.assert_allclose([p["matte2"].alpha, p["matte2"].theta], [0.49, math.radians(52.2)])


def test_value_is_d_over_4_sigma_and_peaks_at_mirror_of_mean_normal():
    p = sf.Params(alpha=0.2, theta=0.3)
    w3 = Vec3(0.0, -math.sin(0.3), math.cos(0.3))
    wi = Vec3(jnp.asarray(0.3), jnp.asarray(0.2), jnp.asarray(math.sqrt(0.87)))
    wo_mirror = w3 * (2 * dot(wi, w3)) - wi
    peak = float(sf.eval(p, wi, wo_mirror)[0])
    sig = math.sqrt(0.04 + 0.96 * float(dot(wi, w3)) ** 2)
    np.testing.assert_allclose(peak, 1 / (math.pi * 0.04) / (4 * sig), rtol=1e-12)
    others = sf.eval(p, wi.map(lambda a: jnp.full((3000,), a)), _dirs(3000, 2))
    assert float(jnp.max(others)) < peak
    np.testing.assert_allclose(sf.eval(p, wi, -wi), 0.0)  # wh undefined: measure zero


@pytest.mark.parametrize("alpha,theta", ((0.5, 0.0), (0.3, 0.6), (0.15, 1.2)))
def test_normalised_white_furnace(alpha, theta):
    testing.assert_white_furnace(sf.MODEL, sf.Params(alpha=alpha, theta=theta), key=3, lossless=True,
                                 n_wi=3, n_theta=256, n_phi=256)


@pytest.mark.parametrize("alpha,theta", ((0.5, 0.4), (0.2, 0.9)))
def test_chi2_sampler(alpha, theta):
    testing.assert_chi2(sf.MODEL, sf.Params(alpha=alpha, theta=theta), key=4, n_samples=2**16, n_wi=2, n_tests=4)


def test_f_sigma_symmetric_and_f_not():
    p = sf.Params(alpha=0.25, theta=0.8)
    wi, wo = _dirs(300, 5), _dirs(300, 6)
    a = np.asarray(sf.eval(p, wi, wo))[:, 0] * np.asarray(sf.sigma(p, wi))
    b = np.asarray(sf.eval(p, wo, wi))[:, 0] * np.asarray(sf.sigma(p, wo))
    np.testing.assert_allclose(a, b, rtol=1e-12)
    f1, f2 = np.asarray(sf.eval(p, wi, wo)), np.asarray(sf.eval(p, wo, wi))
    assert np.max(np.abs(f1 - f2) / (f1 + f2)) > 0.1  # genuinely non-reciprocal


def test_sample_pdf_consistency_weight_one():
    p = sf.Params(alpha=0.3, theta=0.5)
    n = 4096
    wi = _dirs(n, 7)
    wo, weight, pdf = sf.sample(p, wi, jax.random.key(8))
    np.testing.assert_allclose(dot(wo, wo), 1.0, atol=1e-13)
    np.testing.assert_allclose(pdf, sf.pdf(p, wi, wo), rtol=1e-12)
    np.testing.assert_allclose(pdf, sf.eval(p, wi, wo)[:, 0], rtol=1e-12)
    np.testing.assert_allclose(weight, 1.0)
    assert weight.shape == (n, 1) and np.all(np.asarray(pdf) > 0)
    # explicit uniforms give the same as the key's
    u = tuple(jax.random.uniform(k, (n,), jnp.float64) for k in jax.random.split(jax.random.key(8), 2))
    wo2, _, _ = sf.sample(p, wi, u)
    np.testing.assert_allclose(wo2.x, wo.x, atol=1e-15)


def test_tilt_rotates_the_lobe():
    theta = 0.7
    wi, wo = _dirs(200, 9), _dirs(200, 10)
    f0 = sf.eval(sf.Params(alpha=0.2, theta=0.0), wi, wo)
    ft = sf.eval(sf.Params(alpha=0.2, theta=theta), _rot_x(wi, theta), _rot_x(wo, theta))
    np.testing.assert_allclose(ft, f0, rtol=1e-11)
    assert np.max(np.abs(np.asarray(sf.eval(sf.Params(alpha=0.2, theta=theta), wi, wo)) - f0)) > 0.1


def test_gradients_eval_and_sample():
    wi, wo = _dirs(32, 11), _dirs(32, 12)
    p = sf.Params(alpha=0.4, theta=0.5)
    r = testing.assert_gradients(lambda q: jnp.sum(sf.eval(q, wi, wo) ** 2) + jnp.sum(sf.sigma(q, wi)), p)
    assert all(abs(float(np.ravel(g)[0])) > 0 for g in r.ad)
    u = tuple(jax.random.uniform(k, (32,), jnp.float64) for k in jax.random.split(jax.random.key(13)))

    def sampled(q):
        wo_s, weight, pdf = sf.sample(q, wi, u)
        return jnp.sum(wo_s.x + 2 * wo_s.y - wo_s.z) + jnp.sum(jnp.log(pdf))

    testing.assert_gradients(sampled, p)


def test_traced_parameters_under_jit():
    wi, wo = _dirs(8, 14), _dirs(8, 15)
    f = jax.jit(lambda a, t: sf.eval(sf.Params(alpha=a, theta=t), wi, wo))(0.3, 0.2)
    np.testing.assert_allclose(f, sf.eval(sf.Params(alpha=0.3, theta=0.2), wi, wo), rtol=1e-15)


@pytest.mark.parametrize("field,kw", (("alpha", dict(alpha=0.0)), ("alpha", dict(alpha=2.0)),
                                      ("theta", dict(theta=3.0)), ("alpha", dict(alpha=float("nan")))))
def test_bad_parameters_raise(field, kw):
    wi, wo = _dirs(2, 0), _dirs(2, 1)
    with pytest.raises(ValueError, match=rf"Params\.{field}"):
        sf.eval(sf.Params(**kw), wi, wo)
    with pytest.raises(ValueError, match=rf"Params\.{field}"):
        sf.sample(sf.Params(**kw), wi, jax.random.key(0))
