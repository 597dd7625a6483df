"""Vec3: 3-vectors stored as a structure of arrays.

The library's one vector type. A ``Vec3`` holds three same-shaped arrays ``x, y, z``
(never a trailing axis of length 3): element-wise kernels then vectorise over the
sample axes with no gathers, which measured ~4x faster than ``(N, 3)`` arrays for a
GGX evaluation over 1e6 pairs (DESIGN.md, "Conventions"). Spectral bands stay a
trailing axis of the *values*, not of the vectors.

``Vec3`` is a JAX pytree, so it passes through ``jit``, ``vmap`` and ``grad`` as is.

Directions (the ``wi``/``wo`` of every model) are **unit vectors pointing away from the
surface** (both the incident and the outgoing one), in the local shading frame whose z
axis is the normal (:mod:`appearance_jax.core.frame`). A direction below the horizon or
exactly at grazing is valid input (a reflection BSDF returns 0 there). The public model
functions accept (:func:`as_direction`):

- a ``Vec3`` (passed on unchanged, so results are bit-identical to the kernel's);
- an array of shape ``(..., 3)`` (numpy or jax), split along its last axis;
- a tuple or list of three real numbers, one direction.

Anything else (a tuple of three arrays is ambiguous: components or three directions?)
raises a ``TypeError`` naming the argument and the accepted types. Concrete (not traced)
directions are checked eagerly: a non-finite or zero-length vector raises a ``ValueError``
naming the argument, and so does one whose norm differs from 1 by more than
:data:`UNIT_TOLERANCE` (with the measured norm); they are not normalised silently
(:func:`normalize` does it on request).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

Array = Any


@jax.tree_util.register_pytree_node_class
class Vec3:
    """A 3-vector of arrays ``(x, y, z)``; arithmetic broadcasts like the arrays do."""

    __slots__ = ("x", "y", "z")

    def __init__(self, x: Array, y: Array, z: Array):
        self.x = x
        self.y = y
        self.z = z

    # -- pytree -------------------------------------------------------------------
    def tree_flatten(self):
        return (self.x, self.y, self.z), None

    @classmethod
    def tree_unflatten(cls, aux, children):
        return cls(*children)

    # -- construction / conversion ------------------------------------------------
    @classmethod
    def from_array(cls, a: Array, axis: int = -1) -> "Vec3":
        """Split an array with a length-3 axis (default the last) into a Vec3."""
        a = jnp.asarray(a)
        x, y, z = jnp.moveaxis(a, axis, 0)
        return cls(x, y, z)

    def to_array(self, axis: int = -1) -> jax.Array:
        """Stack into an array with a length-3 axis (for I/O and plotting only)."""
        x, y, z = jnp.broadcast_arrays(self.x, self.y, self.z)
        return jnp.stack([x, y, z], axis=axis)

    @property
    def shape(self):
        return jnp.broadcast_shapes(jnp.shape(self.x), jnp.shape(self.y), jnp.shape(self.z))

    def __iter__(self):
        return iter((self.x, self.y, self.z))

    def __repr__(self) -> str:
        return f"Vec3(x={self.x!r}, y={self.y!r}, z={self.z!r})"

    # -- arithmetic ----------------------------------------------------------------
    def __add__(self, o: "Vec3") -> "Vec3":
        return Vec3(self.x + o.x, self.y + o.y, self.z + o.z)

    def __sub__(self, o: "Vec3") -> "Vec3":
        return Vec3(self.x - o.x, self.y - o.y, self.z - o.z)

    def __neg__(self) -> "Vec3":
        return Vec3(-self.x, -self.y, -self.z)

    def __mul__(self, s: Array) -> "Vec3":
        """Scale by a scalar or an array broadcastable to the components."""
        return Vec3(self.x * s, self.y * s, self.z * s)

    __rmul__ = __mul__

    def __truediv__(self, s: Array) -> "Vec3":
        inv = 1.0 / s
        return Vec3(self.x * inv, self.y * inv, self.z * inv)

    def map(self, fn) -> "Vec3":
        """Apply ``fn`` to each component (e.g. ``jnp.broadcast_to``)."""
        return Vec3(fn(self.x), fn(self.y), fn(self.z))


def vec3(x: Array, y: Array, z: Array) -> Vec3:
    """Build a Vec3 from three array-likes (converted to jax arrays)."""
    return Vec3(jnp.asarray(x), jnp.asarray(y), jnp.asarray(z))


def dot(a: Vec3, b: Vec3) -> jax.Array:
    return a.x * b.x + a.y * b.y + a.z * b.z


def cross(a: Vec3, b: Vec3) -> Vec3:
    return Vec3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x)


def norm(a: Vec3) -> jax.Array:
    from .special import safe_sqrt  # local import: special has no dependency on vec

    return safe_sqrt(dot(a, a))


def normalize(a: Vec3, eps: float = 1e-30) -> Vec3:
    """Unit vector along ``a``; the zero vector maps to zero (finite gradient)."""
    n2 = dot(a, a)
    safe = n2 > eps
    inv = jnp.where(safe, jax.lax.rsqrt(jnp.where(safe, n2, 1.0)), 0.0)
    return a * inv


def where(cond: Array, a: Vec3, b: Vec3) -> Vec3:
    """Component-wise ``jnp.where`` for vectors."""
    return Vec3(jnp.where(cond, a.x, b.x), jnp.where(cond, a.y, b.y), jnp.where(cond, a.z, b.z))


# --------------------------------------------------------------------------------------
# Directions at the public boundary

#: |norm - 1| allowed for a direction: float32 unit vectors from trigonometry or a
#: normalisation are within ~1e-7 of 1; 1e-3 also admits directions stored with 3-4 digits.
UNIT_TOLERANCE = 1e-3
_N2_LO, _N2_HI = (1.0 - UNIT_TOLERANCE) ** 2, (1.0 + UNIT_TOLERANCE) ** 2
_ACCEPTED = "a Vec3, an array of shape (..., 3) or a tuple of 3 numbers"


def _is_number(c) -> bool:
    return isinstance(c, (int, float, np.integer, np.floating)) and not isinstance(c, (bool, np.bool_)) or (
        isinstance(c, (np.ndarray, jax.Array)) and np.ndim(c) == 0)


def as_direction(name: str, w, check: bool = True) -> Vec3:
    """Direction argument ``name`` (``"wi"``, ``"wo"``) of a public function as a Vec3.

    Conversions and checks as in the module docstring (``check=False``: convert only, for a
    caller that checks several directions at once with :func:`check_directions`). Raises
    ``TypeError`` for an unsupported type and ``ValueError`` for a non-finite, zero-length or
    non-unit concrete vector.
    """
    if isinstance(w, Vec3):
        v = w
    elif isinstance(w, (tuple, list)):
        if len(w) != 3 or not all(_is_number(c) for c in w):
            raise TypeError(f"{name}: expected {_ACCEPTED}, got a {type(w).__name__} of length {len(w)}"
                            + ("" if len(w) != 3 else " whose entries are not all numbers (for arrays of "
                               "components use Vec3(x, y, z))"))
        dt = jnp.result_type(float)
        v = Vec3(*(jnp.asarray(c, dtype=dt) for c in w))
    elif isinstance(w, (np.ndarray, jax.Array)):
        if np.ndim(w) < 1 or np.shape(w)[-1] != 3:
            raise TypeError(f"{name}: expected {_ACCEPTED}, got an array of shape {np.shape(w)}")
        v = Vec3.from_array(w)
    else:
        raise TypeError(f"{name}: expected {_ACCEPTED}, got {type(w).__name__}")
    if check:
        check_directions({name: v})
    return v


def as_directions(**named) -> tuple:
    """:func:`as_direction` for several arguments with one check for all of them, for public
    functions outside :func:`~appearance_jax.core.model.boundary`:
    ``wi, wo = as_directions(wi=wi, wo=wo)``."""
    out = {n: as_direction(n, w, check=False) for n, w in named.items()}
    check_directions(out)
    return tuple(out.values())


# below this many components in all, directions are checked on the host: a device reduction
# costs a dispatch and a synchronisation (~50 us), numpy a few us on a handful of values
_HOST_CHECK_MAX = 4096


@jax.jit
def _any_bad(vectors):
    bad = jnp.zeros((), bool)
    for x, y, z in vectors:
        n2 = x * x + y * y + z * z
        bad |= jnp.any(~(jnp.isfinite(n2) & (n2 >= _N2_LO) & (n2 <= _N2_HI)))
    return bad


def check_directions(named: dict) -> None:
    """``ValueError`` naming the argument unless every concrete direction of the Vec3s in
    ``named`` (argument name -> Vec3) is a finite unit vector within :data:`UNIT_TOLERANCE`.

    Traced vectors are not checked. Large device arrays are checked by one fused reduction
    (one synchronisation for all of them); the offending entry is looked up only on failure.
    """
    concrete = {n: v for n, v in named.items() if not any(isinstance(c, jax.core.Tracer) for c in v)}
    if not concrete:
        return
    if sum(np.size(c) for v in concrete.values() for c in v) > _HOST_CHECK_MAX:
        bad = _any_bad(tuple(tuple(v) for v in concrete.values()))
        # under an outer trace (constants closed over) the result is a tracer: check on the host
        if not isinstance(bad, jax.core.Tracer) and not bool(bad):
            return
    for n, v in concrete.items():
        _check_host(n, v)


def _check_host(name: str, v: Vec3) -> None:
    comps = np.broadcast_arrays(*(np.asarray(c, dtype=np.float64) for c in v))
    n2 = comps[0] ** 2 + comps[1] ** 2 + comps[2] ** 2
    finite = np.isfinite(n2)
    bad = ~(finite & (n2 >= _N2_LO) & (n2 <= _N2_HI))
    if not np.any(bad):
        return
    idx = tuple(int(i) for i in np.argwhere(bad)[0])
    at = f" at index {idx}" if idx else ""
    xyz = "(" + ", ".join(f"{float(c[idx]):g}" for c in comps) + ")"
    if not finite[idx]:
        why = "is not finite"
    elif n2[idx] == 0.0:
        why = "has zero length"
    else:
        why = f"is not a unit vector: its norm is {float(np.sqrt(n2[idx])):.7g} (tolerance {UNIT_TOLERANCE:g})"
    raise ValueError(f"{name} = {xyz}{at} {why}; directions must be finite unit vectors pointing away from "
                     "the surface (core.vec.normalize makes one)")
