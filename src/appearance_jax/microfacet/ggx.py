"""GGX / Trowbridge-Reitz microfacet distribution (anisotropic), its Smith projected area
and Heitz's (2018) visible-normal sampler.

Use through :mod:`appearance_jax.microfacet.distribution` (``kind="ggx"``), which adds the
generic Smith terms and densities. Roughnesses ``ax, ay`` > 0 (dimensionless slope
scales along the local x and y axes); ``m`` is a unit microfacet normal, ``w`` a unit
direction, all :class:`~appearance_jax.core.vec.Vec3` in the local frame (z = normal).

Equations (Walter et al. 2007, Eq. 33; Heitz 2014, anisotropic form):

    D(m) = 1 / (pi ax ay (m_x^2/ax^2 + m_y^2/ay^2 + m_z^2)^2)          for m_z > 0

which is the usual ``1 / (pi ax ay cos^4 (1 + tan^2 (cos^2 phi/ax^2 + sin^2 phi/ay^2))^2)``
multiplied through by cos^4 (no division by m_z, so it is finite up to the horizon).

    Lambda(w) = (sqrt(1 + a^2 tan^2 theta) - 1) / 2,    a^2 tan^2 theta = (ax^2 w_x^2 + ay^2 w_y^2) / w_z^2

(Heitz 2014). The kernels below use the *projected area*
``mu(w) = |w_z| (1 + Lambda(w)) = (|w_z| + sqrt(w_z^2 + ax^2 w_x^2 + ay^2 w_y^2)) / 2``
(= int max(0, w.m) D(m) dm, Heitz 2014), which stays finite and positive at grazing
incidence where Lambda itself diverges: G1 = |w_z| / mu then vanishes smoothly.
"""

from __future__ import annotations

import jax.numpy as jnp

from ..core.special import safe_sqrt
from ..core.vec import Vec3, cross, normalize


def D_terms(m: Vec3, ax, ay):
    """``(num, den)`` with D(m) = num / den: (1, pi ax ay q^2), and (0, 1) for m_z <= 0.

    For a BSDF that folds D into its own division (one divide instead of two per element).
    The 1/ax, 1/ay are taken once on the parameters' shape, not per element."""
    iax, iay = 1.0 / ax, 1.0 / ay
    q = (m.x * iax) ** 2 + (m.y * iay) ** 2 + m.z * m.z
    up = (m.z > 0) & (q > 0)
    qs = jnp.where(up, q, 1.0)
    return jnp.where(up, 1.0, 0.0), jnp.pi * ax * ay * qs * qs


def D(m: Vec3, ax, ay):
    """GGX normal distribution D(m) in 1/sr; 0 for m_z <= 0 (Walter et al. 2007, Eq. 33)."""
    num, den = D_terms(m, ax, ay)
    return num / den


def projected_area(w: Vec3, ax, ay):
    """mu(w) = |w_z| (1 + Lambda(w)) = int max(0, w.m) D(m) dm (Heitz 2014).

    Finite and > 0 for every unit ``w`` when ax, ay > 0 (grazing: sqrt(ax^2 w_x^2 + ay^2 w_y^2)/2).
    Symmetric in the sign of w_z.
    """
    z = jnp.abs(w.z)
    s = safe_sqrt(w.z * w.z + (ax * w.x) ** 2 + (ay * w.y) ** 2)
    return 0.5 * (z + s)


def sample_visible(w: Vec3, ax, ay, u1, u2) -> Vec3:
    """Sample m with density G1(w, m) max(0, w.m) D(m) / w_z (Heitz 2018, "Sampling the GGX
    distribution of visible normals", JCGT 7(4), Listing 1; the algorithm re-derived here).

    ``w`` must have w_z >= 0 (the dispatcher flips it). Steps: stretch w to the alpha = 1
    configuration, where the visible projected area of the hemisphere of normals is a disk
    (half a disk is the projection of the hemisphere's side); sample that disk uniformly
    after warping its lower half onto the foreshortened part; lift the point onto the
    hemisphere; unstretch the normal.
    """
    vh = normalize(Vec3(ax * w.x, ay * w.y, w.z))
    # orthonormal basis (t1, t2, vh) of the projection plane; t1 is horizontal
    lensq = vh.x * vh.x + vh.y * vh.y
    ok = lensq > 0
    inv = jnp.where(ok, 1.0 / safe_sqrt(jnp.where(ok, lensq, 1.0)), 0.0)
    zero = jnp.zeros_like(vh.z)
    T1 = Vec3(jnp.where(ok, -vh.y * inv, 1.0), jnp.where(ok, vh.x * inv, 0.0), zero)
    T2 = cross(vh, T1)
    # uniform point on the unit disk (polar map)
    r = safe_sqrt(u1)
    phi = 2.0 * jnp.pi * u2
    t1 = r * jnp.cos(phi)
    t2 = r * jnp.sin(phi)
    # warp: the half disk t2 < 0 is compressed by the factor (1 + vh.z)/2, the visible
    # fraction of the lower half (the projected hemisphere boundary is an ellipse)
    s = 0.5 * (1.0 + vh.z)
    t2 = (1.0 - s) * safe_sqrt(1.0 - t1 * t1) + s * t2
    # lift onto the hemisphere around vh
    tz = safe_sqrt(1.0 - t1 * t1 - t2 * t2)
    nh = T1 * t1 + T2 * t2 + vh * tz
    # unstretch (normals transform with the inverse transpose of the stretch)
    return normalize(Vec3(ax * nh.x, ay * nh.y, jnp.maximum(nh.z, 0.0)))


def sample_slopes(ax, ay, u1, u2):
    """Microfacet slopes (s_x, s_y) distributed as P22, i.e. m ~ D(m) m_z (Walter 2007, Eq. 35-36).

    Isotropic alpha = 1 slope radius r^2 = u1 / (1 - u1), then stretched by (ax, ay).
    """
    r = safe_sqrt(u1 / jnp.maximum(1.0 - u1, 1e-30))
    phi = 2.0 * jnp.pi * u2
    return ax * r * jnp.cos(phi), ay * r * jnp.sin(phi)
