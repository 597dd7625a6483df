"""Rough dielectric: generalised reciprocity, energy, sampling consistency, limits, edge cases."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import testing
from appearance_jax.bsdf import rough_dielectric as rd
from appearance_jax.core.frame import spherical_direction
from appearance_jax.core.quadrature import sphere_rule
from appearance_jax.core.vec import Vec3
from appearance_jax.optics.fresnel import fresnel_dielectric

CONFIGS = {
    "ggx_glass": rd.Params(alpha=0.3, eta=1.5),
    "beckmann_aniso_water_sep": rd.Params(alpha=0.15, alpha_v=0.45, eta=1.33, distribution="beckmann",
                                          shadowing="separable"),
    "ggx_bubble": rd.Params(alpha=0.5, eta=0.7),
}


def _sphere(key, n):
    v = jax.random.normal(key, (3, n), dtype=jnp.float64)
    v = v / jnp.linalg.norm(v, axis=0)
    return Vec3(v[0], v[1], v[2])


@pytest.mark.parametrize("name", list(CONFIGS))
def test_generalised_reciprocity(name):
    """f(wi -> wo) / eta_o^2 = f(wo -> wi) / eta_i^2 (Veach 1997, Sec. 5.2); plain for reflection."""
    p = CONFIGS[name]
    n = 4000
    wi, wo = _sphere(jax.random.PRNGKey(0), n), _sphere(jax.random.PRNGKey(1), n)
    a, b = rd.eval(p, wi, wo)[:, 0], rd.eval(p, wo, wi)[:, 0]
    eta = float(p.eta)
    eta_i = jnp.where(wi.z < 0, eta, 1.0)
    eta_o = jnp.where(wo.z < 0, eta, 1.0)
    transmit = wi.z * wo.z < 0
    assert float(jnp.mean(transmit & (a > 0))) > 0.05  # the transmission lobe is exercised
    np.testing.assert_allclose(np.asarray(a / eta_o**2), np.asarray(b / eta_i**2), rtol=1e-10, atol=1e-14)
    # and the transmitted lobe is genuinely non-symmetric
    t = transmit & (a > 1e-3)
    assert float(jnp.max(jnp.abs(a - b) / jnp.maximum(a, 1e-30) * t)) > 0.1


@pytest.mark.parametrize("name", list(CONFIGS))
def test_sample_consistency(name):
    p = CONFIGS[name]
    n = 20_000
    for theta in (0.0, 0.7, 1.45, math.pi - 0.3, math.pi - 1.2):
        wi = spherical_direction(jnp.full(n, theta), jnp.full(n, 0.3))
        wo, w, pdf = rd.sample(p, wi, jax.random.PRNGKey(7))
        assert w.shape == (n, 1) and pdf.shape == (n,)
        ok = pdf > 0
        assert float(jnp.mean(ok)) > 0.5
        assert bool(jnp.all(jnp.where(ok[:, None], True, w == 0)))
        f = rd.eval(p, wi, wo)
        pe = rd.pdf(p, wi, wo)
        np.testing.assert_allclose(np.asarray(pe[ok]), np.asarray(pdf[ok]), rtol=1e-9)
        ref = f * jnp.abs(wo.z)[:, None] / jnp.where(ok, pdf, 1.0)[:, None]
        np.testing.assert_allclose(np.asarray(w[ok]), np.asarray(ref[ok]), rtol=1e-9)


@pytest.mark.parametrize("name", list(CONFIGS))
def test_energy_and_pdf_integral(name):
    """Flux albedo int f |cos_o| d wo <= 1 and int pdf <= 1 over the sphere (quadrature),
    and the MC albedo (mean sample weight) agrees with the quadrature within 5 sigma."""
    p = CONFIGS[name]
    d, wt = sphere_rule(400, 300)
    n = 50_000
    for theta in (0.3, 1.3, math.pi - 0.4, math.pi - 1.2):
        wi1 = spherical_direction(theta, 0.5)
        alb = float(jnp.sum(rd.eval(p, wi1, d)[:, 0] * jnp.abs(d.z) * wt))
        pint = float(jnp.sum(rd.pdf(p, wi1, d) * wt))
        assert 0.3 < alb <= 1.0 + 1e-4 and pint <= 1.0 + 1e-4
        wi = spherical_direction(jnp.full(n, theta), jnp.full(n, 0.5))
        _, w, pdf = rd.sample(p, wi, jax.random.PRNGKey(11))
        w = w[:, 0]
        se = float(jnp.std(w)) / math.sqrt(n)
        assert float(jnp.mean(w)) - 5 * se <= 1.0
        assert abs(float(jnp.mean(w)) - alb) < 5 * se + 2e-3  # 2e-3: quadrature error
        frac = float(jnp.mean(pdf > 0))
        assert abs(frac - pint) < 5 * math.sqrt(max(pint * (1 - pint), 1e-6) / n) + 2e-3


def test_smooth_limit_fresnel_split_and_tir():
    """Small roughness: reflected / transmitted flux -> F / 1 - F of a smooth interface;
    beyond the critical angle from inside nothing is transmitted."""
    n = 40_000
    p = rd.Params(alpha=0.01, eta=1.5)
    for theta, outside in [(0.5, True), (1.2, True), (0.4, False)]:
        th = theta if outside else math.pi - theta
        wi = spherical_direction(jnp.full(n, th), jnp.full(n, 0.2))
        wo, w, pdf = rd.sample(p, wi, jax.random.PRNGKey(3))
        refl = wo.z * wi.z > 0
        R = float(jnp.mean(w[:, 0] * refl))
        T = float(jnp.mean(w[:, 0] * ~refl))
        F = float(fresnel_dielectric(jnp.cos(th), 1.5)[0])
        se = math.sqrt(F * (1 - F) / n)
        assert abs(R - F) < 5 * se + 5e-3 and abs(T - (1 - F)) < 5 * se + 5e-3
    # inside, sin(theta) = 0.9 > 1/1.5: total internal reflection
    wi = spherical_direction(jnp.full(n, math.pi - math.asin(0.9)), jnp.full(n, 0.2))
    wo, w, _ = rd.sample(p, wi, jax.random.PRNGKey(4))
    assert float(jnp.mean(w[:, 0] * (wo.z * wi.z < 0))) < 1e-3
    assert float(jnp.mean(w[:, 0])) > 0.95


def test_correlated_vs_separable():
    """Height correlation raises G2 for reflection and lowers it for transmission (the Beta
    function: the incoming ray prefers high points, the refracted outgoing one low points)."""
    n = 4000
    wi, wo = _sphere(jax.random.PRNGKey(5), n), _sphere(jax.random.PRNGKey(6), n)
    c = rd.eval(rd.Params(alpha=0.6), wi, wo)[:, 0]
    s = rd.eval(rd.Params(alpha=0.6, shadowing="separable"), wi, wo)[:, 0]
    transmit = wi.z * wo.z < 0
    assert bool(jnp.all(jnp.where(transmit, c <= s * (1 + 1e-12), c >= s * (1 - 1e-12))))
    assert float(jnp.max(jnp.where(transmit, s - c, 0.0))) > 0
    assert float(jnp.max(jnp.where(transmit, 0.0, c - s))) > 0


def test_grazing_gives_zero_with_finite_gradients():
    p = rd.Params(alpha=0.3, alpha_v=0.2)

    def vec(a):
        return Vec3(a[0], a[1], a[2])

    dirs = [jnp.array(v) for v in ([0.0, 0.0, 1.0], [0.6, 0.8, 0.0], [0.6, 0.0, -0.8], [0.0, 0.0, -1.0],
                                   [0.0, 0.6, 0.8])]
    graz = dirs[1]
    for other in dirs:
        assert float(rd.eval(p, vec(graz), vec(other))[0]) == 0.0
        assert float(rd.eval(p, vec(other), vec(graz))[0]) == 0.0
        assert float(rd.pdf(p, vec(graz), vec(other))) == 0.0
    _, w, pdf = rd.sample(p, vec(graz), (0.3, 0.6, 0.5))
    assert float(pdf) == 0.0 and float(w[0]) == 0.0

    W = jnp.stack([a for a in dirs for _ in dirs], axis=1)
    O = jnp.stack([b for _ in dirs for b in dirs], axis=1)

    @jax.jit
    def grads(wi, wo, p):
        ge = jax.grad(lambda wi, wo, p: jnp.sum(rd.eval.kernel(p, vec(wi), vec(wo))), argnums=(0, 1, 2))(wi, wo, p)
        gp = jax.grad(lambda wi, wo, p: jnp.sum(rd.pdf.kernel(p, vec(wi), vec(wo))), argnums=(0, 1, 2))(wi, wo, p)

        def s(wi, p, u3):
            wo, w, pdf = rd.sample.kernel(p, vec(wi), (0.3, 0.6, u3))
            return jnp.sum(w) + jnp.sum(pdf) + jnp.sum(wo.to_array())

        # u3 = 0.01 picks reflection, 0.99 refraction (or TIR reflection)
        gs = [jax.grad(s, argnums=(0, 1))(wi, p, u3) for u3 in (0.01, 0.99)]
        return ge, gp, gs

    for g in jax.tree_util.tree_leaves(grads(W, O, p)):
        assert bool(jnp.all(jnp.isfinite(g)))


def test_gradient_matches_finite_differences():
    wi = spherical_direction(0.5, 0.2)
    pairs = [spherical_direction(0.7, 2.9), spherical_direction(math.pi - 0.4, 3.0)]  # reflect, transmit

    @jax.jit
    def f(a, e):
        p = rd.Params(alpha=a, alpha_v=0.3, eta=e)
        return sum(jnp.sum(rd.eval.kernel(p, wi, wo)) for wo in pairs)

    testing.assert_gradients(lambda x: f(*x), (0.25, 1.4), rtol=1e-6, name="rough_dielectric")


@pytest.mark.parametrize(
    "kw,field",
    [(dict(alpha=-0.1), "alpha"), (dict(alpha=float("nan")), "alpha"), (dict(alpha_v=-1.0), "alpha_v"),
     (dict(eta=0.0), "eta"), (dict(eta=-1.5), "eta"), (dict(eta=float("nan")), "eta"), (dict(eta=1.0), "eta"),
     (dict(eta=1.0005), "eta"), (dict(eta=50.0), "eta")],
)
def test_invalid_params_raise(kw, field):
    wi = spherical_direction(0.3, 0.0)
    with pytest.raises(ValueError, match=rf"Params\.{field}"):
        rd.eval(rd.Params(**kw), wi, wi)


def test_model_record():
    m = rd.MODEL
    assert m.name == "rough_dielectric" and not m.reciprocal and m.transmissive
    assert m.Params is rd.Params and "glass" in m.presets
