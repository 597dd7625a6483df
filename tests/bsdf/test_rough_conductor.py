"""Rough conductor: closed forms, reciprocity, energy, sampling consistency, edge cases."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import testing
from appearance_jax.bsdf import rough_conductor as rc
from appearance_jax.core.frame import spherical_direction
from appearance_jax.core.quadrature import sphere_rule
from appearance_jax.core.vec import Vec3

CONFIGS = {
    "ggx_iso_corr": rc.Params(alpha=0.3),
    "beckmann_aniso": rc.Params(alpha=0.15, alpha_v=0.5, distribution="beckmann"),
    "ggx_sep_rough": rc.Params(alpha=0.6, shadowing="separable"),
}


def _upper(key, n):
    v = jax.random.normal(key, (3, n), dtype=jnp.float64)
    v = v / jnp.linalg.norm(v, axis=0)
    return Vec3(v[0], v[1], jnp.abs(v[2]))


@pytest.mark.parametrize("name", list(CONFIGS))
def test_reciprocity(name):
    p = CONFIGS[name]
    wi, wo = _upper(jax.random.PRNGKey(0), 2000), _upper(jax.random.PRNGKey(1), 2000)
    a, b = rc.eval(p, wi, wo), rc.eval(p, wo, wi)
    assert a.shape == (2000, 3)
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-11, atol=1e-14)


@pytest.mark.parametrize("kind", ["ggx", "beckmann"])
def test_normal_incidence_closed_form(kind):
    """wi = wo = n: h = n, G2 = 1, D(n) = 1/(pi ax ay) for both NDFs, F = F0 of n + ik."""
    eta, k = np.array([0.2, 0.9, 1.3]), np.array([3.5, 2.0, 1.8])
    p = rc.Params(alpha=0.2, alpha_v=0.35, eta=eta, k=k, specular_reflectance=(1.0, 0.5, 0.25), distribution=kind)
    n = Vec3(0.0, 0.0, 1.0)
    f = np.asarray(rc.eval(p, n, n))
    f0 = ((eta - 1) ** 2 + k**2) / ((eta + 1) ** 2 + k**2)
    np.testing.assert_allclose(f, f0 * np.array([1.0, 0.5, 0.25]) / (4 * math.pi * 0.2 * 0.35), rtol=1e-12)


def test_isotropic_default_equals_explicit_and_rotation():
    wi, wo = _upper(jax.random.PRNGKey(2), 500), _upper(jax.random.PRNGKey(3), 500)
    a = rc.eval(rc.Params(alpha=0.25), wi, wo)
    b = rc.eval(rc.Params(alpha=0.25, alpha_v=0.25), wi, wo)
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-13)
    # swapping the roughnesses = rotating both directions by 90 degrees about z
    rot = lambda w: Vec3(-w.y, w.x, w.z)  # noqa: E731
    for kind in ("ggx", "beckmann"):
        c = rc.eval(rc.Params(alpha=0.1, alpha_v=0.4, distribution=kind), wi, wo)
        d = rc.eval(rc.Params(alpha=0.4, alpha_v=0.1, distribution=kind), rot(wi), rot(wo))
        np.testing.assert_allclose(np.asarray(c), np.asarray(d), rtol=1e-11, atol=1e-14)


def test_correlated_at_least_separable():
    wi, wo = _upper(jax.random.PRNGKey(4), 1000), _upper(jax.random.PRNGKey(5), 1000)
    c = rc.eval(rc.Params(alpha=0.5), wi, wo)
    s = rc.eval(rc.Params(alpha=0.5, shadowing="separable"), wi, wo)
    assert bool(jnp.all(c >= s * (1 - 1e-12)))
    assert float(jnp.max(c - s)) > 0


@pytest.mark.parametrize("name", list(CONFIGS))
def test_sample_consistency(name):
    """weight == f cos_o / pdf and pdf == pdf(wi, wo) at the samples; failures are 0."""
    p = CONFIGS[name]
    n = 20_000
    for theta in (0.0, 0.8, 1.45):
        wi = spherical_direction(jnp.full(n, theta), jnp.full(n, 0.3))
        wo, w, pdf = rc.sample(p, wi, jax.random.PRNGKey(7))
        assert w.shape == (n, 3) and pdf.shape == (n,)
        ok = pdf > 0
        assert float(jnp.mean(ok)) > 0.5
        assert bool(jnp.all(jnp.where(ok, wo.z > 0, True)))
        assert bool(jnp.all(jnp.where(ok[:, None], True, w == 0)))
        f = rc.eval(p, wi, wo)
        pe = rc.pdf(p, wi, wo)
        np.testing.assert_allclose(np.asarray(pe[ok]), np.asarray(pdf[ok]), rtol=1e-10)
        ref = f * wo.z[:, None] / jnp.where(ok, pdf, 1.0)[:, None]
        np.testing.assert_allclose(np.asarray(w[ok]), np.asarray(ref[ok]), rtol=1e-10)


def _mirror(**kw):
    # eta = 0 makes F = 1 exactly (a perfect mirror), so the albedo is the microfacet term alone
    return rc.Params(eta=0.0, k=1.0, **kw)


@pytest.mark.parametrize("p", [_mirror(alpha=0.3), _mirror(alpha=0.8, alpha_v=0.2, distribution="beckmann"),
                               _mirror(alpha=1.5, shadowing="separable")], ids=["ggx", "beckmann_aniso", "ggx_sep"])
def test_energy_and_pdf_integral(p):
    """White furnace with F = 1: albedo <= 1 (quadrature and MC agree); int pdf <= 1."""
    d, wt = sphere_rule(300, 300, hemisphere=True)
    n = 50_000
    for theta in (0.2, 1.0, 1.4):
        wi1 = spherical_direction(theta, 0.5)
        alb = float(jnp.sum(rc.eval(p, wi1, d)[:, 0] * d.z * wt))
        pint = float(jnp.sum(rc.pdf(p, wi1, d) * wt))
        assert alb <= 1.0 and pint <= 1.0 + 1e-6
        assert alb > 0.1  # single scattering only: rough + grazing loses up to ~85%
        wi = spherical_direction(jnp.full(n, theta), jnp.full(n, 0.5))
        _, w, pdf = rc.sample(p, wi, jax.random.PRNGKey(11))
        w = w[:, 0]
        se = float(jnp.std(w)) / math.sqrt(n)
        assert abs(float(jnp.mean(w)) - alb) < 5 * se + 1e-4  # 1e-4: quadrature error
        frac = float(jnp.mean(pdf > 0))
        assert abs(frac - pint) < 5 * math.sqrt(pint * (1 - pint) / n) + 1e-4


def test_grazing_and_below_horizon():
    p = rc.Params(alpha=0.3, alpha_v=0.2)

    def vec(a):
        return Vec3(a[0], a[1], a[2])

    dirs = [jnp.array(v) for v in ([0.0, 0.0, 1.0], [0.6, 0.8, 0.0], [0.6, 0.0, -0.8], [0.0, 0.6, 0.8])]
    up, graz, below = dirs[0], dirs[1], dirs[2]
    for a, b in [(graz, up), (up, graz), (below, up), (up, below), (graz, graz)]:
        assert float(jnp.max(jnp.abs(rc.eval(p, vec(a), vec(b))))) == 0.0
        assert float(rc.pdf(p, vec(a), vec(b))) == 0.0
    _, w, pdf = rc.sample(p, vec(graz), (0.3, 0.6))
    assert float(pdf) == 0.0 and float(jnp.max(jnp.abs(w))) == 0.0

    W = jnp.stack([a for a in dirs for _ in dirs], axis=1)
    O = jnp.stack([b for _ in dirs for b in dirs], axis=1)

    @jax.jit
    def grads(wi, wo, p):
        ge = jax.grad(lambda wi, wo, p: jnp.sum(rc.eval.kernel(p, vec(wi), vec(wo))), argnums=(0, 1, 2))(wi, wo, p)
        gp = jax.grad(lambda wi, wo, p: jnp.sum(rc.pdf.kernel(p, vec(wi), vec(wo))), argnums=(0, 1, 2))(wi, wo, p)

        def s(wi, p):
            wo, w, pdf = rc.sample.kernel(p, vec(wi), (0.3, 0.6))
            return jnp.sum(w) + jnp.sum(pdf) + jnp.sum(wo.to_array())

        gs = jax.grad(s, argnums=(0, 1))(wi, p)
        return ge, gp, gs

    for g in jax.tree_util.tree_leaves(grads(W, O, p)):
        assert bool(jnp.all(jnp.isfinite(g)))


def test_gradient_matches_finite_differences():
    wi = spherical_direction(0.5, 0.2)
    wo = spherical_direction(0.7, 2.9)

    @jax.jit
    def f(a, e, k):
        p = rc.Params(alpha=a, alpha_v=0.3, eta=e, k=k, distribution="beckmann")
        return jnp.sum(rc.eval.kernel(p, wi, wo))

    testing.assert_gradients(lambda x: f(*x), (0.25, 1.1, 2.5), rtol=1e-6, name="rough_conductor")


@pytest.mark.parametrize(
    "kw,field",
    [(dict(alpha=-0.1), "alpha"), (dict(alpha=float("nan")), "alpha"), (dict(alpha=0.0), "alpha"),
     (dict(alpha_v=-1.0), "alpha_v"), (dict(eta=(-1.0, 1.0, 1.0)), "eta"), (dict(k=float("nan")), "k"),
     (dict(specular_reflectance=1.5), "specular_reflectance")],
)
def test_invalid_params_raise(kw, field):
    wi = spherical_direction(0.3, 0.0)
    with pytest.raises(ValueError, match=rf"Params\.{field}"):
        rc.eval(rc.Params(**kw), wi, wi)


def test_invalid_static_choice():
    with pytest.raises(ValueError, match="distribution"):
        rc.Params(distribution="phong")
    with pytest.raises(ValueError, match="shadowing"):
        rc.Params(shadowing="none")


def test_model_record():
    m = rc.MODEL
    assert m.name == "rough_conductor" and m.reciprocal and not m.transmissive
    assert m.Params is rc.Params and set(m.presets) >= {"gold"}
    # default gold at 650/510/475 nm: red reflects most at normal incidence
    n = Vec3(0.0, 0.0, 1.0)
    f = np.asarray(rc.eval(rc.Params(), n, n))
    assert f[0] > f[1] > f[2]
