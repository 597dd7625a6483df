"""Rough plastic: coat integrals against independent quadratures and closed-form limits,
reciprocity, energy, sampling, gradients, edge cases (Mitsuba: tests/validation/)."""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad

from appearance_jax import testing
from appearance_jax.bsdf import rough_plastic as rp
from appearance_jax.core.frame import spherical_direction
from appearance_jax.core.params import validate
from appearance_jax.core.quadrature import gauss_legendre
from appearance_jax.core.vec import Vec3
from appearance_jax.microfacet import distribution as md
from appearance_jax.microfacet import interface_integrals as ii
from appearance_jax.optics.fresnel import fresnel_dielectric

# two static configurations (each costs a compilation): the defaults, and Mitsuba's choices
STATIC_A = dict()
STATIC_B = dict(distribution="beckmann", nonlinear=True, shadowing="separable", tables="mitsuba")
CONFIGS = {
    "ggx_precomputed": rp.Params(alpha=0.3, diffuse_reflectance=(0.9, 0.5, 0.1), **STATIC_A),
    "beckmann_mitsuba_nonlinear": rp.Params(alpha=0.2, eta=1.9, diffuse_reflectance=(0.8, 0.3, 0.6), **STATIC_B),
}


def _vec(a):
    return Vec3(a[0], a[1], a[2])


def _g1(kind, mu, alpha):
    """Smith G1 at normal-side facets, from the projected area: G1 = mu / a(w)."""
    w = Vec3(np.sqrt(1.0 - mu * mu), 0.0 * mu, mu)
    return np.asarray(mu / md.projected_area(kind, w, alpha))


# ----------------------------------------------------------------------------------------
# the coat integrals


def _np_fresnel(c, eta):
    """Unpolarised dielectric reflectance (Born & Wolf), c = cos of incidence >= 0, eta =
    eta_t / eta_i; 1 under total internal reflection."""
    s2 = (1.0 - c * c) / eta**2
    if s2 >= 1.0:
        return 1.0
    ct = math.sqrt(1.0 - s2)
    rs = (c - eta * ct) / (c + eta * ct)
    rp_ = (eta * c - ct) / (eta * c + ct)
    return 0.5 * (rs * rs + rp_ * rp_)


def _np_g1(kind, z, alpha):
    """Smith G1 = 1 / (1 + Lambda) for |cos theta| = z (Walter et al. 2007, Eq. 27 and 34)."""
    if z >= 1.0:
        return 1.0
    tan = math.sqrt(1.0 - z * z) / z
    if kind == "ggx":
        return 2.0 / (1.0 + math.sqrt(1.0 + (alpha * tan) ** 2))
    a = 1.0 / (alpha * tan)
    lam = 0.5 * (math.exp(-a * a) / (a * math.sqrt(math.pi)) - math.erfc(a))
    return 1.0 / (1.0 + lam)


def _scipy_normal_incidence(kind, alpha, eta, mode):
    """T(1) or R(1) by adaptive 1D quadrature over the facet angle t, written independently
    of the library: at normal incidence the visible normals have density D(m) cos(t)
    (phi-symmetric), the facet cosine is c = cos t, the mirrored direction has z = cos 2t
    and the refracted one z = -1/eta + c (c/eta - cos_t) (Snell at the facet)."""

    def D(t):
        c, t2 = math.cos(t), math.tan(t) ** 2 / alpha**2
        if kind == "ggx":
            return 1.0 / (math.pi * alpha**2 * c**4 * (1.0 + t2) ** 2)
        return math.exp(-t2) / (math.pi * alpha**2 * c**4)

    def f(t):
        c = math.cos(t)
        base = 2.0 * math.pi * math.sin(t) * c * D(t)
        if mode == "R":
            z = 2.0 * c * c - 1.0
            return base * _np_fresnel(c, eta) * _np_g1(kind, z, alpha) if z > 0 else 0.0
        ct = math.sqrt(1.0 - (1.0 - c * c) / eta**2)
        z = -1.0 / eta + c * (c / eta - ct)
        return base * (1.0 - _np_fresnel(c, eta)) * _np_g1(kind, -z, alpha)

    pts = [math.pi / 4]
    if eta < 1:
        pts.append(math.acos(math.sqrt(1.0 - eta * eta)))
    return quad(f, 0.0, math.pi / 2 - 1e-12, points=pts, epsabs=1e-13, epsrel=1e-12, limit=400)[0]


@pytest.mark.parametrize("kind", ["ggx", "beckmann"])
def test_interface_integrals_normal_incidence_vs_scipy(kind):
    for alpha in (0.05, 0.4, 1.5):
        for mode, eta in (("T", 1.5), ("R", 1 / 1.5), ("R", 1 / 2.4), ("R", 1.5)):
            fn = ii.interface_transmittance if mode == "T" else ii.interface_reflectance
            ours = float(fn(kind, alpha, eta, 1.0))
            ref = _scipy_normal_incidence(kind, alpha, eta, mode)
            assert ours == pytest.approx(ref, rel=2e-6, abs=1e-10), (alpha, mode, eta)


@functools.partial(jax.jit, static_argnames=("kind", "mode", "n"))
def _vndf_rule(kind, alpha, eta, mu, mode, n):
    """The same integrals with an independent map: n x n Gauss-Legendre over the uniforms of
    the visible-normal sampler (md.sample_visible), integrand (1 - F) G1(wt) or F G1(wr)."""
    x, w = gauss_legendre(n, 0.0, 1.0)
    u1, u2 = (jnp.asarray(a.ravel()) for a in np.meshgrid(x, x, indexing="ij"))
    W = jnp.asarray(np.outer(w, w).ravel())
    mu = mu[:, None]
    wi = Vec3(jnp.sqrt(1 - mu * mu), 0.0 * mu, mu)
    m = md.sample_visible(kind, wi, alpha, alpha, u1, u2)
    c = wi.x * m.x + wi.y * m.y + wi.z * m.z
    F = fresnel_dielectric(c, eta)[0]
    if mode == "T":
        ct = jnp.sqrt(1.0 - (1.0 - c * c) / eta**2)
        wt = wi * (-1.0 / eta) + m * (c / eta - ct)
        h = (1.0 - F) * md.G1(kind, wt, m, alpha)
    else:
        wr = m * (2.0 * c) - wi
        h = F * md.G1(kind, wr, m, alpha) * (wr.z > 0)
    return jnp.sum(W * h, axis=-1)


@pytest.mark.parametrize("kind", ["ggx", pytest.param("beckmann", marks=pytest.mark.slow)])
def test_interface_integrals_vs_visible_normal_rule(kind):
    """Oblique incidence: a 192^2 Gauss-Legendre rule through the sampler's warp converges
    algebraically towards ours, to ~1e-6 for T (measured 1.3e-6, 3.8e-7, 1.6e-7 at 128, 192,
    256 nodes) and ~1e-4 for R (its integrand has the TIR kink inside the square)."""
    mu = np.array([0.03, 0.2, 0.55, 0.9])
    for alpha, eta in ((0.1, 1.5), (0.6, 2.0)):
        T = np.asarray(ii.interface_transmittance(kind, alpha, eta, jnp.asarray(mu)))
        np.testing.assert_allclose(T, _vndf_rule(kind, alpha, eta, jnp.asarray(mu), "T", 192), rtol=3e-6)
        R = np.asarray(ii.interface_reflectance(kind, alpha, 1 / eta, jnp.asarray(mu)))
        np.testing.assert_allclose(R, _vndf_rule(kind, alpha, 1 / eta, jnp.asarray(mu), "R", 192), rtol=1e-3)


@pytest.mark.parametrize("kind", ["ggx", "beckmann"])
def test_index_matched_coat_integrals(kind):
    """eta = 1: no Fresnel reflection, the refracted ray is -wi, so T(mu) = G1(wi) exactly
    (the quadrature integrates the visible-normal density to 1) and R = 0."""
    mu = jnp.asarray([1e-6, 0.01, 0.1, 0.37, 0.8, 1.0])
    for alpha in (1e-3, 0.05, 0.5, 2.0):
        T = np.asarray(ii.interface_transmittance(kind, alpha, 1.0, mu))
        np.testing.assert_allclose(T, _g1(kind, np.asarray(mu), alpha), rtol=2e-6)
        assert float(jnp.max(jnp.abs(ii.interface_reflectance(kind, alpha, 1.0, mu)))) < 1e-15


@pytest.mark.parametrize("kind", ["ggx", pytest.param("beckmann", marks=pytest.mark.slow)])
def test_smooth_coat_limit(kind):
    """alpha -> 0: T(mu) -> 1 - F(mu) and R_int -> 1 - (1 - R_ext) / eta^2 with
    R_ext = 2 int F(mu) mu dmu (smooth interface, reciprocity; e.g. Weidlich & Wilkie 2007).
    At alpha = 1e-3 the roughness still shows: O(alpha^2) for Beckmann, but ~1e-4 at
    mu = 0.15 for GGX, whose heavy tail puts a fraction ~alpha of the facets far from n."""
    eta = 1.5
    mu = np.linspace(0.15, 1.0, 12)
    T = np.asarray(ii.interface_transmittance(kind, 1e-3, eta, jnp.asarray(mu)))
    rtol = 2e-4 if kind == "ggx" else 1e-5
    np.testing.assert_allclose(T, 1.0 - np.asarray(fresnel_dielectric(jnp.asarray(mu), eta)[0]), rtol=rtol)
    x, w = gauss_legendre(200, 0.0, 1.0)
    R_ext = 2.0 * np.sum(w * x * np.asarray(fresnel_dielectric(jnp.asarray(x), eta)[0]))
    tab = rp.coat_tables(rp.Params(alpha=1e-3, eta=eta, distribution=kind, tables="accurate"))
    assert float(tab.internal_reflectance) == pytest.approx(1.0 - (1.0 - R_ext) / eta**2, rel=2e-4)


@pytest.mark.parametrize("kind", ["ggx", pytest.param("beckmann", marks=pytest.mark.slow)])
def test_tables_schemes(kind):
    """Accurate scheme: Chebyshev T within 2e-6 of the direct integral (mu >= 0.02), R_int
    converged (vs 48 nodes per piece) to 1e-6. Mitsuba scheme: T exact at its nodes, R_int
    its equal-weight mean, which is ~1/64 low; the rough single-scattering coat loses energy:
    T_avg / eta^2 <= 1 - R_int (reciprocity: what enters from inside = T_avg / eta^2)."""
    for alpha, eta in ((0.08, 1.33), (0.5, 2.2)):
        p = rp.Params(alpha=alpha, eta=eta, distribution=kind, tables="accurate")
        tab = rp.coat_tables(p)
        mu = np.linspace(0.02, 1.0, 96)
        Ti = np.asarray(rp._transmittance_at(p, tab, jnp.asarray(mu)))
        Td = np.asarray(ii.interface_transmittance(kind, alpha, eta, jnp.asarray(mu)))
        np.testing.assert_allclose(Ti, Td, rtol=2e-6)
        c_c = math.sqrt(1 - 1 / eta**2)
        x1, w1 = gauss_legendre(48, 0.0, c_c)
        x2, w2 = gauss_legendre(48, c_c, 1.0)
        x, w = np.concatenate([x1, x2]), np.concatenate([w1, w2])
        R = np.asarray(ii.interface_reflectance(kind, alpha, 1 / eta, jnp.asarray(x)))
        R_int = 2 * np.sum(w * x * R)
        assert float(tab.internal_reflectance) == pytest.approx(R_int, rel=1e-5)
        T_avg = 2 * np.sum(w * x * np.asarray(ii.interface_transmittance(kind, alpha, eta, jnp.asarray(x))))
        assert T_avg / eta**2 <= 1.0 - R_int
        pm = p.replace(tables="mitsuba")
        tm = rp.coat_tables(pm)
        nodes = ii.mitsuba_nodes()
        np.testing.assert_allclose(np.asarray(tm.transmittance),
                                   np.asarray(ii.interface_transmittance(kind, alpha, eta, jnp.asarray(nodes))),
                                   rtol=1e-12)
        np.testing.assert_allclose(np.asarray(rp._transmittance_at(pm, tm, jnp.asarray(nodes[1:]))),
                                   np.asarray(tm.transmittance)[1:], rtol=1e-12)
        low = 1.0 - float(tm.internal_reflectance) / float(tab.internal_reflectance)
        assert 0.003 < low < 0.025


# ----------------------------------------------------------------------------------------
# the BRDF


def test_index_matched_diffuse_limit():
    """eta = 1 and no coat reflection: f = rho G1(wi) G1(wo) / pi (T = G1, R_int = 0); with
    alpha -> 0 that is Lambert rho / pi."""
    wi = spherical_direction(jnp.linspace(0.0, 1.5, 40), 0.3)
    wo = spherical_direction(jnp.linspace(1.4, 0.05, 40), 2.5)
    rho = np.array([0.9, 0.4, 0.05])
    for alpha in (0.4, 1e-3):
        p = rp.Params(alpha=alpha, eta=1.0, diffuse_reflectance=rho, specular_reflectance=0.0)
        f = np.asarray(rp.eval(p, wi, wo))
        ref = rho * (_g1("ggx", np.asarray(wi.z), alpha) * _g1("ggx", np.asarray(wo.z), alpha))[:, None] / math.pi
        np.testing.assert_allclose(f, ref, rtol=2e-5)
    np.testing.assert_allclose(f[wi.z > 0.1], np.broadcast_to(rho / math.pi, f[wi.z > 0.1].shape), rtol=2e-4)


@pytest.mark.parametrize("static", [STATIC_A, STATIC_B], ids=["A", "B"])
def test_diffuse_only_closed_form(static):
    """specular_reflectance = 0: f = rho / (1 - r R_int) T_i T_o / (pi eta^2), r = 1 or rho
    (T: the direct quadrature for the default precomputed tables, within their error; Mitsuba's
    lerp between its nodes)."""
    wi = spherical_direction(jnp.array([0.2, 0.9, 1.3]), 0.0)
    wo = spherical_direction(jnp.array([1.1, 0.4, 0.0]), 1.0)
    rho = np.array([0.9, 0.5, 0.1])
    p = rp.Params(alpha=0.25, eta=1.7, diffuse_reflectance=rho, specular_reflectance=0.0, **static)
    tab = rp.coat_tables(p)
    if p.tables == "precomputed":
        T = lambda mu: np.asarray(ii.interface_transmittance(p.distribution, 0.25, 1.7, mu))  # noqa: E731
        rtol = 2e-4  # the tables' error, <= 1e-4 in T (~0.5 here) and R_int
    else:  # Mitsuba's lerp between its nodes
        nodes = ii.mitsuba_nodes()
        T = lambda mu: np.interp(np.asarray(mu), nodes, np.asarray(tab.transmittance))  # noqa: E731
        rtol = 5e-6
    r = rho if p.nonlinear else 1.0
    ref = rho / (1 - r * float(tab.internal_reflectance)) * (T(wi.z) * T(wo.z))[:, None] / (math.pi * 1.7**2)
    np.testing.assert_allclose(np.asarray(rp.eval(p, wi, wo)), ref, rtol=rtol)


def _reciprocity_pairs(n=1024, seed=3):
    """Half uniform pairs, half near the specular peak (wo = mirror of wi about a normal
    tilted by up to 0.3 rad), where a non-reciprocal specular term would show most."""
    rng = np.random.default_rng(seed)
    u = rng.random((6, n))
    wi = np.array(spherical_direction(np.arccos(u[0]), 2 * np.pi * u[1]).to_array())
    wo = np.array(spherical_direction(np.arccos(u[2]), 2 * np.pi * u[3]).to_array())
    m = np.asarray(spherical_direction(0.3 * u[4], 2 * np.pi * u[5]).to_array())
    mirrored = 2 * np.sum(wi * m, -1, keepdims=True) * m - wi
    use = (np.arange(n) % 2 == 1) & (mirrored[:, 2] > 0.01)
    wo[use] = mirrored[use]
    return _vec(jnp.asarray(wi.T)), _vec(jnp.asarray(wo.T))


@pytest.mark.parametrize("name", list(CONFIGS))
def test_reciprocity(name):
    wi, wo = _reciprocity_pairs()
    testing.assert_reciprocity(rp.MODEL, CONFIGS[name], wi=wi, wo=wo, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("name", ["ggx_precomputed", pytest.param("beckmann_mitsuba_nonlinear", marks=pytest.mark.slow)])
def test_sampling_consistency(name):
    """weight == f cos / pdf, pdf == pdf(), failed samples 0, IS vs uniform estimate."""
    testing.assert_sampling(rp.MODEL, CONFIGS[name], n_wi=4, n_samples=2**13, rtol=1e-10)


@pytest.mark.slow
def test_chi2_sampler_follows_pdf():
    testing.assert_chi2(rp.MODEL, CONFIGS["ggx_precomputed"], n_wi=2, n_samples=2**16, res_theta=16, res_phi=32,
                        n_tests=1)


@pytest.mark.parametrize("static", [pytest.param(STATIC_A, marks=pytest.mark.slow), STATIC_B], ids=["A", "B"])
def test_white_furnace(static):
    """Energy: albedo <= 1 for a white base and full coat reflection (MC and quadrature).

    The single-scattering coat loses what its microfacets mask, on the way in, on every
    internal bounce (T_avg / eta^2 < 1 - R_int) and on the way out: at alpha = 0.5 about
    half of the light is lost."""
    p = rp.Params(alpha=0.5, eta=1.5, diffuse_reflectance=1.0, specular_reflectance=1.0, **static)
    res = testing.assert_white_furnace(rp.MODEL, p, n_wi=4, n_samples=2**13, n_theta=96, n_phi=96)
    assert 0.4 < res.max_albedo < 0.9


@jax.jit
def _value_and_grads(p, wi, wo):
    """sum(f) + sum(pdf) and its gradients w.r.t. the parameters and both directions
    (one compilation shared by the gradient tests; the kernels of eval and pdf with the
    coat tables computed once)."""

    def fn(p, wi, wo):
        tab = rp._tables(p)
        return jnp.sum(rp._eval_with(p, tab, _vec(wi), _vec(wo))) + jnp.sum(rp._pdf_with(p, tab, _vec(wi), _vec(wo)))

    return jax.value_and_grad(fn, argnums=(0, 1, 2))(p, wi, wo)


# 16 direction pairs: every combination of normal, grazing, below-horizon and oblique
_DIRS = np.array([[0.0, 0.0, 1.0], [0.6, 0.8, 0.0], [0.6, 0.0, -0.8], [0.0, 0.6, 0.8]])
_WI = jnp.asarray(np.repeat(_DIRS, 4, axis=0).T)
_WO = jnp.asarray(np.tile(_DIRS, (4, 1)).T)


def test_below_horizon_grazing_zero_and_finite_gradients():
    p = rp.Params(alpha=0.3, diffuse_reflectance=(0.5, 0.2, 0.9))
    f, pdf = np.asarray(rp.eval(p, _vec(_WI), _vec(_WO))), np.asarray(rp.pdf(p, _vec(_WI), _vec(_WO)))
    dead = (np.asarray(_WI[2]) <= 0) | (np.asarray(_WO[2]) <= 0)
    assert dead.sum() == 12 and np.all(f[dead] == 0) and np.all(pdf[dead] == 0)
    assert np.all(f[~dead] > 0) and np.all(pdf[~dead] > 0)
    for d in (_DIRS[1], _DIRS[2]):  # grazing / below: failed sample, weight 0
        _, w, pd = rp.sample(p, _vec(jnp.asarray(d)), (0.3, 0.6, 0.2))
        assert float(pd) == 0.0 and float(jnp.max(jnp.abs(w))) == 0.0
    _, grads = _value_and_grads(p, _WI, _WO)
    for g in jax.tree_util.tree_leaves(grads):
        assert bool(jnp.all(jnp.isfinite(g)))
    # an incident direction below the horizon gets no gradient at all
    assert np.all(np.asarray(grads[1])[:, 8:12] == 0)


def test_gradients_match_finite_differences():
    """Through the coat tables: d(sum f + sum pdf)/d(alpha, eta, rho, k_s) = central
    differences (step 1e-5: truncation ~1e-10, rounding ~1e-11)."""
    p = rp.Params(alpha=0.23, eta=1.45, diffuse_reflectance=(0.3, 0.6, 0.8), specular_reflectance=0.8)
    # same shapes as _WI, _WO (no new compilation): 2 oblique pairs, the rest n -> n
    wi = np.tile([[0.0], [0.0], [1.0]], (1, 16))
    wo = wi.copy()
    wi[:, 0], wi[:, 1] = [0.3, 0.1, math.sqrt(0.9)], [0.7, -0.2, math.sqrt(0.47)]
    wo[:, 0] = np.asarray(spherical_direction(0.6, 3.0).to_array())
    wo[:, 1] = np.asarray(spherical_direction(1.2, 0.4).to_array())
    wi, wo = jnp.asarray(wi), jnp.asarray(wo)
    r = testing.assert_gradients(lambda q: _value_and_grads(q, wi, wo)[0], p, rtol=1e-6, elementwise=True,
                                 grad_fn=lambda q: _value_and_grads(q, wi, wo)[1][0], name="rough_plastic")
    assert set(r.leaves) == {".alpha", ".eta", ".diffuse_reflectance", ".specular_reflectance"}


@pytest.mark.slow
def test_gradients_match_finite_differences_mitsuba_scheme():
    p = rp.Params(alpha=0.23, eta=1.45, diffuse_reflectance=(0.3, 0.6), specular_reflectance=0.8, **STATIC_B)
    wi = spherical_direction(jnp.array([0.3, 1.2]), jnp.array([0.0, 2.0]))
    wo = spherical_direction(jnp.array([0.6, 0.2]), jnp.array([3.0, 0.4]))
    fn = jax.jit(lambda q: jnp.sum(rp.eval.kernel(q, wi, wo)) + jnp.sum(rp.pdf.kernel(q, wi, wo)))
    testing.assert_gradients(fn, p, rtol=1e-5)


@pytest.mark.parametrize("static", [STATIC_A, pytest.param(STATIC_B, marks=pytest.mark.slow)], ids=["A", "B"])
def test_spatially_varying_parameters_broadcast(static):
    """alpha, eta with a leading axis (one coat per direction) = separate scalar evaluations
    (precomputed tables: a scalar set is looked up through its resampled table, a batch of sets
    through the Chebyshev series, equal within the resampling error <= 5.4e-5 in T)."""
    alphas, etas = jnp.array([0.05, 0.3, 1.0]), jnp.array([1.2, 1.5, 2.5])
    wi = spherical_direction(jnp.array([0.1, 0.8, 1.3]), 0.0)
    wo = spherical_direction(jnp.array([0.5, 0.3, 1.0]), jnp.array([3.0, 1.0, 2.0]))
    p = rp.Params(alpha=alphas, eta=etas, diffuse_reflectance=(0.2, 0.7), **static)
    f = np.asarray(rp.eval(p, wi, wo))
    with_pdf = static is STATIC_B  # (slow) the pdf's lookup of T_i too
    pdf = np.asarray(rp.pdf(p, wi, wo)) if with_pdf else None
    for i in range(3):
        q = rp.Params(alpha=float(alphas[i]), eta=float(etas[i]), diffuse_reflectance=(0.2, 0.7), **static)
        wi1, wo1 = Vec3(*(c[i] for c in wi)), Vec3(*(c[i] for c in wo))
        rtol = 2e-4 if q.tables == "precomputed" else 1e-12
        np.testing.assert_allclose(f[i], np.asarray(rp.eval(q, wi1, wo1)), rtol=rtol)
        if with_pdf:
            np.testing.assert_allclose(pdf[i], np.asarray(rp.pdf(q, wi1, wo1)), rtol=1e-12)


def test_traced_parameters_and_float32():
    """Inside the user's jit (no validation) = eager; float32 eval agrees to ~1e-5."""
    wi = spherical_direction(jnp.linspace(0.0, 1.4, 64), 0.0)
    wo = spherical_direction(jnp.linspace(1.3, 0.1, 64), 2.0)
    p = rp.Params(alpha=0.2, eta=1.6)
    f = jax.jit(lambda a: rp.eval(rp.Params(alpha=a, eta=1.6), wi, wo))(0.2)
    np.testing.assert_allclose(np.asarray(f), np.asarray(rp.eval(p, wi, wo)), rtol=1e-12)
    w32 = lambda w: Vec3(*(c.astype(jnp.float32) for c in w))  # noqa: E731
    p32 = rp.Params(alpha=jnp.float32(0.2), eta=jnp.float32(1.6), diffuse_reflectance=jnp.float32(0.5),
                    specular_reflectance=jnp.float32(1.0))
    f32 = rp.eval(p32, w32(wi), w32(wo))
    assert f32.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(f32), np.asarray(f), rtol=3e-5)


@pytest.mark.parametrize("kind", ["beckmann", pytest.param("ggx", marks=pytest.mark.slow)])
def test_float32_table_gradients(kind):
    """float32 coat tables and their gradients are finite and close to float64 (Beckmann's
    measure exp(-r^2) / cos^3 overflows near the horizon in float32 unless guarded)."""

    def R_int(a, e):
        return rp._tables(rp.Params(alpha=a, eta=e, distribution=kind, tables="accurate")).internal_reflectance

    g = jax.jit(jax.value_and_grad(R_int, argnums=(0, 1)))
    f32 = jnp.float32
    v, grads = g(f32(0.3), f32(1.5))
    assert v.dtype == jnp.float32 and all(x.dtype == jnp.float32 for x in grads)
    assert 0.3 < float(v) < 0.6
    # central differences in float32 with h = 1e-2: truncation ~h^2 ~1e-4, rounding ~1e-5
    h = 1e-2
    fd_a = (float(g(f32(0.3 + h), f32(1.5))[0]) - float(g(f32(0.3 - h), f32(1.5))[0])) / (2 * h)
    fd_e = (float(g(f32(0.3), f32(1.5 + h))[0]) - float(g(f32(0.3), f32(1.5 - h))[0])) / (2 * h)
    for ad, fd in zip(grads, (fd_a, fd_e)):
        assert np.isfinite(float(ad)) and float(ad) == pytest.approx(fd, rel=2e-3)


@pytest.mark.parametrize(
    "kw,field",
    [(dict(alpha=0.0), "alpha"), (dict(alpha=2.5), "alpha"), (dict(alpha=float("nan")), "alpha"),
     (dict(eta=0.9), "eta"), (dict(eta=3.5), "eta"), (dict(diffuse_reflectance=(0.5, 1.2)), "diffuse_reflectance"),
     (dict(specular_reflectance=-0.1), "specular_reflectance")],
)
def test_invalid_params_raise(kw, field):
    wi = spherical_direction(0.3, 0.0)
    with pytest.raises(ValueError, match=rf"Params\.{field}"):
        rp.eval(rp.Params(**kw), wi, wi)
    with pytest.raises(ValueError, match=rf"Params\.{field}"):
        rp.coat_tables(rp.Params(**kw))


def test_invalid_static_choices():
    for kw in (dict(distribution="phong"), dict(shadowing="none"), dict(tables="exact"), dict(nonlinear="yes")):
        with pytest.raises(ValueError, match=list(kw)[0]):
            rp.Params(**kw)


def test_model_record_and_presets():
    m = rp.MODEL
    assert m.name == "rough_plastic" and m.kind == "bsdf" and m.reciprocal and not m.transmissive
    assert m.Params is rp.Params and m.eval is rp.eval
    for p in m.presets.values():
        validate(p, rp.Params)
    # the defaults differ from Mitsuba's as documented
    d = rp.Params()
    assert (d.distribution, d.shadowing, d.tables, d.nonlinear) == ("ggx", "correlated", "precomputed", False)
    assert float(d.alpha) == 0.1 and float(d.eta) == 1.5
