"""Sadeghi's thread BCSDF: a rough dielectric cylinder with oriented volume scattering
(Sadeghi 2011 §5.5.3, Eqs. 5.6-5.11, Table 5.1; Sadeghi et al. 2013). Spec seed-002 §1.4.2.

A thread of tangent t, local normal n and binormal v = t x n (any right-handed orthonormal
triple; for an isolated thread n is arbitrary in the normal plane). For a direction w:
sin theta = w.t (inclination from the normal plane, theta = pi/2 along t) and phi is its
azimuth about t measured from n. With theta_h = (theta_i + theta_r)/2,
phi_d = phi_i - phi_r wrapped to [-pi, pi]:

    f_rs = F_r(eta, arccos(cos((theta_i - theta_r)/2) cos(phi_d/2))) cos(phi_d/2) g(gamma_s, theta_h)   (5.7, 5.8)
    f_rv = F ((1 - k_d) g(gamma_v, theta_h) + k_d) / (cos theta_i + cos theta_r) A                   (5.9)
    f_s  = (f_rs + f_rv) / cos^2 theta_d                                                            (5.11)

g(gamma, x) = exp(-x^2 / (2 gamma^2)) / (sqrt(2 pi) gamma) is the *unit-area* Gaussian, in
1/rad, with x and gamma in radians (decision D-C3; Sadeghi Table 5.2 states gamma in degrees: the
public parameters are in **degrees** and are converted once, here, with the amplitudes of a
radian Gaussian). f_s is in 1/sr per unit thread length, used with the curve radiance
integral L_r = int f_s L_i cos theta_i dw_i (Sadeghi Eq. 5.6).

Decisions (each a static option, spec §6):

- D-C1 ``theta_d``: ``"half"`` (default): theta_d = (theta_i - theta_r)/2 in 1/cos^2 theta_d,
  Marschner's solid-angle factor of the specular cone. ``"full"``: the literal
  theta_i - theta_r of Sadeghi Eq. 5.2, whose cos^2 vanishes at theta_i = -theta_r = 45 deg, i.e. *on*
  the specular cone (a non-physical singularity: f_s is clamped to 0 where cos^2 < 1e-12).
  Sadeghi Eq. 5.8 uses theta_d/2 with the full difference, i.e. the half difference, in both options.
- D-C2 ``volume_fresnel``: ``"longitudinal"`` (default): F = (1 - F_r(eta, |theta_i|))
  (1 - F_r(eta, |theta_r|)) (Stokes: F_t(1/eta, w_r') = F_t(eta, w_r); reciprocal).
  ``"eq58"``: both factors at the Sadeghi Eq. 5.8 angle, (1 - F_r(eta, theta_58))^2.
- D-C3: gamma in degrees at this boundary, radians inside g.

F_r is the unpolarised dielectric Fresnel reflectance
(:func:`appearance_jax.optics.fresnel.fresnel_dielectric`). f_s is reciprocal (symmetric in
w_i, w_r) in both options. Directions exactly along t (cos theta = 0) give a finite value
(the volume denominator is clamped at 1e-6; cos^2 theta_d = 1 there for "half").

| parameter | default   | range        | unit | meaning                                       |
|-----------|-----------|--------------|------|-----------------------------------------------|
| eta       | 1.46      | [1, 3]       | 1    | refractive index (Sadeghi Table 2.1)          |
| albedo    | 0.3       | [0, 1]       | 1    | A, coloured volume albedo, per band           |
| k_d       | 0.3       | [0, 1]       | 1    | isotropic fraction of the volume scattering   |
| gamma_s   | 12        | (0, 90]      | deg  | std of the surface Gaussian                   |
| gamma_v   | 24        | (0, 90]      | deg  | std of the volume Gaussian                    |
| theta_d   | "half"    | half, full   | -    | D-C1                                          |
| volume_fresnel | "longitudinal" | longitudinal, eq58 | - | D-C2                           |

Defaults are the Linen thread of Sadeghi Table 5.2 (without its colour). Example::

    from appearance_jax.bcsdf import thread
    p = thread.linen()
    f = thread.eval_angles(p, 0.5236, -0.5236, 0.0)      # (3,) 1/sr: K2 (0.1339, 0.2583, 0.2997)
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from ..core.model import Model, as_bands, boundary
from ..core.params import Bands, param, params_class, Real, static
from ..core.special import safe_sqrt
from ..core.vec import Vec3, dot
from ..optics.fresnel import fresnel_dielectric

DEG = math.pi / 180.0
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
THETA_D = ("half", "full")
VOLUME_FRESNEL = ("longitudinal", "eq58")


@params_class
class Params:
    eta: Real = param(1.46, lo=1.0, hi=3.0, doc="refractive index of the thread")
    albedo: Bands = param(0.3, lo=0.0, hi=1.0, doc="A: coloured volume albedo", bands=True)
    k_d: Real = param(0.3, lo=0.0, hi=1.0, doc="isotropic fraction of the volume scattering")
    gamma_s: Real = param(12.0, lo=0.0, hi=90.0, lo_open=True, unit="deg", doc="std of the surface Gaussian")
    gamma_v: Real = param(24.0, lo=0.0, hi=90.0, lo_open=True, unit="deg", doc="std of the volume Gaussian")
    theta_d: str = static("half", choices=THETA_D, doc="D-C1: theta_d in 1/cos^2 theta_d (Sadeghi Eq. 5.11)")
    volume_fresnel: str = static("longitudinal", choices=VOLUME_FRESNEL,
                                 doc="D-C2: F of the volume term (Sadeghi Eq. 5.10)")


def gaussian(gamma, x):
    """Unit-area Gaussian g(gamma, x) of std ``gamma`` (radians), in 1/rad (Sadeghi Eq. 5.7)."""
    return _INV_SQRT_2PI / gamma * jnp.exp(-0.5 * (x / gamma) ** 2)


def _fresnel(cos_i, eta):
    return fresnel_dielectric(jnp.clip(cos_i, 0.0, 1.0), eta)[0]


def terms_from_angles(p: Params, sin_i, cos_i, sin_r, cos_r, cos_phi_d, *, eta=None, albedo=None, k_d=None,
                      gamma_s=None, gamma_v=None):
    """(f_rs, f_rv, 1/cos^2 theta_d) from the sines/cosines of the inclinations and cos phi_d.

    The kernel shared with :mod:`appearance_jax.bsdf.cloth`: scalar parameters may be given
    explicitly (already broadcast, gammas in **radians**) to override ``p``'s fields.
    f_rs has no bands axis; f_rv and the result carry a trailing bands axis.
    """
    eta = p.eta if eta is None else eta
    albedo = as_bands(p.albedo) if albedo is None else albedo
    k_d = p.k_d if k_d is None else k_d
    gamma_s = p.gamma_s * DEG if gamma_s is None else gamma_s
    gamma_v = p.gamma_v * DEG if gamma_v is None else gamma_v
    theta_i = jnp.arctan2(sin_i, cos_i)
    theta_r = jnp.arctan2(sin_r, cos_r)
    theta_h = 0.5 * (theta_i + theta_r)
    # cos(phi_d / 2) >= 0 for phi_d in [-pi, pi] (half-angle formula, no atan2 needed)
    cos_half_phi = safe_sqrt(0.5 * (1.0 + cos_phi_d))
    cos_half_td = jnp.cos(0.5 * (theta_i - theta_r))  # Sadeghi Eq. 5.8: theta_d / 2 of the full difference
    cos_58 = cos_half_td * cos_half_phi
    f_rs = _fresnel(cos_58, eta) * cos_half_phi * gaussian(gamma_s, theta_h)
    if p.volume_fresnel == "longitudinal":
        F = (1.0 - _fresnel(cos_i, eta)) * (1.0 - _fresnel(cos_r, eta))
    else:
        F = (1.0 - _fresnel(cos_58, eta)) ** 2
    lobe = (1.0 - k_d) * gaussian(gamma_v, theta_h) + k_d
    f_rv = (F * lobe / jnp.maximum(cos_i + cos_r, 1e-6))[..., None] * albedo
    if p.theta_d == "half":
        c2 = cos_half_td * cos_half_td
    else:
        c = jnp.cos(theta_i - theta_r)
        c2 = c * c
    ok = c2 > 1e-12
    inv_c2 = jnp.where(ok, 1.0 / jnp.where(ok, c2, 1.0), 0.0)
    return f_rs, f_rv, inv_c2


def from_dots(p: Params, it, in_, iv, ot, on, ov, **overrides):
    """f_s (bands last) from the dot products of w_i and w_r with (t, n, v) (Sadeghi Eq. 5.11)."""
    sin_i, sin_r = jnp.clip(it, -1.0, 1.0), jnp.clip(ot, -1.0, 1.0)
    pi2, pr2 = in_ * in_ + iv * iv, on * on + ov * ov
    cos_i, cos_r = safe_sqrt(pi2), safe_sqrt(pr2)
    # cos phi_d = normalised projections onto the normal plane; 1 when a direction lies along t
    den = cos_i * cos_r
    ok = den > 1e-12
    cos_phi_d = jnp.where(ok, (in_ * on + iv * ov) / jnp.where(ok, den, 1.0), 1.0)
    f_rs, f_rv, inv_c2 = terms_from_angles(p, sin_i, cos_i, sin_r, cos_r, jnp.clip(cos_phi_d, -1.0, 1.0),
                                           **overrides)
    return (f_rs[..., None] + f_rv) * inv_c2[..., None]


def _eval(p: Params, t: Vec3, n: Vec3, v: Vec3, wi: Vec3, wo: Vec3):
    return from_dots(p, dot(wi, t), dot(wi, n), dot(wi, v), dot(wo, t), dot(wo, n), dot(wo, v))


def _eval_angles(p: Params, theta_i, theta_r, phi_d):
    f_rs, f_rv, inv_c2 = terms_from_angles(p, jnp.sin(theta_i), jnp.cos(theta_i), jnp.sin(theta_r),
                                           jnp.cos(theta_r), jnp.cos(phi_d))
    return (f_rs[..., None] + f_rv) * inv_c2[..., None]


def _surface_term(p: Params, theta_i, theta_r, phi_d):
    return terms_from_angles(p, jnp.sin(theta_i), jnp.cos(theta_i), jnp.sin(theta_r), jnp.cos(theta_r),
                             jnp.cos(phi_d))[0]


def _volume_term(p: Params, theta_i, theta_r, phi_d):
    return terms_from_angles(p, jnp.sin(theta_i), jnp.cos(theta_i), jnp.sin(theta_r), jnp.cos(theta_r),
                             jnp.cos(phi_d))[1]


eval = boundary(_eval, Params)
"""f_s(t, w_i, w_r) in 1/sr (bands last) for a thread frame (t, n, v = t x n) given as Vec3 (Sadeghi Eq. 5.11)."""
eval_angles = boundary(_eval_angles, Params)
"""f_s from (theta_i, theta_r, phi_d) in radians (Sadeghi Eq. 5.11)."""
surface_term = boundary(_surface_term, Params)
"""f_rs of Sadeghi Eq. 5.7 (no bands axis, not divided by cos^2 theta_d)."""
volume_term = boundary(_volume_term, Params)
"""f_rv of Sadeghi Eq. 5.9 (bands last, not divided by cos^2 theta_d)."""


def linen() -> Params:
    """The Linen Plain thread of Sadeghi Table 5.2: eta 1.46, A = 0.3 (0.2, 0.8, 1.0), k_d 0.3, gamma 12/24 deg."""
    return Params(eta=1.46, albedo=(0.06, 0.24, 0.3), k_d=0.3, gamma_s=12.0, gamma_v=24.0)


def _eval_fiber(p: Params, wi: Vec3, wo: Vec3):
    # the fiber frame of appearance_jax.bcsdf: t = x, n = y, v = t x n = z
    return from_dots(p, wi.x, wi.y, wi.z, wo.x, wo.y, wo.z)


eval_fiber = boundary(_eval_fiber, Params)
"""f_s in 1/sr (bands last) for directions in the fiber frame (x = thread tangent; Sadeghi Eq. 5.11)."""

MODEL = Model(
    name="cloth_thread",
    kind="bcsdf",
    Params=Params,
    eval=eval_fiber,
    sample=None,
    pdf=None,
    summary="Sadeghi's cloth thread: rough dielectric cylinder surface lobe + oriented volume scattering",
    source="Sadeghi 2011 Sec. 5.5.3, Eqs. 5.6-5.11, Table 5.1",
    reciprocal=True,
    transmissive=True,
)
