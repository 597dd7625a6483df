"""Single-precision fast paths of the special functions in the hair eval kernels
(:mod:`appearance_jax.bcsdf.chiang`): atan2 / arcsin, exp(a) * I0e(x) and the dielectric
Fresnel reflectance seen from outside. Each function picks its implementation from the dtype
of its argument at trace time: float32 (and narrower) gets the short form below, float64 the
exact one of :mod:`appearance_jax.core.special`, ``jax.scipy.special.i0e`` and
:mod:`appearance_jax.optics.fresnel`, so float64 results are unchanged.

Why: on XLA:CPU the float64-grade forms cost most of chiang's eval in float32 (measured per
1e6 pairs, one core: the 12-term atan2 series ~3 ms per call, ``i0e`` ~2.5 ms per call, about
80 flops plus a divide and a rsqrt, both Chebyshev branches evaluated).

Accuracy in float32 (tests/bcsdf/test_chiang_fast32.py, against float64): atan2 / arcsin
within 2 ulp of the angle (+ 1 ulp of pi), exp(a) I0e(x) within 4e-7 relative (Abramowitz &
Stegun 9.8.1-2, |error| < 1.9e-7), Fresnel within 4 ulp.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.scipy.special import i0e

from ..core.special import _atan2_jvp as _atan2_exact_jvp, atan2 as _atan2_exact, safe_asin as _asin_exact, safe_sqrt
from ..optics.fresnel import fresnel_dielectric

_TAN_PI_8 = 0.41421356237309503
# atan u = u + u^3 P(u^2) on |u| <= tan(pi/8) (Cephes atanf; relative error < 1.2e-7)
_ATANF = (8.05374449538e-2, -1.38776856032e-1, 1.99777106478e-1, -3.33329491539e-1)
# I0(x) = sum c_k (x/3.75)^(2k) for x <= 3.75 (A&S 9.8.1) and sqrt(x) e^-x I0(x) = sum d_k (3.75/x)^k
# for x >= 3.75 (A&S 9.8.2), highest degree first
_I0_SMALL = (0.0045813, 0.0360768, 0.2659732, 1.2067492, 3.0899424, 3.5156229, 1.0)
_I0_LARGE = (0.00392377, -0.01647633, 0.02635537, -0.02057706, 0.00916281, -0.00157565, 0.00225319,
             0.01328592, 0.39894228)


def is_single(x) -> bool:
    """True when ``x`` is float32 or narrower (the fast paths apply)."""
    dt = jnp.result_type(x)
    return jnp.issubdtype(dt, jnp.floating) and jnp.finfo(dt).bits <= 32


def _horner(coeffs, t):
    r = coeffs[0]
    for c in coeffs[1:]:
        r = r * t + c
    return r


def _atan2_kernel(y, x):
    """One divide: octant swap to num/den <= 1, then u = num/den or (num - den)/(num + den)
    (atan t = pi/4 + atan((t - 1)/(t + 1)) above tan(pi/8)), chosen before dividing."""
    ay, ax = jnp.abs(y), jnp.abs(x)
    swap = ay > ax
    num = jnp.where(swap, ax, ay)
    den = jnp.where(swap, ay, ax)
    big = num > _TAN_PI_8 * den
    top = jnp.where(big, num - den, num)
    bot = jnp.where(big, num + den, den)
    u = top / jnp.where(bot > 0, bot, 1.0)
    z = u * u
    r = u + u * z * _horner(_ATANF, z) + jnp.where(big, jnp.pi / 4, 0.0)
    r = jnp.where(swap, jnp.pi / 2 - r, r)
    r = jnp.where(jnp.signbit(x), jnp.pi - r, r)
    return jnp.where(jnp.signbit(y), -r, r)


@jax.custom_jvp
def _atan2_single(y, x):
    return _atan2_kernel(y, x)


@_atan2_single.defjvp
def _atan2_single_jvp(primals, tangents):
    # the tangent of core.special.atan2's rule, (x dy - y dx) / (x^2 + y^2) (0 at the origin);
    # its exact primal is unused (removed by dead-code elimination)
    _, tangent = _atan2_exact_jvp(primals, tangents)
    return _atan2_single(*primals), tangent


def atan2(y, x):
    """atan2(y, x) in [-pi, pi]; the derivative is zero at the origin (as
    :func:`core.special.atan2`)."""
    y, x = jnp.broadcast_arrays(jnp.asarray(y), jnp.asarray(x))
    return _atan2_single(y, x) if is_single(y) else _atan2_exact(y, x)


def asin(x):
    """arcsin of x clamped to [-1, 1], derivative finite at +-1 (as :func:`core.special.safe_asin`)."""
    x = jnp.asarray(x)
    if not is_single(x):
        return _asin_exact(x)
    xc = jnp.clip(x, -1.0, 1.0)
    # atan2 of (x, sqrt(1 - x^2)): the derivative 1/sqrt(1 - x^2) through safe_sqrt is capped at +-1
    return _atan2_single(xc, safe_sqrt((1.0 - xc) * (1.0 + xc)))


def exp_i0e(a, x):
    """exp(a) I0e(x) = exp(a - x) I0(x) for x >= 0, one exponential: the small-x branch folds
    e^-x into exp(a)."""
    if not is_single(x):
        return jnp.exp(a) * i0e(x)
    small = x <= 3.75
    t = x * (1.0 / 3.75)
    ps = _horner(_I0_SMALL, t * t)
    xl = jnp.where(small, 3.75, x)  # keeps the unused branch (and its derivative) finite
    pl = _horner(_I0_LARGE, 3.75 / xl) * jax.lax.rsqrt(xl)
    return jnp.exp(jnp.where(small, a - x, a)) * jnp.where(small, ps, pl)


def fresnel_outside(cos_i, eta):
    """Unpolarised dielectric reflectance for light arriving from outside (0 <= cos_i <= 1) on
    a medium of index ``eta`` >= 1: :func:`optics.fresnel.fresnel_dielectric` without the
    inside branch and with one divide (eta >= 1: no total internal reflection)."""
    if not is_single(cos_i):
        return fresnel_dielectric(cos_i, eta)[0]
    c = jnp.clip(cos_i, 0.0, 1.0)
    ct = safe_sqrt(1.0 - (1.0 - c * c) / (eta * eta))
    a, b = eta * ct, eta * c
    ds, dp = c + a, b + ct
    ns, np_ = (c - a) * dp, (b - ct) * ds
    den = (ds * dp) ** 2
    ok = den > 0  # eta -> 1 at grazing incidence: F -> 1
    return jnp.where(ok, 0.5 * (ns * ns + np_ * np_) / jnp.where(ok, den, 1.0), 1.0)


__all__ = ["asin", "atan2", "exp_i0e", "fresnel_outside", "is_single"]
