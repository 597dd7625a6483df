"""Random numbers for samplers: one entry point that takes either uniforms or a PRNG key."""

from __future__ import annotations

import jax
import jax.numpy as jnp


def is_prng_key(x) -> bool:
    if isinstance(x, jax.Array) and jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key):
        return True
    # raw uint32[2] keys from jax.random.PRNGKey
    return hasattr(x, "dtype") and x.dtype == jnp.uint32 and jnp.shape(x) == (2,)


def as_key(key, default_seed: int):
    """A PRNG key from ``key``: None gives ``PRNGKey(default_seed)`` (a Monte Carlo estimator's fixed
    default: common random numbers), an integer seed its ``PRNGKey``, a key itself."""
    if key is None:
        return jax.random.PRNGKey(default_seed)
    return jax.random.PRNGKey(key) if jnp.ndim(key) == 0 and not is_prng_key(key) else key


def uniforms(u_or_key, shape, n: int, dtype=None):
    """Return a tuple of ``n`` uniform arrays of ``shape``.

    ``u_or_key`` is either a PRNG key (uniforms are drawn from it) or a tuple/list of at
    least ``n`` arrays in [0, 1) (used as given, broadcast to ``shape``), so samplers can be
    driven by stratified or quasi-random points as well as by keys.
    """
    dtype = dtype or jnp.result_type(float)
    if is_prng_key(u_or_key):
        keys = jax.random.split(u_or_key, n)
        return tuple(jax.random.uniform(k, shape, dtype) for k in keys)
    u = tuple(u_or_key)
    if len(u) < n:
        raise ValueError(f"sampler needs {n} uniform arrays, got {len(u)}")
    return tuple(jnp.broadcast_to(jnp.asarray(ui, dtype), shape) for ui in u[:n])
