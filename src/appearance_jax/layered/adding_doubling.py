"""Adding-doubling for stacks of HG-mixture slabs over a Lambertian bottom (spec M36).

A deterministic, differentiable reference for the reflection of plane-parallel,
**index-matched** (no refraction, no Fresnel), homogeneous slabs with isotropic
extinction (σ_t = 1 per unit thickness, so thicknesses are optical thicknesses in mean
free paths), each scattering with albedo ϖ and the two-lobe HG mixture of spec M13,

    p(cos) = w_g f_HG(g1, cos) + (1 - w_g) f_HG(g2, cos),     cos = wi . wo (both away),

stacked top first over a Lambertian bottom of albedo ρ (ρ = 0: black). Method of van de
Hulst (1980, "Multiple Light Scattering", Ch. 5 and 14 (doubling, adding)), derived and
written here in the following form.

``layers``: one :class:`HGLayer` or a sequence of them, top first. Fields are scalars or
arrays with a trailing bands axis (RGB); ``bottom_albedo`` likewise.

| field     | default | range   | unit | meaning                                                |
|-----------|---------|---------|------|--------------------------------------------------------|
| albedo    | --      | [0, 1]  | 1    | single-scattering albedo ϖ = σ_s/σ_t, per band         |
| thickness | --      | [0, oo) | mfp  | optical thickness t (σ_t = 1), per band allowed        |
| g1        | 0.0     | (-1, 1) | 1    | asymmetry of HG lobe 1 (> 0 forward)                   |
| g2        | 0.0     | (-1, 1) | 1    | asymmetry of HG lobe 2                                 |
| w_g       | 1.0     | [0, 1]  | 1    | weight of lobe 1 (1: single lobe HG(g1))               |
| bottom_albedo ρ | -- | [0, 1] | 1    | Lambertian bottom, f = ρ/π, per band                   |

Method (the derivation, written out in docs/cosmetics.md): ``n_nodes`` Gauss-Legendre
cosines per hemisphere ("double Gauss"); the phase function in Legendre moments
χ_l = w_g g1^l + (1 - w_g) g2^l, split into ``n_fourier`` azimuthal Fourier modes; each slab
starts from a layer of thickness t 2^-K (K = ``n_doublings``, default 30) with the exact
single-scattering kernels (spec M35), doubled K times, then the slabs and the Lambertian
bottom are combined with the adding equations; the direct beam is carried as a diagonal,
never as a kernel. A zero-thickness layer is an exact no-op. Arbitrary query cosines are
appended to the nodes with zero quadrature weight (no interpolation error). Cost per
Fourier mode and band: O(K (n + q)^2 n) with q = 2 x (number of query pairs); evaluate
large tables in chunks, or on a cosine grid with :func:`fourier_kernels`.

Accuracy: the defaults ``n_nodes = 24`` and ``n_fourier = 24`` suit lobes up to g ~ 0.8
(measured numbers: docs/cosmetics.md). Use float64 (``jax_enable_x64``): the starting layer
is ~1e-9 thick and thirty doublings amplify float32 rounding.
Below-horizon or grazing directions (μ <= 0) return 0, with finite gradients.

Public functions: :func:`brdf` (full azimuth), :func:`brdf_azimuthal_average` (m = 0),
:func:`albedo_directional` (over the bottom), :func:`reflectance_transmittance` (stack
alone, black bottom), :func:`fourier_kernels` (all modes on a cosine grid).
"""

from __future__ import annotations

import math
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..core.params import ParamSpec, check_int, check_value
from ..core.quadrature import gauss_legendre
from ..core.special import atan2
from ..core.vec import Vec3
from .kernel_ops import (Op as _Op, add as _add, cmul as _cmul, double as _double, left as _left, phi as _phi,
                         resolvent as _resolvent, right as _right)

DEFAULT_NODES = 24
DEFAULT_FOURIER = 24
DEFAULT_DOUBLINGS = 30

_MU_SAFE = 0.5  # stand-in cosine for masked (below-horizon) queries: keeps gradients finite


class HGLayer(NamedTuple):
    """One homogeneous slab (see the module's parameter table). A NamedTuple, hence a pytree."""

    albedo: Any
    thickness: Any
    g1: Any = 0.0
    g2: Any = 0.0
    w_g: Any = 1.0


# ------------------------------------------------------------------------------------
# validation (eager, at the public boundary; skipped for traced values)


def _check_range(name, v, lo, hi, lo_open=False, hi_open=False):
    hi = math.inf if hi is None else hi
    check_value(f"adding_doubling: {name}", v, ParamSpec(lo, hi, lo_open, hi_open))


def _check_int(name, v):
    check_int(f"adding_doubling: {name}", v)


def _as_layers(layers) -> tuple:
    if isinstance(layers, HGLayer):
        return (layers,)
    layers = tuple(layers)
    if not layers or not all(isinstance(l, HGLayer) for l in layers):
        raise ValueError(f"adding_doubling: layers = {layers!r} must be an HGLayer or a non-empty sequence of them")
    return layers


def _validate(layers, bottom_albedo, n_nodes, n_fourier, n_doublings):
    _check_int("n_nodes", n_nodes)
    _check_int("n_fourier", n_fourier)
    _check_int("n_doublings", n_doublings)
    for i, l in enumerate(layers):
        _check_range(f"layers[{i}].albedo", l.albedo, 0.0, 1.0)
        _check_range(f"layers[{i}].thickness", l.thickness, 0.0, None)
        _check_range(f"layers[{i}].g1", l.g1, -1.0, 1.0, True, True)
        _check_range(f"layers[{i}].g2", l.g2, -1.0, 1.0, True, True)
        _check_range(f"layers[{i}].w_g", l.w_g, 0.0, 1.0)
    _check_range("bottom_albedo", bottom_albedo, 0.0, 1.0)


# ------------------------------------------------------------------------------------
# angular building blocks


def _assoc_legendre(mu, n_fourier: int, n_legendre: int):
    """Normalised associated Legendre functions Λ_l^m(mu) = sqrt((l-m)!/(l+m)!) P_l^m(mu).

    Shape ``(n_fourier, n_legendre) + mu.shape``; zero for l < m. The Condon-Shortley phase
    is dropped (it cancels in the products Λ_l^m(μ) Λ_l^m(μ') used here). Recurrence in l
    for all m at once (stable upward recurrence of the normalised functions):
    Λ_l^m = [(2l-1) μ Λ_{l-1}^m - sqrt((l-1)^2 - m^2) Λ_{l-2}^m] / sqrt(l^2 - m^2).
    """
    mu = jnp.asarray(mu)
    s = jnp.sqrt(jnp.maximum(1.0 - mu * mu, 0.0))
    m = np.arange(n_fourier)
    # Λ_m^m = prod_{k=1..m} sqrt((2k-1)/(2k)) * s^m
    coef = np.concatenate([[1.0], np.cumprod(np.sqrt((2 * m[1:] - 1) / (2.0 * m[1:])))])
    mm = jnp.asarray(coef).reshape((-1,) + (1,) * mu.ndim) * s[None] ** m.reshape((-1,) + (1,) * mu.ndim)
    mb = m.reshape((-1,) + (1,) * mu.ndim).astype(float)

    def step(carry, l):
        p1, p2 = carry  # Λ_{l-1}, Λ_{l-2}
        lf = l.astype(mu.dtype)
        den = jnp.sqrt(jnp.maximum(lf * lf - mb * mb, 1.0))
        c2 = jnp.sqrt(jnp.maximum((lf - 1.0) ** 2 - mb * mb, 0.0))
        rec = ((2.0 * lf - 1.0) * mu * p1 - c2 * p2) / den
        new = jnp.where(lf == mb, mm, jnp.where(lf > mb, rec, 0.0))
        return (new, p1), new

    zeros = jnp.zeros_like(mm)
    _, lam = jax.lax.scan(step, (zeros, zeros), jnp.arange(n_legendre))
    return jnp.swapaxes(lam, 0, 1)  # (M, L, ...)


def _phase_modes(chi, lam):
    """Fourier kernels of the phase function: ``(pR, pT)`` of shape (M, N, N) [1/sr].

    ``chi``: (L,) Legendre moments; ``lam``: (M, L, N) normalised associated Legendre.
    Index order [out, in]. pR carries (-1)^(l+m) (one of the two cosines flips sign).
    """
    M, L, _ = lam.shape
    l = np.arange(L)
    a = chi * (2.0 * l + 1.0) / (4.0 * np.pi)
    sign = (-1.0) ** (l[None, :] + np.arange(M)[:, None])  # (M, L)
    pT = jnp.einsum("l,mla,mlb->mab", a, lam, lam)
    pR = jnp.einsum("ml,mla,mlb->mab", a * sign, lam, lam)
    return pR, pT


# ------------------------------------------------------------------------------------
# one slab (the kernel algebra is in .kernel_ops)


def _slab(albedo, thickness, chi, lam, mu, c, n, n_doublings):
    """R, T (M, N, N) and e (N,) of one homogeneous slab: thin start + ``n_doublings`` doublings."""
    pR, pT = _phase_modes(chi, lam)
    tau0 = thickness * 2.0 ** (-n_doublings)
    mo = mu[:, None]  # out
    mi = mu[None, :]  # in
    inv = tau0 / (mo * mi)
    # exact single scattering in the starting layer (spec M35 with σ_t = 1), written with
    # phi(x) = (1 - e^-x)/x so that t = 0 and μo = μi need no special case
    R0 = albedo * pR * (inv * _phi(tau0 * (1.0 / mi + 1.0 / mo)))
    T0 = albedo * pT * (jnp.exp(-tau0 / mo) * inv * _phi(tau0 * (1.0 / mi - 1.0 / mo)))

    def step(carry, level):
        R, T = carry
        # the direct beam of the current layer, exp(-τ0 2^j / μ), computed afresh at every
        # level: squaring e0 = 1 - O(1e-9) thirty times would turn its rounding error into
        # a relative error ~1e-7 of exp(-t/μ) (measured as finite-difference noise in t)
        e = jnp.exp(-(tau0 * 2.0**level) / mu)
        R2, T2, _ = _double(R, T, e, c, n)
        return (R2, T2), None

    levels = jnp.arange(n_doublings, dtype=mu.dtype)
    (R, T), _ = jax.lax.scan(step, (R0, T0), levels)
    e = jnp.exp(-(tau0 * 2.0**n_doublings) / mu)
    return _Op(R, T, R, T, e)


def _moments(g1, g2, w_g, n_legendre):
    """Legendre moments of the HG mixture, chi_l = w g1^l + (1 - w) g2^l (spec M12/M13)."""
    # g^l as cumulative products: exact at g = 0 (g^0 = 1) with finite derivatives,
    # where jnp.power(g, l) would differentiate through log(g)
    def powers(g):
        return jnp.concatenate([jnp.ones((1,), jnp.result_type(g, float)),
                                jnp.cumprod(jnp.full((n_legendre - 1,), g))])

    return w_g * powers(g1) + (1.0 - w_g) * powers(g2)


def _solve_band(P, rho, mu_x, n, n_fourier, n_doublings, want_stack=False):
    """Reflection kernels (M, N, N) of the stack over the Lambertian bottom, one band.

    ``P``: (n_layers, 5) rows (albedo, thickness, g1, g2, w_g), top first; ``rho``: scalar.
    Node list: the n Gauss nodes, then the zero-weight queries ``mu_x``.
    """
    x, w = gauss_legendre(n, 0.0, 1.0)
    mu = jnp.concatenate([jnp.asarray(x), mu_x])
    c = jnp.concatenate([jnp.asarray(2.0 * np.pi * x * w), jnp.zeros_like(mu_x)])
    n_legendre = 2 * n  # double-Gauss integrates P_l exactly for l <= 2n - 1: discrete energy conservation
    lam = _assoc_legendre(mu, n_fourier, n_legendre)

    def one(p):
        chi = _moments(p[2], p[3], p[4], n_legendre)
        return _slab(p[0], p[1], chi, lam, mu, c, n, n_doublings)

    slabs = jax.vmap(one)(P)
    stack = jax.tree_util.tree_map(lambda a: a[0], slabs)
    for i in range(1, P.shape[0]):
        stack = _add(stack, jax.tree_util.tree_map(lambda a, i=i: a[i], slabs), c, n)
    N = mu.shape[0]
    # Lambertian bottom: R = ρ/π in mode 0 only, no transmission
    Rb = jnp.zeros((n_fourier, N, N), dtype=stack.R.dtype).at[0].set(rho / np.pi)
    W = _resolvent(Rb, stack.Rs, c, n)
    R = stack.R + _left(stack.e, stack.Ts, _right(W, stack.e, stack.T, c, n), c, n)
    if want_stack:
        return R, stack, c
    return R


# ------------------------------------------------------------------------------------
# public functions


def _prepare(layers, bottom_albedo, n_nodes, n_fourier, n_doublings):
    """Validate and pack parameters: ``(P (n_layers, 5, B), rho (B,), banded)``."""
    layers = _as_layers(layers)
    _validate(layers, bottom_albedo, n_nodes, n_fourier, n_doublings)
    leaves = [jnp.asarray(v, dtype=jnp.result_type(float)) for l in layers for v in
              (l.albedo, l.thickness, l.g1, l.g2, l.w_g)]
    rho = jnp.asarray(bottom_albedo, dtype=jnp.result_type(float))
    for v in leaves + [rho]:
        if v.ndim > 1:
            raise ValueError(f"adding_doubling: parameter of shape {v.shape}: expected a scalar or one bands axis")
    banded = any(v.ndim == 1 for v in leaves + [rho])
    B = jnp.broadcast_shapes(*[v.shape for v in leaves + [rho]]) if banded else (1,)
    leaves = [jnp.broadcast_to(v, B) for v in leaves]
    P = jnp.stack(leaves).reshape(len(layers), 5, B[0])
    return P, jnp.broadcast_to(rho, B), banded


def _queries(mu):
    """Cosines safe to put on the node list (μ <= 0 replaced; masked later) and the mask."""
    mu = jnp.asarray(mu, dtype=jnp.result_type(float))
    above = mu > 0.0
    return jnp.where(above, jnp.minimum(mu, 1.0), _MU_SAFE), above


def _kernels(P, rho, mu_x, n, M, K):
    """(M, N, N, B) reflection kernels, bands last, in the 'away' azimuth convention."""
    R = jax.vmap(lambda p, r: _solve_band(p, r, mu_x, n, M, K), in_axes=(2, 0), out_axes=-1)(P, rho)
    sign = (-1.0) ** np.arange(M)  # propagation -> away azimuths: cos(m(Δφ - π)) = (-1)^m cos(mΔφ)
    return R * sign[:, None, None, None]


def fourier_kernels(layers, bottom_albedo, mu, *, n_nodes: int = DEFAULT_NODES,
                    n_fourier: int = DEFAULT_FOURIER, n_doublings: int = DEFAULT_DOUBLINGS):
    """Fourier modes f_m(μ_out, μ_in) of the BRDF on a grid of cosines [1/sr].

    ``mu``: 1-D array of k cosines in (0, 1]. Returns shape ``(n_fourier, k, k)`` (+ bands),
    index order [out, in], such that ``f = sum_m (2 - δ_m0) f_m cos(m (φo - φi))`` with the
    azimuths of the directions pointing away from the surface. Entries at μ <= 0 are 0.
    """
    P, rho, banded = _prepare(layers, bottom_albedo, n_nodes, n_fourier, n_doublings)
    return _fourier_kernels(P, rho, jnp.asarray(mu), banded, n_nodes, n_fourier, n_doublings)


@partial(jax.jit, static_argnums=(3, 4, 5, 6))
def _fourier_kernels(P, rho, mu, banded, n, M, K):
    mq, above = _queries(jnp.ravel(mu))
    F = _kernels(P, rho, mq, n, M, K)[:, n:, n:]
    F = jnp.where((above[:, None] & above[None, :])[None, :, :, None], F, 0.0)
    return F if banded else F[..., 0]


@partial(jax.jit, static_argnums=(5, 6, 7, 8))
def _brdf(P, rho, mu_i, mu_o, dphi, banded, n, M, K):
    shape = jnp.broadcast_shapes(mu_i.shape, mu_o.shape, dphi.shape)
    mi, ai = _queries(jnp.broadcast_to(mu_i, shape).ravel())
    mo, ao = _queries(jnp.broadcast_to(mu_o, shape).ravel())
    q = mi.shape[0]
    F = _kernels(P, rho, jnp.concatenate([mi, mo]), n, M, K)  # (M, N, N, B)
    idx = jnp.arange(q)
    pairs = F[:, n + q + idx, n + idx]  # (M, q, B): out = μo, in = μi
    m = np.arange(M)
    cosm = jnp.cos(m[:, None] * jnp.broadcast_to(dphi, shape).ravel()[None, :]) * np.where(m == 0, 1.0, 2.0)[:, None]
    f = jnp.einsum("mq,mqb->qb", cosm, pairs)
    f = jnp.where((ai & ao)[:, None], f, 0.0).reshape(shape + (-1,))
    return f if banded else f[..., 0]


def brdf(layers, bottom_albedo, wi: Vec3, wo: Vec3, *, n_nodes: int = DEFAULT_NODES,
         n_fourier: int = DEFAULT_FOURIER, n_doublings: int = DEFAULT_DOUBLINGS):
    """BRDF f(wi, wo) of the stack over the Lambertian bottom, full azimuth dependence [1/sr].

    ``wi``, ``wo``: Vec3 (pointing away, z = normal), broadcast against each other.
    Returns ``shape + bands`` (no bands axis when every parameter is a scalar); 0 where
    either cosine is <= 0. Cost: see the module docstring ("Query angles").
    """
    P, rho, banded = _prepare(layers, bottom_albedo, n_nodes, n_fourier, n_doublings)
    dphi = atan2(wo.y, wo.x) - atan2(wi.y, wi.x)
    return _brdf(P, rho, jnp.asarray(wi.z), jnp.asarray(wo.z), dphi, banded, n_nodes, n_fourier, n_doublings)


def brdf_azimuthal_average(layers, bottom_albedo, mu_i, mu_o, *, n_nodes: int = DEFAULT_NODES,
                           n_fourier: int = 1, n_doublings: int = DEFAULT_DOUBLINGS):
    """Azimuthal average (1/2π) ∫ f dΔφ = f_0(μi, μo) of the BRDF [1/sr] (mode m = 0 only).

    ``mu_i``, ``mu_o`` broadcast; only the m = 0 mode is computed (``n_fourier`` is
    accepted for symmetry and ignored beyond 1).
    """
    P, rho, banded = _prepare(layers, bottom_albedo, n_nodes, n_fourier, n_doublings)
    mu_i = jnp.asarray(mu_i, dtype=jnp.result_type(float))
    return _brdf(P, rho, mu_i, jnp.asarray(mu_o, dtype=mu_i.dtype), jnp.zeros(()), banded, n_nodes, 1, n_doublings)


@partial(jax.jit, static_argnums=(3, 4, 5, 6))
def _albedo(P, rho, mu_i, banded, n, K, with_t):
    shape = jnp.shape(mu_i)
    mi, ai = _queries(jnp.ravel(mu_i))
    out = []
    for b in range(P.shape[2]):
        R, stack, c = _solve_band(P[:, :, b], rho[b], mi, n, 1, K, want_stack=True)
        alb = jnp.einsum("j,jq->q", c[:n], R[0, :n, n:])
        tr = stack.e[n:] + jnp.einsum("j,jq->q", c[:n], stack.T[0, :n, n:])
        out.append((alb, tr))
    alb = jnp.stack([o[0] for o in out], -1)
    tr = jnp.stack([o[1] for o in out], -1)
    alb = jnp.where(ai[:, None], alb, 0.0).reshape(shape + (-1,))
    tr = jnp.where(ai[:, None], tr, 0.0).reshape(shape + (-1,))
    if not banded:
        alb, tr = alb[..., 0], tr[..., 0]
    return (alb, tr) if with_t else alb


def albedo_directional(layers, bottom_albedo, mu_i, *, n_nodes: int = DEFAULT_NODES,
                       n_doublings: int = DEFAULT_DOUBLINGS):
    """Directional-hemispherical reflectance ∫ f(μi, wo) μo dωo of the stack over the bottom [1].

    Computed from the m = 0 mode with the Gauss rule (exact for the discrete solution).
    """
    P, rho, banded = _prepare(layers, bottom_albedo, n_nodes, 1, n_doublings)
    return _albedo(P, rho, jnp.asarray(mu_i, dtype=jnp.result_type(float)), banded, n_nodes, n_doublings, False)


def reflectance_transmittance(layers, mu_i, *, n_nodes: int = DEFAULT_NODES,
                              n_doublings: int = DEFAULT_DOUBLINGS):
    """Directional reflectance and total (direct + diffuse) transmittance of the stack, no bottom [1].

    For illumination from above at cosine ``mu_i``; the transmitted light leaves the
    bottom of the lowest layer. For ϖ = 1 everywhere, R + T = 1 (energy conservation).
    """
    P, rho, banded = _prepare(layers, 0.0, n_nodes, 1, n_doublings)
    return _albedo(P, rho, jnp.asarray(mu_i, dtype=jnp.result_type(float)), banded, n_nodes, n_doublings, True)
