"""Special functions that stay finite, with finite gradients, at the edges of their domain.

Autodiff of ``sqrt`` at 0 or ``arccos`` at +-1 gives inf, and inf * 0 in a chain rule gives
NaN: the classic source of NaN gradients at grazing angles. These versions clamp the
argument into the domain and give the derivative a finite one-sided value there
(``custom_jvp``), so that a masked-out grazing sample contributes 0, not NaN, to a gradient.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

# Largest derivative we allow at a domain edge; large enough to be "steep", small
# enough that 0 * it stays 0 in float32.
_EDGE_SLOPE = 1e6


@jax.custom_jvp
def safe_sqrt(x):
    """sqrt(max(x, 0)); the derivative at x <= 0 is 0 rather than inf."""
    return jnp.sqrt(jnp.maximum(x, 0.0))


@safe_sqrt.defjvp
def _safe_sqrt_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    y = safe_sqrt(x)
    slope = jnp.where(y > 0, 0.5 / jnp.where(y > 0, y, 1.0), 0.0)
    slope = jnp.minimum(slope, _EDGE_SLOPE)
    return y, slope * dx


@jax.custom_jvp
def safe_acos(x):
    """arccos of x clamped to [-1, 1]; the derivative stays finite at +-1."""
    return jnp.arccos(jnp.clip(x, -1.0, 1.0))


@safe_acos.defjvp
def _safe_acos_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    xc = jnp.clip(x, -1.0, 1.0)
    s = jnp.sqrt(jnp.maximum(1.0 - xc * xc, 0.0))
    inside = (x > -1.0) & (x < 1.0) & (s > 0)
    slope = jnp.where(inside, -1.0 / jnp.where(inside, s, 1.0), 0.0)
    slope = jnp.maximum(slope, -_EDGE_SLOPE)
    return jnp.arccos(xc), slope * dx


@jax.custom_jvp
def safe_asin(x):
    """arcsin of x clamped to [-1, 1]; the derivative stays finite at +-1."""
    return jnp.arcsin(jnp.clip(x, -1.0, 1.0))


@safe_asin.defjvp
def _safe_asin_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    xc = jnp.clip(x, -1.0, 1.0)
    s = jnp.sqrt(jnp.maximum(1.0 - xc * xc, 0.0))
    inside = (x > -1.0) & (x < 1.0) & (s > 0)
    slope = jnp.where(inside, 1.0 / jnp.where(inside, s, 1.0), 0.0)
    slope = jnp.minimum(slope, _EDGE_SLOPE)
    return jnp.arcsin(xc), slope * dx


def safe_atan2(y, x):
    """atan2 with a zero gradient at the origin (where it is undefined) instead of NaN."""
    r2 = x * x + y * y
    ok = r2 > 0
    return jnp.where(ok, jnp.arctan2(jnp.where(ok, y, 0.0), jnp.where(ok, x, 1.0)), 0.0)


def safe_div(a, b, eps: float = 0.0):
    """a / b where |b| > eps, else 0; both branches stay finite under autodiff."""
    ok = jnp.abs(b) > eps
    return jnp.where(ok, a / jnp.where(ok, b, 1.0), 0.0)


def erf(x):
    return jax.scipy.special.erf(x)


def erfinv(x):
    return jax.scipy.special.erfinv(x)
