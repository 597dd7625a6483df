"""Random test directions with fixed keys, and the integration domains of each model kind.

Domains (conventions of :mod:`appearance_jax.core.frame`, directions point away):

- ``"upper"``: z > 0, the incident and scattering domain of reflection-only BSDFs;
- ``"lower"``: z < 0;
- ``"sphere"``: all directions (phase functions, fibers, transmissive BSDFs).

The projection cosine of the albedo ``A(wi) = int f(wi, wo) cos_o dwo`` depends on the kind:
``|wo.z|`` for BSDFs, 1 for phase functions, and for fiber BCSDFs ``cos theta_o`` of the
longitudinal angle, ``sqrt(1 - wo.x^2)`` (Marschner et al. 2003: ``int S cos theta_o dwo``
is the fiber's albedo) [ASSUMPTION: the library's BCSDF convention; pass ``cosine=`` to the
checks to override it].
"""

from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from ..core.frame import orthonormal_basis
from ..core.special import safe_sqrt
from ..core.vec import Vec3

DOMAINS = ("upper", "lower", "sphere")


def as_key(key):
    """An int seed or a PRNG key -> a PRNG key."""
    if isinstance(key, int):
        return jax.random.key(key)
    return key


def random_directions(key, n: int, domain: str = "upper", min_cos: float = 0.0) -> Vec3:
    """``n`` directions uniform in solid angle over ``domain`` (shape ``(n,)``), from ``key``.

    ``min_cos`` keeps ``|z| >= min_cos`` (away from the horizon); exactly grazing
    directions (z = 0) are never returned for the hemispheres.
    """
    if domain not in DOMAINS:
        raise ValueError(f"domain = {domain!r} must be one of {DOMAINS}")
    k1, k2, k3 = jax.random.split(as_key(key), 3)
    dt = jnp.result_type(float)
    u1 = jax.random.uniform(k1, (n,), dt)
    u2 = jax.random.uniform(k2, (n,), dt)
    # 1 - u1 lies in (0, 1]: |z| uniform on (min_cos, 1] is uniform in solid angle there
    z = min_cos + (1.0 - min_cos) * (1.0 - u1)
    if domain == "lower":
        z = -z
    elif domain == "sphere":
        if min_cos > 0:
            z = jnp.where(jax.random.bernoulli(k3, 0.5, (n,)), z, -z)
        else:
            z = 1.0 - 2.0 * u1
    r = safe_sqrt(1.0 - z * z)
    phi = 2.0 * jnp.pi * u2
    return Vec3(r * jnp.cos(phi), r * jnp.sin(phi), z)


def incident_domain(model) -> str:
    """Where incident directions of ``model`` are drawn by default.

    Reflection-only BSDFs: from above. Transmissive BSDFs, phase functions and fibers:
    the whole sphere (a transmissive interface is also lit from its inside).
    """
    if model.kind == "bsdf" and not getattr(model, "transmissive", False):
        return "upper"
    return "sphere"


def scattering_domain(model) -> str:
    """Where ``wo`` ranges: the upper hemisphere for reflection-only BSDFs, else the sphere."""
    if model.kind == "bsdf" and not getattr(model, "transmissive", False):
        return "upper"
    return "sphere"


def projection_cosine(model) -> Callable[[Vec3], jax.Array]:
    """The cosine factor of the albedo integral (module docstring): a function of ``wo``."""
    if model.kind == "phase":
        return lambda w: jnp.ones_like(w.z)
    if model.kind == "bcsdf":
        return lambda w: safe_sqrt(1.0 - w.x * w.x)
    return lambda w: jnp.abs(w.z)


def domain_solid_angle(domain: str) -> float:
    return 4.0 * jnp.pi if domain == "sphere" else 2.0 * jnp.pi


# --------------------------------------------------------------------------------------
# host-side helpers: the harness does its bookkeeping in numpy and calls the (jitted)
# model functions on a few fixed shapes, so a check compiles little.

#: model functions are called on flat direction arrays of exactly this many elements (padded), so
#: that every check of a case (reciprocity, furnace, sampling, chi-square, gradients) runs the same
#: compiled eval, pdf and sample programs: the harness is compile-bound, not run-bound
CHUNK = 2**13


def np_vec(w: Vec3, shape=None) -> Vec3:
    """A Vec3 of numpy arrays (broadcast to ``shape`` if given)."""
    comps = [np.asarray(c) for c in w]
    shape = np.broadcast_shapes(*(c.shape for c in comps)) if shape is None else shape
    return Vec3(*(np.broadcast_to(c, shape) for c in comps))


_basis_jit = jax.jit(orthonormal_basis)


def np_basis(n: Vec3):
    """:func:`appearance_jax.core.frame.orthonormal_basis` of numpy vectors, as numpy vectors."""
    s, t = _basis_jit(Vec3(*(jnp.asarray(c) for c in n)))
    return np_vec(s), np_vec(t)


def np_dot(a: Vec3, b: Vec3) -> np.ndarray:
    return np.asarray(a.x) * b.x + np.asarray(a.y) * b.y + np.asarray(a.z) * b.z


def _flat_padded(components, chunk: int):
    """Broadcast arrays -> ``(shape, n, flat)``: each flattened and padded with copies of its
    first element to a multiple of ``chunk`` (at least one chunk)."""
    shape = np.broadcast_shapes(*(np.shape(c) for c in components))
    flat = [np.broadcast_to(np.asarray(c), shape).ravel() for c in components]
    n = flat[0].size
    total = max(-(-n // chunk), 1) * chunk
    return shape, n, [np.concatenate([c, np.repeat(c[:1], total - n)]) for c in flat]


def _unpad(parts, n: int, shape) -> np.ndarray:
    out = np.concatenate(parts, axis=0)[:n]
    return out.reshape(shape + out.shape[1:])


def call_chunked(fn, params, wi: Vec3, wo: Vec3, chunk: int = CHUNK) -> np.ndarray:
    """``fn(params, wi, wo)`` (an eval or pdf) on broadcast directions, in fixed-size chunks.

    Directions are flattened and padded (with copies of the first pair) to a multiple of
    ``chunk`` and passed ``chunk`` at a time, so a jitted ``fn`` compiles for one shape
    whatever the caller's sizes. Returns a numpy array of shape
    ``broadcast(wi, wo).shape + fn's trailing axes``.
    """
    shape, n, a = _flat_padded((*wi, *wo), chunk)
    outs = []
    for i in range(0, a[0].size, chunk):  # a few fixed-size batches, not a loop over samples
        sl = [jnp.asarray(c[i:i + chunk]) for c in a]
        outs.append(np.asarray(fn(params, Vec3(*sl[:3]), Vec3(*sl[3:]))))
    return _unpad(outs, n, shape)


def sample_chunked(model, params, wi: Vec3, key, chunk: int = CHUNK):
    """``model.sample(params, wi, key)`` on directions of any shape, ``chunk`` at a time.

    Like :func:`call_chunked`: ``wi`` is flattened and padded to a multiple of ``chunk``; chunk
    ``j`` draws with ``jax.random.fold_in(key, j)``. Returns numpy ``(wo, weight, pdf)`` of
    shapes ``wi.shape`` (components), ``wi.shape + (n_bands,)`` and ``wi.shape``.
    """
    shape, n, a = _flat_padded(tuple(wi), chunk)
    key = as_key(key)
    outs = []  # per chunk: wo.x, wo.y, wo.z, weight, pdf
    for j, i in enumerate(range(0, a[0].size, chunk)):
        wo, weight, pdf = model.sample(params, Vec3(*(jnp.asarray(c[i:i + chunk]) for c in a)),
                                       jax.random.fold_in(key, j))
        outs.append([np.asarray(v) for v in (*wo, weight, pdf)])
    x, y, z, weight, pdf = (_unpad([o[k] for o in outs], n, shape) for k in range(5))
    return Vec3(x, y, z), weight, pdf
