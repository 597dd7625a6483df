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
| n_lobes       | 3                    | 3, 4       | -        | R, TT, TRT; 4 adds TRRT (Sec. 4.5)              |

Sampling (Sec. 4.3.4, spec §1.3.11): ``sample(params, wi, key_or_uniforms, with_pdf=True)``
draws h uniformly over the projected width, visible normals at every interface, and the lobe
with probability proportional to the luminance of Huang's attenuations A_p; the weight is
unbiased for S cos(theta_o) (E[weight; wo in dw] = S cos dw, circles and ellipses, any tilt)
but is not S cos / pdf pointwise. ``pdf(params, wi, wo, key=None) -> (estimate, stderr)`` is
the stochastic Eq. 4.33 (Monte Carlo-Simpson, the same ``n_intervals`` / ``n_paths``);
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
from ..core.frame import Frame, fiber_angles, reflect, refract
from ..core.model import Model, as_bands, boundary
from ..core.params import Bands, integer, param, params_class, Real, static, validate
from ..core.rng import is_prng_key, uniforms
from ..core.special import safe_acos, safe_sqrt
from ..core.vec import Vec3
from ..microfacet import distribution as mf
from ..optics.fresnel import fresnel_dielectric
from .chiang import LUMINANCE_RGB
from .fiber import RGB_WAVELENGTHS_NM, half_width, melanin_sigma_a_spectral, meso_normal, wrap_pi

_TINY = 1e-12


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
                         doc="cuticle scale tilt alpha (Eq. 4.39); > 0 tilts towards the tip")
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
    n_lobes: int = static(3, doc="lobes: 3 = R, TT, TRT; 4 adds TRRT (Sec. 4.5)", convert=integer(3, 4))

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


def _r_integrand(kind, beta, alpha, eta, b, wi, wo, g, smith=True):
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
    val = mf.D(kind, h, beta)
    if smith:
        val = val * mf.G1(kind, il, h, beta) * mf.G1(kind, ol, h, beta)
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


def _r_lobe(p: Params, wi: Vec3, wo: Vec3, fresnel=True, smith=True):
    """S_R cos(theta_i) (no bands axis), Eqs. 4.12 / 4.28 / E.3.

    Private switches (static; for the "mirror furnace" check H-3 of spec seed-001 §3.3 only):
    ``fresnel=False`` sets F = 1, ``smith=False`` drops G1 G1 (the hard macro/meso visibility
    stays). ``r_mode="analytic"`` never has G."""
    kind, beta, alpha, eta = p.distribution, p.roughness, p.tilt, p.eta
    b = _b(p.eccentricity)
    thi, phii = _angles(wi)
    tho, pho = _angles(wo)
    lo1, hi1 = _visible_gamma_interval(thi, phii, alpha, b)
    lo2, hi2 = _visible_gamma_interval(tho, pho, alpha, b)
    lo, hi = _intersect(lo1, hi1, lo2, hi2)
    h = V.normalize(wi + wo)
    F, _, _, _ = fresnel_dielectric(jnp.clip(V.dot(wi, h), 0.0, 1.0), eta)
    if not fresnel:
        F = jnp.ones_like(F)
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
        f = _r_integrand(kind, beta, alpha, eta, b, ex(wi), ex(wo), g, smith)
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
    b = _b(p.eccentricity)
    sig = as_bands(p.sigma_a)
    one = jnp.ones_like(g * us[0])
    z = Vec3(0.0 * one, 0.0 * one, one)
    # interface 1 (entry)
    py, pz = _point(g, b)
    ny, nz = _macro_normal(py, pz, b)
    n1 = Vec3(0.0 * ny, ny, nz)
    m1 = meso_normal(ny, nz, alpha)
    fr1 = _local_frame(m1)
    il = fr1.to_local(wi)
    ok = il.z > 0      # macro visibility of w_i: the integration interval
    il = V.where(ok, il, z)
    h1 = mf.sample_visible(kind, il, beta, beta, us[0], us[1])
    ci1 = V.dot(il, h1)
    tl, ok_t = refract(il, h1, eta)
    ok = ok & ok_t & (ci1 > 0) & (tl.z < 0)
    tl = V.where(ok, tl, -z)
    d = fr1.to_world(tl)
    ok = ok & (V.dot(d, n1) < 0)
    F1, _, _, _ = fresnel_dielectric(jnp.abs(ci1), eta)
    w = il.z * (1.0 - F1) * mf.G1(kind, tl, h1, beta)          # |i.m1| T1 G1(t)
    w = jnp.where(ok, w, 0.0)
    A = 1.0
    qy, qz = py, pz
    out = []
    for k in range(1, p.n_lobes):
        # chord to interface k + 1, absorption (Eq. 4.17), exit connection to w_o (Eq. 4.21)
        s = _chord(qy, qz, d, b)
        qy, qz = qy + s * d.y, qz + s * d.z
        my, mz = _macro_normal(qy, qz, b)
        n_in = Vec3(0.0 * my, -my, -mz)
        m_in = -meso_normal(my, mz, alpha)
        A = A * jnp.exp(-sig * s[..., None])
        out.append((w * _exit_pdf(kind, beta, eta, -d, wo, n_in, m_in))[..., None] * A)
        if k == p.n_lobes - 1:
            break
        # internal reflection at interface k + 1 (visible-normal sampling)
        fr = _local_frame(m_in)
        wl = fr.to_local(-d)
        cwn = V.dot(-d, n_in)
        ok = ok & (wl.z > 0) & (cwn > _TINY)
        wl = V.where(ok, wl, z)
        h = mf.sample_visible(kind, wl, beta, beta, us[2 * k], us[2 * k + 1])
        ci = V.dot(wl, h)
        rl = reflect(wl, h)
        ok = ok & (ci > 0) & (rl.z > 0)
        rl = V.where(ok, rl, z)
        d = fr.to_world(rl)
        ok = ok & (V.dot(d, n_in) > 0)
        F, _, _, _ = fresnel_dielectric(jnp.abs(ci), 1.0 / eta)
        area = wl.z / jnp.where(ok, cwn, 1.0)
        w = jnp.where(ok, w * F * mf.G1(kind, rl, h, beta) * area, 0.0)
    arc = safe_sqrt(1.0 - (1.0 - b * b) * jnp.sin(g) ** 2)[..., None]
    return [x * arc for x in out]


def _node_uniforms(key, n_nodes, n_paths, n, dtype):
    return uniforms(key, (n_nodes, n_paths), n, dtype)


def _simpson_mc(x, w, scale, n_paths):
    """Combined Monte Carlo-Simpson estimate (Sec. 4.3.4): Simpson weights ``w`` (nodes, 1)
    over the per-node path means of ``x`` (..., nodes, paths[, bands]), times ``scale``; the
    standard error from the spread over paths (one path: neighbouring-node differences)."""
    mean_node = jnp.mean(x, axis=-2)
    val = jnp.sum(w * mean_node, axis=-2) * scale
    if n_paths > 1:
        var_node = jnp.var(x, axis=-2, ddof=1) / n_paths
    else:  # neighbouring-node differences as a (conservative) variance proxy
        dd = jnp.diff(mean_node, axis=-2)
        var_node = jnp.concatenate([dd[..., :1, :], dd], axis=-2) ** 2 / 2.0
    se = jnp.sqrt(jnp.sum(w * w * var_node, axis=-2)) * jnp.abs(scale)
    return val, se


def _ex(v: Vec3):
    return Vec3(v.x[..., None, None], v.y[..., None, None], v.z[..., None, None])


def _internal(p: Params, wi: Vec3, wo: Vec3, key):
    """[(S_p cos th_i, stderr)] for p = 1 .. n_lobes - 1 (TT, TRT[, TRRT]), bands axis last."""
    dtype = jnp.result_type(float)
    b = _b(p.eccentricity)
    thi, phii = _angles(wi)
    tho, pho = _angles(wo)
    lo, hi = _visible_gamma_interval(thi, phii, p.tilt, b)
    n = p.n_intervals
    t, w = _simpson(n)
    # two uniforms per sampled microfacet; n_lobes = 3 keeps the historical stream (4 uniforms)
    us = _node_uniforms(key, n + 1, p.n_paths, 2 * (p.n_lobes - 1), dtype)
    # shapes: directions (...) + (nodes, paths)
    g = lo[..., None, None] + t[:, None] * (hi - lo)[..., None, None]
    terms = _internal_terms(p, _ex(wi), _ex(wo), g, us)
    scale = (hi - lo) / (2.0 * jnp.maximum(jnp.cos(tho), _TINY) * half_width(p.eccentricity, pho))
    return [_simpson_mc(x, w[:, None], scale[..., None], p.n_paths) for x in terms]


def _default_key(key):
    return jax.random.PRNGKey(0) if key is None else key


def _eval_lobes(p: Params, wi: Vec3, wo: Vec3, key=None):
    """Per-lobe S (R, TT, TRT[, TRRT]) in 1/sr: shape (n_lobes,) + directions + (bands,),
    and standard errors."""
    key = _default_key(key)
    sig = as_bands(p.sigma_a)
    ci = jnp.maximum(jnp.cos(_angles(wi)[0]), _TINY)[..., None]
    r = _r_lobe(p, wi, wo)[..., None] * jnp.ones_like(sig)
    inner = _internal(p, wi, wo, key)
    shape = jnp.broadcast_shapes(r.shape, *(v.shape for v, _ in inner))
    val = jnp.stack([jnp.broadcast_to(r, shape)] + [jnp.broadcast_to(v, shape) for v, _ in inner]) / ci
    se = jnp.stack([jnp.zeros(shape, r.dtype)] + [jnp.broadcast_to(s, shape) for _, s in inner]) / ci
    return _finite(val), _finite(se)


def _finite(x):
    return jnp.where(jnp.isfinite(x), x, 0.0)


def _eval(p: Params, wi: Vec3, wo: Vec3, key=None):
    """S(omega_i, omega_o) = S_R + S_TT + S_TRT (1/sr, bands last) and its standard error."""
    v, s = _eval_lobes(p, wi, wo, key)
    return jnp.sum(v, axis=0), jnp.sqrt(jnp.sum(s * s, axis=0))


eval = boundary(_eval, Params)
eval_lobes = boundary(_eval_lobes, Params)


def _r_only(p: Params, wi: Vec3, wo: Vec3, fresnel=True, smith=True):
    """Deterministic S_R (1/sr) without bands axis (Eq. 4.12 / 4.28 / E.3). The static
    ``fresnel``/``smith`` switches are private (see :func:`_r_lobe`); ``eval_r`` has neither."""
    return _r_lobe(p, wi, wo, fresnel, smith) / jnp.maximum(jnp.cos(_angles(wi)[0]), _TINY)


def _eval_r(p: Params, wi: Vec3, wo: Vec3):
    """Deterministic S_R (1/sr) without bands axis (Eq. 4.12 / 4.28 / E.3)."""
    return _r_only(p, wi, wo)


eval_r = boundary(_eval_r, Params)


# ----------------------------------------------------------------------------------
# importance sampling (Sec. 4.3.4, [T:1194-1209]) and the stochastic pdf (Eq. 4.33)


def _luminance(A):
    """Scalar used for lobe selection: Rec. 709 luminance of 3 bands (Huang's code: the
    luminance mean of the spectral attenuation), the band mean otherwise."""
    if A.shape[-1] == 3:
        return A @ jnp.asarray(LUMINANCE_RGB, dtype=A.dtype)
    return jnp.mean(A, axis=-1)


def _lobe_probabilities(A):
    """P_p = lum(A_p) / sum_q lum(A_q), shape (n_lobes, ...); all zero when every A_p is 0."""
    lum = _luminance(A)
    tot = jnp.sum(lum, axis=0)
    return jnp.where(tot > 0, lum / jnp.where(tot > 0, tot, 1.0), 0.0)


def _entry_gamma(wi: Vec3, h, b):
    """Ellipse parameter of the entry point of the ray from ``wi`` at signed offset
    ``h`` in [-D_i, D_i] (2D line-ellipse intersection on the lit side; for a circle
    gamma = phi_i + asin h, spec §1.3.2). Returns (gamma, valid)."""
    r = jnp.sqrt(wi.y * wi.y + wi.z * wi.z)
    ok = r > _TINY
    r = jnp.where(ok, r, 1.0)
    uy, uz = wi.y / r, wi.z / r           # towards the light
    vy, vz = -uz, uy
    A = uy * uy / (b * b) + uz * uz
    B = 2.0 * h * (vy * uy / (b * b) + vz * uz)
    C = h * h * (vy * vy / (b * b) + vz * vz) - 1.0
    s = (-B + safe_sqrt(B * B - 4.0 * A * C)) / (2.0 * A)
    py, pz = h * vy + s * uy, h * vz + s * uz
    return jnp.arctan2(pz, py / b), ok


def _walk(p: Params, wi: Vec3, g, us, wo: Vec3 | None = None, connect=None):
    """One path of Huang's sampler (Sec. 4.3.4, [T:1194-1209]) entering at ellipse parameter g.

    At interface 1 a microfacet h_1 is drawn from the visible normals of w_i about the
    mesonormal m_1 (Eq. 4.39); R leaves by reflection, the refracted ray crosses the fiber
    (exact chord, absorption exp(-sigma_a s), Eq. 4.17) and at every further interface k a
    microfacet h_k is drawn from the visible normals of the arriving ray: lobe k - 1 leaves by
    refraction through it, the next one continues by reflection. ``us`` holds two uniforms per
    interface.

    Returns ``(A, Vis, dirs, dens)``:

    - ``A`` (n_lobes, ..., bands): Huang's lobe attenuations A_R = R_1, A_TT = T_1 T_2 A_t,
      A_TRT = T_1 R_2 T_3 A_t A_tr (, A_TRRT = T_1 R_2 R_3 T_4 A_t A_tr A_trr): Fresnel products
      and absorption, 0 once the path prefix is invalid (TIR kills TT: T_2 = 0).
    - ``Vis`` (n_lobes, ...): the visibility of lobe p's outgoing path: Smith G1 of every
      outgoing leg about its mesonormal, the meso/macro area ratios |w.m|/|w.n| of the thesis's
      macro-cosine semantics (1 without tilt; what :func:`_exit_pdf` and the flatland tracer
      carry) and the hard macro/meso side tests. Times A_p it is the analog path weight.
    - ``dirs``: the n_lobes sampled outgoing directions (fiber frame, pointing away).
    - ``dens`` (with ``wo`` and ``connect``, an integer array broadcasting against ``g``):
      where ``connect == p`` the microfacet at the interface where lobe p leaves is not drawn
      but the (generalised) half vector of ``wo``, and ``dens`` is the density per sr of ``wo``
      given the rest of the path, D_vis(h) |dh/dwo| (Walter et al. 2007 Jacobians; the
      D G1 / (4 |w_i.m_1|) and D G |w.h||o.h| / (eta^2 |h|^2 |w.m|) terms of Eq. 4.33), 0 where
      that sample would fail. One graph serves all lobes (a leading lobe axis in ``g``):
      a third of the compile time of one walk per lobe.
    """
    kind, beta, alpha, eta = p.distribution, p.roughness, p.tilt, p.eta
    b = _b(p.eccentricity)
    sig = as_bands(p.sigma_a)
    one = jnp.ones_like(g * us[0])
    z = Vec3(0.0 * one, 0.0 * one, one)
    bands = jnp.ones_like(sig)
    dens = None
    # interface 1: entry (reflection = R)
    py, pz = _point(g, b)
    ny, nz = _macro_normal(py, pz, b)
    n1 = Vec3(0.0 * ny, ny, nz)
    fr = _local_frame(meso_normal(ny, nz, alpha))
    il = fr.to_local(wi)
    cin = V.dot(wi, n1)
    ok = (il.z > 0) & (cin > _TINY)
    il = V.where(ok, il, z)
    # h is uniform over the projected width (d h ~ |w_i.n| dl) while the thesis's flux per macro
    # arc length is |w_i.m_1| (Eq. 4.31): the ratio (1 without tilt) keeps the sampler unbiased
    vis = jnp.where(ok, il.z / jnp.where(ok, cin, 1.0), 0.0)
    h = mf.sample_visible(kind, il, beta, beta, us[0], us[1])
    if connect is not None:
        ol = fr.to_local(wo)
        hc = V.normalize(il + ol)
        okc = ok & (ol.z > 0) & (V.dot(wo, n1) > 0) & (hc.z > 0)
        hc = V.where(okc, hc, z)
        co = jnp.where(okc, V.dot(ol, hc), 1.0)
        dens = jnp.where((connect == 0) & okc & (co > 0),
                         mf.pdf_visible(kind, il, hc, beta) / (4.0 * jnp.abs(co)), 0.0)
        h = V.where(connect == 0, hc, h)
    ci = V.dot(il, h)
    ok = ok & (ci > 0)
    F, _, _, _ = fresnel_dielectric(jnp.clip(ci, 0.0, 1.0), eta)
    rl = reflect(il, h)
    r = fr.to_world(rl)
    ok_r = ok & (rl.z > 0) & (V.dot(r, n1) > 0)
    A = [jnp.where(ok, F, 0.0)[..., None] * bands]
    Vis = [jnp.where(ok_r, vis * mf.G1(kind, V.where(ok_r, rl, z), h, beta), 0.0)]
    dirs = [r]
    tl, ok_t = refract(il, h, eta)
    ok = ok & ok_t & (tl.z < 0)
    tl = V.where(ok, tl, -z)
    d = fr.to_world(tl)
    ok = ok & (V.dot(d, n1) < 0)
    vis = jnp.where(ok, vis * mf.G1(kind, tl, h, beta), 0.0)
    thr = jnp.where(ok, 1.0 - F, 0.0)[..., None] * bands       # Fresnel products x absorption
    qy, qz = py, pz
    for k in range(1, p.n_lobes):
        s = _chord(qy, qz, d, b)
        qy, qz = qy + s * d.y, qz + s * d.z
        my, mz = _macro_normal(qy, qz, b)
        n_in = Vec3(0.0 * my, -my, -mz)
        fr = _local_frame(-meso_normal(my, mz, alpha))          # inward mesonormal (§1.3.8)
        thr = thr * jnp.exp(-sig * s[..., None])
        wl = fr.to_local(-d)
        cwn = V.dot(-d, n_in)
        ok = ok & (wl.z > 0) & (cwn > _TINY)
        wl = V.where(ok, wl, z)
        area = wl.z / jnp.where(ok, cwn, 1.0)
        h = mf.sample_visible(kind, wl, beta, beta, us[2 * k], us[2 * k + 1])
        if connect is not None:
            ol = fr.to_local(wo)
            H = wl * (-eta) - ol
            hc = V.normalize(H)
            hc = hc * jnp.where(hc.z < 0, -1.0, 1.0)
            den2 = V.dot(H, H)
            okc = (ok & (hc.z > 0) & (V.dot(wo, n_in) < 0) & (ol.z < 0) & (V.dot(wl, hc) > 0)
                   & (V.dot(ol, hc) < 0) & (den2 > _TINY))
            hc = V.where(okc, hc, z)
            dc = mf.pdf_visible(kind, wl, hc, beta) * jnp.abs(V.dot(ol, hc)) / jnp.where(okc, den2, 1.0)
            dens = jnp.where((connect == k) & okc, dc, dens)
            h = V.where(connect == k, hc, h)
        ci = V.dot(wl, h)
        ok = ok & (ci > 0)
        F, _, _, _ = fresnel_dielectric(jnp.clip(ci, 0.0, 1.0), 1.0 / eta)
        # lobe k leaves by refraction (T_k = 0 under total internal reflection)
        ol_, ok_o = refract(wl, h, 1.0 / eta)
        o = fr.to_world(ol_)
        ok_o = ok & ok_o & (ol_.z < 0) & (V.dot(o, n_in) < 0)
        A.append(thr * jnp.where(ok, 1.0 - F, 0.0)[..., None])
        Vis.append(jnp.where(ok_o, vis * area * mf.G1(kind, V.where(ok_o, ol_, -z), h, beta), 0.0))
        dirs.append(o)
        if k == p.n_lobes - 1:
            break
        rl = reflect(wl, h)
        ok = ok & (rl.z > 0)
        rl = V.where(ok, rl, z)
        d = fr.to_world(rl)
        ok = ok & (V.dot(d, n_in) > 0)
        vis = jnp.where(ok, vis * area * mf.G1(kind, rl, h, beta), 0.0)
        thr = thr * jnp.where(ok, F, 0.0)[..., None]
    return jnp.stack(A), jnp.stack(Vis), dirs, dens


def _n_uniforms(p: Params):
    return 2 + 2 * p.n_lobes  # offset h, lobe, two per interface (8 for R, TT, TRT)


def _sample_path(p: Params, wi: Vec3, u):
    """Huang's sampler with its internals: (wo, weight, lobe, probabilities, A, Vis)."""
    shape = jnp.shape(wi.x)
    us = uniforms(u, shape, _n_uniforms(p))
    u_h, u_lobe, us = us[0], us[1], us[2:]
    b = _b(p.eccentricity)
    thi, phii = _angles(wi)
    D_i = half_width(p.eccentricity, phii)
    g, ok = _entry_gamma(wi, D_i * (2.0 * u_h - 1.0), b)
    A, Vis, dirs, _ = _walk(p, wi, g, us)
    P = _lobe_probabilities(A)
    cdf = jnp.cumsum(P, axis=0)
    lobe = jnp.minimum(jnp.sum(u_lobe[None] >= cdf[:-1], axis=0), p.n_lobes - 1)
    onehot = (jnp.arange(p.n_lobes).reshape((-1,) + (1,) * len(shape)) == lobe[None])
    pick = lambda x: jnp.sum(jnp.where(onehot, x, 0.0), axis=0)  # noqa: E731
    wo = Vec3(*(pick(jnp.stack([getattr(d, c) for d in dirs])) for c in "xyz"))
    P_k, Vis_k = pick(P), pick(Vis)
    A_k = jnp.sum(jnp.where(onehot[..., None], A, 0.0), axis=0)
    tho, pho = _angles(wo)
    D_o = half_width(p.eccentricity, pho)
    good = ok & (P_k > 0) & (Vis_k > 0) & (jnp.cos(thi) > _TINY)
    # analog weight sum_q A_q Vis_p (for gray A); D_i / D_o converts the flux density into
    # S cos(theta_o) (Eq. 4.27), so that E[weight delta(wo)] = S cos(theta_o)
    scale = jnp.where(good, Vis_k * D_i / jnp.where(good, P_k * D_o, 1.0), 0.0)
    weight = _finite(A_k * scale[..., None])
    wo = V.where(good, wo, Vec3(jnp.zeros(shape), jnp.zeros(shape), jnp.ones(shape)) * jnp.ones(shape))
    return wo, weight, lobe, P, A, Vis, good


def _pdf(p: Params, wi: Vec3, wo: Vec3, key=None):
    """Stochastic estimate of the density (1/sr) of the successful samples of :func:`sample`
    at ``wo``, Eq. 4.33 (Huang 2022), and its standard error.

    P(w_o) = int dh / (2 D_i) sum_p E[A_p / sum_q A_q] p_p(w_o | h, path), written as an
    integral over the visible entry arc (dh = |w_i.n| dl / cos th_i) and evaluated like ``eval``:
    composite Simpson over the entry parameter (``n_intervals``) and, at every node,
    ``n_paths`` random internal paths per lobe (the microfacet where lobe p leaves is fixed by
    ``wo``, the others are drawn; A uses luminance as in the sampler). An unbiased estimate up
    to the Simpson error (not an exact density: the thesis evaluates it the same way), so it
    takes a ``key`` (default: fixed, common random numbers) and returns ``(pdf, stderr)``.
    """
    key = _default_key(key)
    dtype = jnp.result_type(float)
    b = _b(p.eccentricity)
    thi, phii = _angles(wi)
    lo, hi = _visible_gamma_interval(thi, phii, p.tilt, b)
    n = p.n_intervals
    t, w = _simpson(n)
    us = _node_uniforms(key, n + 1, p.n_paths, 2 * p.n_lobes, dtype)
    g = lo[..., None, None] + t[:, None] * (hi - lo)[..., None, None]
    wi_, wo_ = _ex(wi), _ex(wo)
    # a leading axis: which lobe's exit is connected to wo (one walk graph for all lobes)
    lobes = jnp.arange(p.n_lobes).reshape((-1,) + (1,) * g.ndim)
    A, _, _, dens = _walk(p, wi_, g[None] + 0.0 * lobes, us, wo_, connect=lobes)
    P = _lobe_probabilities(A)                          # (lobes A, connected lobe, ...)
    x = sum(P[k, k] * dens[k] for k in range(p.n_lobes))
    py, pz = _point(g, b)
    ny, nz = _macro_normal(py, pz, b)
    cin = jnp.maximum(wi_.y * ny + wi_.z * nz, 0.0)
    arc = safe_sqrt(1.0 - (1.0 - b * b) * jnp.sin(g) ** 2)
    x = (x * cin * arc)[..., None]
    ok = jnp.cos(thi) > _TINY
    scale = jnp.where(ok, (hi - lo) / (2.0 * jnp.where(ok, jnp.cos(thi), 1.0) * half_width(p.eccentricity, phii)), 0.0)
    val, se = _simpson_mc(x, w[:, None], scale[..., None], p.n_paths)
    return _finite(jnp.maximum(val[..., 0], 0.0)), _finite(se[..., 0])


def _sample(p: Params, wi: Vec3, u_or_key, with_pdf=True, pdf_key=None):
    """Huang's importance sampler (Sec. 4.3.4 [T:1194-1209]; spec seed-001 §1.3.11).

    Offset h uniform over the projected width [-D_i, D_i], microfacets from the visible
    normals at every interface (refract, reflect, ...), lobe p chosen with probability
    P_p = lum(A_p) / sum_q lum(A_q), weight (per band) A_p Vis_p / P_p x D_i / D_o
    (= (A_R + A_TT + A_TRT) x G of the outgoing direction for gray A, no tilt, circle).
    Uniforms, in order: h, lobe, then two per interface (8 for n_lobes = 3, as in the thesis);
    ``u_or_key`` is a PRNG key or that many arrays.

    The weight is unbiased, E[weight delta(w - wo)] = S(wi, w) cos(theta_w) (the model's eval,
    same microfacet semantics), but it is not the ratio S cos / pdf of the exact density:
    neither is available in closed form. ``pdf`` (with ``with_pdf=True``, static) is the
    stochastic Eq. 4.33 estimate :func:`_pdf` at the sampled direction (key ``pdf_key``, by
    default derived from ``u_or_key`` when it is a key; costly: n_lobes x (n_intervals + 1) x
    n_paths paths per sample); ``with_pdf=False`` returns ``None`` in its place. Failed samples
    (invalid path, masked or below the horizon) have weight 0 and pdf 0.
    """
    wo, weight, _, _, _, _, good = _sample_path(p, wi, u_or_key)
    if not with_pdf:
        return wo, weight, None
    if pdf_key is None:
        pdf_key = jax.random.fold_in(u_or_key, 1) if is_prng_key(u_or_key) else _default_key(None)
    pdf, _ = _pdf(p, wi, wo, pdf_key)
    return wo, weight, jnp.where(good, pdf, 0.0)


_sample_path_jit = jax.jit(_sample_path)
pdf = boundary(_pdf, Params)


@functools.wraps(_sample)
def sample(params, wi, u_or_key, with_pdf=True, pdf_key=None):
    # two jitted stages (the path sampler, then the public pdf), so that a pdf already compiled
    # for these shapes is reused; under a caller's jit both are traced inline
    validate(params, Params)
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
