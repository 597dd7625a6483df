"""Small dense linear algebra in plain XLA operations (no LAPACK custom calls).

Why: on the CPU backend, a batched ``jnp.linalg.solve`` (a LAPACK custom call) inside a
``vmap``-ed ``while_loop`` -- exactly what a multi-start Levenberg-Marquardt fit of a model
with a Nyström solve compiles to -- deadlocked XLA's multi-threaded runtime here (jax
0.10.2: the program compiled and then waited forever at 0 % CPU; with
``--xla_cpu_multi_thread_eigen=false`` it ran). The Nyström systems of the layered models
are small (n <= a few hundred) and diagonally dominant, so Gauss-Jordan elimination
without pivoting, written with ``lax.fori_loop``, is stable, cheap and differentiable.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


@jax.custom_jvp
def solve_diagonally_dominant(A, B):
    """X = A^{-1} B by Gauss-Jordan elimination without pivoting, batched over leading axes.

    ``A``: ``(..., n, n)``; ``B``: ``(..., n, m)`` (broadcast against A's leading axes).
    Stable when A is (row or column) diagonally dominant, e.g. I - K for a Nyström kernel
    whose row sums are below 1 (an operator of norm < 1: a lossy layer); for other
    matrices use ``jnp.linalg.solve``. O(n^2 (n + m)) operations in n sequential steps.

    Derivatives (custom JVP): dX = A^{-1} (dB - dA X), with A^{-1} from the same elimination
    (B augmented by the identity): each tangent costs two matrix products instead of the
    elimination loop differentiated step by step.
    """
    return _eliminate(A, B)


@solve_diagonally_dominant.defjvp
def _solve_jvp(primals, tangents):
    A, B = (jnp.asarray(a) for a in primals)
    dA, dB = tangents
    n, m = A.shape[-1], B.shape[-1]
    lead = jnp.broadcast_shapes(A.shape[:-2], B.shape[:-2])
    dt = jnp.result_type(A, B)
    eye = jnp.broadcast_to(jnp.eye(n, dtype=dt), lead + (n, n))
    Y = _eliminate(A, jnp.concatenate([jnp.broadcast_to(B, lead + B.shape[-2:]).astype(dt), eye], axis=-1))
    X, inv = Y[..., :m], Y[..., m:]
    return X, inv @ (dB - dA @ X)


def _eliminate(A, B):
    A = jnp.asarray(A)
    B = jnp.asarray(B)
    n = A.shape[-1]
    lead = jnp.broadcast_shapes(A.shape[:-2], B.shape[:-2])
    M = jnp.concatenate([jnp.broadcast_to(A, lead + A.shape[-2:]),
                         jnp.broadcast_to(B, lead + B.shape[-2:]).astype(jnp.result_type(A, B))], axis=-1)
    rows = jnp.arange(n)

    def step(k, M):
        pivot_row = jax.lax.dynamic_index_in_dim(M, k, axis=-2, keepdims=False)  # (..., n + m)
        pivot = jax.lax.dynamic_index_in_dim(pivot_row, k, axis=-1, keepdims=False)
        row = pivot_row / pivot[..., None]
        col = jax.lax.dynamic_index_in_dim(M, k, axis=-1, keepdims=False)  # (..., n)
        col = jnp.where(rows == k, 0.0, col)  # the pivot row is replaced, not updated
        M = M - col[..., :, None] * row[..., None, :]
        return jnp.where((rows == k)[:, None], row[..., None, :], M)

    M = jax.lax.fori_loop(0, n, step, M)
    return M[..., n:]
