"""Which array library a host-or-device helper should use (:func:`namespace`).

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

__all__ = ["is_concrete", "namespace"]


def namespace(*xs):
    """``jax.numpy`` if any leaf of ``xs`` is a jax array or tracer, else ``numpy``."""
    return jnp if any(isinstance(x, jax.Array) for x in jax.tree_util.tree_leaves(xs)) else np


def is_concrete(*xs) -> bool:
    """True unless a leaf of ``xs`` is traced (inside ``jit``/``vmap``/``grad``): eager input
    checks run on concrete values only, so kernels never branch on traced ones."""
    return not any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(xs))
