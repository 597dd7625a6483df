"""Rock-dove neck-feather barbule BSDF (Huang 2022 Ch. 5, "elliptical BSDF").

The iridescent barbules of a rock-dove neck feather overlap like shingles into a "barb
plane". Seen along a barbule, each exposes an elliptic arc (semi-major axis 1, semi-minor b,
normal azimuths phi_m in [phi_0, phi_1]); along the barbule the surface is a circular arc of
half-angle theta_d; neighbours lie H apart along the barb plane, which is tilted by mu from
the barbule's own X axis (:mod:`~appearance_jax.bsdf.barbule_row`). The surface is a keratin
film of thickness d in air over a diffusely reflecting melanin layer. With ``<w, n>`` taken to
the barb plane's normal n (Huang Eq. 5.4, 5.13):

    S = S_R + S_TRT  (+ S_T, a delta: :func:`transmission`)
    S_R   = I_R(w_i . w_m) D(w_m) G(w_i, w_m, w_o) / (4 <w_i, n> <w_o, n>)      Huang Eq. 5.14
    D     = b^2 / (2 H sin(theta_d) cos(theta_m)) (sin^2 phi_m + b^2 cos^2 phi_m)^(-3/2)  Eq. 5.7
    S_TRT = rho / pi,   rho = (1/A_i) integral of I_TRT over the lit area            Eq. 5.16-5.17
    S_T(w_i, -w_i) = 1 - Delta h'(phi_i) / Delta h(phi_i)                            Eq. 5.15

w_m is the half vector; G is Huang's binary visibility ([T:1636]): the surface point of
normal w_m faces w_i and w_o and its rays towards both miss the neighbouring barbules
(exact, in the transverse section). I_R is the Airy reflectance of the keratin film in air
(Eq. 5.1-5.2, :func:`~appearance_jax.optics.thinfilm.airy`); I_TRT (Eq. 5.3) its
transmittance at w_i times the melanin reflectance times its transmittance at w_o
(:func:`~appearance_jax.optics.thinfilm.airy_trt`).

rho is computed deterministically (the thesis draws one random (h, l) per evaluation:
:mod:`~appearance_jax.bsdf.rock_dove_stochastic`; S_R without the film: :func:`reflection_geometry`): the
lit area seen from w_i is weighted exactly by the visible-normal measure
``D <w_i, w_m> dw_m / <w_i, n>`` (what Huang's uniform offsets h, l stand for), restricted to
points that also see w_o: ``n_phi`` smoothstep-Gauss nodes in the offset h over each interval
of the arc lit from both directions (at most ``N_RUNS`` runs of lit arc per direction) times
``n_theta`` Gauss nodes over [-theta_d, theta_d].

Conventions. Local frame: z = n (barb-plane normal), y = the barbule axis, x = across the
barbules in the barb plane. Barbule frame: X = cos(mu) x - sin(mu) z, Y = y,
Z = sin(mu) x + cos(mu) z. A reflection BSDF: 0 unless both directions are above the barb plane
(the only transmission is the delta T). A barb's underside is the same structure seen from its
other side: evaluate it with both directions turned by pi about the barbule axis
(:func:`underside`; the thesis' code mirrors the azimuth the same way).

Reciprocity: S_R is reciprocal (the thesis' claim, [T:1590]); S_TRT is not (rho is an
average over the area lit from w_i, Eq. 5.17), so the model is registered non-reciprocal.

Sampling (:func:`sample`, :func:`pdf`): the lit arc is sampled uniformly in the offset h
seen from w_i and theta_m from its exact conditional law, which together is exactly the
visible-normal density D <w_i, w_m> / (<w_i, n> Delta h'/Delta h) (Huang's Algorithm 1
samples l uniformly, an approximation); then the mirror direction (probability P_R from the
film's reflectance at w_i) or a cosine-weighted direction about n. The T delta is not part of
``sample``: :func:`transmission` gives its weight. :func:`sample_lobes` is Huang's Algorithm 1,
one estimator of the whole BSDF with the T delta (a path tracer's sampler).

| parameter           | default | range            | unit | meaning                                             |
|---------------------|---------|------------------|------|-----------------------------------------------------|
| b                   | 0.25    | (0, 1]           | 1    | semi-minor axis of the barbule's elliptic section    |
| phi0                | -0.37   | [-pi, pi]        | rad  | lowest normal azimuth of the arc                    |
| phi1                | 2.64    | [-pi, 2 pi]      | rad  | highest normal azimuth, phi0 < phi1 <= phi0 + pi    |
| H                   | 1.25    | (0, 20]          | 1    | barbule spacing along the barb plane                |
| thickness           | 590     | [0, 5000]        | nm   | keratin film thickness d                             |
| theta_d             | 0.0785  | (0, pi/2)        | rad  | half-angle of the longitudinal arc                   |
| mu                  | -0.35   | (-pi/2, pi/2)    | rad  | barbule orientation against the barb plane          |
| eta_keratin         | 1.55    | [1, 3]           | 1    | keratin index (``keratin="constant"``)              |
| melanin_reflectance | 0.0604  | [0, 1]           | 1    | diffuse melanin reflectance |r_am|^2                |
| keratin             | "constant" | constant, cauchy | -  | cauchy: n = 1.532 + 5890 / lambda^2 (the code's)   |
| color               | "rgb3"  | rgb3, cie, spectral | - | output bands (as ``iridescent``)                    |
| neighbours          | 2       | >= 1             | -    | neighbour barbules tested on each side              |
| n_phi, n_theta      | 12, 2   | >= 1             | -    | quadrature nodes of rho per arc piece / over theta_m |

Defaults are Huang's hand fit to the scatterograms ([T:1746]); ``PRESETS`` holds it and the five
ablations of App. H ([T:2291]). melanin_reflectance 0.0604 = normal-incidence Fresnel of
1.648 + 0.0632 i ([T:2286], :func:`~appearance_jax.optics.melanin.normal_reflectance`).

Example::

    from appearance_jax.bsdf import rock_dove
    from appearance_jax.core.frame import spherical_direction
    p = rock_dove.Params()
    f = rock_dove.eval(p, spherical_direction(0.3, 0.0), spherical_direction(0.4, 3.0))  # (3,) 1/sr
    t = rock_dove.transmission(p, spherical_direction(0.3, 0.0))  # fraction passing between barbules
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..core import spectral
from ..core.arrays import stacked
from ..core.model import Model, boundary, with_bands
from ..core.params import Real, integer, param, params_class, static
from ..core.quadrature import gauss_legendre, smoothstep_rule
from ..core.rng import uniforms
from ..core.special import atan2, safe_asin, safe_sqrt
from ..core import vec as V
from ..core.vec import Vec3
from ..core import warp
from ..optics.thinfilm import airy, airy_trt
from . import barbule_row as row


@params_class
class Params:
    b: Real = param(0.25, lo=0.0, hi=1.0, lo_open=True, unit="1", doc="semi-minor axis of the barbule section")
    phi0: Real = param(-0.37, lo=-math.pi, hi=math.pi, unit="rad", doc="lowest normal azimuth of the arc")
    phi1: Real = param(2.64, lo=-math.pi, hi=2 * math.pi, unit="rad", doc="highest normal azimuth of the arc")
    H: Real = param(1.25, lo=0.0, hi=20.0, lo_open=True, unit="1", doc="barbule spacing (semi-major axes)")
    thickness: Real = param(590.0, lo=0.0, hi=5000.0, unit="nm", doc="keratin film thickness d")
    theta_d: Real = param(0.025 * math.pi, lo=0.0, hi=0.5 * math.pi, lo_open=True, hi_open=True, unit="rad",
                          doc="half-angle of the longitudinal circular arc")
    mu: Real = param(-0.35, lo=-0.5 * math.pi, hi=0.5 * math.pi, lo_open=True, hi_open=True, unit="rad",
                     doc="barbule orientation against the barb plane")
    eta_keratin: Real = param(1.55, lo=1.0, hi=3.0, unit="1", doc="keratin refractive index (keratin='constant')")
    melanin_reflectance: Real = param(0.0604, lo=0.0, hi=1.0, unit="1", doc="diffuse melanin reflectance |r_am|^2")
    keratin: str = static("constant", choices=("constant", "cauchy"), doc="keratin index: constant or Cauchy law")
    color: str = static("rgb3", choices=spectral.COLOR_MODES, doc="output bands: rgb3, cie (linear sRGB), spectral")
    wavelengths: tuple = static(spectral.RGB_WAVELENGTHS, convert=spectral.wavelengths_tuple,
                                doc="wavelengths (nm) of color='spectral'")
    neighbours: int = static(2, convert=integer(1),
                             doc="neighbour barbules tested on each side")
    n_phi: int = static(12, convert=integer(1), doc="rho: nodes per arc piece")
    n_theta: int = static(2, convert=integer(1), doc="rho: nodes over theta_m")

    def _validate(self):
        p0, p1 = np.asarray(self.phi0, np.float64), np.asarray(self.phi1, np.float64)
        if np.any(p1 <= p0) or np.any(p1 - p0 > math.pi):
            raise ValueError(f"rock_dove.Params: phi0 = {self.phi0}, phi1 = {self.phi1}: need phi0 < phi1 <= "
                             "phi0 + pi (an arc wider than pi would face one direction in two pieces)")


# --------------------------------------------------------------------------------------
# Film terms
# --------------------------------------------------------------------------------------


def keratin_index(p: Params, wl):
    """eta_k per wavelength: constant, or Huang's code's Cauchy law 1.532 + 5890 / lambda^2 (nm)."""
    if p.keratin == "cauchy":
        return 1.532 + 5890.0 / (wl * wl)
    return with_bands(p.eta_keratin) * jnp.ones_like(wl)


def _bands(p: Params, values):
    out = spectral.to_bands(values, p.color, p.wavelengths, illuminant="D65")
    return jnp.maximum(out, 0.0) if p.color == "cie" else out


def film_r(p: Params, cos_b):
    """I_R (Huang Eq. 5.2) at the facet cosine ``cos_b``, over the output bands: ``cos_b.shape + (n_bands,)``."""
    wl = spectral.band_wavelengths(p.color, p.wavelengths)
    one = jnp.ones((), wl.dtype)
    r = airy(with_bands(cos_b), wl, with_bands(p.thickness), one, keratin_index(p, wl), one).R
    return _bands(p, r)


def film_trt(p: Params, cos_i, cos_o):
    """I_TRT (Huang Eq. 5.3) at facet cosines ``cos_i``, ``cos_o``, over the output bands."""
    wl = spectral.band_wavelengths(p.color, p.wavelengths)
    v = airy_trt(with_bands(cos_i), with_bands(cos_o), wl, with_bands(p.thickness), keratin_index(p, wl),
                 with_bands(p.melanin_reflectance))
    return _bands(p, v)


# --------------------------------------------------------------------------------------
# Frames and the geometry shared by eval, pdf and sample
# --------------------------------------------------------------------------------------


def underside(w: Vec3) -> Vec3:
    """``w`` turned by pi about the barbule axis, (x, y, z) -> (-x, y, -z): evaluate the underside of
    a barb (both directions below the barb plane) as this model seen from above, as Huang's
    code does (it mirrors the azimuth). The model itself is 0 below the plane (a reflection BSDF)."""
    return Vec3(-w.x, w.y, -w.z)


def to_barbule(p: Params, w: Vec3) -> Vec3:
    c, s = jnp.cos(p.mu), jnp.sin(p.mu)
    return Vec3(c * w.x - s * w.z, w.y, s * w.x + c * w.z)


def from_barbule(p: Params, w: Vec3) -> Vec3:
    c, s = jnp.cos(p.mu), jnp.sin(p.mu)
    return Vec3(c * w.x + s * w.z, w.y, -s * w.x + c * w.z)


def _transverse(w: Vec3):
    """(dx, dz, cos theta, sin theta) of a barbule-frame direction: its unit projection onto the
    transverse plane ((0, 0) along the barbule axis) and its longitudinal angle."""
    r = safe_sqrt(w.x * w.x + w.z * w.z)  # 0 (finite derivative) along the barbule axis
    ok = r > 0
    inv = jnp.where(ok, 1.0 / jnp.where(ok, r, 1.0), 0.0)
    return w.x * inv, w.z * inv, r, w.y


def ndf(p: Params, theta_m, phi_m):
    """D(w_m) of Huang Eq. 5.7 (1/sr) at longitudinal angle theta_m and normal azimuth phi_m."""
    inside = row.in_arc(phi_m, p.phi0, p.phi1) & (jnp.abs(theta_m) < p.theta_d)
    cos_t = jnp.cos(theta_m)
    d = row.radius_of_curvature(phi_m, p.b) / (2.0 * p.H * jnp.sin(p.theta_d) * jnp.where(inside, cos_t, 1.0))
    return jnp.where(inside, d, 0.0)


def _lift(p: Params, k: int = 1) -> Params:
    """``p`` with ``k`` trailing axes on every per-direction (non-scalar) leaf, to broadcast against
    quadrature nodes on trailing axes."""
    return jax.tree_util.tree_map(lambda v: jnp.reshape(v, jnp.shape(v) + (1,) * k) if jnp.ndim(v) else v, p)


def _sees(p: Params, phi_m, dx, dz):
    """The arc point of normal azimuth phi_m faces the 2D direction d and its ray along d misses the
    neighbours (p's leaves, dx and dz broadcast against phi_m)."""
    mx, mz = row.arc_point(phi_m, p.b)
    cx, cz = row.offsets(p.H, p.mu, p.neighbours)
    blocked = row.occluded(mx, mz, dx, dz, p.b, p.phi0, p.phi1, cx, cz)
    faces = (dx * jnp.sin(phi_m) + dz * jnp.cos(phi_m)) > 0
    return faces & ~blocked


def _valid_length(p: Params, dx, dz):
    """Delta h' (projected length of the lit arc seen from d) and the pieces of :func:`row.lit_pieces`."""
    bp, lit, dh = row.lit_pieces(dx, dz, p.b, p.phi0, p.phi1, p.H, p.mu, p.neighbours)
    return jnp.sum(jnp.where(lit, dh, 0.0), axis=-1), (bp, lit, dh)


def valid_fraction(p: Params, w: Vec3):
    """Delta h' / Delta h seen from the local direction ``w`` (above the barb plane)."""
    dx, dz, _, _ = _transverse(to_barbule(p, w))
    return row.valid_fraction(dx, dz, p.b, p.phi0, p.phi1, p.H, p.mu, p.neighbours)


# --------------------------------------------------------------------------------------
# Lobes
# --------------------------------------------------------------------------------------


def _s_r_geometry(p: Params, wi: Vec3, wo: Vec3, bi: Vec3, bo: Vec3):
    """S_R / I_R = D G / (4 <w_i, n> <w_o, n>) and the facet cosine; wi, wo above the barb plane
    (local), bi, bo in the barbule frame."""
    h = V.normalize(bi + bo)
    theta_m = safe_asin(h.y)
    phi_m = atan2(h.x, h.z)
    dxi, dzi, _, _ = _transverse(bi)
    dxo, dzo, _, _ = _transverse(bo)
    # both directions as one computation (core.arrays.stacked)
    g = _sees(p, phi_m, stacked(dxi, dxo, like=(p, phi_m)), stacked(dzi, dzo, like=(p, phi_m)))
    g = g[0] & g[1]
    cos_b = jnp.clip(V.dot(bi, h), 0.0, 1.0)
    d = jnp.where(g, ndf(p, theta_m, phi_m), 0.0)
    denom = 4.0 * wi.z * wo.z
    ok = denom > 0
    return jnp.where(ok, d / jnp.where(ok, denom, 1.0), 0.0), cos_b


def _s_r(p: Params, wi: Vec3, wo: Vec3, bi: Vec3, bo: Vec3):
    """S_R (Huang Eq. 5.14), bands last."""
    scale, cos_b = _s_r_geometry(p, wi, wo, bi, bo)
    return with_bands(scale) * film_r(p, cos_b)


def _reflection_geometry(p: Params, wi: Vec3, wo: Vec3):
    """S_R with I_R = 1 (1/sr, shape of ``wi.z``): the film-free mirror lobe D G / (4 <w_i, n> <w_o, n>),
    what a flatland trace of mirror-reflecting arcs measures (flatland.feather)."""
    p = _arc_within_pi(p)
    ok = (wi.z > 0) & (wo.z > 0)
    return jnp.where(ok, _s_r_geometry(p, wi, wo, to_barbule(p, wi), to_barbule(p, wo))[0], 0.0)


# maximal runs of lit arc kept per direction for rho: the lit set is the facing part of the arc
# minus the neighbours' shadows; one run at every one of 64 directions of 300 random rows
# (b, H, mu, arc ends as in the tests) and at the presets, so 2 leave a margin
N_RUNS = 2


def _both_lit(p: Params, dxi, dzi, dxo, dzo):
    """(lo, hi) (..., N_RUNS^2): the intervals of normal azimuths lit from both 2D directions."""
    dx, dz = stacked(dxi, dxo, like=p), stacked(dzi, dzo, like=p)  # both directions as one computation
    (si, so), (ei, eo) = row.lit_runs(*row.lit_pieces(dx, dz, p.b, p.phi0, p.phi1, p.H, p.mu, p.neighbours)[:2], N_RUNS)
    lo = jnp.maximum(si[..., :, None], so[..., None, :])
    hi = jnp.minimum(ei[..., :, None], eo[..., None, :])
    shape = lo.shape[:-2] + (N_RUNS * N_RUNS,)
    return lo.reshape(shape), jnp.maximum(hi, lo).reshape(shape)


def _s_trt(p: Params, wi: Vec3, wo: Vec3, bi: Vec3, bo: Vec3):
    """S_TRT = rho / pi (Huang Eq. 5.16-5.17), bands last (see the module for rho's quadrature)."""
    dxi, dzi, ci, si = _transverse(bi)
    dxo, dzo, co, so = _transverse(bo)
    lo, hi = _both_lit(p, dxi, dzi, dxo, dzo)
    # nodes uniform in the offset h seen from w_i (the measure D_phi dphi = dh / (H cos dphi) is
    # flat there; in phi, D_phi peaks like 1/b^3 at the arc's flat top), smoothstep-mapped Gauss
    # for the 1/sqrt ends at silhouettes
    g, gw = (jnp.asarray(v, lo.dtype) for v in smoothstep_rule(p.n_phi))
    e = lambda v: jnp.asarray(v)[..., None]  # noqa: E731
    ha, hb = row.projected(lo, e(dxi), e(dzi), e(p.b)), row.projected(hi, e(dxi), e(dzi), e(p.b))
    h = (ha[..., None] + (hb - ha)[..., None] * g).reshape(lo.shape[:-1] + (-1,))  # (..., K)
    wh = (jnp.abs(hb - ha)[..., None] * gw).reshape(h.shape)
    phi = row.front_point(h, e(dxi), e(dzi), e(p.b))
    phi = jnp.clip(row.wrap_near(phi, e(0.5 * (p.phi0 + p.phi1))), jnp.repeat(lo, p.n_phi, -1),
                   jnp.repeat(hi, p.n_phi, -1))
    facing = jnp.maximum(e(dxi) * jnp.sin(phi) + e(dzi) * jnp.cos(phi), 1e-12)
    wphi = wh / facing  # dh / cos(dphi) = dphi / kappa: the arc length; / H below makes it D_phi dphi
    # theta_m over the part of [-theta_d, theta_d] that faces both directions (the cut-offs of
    # <w_i, w_m> > 0 and <w_o, w_m> > 0 are ends of the rule, not kinks inside it: grazing pairs)
    ai = e(ci) * facing
    ao = e(co) * (e(dxo) * jnp.sin(phi) + e(dzo) * jnp.cos(phi))
    alpha_i, alpha_o = atan2(e(si), ai), atan2(e(so), ao)
    tlo = jnp.maximum(jnp.maximum(-e(p.theta_d), alpha_i - 0.5 * math.pi), alpha_o - 0.5 * math.pi)
    thi = jnp.maximum(jnp.minimum(jnp.minimum(e(p.theta_d), alpha_i + 0.5 * math.pi), alpha_o + 0.5 * math.pi), tlo)
    t, wt = (jnp.asarray(v, phi.dtype) for v in gauss_legendre(p.n_theta, 0.0, 1.0))
    theta = tlo[..., None] + (thi - tlo)[..., None] * t  # (..., K, T)
    wt = (thi - tlo)[..., None] * wt
    sp, cp = jnp.sin(phi)[..., None], jnp.cos(phi)[..., None]
    st, ct = jnp.sin(theta), jnp.cos(theta)
    # w_m = (sin phi cos theta, sin theta, cos phi cos theta) in the barbule frame
    cos_i = e(e(ci)) * ct * (e(e(dxi)) * sp + e(e(dzi)) * cp) + e(e(si)) * st
    cos_o = e(e(co)) * ct * (e(e(dxo)) * sp + e(e(dzo)) * cp) + e(e(so)) * st
    live = (cos_i > 0) & (cos_o > 0)
    # D dw_m = D_theta D_phi dtheta dphi; D_theta = 1 / (2 sin theta_d), H D_phi = 1 / kappa
    dens = (wphi / e(p.H))[..., None] * wt / (2.0 * jnp.sin(e(e(p.theta_d))))
    weight = jnp.where(live, dens * jnp.maximum(cos_i, 0.0), 0.0)
    itrt = film_trt(_lift(p, 2), jnp.clip(cos_i, 0.0, 1.0), jnp.clip(cos_o, 0.0, 1.0))  # (..., K, T, bands)
    # a contraction, not sum(weight * itrt): XLA:CPU fused the film into that reduction over the
    # node axes and ran it 9x slower than the film alone
    rho = jnp.einsum("...kt,...ktb->...b", weight, itrt)
    ok = wi.z > 0
    return rho * with_bands(jnp.where(ok, 1.0 / (jnp.pi * jnp.where(ok, wi.z, 1.0)), 0.0))


def _arc_within_pi(p: Params) -> Params:
    """phi1 limited to phi0 + pi inside traced code. Params() rejects a wider arc eagerly; a fit
    builds its Params from traced values, which skip that check, and the geometry assumes the arc
    faces any direction in one piece: beyond the limit the model is flat in phi1 (the fit sees a
    bound) instead of silently wrong."""
    return p.replace(phi1=jnp.minimum(p.phi1, p.phi0 + math.pi))


def _eval(p: Params, wi: Vec3, wo: Vec3):
    p = _arc_within_pi(p)
    bi, bo = to_barbule(p, wi), to_barbule(p, wo)
    f = _s_r(p, wi, wo, bi, bo) + _s_trt(p, wi, wo, bi, bo)
    ok = (wi.z > 0) & (wo.z > 0)
    return jnp.where(with_bands(ok), f, 0.0)


def _transmission(p: Params, wi: Vec3):
    """S_T (Huang Eq. 5.15): the fraction of the light from ``wi`` that passes between the barbules
    unchanged (to -wi); wavelength-independent, shape of ``wi``. Light from below the barb plane
    sees the row from its other side: ``wi`` is turned by :func:`underside` there."""
    p = _arc_within_pi(p)
    w = V.where(wi.z < 0, underside(wi), wi)
    return 1.0 - valid_fraction(p, w)


# --------------------------------------------------------------------------------------
# Sampling
# --------------------------------------------------------------------------------------


def _p_r(p: Params, w: Vec3):
    """Probability of the mirror branch: the film's mean I_R against its mean I_TRT at <w, n>."""
    c = jnp.clip(w.z, 0.0, 1.0)
    r = jnp.mean(film_r(p, c), axis=-1)
    t = jnp.mean(film_trt(p, c, c), axis=-1)
    tot = r + t
    return jnp.clip(jnp.where(tot > 0, r / jnp.where(tot > 0, tot, 1.0), 0.5), 0.1, 0.9)


def _theta_law(ci, si, dxi, dzi, phi_m, theta_d):
    """The conditional law of theta_m given phi_m, density prop. to <w_i, w_m> on the facing part of
    [-theta_d, theta_d]: (alpha, lo, hi, norm) with density cos(theta - alpha) / norm."""
    a = ci * (dxi * jnp.sin(phi_m) + dzi * jnp.cos(phi_m))
    alpha = atan2(si, a)
    lo = jnp.maximum(-theta_d, alpha - 0.5 * math.pi)
    hi = jnp.maximum(jnp.minimum(theta_d, alpha + 0.5 * math.pi), lo)
    return alpha, lo, hi, jnp.sin(hi - alpha) - jnp.sin(lo - alpha)


def _pdf_r(p: Params, bi: Vec3, bo: Vec3):
    """Solid-angle density of the mirror branch at ``bo`` (barbule frame), see the module."""
    h = V.normalize(bi + bo)
    theta_m = safe_asin(h.y)
    phi_m = atan2(h.x, h.z)
    dxi, dzi, ci, si = _transverse(bi)
    valid, _ = _valid_length(p, dxi, dzi)
    lit = row.in_arc(phi_m, p.phi0, p.phi1) & _sees(p, phi_m, dxi, dzi) & (valid > 0)
    facing = dxi * jnp.sin(phi_m) + dzi * jnp.cos(phi_m)
    p_phi = row.radius_of_curvature(phi_m, p.b) * facing / jnp.where(lit, valid, 1.0)
    alpha, lo, hi, norm = _theta_law(ci, si, dxi, dzi, phi_m, p.theta_d)
    ok = lit & (theta_m >= lo) & (theta_m <= hi) & (norm > 0)
    p_theta = jnp.cos(theta_m - alpha) / jnp.where(ok, norm, 1.0)
    jac = 4.0 * V.dot(bo, h) * jnp.cos(theta_m)
    ok = ok & (jac > 0)
    return jnp.where(ok, p_phi * p_theta / jnp.where(ok, jac, 1.0), 0.0)


def _pdf(p: Params, wi: Vec3, wo: Vec3):
    p = _arc_within_pi(p)
    ok = (wi.z > 0) & (wo.z > 0)
    pr = _p_r(p, wi)
    dens = pr * _pdf_r(p, to_barbule(p, wi), to_barbule(p, wo)) + (1.0 - pr) * jnp.maximum(wo.z, 0.0) / jnp.pi
    return jnp.where(ok, dens, 0.0)


def _sample_mirror(p: Params, bi: Vec3, uh, ut):
    """A mirror direction (barbule frame): h uniform over the lit pieces seen from w_i, theta_m from
    its conditional law; returns (w_o, valid length > 0)."""
    dxi, dzi, ci, si = _transverse(bi)
    valid, (bp, lit, dh) = _valid_length(p, dxi, dzi)
    wts = jnp.where(lit, dh, 0.0)
    cum = jnp.cumsum(wts, axis=-1)
    t = uh * valid
    j = jnp.minimum(jnp.sum(cum <= t[..., None], axis=-1), wts.shape[-1] - 1)[..., None]
    take = lambda a: jnp.take_along_axis(a, j, axis=-1)[..., 0]  # noqa: E731
    a, c, wj, cj = take(bp[..., :-1]), take(bp[..., 1:]), take(wts), take(cum)
    frac = jnp.clip(jnp.where(wj > 0, (t - (cj - wj)) / jnp.where(wj > 0, wj, 1.0), 0.5), 0.0, 1.0)
    ha, hc = row.projected(a, dxi, dzi, p.b), row.projected(c, dxi, dzi, p.b)
    phi_m = row.front_point(ha + frac * (hc - ha), dxi, dzi, p.b)
    phi_m = jnp.clip(row.wrap_near(phi_m, 0.5 * (a + c)), a, c)
    alpha, lo, hi, norm = _theta_law(ci, si, dxi, dzi, phi_m, p.theta_d)
    theta_m = alpha + safe_asin(jnp.sin(lo - alpha) + ut * norm)
    m = Vec3(jnp.sin(phi_m) * jnp.cos(theta_m), jnp.sin(theta_m), jnp.cos(phi_m) * jnp.cos(theta_m))
    return m * (2.0 * V.dot(bi, m)) - bi, valid > 0


def _sample(p: Params, wi: Vec3, u):
    p = _arc_within_pi(p)
    ul, uh, ut, u1, u2 = uniforms(u, jnp.shape(wi.z), 5)
    mirror, any_lit = _sample_mirror(p, to_barbule(p, wi), uh, ut)
    pick_r = ul < _p_r(p, wi)
    wo = V.where(pick_r, from_barbule(p, mirror), warp.square_to_cosine_hemisphere(u1, u2))
    pdf = _pdf(p, wi, wo)
    f = _eval(p, wi, wo)
    ok = (pdf > 0) & (wo.z > 0) & (wi.z > 0) & (any_lit | ~pick_r)
    weight = jnp.where(with_bands(ok), f * with_bands(wo.z / jnp.where(ok, pdf, 1.0)), 0.0)
    return wo, weight, jnp.where(ok, pdf, 0.0)


LOBES = ("R", "TRT", "T")


def _sample_lobes(p: Params, wi: Vec3, u):
    """Huang's Algorithm 1 [T:1708-1733]: one estimator of the whole BSDF, the T delta included.

    A lit surface point and its normal are drawn as in :func:`sample` (exact visible normals,
    where the thesis draws l uniformly); I_R at w_m and I_TRT at a cosine-weighted w_o^TRT about n;
    the lobe is chosen with probabilities prop. to (f I_R, f I_TRT, 1 - f), f = Delta h'/Delta h
    (the thesis' I_R, I_TRT, Delta h/Delta h' - 1 times f; band means); the sample is rejected
    (weight 0) where the point does not see w_o. Unrejected, every band's weight is
    ``value / P(lobe)``; for one band it is the thesis' sample value (I_R + I_TRT - 1) f + 1 <= 1.
    E[weight g(w_o)] = int S <w_o, n> g dw_o + S_T g(-w_i) for any g. Returns
    ``(wo, weight (..., bands), lobe)``, lobe an index into :data:`LOBES`; 0 weight below the plane.
    """
    p = _arc_within_pi(p)
    ul, uh, ut, u1, u2 = uniforms(u, jnp.shape(wi.z), 5)
    bi = to_barbule(p, wi)
    mirror_b, any_lit = _sample_mirror(p, bi, uh, ut)
    m = V.normalize(bi + mirror_b)  # the sampled normal (barbule frame)
    cos_m = jnp.clip(V.dot(bi, m), 0.0, 1.0)
    trt = warp.square_to_cosine_hemisphere(u1, u2)
    bt = to_barbule(p, trt)
    cos_t = V.dot(bt, m)
    i_r = film_r(p, cos_m)
    i_trt = jnp.where(with_bands(cos_t > 0), film_trt(p, cos_m, jnp.clip(cos_t, 0.0, 1.0)), 0.0)
    f = valid_fraction(p, wi)
    f = jnp.where(any_lit, f, 0.0)
    w_r, w_t = f * jnp.mean(i_r, -1), f * jnp.mean(i_trt, -1)
    w_d = 1.0 - f
    tot = w_r + w_t + w_d
    x = ul * tot
    lobe = jnp.where(x < w_r, 0, jnp.where(x < w_r + w_t, 1, 2))
    wo = V.where(lobe == 0, from_barbule(p, mirror_b), V.where(lobe == 1, trt, -wi))
    # the point must see w_o (R and TRT; T passes between the barbules)
    dxo, dzo, _, _ = _transverse(to_barbule(p, wo))
    phi_m = atan2(m.x, m.z)
    sees = _sees(p, phi_m, dxo, dzo) & (wo.z > 0)
    value = jnp.where(with_bands(lobe == 0), with_bands(f) * i_r,
                      jnp.where(with_bands(lobe == 1), with_bands(f) * i_trt, with_bands(w_d)))
    prob = jnp.where(lobe == 0, w_r, jnp.where(lobe == 1, w_t, w_d)) / jnp.where(tot > 0, tot, 1.0)
    ok = (wi.z > 0) & (prob > 0) & ((lobe == 2) | sees)
    weight = jnp.where(with_bands(ok), value / with_bands(jnp.where(ok, prob, 1.0)), 0.0)
    return wo, weight, lobe


eval = boundary(_eval, Params)
pdf = boundary(_pdf, Params)
sample = boundary(_sample, Params)
transmission = boundary(_transmission, Params)
sample_lobes = boundary(_sample_lobes, Params)
reflection_geometry = boundary(_reflection_geometry, Params)

# Huang's hand fit to the scatterograms [T:1746] and the five one-parameter ablations of
# App. H, Fig. H.1 [T:2291]; everything else at the defaults.
PRESETS = {
    "thesis_fit": Params(),
    "ablation_thickness_500": Params(thickness=500.0),
    "ablation_mu_-0.8": Params(mu=-0.8),
    "ablation_circular": Params(b=1.0),
    "ablation_spacing_2.5": Params(H=2.5),
    "ablation_theta_d_0.1571": Params(theta_d=0.05 * math.pi),
}

MODEL = Model(
    name="rock_dove",
    kind="bsdf",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="Rock-dove barbule BSDF: elliptic-arc NDF, exact barbule visibility, keratin film R + melanin TRT "
            "(T: transmission())",
    source="Huang 2022 Ch. 5 (Eqs. 5.1-5.17)",
    reciprocal=False,
    presets=PRESETS,
)
