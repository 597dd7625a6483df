"""Huang's microfacet hair BCSDF (Huang 2022, Ch. 4): lobes R, TT, TRT of a rough dielectric
(circular or elliptical) cylinder with a Smith microsurface (GGX or Beckmann), cuticle tilt
and a homogeneous absorbing interior.

Geometry and conventions (:mod:`appearance_jax.bcsdf.fiber`, which also holds the ellipse
geometry used here): x = fiber tangent (root -> tip), theta with sin theta = w.x,
phi = atan2(w.z, w.y); both directions point away from the fiber. This is Huang's frame after
the relabelling x_H -> z, y_H -> x, z_H -> y. The cross-section is the ellipse
y^2 / b^2 + z^2 = 1, b = sqrt(1 - e^2), points (b cos g, sin g) (Huang's gamma), outward
macronormal n(g) at azimuth phi_m = atan2(b sin g, cos g), arc length
dl = sqrt(1 - e^2 sin^2 g) dg (Huang Eq. 4.26), projected half width
D(phi) = sqrt(1 - e^2 sin^2 phi) (Huang Eq. 4.27). The tilted mesonormal is
m_alpha = (sin alpha, cos alpha n_y, cos alpha n_z) (Huang Eq. 4.39); alpha > 0 tilts it towards
the tip, so the R lobe moves to theta_o ~ 2 alpha - theta_i (real cuticles: alpha ~ -2 .. -4 deg).
Lengths and sigma_a are per unit (semi-major) radius.

Semantics (Huang Eqs. 4.4-4.7): the microfacet normal distribution D is centred on the
mesonormal and normalised over the macro area element dl ds; Smith G1 is taken about the
mesonormal (separable); every direction must also lie on the correct side of the untilted
macronormal (hard visibility); BSDF denominators carry macro cosines; the projected width a_o
is untilted. This is also what :func:`appearance_jax.flatland.fiber` traces (the decision and
its consequences: ``docs/hair.md``).

- R (Huang Eqs. 4.12, 4.28): S_R = F(|w_i.h|) / (8 D_o cos th_o cos th_i) int D(h; m_alpha)
  G1(i) G1(o) dl over the entry points that see both directions; composite Simpson in gamma with
  a static number of sub-intervals mapped to the visible interval (differentiable end points).
  Option ``r_mode="analytic"``: the closed-form GGX integral without G (Huang App. E, Huang Eq. E.3;
  circles).
- TT, TRT (Huang Eqs. 4.29-4.32, the combined Monte Carlo-Simpson estimator of Huang Sec. 4.4):
  Simpson over the entry point, at every node ``n_paths`` internal paths: the first microfacet
  (and, for TRT, the internal one) drawn from the visible-normal distribution, the chord to the
  next interface by exact line-ellipse intersection, absorption exp(-sigma_a * 3D chord length)
  (Huang Eq. 4.17 in its corrected, explicit form), and a deterministic connection to omega_o
  through the rough transmission BSDF at the exit (generalised half vector, Huang Eq. 4.21).
  Written as a flux integral over the entry arc length,

    S_p cos th_i = 1 / (2 D_o cos th_o) int dl |w_i . m_alpha1| E[T_1 G1(t) A ... p_exit(w_o)],

  which is Huang Eqs. 4.29-4.32 after the change of variables of Huang Sec. 4.3
  (|t.n_1| dl_1 = |t.n_2| dl_2). The exit cosine is the macro cosine |t . n_2| (``docs/hair.md``).

``eval`` is a Monte Carlo estimator (``Model.stochastic``): it returns ``(S, stderr)`` with a
fixed default key (common random numbers: a deterministic, differentiable function of
parameters and directions, the same uniforms for every direction pair).

| parameter     | default              | range      | unit     | meaning                                         |
|---------------|----------------------|------------|----------|-------------------------------------------------|
| roughness     | 0.15                 | (0, 1]     | 1        | GGX / Beckmann roughness beta of the cuticle    |
| tilt          | -0.0524 (-3 deg)     | [-0.3, 0.3]| rad      | cuticle scale tilt alpha (+ towards the tip)    |
| eta           | 1.55                 | (1, 3]     | 1        | relative index keratin / air (1.548 in thesis)  |
| sigma_a       | (0.309,0.467,0.891)  | [0, inf)   | 1/radius | absorption per band (brown: melanin 0.6/0.6)    |
| eccentricity  | 0                    | [0, 0.99]  | 1        | e = sqrt(1 - b^2) of the elliptical section     |
| distribution  | "ggx"                | ggx/beckmann | -      | microfacet distribution                         |
| r_mode        | "numeric"            | numeric/analytic | -  | R lobe: Simpson with G, or GGX closed form (no G) |
| n_intervals   | 64                   | even >= 2  | -        | Simpson sub-intervals (step ~0.7 beta: beta >= 0.05) |
| n_paths       | 4                    | >= 1       | -        | internal paths per Simpson node (TT, TRT)       |
| n_lobes       | 3                    | 3, 4       | -        | R, TT, TRT; 4 adds TRRT (Huang Sec. 4.5)        |

Sampling (Huang Sec. 4.3.4, spec seed-001 §1.3.11; kernels in
:mod:`appearance_jax.bcsdf.huang_sampling`): ``sample(params, wi, key_or_uniforms,
with_pdf=True)`` draws h uniformly over the projected width, visible normals at every interface,
and the lobe with probability proportional to the luminance of Huang's attenuations A_p; the
weight is unbiased for S cos(theta_o) (E[weight; wo in dw] = S cos dw, circles and ellipses, any
tilt) but is not S cos / pdf pointwise. ``pdf(params, wi, wo, key=None) -> (estimate, stderr)``
is the stochastic Huang Eq. 4.33 (Monte Carlo-Simpson, the same ``n_intervals`` / ``n_paths``);
``sample`` returns it at the sampled direction (``with_pdf=False``: ``None``, much cheaper).

Example::

    from appearance_jax.bcsdf import huang
    from appearance_jax.core.frame import fiber_direction
    p = huang.Params.from_melanin(0.6, 0.6, roughness=0.12, tilt=-0.05)
    wi, wo = fiber_direction(0.3, 0.0), fiber_direction(-0.4, 2.5)
    S, se = huang.eval(p, wi, wo)                       # (3,) in 1/sr, and its standard error
    lobes, lobes_se = huang.eval_lobes(p, wi, wo)       # (3 lobes R/TT/TRT, 3 bands)
    wo_s, weight, pdf = huang.sample(p, wi, jax.random.PRNGKey(1))
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from ..core import vec as V
from ..core.frame import fiber_angles, reflect, refract
from ..core.fusion import materialize
from ..core.model import Model, as_bands, boundary
from ..core.params import Bands, integer, param, params_class, Real, static, validate
from ..core.quadrature import simpson, simpson_mc
from ..core.rng import is_prng_key, uniforms
from ..core.vec import as_directions, Vec3
from ..microfacet import distribution as mf
from ..optics.fresnel import fresnel_dielectric
from .fiber import (RGB_WAVELENGTHS_NM, arc_element, ellipse_chord, ellipse_normal, ellipse_point, half_width,
                    intersect_intervals, melanin_sigma_a_spectral, meso_frame, meso_normal, minor_axis,
                    to_gamma, to_phi, visible_gamma_interval, wrap_pi)  # to_gamma, to_phi: huang's public names
from .huang_sampling import _TINY, _default_key, _ex, _finite, _pdf, _sample, _sample_path_jit


def _even(v):
    n = integer(2)(v)
    if n % 2:
        raise ValueError("must be even (composite Simpson)")
    return n


@params_class
class Params:
    roughness: Real = param(0.15, lo=0.0, hi=1.0, lo_open=True, unit="1",
                              doc="microfacet roughness beta of the cuticle (GGX/Beckmann)")
    tilt: Real = param(-0.05236, lo=-0.3, hi=0.3, unit="rad",
                         doc="cuticle scale tilt alpha (Huang Eq. 4.39); > 0 tilts towards the tip")
    eta: Real = param(1.55, lo=1.0, hi=3.0, lo_open=True, unit="1", doc="relative index of refraction")
    sigma_a: Bands = param((0.309, 0.467, 0.891), lo=0.0, unit="1/radius", bands=True,
                            doc="absorption coefficient per unit radius per band")
    eccentricity: Real = param(0.0, lo=0.0, hi=0.99, unit="1",
                                 doc="eccentricity e = sqrt(1 - b^2) of the cross-section")
    distribution: str = static("ggx", choices=("ggx", "beckmann"), doc="microfacet distribution")
    r_mode: str = static("numeric", choices=("numeric", "analytic"),
                         doc="R lobe: Simpson with Smith G, or closed-form GGX without G (App. E)")
    n_intervals: int = static(64, doc="Simpson sub-intervals over the visible azimuths", convert=_even)
    n_paths: int = static(4, doc="internal paths per Simpson node (TT, TRT)", convert=integer(1))
    n_lobes: int = static(3, doc="lobes: 3 = R, TT, TRT; 4 adds TRRT (Huang Sec. 4.5)", convert=integer(3, 4))

    def _validate(self):
        if self.r_mode == "analytic":
            if self.distribution != "ggx":
                raise ValueError("huang.Params: r_mode='analytic' needs distribution='ggx' (App. E)")
            if float(jnp.max(jnp.asarray(self.eccentricity))) != 0.0:
                raise ValueError("huang.Params: r_mode='analytic' is the circular closed form (e = 0)")

    @classmethod
    def from_melanin(cls, eumelanin, pheomelanin, wavelength_nm=RGB_WAVELENGTHS_NM, **kw):
        """sigma_a from melanin concentrations with Huang's code constants (spec seed-001 §1.3.13;
        :func:`fiber.melanin_sigma_a_spectral`)."""
        return cls(sigma_a=melanin_sigma_a_spectral(eumelanin, pheomelanin, wavelength_nm), **kw)


# ----------------------------------------------------------------------------------
# interface events (mesonormal-centred microfacets, macro hard visibility)


def _exit_pdf(kind, beta, eta, w: Vec3, o: Vec3, n_in: Vec3, m_in: Vec3):
    """Flux density per sr of o leaving through a rough interface from inside:
    f_t(w -> o) |o.n| with f_t = |w.h||o.h| (1 - F) D G1(w) G1(o) / (|w.n||o.n| |eta w + o|^2)
    (Walter et al. 2007 with macro cosines; Huang Eq. 4.21's Jacobian: |eta w + o|^2 = eta^2 |h2|^2).
    ``w`` points back into the fiber (= -travel), ``n_in``/``m_in`` face the inside."""
    fr = meso_frame(m_in)
    wl, ol = fr.to_local(w), fr.to_local(o)
    H = wl * (-eta) - ol
    h = V.normalize(H)
    h = h * jnp.where(h.z < 0, -1.0, 1.0)
    cw, co = V.dot(wl, h), V.dot(ol, h)
    den2 = V.dot(H, H)
    cwn = jnp.abs(V.dot(w, n_in))
    ok = ((wl.z > 0) & (cw > 0) & (h.z > 0) & (cwn > _TINY) & (V.dot(o, n_in) < 0) & (ol.z < 0)
          & (co < 0) & (den2 > _TINY))
    one = jnp.ones_like(cw)
    z = Vec3(0.0 * one, 0.0 * one, one)
    h = V.where(ok, h, z)
    wl = V.where(ok, wl, z)
    ol = V.where(ok, ol, -z)
    cw, co = V.dot(wl, h), V.dot(ol, h)
    den2 = jnp.where(ok, den2, 1.0)
    cwn = jnp.where(ok, cwn, 1.0)
    F, _, _, _ = fresnel_dielectric(jnp.abs(cw), 1.0 / eta)
    D = mf.D(kind, h, beta)
    g = mf.G1(kind, wl, h, beta) * mf.G1(kind, ol, h, beta)
    val = jnp.abs(cw * co) * (1.0 - F) * D * g / (cwn * den2)
    return jnp.where(ok, val, 0.0)


# ----------------------------------------------------------------------------------
# R lobe


def _r_integrand(kind, beta, alpha, eta, b, wi, wo, g, smith=True):
    py, pz = ellipse_point(g, b)
    ny, nz = ellipse_normal(py, pz, b)
    n = Vec3(jnp.zeros_like(ny), ny, nz)
    m = meso_normal(ny, nz, alpha)
    fr = meso_frame(m)
    il, ol = fr.to_local(wi), fr.to_local(wo)
    h = V.normalize(il + ol)
    # the macro visibility is enforced by the integration interval itself: testing it again
    # here would make the end nodes (exactly on the macro horizon) depend on rounding
    ok = (il.z > 0) & (ol.z > 0) & (h.z > 0)
    one = jnp.ones_like(h.z)
    h = V.where(ok, h, Vec3(0.0 * one, 0.0 * one, one))
    val = mf.D(kind, h, beta)
    if smith:
        val = val * mf.G1(kind, il, h, beta) * mf.G1(kind, ol, h, beta)
    arc = arc_element(g, b)
    return jnp.where(ok, val, 0.0) * arc


def _ggx_azimuthal_antiderivative(A, B, beta, u):
    """Huang Eq. E.3 (Huang 2022, App. E): an antiderivative in phi_m (u = phi_h - phi_m) of the GGX
    D(omega_h, omega_m_alpha), with A = cos th_h cos alpha sqrt(1 - b^2), B = sin th_h sin alpha
    sqrt(1 - b^2). Valid for |u| < pi."""
    t = jnp.tan(0.5 * u)
    qm = (B - 1.0) ** 2 - A * A
    qp = (B + 1.0) ** 2 - A * A
    c = A * jnp.cos(u)
    s = A * jnp.sin(u)
    val = (2.0 * (A * A - B * B + 3.0 * B - 2.0) / qm ** 1.5 * jnp.arctan((A - B + 1.0) * t / jnp.sqrt(qm))
           + 2.0 * (A * A - B * B - 3.0 * B - 2.0) / qp ** 1.5 * jnp.arctan((B - A + 1.0) * t / jnp.sqrt(qp))
           + s / (qm * (c + B - 1.0)) + s / (qp * (c + B + 1.0)))
    return beta * beta / (4.0 * jnp.pi) * val


def ggx_azimuthal_antiderivative_e4(A, beta, u):
    """Huang Eq. E.4 (alpha = 0), valid for |u| < pi/2 (for tests of E.3)."""
    q = 1.0 - A * A
    return beta * beta / (2.0 * jnp.pi) * ((A * A - 2.0) / q ** 1.5 * jnp.arctan(jnp.tan(u) / jnp.sqrt(q))
                                           + A * A * jnp.sin(2 * u) / (q * (A * A * jnp.cos(2 * u) + A * A - 2.0)))


def _r_lobe(p: Params, wi: Vec3, wo: Vec3, fresnel=True, smith=True):
    """S_R cos(theta_i) (no bands axis), Huang Eqs. 4.12 / 4.28 / E.3.

    Private switches (static; for the "mirror furnace" check H-3 of spec seed-001 §3.3 only):
    ``fresnel=False`` sets F = 1, ``smith=False`` drops G1 G1 (the hard macro/meso visibility
    stays). ``r_mode="analytic"`` never has G."""
    kind, beta, alpha, eta = p.distribution, p.roughness, p.tilt, p.eta
    b = minor_axis(p.eccentricity)
    thi, phii = fiber_angles(wi)
    tho, pho = fiber_angles(wo)
    lo1, hi1 = visible_gamma_interval(thi, phii, alpha, b)
    lo2, hi2 = visible_gamma_interval(tho, pho, alpha, b)
    lo, hi = materialize(intersect_intervals(lo1, hi1, lo2, hi2))
    h = V.normalize(wi + wo)
    F, _, _, _ = fresnel_dielectric(jnp.clip(V.dot(wi, h), 0.0, 1.0), eta)
    if not fresnel:
        F = jnp.ones_like(F)
    cos_o = jnp.maximum(jnp.cos(tho), _TINY)
    Do = half_width(p.eccentricity, pho)
    if p.r_mode == "analytic":
        thh, phh = fiber_angles(h)
        k = jnp.sqrt(1.0 - beta * beta)
        A = jnp.cos(thh) * jnp.cos(alpha) * k
        B = jnp.sin(thh) * jnp.sin(alpha) * k
        mid = 0.5 * (lo + hi)
        uc = wrap_pi(phh - mid)
        u_lo = uc + (mid - lo)     # u at phi_m = lo
        u_hi = uc - (hi - mid)     # u at phi_m = hi
        integral = (_ggx_azimuthal_antiderivative(A, B, beta, u_hi)
                    - _ggx_azimuthal_antiderivative(A, B, beta, u_lo))
        integral = jnp.where(hi > lo, integral, 0.0)
    else:
        t, w = simpson(p.n_intervals)
        g = lo[..., None] + t * (hi - lo)[..., None]
        # one flat axis (directions x nodes): faster to compile, see _internal
        shape = jnp.broadcast_shapes(g.shape, *(jnp.shape(c) + (1,) for c in (*wi, *wo)))
        flat = lambda v: jnp.broadcast_to(v, shape).reshape(-1)  # noqa: E731
        fv = lambda v: Vec3(*(flat(c[..., None]) for c in (v.x, v.y, v.z)))  # noqa: E731
        f = _r_integrand(kind, beta, alpha, eta, b, fv(wi), fv(wo), flat(g), smith).reshape(shape)
        integral = (hi - lo) * jnp.sum(w * f, axis=-1)
    return F * integral / (8.0 * cos_o * Do)


# ----------------------------------------------------------------------------------
# TT and TRT: combined Monte Carlo-Simpson estimator


def _internal_terms(p: Params, wi: Vec3, wo: Vec3, g, us):
    """Per-node, per-path contributions (without Simpson weights) to S_p cos th_i times
    2 D_o cos th_o for the transmitted lobes p = 1 .. n_lobes - 1 (TT, TRT[, TRRT]), entry
    parameter g; ``us`` = uniforms, two per sampled microfacet (entry, then every internal
    reflection). Shapes broadcast; each result carries a trailing bands axis."""
    kind, beta, alpha, eta = p.distribution, p.roughness, p.tilt, p.eta
    b = minor_axis(p.eccentricity)
    sig = as_bands(p.sigma_a)
    one = jnp.ones_like(g * us[0])
    z = Vec3(0.0 * one, 0.0 * one, one)
    # interface 1 (entry)
    py, pz = ellipse_point(g, b)
    ny, nz = ellipse_normal(py, pz, b)
    n1 = Vec3(0.0 * ny, ny, nz)
    m1 = meso_normal(ny, nz, alpha)
    fr1 = meso_frame(m1)
    il = materialize(fr1.to_local(wi))
    ok = il.z > 0      # macro visibility of w_i: the integration interval
    il = V.where(ok, il, z)
    h1 = materialize(mf.sample_visible(kind, il, beta, beta, us[0], us[1]))
    ci1 = V.dot(il, h1)
    tl, ok_t = refract(il, h1, eta)
    ok = ok & ok_t & (ci1 > 0) & (tl.z < 0)
    tl = V.where(ok, tl, -z)
    d = materialize(fr1.to_world(tl))
    ok = ok & (V.dot(d, n1) < 0)
    F1, _, _, _ = fresnel_dielectric(jnp.abs(ci1), eta)
    w = il.z * (1.0 - F1) * mf.G1(kind, tl, h1, beta)          # |i.m1| T1 G1(t)
    w = jnp.where(ok, w, 0.0)
    A = 1.0
    qy, qz = py, pz
    out = []
    for k in range(1, p.n_lobes):
        # chord to interface k + 1, absorption (Huang Eq. 4.17), exit connection to w_o (Huang Eq. 4.21)
        s = ellipse_chord(qy, qz, d, b)
        qy, qz = qy + s * d.y, qz + s * d.z
        my, mz = materialize(ellipse_normal(qy, qz, b))
        n_in = Vec3(0.0 * my, -my, -mz)
        m_in = -meso_normal(my, mz, alpha)
        A = A * jnp.exp(-sig * s[..., None])
        out.append((w * _exit_pdf(kind, beta, eta, -d, wo, n_in, m_in))[..., None] * A)
        if k == p.n_lobes - 1:
            break
        # internal reflection at interface k + 1 (visible-normal sampling)
        fr = meso_frame(m_in)
        wl = materialize(fr.to_local(-d))
        cwn = V.dot(-d, n_in)
        ok = ok & (wl.z > 0) & (cwn > _TINY)
        wl = V.where(ok, wl, z)
        h = materialize(mf.sample_visible(kind, wl, beta, beta, us[2 * k], us[2 * k + 1]))
        ci = V.dot(wl, h)
        rl = reflect(wl, h)
        ok = ok & (ci > 0) & (rl.z > 0)
        rl = V.where(ok, rl, z)
        d = materialize(fr.to_world(rl))
        ok = ok & (V.dot(d, n_in) > 0)
        F, _, _, _ = fresnel_dielectric(jnp.abs(ci), 1.0 / eta)
        area = wl.z / jnp.where(ok, cwn, 1.0)
        w = jnp.where(ok, w * F * mf.G1(kind, rl, h, beta) * area, 0.0)
    arc = arc_element(g, b)[..., None]
    return [x * arc for x in out]


def _internal(p: Params, wi: Vec3, wo: Vec3, key):
    """[(S_p cos th_i, stderr)] for p = 1 .. n_lobes - 1 (TT, TRT[, TRRT]), bands axis last."""
    dtype = jnp.result_type(float)
    b = minor_axis(p.eccentricity)
    thi, phii = fiber_angles(wi)
    tho, pho = fiber_angles(wo)
    lo, hi = visible_gamma_interval(thi, phii, p.tilt, b)
    n = p.n_intervals
    t, w = simpson(n)
    # two uniforms per sampled microfacet; n_lobes = 3 keeps the historical stream (4 uniforms)
    us = uniforms(key, (n + 1, p.n_paths), 2 * (p.n_lobes - 1), dtype)
    us = materialize(us)
    # shapes: directions (...) + (nodes, paths), flattened to one axis for the per-path work:
    # XLA:CPU compiles elementwise kernels over one flat axis ~30% faster than over broadcasts
    g = lo[..., None, None] + t[:, None] * (hi - lo)[..., None, None]
    shape = jnp.broadcast_shapes(g.shape, us[0].shape, *(jnp.shape(c) + (1, 1) for c in (*wi, *wo)))
    flat = lambda v: jnp.broadcast_to(v, shape).reshape(-1)  # noqa: E731
    fv = lambda v: Vec3(*(flat(c) for c in _ex(v)))  # noqa: E731
    terms = _internal_terms(p, fv(wi), fv(wo), flat(g), tuple(flat(u) for u in us))
    terms = [x.reshape(shape + x.shape[-1:]) for x in terms]
    scale = (hi - lo) / (2.0 * jnp.maximum(jnp.cos(tho), _TINY) * half_width(p.eccentricity, pho))
    return [simpson_mc(x, w[:, None], scale[..., None], p.n_paths) for x in terms]


def _eval_lobes(p: Params, wi: Vec3, wo: Vec3, key=None):
    """Per-lobe S (R, TT, TRT[, TRRT]) in 1/sr: shape (n_lobes,) + directions + (bands,),
    and standard errors."""
    key = _default_key(key)
    sig = as_bands(p.sigma_a)
    ci = jnp.maximum(jnp.cos(fiber_angles(wi)[0]), _TINY)[..., None]
    r = _r_lobe(p, wi, wo)[..., None] * jnp.ones_like(sig)
    inner = _internal(p, wi, wo, key)
    shape = jnp.broadcast_shapes(r.shape, *(v.shape for v, _ in inner))
    val = jnp.stack([jnp.broadcast_to(r, shape)] + [jnp.broadcast_to(v, shape) for v, _ in inner]) / ci
    se = jnp.stack([jnp.zeros(shape, r.dtype)] + [jnp.broadcast_to(s, shape) for _, s in inner]) / ci
    return _finite(val), _finite(se)


def _eval(p: Params, wi: Vec3, wo: Vec3, key=None):
    """S(omega_i, omega_o) = S_R + S_TT + S_TRT (1/sr, bands last) and its standard error."""
    v, s = _eval_lobes(p, wi, wo, key)
    return jnp.sum(v, axis=0), jnp.sqrt(jnp.sum(s * s, axis=0))


eval = boundary(_eval, Params)
eval_lobes = boundary(_eval_lobes, Params)


def _r_only(p: Params, wi: Vec3, wo: Vec3, fresnel=True, smith=True):
    """Deterministic S_R (1/sr) without bands axis (Huang Eq. 4.12 / 4.28 / E.3). The static
    ``fresnel``/``smith`` switches are private (see :func:`_r_lobe`); ``eval_r`` has neither."""
    return _r_lobe(p, wi, wo, fresnel, smith) / jnp.maximum(jnp.cos(fiber_angles(wi)[0]), _TINY)


def _eval_r(p: Params, wi: Vec3, wo: Vec3):
    """Deterministic S_R (1/sr) without bands axis (Huang Eq. 4.12 / 4.28 / E.3)."""
    return _r_only(p, wi, wo)


eval_r = boundary(_eval_r, Params)


# ----------------------------------------------------------------------------------
# importance sampling (Sec. 4.3.4) and the stochastic pdf (Huang Eq. 4.33): kernels in huang_sampling

pdf = boundary(_pdf, Params)


@functools.wraps(_sample)
def sample(params, wi, u_or_key, with_pdf=True, pdf_key=None):
    # two jitted stages (the path sampler, then the public pdf), so that a pdf already compiled
    # for these shapes is reused; under a caller's jit both are traced inline
    validate(params, Params)
    (wi,) = as_directions(wi=wi)
    wo, weight, _, _, _, _, good = _sample_path_jit(params, wi, u_or_key)
    if not with_pdf:
        return wo, weight, None
    if pdf_key is None:
        pdf_key = jax.random.fold_in(u_or_key, 1) if is_prng_key(u_or_key) else _default_key(None)
    est, _ = pdf(params, wi, wo, key=pdf_key)
    return wo, weight, jnp.where(good, est, 0.0)


sample.kernel = _sample
MODEL = Model(
    name="huang_hair",
    kind="bcsdf",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="microfacet hair BCSDF R+TT+TRT: rough tilted dielectric (elliptical) cylinder, MC-Simpson TT/TRT",
    source="Huang 2022, Ch. 4 (Eqs. 4.12, 4.28-4.32, App. E)",
    reciprocal=True,
    transmissive=True,
    stochastic=True,
)
