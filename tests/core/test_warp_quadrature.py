import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.core import warp
from appearance_jax.core.quadrature import gauss_legendre, sphere_rule
from appearance_jax.core.rng import uniforms


def test_gauss_legendre_is_exact_for_degree_2n_minus_1():
    x, w = gauss_legendre(5, 0.0, 2.0)
    for deg in range(10):
        np.testing.assert_allclose(np.sum(w * x**deg), 2.0 ** (deg + 1) / (deg + 1), rtol=1e-12)
    with pytest.raises(ValueError, match="n = 0"):
        gauss_legendre(0)


def test_sphere_rule_weights_and_moments():
    d, w = sphere_rule(16, 32)
    np.testing.assert_allclose(w.sum(), 4 * np.pi, rtol=1e-12)
    np.testing.assert_allclose(jnp.sum(w * d.z**2), 4 * np.pi / 3, rtol=1e-12)
    dh, wh = sphere_rule(16, 32, hemisphere=True)
    np.testing.assert_allclose(wh.sum(), 2 * np.pi, rtol=1e-12)
    np.testing.assert_allclose(jnp.sum(wh * dh.z), np.pi, rtol=1e-12)


@pytest.mark.parametrize(
    "fn, pdf, domain",
    [
        (warp.square_to_uniform_sphere, warp.square_to_uniform_sphere_pdf, "sphere"),
        (warp.square_to_uniform_hemisphere, warp.square_to_uniform_hemisphere_pdf, "hemi"),
        (warp.square_to_cosine_hemisphere, warp.square_to_cosine_hemisphere_pdf, "hemi"),
    ],
)
def test_direction_warps_match_their_pdfs(fn, pdf, domain):
    # (1) the pdf integrates to 1 over its domain
    d, w = sphere_rule(32, 64, hemisphere=(domain == "hemi"))
    np.testing.assert_allclose(jnp.sum(w * pdf(d)), 1.0, rtol=1e-10)
    # (2) samples are unit, and E[z], E[z^2] under sampling equal the pdf's moments (5 sigma)
    n = 200_000
    u1, u2 = uniforms(jax.random.PRNGKey(0), (n,), 2)
    s = fn(u1, u2)
    np.testing.assert_allclose(s.x**2 + s.y**2 + s.z**2, 1.0, atol=1e-10)
    for k in (1, 2):
        exact = jnp.sum(w * pdf(d) * d.z**k)
        est = jnp.mean(s.z**k)
        se = jnp.std(s.z**k) / np.sqrt(n)
        assert abs(est - exact) < 5 * se + 1e-12, (k, est, exact, se)
    # azimuth uniform: E[cos phi] = 0
    assert abs(jnp.mean(s.x)) < 5 * jnp.std(s.x) / np.sqrt(n)


def test_concentric_disk_covers_unit_disk_uniformly():
    n = 100_000
    u1, u2 = uniforms(jax.random.PRNGKey(1), (n,), 2)
    x, y = warp.square_to_uniform_disk_concentric(u1, u2)
    r2 = x * x + y * y
    assert float(r2.max()) <= 1.0 + 1e-12
    # uniform on the disk: r^2 is U(0, 1) -> mean 1/2, se sqrt(1/12 / n)
    assert abs(float(r2.mean()) - 0.5) < 5 * np.sqrt(1 / 12 / n)
    x0, y0 = warp.square_to_uniform_disk_concentric(jnp.array(0.5), jnp.array(0.5))
    assert float(x0) == 0 and float(y0) == 0


def test_uniforms_accepts_keys_and_arrays():
    a = uniforms(jax.random.PRNGKey(0), (4,), 3)
    assert len(a) == 3 and a[0].shape == (4,)
    b = uniforms((0.1, 0.2), (4,), 2)
    np.testing.assert_allclose(b[1], 0.2)
    with pytest.raises(ValueError, match="needs 3"):
        uniforms((0.1, 0.2), (4,), 3)
