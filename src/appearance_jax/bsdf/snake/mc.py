"""The snake skin for a path tracer: the whole BSDF's sampler and an independent Monte Carlo f_d.

:func:`sample_full` samples the mirror lobe and the non-delta part f_d together (spec
§2.1.4); :func:`eval_mc` estimates f_d by a position-free random walk between the absorbing
diffuse layer and the film's underside (next-event estimation at every bottom vertex,
cosine-sampled bounces, the underside reflection taken as a weight or by Russian roulette),
the check of the Nyström solution of :mod:`.model` that shares none of its quadrature.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ...core import warp
from ...core.model import boundary, with_bands
from ...core.params import check_int
from ...core.rng import is_prng_key, uniforms
from ...core.vec import Vec3
from .model import Params, _components
from .solver import _band, _f1, _film_R, _film_Rs, _out, _safe_mu, _scal, _wavelengths


def _sample_full(p: Params, wi: Vec3, u):
    """Mirror lobe with probability mean(R) / (mean(R) + mean(A_d)), else cosine-weighted."""
    shape = jnp.shape(wi.z)
    u0, u1, u2 = uniforms(u, shape, 3)
    ok = wi.z > 0
    wd = warp.square_to_cosine_hemisphere(u1, u2)
    f, R, A = _components(p, wi, wd)
    r, a = jnp.mean(R, axis=-1), jnp.mean(A, axis=-1)
    tot = r + a
    pos = tot > 0
    p_spec = jnp.where(pos, r / jnp.where(pos, tot, 1.0), 0.0)
    is_delta = ok & (u0 < p_spec)
    mirror = Vec3(-wi.x, -wi.y, wi.z)
    wo = Vec3(*(jnp.where(is_delta, m, d) for m, d in zip(mirror, wd)))
    ok_d = ok & ~is_delta & (wd.z > 0) & (p_spec < 1)
    w_spec = R / with_bands(jnp.where(is_delta, p_spec, 1.0))
    w_diff = jnp.pi * f / with_bands(jnp.where(ok_d, 1.0 - p_spec, 1.0))
    weight = jnp.where(with_bands(is_delta), w_spec, jnp.where(with_bands(ok_d), w_diff, 0.0))
    return wo, weight, is_delta


def _eval_mc(p: Params, wi: Vec3, wo: Vec3, key, n_paths: int, max_bounces: int, roulette: bool):
    """Position-free random walk between f_1 and the film's underside (see :func:`eval_mc`)."""
    wl = _wavelengths(p)
    ok = (wi.z > 0) & (wo.z > 0)
    mi, mo = _safe_mu(wi.z), _safe_mu(wo.z)
    kd = _band(p.kd, 0)
    tau = _band(p.sigma_a, 0) * _scal(p.depth, 1)
    R_i, R_o = _film_Rs(p, wl, [(mi, "top", 1), (mo, "under", 1)])
    T_in, T_out = 1.0 - R_i, 1.0 - R_o  # S + (L,)
    base = jnp.broadcast_shapes(jnp.shape(mi), jnp.shape(mo), T_in.shape[:-1], T_out.shape[:-1],
                                kd.shape[:-1], tau.shape[:-1])
    L = wl.shape[0]
    shape = base + (n_paths,)
    kd, tau = kd[..., None, :], tau[..., None, :]  # broadcast against shape + (L,)
    mo_p = with_bands(jnp.broadcast_to(mo[..., None], shape))
    mu0 = jnp.broadcast_to(mi[..., None], shape)
    beta0 = jnp.broadcast_to(T_in[..., None, :], shape + (L,))
    acc0 = jnp.zeros(shape + (L,), beta0.dtype)

    def step(carry, k):
        mu, beta, acc = carry
        # next-event estimation towards wo at this bottom vertex
        acc = acc + beta * _f1(p.absorption, kd, tau, with_bands(mu), mo_p)
        # bounce: cosine-weighted mu' (pdf mu'/pi), weight f_1 mu' / pdf = pi f_1
        k1, k2 = jax.random.split(k)
        u = jax.random.uniform(k1, shape, beta.dtype)
        mu_new = jnp.sqrt(1.0 - u)  # in (0, 1]
        mu_new = jnp.where(mu_new > 0, mu_new, 1.0)
        R = _film_R(p, with_bands(mu_new), wl, 1, "under")
        beta = beta * jnp.pi * _f1(p.absorption, kd, tau, with_bands(mu), with_bands(mu_new))
        if roulette:  # survive the underside with probability mean_band(R), weight R / q
            q = jnp.mean(R, axis=-1)
            alive = jax.random.uniform(k2, shape, beta.dtype) < q
            beta = jnp.where(with_bands(alive), beta * R / with_bands(jnp.where(alive, q, 1.0)), 0.0)
        else:  # the underside reflection as a weight
            beta = beta * R
        return (mu_new, beta, acc), None

    keys = jax.random.split(key, max_bounces)
    (_, _, acc), _ = jax.lax.scan(step, (mu0, beta0, acc0), keys)
    x = acc * T_out[..., None, :]  # per-path estimates, base + (n_paths, L)
    x = jnp.where(with_bands(ok[..., None]), x, 0.0)
    x = _out(p, x)
    est = jnp.mean(x, axis=-2)
    se = jnp.std(x, axis=-2, ddof=1) / math.sqrt(n_paths) if n_paths > 1 else jnp.zeros_like(est)
    return est, se


# --------------------------------------------------------------------------------------
# public functions

_sample_full_b = boundary(_sample_full, Params)
_eval_mc_b = boundary(_eval_mc, Params, static_argnames=("n_paths", "max_bounces", "roulette"))


def sample_full(params: Params, wi: Vec3, u_or_key):
    """Sample the whole BSDF (mirror lobe + f_d) for a path tracer: ``(wo, weight, is_delta)``.

    The mirror direction is chosen with probability P = mean(R) / (mean(R) + mean(A_d))
    (band means of :func:`specular` and :func:`albedo`, spec §2.1.4), with weight R / P;
    otherwise a cosine-weighted direction with weight pi f_d / (1 - P). ``u_or_key``: a PRNG
    key or 3 uniform arrays (lobe choice, then the two of the cosine warp).
    """
    return _sample_full_b(params, wi, u_or_key)


def eval_mc(params: Params, wi: Vec3, wo: Vec3, key, n_paths: int = 4096, max_bounces: int = 64,
            roulette: bool = False):
    """Monte Carlo estimate of the non-delta part f_d and its standard error (bands).

    An independent, position-free random walk (the PFMC of the thesis reduced to this
    two-layer stack): the path enters through the film with the deterministic weight
    T(mu_i) and travels straight down at mu_i; at every bottom vertex (arriving at mu)

    * next-event estimation towards wo: adds weight f_1(mu, mu_o) T_u(mu_o);
    * bounce: mu' cosine-weighted (pdf mu'/pi in solid angle), weight *= pi f_1(mu, mu');
    * film underside: weight *= R_u(mu') (``roulette=False``), or the path survives with
      probability q = mean_band R_u(mu') and weight *= R_u / q (``roulette=True``; dead paths
      carry weight 0, the alive mask); then it goes down again at mu'.

    ``lax.scan`` over ``max_bounces`` vertices (the tail beyond them is dropped: bias
    <= the mean remaining weight, negligible for the 64 default unless R_u ~ 1 and
    k_d ~ 1 with sigma_a = 0). Returns ``(estimate, stderr)`` of shape ``wi.shape + (bands,)``;
    stderr = sample std (ddof 1) / sqrt(n_paths) over the per-path estimates. The same
    ``key`` gives the same numbers (common random numbers: the directions do not depend
    on the parameters, so gradients of the estimate are consistent). ``key``: a PRNG key
    or an int seed.
    """
    n_paths = check_int("snake.eval_mc: n_paths", n_paths, 2)
    max_bounces = check_int("snake.eval_mc: max_bounces", max_bounces, 1)
    if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
        key = jax.random.key(int(key))
    elif not is_prng_key(key):
        raise ValueError(f"snake.eval_mc: key = {key!r} must be a PRNG key or an int seed")
    return _eval_mc_b(params, wi, wo, key, n_paths=n_paths, max_bounces=max_bounces, roulette=bool(roulette))


__all__ = ["sample_full", "eval_mc"]
