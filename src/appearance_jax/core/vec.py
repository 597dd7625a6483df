"""Vec3: 3-vectors stored as a structure of arrays.

The library's one vector type. A ``Vec3`` holds three same-shaped arrays ``x, y, z``
(never a trailing axis of length 3): element-wise kernels then vectorise over the
sample axes with no gathers, which measured ~4x faster than ``(N, 3)`` arrays for a
GGX evaluation over 1e6 pairs (DESIGN.md, "Conventions"). Spectral bands stay a
trailing axis of the *values*, not of the vectors.

``Vec3`` is a JAX pytree, so it passes through ``jit``, ``vmap`` and ``grad`` as is.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

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
