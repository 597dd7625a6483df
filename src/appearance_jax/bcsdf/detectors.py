"""Detector functions of Padrón's feather fibre BCSDF: the roughness that spreads each delta lobe.

Padrón 2025 Eq. 5.2 ([T:972-974] of seed 000) turns the fibre's delta lobes (direction Theta_k,
Phi_k, amplitude A_k) into a smooth BCSDF with "longitudinal and azimuthal Gaussian detector
functions" G_M(Delta theta | beta_m) and G_N(Delta phi | beta_n):
``S(h) = sum_k A_k(h) G_M(Theta_k - theta_o) G_N(Phi_k - phi_o)`` (spec seed-000 M20, decision D6).
The thesis gives no formulas; these are the literal reading (all angles and widths in radians):

    G_M(x | beta) = exp(-x^2 / (2 beta^2)) / (sqrt(2 pi) beta)                   1/rad
    G_N(x | beta) = sum_k exp(-(x - 2 pi k)^2 / (2 beta^2)) / (sqrt(2 pi) beta)  1/rad, wrapped:
                    its integral over one period is 1 (|k| <= K_WRAP terms, exact to 1e-16 for beta <= 1.5)

Eq. 5.2 integrates over cos(Theta) dTheta dPhi, so the plain G_M does not conserve a lobe's
energy: :func:`longitudinal` offers three forms of the longitudinal factor, each a density of
theta_o in [-pi/2, pi/2] under the measure cos(theta_o) dtheta_o except the first:

- ``"gaussian"``: G_M(theta_o - Theta | beta) itself (the thesis' literal term);
- ``"gaussian_cos"``: G_M / Z(Theta, beta), Z = integral of G_M(theta - Theta) cos(theta) dtheta over
  [-pi/2, pi/2] (per-lobe normalised: integral of the factor times cos(theta_o) dtheta_o = 1);
- ``"deon"``: d'Eon et al. 2011's M(-Theta, theta_o; v) with the variance v = beta^2 (normalised the
  same way; :func:`appearance_jax.bcsdf.chiang.longitudinal_lobe`), the pbrt-style alternative.

Samplers: :func:`sample_azimuthal` draws from G_N exactly (a normal, wrapped to [-pi, pi));
:func:`sample_longitudinal` draws theta_o from G_M truncated to [-pi/2, pi/2] (inverse CDF) and
returns its density, which a caller divides into the factor it evaluates.

Example::

    from appearance_jax.bcsdf import detectors
    g = detectors.azimuthal(0.3, 0.12)                              # 1/rad
    m = detectors.longitudinal(0.2, 0.25, 0.13, "gaussian_cos")    # 1/rad per cos(theta_o)
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import ndtr, ndtri

from ..core.quadrature import gauss_legendre
from . import fiber
from .chiang import longitudinal_lobe

#: wrapped terms on each side of G_N; exp(-(2 pi)^2 / (2 * 1.5^2) * 9) ~ 1e-34: negligible for beta <= 1.5
K_WRAP = 3
#: longitudinal factor forms (module docstring)
LONGITUDINAL_KINDS = ("gaussian", "gaussian_cos", "deon")
_NODES = 32  # Gauss-Legendre nodes of Z(Theta, beta), in the Gaussian's own variable (smooth there)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)


def _check_beta(label, beta):
    """Eager check of a concrete width: finite and > 0 (a traced one is the caller's)."""
    if isinstance(beta, jax.core.Tracer):
        return
    b = np.asarray(beta, float)
    if not np.all(np.isfinite(b)) or np.any(b <= 0):
        raise ValueError(f"detectors.{label}: beta = {beta!r} rad must be finite and > 0")


def gaussian(x, beta):
    """G_M(x | beta): the normal density of width ``beta`` (rad) at ``x`` (rad), 1/rad."""
    _check_beta("gaussian", beta)
    return _normal(x, beta)


def _normal(x, beta):
    z = x / beta
    return jnp.exp(-0.5 * z * z) * (_INV_SQRT_2PI / beta)


def azimuthal(dphi, beta):
    """G_N(dphi | beta): the wrapped normal density (1/rad) of the azimuthal offset ``dphi`` (any
    real; 2 pi periodic); ``beta`` (rad) <= ~1.5 for the truncation's exactness."""
    _check_beta("azimuthal", beta)
    x = fiber.wrap_pi(jnp.asarray(dphi))
    return sum(_normal(x - 2.0 * math.pi * k, beta) for k in range(-K_WRAP, K_WRAP + 1))


def cos_normaliser(Theta, beta):
    """Z(Theta, beta) = integral of G_M(theta - Theta | beta) cos(theta) dtheta over [-pi/2, pi/2],
    by Gauss-Legendre in u = (theta - Theta) / beta over [-8, 8] clipped to the range (the
    integrand is smooth there for every width)."""
    _check_beta("cos_normaliser", beta)
    Theta, beta = jnp.asarray(Theta), jnp.asarray(beta)
    lo = jnp.maximum((-0.5 * math.pi - Theta) / beta, -8.0)
    hi = jnp.minimum((0.5 * math.pi - Theta) / beta, 8.0)
    hi = jnp.maximum(hi, lo)
    x, w = (jnp.asarray(v, jnp.result_type(Theta, float)) for v in gauss_legendre(_NODES, 0.0, 1.0))
    u = lo[..., None] + (hi - lo)[..., None] * x
    f = jnp.exp(-0.5 * u * u) * jnp.cos(Theta[..., None] + beta[..., None] * u)
    return jnp.sum(f * w, axis=-1) * (hi - lo) * _INV_SQRT_2PI


def longitudinal(theta_o, Theta, beta, kind: str = "gaussian"):
    """The longitudinal factor of a lobe at Theta (rad) seen at theta_o (rad), width beta (rad):
    ``kind`` in :data:`LONGITUDINAL_KINDS` (module docstring); 1/rad."""
    if kind not in LONGITUDINAL_KINDS:
        raise ValueError(f"detectors.longitudinal: kind = {kind!r}; valid: {LONGITUDINAL_KINDS}")
    _check_beta("longitudinal", beta)
    if kind == "deon":
        return longitudinal_lobe(-jnp.asarray(Theta), jnp.asarray(theta_o), jnp.asarray(beta) ** 2)
    g = gaussian(jnp.asarray(theta_o) - Theta, beta)
    return g / cos_normaliser(Theta, beta) if kind == "gaussian_cos" else g


def truncation_cdfs(Theta, beta):
    """Phi((-pi/2 - Theta) / beta) and Phi((pi/2 - Theta) / beta): the normal CDF at both ends of
    [-pi/2, pi/2] for a lobe at Theta of width beta. One ndtr on the two stacked arguments: each ndtr
    call site compiles to its own large rational approximation."""
    Theta, beta = jnp.broadcast_arrays(jnp.asarray(Theta), jnp.asarray(beta, jnp.result_type(Theta, float)))
    ends = ndtr((jnp.stack([jnp.full_like(Theta, -0.5 * math.pi), jnp.full_like(Theta, 0.5 * math.pi)])
                 - Theta) / beta)
    return ends[0], ends[1]


def sample_azimuthal(u, Phi, beta):
    """phi_o ~ G_N(phi_o - Phi | beta) from a uniform ``u`` in (0, 1): a normal offset wrapped to
    [-pi, pi) about Phi (exact). Returns ``(phi_o, density)``."""
    _check_beta("sample_azimuthal", beta)
    phi = fiber.wrap_pi(Phi + beta * ndtri(jnp.clip(u, 1e-16, 1.0 - 1e-16)))
    return phi, azimuthal(phi - Phi, beta)


def sample_longitudinal(u, Theta, beta):
    """theta_o ~ G_M(theta_o - Theta | beta) truncated to [-pi/2, pi/2] (inverse CDF) from a uniform
    ``u`` in (0, 1). Returns ``(theta_o, density in dtheta_o)``; divide a factor evaluated at
    theta_o by it (and by cos(theta_o) for a solid-angle measure)."""
    _check_beta("sample_longitudinal", beta)
    a, b = truncation_cdfs(Theta, beta)
    p = a + jnp.clip(u, 0.0, 1.0) * (b - a)
    theta = jnp.clip(Theta + beta * ndtri(jnp.clip(p, 1e-300, 1.0 - 1e-16)), -0.5 * math.pi, 0.5 * math.pi)
    mass = b - a
    return theta, gaussian(theta - Theta, beta) / jnp.where(mass > 0, mass, 1.0)
