"""Sadeghi's artist-friendly hair: single-scattering pseudo functions (Sadeghi Eqs. 4.9-4.16),
spec seed-002 §1.3.7-1.3.8. The dual-scattering approximation for a hair volume built on these
lobes (Sadeghi §4.7, after Zinke et al. 2008) is :mod:`appearance_jax.bcsdf.dual_scattering`.

Single scattering (Sadeghi Eqs. 4.9-4.16), with theta_h = (theta_i + theta_o)/2,
theta_d = (theta_o - theta_i)/2 (Marschner's half/difference angles) and |phi| wrapped to
[0, pi] (decision D-H9):

    M'_X = g'(beta_X^2; theta_h - alpha_X)          unit *height* Gaussian (Sadeghi Eq. 4.9)
    N'_R = cos(phi/2)                                Kim's approximation, no Fresnel (4.10)
    N'_TT = g'(gamma_TT^2; pi - phi)                 (4.11)
    N'_TRT = cos(phi/2) + I_g g'(gamma_g^2; G_angle - phi)   (4.12-4.14)
    f'_s = sum_X C_X I_X M'_X N'_X / cos^2 theta_d   (4.15-4.16; not energy conserving)

AFC parameters (Sadeghi Table B.1 names in brackets; defaults are the spec §1.3.8 proposals, D-H8;
"hair colour" = exp(-2 sigma_a) of the RSL default sigma_a = (0.2, 0.3, 0.5)):

| parameter       | default            | range       | unit | meaning                                      |
|-----------------|--------------------|-------------|------|----------------------------------------------|
| color_r         | (1, 1, 1)          | [0, inf)    | 1    | C_R [specular colour]                        |
| intensity_r     | 1                  | [0, inf)    | 1    | I_R [specular scale]                         |
| alpha_r         | -5 deg             | [-pi/4, pi/4] | rad | alpha_R [specular angular offset]          |
| beta_r          | 7.5 deg            | (0, pi/2]   | rad  | beta_R, std [specular roughness]             |
| color_tt        | (0.670, 0.549, 0.368) | [0, inf) | 1    | C_TT [transmission colour]                   |
| intensity_tt    | 1                  | [0, inf)    | 1    | I_TT [transmission scale]                    |
| alpha_tt        | 2.5 deg            |             | rad  | alpha_TT [transmission offset]               |
| beta_tt         | 3.75 deg           |             | rad  | beta_TT [transmission roughness]             |
| gamma_tt        | 30 deg             | (0, pi]     | rad  | gamma_TT, azimuthal std [transmission spread]|
| color_trt       | (0.670, 0.549, 0.368) | [0, inf) | 1    | C_TRT [subspecular colour]                   |
| intensity_trt   | 1                  | [0, inf)    | 1    | I_TRT [subspecular scale]                    |
| alpha_trt       | 7.5 deg            |             | rad  | alpha_TRT [subspecular offset]               |
| beta_trt        | 15 deg             |             | rad  | beta_TRT [subspecular roughness]             |
| glint_intensity | 0.5                | [0, inf)    | 1    | I_g, relative to TRT                         |
| glint_width     | 5 deg              | (0, pi]     | rad  | gamma_g, azimuthal std ("frequency")         |
| glint_angle     | 37.5 deg           | [0, pi/2]   | rad  | G_angle (thesis: U(30, 45) deg per strand,   |
|                 |                    |             |      | :func:`random_glint_angle`)                  |

The decisions D-H1 ... D-H9 (the spec's register), their history and the validation: docs/hair.md.

Example::

    from appearance_jax.bcsdf import sadeghi
    from appearance_jax.core.frame import fiber_direction
    wi = fiber_direction(0.3, 0.0); wo = fiber_direction(-0.2, 2.5)
    f = sadeghi.eval(sadeghi.Params(), wi, wo)                      # single scattering, (3,), 1/sr
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..core.frame import fiber_angles
from ..core.model import Model, as_bands, boundary
from ..core.params import Bands, param, params_class, Real, validate
from ..core.quadrature import gauss_legendre
from ..core.special import safe_sqrt
from ..core.vec import Vec3
from . import marschner
from .fiber import exit_azimuth, wrap_pi

DEG = math.pi / 180.0
HAIR_COLOR = tuple(float(np.exp(-2.0 * s)) for s in (0.2, 0.3, 0.5))


@params_class
class Params:
    color_r: Bands = param((1.0, 1.0, 1.0), lo=0.0, doc="C_R specular colour", bands=True)
    intensity_r: Real = param(1.0, lo=0.0, doc="I_R specular scale")
    alpha_r: Real = param(-5.0 * DEG, lo=-math.pi / 4, hi=math.pi / 4, unit="rad", doc="alpha_R specular offset")
    beta_r: Real = param(7.5 * DEG, lo=0.0, hi=math.pi / 2, lo_open=True, unit="rad",
                           doc="beta_R specular roughness (std)")
    color_tt: Bands = param(HAIR_COLOR, lo=0.0, doc="C_TT transmission colour", bands=True)
    intensity_tt: Real = param(1.0, lo=0.0, doc="I_TT transmission scale")
    alpha_tt: Real = param(2.5 * DEG, lo=-math.pi / 4, hi=math.pi / 4, unit="rad", doc="alpha_TT offset")
    beta_tt: Real = param(3.75 * DEG, lo=0.0, hi=math.pi / 2, lo_open=True, unit="rad",
                            doc="beta_TT transmission roughness (std)")
    gamma_tt: Real = param(30.0 * DEG, lo=0.0, hi=math.pi, lo_open=True, unit="rad",
                             doc="gamma_TT transmission spread (azimuthal std)")
    color_trt: Bands = param(HAIR_COLOR, lo=0.0, doc="C_TRT subspecular colour", bands=True)
    intensity_trt: Real = param(1.0, lo=0.0, doc="I_TRT subspecular scale")
    alpha_trt: Real = param(7.5 * DEG, lo=-math.pi / 4, hi=math.pi / 4, unit="rad", doc="alpha_TRT offset")
    beta_trt: Real = param(15.0 * DEG, lo=0.0, hi=math.pi / 2, lo_open=True, unit="rad",
                             doc="beta_TRT subspecular roughness (std)")
    glint_intensity: Real = param(0.5, lo=0.0, doc="I_g glint intensity relative to TRT")
    glint_width: Real = param(5.0 * DEG, lo=0.0, hi=math.pi, lo_open=True, unit="rad",
                                doc="gamma_g azimuthal std of the glints")
    glint_angle: Real = param(37.5 * DEG, lo=0.0, hi=math.pi / 2, unit="rad",
                                doc="G_angle half angle between the glints")


def random_glint_angle(key, shape=()):
    """G_angle ~ U(30 deg, 45 deg) per strand (L1695)."""
    return jax.random.uniform(key, shape, minval=30.0 * DEG, maxval=45.0 * DEG)


def unit_gaussian(x, std):
    """g'(std^2; x) = exp(-x^2 / (2 std^2)): unit height (Sadeghi Eq. 4.9)."""
    return jnp.exp(-0.5 * (x / std) ** 2)


def _abs_phi(phi):
    return jnp.abs(wrap_pi(phi))


def colors(p: Params):
    """C_X I_X per lobe, shape (3, bands)."""
    cr, ctt, ctrt = jnp.broadcast_arrays(as_bands(p.color_r), as_bands(p.color_tt), as_bands(p.color_trt))
    return jnp.stack([cr * p.intensity_r, ctt * p.intensity_tt, ctrt * p.intensity_trt])


def shifts(p: Params):
    """(alpha_R, alpha_TT, alpha_TRT), (beta_R, beta_TT, beta_TRT)."""
    return (p.alpha_r, p.alpha_tt, p.alpha_trt), (p.beta_r, p.beta_tt, p.beta_trt)


def longitudinal(p: Params, theta_h, extra_var=0.0):
    """(M'_R, M'_TT, M'_TRT): unit-height g'(beta_X^2 + extra_var; theta_h - alpha_X)."""
    al, be = shifts(p)
    return jnp.stack([unit_gaussian(theta_h - a, safe_sqrt(b * b + extra_var)) for a, b in zip(al, be)])


def azimuthal(p: Params, phi):
    """(N'_R, N'_TT, N'_TRT) of Sadeghi Eqs. 4.10-4.14 with |phi| wrapped to [0, pi] (D-H9)."""
    a = _abs_phi(phi)
    c = jnp.cos(0.5 * a)
    n_tt = unit_gaussian(jnp.pi - a, p.gamma_tt)
    n_trt = c + p.glint_intensity * unit_gaussian(p.glint_angle - a, p.glint_width)
    return jnp.stack([c, n_tt, n_trt])


def lobes(p: Params, theta_i, theta_o, phi):
    """f'_X = C_X I_X M'_X N'_X / cos^2 theta_d, shape (3,) + broadcast + bands (1/sr)."""
    theta_i, theta_o, phi = jnp.broadcast_arrays(*(jnp.asarray(v, dtype=jnp.result_type(float))
                                                   for v in (theta_i, theta_o, phi)))
    th_h = 0.5 * (theta_i + theta_o)
    c2 = jnp.cos(0.5 * (theta_o - theta_i)) ** 2
    ok = c2 > 1e-12
    MN = longitudinal(p, th_h) * azimuthal(p, phi) / jnp.where(ok, c2, 1.0)
    MN = jnp.where(ok, MN, 0.0)
    C = colors(p)
    return MN[..., None] * C.reshape((3,) + (1,) * th_h.ndim + (-1,))


def _eval(p: Params, wi: Vec3, wo: Vec3):
    th_i, ph_i = fiber_angles(wi)
    th_o, ph_o = fiber_angles(wo)
    return jnp.sum(lobes(p, th_i, th_o, ph_o - ph_i), axis=0)


eval = boundary(_eval, Params)


# ---------------------------------------------------------------------------------------
# physical -> artist mapping (spec §1.3.8b, a proposal: the thesis gives none)


def afc_from_marschner(mp: marschner.Params, theta_d: float = 0.0, glint_angle=None) -> Params:
    """Closed-form artist parameters that reproduce the MJC03 lobes at ``theta_d`` (spec §1.3.8b):
    alpha/beta carry over; C_X I_X = (physical peak) / (sqrt(2 pi) beta_X) (unit height vs unit
    area: the spec's "I_X <- I_X sqrt(2 pi beta^2)" is the inverse direction); R: N_R(0) = F(gamma_i = 0)/4 (the Fresnel falloff with phi is lost); TT: the value
    N_TT(pi) and gamma_TT from the second moment of N_TT about pi; TRT: the off-caustic level
    N_2(0) of the smooth fiber, G_angle = phi_c (caustic azimuth), gamma_g = w_c,
    I_g = k_G A(2, h_c) Delta h g(w_c; 0) / level (band mean). Intensities are put in the
    I_X, colours in the C_X. Not jittable (builds a Params eagerly)."""
    validate(mp, marschner.Params)
    al, be = marschner.lobe_shifts(mp)
    sa = as_bands(mp.sigma_a)
    td = jnp.asarray(theta_d, dtype=jnp.result_type(float))
    eta_p = marschner.bravais_eta(mp.eta, td)
    n_r = marschner.smooth_azimuthal(0, 0.0, mp.eta, td, sa, mp.fresnel, mp.chord)
    n_tt = marschner.smooth_azimuthal(1, jnp.pi, mp.eta, td, sa, mp.fresnel, mp.chord)
    n_trt = marschner.smooth_azimuthal(2, 0.0, mp.eta, td, sa, mp.fresnel, mp.chord)
    # second moment of N_TT about pi, by quadrature over h: int N (phi - pi)^2 dphi = 1/2 int A (Phi - pi)^2 dh
    u, wu = gauss_legendre(256, -math.pi / 2, math.pi / 2)
    h = jnp.asarray(np.sin(u))
    wh = jnp.asarray(wu * np.cos(u))
    A1 = marschner.attenuation(1, h, mp.eta, td, sa, mp.fresnel, mp.chord)
    d2 = (exit_azimuth(1, h, eta_p) - jnp.pi) ** 2
    m2 = jnp.sum(wh[:, None] * A1 * d2[:, None], 0) / jnp.sum(wh[:, None] * A1, 0)
    gamma_tt = float(jnp.mean(jnp.sqrt(m2)))
    phi_c, t, glint = marschner.trt_caustic(mp.eta, td, sa, mp.caustic_width, mp.caustic_fade, mp.caustic_limit,
                                            mp.glint_scale, mp.fresnel, mp.chord, mp.fade)
    g0 = 1.0 / (mp.caustic_width * math.sqrt(2.0 * math.pi))
    level = jnp.maximum(n_trt, 1e-300)
    i_g = float(jnp.mean(t * glint * g0 / level))
    # unit height vs unit area: M_X = M'_X / (sqrt(2 pi) beta_X), so I_X = 1 / (sqrt(2 pi) beta_X)
    # (spec §1.3.8b writes I_X <- I_X sqrt(2 pi beta_X^2): that is the artist -> physical direction)
    s2p = math.sqrt(2.0 * math.pi) / (0.5 if mp.longitudinal == "half" else 1.0)
    return Params(
        color_r=np.asarray(n_r), intensity_r=float(1.0 / (s2p * be[0])), alpha_r=float(al[0]), beta_r=float(be[0]),
        color_tt=np.asarray(n_tt), intensity_tt=float(1.0 / (s2p * be[1])), alpha_tt=float(al[1]), beta_tt=float(be[1]),
        gamma_tt=gamma_tt,
        color_trt=np.asarray(n_trt), intensity_trt=float(1.0 / (s2p * be[2])), alpha_trt=float(al[2]), beta_trt=float(be[2]),
        glint_intensity=i_g, glint_width=float(mp.caustic_width),
        glint_angle=float(phi_c) if glint_angle is None else glint_angle,
    )


MODEL = Model(
    name="sadeghi_hair",
    kind="bcsdf",
    Params=Params,
    eval=eval,
    sample=None,
    pdf=None,
    summary="Sadeghi 2011 artist-friendly hair: R/TT/TRT/glint pseudo lobes (+ dual scattering in bcsdf.dual_scattering)",
    source="Sadeghi 2011, Eqs. 4.9-4.16, §4.7 (Zinke et al. 2008 dual scattering)",
    reciprocal=True,
    transmissive=True,
)
