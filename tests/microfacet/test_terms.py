"""D_terms and G2_terms: D and G2 / (|wi.z| |wo.z|) as fractions (num, den), which the rough
dielectric and plastic fold into their own single division, against D and G2."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.core.vec import Vec3, normalize
from appearance_jax.microfacet import distribution as md


def _sphere(key, n):
    v = jax.random.normal(key, (3, n), dtype=jnp.float64)
    v = v / jnp.linalg.norm(v, axis=0)
    return Vec3(v[0], v[1], v[2])


@pytest.mark.parametrize("kind", md.KINDS)
@pytest.mark.parametrize("ax,ay", [(0.3, None), (0.15, 0.45), (1e-3, 1e-3), (2.0, 0.5)])
def test_d_terms(kind, ax, ay):
    m = _sphere(jax.random.PRNGKey(0), 4000)  # half of them below the horizon
    num, den = md.D_terms(kind, m, ax, ay)
    assert bool(jnp.all(den > 0))
    np.testing.assert_allclose(np.asarray(num / den), np.asarray(md.D(kind, m, ax, ay)), rtol=1e-14, atol=0)
    assert bool(jnp.all(jnp.where(m.z <= 0, num == 0, True)))


@pytest.mark.parametrize("kind", md.KINDS)
@pytest.mark.parametrize("correlated", [True, False])
@pytest.mark.parametrize("reflection_only", [False, True])
def test_g2_terms(kind, correlated, reflection_only):
    n = 4000
    wi, wo = _sphere(jax.random.PRNGKey(1), n), _sphere(jax.random.PRNGKey(2), n)
    # half vectors as the dielectric forms them (reflection and refraction with eta 1.5), and random ones
    transmit = wi.z * wo.z < 0
    eta_i, eta_o = jnp.where(wi.z < 0, 1.5, 1.0), jnp.where(wo.z < 0, 1.5, 1.0)
    h = normalize(wi + wo * jnp.where(transmit, eta_o / eta_i, 1.0))
    h = h * jnp.where(h.z < 0, -1.0, 1.0)
    for m in (h, _sphere(jax.random.PRNGKey(3), n)):
        ax, ay = 0.35, 0.2
        num, den = md.G2_terms(kind, wi, wo, m, ax, ay, correlated=correlated, reflection_only=reflection_only)
        g2 = np.asarray(md.G2(kind, wi, wo, m, ax, ay, correlated=correlated, reflection_only=reflection_only))
        if reflection_only:  # G2_terms: 0 for transmission pairs in both forms (G2's separable form ignores it)
            g2 = np.where(np.asarray(transmit), 0.0, g2)
        ok = np.asarray(den > 0)
        assert ok.mean() > 0.99
        zz = np.asarray(jnp.abs(wi.z * wo.z))
        np.testing.assert_allclose(np.asarray(num)[ok] / np.asarray(den)[ok] * zz[ok], g2[ok], rtol=1e-12, atol=1e-300)
        assert np.all(g2[~ok] == 0)
        if reflection_only:
            assert np.all(np.asarray(num)[np.asarray(transmit)] == 0)
