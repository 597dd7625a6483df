"""The cosmetic medium (Eqs. 4.3-4.10, Padrón 2025; spec M15, Q-C1..Q-C3) and the closed-form
single scattering of a slab (spec M35)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.core.frame import spherical_direction
from appearance_jax.core.quadrature import sphere_rule
from appearance_jax.core.vec import Vec3
from appearance_jax.layered import medium, single_scattering
from appearance_jax.microfacet import sggx
from appearance_jax.phase import hg_mixture, sggx_flakes

M = medium.Params(c_d=0.6, albedo_d=(0.9, 0.7, 0.5), albedo_p=(0.8, 0.85, 0.9), w_g=0.6, g1=0.6, g2=-0.3,
                  alpha=0.35, theta=0.5)


def directions(n, seed):
    k1, k2 = jax.random.split(jax.random.key(seed))
    z = jax.random.uniform(k1, (n,), minval=-1.0, maxval=1.0)
    phi = jax.random.uniform(k2, (n,), maxval=2 * math.pi)
    return spherical_direction(jnp.arccos(z), phi)


def test_platelet_area_is_one_at_most_along_the_mean_normal():
    """Q-C3: C_d = max C_p = 1, reached along the mean flake normal."""
    w = directions(4096, 0)
    c = np.asarray(medium.platelet_area(M, w))
    assert c.max() <= 1.0 + 1e-12 and c.min() >= M.alpha - 1e-12
    np.testing.assert_allclose(medium.platelet_area(M, sggx.mean_normal(M.theta)), 1.0, rtol=1e-12)


@jax.jit
def _phase_totals(wis, w, weight):
    """The quadrature of the phase function over wo, per incident direction (one compiled program
    for both seeds below instead of op-by-op dispatch)."""
    def total(x, y, z):
        wi = Vec3(*(jnp.full(w.z.shape, c) for c in (x, y, z)))
        return jnp.sum(weight[:, None] * medium.phase(M, wi, w), axis=0)
    return jax.vmap(total)(wis.x, wis.y, wis.z)


@pytest.mark.parametrize("seed", [1, 2])
def test_phase_function_is_normalised(seed):
    """Q-C1: the mixture (4.8) integrates to 1 over wo, for any incident direction."""
    np.testing.assert_allclose(_phase_totals(directions(3, seed), *sphere_rule(256, 512)), 1.0, atol=2e-3)


def test_medium_reciprocity():
    """Q-C2: f(w -> wo) sigma_s(w) == f(wo -> w) sigma_s(wo), i.e. sigma_t(wi) Lambda f is symmetric."""
    wi, wo = directions(256, 3), directions(256, 4)
    a = medium.extinction(M, wi)[:, None] * medium.scattering(M, wi, wo)
    b = medium.extinction(M, wo)[:, None] * medium.scattering(M, wo, wi)
    np.testing.assert_allclose(a, b, rtol=1e-10)


def test_limits_cd_one_and_zero():
    wi, wo = directions(64, 5), directions(64, 6)
    hg = hg_mixture.Params(w_g=M.w_g, g1=M.g1, g2=M.g2)
    diff = medium.Params(**{**{n: getattr(M, n) for n in medium.FIELDS}, "c_d": 1.0})
    np.testing.assert_allclose(medium.scattering(diff, wi, wo),
                               jnp.asarray(M.albedo_d) * hg_mixture.eval(hg, wi, wo), rtol=1e-10)
    flakes = medium.Params(**{**{n: getattr(M, n) for n in medium.FIELDS}, "c_d": 0.0})
    np.testing.assert_allclose(medium.extinction(flakes, wi), sggx_flakes.sigma(sggx_flakes.Params(
        alpha=M.alpha, theta=M.theta), wi), rtol=1e-12)
    np.testing.assert_allclose(medium.scattering(flakes, wi, wo), jnp.asarray(M.albedo_p) * sggx_flakes.eval(
        sggx_flakes.Params(alpha=M.alpha, theta=M.theta), wi, wo), rtol=1e-10)


def _collide_mc(m, wi, n, key):
    us = jax.random.uniform(key, (4, n))
    wis = Vec3(*(jnp.full((n,), c) for c in wi))
    return medium.collide(m, wis, *us)


def test_collision_kernel_has_the_expectation_of_eqs_4_7_and_4_8():
    """E[weight h(wo)] over the event kernel == int Lambda(wi) f(wi -> wo) h(wo) dwo (spec M15)."""
    wi = (0.3, -0.4, math.sqrt(1 - 0.25))
    tests = [lambda v: jnp.ones_like(v.z), lambda v: v.z, lambda v: (v.x + 0.5) ** 2, lambda v: v.y * v.z]

    # the quadratures and the samples each one compiled program (not op by op)
    @jax.jit
    def reference(w, weight):
        wis = Vec3(*(jnp.full(w.z.shape, c) for c in wi))
        s = medium.scattering(M, wis, w)
        return [jnp.sum(weight[:, None] * h(w)[:, None] * s, axis=0) for h in tests]

    n = 2**18

    @jax.jit
    def samples(key):
        wo, wgt = _collide_mc(M, wi, n, key)
        return [wgt * h(wo)[:, None] for h in tests]

    ref = [np.asarray(r) for r in reference(*sphere_rule(256, 512))]
    for x, r in zip(samples(jax.random.key(7)), ref):
        x = np.asarray(x)
        mean, se = x.mean(0), x.std(0, ddof=1) / math.sqrt(n)
        assert np.all(np.abs(mean - r) < 4 * se + 1e-3 * np.abs(r)), (mean, r, se)


def test_collision_kernel_gradients_are_unbiased():
    """d/dparam E[weight h(wo)] from autodiff of the samples (score terms) == d/dparam of quadrature."""
    wi = (0.5, 0.1, math.sqrt(1 - 0.26))
    w, weight = sphere_rule(192, 384)
    wis = Vec3(*(jnp.full(w.z.shape, c) for c in wi))

    def h(v):
        return (v.x + 0.5) ** 2 + v.z

    def make(x):
        return medium.Params(c_d=x[0], albedo_d=M.albedo_d, albedo_p=M.albedo_p, w_g=x[1], g1=x[2], g2=M.g2,
                             alpha=x[3], theta=x[4])

    x0 = jnp.array([M.c_d, M.w_g, M.g1, M.alpha, M.theta])
    # jitted: one program instead of the op-by-op gradient's many small ones
    quad = jax.jit(jax.grad(lambda x: jnp.sum(weight[:, None] * h(w)[:, None] * medium.scattering(make(x), wis, w))))(x0)
    n, n_keys = 2**16, 16
    @jax.jit
    def grad_est(key):
        wi_n = Vec3(*(jnp.full((n,), c) for c in wi))  # built inside: not a 2^16-element constant of the program
        us = jax.random.uniform(key, (4, n))

        def est(x):
            wo, wgt = medium.collide(make(x), wi_n, *us)
            return jnp.sum(jnp.mean(wgt * h(wo)[:, None], axis=0))
        return jax.grad(est)(x0)

    g = np.array([np.asarray(grad_est(jax.random.key(100 + k))) for k in range(n_keys)])
    mean, se = g.mean(0), g.std(0, ddof=1) / math.sqrt(n_keys)
    assert np.all(np.abs(mean - np.asarray(quad)) < 4 * se + 2e-3 * np.abs(np.asarray(quad))), (mean, quad, se)


# ------------------------------------------------------------------------------------
# single scattering (M35)


def test_single_scattering_is_reciprocal_and_zero_for_zero_thickness():
    wi, wo = directions(64, 8), directions(64, 9)
    wi, wo = (Vec3(v.x, v.y, jnp.abs(v.z)) for v in (wi, wo))
    a = single_scattering.brdf(M, 2.0, wi, wo)
    np.testing.assert_allclose(a, single_scattering.brdf(M, 2.0, wo, wi), rtol=1e-10)
    assert np.all(np.asarray(single_scattering.brdf(M, 0.0, wi, wo)) == 0.0)


def test_single_scattering_aligned_flake_limit():
    """theta_p = 0, small alpha, t -> inf: f_ss -> Lambda_p D(wh) / (8 mu_i mu_o) (spec M35)."""
    fl = medium.Params(c_d=0.0, albedo_d=0.5, albedo_p=0.7, alpha=1e-3, theta=0.0)
    wi = spherical_direction(jnp.array([0.4, 0.9]), jnp.array([0.0, 1.0]))
    wo = spherical_direction(jnp.array([0.5, 0.6]), jnp.array([2.8, 4.0]))
    f = single_scattering.brdf(fl, jnp.inf, wi, wo)[..., 0]
    h = Vec3(wi.x + wo.x, wi.y + wo.y, wi.z + wo.z)
    d = sggx.flake_D(1e-3, sggx.mean_normal(0.0), h * (1 / jnp.sqrt(h.x**2 + h.y**2 + h.z**2)))
    np.testing.assert_allclose(f, 0.7 * d / (8 * wi.z * wo.z), rtol=2e-3)


def test_single_scattering_below_horizon_is_zero():
    wi = Vec3(jnp.array([0.6, 1.0]), jnp.zeros(2), jnp.array([-0.8, 0.0]))
    wo = Vec3(jnp.array([0.6, 0.6]), jnp.zeros(2), jnp.array([0.8, 0.8]))
    f = single_scattering.brdf(M, 1.0, wi, wo)
    assert np.all(np.asarray(f) == 0.0)
