"""The cosmetic medium: spherical diffusers and SGGX platelets in one slab (Ch. 4, Padrón 2025;
seed-000 spec M15).

Extinction, albedo and phase function of the anisotropic RTE (Padrón Eq. 4.2), with the base
extinction ``sigma_base = 1`` (thicknesses are in base mean free paths, [T:774, 804]):

    sigma_t(w) = c_d + (1 - c_d) C(w)                                    (Padrón Eq. 4.5)
    Lambda(w)  = (Lambda_d c_d + Lambda_p (1 - c_d) C(w)) / sigma_t(w)   (Padrón Eq. 4.7)
    f(w -> wo) = (Lambda_d c_d f_d + Lambda_p (1 - c_d) C(w) f_p)
                 / (Lambda_d c_d + Lambda_p (1 - c_d) C(w))               (Padrón Eq. 4.8)

``C(w)`` = Ĉ_p(w) is the platelets' normalised projected area, the SGGX sigma(w) of
:func:`appearance_jax.phase.sggx_flakes.sigma` (max 1 along the mean flake normal); ``f_d`` is
the two-lobe HG mixture (Padrón Eq. 4.9) and ``f_p`` the specular flake phase function
(Padrón Eq. 4.10).
Both directions point away from the scattering point; light travels along ``d = -wi`` and C
is even, so the direction "seen" by the light is immaterial (decision D5).

What a random walk needs is the product ``Lambda(wi) f(wi -> wo)`` (:func:`scattering`),
which simplifies to ``(Lambda_d c_d f_d + Lambda_p (1 - c_d) D(wh) / 4) / sigma_t(wi)``
because ``C(wi) f_p = D(wh) / 4`` (no division by a small projected area), and the
collision kernel (:func:`collide`): the particle is a platelet with the colourless
probability ``P_p = (1 - c_d) C(wi) / sigma_t(wi)``, otherwise a diffuser; the throughput
is multiplied by that particle's albedo and the direction is drawn from its phase function
(SGGX visible normals; HG inversion). Its expectation is ``Lambda(wi) f(wi -> wo)``: the
two formulations of the thesis [T:736] agree (tests/layered/test_medium.py).

Gradients: the particle type and the HG lobe are discrete choices. They are drawn with
``stop_gradient`` probabilities (``q = P_p`` and ``q_w = w_g``, frozen) and the weight is the
one-sample mixture estimate ``Lambda f(wi -> wo) / pdf_q(wo)`` with
``pdf_q = q f_p + (1 - q) (q_w f_HG(g1) + (1 - q_w) f_HG(g2))`` evaluated at the sampled
direction (spec §6.4, "discrete choices"): in value it is the colour-mixed albedo (exactly 1
for white media, so a white furnace conserves energy path by path); its derivative carries
the score terms, and because every lobe has full support it stays unbiased even at the
bounds (w_g = 1, c_d = 1), where one branch is never sampled (why not defensive sampling:
docs/cosmetics.md).
Directions are reparameterised samples, smooth in g1, g2, alpha and theta; the mixture
density keeps its dependence on them, as a reparameterised estimator requires.

| parameter | default | range     | unit | meaning                                              |
|-----------|---------|-----------|------|------------------------------------------------------|
| c_d       | 0.9     | [0, 1]    | 1    | relative diffuser concentration sigma_d / sigma_base |
| albedo_d  | 0.95    | [0, 1]    | 1    | diffuser single-scattering albedo Lambda_d, per band |
| albedo_p  | 0.9     | [0, 1]    | 1    | platelet single-scattering albedo Lambda_p, per band |
| w_g       | 1.0     | [0, 1]    | 1    | weight of HG lobe 1 of the diffusers                 |
| g1        | 0.5     | (-1, 1)   | 1    | asymmetry of HG lobe 1                               |
| g2        | -0.2    | (-1, 1)   | 1    | asymmetry of HG lobe 2                               |
| alpha     | 0.2     | (0, 1]    | 1    | platelet SGGX roughness alpha_p                      |
| theta     | 0.0     | [0, pi/2] | rad  | tilt theta_p of the mean platelet normal about x     |

The functions below take any object with these attributes (the cosmetic BSDF's ``Params``
adds a thickness and a base), with scalars or arrays that broadcast against the directions.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from ..core.frame import reflect
from ..core.model import with_bands
from ..core.params import Bands, param, params_class, Real
from ..core.vec import Vec3, dot, normalize, where
from ..microfacet import sggx
from ..phase.henyey_greenstein import direction_about, hg_value, sample_cos
from ..phase.hg_mixture import mixture_value

@params_class
class Params:
    c_d: Real = param(0.9, lo=0.0, hi=1.0, unit="1", doc="relative diffuser concentration sigma_d / sigma_base")
    albedo_d: Bands = param(0.95, lo=0.0, hi=1.0, unit="1", doc="diffuser single-scattering albedo Lambda_d",
                             bands=True)
    albedo_p: Bands = param(0.9, lo=0.0, hi=1.0, unit="1", doc="platelet single-scattering albedo Lambda_p",
                             bands=True)
    w_g: Real = param(1.0, lo=0.0, hi=1.0, unit="1", doc="weight of the diffusers' HG lobe 1")
    g1: Real = param(0.5, lo=-1.0, hi=1.0, lo_open=True, hi_open=True, unit="1", doc="asymmetry of HG lobe 1")
    g2: Real = param(-0.2, lo=-1.0, hi=1.0, lo_open=True, hi_open=True, unit="1", doc="asymmetry of HG lobe 2")
    alpha: Real = param(0.2, lo=0.0, hi=1.0, lo_open=True, unit="1", doc="platelet SGGX roughness alpha_p")
    theta: Real = param(0.0, lo=0.0, hi=math.pi / 2, unit="rad",
                          doc="tilt theta_p of the mean platelet normal about x (Padrón Table A.1: degrees)")


FIELDS = ("c_d", "albedo_d", "albedo_p", "w_g", "g1", "g2", "alpha", "theta")
BAND_FIELDS = ("albedo_d", "albedo_p")


def platelet_area(m, w: Vec3):
    """Ĉ_p(w) = sigma(w) = sqrt(alpha^2 + (1 - alpha^2)(w . w3)^2) in [alpha, 1] (Padrón Eq. 4.6, spec M14)."""
    return sggx.flake_projected_area(m.alpha, sggx.mean_normal(m.theta), w)


def extinction(m, w: Vec3):
    """sigma_t(w) / sigma_base = c_d + (1 - c_d) Ĉ_p(w), Padrón Eq. 4.5 (even in w)."""
    return m.c_d + (1.0 - m.c_d) * platelet_area(m, w)


def platelet_probability(m, w: Vec3):
    """P_p(w) = (1 - c_d) Ĉ_p(w) / sigma_t(w): the chance that a collision is with a platelet."""
    a = (1.0 - m.c_d) * platelet_area(m, w)
    return a / (m.c_d + a)


def albedo(m, w: Vec3):
    """Lambda(w), Padrón Eq. 4.7, with a trailing bands axis."""
    a = with_bands((1.0 - m.c_d) * platelet_area(m, w))
    cd = with_bands(m.c_d)
    return (jnp.asarray(m.albedo_d) * cd + jnp.asarray(m.albedo_p) * a) / (cd + a)


def diffuser_phase(m, wi: Vec3, wo: Vec3):
    """f_d(wi, wo), the two-lobe HG mixture of Padrón Eq. 4.9 [1/sr] (no bands axis)."""
    return mixture_value(m.w_g, m.g1, m.g2, dot(wi, wo))


def platelet_D(m, wi: Vec3, wo: Vec3):
    """D(wh) of the platelets' SGGX distribution at wh = normalize(wi + wo) [1/sr]."""
    return sggx.flake_D(m.alpha, sggx.mean_normal(m.theta), normalize(wi + wo))


def scattering(m, wi: Vec3, wo: Vec3):
    """Lambda(wi) f(wi -> wo) of Padrón Eqs. 4.7 x 4.8 [1/sr], bands last.

    Written as ``(Lambda_d c_d f_d + Lambda_p (1 - c_d) D(wh) / 4) / sigma_t(wi)``, which
    avoids dividing by the projected area. Multiplied by ``sigma_t(wi)`` it is symmetric in
    (wi, wo): the reciprocity of the medium, f(w -> wo) sigma_s(w) = f(wo -> w) sigma_s(wo)
    [T:710].
    """
    return scattering_coefficient(m, wi, wo) / with_bands(extinction(m, wi))


def scattering_coefficient(m, wi: Vec3, wo: Vec3):
    """sigma_s(wi) f(wi -> wo) = sigma_t(wi) Lambda(wi) f(wi -> wo) [1/sr per mfp], bands last:
    ``Lambda_d c_d f_d + Lambda_p (1 - c_d) D(wh) / 4``, symmetric in (wi, wo) (the medium's
    reciprocity, [T:710]); the kernel of a deterministic transport solver."""
    cd = with_bands(m.c_d)
    return (jnp.asarray(m.albedo_d) * cd * with_bands(diffuser_phase(m, wi, wo))
            + jnp.asarray(m.albedo_p) * (1.0 - cd) * with_bands(0.25 * platelet_D(m, wi, wo)))


def phase(m, wi: Vec3, wo: Vec3):
    """f(wi -> wo) of Padrón Eq. 4.8 [1/sr], bands last; normalised over wo for every wi."""
    return scattering(m, wi, wo) / albedo(m, wi)


def choice_weight(p, chosen):
    """Choose a branch of probability ``p`` with ``q = stop_gradient(p)``: returns ``(take,
    weight)`` given the uniform ``chosen``; ``weight = p / q`` or ``(1 - p) / (1 - q)``: 1 in
    value, the score term in its derivative (spec §6.4)."""
    q = jax.lax.stop_gradient(p)
    take = chosen < q
    # safe denominators: the branch not taken may have q = 0 or 1 (no inf/NaN in its tangent)
    w_take = p / jnp.where(q > 0, q, 1.0)
    w_skip = (1.0 - p) / jnp.where(q < 1, 1.0 - q, 1.0)
    return take, jnp.where(take, w_take, w_skip)


def collide(m, wi: Vec3, u_event, u_lobe, u1, u2):
    """Sample a scattering event of the medium at a collision (spec M15 collision kernel).

    ``wi`` = -d points back along the light's travel direction; the four uniforms pick the
    particle type, the HG lobe and the new direction. Returns ``(wo, weight)`` with
    ``E[weight h(wo)] = int Lambda(wi) f(wi -> wo) h(wo) dwo`` (weight with bands last;
    0 for a failed SGGX sample). See the module docstring for the mixture weight.
    """
    sg = jax.lax.stop_gradient
    q = sg(platelet_probability(m, wi))
    platelet = u_event < q
    # diffuser: HG lobe 1 with probability w_g, then HG inversion about d
    q_w = sg(jnp.asarray(m.w_g))
    mu, sin_t = sample_cos(jnp.where(u_lobe < q_w, m.g1, m.g2), u1)
    wo_d = direction_about(wi, mu, sin_t, 2.0 * jnp.pi * u2)
    # platelet: a visible normal of the SGGX flakes, mirror reflection (spec M14)
    S = sggx.flake_matrix(m.alpha, m.theta)
    n = sggx.sample_visible_normal(S, wi, u1, u2)
    wo_p = normalize(reflect(wi, n))
    ok = ~platelet | ((dot(wi, n) > 0) & (dot(wo_p, wo_p) > 0.5))
    wo = where(platelet & ok, wo_p, wo_d)  # a failed platelet sample keeps a valid direction
    # one-sample mixture weight: Lambda f / (q f_p + (1 - q) f_d|q_w); each lobe evaluated once
    c = dot(wi, wo)
    h1, h2 = hg_value(m.g1, c), hg_value(m.g2, c)
    d4 = 0.25 * platelet_D(m, wi, wo)  # = C(wi) f_p
    area = platelet_area(m, wi)
    pdf = q * d4 / area + (1.0 - q) * (q_w * h1 + (1.0 - q_w) * h2)
    good = ok & (pdf > 0)
    cd = with_bands(m.c_d)
    f_d = with_bands(m.w_g * h1 + (1.0 - m.w_g) * h2)
    scat = (jnp.asarray(m.albedo_d) * cd * f_d + jnp.asarray(m.albedo_p) * (1.0 - cd) * with_bands(d4)) \
        / with_bands(m.c_d + (1.0 - m.c_d) * area)  # = scattering(m, wi, wo)
    weight = scat / with_bands(jnp.where(good, pdf, 1.0))
    return wo, jnp.where(with_bands(good), weight, 0.0)
