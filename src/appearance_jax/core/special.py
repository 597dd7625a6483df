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


# Taylor coefficients (-1)^k / (2k + 1) of atan(w)/w in w^2; after the two reductions below
# |w| <= tan(pi/16) ~ 0.199, where 12 terms leave a relative truncation error < 1e-18.
_ATAN_TAYLOR = tuple((-1.0) ** k / (2 * k + 1) for k in range(12))
_TAN_PI_8 = 0.41421356237309503


def _atan2_kernel(y, x):
    """atan2(y, x) in [-pi, pi] from +, *, /, sqrt and selects only.

    Why: XLA:CPU lowers ``atan2`` (and ``arcsin``/``arccos``, which become atan2) to a scalar
    libm call per element, 50-100x slower than the vectorised exp/log; in the hair kernels these
    calls were most of the run time. Reductions: octant swap to t = min/max in [0, 1];
    atan t = pi/4 + atan((t - 1)/(t + 1)) above tan(pi/8); one half-angle step
    atan u = 2 atan(u / (1 + sqrt(1 + u^2))); then the Taylor series. Accurate to a few ulp in
    float64 and float32; atan2(+-0, x < 0) = +-pi and atan2(0, 0) = 0 as in libm."""
    ay, ax = jnp.abs(y), jnp.abs(x)
    swap = ay > ax
    num = jnp.where(swap, ax, ay)
    den = jnp.where(swap, ay, ax)
    t = num / jnp.where(den > 0, den, 1.0)
    big = t > _TAN_PI_8
    u = jnp.where(big, (t - 1.0) / (t + 1.0), t)
    w = u / (1.0 + jnp.sqrt(1.0 + u * u))
    z = w * w
    poly = jnp.full_like(z, _ATAN_TAYLOR[-1])
    for c in _ATAN_TAYLOR[-2::-1]:
        poly = poly * z + c
    r = 2.0 * w * poly + jnp.where(big, jnp.pi / 4, 0.0)
    r = jnp.where(swap, jnp.pi / 2 - r, r)
    r = jnp.where(jnp.signbit(x), jnp.pi - r, r)
    return jnp.where(jnp.signbit(y), -r, r)


@jax.custom_jvp
def atan2(y, x):
    """atan2(y, x) that XLA:CPU vectorises (see :func:`_atan2_kernel`); derivative
    (x dy - y dx) / (x^2 + y^2), zero at the origin instead of NaN."""
    y, x = jnp.broadcast_arrays(jnp.asarray(y), jnp.asarray(x))
    return _atan2_kernel(y, x)


@atan2.defjvp
def _atan2_jvp(primals, tangents):
    (y, x), (dy, dx) = primals, tangents
    r2 = x * x + y * y
    ok = r2 > 0
    inv = jnp.where(ok, 1.0 / jnp.where(ok, r2, 1.0), 0.0)
    return atan2(y, x), (x * dy - y * dx) * inv


def _cos_from_sin(xc):
    """sqrt(1 - x^2) as sqrt((1 - x)(1 + x)): no cancellation near |x| = 1."""
    return jnp.sqrt(jnp.maximum((1.0 - xc) * (1.0 + xc), 0.0))


@jax.custom_jvp
def safe_acos(x):
    """arccos of x clamped to [-1, 1]; the derivative stays finite at +-1."""
    xc = jnp.clip(x, -1.0, 1.0)
    return _atan2_kernel(_cos_from_sin(xc), xc)


@safe_acos.defjvp
def _safe_acos_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    xc = jnp.clip(x, -1.0, 1.0)
    s = jnp.sqrt(jnp.maximum(1.0 - xc * xc, 0.0))
    inside = (x > -1.0) & (x < 1.0) & (s > 0)
    slope = jnp.where(inside, -1.0 / jnp.where(inside, s, 1.0), 0.0)
    slope = jnp.maximum(slope, -_EDGE_SLOPE)
    return safe_acos(x), slope * dx


@jax.custom_jvp
def safe_asin(x):
    """arcsin of x clamped to [-1, 1]; the derivative stays finite at +-1."""
    xc = jnp.clip(x, -1.0, 1.0)
    return _atan2_kernel(xc, _cos_from_sin(xc))


@safe_asin.defjvp
def _safe_asin_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    xc = jnp.clip(x, -1.0, 1.0)
    s = jnp.sqrt(jnp.maximum(1.0 - xc * xc, 0.0))
    inside = (x > -1.0) & (x < 1.0) & (s > 0)
    slope = jnp.where(inside, 1.0 / jnp.where(inside, s, 1.0), 0.0)
    slope = jnp.minimum(slope, _EDGE_SLOPE)
    return safe_asin(x), slope * dx


def safe_atan2(y, x):
    """atan2 with a zero gradient at the origin (where it is undefined) instead of NaN; 0 there."""
    return atan2(y, x)


def safe_div(a, b, eps: float = 0.0):
    """a / b where |b| > eps, else 0; both branches stay finite under autodiff."""
    ok = jnp.abs(b) > eps
    return jnp.where(ok, a / jnp.where(ok, b, 1.0), 0.0)


def smoothstep(x):
    """3 x^2 - 2 x^3 of x clipped to [0, 1]: 0 -> 1 with zero slope at both ends."""
    x = jnp.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def erf(x):
    return jax.scipy.special.erf(x)


def erfinv(x):
    return jax.scipy.special.erfinv(x)
