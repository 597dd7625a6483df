"""Steering XLA's fusion: values computed once and stored instead of recomputed per consumer.

XLA:CPU fuses a chain of cheap elementwise ops (+, *, select, compare) into *every* fusion
that consumes it, so a value used by several fusions is recomputed, and compiled, once per
consumer. In the hair kernels (Vec3 components and per-direction values broadcast over nodes
and paths) this duplicated the generated code 4-7x and made compilation slow
(benchmarks/README.md, "Compilation").
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def materialize(tree):
    """The arrays of ``tree`` unchanged (bit for bit), computed once and stored.

    XLA:CPU fuses a chain of cheap elementwise ops (+, *, select, compare) into *every*
    consumer, so a value used by several fusions is recomputed, and compiled, once per
    consumer: in the hair kernels, with Vec3 components and per-direction values broadcast
    over (nodes, paths), this duplicated the generated code 4-7x and made the compile slow.
    It never duplicates a divide, so dividing by a 1 that the compiler cannot fold (it comes
    out of an optimisation barrier) ends the chain: one store, one fused kernel. x / 1 = x
    exactly; integer and boolean leaves are passed through."""
    one = jax.lax.optimization_barrier(jnp.ones((), jnp.result_type(float)))

    def one_div(v):
        v = jnp.asarray(v)
        return (v / one.astype(v.dtype)) if jnp.issubdtype(v.dtype, jnp.inexact) else v

    return jax.tree.map(one_div, tree)


__all__ = ["materialize"]
