"""Position-free Monte Carlo random walk through a stack of plane-parallel layers
(Guo, Hašan & Zhao 2018; Ch. 4 of Padrón 2025; seed-000 spec M16).

The stack: layers 0 .. L-1 from the top, each a homogeneous slab of the cosmetic medium
(:mod:`appearance_jax.layered.medium`: direction-dependent extinction, albedo and phase
function; ``c_d = 1`` is a classical HG-mixture medium) with a thickness in base mean free
paths and a real refractive index ``eta``; air (index 1) above; below the last layer any
BSDF model of this library, or nothing (black). Interfaces are smooth: where the indices
on both sides are equal they are index-matched (no reflection, no refraction: the
thesis' cosmetic layers [T:618, 653]); otherwise they are smooth dielectrics (Fresnel
reflection, Snell refraction). Layers are laterally infinite, so only the depth and the
direction of a path are tracked ("position-free").

The estimator, per path (spec M16, unidirectional with next-event estimation):

- the light refracts into layer 0 (throughput ``1 - F(mu_i)``; the top's mirror reflection
  ``F(mu_i)`` is a delta lobe and is not part of this estimate);
- at each step the path either collides inside its layer or reaches the layer's boundary:
  collide with probability ``p_c = 1 - exp(-sigma_t(d) s_max)`` and then at the distance
  ``s = -ln(1 - xi p_c) / sigma_t(d)`` (a truncated exponential, smooth in sigma_t and in
  the thickness; spec §6.4);
- at a collision it adds the next-event estimate ``beta Lambda(-d) f(-d -> wo_k)
  Tr_up T_up mu_o / (eta_k^2 mu_k)`` towards the viewer (``wo_k``: the viewing direction
  refracted into layer k; ``Tr_up``: the transmittance along it to the top; ``T_up``: the
  Fresnel transmittances of the interfaces above; ``mu_o / (eta_k^2 mu_k)``: radiance and
  solid-angle change across them) and scatters with the medium's collision kernel;
- at the bottom it adds ``beta f_b(-d, wo_L) mu_L ...`` and bounces by the bottom BSDF's
  own sampler;
- at an interface it reflects with probability F or refracts into the next layer; at the
  top, refraction means escape: the path ends (its light was counted by next-event
  estimation).

The mean of the path sums estimates ``f(wi, wo) mu_o``; :func:`walk` returns ``f`` and its
standard error. Every walk runs ``max_bounces`` steps of a ``lax.scan`` (a step is one
collision, one bottom bounce or one interface event); ended paths carry zero throughput
(an alive mask, no Russian roulette: §6.4). Light still in the stack after the last step
is lost: the truncation bias, measured in tests/layered/test_random_walk.py.

Gradients: all discrete choices (collide or cross, particle type, HG lobe, Fresnel
reflect or transmit) are drawn with stop-gradient probabilities and weighted by
``p / q`` (score terms); distances and directions are reparameterised. The autodiff
derivative of the estimate (same key: common random numbers) is an unbiased estimate of
the derivative of ``f``, in every medium parameter, the thicknesses and the bottom BSDF's
parameters (pathwise through its sampler).

Random numbers: one PRNG key per call; the same key gives the same numbers for the same
shapes (common random numbers for fitting).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp

from ..core.model import with_bands
from ..core.vec import Vec3, where
from . import medium as med
from ..optics.fresnel import fresnel_dielectric

_TINY = 1e-12


@dataclass(frozen=True)
class Bottom:
    """The surface below the stack: a model of this library and its parameters.

    ``eval(params, wi, wo)`` and ``sample(params, wi, u)`` of the model's kernels are used
    (no validation inside the walk). ``None`` instead of a Bottom is black.
    """

    model: Any
    params: Any


class _Static:
    """Hashable-by-identity holder of a model (pytree auxiliary data of :class:`Bottom`)."""

    def __init__(self, obj):
        self.obj = obj

    def __hash__(self):
        return id(self.obj)

    def __eq__(self, other):
        return isinstance(other, _Static) and other.obj is self.obj


jax.tree_util.register_pytree_node(
    Bottom, lambda b: ((b.params,), _Static(b.model)), lambda aux, ch: Bottom(aux.obj, ch[0]))


def _fresnel(cos_i, eta_ratio):
    """Unpolarised Fresnel reflectance for |cos_i| and eta_t / eta_i, and cos_t >= 0 (0 under TIR)."""
    F, cos_t, _, _ = fresnel_dielectric(jnp.abs(cos_i), eta_ratio)
    return F, -cos_t  # fresnel_dielectric's cos_t has the sign opposite to cos_i


def _pick(stacked, k, n_layers: int, bands: bool = False):
    """``stacked[k]`` for an integer array ``k`` of layer indices (one-hot sum: differentiable).

    ``bands``: the entries carry a trailing bands axis that ``k`` lacks."""
    if n_layers == 1:
        return stacked[0]
    out = 0.0
    for j in range(n_layers):
        sel = k == j
        out = out + jnp.where(sel[..., None] if bands else sel, stacked[j], 0.0)
    return out


def _layer(media, k, n_layers):
    """The medium parameters of layer ``k`` (per path)."""
    return med.Params(**{name: _pick(getattr(media, name), k, n_layers, name in med.BAND_FIELDS)
                         for name in med.FIELDS})


def _inside(w: Vec3, eta):
    """The direction inside a medium of index ``eta`` (below air) that refracts into ``w``
    (pointing up), with its cosine; zero vector and mu = 0 where no such direction exists."""
    sin2 = (w.x * w.x + w.y * w.y) / (eta * eta)
    ok = sin2 < 1.0
    mu = jnp.sqrt(jnp.where(ok, 1.0 - sin2, 1.0))
    v = Vec3(w.x / eta, w.y / eta, mu)
    zero = jnp.zeros_like(mu)
    return where(ok, v, Vec3(zero, zero, zero)), jnp.where(ok, mu, 0.0)


def _rotate_z(w: Vec3, c, s) -> Vec3:
    return Vec3(c * w.x - s * w.y, s * w.x + c * w.y, w.z)


@functools.partial(jax.jit, static_argnames=("n_samples", "max_bounces", "orders", "azimuth_average", "n_bands"))
def walk(media, thickness, wi: Vec3, wo: Vec3, key, *, eta=None, bottom: Bottom | None = None,
         n_samples: int = 128, max_bounces: int = 128, orders: tuple[int, int | None] = (1, None),
         azimuth_average: bool = False, n_bands: int | None = None):
    """Estimate the BSDF ``f(wi, wo)`` [1/sr] of a layer stack and its standard error.

    Args:
        media: medium parameters (:class:`appearance_jax.layered.medium.Params` or any object
            with its fields) with a **leading layer axis** (top first) on every field:
            ``c_d`` (L,), ``albedo_d`` (L, B) ...
        thickness: (L,) layer thicknesses in base mean free paths (>= 0).
        wi, wo: directions (Vec3, same or broadcastable shapes S), pointing away, z = normal.
        key: a PRNG key (common random numbers: the same key gives the same estimate).
        eta: (L,) refractive indices of the layers' host media (default 1: index-matched).
        bottom: the BSDF below the stack (:class:`Bottom`) or None (black).
        n_samples: paths per direction pair. max_bounces: steps of the walk (collisions,
            bottom bounces and interface events each take one).
        orders: count only light scattered ``orders[0] <= n <= orders[1]`` times (volume
            collisions and bottom bounces); (1, 1) is single scattering.
        azimuth_average: rotate each path's (wi, wo) pair by a uniform random azimuth
            about the normal: the BSDF of the sample rotated uniformly about n (spec §4.1,
            ``azimuth_mode = "averaged"``).
        n_bands: number of output bands (default: from the albedos).

    Returns:
        ``(f, stderr)``, each of shape ``S + (B,)``. Directions at or below the horizon give 0.
    """
    f, se, _ = _run(media, thickness, wi, wo, key, eta, bottom, n_samples, max_bounces, orders,
                    azimuth_average, n_bands, "nee")
    return f, se


@functools.partial(jax.jit, static_argnames=("n_samples", "max_bounces", "n_bands"))
def albedo(media, thickness, wi: Vec3, key, *, eta=None, bottom: Bottom | None = None, n_samples: int = 4096,
           max_bounces: int = 128, n_bands: int | None = None):
    """Directional albedo of the stack by counting escaping paths (no next-event estimation).

    The throughput of every path that leaves through the top is the estimate of the
    fraction of the light from ``wi`` that the stack reflects diffusely (the top's mirror
    reflection excluded). Returns ``(albedo, stderr, remaining)``: ``remaining`` is the
    mean throughput still inside the stack after ``max_bounces`` steps -- the energy a
    truncated walk loses (with lossless media over a white base, albedo + remaining = 1).
    An independent check of the next-event estimates of :func:`walk`, whose integral
    over wo must equal this albedo.
    """
    return _run(media, thickness, wi, wi, key, eta, bottom, n_samples, max_bounces, (1, None), False,
                n_bands, "escape")


def _run(media, thickness, wi, wo, key, eta, bottom, n_samples, max_bounces, orders, azimuth_average,
         n_bands, mode):
    L = int(jnp.shape(thickness)[0])
    thickness = jnp.asarray(thickness)
    eta = jnp.ones((L,), thickness.dtype) if eta is None else jnp.asarray(eta, thickness.dtype)
    if n_bands is None:
        n_bands = max(jnp.shape(jnp.atleast_1d(media.albedo_d))[-1] if jnp.ndim(media.albedo_d) > 1 else 1,
                      jnp.shape(jnp.atleast_1d(media.albedo_p))[-1] if jnp.ndim(media.albedo_p) > 1 else 1)
    B = n_bands
    media = med.Params(**{n: (jnp.broadcast_to(jnp.asarray(getattr(media, n)).reshape(L, -1), (L, B))
                           if n in med.BAND_FIELDS else jnp.broadcast_to(jnp.asarray(getattr(media, n)), (L,)))
                       for n in med.FIELDS})
    z_top = jnp.concatenate([jnp.zeros((1,), thickness.dtype), jnp.cumsum(thickness)[:-1]])
    z_bot = jnp.cumsum(thickness)
    eta_above = jnp.concatenate([jnp.ones((1,), eta.dtype), eta[:-1]])
    lo, hi = orders
    hi = max_bounces + 1 if hi is None else hi

    S = jnp.broadcast_shapes(jnp.shape(wi.z), jnp.shape(wo.z))
    shape = S + (n_samples,)
    key_rot, key_walk = jax.random.split(key)
    # the walk runs on one flat axis (directions x samples): XLA:CPU compiles elementwise
    # kernels over a flat axis much faster than over broadcasts (same numbers, same order)
    full_shape, shape = shape, (math.prod(shape),)
    wi = wi.map(lambda a: jnp.broadcast_to(jnp.asarray(a)[..., None], full_shape).reshape(shape))
    wo = wo.map(lambda a: jnp.broadcast_to(jnp.asarray(a)[..., None], full_shape).reshape(shape))
    if azimuth_average:
        psi = 2.0 * jnp.pi * jax.random.uniform(key_rot, shape, thickness.dtype)
        c, s = jnp.cos(psi), jnp.sin(psi)
        wi, wo = _rotate_z(wi, c, s), _rotate_z(wo, c, s)
    ok = (wi.z > 0) & (wo.z > 0)
    mu_o = jnp.where(ok, wo.z, 1.0)

    # --- what next-event estimation needs per layer j: the viewing direction inside it, its
    # transmittance through the layers above and the interface factors (independent of the path)
    wo_in, mu_in, sig_o, factor, tau_above = [], [], [], [], []
    T_up, tau_acc = jnp.ones(shape), jnp.zeros(shape)
    for j in range(L):
        wj, mj = _inside(wo, eta[j])
        # interface above layer j: from index eta[j] up into eta_above[j]
        F, _ = _fresnel(mj, eta_above[j] / eta[j])
        T_up = T_up * jnp.where(mj > 0, 1.0 - F, 0.0)
        mj_safe = jnp.where(mj > 0, mj, 1.0)
        m_j = med.Params(**{n: getattr(media, n)[j] for n in med.FIELDS})
        sj = med.extinction(m_j, wj)
        wo_in.append(wj)
        mu_in.append(mj_safe)
        sig_o.append(sj)
        factor.append(T_up * mu_o / (eta[j] ** 2 * mj_safe))
        tau_above.append(tau_acc)
        tau_acc = tau_acc + sj * thickness[j] / mj_safe

    def pick_vec(lst, k):
        return Vec3(*(_pick([getattr(v, c) for v in lst], k, L) for c in "xyz"))

    def transmittance_up(depth, k):
        """Tr_up x interface factors from depth inside layer k to the viewer."""
        mk = _pick(mu_in, k, L)
        return _pick(factor, k, L) * jnp.exp(-_pick(tau_above, k, L) - _pick(sig_o, k, L) * (depth - z_top[k]) / mk)

    # --- entering: refraction into layer 0
    F0, ct0 = _fresnel(jnp.where(ok, wi.z, 1.0), eta[0])
    d0 = Vec3(-wi.x / eta[0], -wi.y / eta[0], -ct0)
    beta0 = with_bands(jnp.where(ok, 1.0 - F0, 0.0)) * jnp.ones(shape + (B,))
    depth0 = jnp.zeros(shape)
    k0 = jnp.zeros(shape, jnp.int32)
    order0 = jnp.zeros(shape, jnp.int32)
    acc0 = jnp.zeros(shape + (B,))

    def bottom_nee(beta, wb_in):
        if bottom is None:
            return jnp.zeros_like(beta)
        kL = jnp.full(shape, L - 1, jnp.int32)
        wL = wo_in[L - 1]
        f_b = jnp.asarray(bottom.model.eval.kernel(bottom.params, wb_in, wL))
        return beta * f_b * with_bands(mu_in[L - 1] * transmittance_up(z_bot[L - 1], kL))

    def step(carry, step_key):
        depth, k, d, beta, acc, order = carry
        u = jax.random.uniform(step_key, (8,) + shape, thickness.dtype)
        m = _layer(media, k, L)
        down = d.z < 0
        dz = jnp.where(jnp.abs(d.z) > _TINY, jnp.abs(d.z), _TINY)
        s_max = jnp.where(down, z_bot[k] - depth, depth - z_top[k]) / dz
        s_max = jnp.maximum(s_max, 0.0)
        back = -d
        sig = med.extinction(m, back)
        p_c = -jnp.expm1(-sig * s_max)
        collide, w_c = med.choice_weight(p_c, u[0])
        p_cs = jnp.where(p_c > 0, p_c, 1.0)
        s = -jnp.log1p(-u[1] * p_cs) / sig
        depth_c = depth - s * d.z  # depth grows downwards (d.z < 0)
        depth_c = jnp.clip(depth_c, z_top[k], z_bot[k])
        beta = beta * with_bands(w_c)

        # (a) volume collision: next-event estimate, then scatter
        n_new = order + 1
        count = with_bands(collide & (n_new >= lo) & (n_new <= hi))
        wo_k = pick_vec(wo_in, k)
        nee_v = beta * med.scattering(m, back, wo_k) * with_bands(transmittance_up(depth_c, k))
        wo_c, w_s = med.collide(m, back, u[2], u[3], u[4], u[5])

        # (b) reaching a boundary
        at_bottom = ~collide & down & (k == L - 1)
        at_top = ~collide & ~down & (k == 0)
        crossing = ~collide & ~at_bottom & ~at_top
        # bottom surface
        count_b = with_bands(at_bottom & (n_new >= lo) & (n_new <= hi))
        nee_b = bottom_nee(beta, back)
        if bottom is None:
            wo_b, w_b = d, jnp.zeros_like(beta)
        else:
            wo_b, w_b, _ = bottom.model.sample.kernel(bottom.params, back, (u[5], u[6], u[7]))
            good = wo_b.z > 0
            w_b = jnp.where(with_bands(good), jnp.asarray(w_b), 0.0)
            up = Vec3(jnp.zeros(shape), jnp.zeros(shape), jnp.ones(shape))
            wo_b = where(good, wo_b, up)  # a failed sample keeps a valid direction (weight 0)
        # interfaces: above layer k (moving up) or below it (moving down); k_next the other side
        k_next = jnp.clip(jnp.where(down, k + 1, k - 1), 0, L - 1)
        eta_here = eta[k]
        eta_there = jnp.where(at_top, 1.0, eta[k_next])
        F, ct = _fresnel(d.z, eta_there / eta_here)
        reflect_i, w_f = med.choice_weight(F, u[7])
        ratio = eta_here / eta_there
        d_t = Vec3(d.x * ratio, d.y * ratio, jnp.where(down, -ct, ct))
        d_r = Vec3(d.x, d.y, -d.z)
        d_i = where(reflect_i, d_r, d_t)
        escape = at_top & ~reflect_i

        # --- combine
        if mode == "nee":
            acc = acc + jnp.where(count, nee_v, 0.0) + jnp.where(count_b, nee_b, 0.0)
        else:  # escape counting: the light leaving through the top
            acc = acc + jnp.where(with_bands(escape), beta * with_bands(w_f), 0.0)
        d_new = where(collide, wo_c, where(at_bottom, wo_b, d_i))
        w_step = jnp.where(with_bands(collide), w_s,
                           jnp.where(with_bands(at_bottom), w_b, with_bands(jnp.where(escape, 0.0, w_f))))
        beta = beta * w_step
        depth_new = jnp.where(collide, depth_c, jnp.where(down, z_bot[k], z_top[k]))
        k_new = jnp.where(crossing & ~reflect_i, k_next, k)
        order = jnp.where(collide | at_bottom, n_new, order)
        return (depth_new, k_new, d_new, beta, acc, order), None

    keys = jax.random.split(key_walk, max_bounces)
    (_, _, _, beta, acc, _), _ = jax.lax.scan(step, (depth0, k0, d0, beta0, acc0, order0), keys)
    if mode == "nee":
        x = jnp.where(with_bands(ok), acc / with_bands(mu_o), 0.0)
    else:
        x = jnp.where(with_bands(ok), acc, 0.0)
    x, beta, ok = x.reshape(full_shape + (B,)), beta.reshape(full_shape + (B,)), ok.reshape(full_shape)
    f = jnp.mean(x, axis=-2)
    se = jnp.std(x, axis=-2, ddof=1) / math.sqrt(n_samples) if n_samples > 1 else jnp.zeros_like(f)
    remaining = jnp.mean(jnp.where(with_bands(ok), beta, 0.0), axis=-2)
    return f, se, remaining
