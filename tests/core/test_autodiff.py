"""core.autodiff.forward_jacobian_rule: values and derivatives equal the unwrapped function's
in every transformation, on both paths (Jacobian columns, native fallback)."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.bsdf import rough_conductor as rc
from appearance_jax.core.autodiff import forward_jacobian_rule
from appearance_jax.core.vec import Vec3


def _f(p, x, n):
    """A scalar leaf, a band leaf (3,), a per-element leaf x (5,), an integer leaf n; two outputs."""
    y = jnp.sin(p["a"] * x[:, None] + p["bands"]) * p["bands"] ** 2 / (1.0 + n)
    return y, jnp.exp(-p["a"] * x) * n


P = {"a": jnp.float64(0.7), "bands": jnp.array([0.2, 0.5, 1.3])}
X = jnp.linspace(0.1, 2.0, 5)
N = jnp.int32(3)


def _loss(f):
    c = jnp.arange(15.0).reshape(5, 3) / 7.0
    return lambda p, x: jnp.sum(c * f(p, x, N)[0]) + jnp.sum(jnp.cos(f(p, x, N)[1]))


def _close(a, b):
    jax.tree.map(lambda u, v: np.testing.assert_allclose(np.asarray(u), np.asarray(v), rtol=1e-13, atol=1e-14),
                 a, b)


@functools.partial(jax.jit, static_argnums=0)
def _everything(f, p, x):
    """Value and derivatives of ``f`` in every transformation (one compilation per ``f``)."""
    lf = _loss(f)
    only_a = lambda a, x: lf({"a": a, "bands": p["bands"]}, x)  # noqa: E731
    only_b = lambda b, x: lf({"a": p["a"], "bands": b}, x)  # noqa: E731
    t = {"a": jnp.asarray(1.5), "bands": jnp.zeros(3)}
    a4 = jnp.array([0.1, 0.4, 0.9, 1.6])
    return dict(
        value=f(p, x, N),
        # reverse mode: one scalar leaf, the band leaf, all parameters, parameters and x
        grad_a=jax.grad(only_a)(p["a"], x), grad_b=jax.grad(only_b)(p["bands"], x),
        grad_p=jax.value_and_grad(lf)(p, x), grad_px=jax.grad(lf, argnums=(0, 1))(p, x),
        # forward mode: a tangent on `a` only; Jacobians of the whole output
        jvp=jax.jvp(lambda q: f(q, x, N), (p,), (t,)),
        jacfwd=jax.jacfwd(lambda q: f(q, x, N))(p), jacrev=jax.jacrev(lambda q: f(q, x, N))(p),
        # vmap over parameter sets, outside and inside the derivative
        vmap_grad=jax.vmap(jax.grad(only_a), (0, None))(a4, x),
        jacfwd_vmap=jax.jacfwd(jax.vmap(only_a, (0, None)))(a4, x),
        # second derivative (differentiates the forward-mode columns)
        hess_a=jax.grad(jax.grad(only_a))(p["a"], x))


@pytest.mark.parametrize("max_scalars", [1, 100])
def test_matches_unwrapped(max_scalars):
    """max_scalars 1: columns for `a` alone, native fallback otherwise; 100: columns everywhere."""
    _close(_everything(forward_jacobian_rule(_f, max_scalars=max_scalars), P, X), _everything(_f, P, X))


def test_keeps_signature_and_rejects_bad_max_scalars():
    g = forward_jacobian_rule(_f)
    assert g.unwrapped is _f and g.__name__ == "_f"
    _close(g(p=P, x=X, n=N), _f(P, X, N))
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match=r"max_scalars = .*must be an int >= 0"):
            forward_jacobian_rule(_f, max_scalars=bad)


def test_rough_conductor_eval_carries_the_rule():
    """The shipped kernel: gradients w.r.t. alpha (columns), all parameters and the directions
    (native) equal the unwrapped kernel's; static fields (distribution) pass through."""
    kern = rc.eval.kernel
    p = rc.Params(alpha=0.3, eta=(0.2, 0.5, 1.3), k=(3.4, 2.2, 1.8), specular_reflectance=(0.9, 0.8, 1.0),
                  distribution="beckmann")
    rng = np.random.default_rng(0)
    w = rng.normal(size=(2, 3, 8))
    w[:, 2] = np.abs(w[:, 2])
    wi, wo = (Vec3(*(jnp.asarray(c) for c in v / np.linalg.norm(v, axis=0))) for v in w)

    @functools.partial(jax.jit, static_argnums=1)
    def derivatives(a, k):
        """value and gradient w.r.t. alpha (columns), gradients w.r.t. all parameters and wi (native)"""
        loss = lambda q, wi: jnp.sum(jnp.sqrt(k(q, wi, wo)))  # noqa: E731
        return (jax.value_and_grad(lambda a: loss(p.replace(alpha=a), wi))(a),
                jax.grad(loss, argnums=(0, 1))(p, wi))

    _close(derivatives(p.alpha, kern), derivatives(p.alpha, kern.unwrapped))
