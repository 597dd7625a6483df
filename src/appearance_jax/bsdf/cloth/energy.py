"""The thread energy cap of the cloth model (this library's decision D-C10; not in the thesis).

Sadeghi's thread BCSDF (Sadeghi Eq. 5.11) is a hand-fitted shading model, not normalised: its surface
term has no 1/4 in azimuth (Marschner's N_R has one) and its volume term is the semi-infinite
single-scattering form without Chandrasekhar's 1/(4 pi), the factors Table 5.2's albedos absorbed.
Seen through the weave this is harmless at moderate incidence (the presets reflect 0.1-0.2 of
the light at normal incidence), but when the light runs along a thread (theta_i(t) -> 90 deg) the
Fresnel factor of the surface term -> 1 and the volume term's 1/(cos theta_i + cos theta_r) grows:
a bright weave then sends out more light than it receives (albedo 1.3-3.9 near grazing).

The cap: each tangent sample's f_s is divided by max(1, rho), rho the fraction of the light the
sample intercepts that it sends out of the patch, in the exit measure of Sadeghi Eq. 5.20 (masking M_r,
projected onto N):

    rho(theta_i, alpha) = int f_s(theta_i, theta_r, phi_d = -phi_r) M_r (N . w_r) dw_r,
    M_r = max(cos phi_r, 0),  N . w_r = cos(alpha) cos(theta_r) cos(phi_r) + sin(alpha) sin(theta_r),

with the light in the sample's normal-tangent plane (phi_i = 0, where M_i = 1 and
M(w_i, w_r) = M_r exactly; an off-plane light meets the same lobes at smaller M_r). Bounding
[a + b]_+ <= [a]_+ + [b]_+ splits rho into three one-dimensional tables in theta_i per family:

    rho <= cos(alpha) C2(theta_i) + [sin alpha]_+ C1p(theta_i) + [-sin alpha]_+ C1m(theta_i),
    C2  = int f_s cos^2(phi_r) cos^2(theta_r)            dtheta_r dphi_r,
    C1p = int f_s cos(phi_r) [ sin theta_r]_+ cos(theta_r) dtheta_r dphi_r,   (C1m: [-sin theta_r]_+)

(phi_r in [-pi/2, pi/2]; with ``masking=False``, M_r = 1 and phi_r over the whole circle). The tables are computed from the family parameters at every call
(differentiable; ~50 theta_i nodes x 54 theta_r x 8 phi_r thread evaluations per family, small
next to one eval batch) and interpolated linearly in theta_i. Where rho <= 1 the model is the
thesis' unchanged; the measured effect on the presets and the albedo bounds are in
``docs/cloth.md``.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from ...bcsdf import thread
from ...core.quadrature import gauss_legendre, piecewise_rule

N_THETA_I = 49  # table nodes in theta_i over [-pi/2, pi/2] (3.75 deg apart)
N_PER_PIECE = 6  # smoothstep Gauss-Legendre nodes per theta_r piece
N_PHI = 8  # Gauss-Legendre nodes in phi_r over [0, pi/2] (the integrands are even in phi_r)
CONE_CUTS = (2.0, 6.0)  # theta_r pieces end at the specular cone -theta_i +- k gamma (k in CONE_CUTS)


def theta_nodes():
    """The table's theta_i nodes (numpy, radians, increasing over [-pi/2, pi/2])."""
    return np.linspace(-0.5 * math.pi, 0.5 * math.pi, N_THETA_I)


def exit_tables(p, eta, albedo, k_d, gamma_s, gamma_v):
    """(C2, C1p, C1m), each (..., J, N_THETA_I, bands), for the family parameters given:
    ``eta`` (...), ``albedo`` (..., J, bands), ``k_d``, ``gamma_s``, ``gamma_v`` (..., J), the
    gammas in radians. ``p`` supplies the static options (theta_d, volume_fresnel)."""
    fam = lambda x: jnp.asarray(x)[..., None, None, None]  # (..., J) -> (..., J, 1, 1, 1)  # noqa: E731
    half = 0.5 * math.pi
    th_i = jnp.asarray(theta_nodes())[:, None]  # (N, 1)
    # theta_r pieces: the specular cone theta_r = -theta_i is where both Gaussians peak (in
    # theta_h = (theta_i + theta_r) / 2, i.e. std 2 gamma in theta_r)
    cuts = [-th_i + s * k * 2.0 * jnp.asarray(g)[..., None, None]
            for g in (gamma_s, gamma_v) for k in CONE_CUTS for s in (-1.0, 1.0)]
    bps = jnp.sort(jnp.clip(jnp.stack(jnp.broadcast_arrays(*cuts), axis=-1), -half, half), axis=-1)
    ends = jnp.full_like(bps[..., :1], half)
    bps = jnp.concatenate([-ends, bps, ends], axis=-1)  # (..., J, N, 1, pieces + 1)
    th_r, w_r = piecewise_rule(bps, N_PER_PIECE)  # (..., J, N, 1, R)
    th_r, w_r = th_r[..., 0, :, None], w_r[..., 0, :, None]  # (..., J, N, R, 1)
    # phi_r >= 0 (the integrands are even): [0, pi/2] in front of the sample, and behind it,
    # [pi/2, pi], only without masking (M_r = 1 there; N . w_r may still be > 0 by the tilt)
    rules = [gauss_legendre(N_PHI, 0.0, half)] + ([] if p.masking else [gauss_legendre(N_PHI, half, math.pi)])
    phi, w_phi = (jnp.asarray(np.concatenate(v)) for v in zip(*rules))  # (P,)
    s_i, c_i = jnp.sin(th_i)[..., None], jnp.cos(th_i)[..., None]  # (N, 1, 1)
    s_r, c_r = jnp.sin(th_r), jnp.cos(th_r)
    eta = jnp.asarray(eta)[..., None, None, None, None]
    albedo = jnp.asarray(albedo)[..., :, None, None, None, :]
    f_rs, f_rv, inv_c2 = thread.terms_from_angles(p, s_i, c_i, s_r, c_r, jnp.cos(phi), eta=eta, albedo=albedo,
                                                   k_d=fam(k_d), gamma_s=fam(gamma_s), gamma_v=fam(gamma_v))
    f = (f_rs[..., None] + f_rv) * inv_c2[..., None]  # (..., J, N, R, P, bands)
    cp = jnp.cos(phi)
    m_r = jnp.maximum(cp, 0.0) if p.masking else jnp.ones_like(cp)  # M_r at phi_i = 0
    w = 2.0 * w_r * w_phi * m_r * c_r  # both signs of phi_r; dw = cos(theta_r) dtheta_r dphi_r
    C2 = jnp.sum(f * (w * jnp.maximum(cp, 0.0) * c_r)[..., None], axis=(-3, -2))
    C1p = jnp.sum(f * (w * jnp.maximum(s_r, 0.0))[..., None], axis=(-3, -2))
    C1m = jnp.sum(f * (w * jnp.maximum(-s_r, 0.0))[..., None], axis=(-3, -2))
    return C2, C1p, C1m


def _interp(table, theta):
    """table (..., J, N, bands) at theta (..., J, T) -> (..., J, T, bands), linear in theta."""
    x = (theta + 0.5 * math.pi) * ((N_THETA_I - 1) / math.pi)
    idx = jnp.clip(jnp.floor(x), 0, N_THETA_I - 2).astype(jnp.int32)
    frac = jnp.clip(x - idx, 0.0, 1.0)[..., None]
    if table.ndim == 3:  # unbatched parameters: one gather from the flattened (J N, bands) table
        J = table.shape[0]
        flat = table.reshape(J * N_THETA_I, table.shape[-1])
        k = idx + N_THETA_I * jnp.arange(J, dtype=jnp.int32)[:, None]  # (..., J, T)
        v0, v1 = jnp.take(flat, k, axis=0), jnp.take(flat, k + 1, axis=0)
        return v0 + frac * (v1 - v0)
    # batched parameters: broadcast the tables to the directions' batch (slower: a copy per pair)
    shape = jnp.broadcast_shapes(table.shape[:-2], idx.shape[:-1])
    tb = jnp.broadcast_to(table, shape + table.shape[-2:])
    ib = jnp.broadcast_to(idx, shape + idx.shape[-1:])[..., None]
    v0 = jnp.take_along_axis(tb, ib, axis=-2)
    v1 = jnp.take_along_axis(tb, ib + 1, axis=-2)
    return v0 + frac * (v1 - v0)


def exit_albedo(tables, theta_i, alpha):
    """rho (upper estimate) per tangent sample (..., J, T, bands) from :func:`exit_tables`,
    the samples' thread inclinations theta_i = asin(w_i . t) and tilts alpha (radians)."""
    C2, C1p, C1m = (_interp(t, theta_i) for t in tables)
    sa = jnp.sin(alpha)[..., None]
    return jnp.cos(alpha)[..., None] * C2 + jnp.maximum(sa, 0.0) * C1p + jnp.maximum(-sa, 0.0) * C1m


def cap(rho):
    """1 / max(1, rho): the factor that keeps a sample from sending out more than it intercepts."""
    return 1.0 / jnp.maximum(rho, 1.0)
