"""Precomputed coat integrals: T(mu) and R_int of a rough dielectric coat, interpolated in (alpha, eta).

:mod:`appearance_jax.microfacet.interface_integrals` computes the coat integrals of one
parameter set by a facet quadrature (~5e5 integrand evaluations). This module ships them
precomputed by that quadrature (scheme ``"accurate"``: the 64 Chebyshev coefficients of
T(sqrt(mu)) and R_int) on a grid over

    u = ln(alpha),                           alpha in [1e-3, 2]
    w = ln(eta - 1 + DELTA0) + ETA_SLOPE (eta - 1),   eta in [1, 3]

and interpolates them with a tensor-product cubic B-spline (C2 in alpha and eta, so
Jacobians are smooth; differentiable, float32 or float64, jittable, vmappable; alpha and
eta broadcast). The eta coordinate is logarithmic near the index-matched coat: for eta -> 1
the grazing transmittance changes on the scale eta - 1 ~ alpha^2 (Fresnel's grazing
transition c ~ sqrt(2 (eta - 1)) against the facet cosines ~alpha), down to 1e-6 at
alpha = 1e-3; DELTA0 = 1e-8 keeps the map smooth at eta = 1. Outside the grid the
coordinates are clamped to its edges.

:func:`tabulate` dispatches every scheme of :data:`TABLES` (``"precomputed"`` here, the
quadrature schemes ``"accurate"`` and ``"mitsuba"`` in ``interface_integrals``); the
result is a :class:`~appearance_jax.microfacet.interface_integrals.CoatTables`, looked up
per direction by :func:`~appearance_jax.microfacet.interface_integrals.transmittance_at`
(``"precomputed"`` tables are Chebyshev coefficients, as ``"accurate"``).

The table file (``data/coat_tables/coat_tables.npz``, written by
``tools/make_coat_tables.py``) is computed by this project's quadrature, not measured.
Grid, measured accuracy and regeneration: docs/microfacet.md.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from . import interface_integrals as ii
from ..core.special import safe_sqrt
from .interface_integrals import CoatTables, N_CHEB

TABLES = ("precomputed",) + ii.TABLES
KINDS = ("ggx", "beckmann")

ALPHA_RANGE = (1e-3, 2.0)
ETA_RANGE = (1.0, 3.0)
DELTA0 = 1e-8  # eta - 1 below which the eta coordinate stops being logarithmic
ETA_SLOPE = 2.0  # linear part of the eta coordinate: resolution at large eta
N_U = 48  # grid nodes in ln(alpha)
N_W = 64  # grid nodes in the eta coordinate
N_VALUES = N_CHEB + 1  # the Chebyshev coefficients of T, then R_int
N_RESAMPLE = 4096  # cells of the per-direction lookup table, uniform in sqrt(mu)
FILE_FORMAT = 1
FILE_PARTS = ("coat_tables", "coat_tables.npz")


def eta_coordinate(eta):
    """The grid coordinate w(eta) = ln(eta - 1 + DELTA0) + ETA_SLOPE (eta - 1) (numpy or jnp)."""
    xp = np if isinstance(eta, (float, np.ndarray, np.floating)) else jnp
    d = eta - 1.0
    d = xp.where(d < 0.0, 0.0, d)  # eta < 1 is clamped (the gradient at eta = 1 stays one-sided)
    return xp.log(d + DELTA0) + ETA_SLOPE * d


def grid():
    """The grid nodes (numpy float64): alpha (N_U,) uniform in ln(alpha), eta (N_W,) uniform
    in :func:`eta_coordinate` (inverted by Newton's method, to 1e-15)."""
    alpha = np.exp(np.linspace(np.log(ALPHA_RANGE[0]), np.log(ALPHA_RANGE[1]), N_U))
    w = np.linspace(eta_coordinate(ETA_RANGE[0]), eta_coordinate(ETA_RANGE[1]), N_W)
    d = np.exp(w) - DELTA0  # at or above the root; Newton on the concave w(d) then approaches from below
    d = np.minimum(np.maximum(d, 0.0), ETA_RANGE[1] - 1.0)
    for _ in range(100):
        step = (eta_coordinate(1.0 + d) - w) / (1.0 / (d + DELTA0) + ETA_SLOPE)
        d = np.maximum(d - step, 0.0)
        if np.max(np.abs(step) / (d + DELTA0)) < 1e-15:
            break
    return alpha, 1.0 + d


def _grid_record():
    """What the file must have been computed for (checked by the loader)."""
    return np.array([FILE_FORMAT, ALPHA_RANGE[0], ALPHA_RANGE[1], N_U, ETA_RANGE[0], ETA_RANGE[1], N_W,
                     DELTA0, ETA_SLOPE, N_CHEB], dtype=np.float64)


# ----------------------------------------------------------------------------------------
# uniform cubic B-splines


@functools.lru_cache(maxsize=None)
def prefilter_matrix(n: int) -> np.ndarray:
    """(n + 2, n): values at n uniform nodes -> coefficients c_{-1..n} of the cubic B-spline
    through them, with the not-a-knot end conditions (third derivative continuous at the
    second and the second-to-last node), numpy float64."""
    if n < 5:
        raise ValueError(f"prefilter_matrix: n = {n} nodes, need >= 5")
    A = np.zeros((n + 2, n + 2))
    for i in range(n):
        A[i, i:i + 3] = (1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0)
    A[n, 0:5] = (1.0, -4.0, 6.0, -4.0, 1.0)
    A[n + 1, n - 3:n + 2] = (1.0, -4.0, 6.0, -4.0, 1.0)
    rhs = np.zeros((n + 2, n))
    rhs[:n] = np.eye(n)
    return np.linalg.solve(A, rhs)


def _bspline_weights(x, n: int):
    """Cell index j (int32) and the 4 weights of coefficients j..j+3 at x in node units,
    clamped to [0, n - 1]."""
    # clamped with where, not clip: the gradient at an edge node stays 1 (clip halves it)
    x = jnp.where(x < 0.0, 0.0, jnp.where(x > n - 1.0, n - 1.0, x))
    j = jnp.minimum(jnp.floor(x), n - 2.0)
    t = x - j
    s = 1.0 - t
    t2, t3 = t * t, t * t * t
    w = (s * s * s / 6.0, (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0, (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0, t3 / 6.0)
    return j.astype(jnp.int32), jnp.stack(w, axis=-1)


# ----------------------------------------------------------------------------------------
# the file


class CoatTableFileError(ValueError):
    """The shipped coat-table file is missing, unreadable or not what this module expects."""


def table_path():
    """Path of the shipped table file."""
    from ..data import path

    return path(*FILE_PARTS)


@functools.lru_cache(maxsize=4)
def load(path=None) -> dict:
    """The B-spline coefficients per distribution, ``{kind: (N_U + 2, N_W + 2, N_VALUES)}``
    (numpy float32), from ``path`` (default: the shipped file), checked for its keys, grid,
    shapes, dtype and finiteness; raises :class:`CoatTableFileError` naming what is wrong."""
    path = table_path() if path is None else path
    try:
        with np.load(path, allow_pickle=False) as f:
            arrays = {k: f[k] for k in f.files}
    except Exception as e:  # noqa: BLE001 - any failure to read means a bad file
        raise CoatTableFileError(f"coat tables: cannot read {path} ({type(e).__name__}: {e}); "
                                 "regenerate it with tools/make_coat_tables.py") from e
    want = {"grid", *KINDS}
    if set(arrays) != want:
        raise CoatTableFileError(f"coat tables: {path} holds arrays {sorted(arrays)}, expected {sorted(want)}")
    rec = _grid_record()
    if arrays["grid"].shape != rec.shape or not np.array_equal(arrays["grid"], rec):
        raise CoatTableFileError(f"coat tables: {path} was computed for grid {arrays['grid'].tolist()}, "
                                 f"this version expects {rec.tolist()}; regenerate it with tools/make_coat_tables.py")
    shape = (N_U + 2, N_W + 2, N_VALUES)
    out = {}
    for k in KINDS:
        a = arrays[k]
        if a.shape != shape or a.dtype != np.float32:
            raise CoatTableFileError(f"coat tables: {path}[{k!r}] has shape {a.shape} dtype {a.dtype}, "
                                     f"expected {shape} float32")
        if not np.all(np.isfinite(a)):
            raise CoatTableFileError(f"coat tables: {path}[{k!r}] has non-finite values")
        out[k] = a
    return out


# ----------------------------------------------------------------------------------------
# interpolation


def _interpolate_one(coefs, x, y):
    """sum_ab wx_a wy_b coefs[i + a, j + b] for scalar node coordinates x, y."""
    i, wx = _bspline_weights(x, N_U)
    j, wy = _bspline_weights(y, N_W)
    block = jax.lax.dynamic_slice(coefs, (i, j, jnp.zeros_like(i)), (4, 4, N_VALUES))
    return jnp.einsum("a,b,abk->k", wx, wy, block)


@functools.partial(jax.jit, static_argnames="kind")
def _interpolate(kind: str, alpha, eta):
    dtype = jnp.result_type(alpha, eta)
    shape = jnp.broadcast_shapes(alpha.shape, eta.shape)
    coefs = jnp.asarray(load()[kind], dtype)
    # Python floats (weak types): float32 inputs stay float32
    lo, hi = float(np.log(ALPHA_RANGE[0])), float(np.log(ALPHA_RANGE[1]))
    x = (jnp.log(alpha) - lo) * ((N_U - 1) / (hi - lo))
    wlo, whi = float(eta_coordinate(ETA_RANGE[0])), float(eta_coordinate(ETA_RANGE[1]))
    y = (eta_coordinate(eta) - wlo) * ((N_W - 1) / (whi - wlo))
    x, y = (jnp.broadcast_to(v, shape).reshape(-1) for v in (x, y))
    v = jax.vmap(_interpolate_one, in_axes=(None, 0, 0))(coefs, x, y).reshape(shape + (N_VALUES,))
    return CoatTables(v[..., :N_CHEB], v[..., N_CHEB])


def interpolate(kind: str, alpha, eta) -> CoatTables:
    """The precomputed coat integrals at (alpha, eta) (leading axes broadcast): Chebyshev
    coefficients of T in sqrt(mu) (..., 64) and R_int (...), as ``tabulate(..., "accurate")``
    up to the interpolation error (docs/microfacet.md). Differentiable in alpha and eta."""
    if kind not in KINDS:
        raise ValueError(f"coat tables: distribution {kind!r} not in {KINDS}")
    dtype = jnp.result_type(alpha, eta, float)
    load()  # a bad file raises here, eagerly, not inside a trace
    return _interpolate(kind, jnp.asarray(alpha, dtype), jnp.asarray(eta, dtype))


def tabulate(kind: str, alpha, eta, scheme: str = "precomputed") -> CoatTables:
    """The coat integrals of a rough interface in any scheme of :data:`TABLES`:
    ``"precomputed"`` (:func:`interpolate`), or the quadrature schemes of
    :func:`appearance_jax.microfacet.interface_integrals.tabulate`."""
    if scheme not in TABLES:
        raise ValueError(f"coat tables: scheme {scheme!r} not in {TABLES}")
    if scheme == "precomputed":
        return interpolate(kind, alpha, eta)
    return ii.tabulate(kind, alpha, eta, scheme)


@functools.lru_cache(maxsize=None)
def _resampling_matrix():
    """(N_RESAMPLE + 1, N_CHEB): Chebyshev coefficients -> T at s = k / N_RESAMPLE (numpy)."""
    s = np.linspace(0.0, 1.0, N_RESAMPLE + 1)
    return np.polynomial.chebyshev.chebvander(2.0 * s - 1.0, N_CHEB - 1)


def transmittance_lookup(scheme: str, tab: CoatTables):
    """A function mu -> T(mu) for tables of ``scheme`` (mu in [0, 1], any shape broadcasting
    with the tables' leading axes).

    ``"precomputed"`` tables of one parameter set (no leading axes, also per item inside a
    vmap) are resampled once on N_RESAMPLE + 1 nodes uniform in s = sqrt(mu) and looked up
    by linear interpolation in s: two gathers per direction instead of a 64-term Chebyshev
    series (~4x faster on CPU for 1e6 directions; measured error of the resampling
    <= 5.4e-5, at alpha = 1e-3 and mu ~ 1e-8, <= 5e-6 for alpha >= 0.01; docs/microfacet.md). With leading axes (spatially varying alpha, eta) and for
    the quadrature schemes: :func:`~appearance_jax.microfacet.interface_integrals.transmittance_at`.
    """
    T = tab.transmittance
    if scheme != "precomputed" or T.ndim != 1:
        return lambda mu: ii.transmittance_at("accurate" if scheme == "precomputed" else scheme, tab, mu)
    # a matrix product, which XLA materialises (a Clenshaw series here would be fused into
    # the gathers and summed per direction again, ~10x slower)
    nodes = jnp.clip(jnp.asarray(_resampling_matrix(), T.dtype) @ T, 0.0, 1.0)

    def lookup(mu):
        x = safe_sqrt(jnp.clip(mu, 0.0, 1.0)) * N_RESAMPLE
        i = jnp.minimum(jnp.floor(x), N_RESAMPLE - 1.0)
        t = x - i
        i = i.astype(jnp.int32)
        v0, v1 = nodes[i], nodes[i + 1]
        return v0 + t * (v1 - v0)

    return lookup


def transmittance_at(scheme: str, tab: CoatTables, mu):
    """T(mu) from tables of any scheme of :data:`TABLES` (see :func:`transmittance_lookup`)."""
    return transmittance_lookup(scheme, tab)(mu)
