"""bsdf.barb_frames: the barb primitive's shading frame (Huang [T:1690-1704, 1792]) and mu noise per
barb ([T:1750]): orthonormal right-handed frames, the barbule axis at the stated angle from the ramus,
the barb plane's normal from the vertex normal, and the noise's moments against its standard error."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.bsdf import barb_frames as bf
from appearance_jax.bsdf import rock_dove as rd
from appearance_jax.core import vec as V
from appearance_jax.core.vec import Vec3


def _random(seed, n):
    r = np.random.default_rng(seed).normal(size=(3, n))
    return Vec3(*(jnp.asarray(v) for v in r))


def test_frames_are_orthonormal_right_handed_with_n_from_the_vertex_normal():
    T, N = _random(1, 64), _random(2, 64)
    for angle in (0.5 * math.pi, 0.3, 1.2):
        f = bf.barb_frame(T, N, angle)
        for a, b in ((f.s, f.t), (f.t, f.n), (f.s, f.n)):
            np.testing.assert_allclose(np.asarray(V.dot(a, b)), 0.0, atol=1e-12)
        for a in (f.s, f.t, f.n):
            np.testing.assert_allclose(np.asarray(V.norm(a)), 1.0, rtol=1e-12)
        np.testing.assert_allclose(np.asarray(V.dot(V.cross(f.s, f.t), f.n)), 1.0, rtol=1e-12)
        # n is the vertex normal's direction; the barbule axis makes the given angle with the ramus
        np.testing.assert_allclose(np.asarray(V.dot(f.n, V.normalize(N))), 1.0, rtol=1e-12)
        tp = V.normalize(T - f.n * V.dot(f.n, T))
        np.testing.assert_allclose(np.asarray(V.dot(f.t, tp)), math.cos(angle), atol=1e-12)


def test_perpendicular_barbules_put_the_ramus_across_them():
    """Default angle pi/2: the ramus tangent is local x (neighbours H apart along it), the barbule
    axis local y, the vertex normal local z; a direction along the ramus is local (1, 0, 0)."""
    f = bf.barb_frame(Vec3(2.0, 0.0, 0.0), Vec3(0.0, 0.0, 3.0))
    np.testing.assert_allclose([float(c) for c in f.s], [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose([float(c) for c in f.t], [0, 1, 0], atol=1e-15)
    w = f.to_local(Vec3(0.6, 0.0, 0.8))
    np.testing.assert_allclose([float(c) for c in w], [0.6, 0.0, 0.8], atol=1e-15)
    # a tilted vertex normal tilts the barb plane, the tangent is made orthogonal to it
    g = bf.barb_frame(Vec3(1.0, 0.0, 0.5), Vec3(0.0, 0.0, 1.0))
    np.testing.assert_allclose([float(c) for c in g.s], [1, 0, 0], atol=1e-15)


def test_mu_noise_per_barb():
    mu = bf.barb_mu(-0.35, 0.05, jax.random.PRNGKey(4), 20000)
    m = np.asarray(mu)
    assert m.shape == (20000,)
    assert abs(m.mean() + 0.35) < 4.5 * 0.05 / math.sqrt(m.size)
    assert abs(m.std(ddof=1) - 0.05) < 4.5 * 0.05 / math.sqrt(2 * (m.size - 1))
    np.testing.assert_array_equal(m, np.asarray(bf.barb_mu(-0.35, 0.05, jax.random.PRNGKey(4), 20000)))
    wide = np.asarray(bf.barb_mu(1.4, 2.0, jax.random.PRNGKey(0), 2000))
    assert np.all(np.abs(wide) < 0.5 * math.pi) and np.any(np.abs(wide) > 1.57)
    rd.Params(mu=jnp.asarray(wide))  # every value is a valid mu
    np.testing.assert_array_equal(np.asarray(bf.barb_mu(-0.35, 0.0, jax.random.PRNGKey(0), 3)), -0.35)


@pytest.mark.parametrize("call, match", [
    (lambda: bf.barb_frame(Vec3(0.0, 0.0, 0.0), Vec3(0.0, 0.0, 1.0)), "tangent"),
    (lambda: bf.barb_frame(Vec3(1.0, 0.0, 0.0), Vec3(float("nan"), 0.0, 1.0)), "normal"),
    (lambda: bf.barb_frame(Vec3(0.0, 0.0, 2.0), Vec3(0.0, 0.0, 1.0)), "parallel"),
    (lambda: bf.barb_mu(-0.35, -0.1, jax.random.PRNGKey(0), 3), "sigma = -0.1"),
    (lambda: bf.barb_mu(1.7, 0.1, jax.random.PRNGKey(0), 3), "mu = 1.7"),
    (lambda: bf.barb_mu(0.0, 0.1, jax.random.PRNGKey(0), 0), "n_barbs"),
])
def test_bad_input_is_named(call, match):
    with pytest.raises(ValueError, match=match):
        call()
