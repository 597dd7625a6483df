"""Quadrature: Gauss-Legendre and composite Simpson on intervals (Simpson also combined with
Monte Carlo inner estimates), product rules on the (hemi)sphere."""

from __future__ import annotations

import functools

import numpy as np
import jax.numpy as jnp

from .frame import spherical_direction


def gauss_legendre(n: int, a: float = -1.0, b: float = 1.0):
    """Nodes and weights of the n-point Gauss-Legendre rule on [a, b] (numpy float64).

    Exact for polynomials of degree <= 2n - 1.
    """
    if n < 1:
        raise ValueError(f"gauss_legendre: n = {n} must be >= 1")
    x, w = np.polynomial.legendre.leggauss(int(n))
    half = 0.5 * (b - a)
    return half * x + 0.5 * (a + b), half * w


def sphere_rule(n_theta: int, n_phi: int, hemisphere: bool = False):
    """Product rule over directions: Gauss-Legendre in cos(theta), uniform midpoints in phi.

    Returns ``(w, weight)`` with ``w`` a Vec3 of shape ``(n_theta * n_phi,)`` and weights
    summing to 4 pi (2 pi for the upper hemisphere). Integrates ``f(w) dw``.
    """
    mu, wmu = gauss_legendre(n_theta, 0.0 if hemisphere else -1.0, 1.0)
    phi = (np.arange(n_phi) + 0.5) * (2.0 * np.pi / n_phi)
    MU, PHI = np.meshgrid(mu, phi, indexing="ij")
    W = np.repeat(wmu[:, None] * (2.0 * np.pi / n_phi), n_phi, axis=1)
    theta = np.arccos(np.clip(MU, -1.0, 1.0))
    d = spherical_direction(jnp.asarray(theta.ravel()), jnp.asarray(PHI.ravel()))
    return d, jnp.asarray(W.ravel())


@functools.lru_cache(maxsize=None)
def smoothstep_rule(n: int):
    """Gauss-Legendre on [0, 1] pulled through s(t) = 3t^2 - 2t^3: nodes s, weights s'(t) w.

    s' vanishes at both ends, so an integrand with a sqrt or (.)^(3/2) singularity at an end
    of its piece becomes smooth in t (exponential convergence instead of algebraic).
    """
    t, w = gauss_legendre(n, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t), 6.0 * t * (1.0 - t) * w


def piecewise_rule(bps, n: int, complement=None):
    """Nodes and weights on consecutive pieces [bps[k], bps[k+1]] (last axis), flattened.

    ``bps`` (..., nb) is non-decreasing; empty pieces get zero weight. Returns (x, w) of
    shape (..., (nb - 1) n); with ``complement`` (= 1 - bps, computed accurately by the
    caller) also 1 - x, without the cancellation of forming it from x.
    """
    s, ds = (jnp.asarray(v, dtype=bps.dtype) for v in smoothstep_rule(n))
    a = bps[..., :-1, None]
    d = bps[..., 1:, None] - a
    shape = a.shape[:-2] + (a.shape[-2] * n,)
    x = (a + d * s).reshape(shape)
    w = (d * ds).reshape(shape)
    if complement is None:
        return x, w
    return x, w, (complement[..., :-1, None] - d * s).reshape(shape)


def simpson(n: int):
    """Composite Simpson rule with ``n`` (even) sub-intervals on [0, 1]: nodes ``t`` and weights
    ``w`` (n + 1,), so that int_lo^hi f ~ (hi - lo) sum w f(lo + t (hi - lo))."""
    w = jnp.ones(n + 1).at[1:-1:2].set(4.0).at[2:-1:2].set(2.0) / (3.0 * n)
    t = jnp.linspace(0.0, 1.0, n + 1)
    return t, w


def simpson_mc(x, w, scale, n_paths: int):
    """Combined Monte Carlo-Simpson estimate (Huang 2022, Sec. 4.3.4): Simpson weights ``w``
    (nodes, 1) over the per-node path means of ``x`` (..., nodes, paths[, bands]), times
    ``scale``; the standard error from the spread over paths (one path: neighbouring-node
    differences). Returns (value, stderr)."""
    mean_node = jnp.mean(x, axis=-2)
    val = jnp.sum(w * mean_node, axis=-2) * scale
    if n_paths > 1:
        var_node = jnp.var(x, axis=-2, ddof=1) / n_paths
    else:  # neighbouring-node differences as a (conservative) variance proxy
        dd = jnp.diff(mean_node, axis=-2)
        var_node = jnp.concatenate([dd[..., :1, :], dd], axis=-2) ** 2 / 2.0
    se = jnp.sqrt(jnp.sum(w * w * var_node, axis=-2)) * jnp.abs(scale)
    return val, se
