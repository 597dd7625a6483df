"""Scattering events at a hit: the two children (reflected, transmitted) of an interface.

Directions here are **propagation** directions (the way the ray travels); ``n_out`` is the
shape's outward 3D normal (0, n_y, n_z), which lies in the section plane. Each event returns
the reflected and transmitted children with their direction, power factor per band and
(optionally) Jones field, plus validity masks. The tracer then splits or chooses.

Rough dielectrics (Huang 2022, Ch. 4; spec seed-001 §4.3 item 3): the microfacet normal is
drawn from the visible-normal distribution about the **mesonormal**
n_alpha = (sin alpha, n_y cos alpha, n_z cos alpha) (Huang Eq. 4.39; from inside the tilt sign
flips, spec seed-001 §1.3.8), the child is weighted by Smith G1 of its direction about the mesonormal, and
rays whose incoming, outgoing or microfacet directions fall on the wrong side of the macro
or meso surface are killed. Their microfacet BSDF has the meso-centred NDF but macro-frame
cosines, f = F D G1 G1 / (4 |i.n||o.n|) (the thesis's semantics: the macro area element
da_m = dphi_m ds of Huang Eq. 4.4 receives flux L |omega_i . omega_h| D, Huang Eqs. 4.5-4.7): sampled
weights therefore carry |d.n_alpha| / |d.n| (the meso area seen per macro area), which is 1
without tilt.
"""

from __future__ import annotations

import jax.numpy as jnp

from ..core import vec as V
from ..core.frame import Frame, reflect, refract
from ..core.frame import meso_normal as cuticle_normal
from ..core.vec import Vec3
from ..core.warp import square_to_cosine_hemisphere
from ..microfacet import distribution as mf
from ..optics.fresnel import fresnel_amplitudes_complex, fresnel_dielectric


def meso_normal(n_out: Vec3, tilt, from_outside):
    """Mesonormal facing the incident side (Huang Eq. 4.39; inside: negated)."""
    m = cuticle_normal(n_out.y, n_out.z, tilt)
    return V.where(from_outside, m, -m)


def _perp_s(d: Vec3, m: Vec3):
    """Unit s vector (perpendicular to the plane of incidence); the fiber axis at normal
    incidence on the facet, where the plane is undefined."""
    s = V.cross(d, m)
    n = V.norm(s)
    ok = n > 1e-12
    inv = jnp.where(ok, 1.0 / jnp.where(ok, n, 1.0), 0.0)
    # normal incidence happens only with d close to the section plane (|m.x| = sin(tilt)),
    # where x cross d is a valid perpendicular
    alt = V.normalize(V.cross(Vec3(jnp.ones_like(d.x), jnp.zeros_like(d.x), jnp.zeros_like(d.x)), d))
    return V.where(ok, s * inv, alt)


def jones(E: Vec3, d: Vec3, m: Vec3, d_r: Vec3, d_t: Vec3, r_s, r_p, t_s, t_p):
    """Apply amplitude coefficients to the complex field ``E`` (a 3-vector perpendicular to
    ``d``) with the basis s = d x m / |.|, p = s x d before and p' = s x d' after (the
    convention of :mod:`optics.fresnel`: at normal incidence r_s = -r_p and the reflected
    field is r E). Returns the reflected and transmitted fields."""
    s = _perp_s(d, m)
    p = V.cross(s, d)
    Es, Ep = V.dot(E, s), V.dot(E, p)
    pr, pt = V.cross(s, d_r), V.cross(s, d_t)
    Er = s * (r_s * Es) + pr * (r_p * Ep)
    Et = s * (t_s * Es) + pt * (t_p * Ep)
    return Er, Et


def dielectric(d: Vec3, n_out: Vec3, from_outside, eta1, eta2, itf, u1, u2, polarized, E):
    """Children of a (smooth or rough) dielectric interface; ``eta1`` is the index on the
    incident side, ``eta2`` on the other. Returns (d_r, g_r, d_t, g_t, E_r, E_t) where g are
    the power factors (Fresnel x Smith x meso area; 0 for killed children)."""
    n_f = V.where(from_outside, n_out, -n_out)          # macro normal, incident side
    n_m = meso_normal(n_out, itf.tilt, from_outside)      # mesonormal, incident side
    wi = -d
    rough = itf.rough
    if rough:
        frame = Frame.from_normal_tangent(n_m, Vec3(jnp.ones_like(d.x), jnp.zeros_like(d.x), jnp.zeros_like(d.x)))
        wl = frame.to_local(wi)
        ml = mf.sample_visible(itf.distribution, wl, itf.roughness, itf.roughness, u1, u2)
        m = frame.to_world(ml)
    else:
        m = n_m
    eta = eta2 / eta1
    cos_i = V.dot(wi, m)
    d_r = reflect(wi, m)
    d_t, ok_t = refract(wi, m, eta)
    E_r = E_t = None
    if polarized:
        r_s, r_p, t_s, t_p, cos_t = fresnel_amplitudes_complex(jnp.abs(cos_i), eta1, eta2)
        # power normalisation, so that |E|^2 is the power: T = Re(eta2 cos_t)/(eta1 cos_i) |t|^2
        ci = jnp.maximum(jnp.abs(cos_i), 1e-30)
        k = jnp.sqrt(jnp.maximum(jnp.real(eta2 * cos_t), 0.0) / (eta1 * ci))
        E_r, E_t = jones(E, d, m, d_r, d_t, r_s, r_p, t_s * k, t_p * k)
        e2 = _abs2(E)
        inv = jnp.where(e2 > 0, 1.0 / jnp.where(e2 > 0, e2, 1.0), 0.0)
        R, T = _abs2(E_r) * inv, _abs2(E_t) * inv      # polarisation-resolved powers
    else:
        R, _, _, _ = fresnel_dielectric(jnp.abs(cos_i), eta)
        T = 1.0 - R
    # meso area per macro area (1 without tilt), see the module docstring
    area = jnp.abs(V.dot(wi, n_m)) / jnp.maximum(jnp.abs(V.dot(wi, n_f)), 1e-30)
    ok_i = (V.dot(wi, n_m) > 0) & (cos_i > 0)
    ok_r = ok_i & (V.dot(d_r, n_f) > 0) & (V.dot(d_r, n_m) > 0)
    ok_t = ok_t & ok_i & (V.dot(d_t, n_f) < 0) & (V.dot(d_t, n_m) < 0)
    g_r, g_t = R * area, T * area
    if rough:
        # killed children get a harmless stand-in direction, so that G1's 0/0 at a zero
        # vector (total internal reflection) cannot leak NaN into gradients
        safe_r = V.where(ok_r, d_r, n_m)
        safe_t = V.where(ok_t, d_t, -n_m)
        g_r = g_r * mf.G1(itf.distribution, frame.to_local(safe_r), ml, itf.roughness)
        g_t = g_t * mf.G1(itf.distribution, frame.to_local(safe_t), ml, itf.roughness)
    g_r = jnp.where(ok_r, g_r, 0.0)
    g_t = jnp.where(ok_t, g_t, 0.0)
    return d_r, g_r, d_t, g_t, E_r, E_t


def film(d: Vec3, n_out: Vec3, from_outside, eta1, eta2, itf, polarized, E):
    """Smooth interface coated with a thin film: Airy R and T per band (Airy, spec M10)."""
    from ..optics.thinfilm import airy

    n_f = V.where(from_outside, n_out, -n_out)
    wi = -d
    cos_i = jnp.abs(V.dot(wi, n_f))
    d_r = reflect(wi, n_f)
    d_t, ok_t = refract(wi, n_f, eta2 / eta1)
    res = airy(cos_i[..., None], itf.wavelength_nm, itf.film_nm, eta1[..., None] if jnp.ndim(eta1) else eta1,
               itf.film_eta, eta2[..., None] if jnp.ndim(eta2) else eta2)
    g_r, g_t = res.R, jnp.where(ok_t[..., None], res.T, 0.0)
    E_r = E_t = None
    if polarized:
        raise NotImplementedError("polarized tracing through film interfaces is not implemented; "
                                  "use polarized=False")
    return d_r, g_r, d_t, g_t, E_r, E_t


def diffuse(d: Vec3, n_out: Vec3, from_outside, u1, u2):
    """Lambertian reflection into the incident side, cosine-distributed about the in-plane
    normal (so the longitudinal angle changes: light leaves the specular cone)."""
    n_f = V.where(from_outside, n_out, -n_out)
    frame = Frame.from_normal_tangent(n_f, Vec3(jnp.ones_like(d.x), jnp.zeros_like(d.x), jnp.zeros_like(d.x)))
    return frame.to_world(square_to_cosine_hemisphere(u1, u2))


def barbule(d: Vec3, n_out: Vec3, from_outside, itf, u_theta, u1, u2):
    """A rock-dove barbule's surface in the feather mode (spec seed-001 §4.3 item 8, Huang Ch. 5).

    The section's arc carries a longitudinal circular arc of half-angle theta_d = ``itf.tilt``
    (the saddle cell): the ray lands at a uniform position along it, so the normal is the in-plane
    normal tilted by theta = theta_d (2 u_theta - 1) along the axis. A hit's power factor is the
    flux that element receives per unit axis length relative to an untilted one,
    (theta_d / sin theta_d) <w_i, m> / <w_i, n> (the arc is theta_d / sin theta_d longer than its
    projection), 0 where m faces away. Children, both on the incident side:
    - reflected: the mirror direction about m, times the film's Airy R (kind ``"barbule"``; film
      ``film_nm`` of index ``film_eta`` in air at ``wavelength_nm``) or ``albedo`` (kind
      ``"saddle_mirror"``, e.g. 1: the film-free geometry);
    - "transmitted" slot = TRT (kind ``"barbule"`` only): one Lambertian bounce on the melanin
      under the film, cosine-distributed about m, times I_TRT (Huang Eq. 5.3) with the melanin
      reflectance ``albedo``.
    Children leaving into the barbule (behind the in-plane normal) and hits on an arc's inner
    side are killed (both sides of a barbule are opaque). Returns (d_r, g_r, d_t, g_t), g per band.
    """
    from ..optics.thinfilm import airy, airy_trt

    theta_d = itf.tilt
    m = cuticle_normal(n_out.y, n_out.z, theta_d * (2.0 * u_theta - 1.0))
    wi = -d
    cos_n = V.dot(wi, n_out)
    cos_m = V.dot(wi, m)
    ok = from_outside & (cos_n > 0) & (cos_m > 0)
    weight = jnp.where(ok, theta_d / jnp.sin(theta_d) * cos_m / jnp.where(ok, cos_n, 1.0), 0.0)
    cm = jnp.clip(cos_m, 0.0, 1.0)[..., None]
    d_r = reflect(wi, m)
    ok_r = ok & (V.dot(d_r, n_out) > 0)
    one = jnp.ones((), cm.dtype)
    if itf.kind == "saddle_mirror":
        g_r = jnp.where(ok_r, weight, 0.0)[..., None] * jnp.atleast_1d(itf.albedo)
        return d_r, g_r, d, jnp.zeros_like(g_r)
    g_r = jnp.where(ok_r, weight, 0.0)[..., None] * airy(cm, itf.wavelength_nm, itf.film_nm, one, itf.film_eta,
                                                          one).R
    frame = Frame.from_normal_tangent(m, Vec3(jnp.ones_like(d.x), jnp.zeros_like(d.x), jnp.zeros_like(d.x)))
    d_t = frame.to_world(square_to_cosine_hemisphere(u1, u2))
    ok_t = ok & (V.dot(d_t, n_out) > 0)
    co = jnp.clip(V.dot(d_t, m), 0.0, 1.0)[..., None]
    g_t = jnp.where(ok_t, weight, 0.0)[..., None] * airy_trt(cm, co, itf.wavelength_nm, itf.film_nm, itf.film_eta,
                                                              itf.albedo)
    return d_r, g_r, d_t, g_t


def _abs2(E: Vec3):
    return sum(jnp.real(c) ** 2 + jnp.imag(c) ** 2 for c in E)


def dielectric_eval(d: Vec3, n_out: Vec3, from_outside, eta1, eta2, itf, wl: Vec3):
    """f(omega_l -> -d) |omega_l . n| of a rough dielectric, for next-event estimation.

    ``d`` is the propagation direction of the (camera) ray arriving at the surface from the
    ``eta1`` side, ``wl`` the direction to a delta light (pointing away from the surface).
    Returns the reflection part (``wl`` on the incident side) and the transmission part. Meso-centred
    NDF, macro-frame cosines and separable Smith G1 G1 (module docstring), so eval and the
    sampled weights of :func:`dielectric` describe the same BSDF. Transmission is returned
    in power units (no eta^2 radiance scaling), like the tracer's weights. Rays that fail a
    macro or meso side test get 0.
    """
    n_f = V.where(from_outside, n_out, -n_out)
    n_m = meso_normal(n_out, itf.tilt, from_outside)
    wi = -d
    frame = Frame.from_normal_tangent(n_m, Vec3(jnp.ones_like(d.x), jnp.zeros_like(d.x), jnp.zeros_like(d.x)))
    wi_l, wl_l = frame.to_local(wi), frame.to_local(wl)
    ci_f = jnp.abs(V.dot(wi, n_f))
    refl = V.dot(wl, n_f) > 0
    # reflection half vector / generalised transmission half vector, facing the meso normal
    hr = V.normalize(wi_l + wl_l)
    ht = V.normalize(wi_l * (-eta1) - wl_l * eta2)
    ht = ht * jnp.where(ht.z < 0, -1.0, 1.0)
    hr = hr * jnp.where(hr.z < 0, -1.0, 1.0)
    m = V.where(refl, hr, ht)
    cos_im = V.dot(wi_l, m)
    cos_lm = V.dot(wl_l, m)
    den = eta1 * cos_im + eta2 * cos_lm
    ok = (V.dot(wi, n_m) > 0) & (cos_im > 0) & (m.z > 0) & (ci_f > 1e-12)
    ok_r = ok & refl & (wl_l.z > 0) & (cos_lm > 0)
    ok_t = ok & ~refl & (wl_l.z < 0) & (cos_lm < 0) & (V.dot(wl, n_f) < 0) & (jnp.abs(den) > 1e-12)
    # evaluate on benign stand-ins where the result is masked, so that reverse-mode
    # derivatives of the unused branch (0 x inf) cannot turn into NaN
    use = ok_r | ok_t
    one = jnp.ones_like(ci_f)
    m = V.where(use, m, Vec3(0.0 * one, 0.0 * one, one))
    wi_s = V.where(use, wi_l, Vec3(0.0 * one, 0.0 * one, one))
    wl_s = V.where(use, wl_l, V.where(refl, Vec3(0.0 * one, 0.0 * one, one), Vec3(0.0 * one, 0.0 * one, -one)))
    ci_f = jnp.where(use, ci_f, 1.0)
    den = jnp.where(ok_t, den, 1.0)
    cos_im, cos_lm = V.dot(wi_s, m), V.dot(wl_s, m)
    kind, a = itf.distribution, itf.roughness
    D = mf.D(kind, m, a, a)
    g = mf.G1(kind, wi_s, m, a) * mf.G1(kind, wl_s, m, a)
    F, _, _, _ = fresnel_dielectric(jnp.abs(cos_im), eta2 / eta1)
    f_r = F * D * g / (4.0 * ci_f)
    f_t = jnp.abs(cos_im * cos_lm) * eta2 * eta2 * (1.0 - F) * D * g / (ci_f * den * den)
    return jnp.where(ok_r, f_r, 0.0), jnp.where(ok_t, f_t, 0.0)
