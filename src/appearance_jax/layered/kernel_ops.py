"""Kernel algebra of adding-doubling: composition, resolvents, adding and doubling of slab
operators on a discrete-ordinates node list (shared by :mod:`.adding_doubling` and
:mod:`.ordinates`).

A kernel ``K[..., out, in]`` (1/sr) on the node cosines ``mu`` (the first ``n`` carry the
quadrature measure ``c = 2 pi mu w``, the rest are zero-weight query cosines whose rows and
columns are computed explicitly, never solved for) maps incident radiance to outgoing
radiance by ``L_out = sum_j K[out, j] c_j L_in[j]``. A slab is an :class:`Op`: diffuse
reflection and transmission kernels from above (R, T) and from below (Rs, Ts), and the
direct-beam attenuation ``e`` carried as a diagonal, never as a kernel. Leading axes (Fourier
modes, bands) broadcast. Equations: van de Hulst (1980), "Multiple Light Scattering", Ch. 5
and 14, written out in docs/cosmetics.md.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from ..core.linalg import solve_diagonally_dominant


def phi(x):
    """(1 - e^{-x}) / x with the limit 1 at x = 0 (finite value and derivative)."""
    small = jnp.abs(x) < 1e-6
    xs = jnp.where(small, 1.0, x)
    return jnp.where(small, 1.0 - 0.5 * x + x * x / 6.0, -jnp.expm1(-xs) / xs)


class Op(NamedTuple):
    R: Any  # reflection, illuminated from above        (M, N, N)
    T: Any  # diffuse transmission, downwards           (M, N, N)
    Rs: Any  # reflection, illuminated from below
    Ts: Any  # diffuse transmission, upwards
    e: Any  # direct-beam attenuation exp(-t/μ)          (N,), light travelling down
    es: Any = None  # the same for light travelling up (None: equal to e, an up-down symmetric medium)

    @property
    def e_up(self):
        return self.e if self.es is None else self.es


def cmul(A, B, c, n):
    """Kernel of the composed operator, A C B: the inner sum over the n quadrature nodes only."""
    return jnp.einsum("...ij,j,...jk->...ik", A[..., :, :n], c[:n], B[..., :n, :])


def resolvent(A, B, c, n):
    """(I - A C B C)^{-1} A, with the linear solve on the quadrature block only.

    Rows at the quadrature nodes: (I - S_QQ C_Q) Y_Q = A_Q with S = A C B; rows at the
    zero-weight query nodes then follow explicitly, Y_X = A_X + S_XQ C_Q Y_Q (their
    columns of S C vanish, so they never enter the solve).
    """
    S = cmul(A, B, c, n)
    SC = S[..., :, :n] * c[:n]
    eye = jnp.eye(n, dtype=S.dtype)
    YQ = solve_diagonally_dominant(eye - SC[..., :n, :], A[..., :n, :])
    YX = A[..., n:, :] + SC[..., n:, :] @ YQ
    return jnp.concatenate([YQ, YX], axis=-2)


def left(e, T, X, c, n):
    """(E + T C) X: transmission applied on the out side of a kernel."""
    return e[:, None] * X + cmul(T, X, c, n)


def right(X, e, T, c, n):
    """X (E + C T): transmission applied on the in side of a kernel."""
    return X * e[None, :] + cmul(X, T, c, n)


def add(top: Op, bot: Op, c, n) -> Op:
    """Adding equations (module docstring): ``top`` over ``bot``."""
    W = resolvent(bot.R, top.Rs, c, n)  # (I - R2 C R1* C)^{-1} R2
    V = resolvent(top.Rs, bot.R, c, n)  # (I - R1* C R2 C)^{-1} R1*
    # e: the direct beam travelling down, e_up: travelling up (they differ in an oriented medium)
    R = top.R + left(top.e_up, top.Ts, right(W, top.e, top.T, c, n), c, n)
    T = (bot.e[:, None] * top.T + bot.T * top.e[None, :] + cmul(bot.T, top.T, c, n)
         + left(bot.e, bot.T, right(cmul(V, bot.R, c, n), top.e, top.T, c, n), c, n))
    Rs = bot.Rs + left(bot.e, bot.T, right(V, bot.e_up, bot.Ts, c, n), c, n)
    Ts = (top.e_up[:, None] * bot.Ts + top.Ts * bot.e_up[None, :] + cmul(top.Ts, bot.Ts, c, n)
          + left(top.e_up, top.Ts, right(cmul(W, top.Rs, c, n), bot.e_up, bot.Ts, c, n), c, n))
    es = None if top.es is None and bot.es is None else top.e_up * bot.e_up
    return Op(R, T, Rs, Ts, top.e * bot.e, es)


def double(R, T, e, c, n):
    """One doubling step of an up-down symmetric slab (R = R*, T = T*, so W = V): one solve."""
    W = resolvent(R, R, c, n)
    R2 = R + left(e, T, right(W, e, T, c, n), c, n)
    T2 = (e[:, None] * T + T * e[None, :] + cmul(T, T, c, n)
          + left(e, T, right(cmul(W, R, c, n), e, T, c, n), c, n))
    return R2, T2, e * e


def doubled_slab(SR, ST, sig, t, mu, c, n, K):
    """Op of one up-down symmetric slab t thick: the exact single scattering of a layer t 2^-K
    thick (reflection kernel ``SR``, transmission ``ST``: sigma_s f, extinction ``sig`` per
    cosine), doubled K times."""
    a = sig / mu
    t0 = t * 2.0 ** (-K)
    ao, ai = a[:, None], a[None, :]
    inv = t0 / (mu[:, None] * mu[None, :])
    R0 = SR * (inv * phi(t0 * (ao + ai)))
    T0 = ST * (jnp.exp(-t0 * ao) * inv * phi(t0 * (ai - ao)))

    def step(carry, level):
        R, T = carry
        e = jnp.exp(-(t0 * 2.0**level) * a)  # afresh at every level (see adding_doubling._slab)
        R2, T2, _ = double(R, T, e, c, n)
        return (R2, T2), None

    (R, T), _ = jax.lax.scan(step, (R0, T0), jnp.arange(K, dtype=mu.dtype))
    e = jnp.exp(-t * a)
    return Op(R, T, R, T, e)
