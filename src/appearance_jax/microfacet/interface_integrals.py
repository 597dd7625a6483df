"""Directional integrals of a rough dielectric interface, and their tables (a coat over anything).

A single rough interface of relative index ``eta`` (isotropic microfacet roughness ``alpha``,
GGX or Beckmann, separable Smith G1 for the second direction, as Mitsuba) seen by light
arriving at cos(theta) = mu:

    T(mu)  = int pdf_vis(wi, m) (1 - F(wi.m; eta)) G1(wt, m) dm               (external transmittance)
    R(mu)  = int pdf_vis(wi, m) F(wi.m; 1/eta) G1(wr, m) [wr.z > 0] dm          (reflectance seen from inside)
    R_int  = 2 int_0^1 R(mu) mu dmu                                            (cosine-averaged, diffuse light)

with wi = (sqrt(1 - mu^2), 0, mu), pdf_vis the visible-normal density
(:func:`appearance_jax.microfacet.distribution.pdf_visible`) and wt / wr the refracted /
mirrored directions. They are single-scattering quantities: light masked by the
microsurface is lost (T + R <= 1). :func:`interface_transmittance` and
:func:`interface_reflectance` compute them by a fixed piecewise Gauss-Legendre quadrature
cut at the integrand's known kinks, jittable and differentiable in alpha and eta (float32
or float64); alpha, eta and mu broadcast.

:func:`tabulate` computes, once per (alpha, eta, distribution), T at fixed nodes and R_int
(:class:`CoatTables`) in one of two schemes (:data:`TABLES`), and :func:`transmittance_at`
looks T up per direction:

- ``"accurate"``: T is a Chebyshev interpolant on 64 nodes in sqrt(mu), R_int a
  Gauss-Legendre integral over mu split at the critical cosine.
- ``"mitsuba"``: Mitsuba 3's discretisation (T linear in mu between 64 equispaced nodes,
  R_int an equal-weight mean over them, about 1% low).

Used by ``bsdf.rough_plastic`` (the coat over a Lambertian base), by default through
:mod:`appearance_jax.microfacet.coat_tables` (scheme ``"precomputed"``: the accurate scheme's
tables computed once on an (alpha, eta) grid and interpolated). The quadrature's design and
the measured accuracy of all schemes: docs/microfacet.md.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..core.quadrature import piecewise_rule
from ..core.special import safe_acos, safe_sqrt
from ..core.vec import Vec3
from ..optics.fresnel import fresnel_dielectric
from . import distribution as md

TABLES = ("accurate", "mitsuba")

# Mitsuba 3's table: MI_ROUGH_TRANSMITTANCE_RES = 64 nodes, equispaced in mu, first node 1e-6
MITSUBA_NODES = 64
MITSUBA_MU0 = 1e-6
# accurate scheme: Chebyshev nodes in s = sqrt(mu) for T; Gauss-Legendre pieces for R_int
N_CHEB = 64
N_MU_RINT = 24  # nodes per piece of the R_int integral over mu (2 pieces)
# nodes per piece of the facet quadrature (polar, azimuth)
N_THETA = 24
N_PHI = 24
_BECKMANN_SLOPE_CUTS = (3.0, 6.0)
_BECKMANN_R2_MAX = 100.0


# ----------------------------------------------------------------------------------------
# the rough interface's directional integrals


def _polar_coordinate(theta, alpha):
    """The integration variable q = 1 - cos(theta') of the facet polar angle theta, and 1 - q.

    theta' is the polar angle in the alpha = 1 configuration, tan(theta') = tan(theta)/alpha,
    so the peak of D (width ~alpha in theta) is spread over q in [0, 1] for any alpha. The
    measure in q (see :func:`_facet_polar`) is smooth up to the horizon q = 1, for GGX's heavy
    tail too (where the mean slope diverges).
    """
    st, ct = jnp.sin(theta), jnp.cos(theta)
    ac = alpha * ct
    r = jnp.sqrt(ac * ac + st * st)
    # 1 - cos(theta') = sin^2(theta') / (1 + cos(theta')), without cancellation
    return st * st / (r * (r + ac)), ac / r


def _facet_polar(kind: str, alpha, q, qc, wq):
    """tan and cos of the facet polar angle at the nodes (q, qc = 1 - q = cos(theta')), and
    the weights of the measure D(m) cos(theta) dm / (dphi / 2 pi).

    With r = tan(theta') the slope in the alpha = 1 configuration, D(m) cos(theta) dm =
    P(r) 2 pi r dr dphi / (2 pi) with the projected-normal CDF u(r) = r^2 / (1 + r^2) (GGX)
    or 1 - exp(-r^2) (Beckmann) (Walter et al. 2007, Eq. 28 and 35), so per dq:
    du/dq = 2 cos(theta') (GGX) and 2 exp(-r^2) / cos^3(theta') (Beckmann).
    """
    # nodes of empty pieces may sit exactly on the horizon (qc = 0): safe-where them away,
    # their weight is 0 anyway
    ok = qc > 0
    qs = jnp.where(ok, qc, 1.0)
    r2 = jnp.where(ok, q * (2.0 - q) / (qs * qs), 0.0)  # tan^2(theta') = sin^2 / cos^2
    if kind == "ggx":
        w = 2.0 * qc * wq
    else:
        # beyond r^2 = 100 the measure is < exp(-100): weight 0, and the node is pulled back
        # to r^2 = 100 so that no overflowing geometry (1/qc^3 in float32) reaches a gradient
        ok = ok & (r2 < _BECKMANN_R2_MAX)
        r2 = jnp.where(ok, r2, _BECKMANN_R2_MAX)
        qs = jnp.where(ok, qs, 1.0)
        w = jnp.where(ok, 2.0 * jnp.exp(-r2) / (qs * qs * qs), 0.0) * wq
    t2 = alpha * alpha * r2
    return safe_sqrt(t2), jax.lax.rsqrt(1.0 + t2), w


def _azimuth_of(c, B, A):
    """phi in [0, pi] where A cos(phi) + B = c (clamped: 0 if c > A + B, pi if c < B - A)."""
    ok = A > 0
    r = jnp.where(ok, (c - B) / jnp.where(ok, A, 1.0), jnp.where(c > B, 2.0, -2.0))
    return safe_acos(jnp.clip(r, -1.0, 1.0))


def _interface_integral(kind, alpha, eta, mu, mode: str, n_theta: int, n_phi: int):
    """T(mu) (mode "T") or R(mu) (mode "R") of a rough interface of relative index eta.

    Facet normals m = (sin t cos phi, sin t sin phi, cos t) and wi = (sqrt(1 - mu^2), 0, mu):
    c = wi.m = A cos(phi) + B with A = sin(theta_i) sin t, B = mu cos t, decreasing in phi,
    and by the mirror symmetry phi -> -phi only phi in [0, pi] is integrated. The visible-normal
    density is c D(m) / a(wi) with a(wi) = projected area (Heitz 2014), and
    D(m) dm = dq-measure dphi / (2 pi cos t), so

        I(mu) = 1/(pi a(wi)) int dq-measure int_0^pi (c / cos t) h(m) dphi,

    h = (1 - F(c; eta)) G1(wt, m) for T, F(c; eta) G1(wr, m) for R.
    """
    st_i = safe_sqrt(1.0 - mu * mu)
    th_i = safe_acos(mu)
    quarter = 0.25 * jnp.pi
    half = 0.5 * jnp.pi
    if mode == "T":
        # c(phi = pi) = cos(theta_i + t) = 0: beyond, part of the azimuths are invisible
        th_bps = [half - th_i]
        c_c = jnp.zeros_like(mu)
    else:
        # TIR for c < c_c (eta < 1); the mirrored direction is above the horizon for
        # c > mu / (2 cos t) (c_lo). Breakpoints where c(phi = 0) = cos(theta_i - t) or
        # c(phi = pi) = cos(theta_i + t) crosses c_c or c_lo: t = theta_i +- theta_c,
        # theta_c - theta_i, pi/4 +- theta_i/2.
        c_c = safe_sqrt(1.0 - eta * eta)
        th_c = safe_acos(c_c)
        th_bps = [th_i - th_c, th_i + th_c, th_c - th_i, quarter + 0.5 * th_i, quarter - 0.5 * th_i]
    if kind == "ggx":
        # pi/4 separates the bulk of D from the heavy tail (see _polar_coordinate)
        th_bps.append(jnp.full_like(mu, quarter))
    else:
        # Beckmann's measure exp(-r^2) dr^2 is smooth but not analytic at the horizon
        # (r -> inf): cut at slopes r = 3, 6 so that the pieces carrying the mass are
        # analytic; beyond r = 6 lies exp(-36) of it
        th_bps += [jnp.arctan(alpha * r) for r in _BECKMANN_SLOPE_CUTS]
    th_bps = jnp.stack(th_bps, axis=-1)
    th_bps = jnp.sort(jnp.clip(th_bps, 0.0, half), axis=-1)
    ends = jnp.zeros_like(th_bps[..., :1])
    th_bps = jnp.concatenate([ends, th_bps, ends + half], axis=-1)
    a = alpha[..., None]
    q_bps, qc_bps = _polar_coordinate(th_bps, a)
    q, wq, qc = piecewise_rule(q_bps, n_theta, qc_bps)  # (..., Q)
    tan_m, cos_m, wq = _facet_polar(kind, a, q, qc, wq)
    sin_m = tan_m * cos_m

    A = st_i[..., None] * sin_m
    B = mu[..., None] * cos_m
    if mode == "T":
        phi_bps = [jnp.zeros_like(A), _azimuth_of(0.0, B, A)]
    else:
        p_lo = _azimuth_of(mu[..., None] / (2.0 * cos_m), B, A)
        p_c = jnp.minimum(_azimuth_of(c_c[..., None], B, A), p_lo)
        phi_bps = [jnp.zeros_like(A), p_c, p_lo]
    phi, wphi = piecewise_rule(jnp.stack(phi_bps, axis=-1), n_phi)  # (..., Q, P)
    cphi = jnp.cos(phi)

    x1 = (..., None, None)
    c = A[..., None] * cphi + B[..., None]
    c_over_cos = mu[x1] + st_i[x1] * tan_m[..., None] * cphi
    e = eta[x1]
    a = alpha[x1]
    cos_m = cos_m[..., None]
    # Only the z components of the scattered directions are needed: the distribution is
    # isotropic, so G1 depends on |w.z| alone, and both directions see the front of m by
    # construction (c > 0; transmission: wt.m = -cos_t < 0 with wt.z < 0).
    F, cos_t, _, _ = fresnel_dielectric(c, e)
    if mode == "T":
        # refracted wt = -wi / eta + m (c / eta - cos_t) (Walter et al. 2007, Eq. 40), cos_t >= 0
        z = mu[x1] / e - cos_m * (c / e + cos_t)  # = -wt.z >= 0 (cos_t is signed: < 0 here)
        h = (1.0 - F) * _g1_of_z(kind, z, a)
    else:
        z = 2.0 * c * cos_m - mu[x1]  # mirrored wr = 2 c m - wi
        h = jnp.where(z > 0, F * _g1_of_z(kind, z, a), 0.0)
    h = jnp.where(c > 0, h * c_over_cos, 0.0)
    # reduce azimuth first, then polar angle: short sums keep float32 round-off small
    inner = jnp.sum(wphi * h, axis=-1)
    total = jnp.sum(wq * inner, axis=-1)
    proj = md.projected_area(kind, Vec3(st_i, jnp.zeros_like(mu), mu), alpha)
    return total / (jnp.pi * proj)


def _g1_of_z(kind, z, alpha):
    """Smith G1 = |z| / a(w) of a direction with |cos theta| = z (isotropic alpha); 0 at z = 0."""
    z = jnp.abs(z)
    pa = md.projected_area(kind, Vec3(safe_sqrt(1.0 - z * z), jnp.zeros_like(z), z), alpha)
    return z / pa


def _broadcast_inputs(alpha, eta, mu):
    alpha = jnp.asarray(alpha)
    eta = jnp.asarray(eta)
    mu = jnp.asarray(mu)
    dtype = jnp.result_type(alpha, eta, mu, float)
    shape = jnp.broadcast_shapes(alpha.shape, eta.shape, mu.shape)
    return tuple(jnp.broadcast_to(x.astype(dtype), shape) for x in (alpha, eta, mu))


@functools.partial(jax.jit, static_argnames=("kind", "n_theta", "n_phi"))
def interface_transmittance(kind: str, alpha, eta, mu, n_theta: int = N_THETA, n_phi: int = N_PHI):
    """Directional transmittance T(mu) of a rough dielectric interface, light arriving from the
    side of index 1 at cos(theta) = mu onto a side of relative index ``eta`` >= 1.

    T(mu) = int pdf_vis(wi, m) (1 - F(wi.m; eta)) G1(wt, m) dm (single scattering; what is
    neither reflected nor transmitted was masked: T + R <= 1). Isotropic ``alpha``; alpha,
    eta, mu broadcast. For eta < 1 (not needed by a coat) the refracted ray may leave upwards,
    which this quadrature does not cut at.
    """
    alpha, eta, mu = _broadcast_inputs(alpha, eta, mu)
    return _interface_integral(kind, alpha, eta, mu, "T", n_theta, n_phi)


@functools.partial(jax.jit, static_argnames=("kind", "n_theta", "n_phi"))
def interface_reflectance(kind: str, alpha, eta, mu, n_theta: int = N_THETA, n_phi: int = N_PHI):
    """Directional reflectance R(mu) = int pdf_vis(wi, m) F(wi.m; eta) G1(wr, m) [wr.z > 0] dm of
    a rough interface seen from the side where the relative index is ``eta`` (any eta > 0:
    eta < 1 is the inside of a denser coat, with total internal reflection)."""
    alpha, eta, mu = _broadcast_inputs(alpha, eta, mu)
    return _interface_integral(kind, alpha, eta, mu, "R", n_theta, n_phi)


# ----------------------------------------------------------------------------------------
# tables: T at fixed nodes and R_int, once per (alpha, eta)


class CoatTables(NamedTuple):
    """The coat integrals of one parameter set (leading axes: those of alpha and eta).

    ``transmittance``: T at the nodes of the scheme (..., 64) (Mitsuba: mu_k; accurate:
    Chebyshev coefficients in sqrt(mu)); ``internal_reflectance``: R_int (...).
    """

    transmittance: jax.Array
    internal_reflectance: jax.Array


def mitsuba_nodes():
    """Mitsuba 3's table nodes mu_k = max(1e-6, k / 63), k = 0..63 (numpy)."""
    return np.maximum(MITSUBA_MU0, np.linspace(0.0, 1.0, MITSUBA_NODES))


@functools.lru_cache(maxsize=None)
def _chebyshev_nodes(n: int):
    """Chebyshev points of the first kind on [0, 1] (increasing), and the DCT matrix that
    maps values there to Chebyshev coefficients in x = 2 s - 1."""
    j = np.arange(n)
    x = -np.cos((j + 0.5) * np.pi / n)  # increasing in [-1, 1]
    k = j[:, None]
    # c_k = (2 / n) sum_j f_j T_k(x_j), halved for k = 0
    M = (2.0 / n) * np.cos(k * np.arccos(x)[None, :])
    M[0] *= 0.5
    return 0.5 * (x + 1.0), M


def chebyshev_series(coefs, x):
    """sum_k c_k T_k(x) for coefs (..., n) and x broadcasting against the leading axes.

    Unrolled (not a lax.scan): XLA fuses the 2n multiply-adds per direction into one
    elementwise loop, where a scan makes n passes over the direction arrays (~10x slower
    on CPU for 1e6 directions)."""
    n = coefs.shape[-1]
    x2 = 2.0 * x
    b1 = b2 = jnp.zeros((), jnp.result_type(x, coefs))
    for k in range(n - 1, 0, -1):
        b1, b2 = x2 * b1 - b2 + coefs[..., k], b1
    return x * b1 - b2 + coefs[..., 0]


def tabulate(kind: str, alpha, eta, scheme: str = "accurate") -> CoatTables:
    """The coat integrals of a rough interface (``kind`` "ggx" or "beckmann", roughness
    ``alpha``, relative index ``eta`` >= 1; leading axes broadcast) in the table ``scheme``
    (:data:`TABLES`): T at the scheme's nodes and R_int (not jitted: call it inside a jit)."""
    dtype = jnp.result_type(alpha, eta, float)
    alpha = jnp.asarray(alpha, dtype)[..., None]
    eta = jnp.asarray(eta, dtype)[..., None]
    if scheme == "mitsuba":
        mu = jnp.asarray(mitsuba_nodes(), dtype)
        T = interface_transmittance(kind, alpha, eta, mu)
        R = interface_reflectance(kind, alpha, 1.0 / eta, mu)
        R_int = 2.0 * jnp.mean(R * mu, axis=-1)
        return CoatTables(T, R_int)
    s, M = _chebyshev_nodes(N_CHEB)
    T = interface_transmittance(kind, alpha, eta, jnp.asarray(s * s, dtype))
    coefs = T @ jnp.asarray(M.T, dtype)
    # R_int = 2 int_0^1 R(mu) mu dmu, split where a smooth coat has TIR (R has a sqrt kink)
    c_c = safe_sqrt(1.0 - 1.0 / (eta * eta))
    bps = jnp.concatenate([jnp.zeros_like(c_c), c_c, jnp.ones_like(c_c)], axis=-1)
    mu, w = piecewise_rule(bps, N_MU_RINT)
    R = interface_reflectance(kind, alpha, 1.0 / eta, mu)
    R_int = 2.0 * jnp.sum(w * mu * R, axis=-1)
    return CoatTables(coefs, R_int)


def transmittance_at(scheme: str, tab: CoatTables, mu):
    """T(mu) from tables of ``scheme`` (:func:`tabulate`), for mu in [0, 1] (any shape
    broadcasting with the tables' leading axes)."""
    T = tab.transmittance
    mu = jnp.clip(mu, 0.0, 1.0)
    if scheme == "mitsuba":
        # linear interpolation between equispaced nodes, as Mitsuba's lerp_gather
        x = mu * (MITSUBA_NODES - 1)
        idx = jnp.minimum(jnp.floor(x), MITSUBA_NODES - 2).astype(jnp.int32)
        frac = x - idx
        if T.ndim == 1:
            v0, v1 = T[idx], T[idx + 1]
        else:
            shape = jnp.broadcast_shapes(T.shape[:-1], idx.shape)
            Tb = jnp.broadcast_to(T, shape + T.shape[-1:])
            ib = jnp.broadcast_to(idx, shape)[..., None]
            v0 = jnp.take_along_axis(Tb, ib, axis=-1)[..., 0]
            v1 = jnp.take_along_axis(Tb, ib + 1, axis=-1)[..., 0]
        return v0 + frac * (v1 - v0)
    # Chebyshev series in s = sqrt(mu), x = 2 s - 1; clipped to [0, 1] so that an
    # interpolation ripple (~1e-6) near T = 1 cannot make a lobe probability negative
    return jnp.clip(chebyshev_series(T, 2.0 * safe_sqrt(mu) - 1.0), 0.0, 1.0)
