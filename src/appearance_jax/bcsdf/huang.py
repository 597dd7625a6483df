"""Huang's microfacet hair BCSDF (Huang 2022, Ch. 4): lobes R, TT, TRT of a rough dielectric
(circular or elliptical) cylinder with a Smith microsurface (GGX or Beckmann), cuticle tilt
and a homogeneous absorbing interior.

Geometry and conventions (:mod:`appearance_jax.bcsdf.fiber`): x = fiber tangent (root -> tip),
theta with sin theta = w.x, phi = atan2(w.z, w.y); both directions point away from the fiber.
This is Huang's frame after the relabelling x_H -> z, y_H -> x, z_H -> y. The cross-section is
the ellipse y^2 / b^2 + z^2 = 1, b = sqrt(1 - e^2), points (b cos g, sin g) (Huang's gamma),
outward macronormal n(g) at azimuth phi_m = atan2(b sin g, cos g), arc length
dl = sqrt(1 - e^2 sin^2 g) dg (Eq. 4.26), projected half width D(phi) = sqrt(1 - e^2 sin^2 phi)
(Eq. 4.27). The tilted mesonormal is m_alpha = (sin alpha, cos alpha n_y, cos alpha n_z)
(Eq. 4.39); alpha > 0 tilts it towards the tip, so the R lobe moves to theta_o ~ 2 alpha - theta_i
(real cuticles: alpha ~ -2 .. -4 deg). Lengths and sigma_a are per unit (semi-major) radius.

Semantics (Eqs. 4.4-4.7): the microfacet normal distribution D is centred on the mesonormal
and normalised over the macro area element dl ds; Smith G1 is taken about the mesonormal
(separable); every direction must also lie on the correct side of the untilted macronormal
(hard visibility); BSDF denominators carry macro cosines; the projected width a_o is untilted.
This is also what :func:`appearance_jax.flatland.fiber` traces.

- R (Eqs. 4.12, 4.28): S_R = F(|w_i.h|) / (8 D_o cos th_o cos th_i) int D(h; m_alpha) G1(i) G1(o) dl
  over the entry points that see both directions; composite Simpson in gamma with a static
  number of sub-intervals mapped to the visible interval (differentiable end points). Option
  ``r_mode="analytic"``: the closed-form GGX integral without G (App. E, Eq. E.3; circles).
- TT, TRT (Eqs. 4.29-4.32, the combined Monte Carlo-Simpson estimator of Sec. 4.4): Simpson
  over the entry point, at every node ``n_paths`` internal paths: the first microfacet (and,
  for TRT, the internal one) drawn from the visible-normal distribution, the chord to the next
  interface by exact line-ellipse intersection, absorption exp(-sigma_a * 3D chord length)
  (Eq. 4.17 in its corrected, explicit form), and a deterministic connection to omega_o
  through the rough transmission BSDF at the exit (generalised half vector, Eq. 4.21). Written
  as a flux integral over the entry arc length,

    S_p cos th_i = 1 / (2 D_o cos th_o) int dl |w_i . m_alpha1| E[T_1 G1(t) A ... p_exit(w_o)],

  which is Eq. 4.29-4.32 after the change of variables of Sec. 4.3 (|t.n_1| dl_1 = |t.n_2| dl_2).
  With macro cosines in the exit BSDF the exit cosine is |t . n_2| (not the thesis's
  |t . m_alpha1|; identical for alpha = 0 on a circle): we keep the semantics the flatland
  tracer implements, so the two agree to Monte Carlo noise.

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

Example::

    from appearance_jax.bcsdf import huang
    from appearance_jax.core.frame import fiber_direction
    p = huang.Params.from_melanin(0.6, 0.6, roughness=0.12, tilt=-0.05)
    wi, wo = fiber_direction(0.3, 0.0), fiber_direction(-0.4, 2.5)
    S, se = huang.eval(p, wi, wo)                       # (3,) in 1/sr, and its standard error
    lobes, lobes_se = huang.eval_lobes(p, wi, wo)       # (3 lobes R/TT/TRT, 3 bands)
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..core import vec as V
from ..core.frame import Frame, fiber_angles, reflect, refract
from ..core.model import Model, as_bands, boundary
from ..core.params import integer, param, params_class, static
from ..core.rng import uniforms
from ..core.special import safe_acos, safe_sqrt
from ..core.vec import Vec3
from ..microfacet import distribution as mf
from ..optics.fresnel import fresnel_dielectric
from .fiber import RGB_WAVELENGTHS_NM, half_width, melanin_sigma_a_spectral, meso_normal, wrap_pi

_TINY = 1e-12


def _even(v):
    n = integer(2)(v)
    if n % 2:
        raise ValueError("must be even (composite Simpson)")
    return n


@params_class
class Params:
    roughness: object = param(0.15, lo=0.0, hi=1.0, lo_open=True, unit="1",
                              doc="microfacet roughness beta of the cuticle (GGX/Beckmann)")
    tilt: object = param(-0.05236, lo=-0.3, hi=0.3, unit="rad",
                         doc="cuticle scale tilt alpha (Eq. 4.39); > 0 tilts towards the tip")
    eta: object = param(1.55, lo=1.0, hi=3.0, lo_open=True, unit="1", doc="relative index of refraction")
    sigma_a: object = param((0.309, 0.467, 0.891), lo=0.0, unit="1/radius", bands=True,
                            doc="absorption coefficient per unit radius per band")
    eccentricity: object = param(0.0, lo=0.0, hi=0.99, unit="1",
                                 doc="eccentricity e = sqrt(1 - b^2) of the cross-section")
    distribution: str = static("ggx", choices=("ggx", "beckmann"), doc="microfacet distribution")
    r_mode: str = static("numeric", choices=("numeric", "analytic"),
                         doc="R lobe: Simpson with Smith G, or closed-form GGX without G (App. E)")
    n_intervals: int = static(64, doc="Simpson sub-intervals over the visible azimuths", convert=_even)
    n_paths: int = static(4, doc="internal paths per Simpson node (TT, TRT)", convert=integer(1))

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
# geometry of the cross-section


def _b(e):
    return safe_sqrt(1.0 - e * e)


def to_gamma(phi, b):
    """Ellipse parameter gamma of the point whose outward normal has azimuth phi."""
    return jnp.arctan2(jnp.sin(phi), b * jnp.cos(phi))


def to_phi(gamma, b):
    """Azimuth of the outward normal at parameter gamma: atan2(b sin g, cos g)."""
    return jnp.arctan2(b * jnp.sin(gamma), jnp.cos(gamma))


def _point(g, b):
    return b * jnp.cos(g), jnp.sin(g)


def _macro_normal(py, pz, b):
    ny, nz = py / (b * b), pz
    r = jnp.sqrt(ny * ny + nz * nz)
    return ny / r, nz / r


def _chord(py, pz, d: Vec3, b):
    """Parameter s of the second intersection of p + s (d.y, d.z) with the ellipse (p on it).
    For a unit 3D direction d this is the 3D path length."""
    A = d.y * d.y / (b * b) + d.z * d.z
    B = 2.0 * (py * d.y / (b * b) + pz * d.z)
    ok = A > _TINY
    s = jnp.where(ok, -B / jnp.where(ok, A, 1.0), 0.0)
    return jnp.maximum(s, 0.0)


def _visible_gamma_interval(theta, phi, alpha, b):
    """Entry parameters gamma seen by direction (theta, phi) from both the macro- and the
    mesonormal: cos(phi - phi_m) > max(0, -tan alpha tan theta) (spec §1.3.3). Returns
    (lo, hi) with hi >= lo (empty: hi = lo) and lo unwrapped near gamma(phi)."""
    c = jnp.maximum(0.0, -jnp.tan(alpha) * jnp.tan(theta))
    w = safe_acos(jnp.minimum(c, 1.0))
    gc = to_gamma(phi, b)
    lo = gc - jnp.mod(gc - to_gamma(phi - w, b), 2.0 * jnp.pi)
    hi = gc + jnp.mod(to_gamma(phi + w, b) - gc, 2.0 * jnp.pi)
    # w = 0: the mods may return 2 pi - eps; collapse
    lo = jnp.where(w > 0, lo, gc)
    hi = jnp.where(w > 0, hi, gc)
    return lo, hi


def _intersect(lo1, hi1, lo2, hi2):
    m1, m2 = 0.5 * (lo1 + hi1), 0.5 * (lo2 + hi2)
    shift = wrap_pi(m2 - m1) - (m2 - m1)
    lo2, hi2 = lo2 + shift, hi2 + shift
    lo, hi = jnp.maximum(lo1, lo2), jnp.minimum(hi1, hi2)
    return lo, jnp.maximum(hi, lo)


def _simpson(n):
    w = jnp.ones(n + 1).at[1:-1:2].set(4.0).at[2:-1:2].set(2.0) / (3.0 * n)
    t = jnp.linspace(0.0, 1.0, n + 1)
    return t, w  # int_lo^hi f ~ (hi - lo) sum w f(lo + t (hi - lo))


def _angles(w):
    th, ph = fiber_angles(w)
    return th, ph


# ----------------------------------------------------------------------------------
# interface events (mesonormal-centred microfacets, macro hard visibility)


def _local_frame(m: Vec3):
    one = jnp.ones_like(m.x)
    return Frame.from_normal_tangent(m, Vec3(one, 0.0 * one, 0.0 * one))


def _exit_pdf(kind, beta, eta, w: Vec3, o: Vec3, n_in: Vec3, m_in: Vec3):
    """Flux density per sr of o leaving through a rough interface from inside:
    f_t(w -> o) |o.n| with f_t = |w.h||o.h| (1 - F) D G1(w) G1(o) / (|w.n||o.n| |eta w + o|^2)
    (Walter et al. 2007 with macro cosines; Eq. 4.21's Jacobian: |eta w + o|^2 = eta^2 |h2|^2).
    ``w`` points back into the fiber (= -travel), ``n_in``/``m_in`` face the inside."""
    fr = _local_frame(m_in)
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


def _r_integrand(kind, beta, alpha, eta, b, wi, wo, g):
    py, pz = _point(g, b)
    ny, nz = _macro_normal(py, pz, b)
    n = Vec3(jnp.zeros_like(ny), ny, nz)
    m = meso_normal(ny, nz, alpha)
    fr = _local_frame(m)
    il, ol = fr.to_local(wi), fr.to_local(wo)
    h = V.normalize(il + ol)
    # the macro visibility is enforced by the integration interval itself: testing it again
    # here would make the end nodes (exactly on the macro horizon) depend on rounding
    ok = (il.z > 0) & (ol.z > 0) & (h.z > 0)
    one = jnp.ones_like(h.z)
    h = V.where(ok, h, Vec3(0.0 * one, 0.0 * one, one))
    val = mf.D(kind, h, beta) * mf.G1(kind, il, h, beta) * mf.G1(kind, ol, h, beta)
    arc = safe_sqrt(1.0 - (1.0 - b * b) * jnp.sin(g) ** 2)
    return jnp.where(ok, val, 0.0) * arc


def _ggx_azimuthal_antiderivative(A, B, beta, u):
    """Eq. E.3 (Huang 2022, App. E): an antiderivative in phi_m (u = phi_h - phi_m) of the GGX
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
    """Eq. E.4 (alpha = 0), valid for |u| < pi/2 (for tests of E.3)."""
    q = 1.0 - A * A
    return beta * beta / (2.0 * jnp.pi) * ((A * A - 2.0) / q ** 1.5 * jnp.arctan(jnp.tan(u) / jnp.sqrt(q))
                                           + A * A * jnp.sin(2 * u) / (q * (A * A * jnp.cos(2 * u) + A * A - 2.0)))


def _r_lobe(p: Params, wi: Vec3, wo: Vec3):
    """S_R cos(theta_i) (no bands axis), Eqs. 4.12 / 4.28 / E.3."""
    kind, beta, alpha, eta = p.distribution, p.roughness, p.tilt, p.eta
    b = _b(p.eccentricity)
    thi, phii = _angles(wi)
    tho, pho = _angles(wo)
    lo1, hi1 = _visible_gamma_interval(thi, phii, alpha, b)
    lo2, hi2 = _visible_gamma_interval(tho, pho, alpha, b)
    lo, hi = _intersect(lo1, hi1, lo2, hi2)
    h = V.normalize(wi + wo)
    F, _, _, _ = fresnel_dielectric(jnp.clip(V.dot(wi, h), 0.0, 1.0), eta)
    cos_o = jnp.maximum(jnp.cos(tho), _TINY)
    Do = half_width(p.eccentricity, pho)
    if p.r_mode == "analytic":
        thh, phh = _angles(h)
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
        t, w = _simpson(p.n_intervals)
        g = lo[..., None] + t * (hi - lo)[..., None]
        ex = lambda v: Vec3(v.x[..., None], v.y[..., None], v.z[..., None])
        f = _r_integrand(kind, beta, alpha, eta, b, ex(wi), ex(wo), g)
        integral = (hi - lo) * jnp.sum(w * f, axis=-1)
    return F * integral / (8.0 * cos_o * Do)


# ----------------------------------------------------------------------------------
# TT and TRT: combined Monte Carlo-Simpson estimator


def _tt_trt_terms(p: Params, wi: Vec3, wo: Vec3, g, u1, u2, u3, u4):
    """Per-node, per-path contributions (without Simpson weights) to S_TT cos th_i and
    S_TRT cos th_i times 2 D_o cos th_o, for entry parameter g. Shapes broadcast; the result
    carries a trailing bands axis."""
    kind, beta, alpha, eta = p.distribution, p.roughness, p.tilt, p.eta
    b = _b(p.eccentricity)
    sig = as_bands(p.sigma_a)
    one = jnp.ones_like(g * u1)
    z = Vec3(0.0 * one, 0.0 * one, one)
    # interface 1 (entry)
    py, pz = _point(g, b)
    ny, nz = _macro_normal(py, pz, b)
    n1 = Vec3(0.0 * ny, ny, nz)
    m1 = meso_normal(ny, nz, alpha)
    fr1 = _local_frame(m1)
    il = fr1.to_local(wi)
    ok1 = il.z > 0      # macro visibility of w_i: the integration interval
    il = V.where(ok1, il, z)
    h1 = mf.sample_visible(kind, il, beta, beta, u1, u2)
    ci1 = V.dot(il, h1)
    tl, ok_t = refract(il, h1, eta)
    ok1 = ok1 & ok_t & (ci1 > 0) & (tl.z < 0)
    tl = V.where(ok1, tl, -z)
    t = fr1.to_world(tl)
    ok1 = ok1 & (V.dot(t, n1) < 0)
    F1, _, _, _ = fresnel_dielectric(jnp.abs(ci1), eta)
    w1 = il.z * (1.0 - F1) * mf.G1(kind, tl, h1, beta)          # |i.m1| T1 G1(t)
    w1 = jnp.where(ok1, w1, 0.0)
    # chord 1 -> 2
    s1 = _chord(py, pz, t, b)
    qy, qz = py + s1 * t.y, pz + s1 * t.z
    my, mz = _macro_normal(qy, qz, b)
    n2_in = Vec3(0.0 * my, -my, -mz)
    m2_in = -meso_normal(my, mz, alpha)
    A1 = jnp.exp(-sig * s1[..., None])
    w_back = -t
    tt = (w1 * _exit_pdf(kind, beta, eta, w_back, wo, n2_in, m2_in))[..., None] * A1
    # TRT: internal reflection at 2
    fr2 = _local_frame(m2_in)
    wl2 = fr2.to_local(w_back)
    cwn2 = V.dot(w_back, n2_in)
    ok2 = ok1 & (wl2.z > 0) & (cwn2 > _TINY)
    wl2 = V.where(ok2, wl2, z)
    h2 = mf.sample_visible(kind, wl2, beta, beta, u3, u4)
    ci2 = V.dot(wl2, h2)
    rl = reflect(wl2, h2)
    ok2 = ok2 & (ci2 > 0) & (rl.z > 0)
    rl = V.where(ok2, rl, z)
    r = fr2.to_world(rl)
    ok2 = ok2 & (V.dot(r, n2_in) > 0)
    F2, _, _, _ = fresnel_dielectric(jnp.abs(ci2), 1.0 / eta)
    area2 = wl2.z / jnp.where(ok2, cwn2, 1.0)
    w2 = jnp.where(ok2, F2 * mf.G1(kind, rl, h2, beta) * area2, 0.0)
    s2 = _chord(qy, qz, r, b)
    ry, rz = qy + s2 * r.y, qz + s2 * r.z
    ky, kz = _macro_normal(ry, rz, b)
    n3_in = Vec3(0.0 * ky, -ky, -kz)
    m3_in = -meso_normal(ky, kz, alpha)
    A2 = jnp.exp(-sig * s2[..., None])
    trt = (w1 * w2 * _exit_pdf(kind, beta, eta, -r, wo, n3_in, m3_in))[..., None] * A1 * A2
    arc = safe_sqrt(1.0 - (1.0 - b * b) * jnp.sin(g) ** 2)[..., None]
    return tt * arc, trt * arc


def _node_uniforms(key, n_nodes, n_paths, dtype):
    u = uniforms(key, (n_nodes, n_paths), 4, dtype)
    return u


def _tt_trt(p: Params, wi: Vec3, wo: Vec3, key):
    """(S_TT cos th_i, S_TRT cos th_i) and their standard errors, bands axis last."""
    dtype = jnp.result_type(float)
    b = _b(p.eccentricity)
    thi, phii = _angles(wi)
    tho, pho = _angles(wo)
    lo, hi = _visible_gamma_interval(thi, phii, p.tilt, b)
    n = p.n_intervals
    t, w = _simpson(n)
    u1, u2, u3, u4 = _node_uniforms(key, n + 1, p.n_paths, dtype)
    # shapes: directions (...) + (nodes, paths)
    ex = lambda v: Vec3(v.x[..., None, None], v.y[..., None, None], v.z[..., None, None])
    g = lo[..., None, None] + t[:, None] * (hi - lo)[..., None, None]
    tt, trt = _tt_trt_terms(p, ex(wi), ex(wo), g, u1, u2, u3, u4)
    scale = (hi - lo) / (2.0 * jnp.maximum(jnp.cos(tho), _TINY) * half_width(p.eccentricity, pho))
    scale = scale[..., None]
    w = w[:, None]

    def est(x):
        mean_node = jnp.mean(x, axis=-2)                       # (..., nodes, bands)
        val = jnp.sum(w * mean_node, axis=-2) * scale
        if p.n_paths > 1:
            var_node = jnp.var(x, axis=-2, ddof=1) / p.n_paths
        else:  # neighbouring-node differences as a (conservative) variance proxy
            d = jnp.diff(mean_node, axis=-2)
            var_node = jnp.concatenate([d[..., :1, :], d], axis=-2) ** 2 / 2.0
        se = jnp.sqrt(jnp.sum(w * w * var_node, axis=-2)) * jnp.abs(scale)
        return val, se

    (v_tt, s_tt), (v_trt, s_trt) = est(tt), est(trt)
    return v_tt, s_tt, v_trt, s_trt


def _default_key(key):
    return jax.random.PRNGKey(0) if key is None else key


def _eval_lobes(p: Params, wi: Vec3, wo: Vec3, key=None):
    """Per-lobe S (R, TT, TRT) in 1/sr: shape (3,) + directions + (bands,), and standard errors."""
    key = _default_key(key)
    sig = as_bands(p.sigma_a)
    ci = jnp.maximum(jnp.cos(_angles(wi)[0]), _TINY)[..., None]
    r = _r_lobe(p, wi, wo)[..., None] * jnp.ones_like(sig)
    v_tt, s_tt, v_trt, s_trt = _tt_trt(p, wi, wo, key)
    r, v_tt, v_trt = (jnp.broadcast_to(x, jnp.broadcast_shapes(r.shape, v_tt.shape)) for x in (r, v_tt, v_trt))
    val = jnp.stack([r, v_tt, v_trt]) / ci
    se = jnp.stack([jnp.zeros_like(r), jnp.broadcast_to(s_tt, r.shape), jnp.broadcast_to(s_trt, r.shape)]) / ci
    return _finite(val), _finite(se)


def _finite(x):
    return jnp.where(jnp.isfinite(x), x, 0.0)


def _eval(p: Params, wi: Vec3, wo: Vec3, key=None):
    """S(omega_i, omega_o) = S_R + S_TT + S_TRT (1/sr, bands last) and its standard error."""
    v, s = _eval_lobes(p, wi, wo, key)
    return jnp.sum(v, axis=0), jnp.sqrt(jnp.sum(s * s, axis=0))


eval = boundary(_eval, Params)
eval_lobes = boundary(_eval_lobes, Params)


def _r_only(p: Params, wi: Vec3, wo: Vec3):
    """Deterministic S_R (1/sr) without bands axis (Eq. 4.12 / 4.28 / E.3)."""
    return _r_lobe(p, wi, wo) / jnp.maximum(jnp.cos(_angles(wi)[0]), _TINY)


eval_r = boundary(_r_only, Params)


MODEL = Model(
    name="huang_hair",
    kind="bcsdf",
    Params=Params,
    eval=eval,
    sample=None,
    pdf=None,
    summary="microfacet hair BCSDF R+TT+TRT: rough tilted dielectric (elliptical) cylinder, MC-Simpson TT/TRT",
    source="Huang 2022, Ch. 4 (Eqs. 4.12, 4.28-4.32, App. E)",
    reciprocal=True,
    transmissive=True,
    stochastic=True,
)
