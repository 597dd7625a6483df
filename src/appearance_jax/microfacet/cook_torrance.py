"""Cook-Torrance microfacet reflection with the Fresnel term passed in.

    f(wi, wo) = F(wi.h) D(h) G2(wi, wo, h) / (4 cos theta_i cos theta_o),   h = (wi + wo) / |wi + wo|

(Cook & Torrance 1982; Walter et al. 2007, Eq. 20; Padrón 2025 spec M08, with the Fresnel
term at the microfacet angle wi.h), for wi, wo both above the surface, else 0. Every
reflective microfacet BSDF of the library (``rough_conductor``: conductor Fresnel;
``iridescent``: Airy thin film) is this function with its own ``fresnel(cos_h)``, which
maps a per-pair cosine in [0, 1] to ``cos_h.shape + (n_bands,)``.

Sampling: visible normals of wi (Heitz 2018 for GGX, CDF inversion for Beckmann), then
mirror: pdf(wi, wo) = G1(wi, h) D(h) / (4 cos theta_i) = D(h) / (4 mu(wi)) (Heitz 2014; the
reflection Jacobian 1/(4 |wo.h|), Walter et al. 2007, Eq. 14) and
weight = f cos theta_o / pdf = F G2 / G1(wi) = F G2 mu(wi) / cos theta_i (no D: exact even
where D is huge for small roughness).

``p`` is any Params with ``alpha``, ``alpha_v`` (None: isotropic), and the static fields
``distribution`` and ``shadowing`` ("correlated" or "separable" Smith G2).
"""

from __future__ import annotations

import jax.numpy as jnp

from ..core.frame import reflect
from ..core.model import with_bands
from ..core.rng import uniforms
from ..core.vec import Vec3, dot, normalize
from . import distribution as md


def alphas(p):
    """(alpha_x, alpha_y): alpha_v defaults to alpha (isotropic)."""
    ax = jnp.asarray(p.alpha)
    ay = ax if p.alpha_v is None else jnp.asarray(p.alpha_v)
    return ax, ay


def half(wi: Vec3, wo: Vec3) -> Vec3:
    return normalize(wi + wo)


def _g2(p, wi: Vec3, wo: Vec3, m: Vec3, ax, ay):
    return md.G2(p.distribution, wi, wo, m, ax, ay, correlated=p.shadowing == "correlated", reflection_only=True)


def reflection(p, wi: Vec3, wo: Vec3, fresnel):
    """``fresnel(wi.h) D G2 / (4 cos_i cos_o)`` over the bands of ``fresnel``; 0 below the surface."""
    ax, ay = alphas(p)
    h = half(wi, wo)
    den = 4.0 * wi.z * wo.z
    ok = (wi.z > 0) & (wo.z > 0) & (den > 0)
    dg = md.D(p.distribution, h, ax, ay) * _g2(p, wi, wo, h, ax, ay)
    # safe-where: the masked branch divides by 1, so gradients stay finite at grazing
    base = jnp.where(ok, dg / jnp.where(ok, den, 1.0), 0.0)
    return with_bands(base) * fresnel(jnp.clip(dot(wi, h), 0.0, 1.0))


def pdf_from_half(p, wi: Vec3, h: Vec3, ok):
    """pdf(wo) = pdf_visible(wi, h) / (4 |wi.h|) = D(h) / (4 mu(wi)) where ``ok``."""
    ax, ay = alphas(p)
    mu = md.projected_area(p.distribution, wi, ax, ay)
    ok = ok & (dot(wi, h) > 0)
    return jnp.where(ok, md.D(p.distribution, h, ax, ay) / (4.0 * mu), 0.0)


def pdf(p, wi: Vec3, wo: Vec3):
    """Density of :func:`sample_reflection` (1/sr); 0 unless both directions are above."""
    return pdf_from_half(p, wi, half(wi, wo), (wi.z > 0) & (wo.z > 0))


def sample_reflection(p, wi: Vec3, u, fresnel):
    """Visible-normal sample: ``(wo, weight, pdf)``; failed samples have weight 0 and pdf 0.

    ``u`` is a PRNG key or 2 uniform arrays (the visible normal).
    """
    ax, ay = alphas(p)
    shape = jnp.broadcast_shapes(jnp.shape(wi.z), jnp.shape(ax), jnp.shape(ay))
    u1, u2 = uniforms(u, shape, 2)
    m = md.sample_visible(p.distribution, wi, ax, ay, u1, u2)
    wo = reflect(wi, m)
    cos_m = dot(wi, m)
    pdf_ = pdf_from_half(p, wi, m, (wi.z > 0) & (wo.z > 0) & (cos_m > 0))
    ok = pdf_ > 0
    g2_mu = _g2(p, wi, wo, m, ax, ay) * md.projected_area(p.distribution, wi, ax, ay)
    w = jnp.where(ok, g2_mu / jnp.where(ok, wi.z, 1.0), 0.0)
    return wo, with_bands(w) * fresnel(jnp.clip(cos_m, 0.0, 1.0)), pdf_
