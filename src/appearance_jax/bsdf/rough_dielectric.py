"""Rough dielectric interface: microfacet reflection + refraction (Walter et al. 2007).

The interface separates the outside (the side z > 0, index eta_ext) from the inside
(z < 0, index eta_int); ``eta = eta_int / eta_ext``. wi (towards the light) and wo
(towards the viewer) range over the whole sphere. Let eta_i, eta_o be the indices on the
sides of wi and wo.

Reflection (wi.z wo.z > 0), h = sign * (wi + wo) normalised into the upper hemisphere:

    f_r = F(wi.h) D(h) G2(wi, wo, h) / (4 |wi.z| |wo.z|)                      (Walter, Eq. 20)

Transmission (wi.z wo.z < 0), h = -(eta_i wi + eta_o wo) normalised into the upper
hemisphere (Walter, Eq. 16):

    f_t = |wi.h| |wo.h| / (|wi.z| |wo.z|)
          * eta_o^2 (1 - F(wi.h)) D(h) G2(wi, wo, h) / (eta_i wi.h + eta_o wo.h)^2   (Walter, Eq. 21)

F is the unpolarised dielectric Fresnel reflectance at the microfacet (1 under total
internal reflection). G2 uses the generalised chi+((w.h)(w.z)) of
:mod:`appearance_jax.microfacet.distribution`, so both directions must see the front of h
from their own side.

**Radiance transport.** f_t is the BSDF for *radiance* (light at wi, viewer at wo). Its
eta_o^2 / (eta_i wi.h + eta_o wo.h)^2 is the Jacobian d omega_h / d omega_o of the
refracted half vector (Walter, Eq. 17), so the flux balance over the outgoing directions
holds, int f |wo.z| d wo <= 1 (F reflected + (1 - F) transmitted for a smooth interface),
while integrating over the incident directions gives the radiance gain of refraction,
(eta_o / eta_i)^2 (1 - F):
radiance entering the denser medium is concentrated into a smaller solid angle
(Veach 1997, Sec. 5.2). f_t is therefore not symmetric; it obeys the generalised
reciprocity f_t(wi -> wo) / eta_o^2 = f_t(wo -> wi) / eta_i^2, and the model is registered
with ``reciprocal=False``. Reflection is reciprocal. The adjoint BSDF for importance
transport (light tracing) is f_t(wo -> wi) = f_t(wi -> wo) (eta_i / eta_o)^2.

Sampling: a visible normal m of wi (of -wi when wi is inside), then reflection with
probability F(wi.m), refraction otherwise (Walter et al. 2007, Sec. 5, with visible normals
instead of D(m) m.z, Heitz 2014).
pdf = pdf_visible(wi, h) * [F / (4 |wo.h|)] for reflection and
pdf_visible(wi, h) * [(1 - F) eta_o^2 |wo.h| / (eta_i wi.h + eta_o wo.h)^2] for
transmission (Walter, Eq. 14 and 17); weight = f |wo.z| / pdf = G2 / G1(wi) in both cases.
``sample(params, wi, u_or_key)`` takes a PRNG key or 3 uniform arrays (2 for the visible
normal, 1 for the reflection/refraction choice).

| parameter    | default       | range                | unit | meaning                                  |
|--------------|---------------|----------------------|------|------------------------------------------|
| alpha        | 0.1           | [1e-3, 2]            | 1    | roughness along x (u); isotropic if alone |
| alpha_v      | None (=alpha) | [1e-3, 2]            | 1    | roughness along y (v), anisotropic       |
| eta          | 1.5           | [0.2, 5], |eta-1|>=1e-3 | 1  | relative index eta_int / eta_ext        |
| distribution | "ggx"         | ggx, beckmann        | -    | microfacet normal distribution           |
| shadowing    | "correlated"  | correlated, separable | -   | Smith G2 form (transmission: Beta form)  |

Range of eta: 0.2 - 5 covers every optical interface (air/germanium 4.0 in the infrared,
diamond/air 1/2.42, eta < 1 being an interface seen from its denser side, e.g. an air
bubble in water). At eta = 1 the interface is invisible: transmission becomes a delta
(h is undefined for wo = -wi), so |eta - 1| < 1e-3 is rejected; use no interface instead.
Output: one band (eta is not spectral here: a dispersive interface would need one sampled
direction per wavelength).

Support: a refraction pair needs h.z > 0 for the generalised half vector, i.e.
eta_i wi.z + eta_o wo.z of the sign of wi.z. At that boundary h is horizontal, where GGX
still has D = 1 / (pi ax ay (cos^2 phi / ax^2 + sin^2 phi / ay^2)^2) > 0 (alpha^2 / pi
isotropic: its heavy tail), so
for GGX the transmitted lobe (and its pdf) ends with a jump there; Beckmann's D -> 0 makes
it continuous. Quadratures over wo should not assume smoothness across that curve (it
lies close to the horizon on the far side, e.g. wo.z = -wi.z / eta from outside).

Differences from Mitsuba 3's ``roughdielectric``: Mitsuba's default distribution is
``beckmann`` and its Smith G is separable (``shadowing="separable"`` here); its Beckmann G1 is
Walter's rational approximation; its ``eval(si.wi, wo)`` returns f |cos theta_o| and its
``si.wi`` is the direction the path came from: with ``TransportMode.Importance`` and
``si.wi = wi`` it equals our ``f(wi, wo) |wo.z|``; with ``TransportMode.Radiance`` the roles
swap (``si.wi`` = our wo, Mitsuba's ``wo`` = our wi) and it equals ``f(wi, wo) |wi.z|``.
"""

from __future__ import annotations

import jax.numpy as jnp

from ..core.model import Model, boundary, with_bands
from ..core.params import param, params_class, Real, static
from ..core.rng import uniforms
from ..core.vec import Vec3, dot, normalize
from ..microfacet import cook_torrance as ct
from ..microfacet import distribution as md
from ..optics.fresnel import fresnel_dielectric, fresnel_dielectric_terms


@params_class
class Params:
    alpha: Real = param(0.1, lo=1e-3, hi=2.0, unit="1", doc="microfacet roughness (RMS slope) along x / u")
    alpha_v: Real | None = param(None, lo=1e-3, hi=2.0, unit="1", doc="roughness along y / v (None: isotropic)")
    eta: Real = param(1.5, lo=0.2, hi=5.0, unit="1", doc="relative index eta_int / eta_ext, |eta - 1| >= 1e-3")
    distribution: str = static("ggx", choices=md.KINDS, doc="microfacet normal distribution")
    shadowing: str = static("correlated", choices=("correlated", "separable"), doc="Smith G2 form")

    def _validate(self):
        import numpy as np

        e = np.atleast_1d(np.asarray(self.eta, dtype=float))
        close = np.abs(e - 1.0) < 1e-3
        if np.any(close):
            raise ValueError(
                f"Params.eta = {e[close][0]:g} is too close to 1 (|eta - 1| must be >= 1e-3): an index-matched "
                "interface has a delta transmission lobe"
            )


def _geometry(p: Params, wi: Vec3, wo: Vec3):
    """Half vector (upper hemisphere), transmission flag, eta_i, eta_o, and validity."""
    eta = jnp.asarray(p.eta)
    transmit = wi.z * wo.z < 0
    eta_i = jnp.where(wi.z < 0, eta, 1.0)
    eta_o = jnp.where(wo.z < 0, eta, 1.0)
    # reflection: wi + wo; transmission: -(eta_i wi + eta_o wo) (the sign is fixed below);
    # eta_o / eta_i selected from eta and 1/eta (scalars): no division per element
    scale = jnp.where(transmit, jnp.where(wo.z < 0, eta, 1.0 / eta), 1.0)
    h = normalize(wi + wo * scale)
    h = h * jnp.where(h.z < 0, -1.0, 1.0)
    valid = (wi.z != 0) & (wo.z != 0) & (h.z > 0)
    return h, transmit, eta_i, eta_o, valid


def _eval(p: Params, wi: Vec3, wo: Vec3):
    # f_r and f_t (module docstring) as one quotient num / den: F, 1 - F, D and G2 / |zi zo| are
    # each a fraction (fresnel_dielectric_terms, md.D_terms, md.G2_terms) whose denominators are
    # multiplied into one division per element (issue 20: 19 divisions before, and XLA:CPU
    # stores a quotient read by several operations, which split the kernel in 10)
    ax, ay = ct.alphas(p)
    kind = p.distribution
    eta = jnp.asarray(p.eta)
    h, transmit, eta_i, eta_o, valid = _geometry(p, wi, wo)
    ci, co = dot(wi, h), dot(wo, h)
    # Fresnel from wi's side: eta_t / eta_i is eta outside, 1 / eta inside
    r, t, d = fresnel_dielectric_terms(jnp.abs(ci), jnp.where(wi.z < 0, 1.0 / eta, eta))
    d_num, d_den = md.D_terms(kind, h, ax, ay)
    g_num, g_den = md.G2_terms(kind, wi, wo, h, ax, ay, correlated=p.shadowing == "correlated")
    #   f_r = (r/d) D G2 / (4 |zi zo|),  f_t = |ci co| eta_o^2 (t/d) D G2 / (|zi zo| den^2)
    den = eta_i * ci + eta_o * co  # >= |eta - 1| |h| > 0 for a refraction pair
    num = d_num * g_num * jnp.where(transmit, jnp.abs(ci * co) * eta_o * eta_o * t, r)
    q = d * d_den * g_den * jnp.where(transmit, den * den, 4.0)
    ok = valid & (q > 0)
    # safe-where: the masked branch divides by 1, so gradients stay finite at grazing
    return with_bands(jnp.where(ok, num / jnp.where(ok, q, 1.0), 0.0))


def _pdf_geom(p: Params, wi: Vec3, wo: Vec3, h, transmit, eta_i, eta_o, ok):
    ax, ay = ct.alphas(p)
    kind = p.distribution
    ci, co = dot(wi, h), dot(wo, h)
    F = fresnel_dielectric(ci, p.eta)[0]
    pv = md.pdf_visible(kind, wi, h, ax, ay)
    # chi for wo: it must see the front of h from its own side (as in G2)
    ok = ok & (co * wo.z > 0) & (pv > 0)
    aco = jnp.where(ok, jnp.abs(co), 1.0)
    pdf_r = F / (4.0 * aco)
    den = eta_i * ci + eta_o * co
    den2 = jnp.where(ok & transmit, den * den, 1.0)
    pdf_t = (1.0 - F) * eta_o * eta_o * aco / den2
    return jnp.where(ok, pv * jnp.where(transmit, pdf_t, pdf_r), 0.0)


def _pdf(p: Params, wi: Vec3, wo: Vec3):
    h, transmit, eta_i, eta_o, valid = _geometry(p, wi, wo)
    return _pdf_geom(p, wi, wo, h, transmit, eta_i, eta_o, valid)


def _sample(p: Params, wi: Vec3, u):
    ax, ay = ct.alphas(p)
    kind = p.distribution
    eta = jnp.asarray(p.eta)
    shape = jnp.broadcast_shapes(jnp.shape(wi.z), jnp.shape(ax), jnp.shape(ay), jnp.shape(eta))
    u1, u2, u3 = uniforms(u, shape, 3)
    m = md.sample_visible(kind, wi, ax, ay, u1, u2)
    ci = dot(wi, m)
    F, cos_t, _, eta_ti = fresnel_dielectric(ci, eta)
    reflect = u3 < F
    # refraction about m (Snell, vector form): tangential part scaled by eta_ti, normal
    # part the signed cos_t (opposite sign to ci); under TIR F = 1 so this is unused
    wt = m * (ci * eta_ti + cos_t) - wi * eta_ti
    wr = m * (2.0 * ci) - wi
    wo = Vec3(*(jnp.where(reflect, a, b) for a, b in zip(wr, wt)))
    # the sampled lobe must land on its side: reflection same side, refraction opposite
    side_ok = jnp.where(reflect, wi.z * wo.z > 0, wi.z * wo.z < 0)
    ok = side_ok & (wi.z != 0) & (m.z > 0) & (ci * wi.z > 0)
    eta_i = jnp.where(wi.z < 0, eta, 1.0)
    eta_o = jnp.where(wo.z < 0, eta, 1.0)
    pdf = _pdf_geom(p, wi, wo, m, ~reflect, eta_i, eta_o, ok)
    ok = ok & (pdf > 0)
    # weight = f |wo.z| / pdf = G2 / G1(wi) (the Fresnel choice and D cancel), 1/G1 = mu/|wi.z|
    G = md.G2(kind, wi, wo, m, ax, ay, correlated=p.shadowing == "correlated")
    mu = md.projected_area(kind, wi, ax, ay)
    azi = jnp.where(ok, jnp.abs(wi.z), 1.0)
    w = jnp.where(ok, G * mu / azi, 0.0)
    pdf = jnp.where(ok, pdf, 0.0)
    return wo, with_bands(w), pdf


eval = boundary(_eval, Params)
pdf = boundary(_pdf, Params)
sample = boundary(_sample, Params)

MODEL = Model(
    name="rough_dielectric",
    kind="bsdf",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="rough dielectric interface, microfacet reflection + refraction (radiance BSDF)",
    source="Walter et al. 2007; Heitz 2014, 2018",
    reciprocal=False,
    transmissive=True,
    presets={
        "glass": Params(),
        "frosted_glass": Params(alpha=0.3),
        "water": Params(eta=1.333),
    },
)
