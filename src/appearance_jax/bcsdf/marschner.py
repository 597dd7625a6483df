"""Marschner et al. 2003 hair BCSDF: R, TT and TRT lobes of a smooth dielectric cylinder
with tilted cuticle scales (Marschner, Jensen, Cammarano, Worley, Hanrahan 2003,
"Light scattering from human hair fibers"; Sadeghi Eqs. 4.7-4.8; spec seed-002 §1.3.5).

    S(wi, wo) = sum_{X in R, TT, TRT} M_X(theta_h) N_X(eta'(theta_d), phi) / cos^2(theta_d)

- ``M_X = g(beta_X^2; theta_h - alpha_X)`` is a unit-integral Gaussian of variance beta_X^2
  (Sadeghi Eq. 4.8), shifted by the cuticle tilt: alpha_R = alpha, alpha_TT = -alpha/2,
  alpha_TRT = -3 alpha/2; beta_TT = beta/2, beta_TRT = 2 beta (MJC03 Table 1) unless given.
- ``N_p(phi) = sum_roots A(p, h) / |2 dPhi/dh|`` (MJC03 §4.2) with the exit azimuth
  Phi(p, h) = 2 p gamma_t - 2 gamma_i + p pi (:func:`fiber.exit_azimuth`), Bravais' index
  eta'(theta_d) for Snell's law in the normal plane (MJC03 App. B), and
  A(0, h) = F, A(p, h) = (1 - F)^2 F^(p-1) T^p. Internal reflections use
  F(1/eta', 1/eta'', gamma_t), which equals the external F(eta', eta'', gamma_i)
  (Fresnel reciprocity), so one F serves all events.
- Roots of Phi(p, h) = phi (mod 2 pi) are found branch-free: Phi(p, .) is monotone on
  [-1, 1] for p = 0, 1 and on the three pieces [-1, -h_c], [-h_c, h_c], [h_c, 1] for
  p = 2 (h_c = sqrt((4 - eta'^2)/3), the TRT caustic; h_c = 0 when eta' >= 2); every piece
  is bisected a fixed number of times (masks mark pieces without a root), then one
  Newton step on the exact Phi restores the implicit-function derivatives w.r.t. phi
  and eta (the bisection itself carries no gradient). p = 0 is in closed form.
- TRT caustic (MJC03 §4.3): the smooth N_2 is faded out around +-phi_c over the caustic
  width w_c and replaced by glints k_G A(2, h_c) Delta h g(w_c; phi -+ phi_c), with
  Delta h = min(Delta h_M, 2 sqrt(2 w_c / |d^2 Phi/dh^2 (h_c)|)); for eta' >= 2 the
  caustics merge at phi_c = 0 and fade over [2, 2 + Delta eta'].
- Eccentricity (TRT only): eta* = ((eta*_1 + eta*_2) + cos(2 phi_h)(eta*_1 - eta*_2)) / 2,
  eta*_1 = 2(eta - 1) a^2 - eta + 2, eta*_2 = 2(eta - 1) a^-2 - eta + 2, replaces eta;
  phi_h = (phi_i + phi_o)/2 is measured from the fiber frame's y axis; eta* is clamped
  to > 1 (extreme eta, a give eta* < 1).

Decisions (static fields; defaults first; their reasons and history: docs/hair.md):

- ``fresnel``: ``"bravais"`` (MJC03: (F_perp(eta') + F_par(eta''))/2 at the 2D angle
  gamma) | ``"exact"`` (unpolarised dielectric Fresnel at the true 3D angle,
  cos = cos(theta_d) cos(gamma_i), true eta, as :mod:`appearance_jax.flatland` uses).
- ``chord``: ``"corrected"`` (T = exp(-sigma_a' 2 cos gamma_t), the chord of a unit circle;
  spec M18 / d'Eon et al. 2011) | ``"mjc03"`` (the printed T = exp(-2 sigma_a' (1 + cos 2
  gamma_t))). In both, sigma_a' = sigma_a / cos theta_t with sin theta_t = sin theta_d / eta.
- ``caustic``: ``"mjc03"`` (fade + glints) | ``"none"`` (the pure smooth-cylinder N_2).
- ``fade``: ``"continuous"`` (t = 1 - smoothstep(2, 2 + Delta eta', eta'), continuous at
  eta' = 2) | ``"literal"`` (t = smoothstep(2, 2 + Delta eta', eta') as printed in the spec).
- ``longitudinal``: ``"mjc03"`` (M_X = g(beta_X^2; theta_h - alpha_X), unit integral in
  theta_h, as printed in MJC03 and Sadeghi Eq. 4.8; it integrates to 2 over theta_o) |
  ``"half"`` (M_X / 2: the smooth limit delta(theta_i + theta_o), albedo <= 1 up to the
  cos^2 theta_d approximation).

Known limitation (d'Eon et al. 2011): a Gaussian in theta_h over cos^2 theta_d does not
conserve energy exactly; there is no white-furnace identity for this model. No sampler
(``sample``/``pdf`` are None). The N_p of the smooth model are singular (integrably) at
caustics; 1/|2 dPhi/dh| is capped at 1e6 there so values stay finite.

| parameter     | default        | range        | unit       | meaning                                        |
|---------------|----------------|--------------|------------|------------------------------------------------|
| eta           | 1.55           | (1, 4]       | 1          | refractive index of the cortex                 |
| sigma_a       | (0.2, 0.3, 0.5)| [0, inf)     | 1/radius   | absorption per unit fiber radius, per band     |
| alpha         | -5 deg         | [-pi/4, pi/4]| rad        | cuticle shift alpha_R (negative: to the root)  |
| beta          | 7.5 deg        | (0, pi/2]    | rad        | longitudinal width (std) beta_R                |
| alpha_tt ...  | None           |              | rad        | override -alpha/2, -3alpha/2, beta/2, 2beta    |
| axis_ratio    | 1              | [0.5, 1]     | 1          | cross-section axis ratio a (TRT only)          |
| glint_scale   | 0.5            | [0, 10]      | 1          | k_G                                            |
| caustic_width | 15 deg         | (0, pi/2]    | rad        | w_c (std of the glint Gaussians)               |
| caustic_fade  | 0.3            | (0, 2]       | 1          | Delta eta'                                     |
| caustic_limit | 0.5            | (0, 2]       | 1          | Delta h_M                                      |

Example::

    import jax.numpy as jnp
    from appearance_jax.bcsdf import marschner
    from appearance_jax.core.frame import fiber_direction
    wi = fiber_direction(0.3, 0.0); wo = fiber_direction(-0.2, 2.5)
    S = marschner.eval(marschner.Params(), wi, wo)        # shape (3,), 1/sr

Validation and the history of the decisions: docs/hair.md.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..core.frame import fiber_angles
from ..core.fusion import materialize
from ..core.model import Model, as_bands, boundary
from ..core.params import Bands, param, params_class, Real, static
from ..core.special import safe_sqrt, smoothstep
from ..core.vec import Vec3
from ..optics.fresnel import fresnel_dielectric, fresnel_dielectric_amplitudes
from .fiber import bravais_eta, bravais_eta_parallel, exit_azimuth, wrap_pi

DEG = math.pi / 180.0
N_BISECT = 60          # bisection steps per monotone piece (2^-60: float64 round-off)
_MAX_DENSITY = 1e6     # cap of 1 / |2 dPhi/dh| at caustics


@params_class
class Params:
    eta: Real = param(1.55, lo=1.0, hi=4.0, lo_open=True, doc="refractive index of the cortex")
    sigma_a: Bands = param((0.2, 0.3, 0.5), lo=0.0, unit="1/radius",
                            doc="absorption per unit fiber radius", bands=True)
    alpha: Real = param(-5.0 * DEG, lo=-math.pi / 4, hi=math.pi / 4, unit="rad",
                          doc="cuticle shift alpha_R of the R lobe (negative: toward the root)")
    beta: Real = param(7.5 * DEG, lo=0.0, hi=math.pi / 2, lo_open=True, unit="rad",
                         doc="longitudinal width (std) beta_R of the R lobe")
    alpha_tt: Real | None = param(None, lo=-math.pi / 4, hi=math.pi / 4, unit="rad", doc="alpha_TT (None: -alpha/2)")
    alpha_trt: Real | None = param(None, lo=-math.pi / 4, hi=math.pi / 4, unit="rad",
                              doc="alpha_TRT (None: -3 alpha/2)")
    beta_tt: Real | None = param(None, lo=0.0, hi=math.pi / 2, lo_open=True, unit="rad", doc="beta_TT (None: beta/2)")
    beta_trt: Real | None = param(None, lo=0.0, hi=math.pi / 2, lo_open=True, unit="rad", doc="beta_TRT (None: 2 beta)")
    axis_ratio: Real = param(1.0, lo=0.5, hi=1.0, doc="cross-section axis ratio a (eccentricity; TRT only)")
    glint_scale: Real = param(0.5, lo=0.0, hi=10.0, doc="glint intensity k_G")
    caustic_width: Real = param(15.0 * DEG, lo=0.0, hi=math.pi / 2, lo_open=True, unit="rad",
                                  doc="caustic width w_c (std of the glint Gaussians)")
    caustic_fade: Real = param(0.3, lo=0.0, hi=2.0, lo_open=True, doc="caustic fade range Delta eta'")
    caustic_limit: Real = param(0.5, lo=0.0, hi=2.0, lo_open=True, doc="caustic intensity limit Delta h_M")
    fresnel: str = static("bravais", choices=("bravais", "exact"), doc="Fresnel: MJC03 Bravais pair or exact 3D")
    chord: str = static("corrected", choices=("corrected", "mjc03"), doc="absorption path length")
    caustic: str = static("mjc03", choices=("mjc03", "none"), doc="TRT caustic fade + glints, or none")
    fade: str = static("continuous", choices=("continuous", "literal"), doc="glint fade above eta' = 2")
    longitudinal: str = static("mjc03", choices=("mjc03", "half"),
                               doc="M_X unit integral in theta_h (MJC03) or in theta_o (halved)")


def lobe_shifts(p: Params):
    """(alpha_R, alpha_TT, alpha_TRT), (beta_R, beta_TT, beta_TRT) in radians (MJC03 Table 1)."""
    a, b = p.alpha, p.beta
    al = (a, -0.5 * a if p.alpha_tt is None else p.alpha_tt, -1.5 * a if p.alpha_trt is None else p.alpha_trt)
    be = (b, 0.5 * b if p.beta_tt is None else p.beta_tt, 2.0 * b if p.beta_trt is None else p.beta_trt)
    return al, be


def gaussian(x, std):
    """Unit-integral Gaussian g(std^2; x) (Sadeghi Eq. 4.8)."""
    return jnp.exp(-0.5 * (x / std) ** 2) / (std * math.sqrt(2.0 * math.pi))


def eccentric_eta(eta, axis_ratio, phi_h):
    """eta* of an elliptical fiber (MJC03 §4.3), used for TRT only."""
    a2 = axis_ratio * axis_ratio
    e1 = 2.0 * (eta - 1.0) * a2 - eta + 2.0
    e2 = 2.0 * (eta - 1.0) / a2 - eta + 2.0
    # clamped to > 1: extreme (eta, a) pairs (e.g. eta = 3.5, a = 0.5) give eta* < 1
    return jnp.maximum(0.5 * ((e1 + e2) + jnp.cos(2.0 * phi_h) * (e1 - e2)), 1.0 + 1e-6)


# ---------------------------------------------------------------------------------------
# ray optics of a circle


# Phi(p, h) = 2 p gamma_t - 2 gamma_i + p pi (unwrapped), the shared fiber convention
exit_phi = exit_azimuth


def exit_phi_slope_scaled(p, h, eta_p):
    """cos(gamma_i) dPhi/dh = 2 p cos gamma_i / (eta' cos gamma_t) - 2 (finite at h = +-1)."""
    cgi = safe_sqrt(1.0 - h * h)
    cgt_e = safe_sqrt(eta_p * eta_p - h * h)  # eta' cos gamma_t
    return 2.0 * p * cgi / jnp.maximum(cgt_e, 1e-300) - 2.0


def _dphi_dh(p, h, eta_p):
    cgi = jnp.maximum(safe_sqrt(1.0 - h * h), 1e-12)
    return exit_phi_slope_scaled(p, h, eta_p) / cgi


def _d2phi_dh2(p, h, eta_p):
    a = jnp.maximum(eta_p * eta_p - h * h, 1e-300)
    b = jnp.maximum(1.0 - h * h, 1e-300)
    return 2.0 * p * h / a ** 1.5 - 2.0 * h / b ** 1.5


def caustic_offset(eta_p):
    """h_c = sqrt((4 - eta'^2)/3) where dPhi(2, h)/dh = 0 (0 when eta' >= 2)."""
    return safe_sqrt((4.0 - eta_p * eta_p) / 3.0)


def _bisect(fn, lo, hi, n_iter):
    flo = fn(lo)

    def body(_, c):
        a, b, fa = c
        m = 0.5 * (a + b)
        fm = fn(m)
        left = (fa >= 0) != (fm >= 0)
        return jnp.where(left, a, m), jnp.where(left, m, b), jnp.where(left, fa, fm)

    a, b, _ = jax.lax.fori_loop(0, n_iter, body, (lo, hi, flo))
    return 0.5 * (a + b)


class Roots(NamedTuple):
    h: jax.Array       # (3,) + shape: candidate roots (one slot per monotone piece)
    valid: jax.Array   # bool, same shape


def roots(p: int, phi, eta_p, n_iter: int = N_BISECT) -> Roots:
    """Offsets h in [-1, 1] with Phi(p, h) = phi (mod 2 pi), branch-free.

    ``p`` is a Python int (0, 1 or 2); ``phi`` and ``eta_p`` (Bravais' eta') broadcast.
    Three slots: p = 0 and 1 use slot 0 only; p = 2 uses one slot per monotone piece.
    The returned h are differentiable in phi and eta_p (a Newton step on the bisected root).
    """
    phi, eta_p = jnp.broadcast_arrays(jnp.asarray(phi, dtype=jnp.result_type(float)),
                                      jnp.asarray(eta_p, dtype=jnp.result_type(float)))
    if p == 0:
        h = jnp.sin(-0.5 * wrap_pi(phi))
        z = jnp.zeros_like(h)
        f = jnp.zeros(h.shape, bool)
        return Roots(jnp.stack([h, z, z]), jnp.stack([jnp.ones(h.shape, bool), f, f]))
    # target in the unwrapped range of Phi(p, .): [0, 2 pi) for p = 1, [p pi - pi, p pi + pi) else
    target = p * jnp.pi + wrap_pi(phi - p * jnp.pi)
    eta_s = jax.lax.stop_gradient(eta_p)
    t_s = jax.lax.stop_gradient(target)
    one = jnp.ones_like(phi)
    if p == 1:
        pieces = [(-one, one)]
    else:
        hc = jax.lax.stop_gradient(caustic_offset(eta_p))
        pieces = [(-one, -hc), (-hc, hc), (hc, one)]
    lo = jnp.stack([a for a, _ in pieces])
    hi = jnp.stack([b for _, b in pieces])
    fn = lambda h: exit_phi(p, h, eta_s) - t_s  # noqa: E731  (all pieces in one bisection)
    valid = (fn(lo) >= 0) != (fn(hi) >= 0)
    hb = jax.lax.stop_gradient(_bisect(fn, lo, hi, n_iter))
    slope = _dphi_dh(p, hb, eta_p)
    ok = jnp.abs(slope) > 1e-6
    step = (exit_phi(p, hb, eta_p) - target) / jnp.where(ok, slope, 1.0)
    h = jnp.clip(hb - jnp.where(ok, step, 0.0), -1.0, 1.0)
    hs, vs = list(h), list(valid)
    return Roots(materialize(jnp.stack(hs)), jnp.stack(vs))


def fresnel_fiber(h, eta, theta_d, mode: str = "bravais"):
    """Fresnel reflectance of the fiber surface at offset h (MJC03 App. B).

    ``"bravais"``: (F_perp(eta', gamma_i) + F_par(eta'', gamma_i))/2 in the normal plane;
    ``"exact"``: unpolarised Fresnel at cos(theta_d) cos(gamma_i) with the true eta.
    """
    cgi = safe_sqrt(1.0 - h * h)
    if mode == "exact":
        return fresnel_dielectric(jnp.cos(theta_d) * cgi, eta)[0]
    r_s = fresnel_dielectric_amplitudes(cgi, bravais_eta(eta, theta_d))[0]
    r_p = fresnel_dielectric_amplitudes(cgi, bravais_eta_parallel(eta, theta_d))[1]
    return 0.5 * (r_s * r_s + r_p * r_p)


def attenuation(p: int, h, eta, theta_d, sigma_a, fresnel: str = "bravais", chord: str = "corrected"):
    """A(p, h): Fresnel and absorption along lobe p (MJC03 §4.2). ``sigma_a`` has a trailing
    bands axis; the result has shape broadcast(h, theta_d) + bands."""
    h = jnp.asarray(h)
    sigma_a = as_bands(sigma_a)
    F = fresnel_fiber(h, eta, theta_d, fresnel)[..., None]
    if p == 0:
        return F * jnp.ones_like(sigma_a)
    eta_p = bravais_eta(eta, theta_d)
    sin_gt = jnp.clip(h / eta_p, -1.0, 1.0)
    cos_gt = safe_sqrt(1.0 - sin_gt * sin_gt)
    sin_tt = jnp.sin(theta_d) / eta
    cos_tt = safe_sqrt(1.0 - sin_tt * sin_tt)
    length = 2.0 * cos_gt if chord == "corrected" else 4.0 * cos_gt * cos_gt
    T = jnp.exp(-sigma_a * (length / cos_tt)[..., None])
    return (1.0 - F) ** 2 * F ** (p - 1) * T ** p


def smooth_azimuthal(p: int, phi, eta, theta_d, sigma_a, fresnel="bravais", chord="corrected"):
    """N_p(phi) of the smooth circular fiber (no caustic treatment): sum over the roots of
    A(p, h) / |2 dPhi/dh|; shape broadcast(phi, theta_d) + bands."""
    eta_p = bravais_eta(eta, theta_d)
    r = roots(p, phi, eta_p)
    dens = jnp.abs(exit_phi_slope_scaled(p, r.h, eta_p))
    cgi = safe_sqrt(1.0 - r.h * r.h)
    d = 2.0 * dens
    small = d * _MAX_DENSITY <= cgi  # caustic: cap (double where keeps the gradient finite)
    inv = jnp.where(small, _MAX_DENSITY, cgi / jnp.where(small, 1.0, d))
    A = attenuation(p, r.h, eta, theta_d, sigma_a, fresnel, chord)
    w = jnp.where(r.valid, inv, 0.0)[..., None]
    return jnp.sum(A * w, axis=0)


def trt_caustic(eta, theta_d, sigma_a, caustic_width, caustic_fade, caustic_limit, glint_scale,
                fresnel="bravais", chord="corrected", fade="continuous"):
    """(phi_c, t, glint amplitude k_G A(2, h_c) Delta h) of the MJC03 caustic model."""
    eta_p = bravais_eta(eta, theta_d)
    below = eta_p < 2.0
    hc = caustic_offset(eta_p)
    phi_c = materialize(jnp.where(below, wrap_pi(exit_phi(2, hc, eta_p)), 0.0))
    d2 = jnp.abs(_d2phi_dh2(2, hc, eta_p))
    dh_c = 2.0 * safe_sqrt(2.0 * caustic_width / jnp.maximum(d2, 1e-12))
    dh = jnp.where(below, jnp.minimum(caustic_limit, dh_c), caustic_limit)
    ss = smoothstep((eta_p - 2.0) / caustic_fade)
    t_above = 1.0 - ss if fade == "continuous" else ss
    t = jnp.where(below, 1.0, t_above)
    A = attenuation(2, hc, eta, theta_d, sigma_a, fresnel, chord)
    return phi_c, t, glint_scale * A * dh[..., None]


def azimuthal(p: Params, phi, theta_d, phi_h=0.0):
    """(N_R, N_TT, N_TRT) stacked on axis 0; shape (3,) + broadcast + bands."""
    phi, theta_d, phi_h = jnp.broadcast_arrays(*(jnp.asarray(v, dtype=jnp.result_type(float))
                                                 for v in (phi, theta_d, phi_h)))
    sa = as_bands(p.sigma_a)
    n_r = smooth_azimuthal(0, phi, p.eta, theta_d, sa, p.fresnel, p.chord)
    n_tt = smooth_azimuthal(1, phi, p.eta, theta_d, sa, p.fresnel, p.chord)
    eta3 = eccentric_eta(p.eta, p.axis_ratio, phi_h)
    n_trt = smooth_azimuthal(2, phi, eta3, theta_d, sa, p.fresnel, p.chord)
    if p.caustic == "mjc03":
        phi_c, t, glint = trt_caustic(eta3, theta_d, sa, p.caustic_width, p.caustic_fade, p.caustic_limit,
                                      p.glint_scale, p.fresnel, p.chord, p.fade)
        w = p.caustic_width
        g0 = 1.0 / (w * math.sqrt(2.0 * math.pi))
        gm = gaussian(wrap_pi(phi - phi_c), w)
        gp = gaussian(wrap_pi(phi + phi_c), w)
        fade_f = ((1.0 - t * gm / g0) * (1.0 - t * gp / g0))[..., None]
        n_trt = n_trt * fade_f + (t * (gm + gp))[..., None] * glint
    return jnp.stack([n_r, n_tt, n_trt])


def longitudinal(p: Params, theta_h):
    """(M_R, M_TT, M_TRT) = g(beta_X^2; theta_h - alpha_X), stacked on axis 0."""
    al, be = lobe_shifts(p)
    k = 0.5 if p.longitudinal == "half" else 1.0
    return jnp.stack([k * gaussian(theta_h - a, b) for a, b in zip(al, be)])


def lobes(p: Params, theta_i, theta_o, phi, phi_h=0.0):
    """Per-lobe S_X = M_X N_X / cos^2 theta_d, shape (3,) + broadcast + bands (1/sr)."""
    theta_i, theta_o, phi, phi_h = jnp.broadcast_arrays(*(jnp.asarray(v, dtype=jnp.result_type(float))
                                                          for v in (theta_i, theta_o, phi, phi_h)))
    th_h = 0.5 * (theta_i + theta_o)
    th_d = 0.5 * (theta_o - theta_i)
    c2 = jnp.cos(th_d) ** 2
    ok = c2 > 1e-12
    N = azimuthal(p, phi, th_d, phi_h)
    M = longitudinal(p, th_h)
    return jnp.where(ok[None, ..., None], M[..., None] * N / jnp.where(ok, c2, 1.0)[None, ..., None], 0.0)


def _eval(p: Params, wi: Vec3, wo: Vec3):
    # the angles (atan2 polynomials) feed every lobe: computed once (core.fusion.materialize)
    th_i, ph_i, th_o, ph_o = materialize((*fiber_angles(wi), *fiber_angles(wo)))
    return jnp.sum(lobes(p, th_i, th_o, ph_o - ph_i, 0.5 * (ph_i + ph_o)), axis=0)


eval = boundary(_eval, Params)

MODEL = Model(
    name="marschner_hair",
    kind="bcsdf",
    Params=Params,
    eval=eval,
    sample=None,
    pdf=None,
    summary="Marschner 2003 hair: R/TT/TRT, Gaussian M(theta_h), smooth-cylinder N_p with caustic glints",
    source="Marschner et al. 2003; Sadeghi 2011 Eqs. 4.7-4.8",
    reciprocal=True,
    transmissive=True,
)
