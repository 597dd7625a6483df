"""Which array library a host-or-device helper should use (:func:`namespace`), and
:func:`stacked`, which runs several like computations as one.

Eager jax.numpy on concrete values compiles one small XLA program per operation and shape
(tens of milliseconds each on a first call, even when the persistent compilation cache holds
them). Helpers that mostly run on host data (report figures, preset builders, sRGB encoding of
a plot) use numpy for numpy inputs and jax.numpy as soon as an input is a jax array (a tracer
under ``jit``/``grad`` included), so they stay differentiable and jittable.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["is_concrete", "namespace", "stacked"]


def namespace(*xs):
    """``jax.numpy`` if any leaf of ``xs`` is a jax array or tracer, else ``numpy``."""
    return jnp if any(isinstance(x, jax.Array) for x in jax.tree_util.tree_leaves(xs)) else np


def is_concrete(*xs) -> bool:
    """True unless a leaf of ``xs`` is traced (inside ``jit``/``vmap``/``grad``): eager input
    checks run on concrete values only, so kernels never branch on traced ones."""
    return not any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(xs))


def stacked(*xs, like=()) -> jax.Array:
    """``xs`` broadcast against each other and against the leaves of ``like``, stacked on a new
    leading axis: shape ``(len(xs), *broadcast shape)``.

    Evaluating a function once on the stacked arrays, instead of once per array, compiles one copy
    of its code instead of ``len(xs)``; XLA:CPU also copies a reverse pass into every fusion that
    reads it, so the saving grows under ``jax.grad`` (rock_dove's value and gradient: 153k -> 57k
    lines of optimised HLO, benchmarks/README.md). Heavy elementwise code whose outputs are then
    combined can run slower stacked (the outputs are written out instead of fused into their
    consumer): measure before using it in a hot loop.
    """
    shape = jnp.broadcast_shapes(*(jnp.shape(v) for v in jax.tree_util.tree_leaves((xs, like))))
    return jnp.stack([jnp.broadcast_to(v, shape) for v in xs])
