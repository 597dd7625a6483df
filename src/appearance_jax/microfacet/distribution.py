"""Microfacet distributions with Smith masking-shadowing: one API, dispatched on ``kind``.

``kind`` is a static string, ``"ggx"`` (:mod:`.ggx`) or ``"beckmann"`` (:mod:`.beckmann`).
Roughnesses ``ax, ay`` (> 0, dimensionless) broadcast against the vector components;
``ay=None`` means isotropic (``ay = ax``). ``m`` (a microfacet normal) and ``w`` (a
direction) are unit :class:`~appearance_jax.core.vec.Vec3` in the local frame, z = the
macro normal n, pointing away from the surface.

Definitions (Walter et al. 2007, "Microfacet models for refraction through rough
surfaces"; Heitz 2014, "Understanding the masking-shadowing function in microfacet-based
BRDFs", JCGT 3(2); Heitz 2018, "Sampling the GGX distribution of visible normals", JCGT 7(4)):

- ``D(m)``: normal distribution in 1/sr, 0 for m.z <= 0, normalised so that
  int D(m) (m.n) dm = 1 (Heitz 2014).
- ``smith_lambda(w)``: Smith's Lambda, anisotropic (Heitz 2014 with the projected
  roughness alpha_w^2 = ax^2 cos^2 phi + ay^2 sin^2 phi).
- ``projected_area(w) = |w.z| (1 + Lambda(w)) = int max(0, w.m) D(m) dm`` (Heitz 2014):
  the finite quantity every other term is built from, so nothing divides by w.z.
- ``G1(w, m) = chi+((w.m) (w.n)) / (1 + Lambda(w)) = chi+((w.m)(w.n)) |w.n| / projected_area(w)``.
  **Below the horizon** we follow Walter et al. 2007 (their chi+((v.m)/(v.n)), Eq. 23) rather
  than returning 0: a direction below the macro surface sees the back sides of the
  (upward-facing) microfacets, m with w.m < 0, and Lambda is even in w.z. This is what a
  transmissive BSDF needs (light arriving from inside a dielectric). For w.z > 0 it
  reduces to chi+(w.m) chi+(w.z) / (1 + Lambda(w)); exactly grazing w.z = 0 gives 0.
  Reflection-only models mask w.z <= 0 themselves.
- ``G2(wi, wo, m)``: masking-shadowing.
  ``correlated=True`` is Smith's height-correlated form (Heitz 2014):
  reflection (wi, wo on the same side) 1 / (1 + Lambda(wi) + Lambda(wo));
  transmission (opposite sides) the Beta function B(1 + Lambda(wi), 1 + Lambda(wo)) =
  int_0^1 u^Lambda(wi) (1 - u)^Lambda(wo) du (the incoming ray is unblocked above height
  h with probability C1(h)^Lambda(wi), the outgoing one below h with (1 - C1(h))^Lambda(wo)).
  [pbrt-v4 applies the reflection form to transmission too; Mitsuba 3 is separable.]
  ``correlated=False`` is the separable product G1(wi, m) G1(wo, m) (Walter et al. 2007, Eq. 23).
  Both carry the chi+ factors of G1.
- ``sample_visible(w, u1, u2) -> m`` draws m with the density of visible normals
  ``pdf_visible(w, m) = G1(w, m) |w.m| D(m) / |w.n|`` (Heitz 2014; per sr of m),
  which integrates to 1 over m. GGX: Heitz 2018; Beckmann: CDF inversion of the visible
  slopes (Heitz & d'Eon 2014; Jakob 2014). A direction below the horizon is replaced by
  -w (the same visible-normal density under the Walter convention above), so m.z >= 0.
- ``sample_normal(u1, u2) -> m`` draws m with ``pdf_normal(m) = D(m) m.z`` (Walter et al.
  2007, Eq. 24, 28-29, 35-36).

All functions are branch-free, and return 0 with finite gradients for grazing or masked
inputs (safe-where trick).
"""

from __future__ import annotations

import jax.numpy as jnp

from ..core.special import beta1p
from ..core.vec import Vec3, dot, normalize
from . import beckmann, ggx

KINDS = ("ggx", "beckmann")

# Lambda is clamped here in the transmission Beta function: B(1 + L, 1 + L') <= 1/(1 + L) is
# then < 1e-8 anyway (and Lambda's own float32 rounding is no better there).
_LAMBDA_MAX = 1e8


def _mod(kind: str):
    if kind == "ggx":
        return ggx
    if kind == "beckmann":
        return beckmann
    raise ValueError(f"microfacet distribution kind = {kind!r} is not one of {list(KINDS)}")


def _ay(ax, ay):
    return ax if ay is None else ay


def D(kind: str, m: Vec3, ax, ay=None):
    """Normal distribution D(m) in 1/sr (0 for m.z <= 0); int D(m) (m.n) dm = 1."""
    return _mod(kind).D(m, ax, _ay(ax, ay))


def D_terms(kind: str, m: Vec3, ax, ay=None):
    """``(num, den)`` with D(m) = num / den, den > 0: for a BSDF that folds D into its own
    single division per element (num = 0, den = 1 for m.z <= 0)."""
    return _mod(kind).D_terms(m, ax, _ay(ax, ay))


def projected_area(kind: str, w: Vec3, ax, ay=None):
    """|w.z| (1 + Lambda(w)) = int max(0, w.m) D(m) dm; finite and > 0, even in w.z."""
    return _mod(kind).projected_area(w, ax, _ay(ax, ay))


def smith_lambda(kind: str, w: Vec3, ax, ay=None):
    """Smith Lambda(w) (Heitz 2014); even in w.z.

    Diverges at grazing incidence; returned finite there (~ 1/tiny), with finite gradients.
    """
    z = jnp.abs(w.z)
    tiny = jnp.finfo(jnp.result_type(z, float)).tiny ** 0.5
    return projected_area(kind, w, ax, ay) / jnp.maximum(z, tiny) - 1.0


def _chi(w: Vec3, m: Vec3):
    """chi+((w.m)(w.n)): w sees the front of m from its side of the macro surface."""
    return dot(w, m) * w.z > 0


def _g1_nochi(kind, w, ax, ay):
    mu = projected_area(kind, w, ax, ay)
    return jnp.abs(w.z) / mu


def G1(kind: str, w: Vec3, m: Vec3, ax, ay=None):
    """Smith masking chi+((w.m)(w.n)) / (1 + Lambda(w)) (Walter et al. 2007, Eq. 23/27/34)."""
    ay = _ay(ax, ay)
    return jnp.where(_chi(w, m), _g1_nochi(kind, w, ax, ay), 0.0)


def G2(kind: str, wi: Vec3, wo: Vec3, m: Vec3, ax, ay=None, correlated: bool = True,
       reflection_only: bool = False):
    """Masking-shadowing G2(wi, wo, m): height-correlated (default) or separable.

    Reflection (wi.z wo.z > 0) correlated: 1 / (1 + Lambda_i + Lambda_o) (Heitz 2014),
    computed as |zi||zo| / (mu_i |zo| + mu_o |zi| - |zi||zo|) to stay finite at grazing.
    Transmission (wi.z wo.z < 0) correlated: B(1 + Lambda_i, 1 + Lambda_o) (Heitz 2014).
    Separable: G1(wi, m) G1(wo, m).

    The Beta function is :func:`~appearance_jax.core.special.beta1p` (one Stirling series, not
    three log-Gammas). ``reflection_only=True`` (static) skips the transmission branch:
    reflection-only models (conductors, coated diffuse) then do not pay for it, which jnp.where
    would otherwise compute for every sample.
    """
    ay = _ay(ax, ay)
    chi = _chi(wi, m) & _chi(wo, m)
    if not correlated:
        g = _g1_nochi(kind, wi, ax, ay) * _g1_nochi(kind, wo, ax, ay)
        return jnp.where(chi, g, 0.0)
    zi, zo = jnp.abs(wi.z), jnp.abs(wo.z)
    mui = projected_area(kind, wi, ax, ay)
    muo = projected_area(kind, wo, ax, ay)
    # reflection: 1 / (1 + L_i + L_o) multiplied through by |zi||zo|
    den = mui * zo + muo * zi - zi * zo
    ok = den > 0
    g_refl = jnp.where(ok, zi * zo / jnp.where(ok, den, 1.0), 0.0)
    if reflection_only:
        return jnp.where(chi & (wi.z * wo.z > 0), g_refl, 0.0)
    transmission = wi.z * wo.z < 0
    return jnp.where(chi, jnp.where(transmission, _beta_g2(mui, muo, zi, zo), g_refl), 0.0)


def _beta_g2(mui, muo, zi, zo):
    """B(1 + Lambda_i, 1 + Lambda_o), Lambda = mu/|z| - 1 clamped at grazing (where chi = 0 anyway)."""
    # mu * (1 / z), not mu / z: XLA:CPU does not fuse a quotient read by several operations (it
    # stores it and splits the kernel, ~2x slower here), a reciprocal it does (issue 20)
    li = jnp.minimum(mui * (1.0 / jnp.maximum(zi, 1.0 / _LAMBDA_MAX)) - 1.0, _LAMBDA_MAX)
    lo = jnp.minimum(muo * (1.0 / jnp.maximum(zo, 1.0 / _LAMBDA_MAX)) - 1.0, _LAMBDA_MAX)
    return beta1p(li, lo)  # (rounding below 0 is taken as 0 there)


def G2_terms(kind: str, wi: Vec3, wo: Vec3, m: Vec3, ax, ay=None, correlated: bool = True,
             reflection_only: bool = False):
    """``(num, den)`` with G2(wi, wo, m) / (|wi.z| |wo.z|) = num / den where den > 0 (and G2 = 0
    where den = 0, grazing): what a BSDF divides by anyway, in a form it folds into its own
    single division. Separable: (chi, mu_i mu_o); correlated reflection: (chi, mu_i |zo| +
    mu_o |zi| - |zi||zo|); correlated transmission: (chi B(1 + Lambda_i, 1 + Lambda_o), |zi||zo|).
    Same forms and conventions as :func:`G2` (which returns the value itself);
    ``reflection_only=True`` gives num = 0 for transmission pairs in both forms."""
    ay = _ay(ax, ay)
    chi = _chi(wi, m) & _chi(wo, m)
    if reflection_only:
        chi = chi & (wi.z * wo.z > 0)
    mui = projected_area(kind, wi, ax, ay)
    muo = projected_area(kind, wo, ax, ay)
    one = jnp.where(chi, 1.0, 0.0)
    if not correlated:
        return one, mui * muo
    zi, zo = jnp.abs(wi.z), jnp.abs(wo.z)
    den = mui * zo + muo * zi - zi * zo
    if reflection_only:
        return one, den
    transmission = wi.z * wo.z < 0
    num = jnp.where(transmission, jnp.where(chi, _beta_g2(mui, muo, zi, zo), 0.0), one)
    return num, jnp.where(transmission, zi * zo, den)


def pdf_visible(kind: str, w: Vec3, m: Vec3, ax, ay=None):
    """Density (per sr of m) of visible normals: G1(w, m) |w.m| D(m) / |w.n| (Heitz 2014).

    Written as chi |w.m| D(m) / projected_area(w), which has no 1/w.z singularity.
    """
    ay = _ay(ax, ay)
    mu = projected_area(kind, w, ax, ay)
    val = jnp.abs(dot(w, m)) * D(kind, m, ax, ay) / mu
    return jnp.where(_chi(w, m), val, 0.0)


def sample_visible(kind: str, w: Vec3, ax, ay, u1, u2) -> Vec3:
    """Sample a visible normal m ~ pdf_visible(w, .); m.z >= 0.

    ``w`` below the horizon is replaced by ``-w`` (the visible-normal density is the same,
    see the module docstring). u1, u2 uniform in [0, 1).
    """
    ay = _ay(ax, ay)
    flip = jnp.where(w.z < 0, -1.0, 1.0)
    return _mod(kind).sample_visible(w * flip, ax, ay, u1, u2)


def pdf_normal(kind: str, m: Vec3, ax, ay=None):
    """Density D(m) m.z of :func:`sample_normal` (per sr of m)."""
    return D(kind, m, ax, ay) * jnp.maximum(m.z, 0.0)


def sample_normal(kind: str, ax, ay, u1, u2) -> Vec3:
    """Sample m ~ D(m) m.z (Walter et al. 2007, Eq. 28-29 Beckmann, 35-36 GGX; anisotropic by
    stretching the alpha = 1 slopes)."""
    ay = _ay(ax, ay)
    sx, sy = _mod(kind).sample_slopes(ax, ay, u1, u2)
    return normalize(Vec3(-sx, -sy, jnp.ones_like(sx)))
