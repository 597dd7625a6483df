"""Chandrasekhar's H-function for the semi-infinite isotropic half-space (seed-000 spec M34)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import testing
from appearance_jax.core.quadrature import gauss_legendre
from appearance_jax.core.vec import Vec3
from appearance_jax.layered import h_function as hf

# spec M34 table: ϖ -> H(0.25), H(0.5), H(1), f(1,1) [1/sr], albedo(1), albedo(0.5)
TABLE = {
    0.5: (1.12965, 1.18773, 1.25126, 0.031148, 0.115226, 0.160145),
    0.9: (1.34327, 1.55603, 1.85010, 0.122572, 0.414948, 0.507939),
    0.99: (1.48074, 1.84860, 2.47279, 0.240863, 0.752721, 0.815140),
}


def _dir(theta, phi=0.0):
    theta, phi = jnp.broadcast_arrays(jnp.asarray(theta, float), jnp.asarray(phi, float))
    return Vec3(jnp.sin(theta) * jnp.cos(phi), jnp.sin(theta) * jnp.sin(phi), jnp.cos(theta))


@pytest.mark.parametrize("albedo", sorted(TABLE))
def test_spec_table(albedo):
    """Every number of the M34 table to its printed digits.

    Tolerance: one unit of the last printed digit (1e-5 for H, 1e-6 otherwise), not half a
    unit: a few table entries are truncated rather than rounded (H(0.5) at ϖ = 0.5 is
    1.1877351, printed 1.18773); a 400-node solution agrees with ours to 1e-11.
    """
    h25, h5, h1, f11, a1, a5 = TABLE[albedo]
    H = hf.h_function(albedo, jnp.array([0.25, 0.5, 1.0]))
    np.testing.assert_allclose(H, [h25, h5, h1], atol=1e-5)
    up = Vec3(0.0, 0.0, 1.0)
    np.testing.assert_allclose(hf.brdf(albedo, up, up), f11, atol=1e-6)
    np.testing.assert_allclose(hf.albedo_directional(albedo, jnp.array([1.0, 0.5])), [a1, a5], atol=1e-6)


def test_conservative_case():
    """ϖ = 1: H(1) = 2.9078 (Chandrasekhar 1960, Table V) and every incident direction reflects all light."""
    np.testing.assert_allclose(hf.h_function(1.0, 1.0), 2.9078, atol=1e-3)
    # the iteration is converged, not just close: 64 and 400 nodes agree to 1e-9
    np.testing.assert_allclose(hf.h_function(1.0, 1.0), hf.h_function(1.0, 1.0, n_nodes=400), atol=1e-9)
    np.testing.assert_allclose(hf.albedo_directional(1.0, jnp.linspace(0.05, 1.0, 7)), 1.0, atol=1e-12)
    assert float(hf.h_function(1.0, 0.0)) == pytest.approx(1.0, abs=1e-12)  # H(0) = 1 always


@pytest.mark.parametrize("albedo", [0.3, 0.9, 0.99, 1.0])
def test_albedo_identity(albedo):
    """int f(mu_i, mu_o) mu_o d omega_o = 1 - H(mu_i) sqrt(1 - ϖ): an independent integral of the BRDF.

    f does not depend on azimuth, so the integral is 2 pi int_0^1 f mu_o dmu_o; a 200-point
    Gauss rule on [0, 1] integrates the smooth integrand to ~1e-8 (the kernel
    1/(mu_i + mu_o) is analytic on [0, 1] for mu_i >= 0.1).
    """
    mu_i = jnp.array([0.1, 0.4, 0.8, 1.0])
    x, w = gauss_legendre(200, 0.0, 1.0)
    wi = _dir(jnp.arccos(mu_i)[:, None] + 0.0 * x[None, :])
    wo = _dir(jnp.arccos(jnp.asarray(x))[None, :] + 0.0 * mu_i[:, None], 1.0)
    f = hf.brdf(albedo, wi, wo)
    integral = 2.0 * np.pi * jnp.sum(f * x * w, axis=-1)
    np.testing.assert_allclose(integral, hf.albedo_directional(albedo, mu_i), atol=1e-7)


def test_reciprocity_and_horizon():
    key = jax.random.split(jax.random.key(0))
    ti = jax.random.uniform(key[0], (50,), minval=0.0, maxval=1.5)
    to = jax.random.uniform(key[1], (50,), minval=0.0, maxval=1.5)
    wi, wo = _dir(ti, 0.3), _dir(to, 2.0)
    np.testing.assert_allclose(hf.brdf(0.8, wi, wo), hf.brdf(0.8, wo, wi), rtol=1e-13)
    below = _dir(jnp.array([1.7, 2.0, 2.5]))
    below = Vec3(below.x.at[1].set(1.0), below.y.at[1].set(0.0), below.z.at[1].set(0.0))  # exactly grazing
    up = _dir(jnp.array([0.3, 0.3, 0.3]))
    for f in (hf.brdf(0.8, up, below), hf.brdf(0.8, below, up), hf.albedo_directional(0.8, below.z)):
        assert np.all(np.asarray(f) == 0.0)
    # gradients at below-horizon directions are finite (masked, not NaN)
    g = jax.jit(jax.grad(lambda a: jnp.sum(hf.brdf(a, up, below))))(0.8)  # one program, not op by op
    assert np.isfinite(g) and g == 0.0


_MU = jnp.array([0.2, 0.7])
# jitted once for the three albedos below (the same programs for every case)
_ALBEDO = jax.jit(lambda a: hf.albedo_directional(a, _MU))
_SUM = jax.jit(lambda a: jnp.sum(hf.albedo_directional(a, _MU)))
_SUM_GRAD = jax.jit(jax.grad(lambda a: jnp.sum(hf.albedo_directional(a, _MU))))


@pytest.mark.parametrize("albedo", [0.3, 0.9, 0.99])
def test_gradient_vs_finite_differences(albedo):
    """d albedo / dϖ by autodiff through the fixed iteration vs central differences (O(h^2) ~ 1e-9)."""
    testing.assert_gradients(_ALBEDO, albedo, rtol=1e-6, elementwise=True, mode="fwd", name="albedo_directional")
    # reverse mode through fori_loop (one compiled grad: grad_fn)
    testing.assert_gradients(_SUM, albedo, rtol=1e-6, name="sum albedo_directional", grad_fn=_SUM_GRAD)


def test_jit_and_bands():
    mu = jnp.array([0.3, 1.0])
    a = jnp.array([0.5, 0.9, 0.99])
    H = jax.jit(hf.h_function)(a, mu)
    assert H.shape == (2, 3)
    for b in range(3):
        np.testing.assert_allclose(H[:, b], hf.h_function(float(a[b]), mu), rtol=1e-14)
    up = Vec3(0.0, 0.0, 1.0)
    np.testing.assert_allclose(jax.jit(hf.brdf)(a, up, up), [TABLE[k][3] for k in (0.5, 0.9, 0.99)], atol=5e-7)


def test_validation():
    with pytest.raises(ValueError, match="albedo"):
        hf.h_function(1.2, 0.5)
    with pytest.raises(ValueError, match="albedo"):
        hf.albedo_directional(0.0, 0.5)
