"""core.linalg: the LAPACK-free solve against numpy, its gradients, and the vmapped-while case."""

import jax
import jax.numpy as jnp
import numpy as np

from appearance_jax.core.linalg import solve_diagonally_dominant


def _system(seed, batch=(4,), n=12, m=3):
    rng = np.random.default_rng(seed)
    K = rng.uniform(size=batch + (n, n))
    K *= 0.95 / K.sum(axis=-1, keepdims=True)  # row sums < 1: a lossy Nyström kernel
    return np.eye(n) - K, rng.normal(size=batch + (n, m))


def test_matches_numpy_and_broadcasts():
    A, B = _system(0)
    np.testing.assert_allclose(np.asarray(solve_diagonally_dominant(A, B)), np.linalg.solve(A, B), rtol=1e-12,
                               atol=1e-13)
    # one right-hand side shared by the batch
    X = np.asarray(solve_diagonally_dominant(A, B[0]))
    np.testing.assert_allclose(X, np.linalg.solve(A, np.broadcast_to(B[0], B.shape)), rtol=1e-12, atol=1e-13)


def test_gradients_match_lapack_solve():
    A, B = _system(1, batch=())
    f = lambda a, b: jnp.sum(jnp.sin(solve_diagonally_dominant(a, b)))  # noqa: E731
    g = lambda a, b: jnp.sum(jnp.sin(jnp.linalg.solve(a, b)))  # noqa: E731
    for argnum in (0, 1):
        np.testing.assert_allclose(np.asarray(jax.grad(f, argnum)(A, B)), np.asarray(jax.grad(g, argnum)(A, B)),
                                   rtol=1e-10, atol=1e-12)
    jf = jax.jacfwd(lambda s: solve_diagonally_dominant(A * s, B))(1.0)
    jg = jax.jacfwd(lambda s: jnp.linalg.solve(A * s, B))(1.0)
    np.testing.assert_allclose(np.asarray(jf), np.asarray(jg), rtol=1e-10, atol=1e-12)


def test_runs_inside_a_vmapped_while_loop():
    """The pattern of a multi-start solver: vmap over starts of a while_loop that solves a system."""
    A, B = _system(2, batch=())

    def run(s):
        def body(c):
            i, x = c
            return i + 1, x + solve_diagonally_dominant(A * (1 + 0.01 * s * i), B).sum()

        return jax.lax.while_loop(lambda c: c[0] < 3 + s.astype(int), body, (0, 0.0))[1]

    out = np.asarray(jax.jit(jax.vmap(run))(jnp.arange(4.0)))
    ref = [sum(np.linalg.solve(A * (1 + 0.01 * s * i), B).sum() for i in range(3 + s)) for s in range(4)]
    np.testing.assert_allclose(out, ref, rtol=1e-12)


def test_custom_jvp_second_order_and_both_modes():
    """The solve's custom JVP (dX = A^-1 (dB - dA X)) against finite differences, forward and
    reverse, to second order (a Hessian of a fit goes through it)."""
    from jax.test_util import check_grads

    with jax.enable_x64(True):
        A, B = _system(5, batch=(2,), n=6, m=2)
        A = np.eye(6) - 0.5 * (np.eye(6) - A)  # row sums 0.475: a well conditioned A for finite differences
        check_grads(lambda a, b: jnp.sum(jnp.sin(solve_diagonally_dominant(a, b))), (jnp.asarray(A), jnp.asarray(B)),
                    order=2, modes=("fwd", "rev"))
