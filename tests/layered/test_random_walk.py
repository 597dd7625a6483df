"""The position-free random walk (layered.random_walk) against references it did not write.

- first-order scattering == the closed-form single scattering of a slab (spec M35);
- a semi-infinite isotropic medium == Chandrasekhar's H-function numbers of spec M34;
- thickness 0 == the base BSDF exactly; a smooth dielectric over a Lambertian base == the
  classical closed form with the interface's internal diffuse reflectance;
- white furnace: lossless media over a white base conserve energy, and the energy left in
  the stack after 128 / 512 steps is reported;
- next-event estimates integrated over wo == the albedo from counting escaping paths;
- reciprocity within Monte Carlo noise; two stacked layers == one layer of the summed
  thickness; gradients (common random numbers) == finite differences within their noise.

Statistical tolerances: |difference| < 4 combined standard errors of the estimators (fixed
keys, so the tests are deterministic; a false failure would have probability ~6e-5 each);
3 standard errors where the issue asks for it (H-function, reciprocity).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.bsdf import lambert
from appearance_jax.core.frame import in_plane_directions, spherical_direction
from appearance_jax.core.quadrature import gauss_legendre
from appearance_jax.core.vec import Vec3
from appearance_jax.layered import adding_doubling, h_function, medium, single_scattering
from appearance_jax.layered import random_walk as layered
from appearance_jax.optics.fresnel import fresnel_dielectric

Z = 4.0  # tolerance in combined standard errors


def media(*layers):
    """medium.Params with a leading layer axis from per-layer keyword dicts (RGB albedos)."""
    ps = [medium.Params(**kw) for kw in layers]

    def field(name):
        vals = [jnp.asarray(getattr(p, name), jnp.float64) for p in ps]
        if name in medium.BAND_FIELDS:
            vals = [jnp.broadcast_to(v, (3,)) for v in vals]
        return jnp.stack(vals)
    return medium.Params(**{n: field(n) for n in medium.FIELDS})


def pairs():
    wi = spherical_direction(jnp.array([0.2, 0.7, 1.1]), jnp.array([0.0, 0.4, 2.0]))
    wo = spherical_direction(jnp.array([0.5, 0.3, 0.9]), jnp.array([2.5, 3.6, 0.3]))
    return wi, wo


def assert_close(a, b, se, what, z=Z):
    a, b, se = (np.asarray(x, np.float64) for x in (a, b, se))
    dev = np.abs(a - b) / np.maximum(se, 1e-300)
    assert np.all(dev < z), f"{what}: max deviation {dev.max():.2f} standard errors\n{a}\n{b}"


def lam(reflectance=0.5):
    """A Lambertian base with an RGB (3,) reflectance: one pytree shape for every test, so the
    walks with the same sizes below share one compiled program."""
    r = jnp.broadcast_to(jnp.asarray(reflectance, jnp.float64), (3,))
    return layered.Bottom(lambert.MODEL, lambert.Params(reflectance=r))


# The walks of the tests below share a few compiled programs (compilation is much of their
# cost): one sizing for the quick checks, one for the statistical comparisons (eta is always
# given: eta = 1 is the default index-matched stack, and a black base is a Lambertian of
# reflectance 0, which reflects nothing: the same estimator as bottom=None), three pairs of
# directions each. A comparison that needs more paths pools several keys (pooled).
# STAT's 64 steps: the walks of these tests (the same keys; the key of step k does not depend
# on the step count) change by at most 0.001 of a standard error from 64 to 128 steps (0.009 at
# 48): what a path still carries after 64 steps is negligible here.
QUICK = dict(n_samples=64, max_bounces=16)
STAT = dict(n_samples=2**13, max_bounces=64)
# escape-counting albedos: two directions x 1024 paths, 128 steps (the white furnace below also
# runs 512 steps)
ALB = dict(n_samples=1024, max_bounces=128)


def ones(n):
    return jnp.ones((n,))


def pooled(estimates):
    """The mean of independent (estimate, standard error) pairs of one quantity and its standard error."""
    k = len(estimates)
    return sum(e[0] for e in estimates) / k, jnp.sqrt(sum(e[1] ** 2 for e in estimates)) / k


def escape_albedo(m, t, wi, key, n_paths, bottom):
    """albedo(wi) (wi of shape (1,)) from ``n_paths`` escape-counted paths: the ALB program on
    (wi, wi) with independent keys, pooled. Returns (albedo, stderr, remaining), bands last."""
    both = Vec3(*(jnp.concatenate([c, c]) for c in wi))
    runs = [layered.albedo(m, t, both, k, bottom=bottom, **ALB)
            for k in jax.random.split(key, n_paths // (2 * ALB["n_samples"]))]
    a, se = pooled([(r[0][j], r[1][j]) for r in runs for j in range(2)])
    return a, se, sum(r[2].sum(0) for r in runs) / (2 * len(runs))


MEDIUM = dict(c_d=0.5, albedo_d=(0.9, 0.8, 0.7), albedo_p=0.85, w_g=0.7, g1=0.5, g2=-0.3, alpha=0.3, theta=0.3)


@pytest.mark.parametrize("c_d", [0.0, 0.5, 1.0])
@pytest.mark.parametrize("t", [0.1, 1.0, 16.0])
def test_first_order_equals_single_scattering(c_d, t):
    m = dict(MEDIUM, c_d=c_d)
    wi, wo = pairs()
    f, se = layered.walk(media(m), jnp.array([t]), wi, wo, jax.random.key(3), n_samples=2**15,
                         max_bounces=1, orders=(1, 1))
    ref = single_scattering.brdf(medium.Params(**m), t, wi, wo)
    assert_close(f, ref, se, f"single scattering c_d={c_d} t={t}")
    assert np.all(np.asarray(se) < 0.05 * np.asarray(ref))  # the test has power


# spec M34 (400-node Gauss-Legendre fixed point of the H-equation): f(1, 1) [1/sr], albedo(mu = 0.5)
H_TABLE = {0.5: (0.031148, 0.160145), 0.9: (0.122572, 0.507939)}


# albedo 0.9 is `slow`: the same programs and checks as 0.5 (tests/layered/test_adding_doubling.py
# and test_ordinates.py compare their solvers with the H-function at 0.9 in the default run)
@pytest.mark.parametrize("w", [0.5, pytest.param(0.9, marks=pytest.mark.slow)])
def test_semi_infinite_isotropic_medium_matches_h_function(w):
    """f(1, 1) and albedo(0.5) of the spec's table within 3 standard errors (2^14 paths each), and
    f at two oblique pairs == the H-function closed form (layers.h_function) within 4."""
    iso = media(dict(c_d=1.0, albedo_d=w, w_g=1.0, g1=0.0))
    # t = 64 mfp: the finite-slab correction ~exp(-2 k t) < 1e-25 for these albedos (spec M34)
    # over black (a Lambertian of reflectance 0: the STAT program); first pair normal to normal
    wi = spherical_direction(jnp.array([0.0, 0.7, 1.1]), jnp.array([0.0, 0.4, 2.0]))
    wo = spherical_direction(jnp.array([0.0, 0.3, 0.9]), jnp.array([0.0, 3.6, 0.3]))
    # STAT's 64 steps: for albedo 0.9 the light scattered more often adds 0.009 standard errors
    # to f(1, 1) (measured against 256 steps, same key); 2 keys x 2^13 paths
    f, se = pooled([layered.walk(iso, jnp.array([64.0]), wi, wo, k, eta=ones(1), bottom=lam(0.0), **STAT)
                    for k in jax.random.split(jax.random.key(4))])
    assert_close(f[0, 0], H_TABLE[w][0], se[0, 0], f"H-function f(1,1), albedo {w}", z=3.0)
    assert_close(f[1:, 0], np.asarray(h_function.brdf(w, wi, wo))[1:], se[1:, 0], f"H-function f, albedo {w}")
    wi = spherical_direction(jnp.array([np.arccos(0.5)]), jnp.zeros(1))
    # 128 steps: the energy still in the stack is < albedo^128 < 1.5e-6
    a, se_a, left = escape_albedo(iso, jnp.array([64.0]), wi, jax.random.key(5), 2**14, lam(0.0))
    assert_close(a[0], H_TABLE[w][1], se_a[0], f"H-function albedo(0.5), albedo {w}", z=3.0)
    assert float(left.max()) < 1e-3 * H_TABLE[w][1]


def test_thickness_zero_returns_the_base_exactly():
    wi, wo = pairs()
    m = media(MEDIUM)
    bottom = lam((0.2, 0.5, 0.9))
    f, se = layered.walk(m, jnp.array([0.0]), wi, wo, jax.random.key(6), eta=ones(1), bottom=bottom, **QUICK)
    np.testing.assert_allclose(f, lambert.eval(bottom.params, wi, wo), rtol=1e-12)
    assert np.all(np.asarray(se) <= 1e-12 * np.asarray(f))  # every path gives the same value
    # other bases (rough_plastic): tests/bsdf/test_cosmetics.py::test_thickness_zero_is_the_base


def test_smooth_dielectric_over_lambert_matches_closed_form():
    """t = 0, eta = 1.5 over Lambert rho: f = (1 - F_i)(1 - F_o) rho / (pi eta^2 (1 - rho r_i))."""
    eta, rho = 1.5, 0.7
    wi, wo = pairs()
    # 2 x 2^13 paths (two keys, the STAT program) == the 2^14 of one estimate: the mean of the two
    # independent estimates, standard error sqrt(se1^2 + se2^2) / 2
    f, se = pooled([layered.walk(media(MEDIUM), jnp.array([0.0]), wi, wo, k, eta=jnp.array([eta]), bottom=lam(rho),
                                 **STAT) for k in jax.random.split(jax.random.key(7))])
    # internal diffuse reflectance of the interface (light from inside, cosine-weighted): Gauss rules
    # on either side of the critical cosine, where F has its kink (total internal reflection
    # below): converged to 3e-9 at 400 nodes (one 2000-node rule over the kink: 4e-5)
    mu_c = np.sqrt(1.0 - 1.0 / eta**2)
    r_i = 0.0
    for a, b in ((0.0, mu_c), (mu_c, 1.0)):
        mu, w = gauss_legendre(400, a, b)
        r_i += float(np.sum(2.0 * mu * w * np.asarray(fresnel_dielectric(-jnp.asarray(mu), eta)[0])))
    Fi = np.asarray(fresnel_dielectric(wi.z, eta)[0])
    Fo = np.asarray(fresnel_dielectric(wo.z, eta)[0])
    ref = (1 - Fi) * (1 - Fo) * rho / (np.pi * eta**2 * (1 - rho * r_i))
    assert_close(f[..., 0], ref, se[..., 0], "dielectric coat over Lambert")


def test_white_furnace_and_truncation():
    """Albedo-1 media over a white Lambertian base: every path keeps weight 1 until it leaves,
    so escaped + remaining == 1; the remaining energy shrinks with the step budget."""
    wi = spherical_direction(jnp.array([0.3, 1.2]), jnp.array([0.0, 1.0]))
    left = {}
    white_media = dict(MEDIUM, albedo_d=1.0, albedo_p=1.0)
    # Dewy 1's single lobe (w_g = 1) and c_d = 1: branches of probability 0 must not lose energy
    dewy1 = dict(c_d=0.9, albedo_d=1.0, albedo_p=1.0, w_g=1.0, g1=0.55, g2=0.09, alpha=0.13, theta=0.0257)
    hg_only = dict(MEDIUM, c_d=1.0, w_g=1.0, albedo_d=1.0)
    # 128 steps: the ALB program; 512 steps (a program of its own) on 256 paths per direction:
    # escaped + remaining == 1 holds path by path, and the energy left is far apart (printed)
    for m, t in ((white_media, 1.0), (white_media, 16.0), (dewy1, 16.0), (hg_only, 4.0)):
        for n in (128, 512):
            a, se, rem = layered.albedo(media(m), jnp.array([t]), wi, jax.random.key(8), bottom=lam(1.0),
                                        **(ALB if n == 128 else dict(n_samples=256, max_bounces=512)))
            np.testing.assert_allclose(a + rem, 1.0, atol=1e-9)
            left[(t, n)] = float(rem.max())
    print("energy left in the stack (t, steps):", left)
    assert left[(16.0, 512)] < left[(16.0, 128)] and left[(1.0, 512)] < 1e-3


def test_next_event_estimates_integrate_to_the_escape_albedo():
    """int f(wi, wo) mu_o dwo by quadrature over NEE estimates == albedo by counting escapes."""
    m = media(dict(MEDIUM, theta=0.0))
    bottom = lam(0.5)
    wi = spherical_direction(jnp.array([0.6]), jnp.array([0.0]))
    mu, wmu = gauss_legendre(8, 0.0, 1.0)
    n_phi = 8
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    M, P = np.meshgrid(mu, phi, indexing="ij")
    W = np.repeat(wmu[:, None], n_phi, 1) * 2 * np.pi / n_phi
    wo = spherical_direction(jnp.arccos(jnp.asarray(M.ravel())), jnp.asarray(P.ravel()))
    f, se = layered.walk(m, jnp.array([2.0]), Vec3(*(jnp.broadcast_to(c, wo.z.shape) for c in (wi.x, wi.y, wi.z))),
                         wo, jax.random.key(9), n_samples=1024, max_bounces=64, bottom=bottom)
    quad = np.sum((W * M).ravel()[:, None] * np.asarray(f), axis=0)
    quad_se = np.sqrt(np.sum(((W * M).ravel()[:, None] * np.asarray(se)) ** 2, axis=0))
    # 2^15 paths; 64 steps above, 128 here: both change by < 2e-6 standard errors from 96 steps
    a, se_a, _ = escape_albedo(m, jnp.array([2.0]), wi, jax.random.key(10), 2**15, bottom)
    # the quadrature of a smooth lobe (g <= 0.5, alpha = 0.3 platelets) is good to ~1e-3 relative
    tol = Z * np.sqrt(quad_se**2 + np.asarray(se_a) ** 2) + 2e-3 * np.asarray(a)
    assert np.all(np.abs(quad - np.asarray(a)) < tol), (quad, a)


def test_reciprocity_within_noise():
    m = media(MEDIUM)  # tilted platelets: anisotropic, still reciprocal
    wi, wo = pairs()
    kw = dict(eta=ones(1), bottom=lam((0.3, 0.5, 0.1)), **STAT)
    f1, s1 = layered.walk(m, jnp.array([1.5]), wi, wo, jax.random.key(11), **kw)
    f2, s2 = layered.walk(m, jnp.array([1.5]), wo, wi, jax.random.key(12), **kw)
    assert_close(f1, f2, np.sqrt(s1**2 + s2**2), "reciprocity", z=3.0)


@pytest.mark.parametrize("eta", [pytest.param(1.0, marks=pytest.mark.slow), 1.3])  # 1.3: dielectric interfaces too
def test_two_stacked_layers_equal_one(eta):
    m = dict(MEDIUM, theta=0.2)
    wi, wo = pairs()
    kw = dict(bottom=lam(0.5), **STAT)
    f1, s1 = layered.walk(media(m), jnp.array([1.2]), wi, wo, jax.random.key(13), eta=jnp.array([eta]), **kw)
    f2, s2 = layered.walk(media(m, m), jnp.array([0.7, 0.5]), wi, wo, jax.random.key(14),
                          eta=jnp.array([eta, eta]), **kw)
    assert_close(f1, f2, np.sqrt(s1**2 + s2**2), f"two layers vs one, eta {eta}")


# the isotropic lobe is `slow`: the two-lobe mixture runs the same programs and checks (isotropic
# scattering in the default run: test_semi_infinite_isotropic_medium_matches_h_function)
@pytest.mark.parametrize("lobes", [pytest.param(dict(w_g=1.0, g1=0.0), marks=pytest.mark.slow),
                                   dict(w_g=0.7, g1=0.6, g2=-0.3)])
def test_hg_media_match_adding_doubling(lobes):
    """c_d = 1 (isotropic extinction, HG mixture): the walk == the deterministic adding-doubling
    solver (spec M36), one layer over a Lambertian base and a two-layer stack over black."""
    wi, wo = pairs()
    top = dict(c_d=1.0, albedo_d=(0.95, 0.8, 0.5), **lobes)
    bot = dict(c_d=1.0, albedo_d=0.9, w_g=1.0, g1=-0.4)
    kw = STAT
    f, se = layered.walk(media(top), jnp.array([2.0]), wi, wo, jax.random.key(15), eta=ones(1), bottom=lam(0.4),
                         **kw)
    hg = adding_doubling.HGLayer(albedo=jnp.array(top["albedo_d"]), thickness=2.0, g1=lobes["g1"],
                                 g2=lobes.get("g2", 0.0), w_g=lobes["w_g"])
    ref = adding_doubling.brdf(hg, 0.4, wi, wo)
    assert_close(f, ref, se, f"adding-doubling, one layer {lobes}")
    # over black: a Lambertian base of reflectance 0 (the two-layer program of test_two_stacked_layers_equal_one;
    # bottom=None itself: test_first_order_equals_single_scattering)
    f, se = layered.walk(media(top, bot), jnp.array([0.5, 3.0]), wi, wo, jax.random.key(16), eta=ones(2),
                         bottom=lam(0.0), **kw)
    ref = adding_doubling.brdf([hg._replace(thickness=0.5), adding_doubling.HGLayer(0.9, 3.0, g1=-0.4)], 0.0,
                               wi, wo)
    assert_close(f, ref, se, f"adding-doubling, two layers {lobes}")


def test_grazing_and_below_horizon_give_zero_not_nan():
    wi = Vec3(jnp.array([1.0, 0.6, 0.6]), jnp.zeros(3), jnp.array([0.0, 0.8, -0.8]))
    wo = Vec3(jnp.array([0.6, 1.0, 0.6]), jnp.zeros(3), jnp.array([0.8, 0.0, 0.8]))
    f, se = layered.walk(media(MEDIUM), jnp.array([1.0]), wi, wo, jax.random.key(0), eta=ones(1), bottom=lam(),
                         **QUICK)
    assert np.all(np.asarray(f) == 0.0) and np.all(np.isfinite(np.asarray(se)))


def test_same_key_same_numbers():
    wi, wo = pairs()
    kw = dict(eta=ones(1), bottom=lam(), **QUICK)
    a = layered.walk(media(MEDIUM), jnp.array([1.0]), wi, wo, jax.random.key(1), **kw)
    b = layered.walk(media(MEDIUM), jnp.array([1.0]), wi, wo, jax.random.key(1), **kw)
    c = layered.walk(media(MEDIUM), jnp.array([1.0]), wi, wo, jax.random.key(2), **kw)
    assert np.array_equal(a[0], b[0]) and not np.array_equal(a[0], c[0])


# ------------------------------------------------------------------------------------
# gradients: autodiff of the estimate (common random numbers, score terms) vs central finite
# differences of the same estimate, both averaged over independent keys


GRAD_NAMES = ("c_d", "w_g", "g1", "alpha", "albedo_d", "thickness")


def _functional(x, key, n_samples):
    c_d, w_g, g1, alpha, albedo_d, t = (x[i] for i in range(6))
    m = dict(MEDIUM, c_d=c_d, w_g=w_g, g1=g1, alpha=alpha, albedo_d=albedo_d)
    # one band: every albedo here is the same in all bands, so more bands would only repeat the work
    stacked = medium.Params(**{n: jnp.asarray(v)[None] if n not in medium.BAND_FIELDS else
                               jnp.asarray(v).reshape(1, 1)
                               for n, v in ((n, m[n]) for n in medium.FIELDS)})
    wi, wo = in_plane_directions(jnp.deg2rad(jnp.array([20.0, 45.0, 45.0])), jnp.deg2rad(jnp.array([20.0, 40.0, -30.0])))
    # 24 steps: m_ad, m_fd and their standard errors below equal those of 48 steps to 4 digits
    # (measured): the later steps carry nothing the test resolves, and every step runs the same code
    f, _ = layered.walk(stacked, t[None], wi, wo, key, n_samples=n_samples, max_bounces=24,
                        bottom=layered.Bottom(lambert.MODEL, lambert.Params(reflectance=0.4)))
    return jnp.sum(f)


def test_gradients_with_common_random_numbers_match_finite_differences():
    x0 = jnp.array([0.6, 0.7, 0.5, 0.3, 0.8, 1.5])
    n, n_keys, h = 1024, 12, 0.02
    keys = jax.random.split(jax.random.key(100), n_keys)
    steps = jnp.concatenate([jnp.eye(6) * h, -jnp.eye(6) * h])  # 12 perturbed points

    @jax.jit
    def per_key(key):
        g = jax.jacfwd(_functional)(x0, key, n)
        vals = jax.vmap(lambda e: _functional(x0 + e, key, n))(steps)
        return g, (vals[:6] - vals[6:]) / (2 * h)

    ad, fd = (np.asarray(a) for a in jax.lax.map(per_key, keys))
    m_ad, m_fd = ad.mean(0), fd.mean(0)
    s = np.sqrt(ad.var(0, ddof=1) / n_keys + fd.var(0, ddof=1) / n_keys)
    z = np.abs(m_ad - m_fd) / s
    print(dict(zip(GRAD_NAMES, np.round(m_ad, 4))), dict(zip(GRAD_NAMES, np.round(m_fd, 4))), np.round(z, 2))
    assert np.all(z < Z), dict(zip(GRAD_NAMES, z))
    # and the test has power: each derivative is resolved (|mean| > 3 standard errors)
    assert np.all(np.abs(m_ad) > 3 * np.sqrt(ad.var(0, ddof=1) / n_keys)), dict(zip(GRAD_NAMES, m_ad))
