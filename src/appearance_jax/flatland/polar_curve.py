"""Star-shaped polar curves r(theta) = a [1 + sum_n c_n cos(n theta)]: the meridian of a
Beard–Chuang raindrop (Sadeghi 2011 Eq. 3.1, Table 3.1; spec seed-002 §1.2.2) and, with all
c_n = 0, the circle.

Lengths are in units of ``a`` (for Beard–Chuang drops the equal-volume radius). The curve
lives in the meridian plane with coordinates ``(x, z)``: ``z`` along the vertical symmetry
axis (up), ``x`` horizontal. ``theta`` is the polar angle from the axis direction
``(0, orient)``: ``orient = -1`` ("down", decision D-R6 default) puts ``theta = 0`` — the
smaller, flattened radius of a falling drop — at the bottom. A point is
``r(theta) (sin theta, orient cos theta)``; as r is even in theta the curve is symmetric
about the axis, and r is a polynomial in ``mu = cos theta`` (``cos n theta = T_n(mu)``,
Chebyshev), so no atan2 is needed.

Ray intersection (:func:`hit_from_outside`, :func:`hit_from_inside`): the level function
``F(x) = |x| - r(theta(x))`` (< 0 inside) is sampled along the ray to bracket the first
sign change (the minimum of F, refined by golden section, brackets rays too close to
grazing for the samples), then a fixed number of safeguarded Newton steps converge to the
root. Gradients follow the implicit-function theorem by the "one Newton step at the
converged root" trick: ``t = sg(t*) - F(t*) / sg(F'(t*))`` has the value of t* (one more
Newton step) and the derivative ``-dF/F'`` with respect to everything F depends on (the
coefficients c_n, the ray's origin and direction). Second derivatives are not those of
the root. Everything is jittable with fixed iteration counts.
"""

from __future__ import annotations

import warnings
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..core.arrays import is_concrete

sg = jax.lax.stop_gradient

#: Sadeghi 2011 Table 3.1 (L1093–1107): equal-volume radius (mm) and c_0..c_7 of Eq. 3.1.
#: The a = 0.4 mm row (a sphere) was added by the author; rows are interpolated linearly.
BEARD_CHUANG_RADII_MM = np.array([0.4, 1.0, 1.5, 2.0, 2.5, 3.0])
BEARD_CHUANG_TABLE = np.array([
    [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [-0.0131, -0.0120, -0.0376, -0.0096, -0.0004, 0.0015, 0.0005, 0.0],
    [-0.0282, -0.0230, -0.0779, -0.0175, 0.0021, 0.0046, 0.0011, -0.0006],
    [-0.0458, -0.0335, -0.1211, -0.0227, 0.0083, 0.0089, 0.0012, -0.0021],
    [-0.0644, -0.0416, -0.1629, -0.0246, 0.0176, 0.0131, 0.0002, -0.0044],
    [-0.0840, -0.0480, -0.2034, -0.0237, 0.0297, 0.0166, -0.0021, -0.0072],
])

_ORIENT = {"down": -1.0, "up": 1.0}


class PolarCurve(NamedTuple):
    """r(theta) / a = 1 + sum_n c[n] cos(n theta); theta from the axis direction (0, orient)."""

    c: jax.Array        # (M,) coefficients, float
    orient: jax.Array   # -1.0: theta = 0 points down (default), +1.0: up


def cosine_series(c, orientation: str = "down") -> PolarCurve:
    """A polar curve from its coefficients ``c`` (any length M >= 1; c[0] is the constant term)."""
    if orientation not in _ORIENT:
        raise ValueError(f"cosine_series: orientation = {orientation!r}; valid: 'down', 'up'")
    c = jnp.atleast_1d(jnp.asarray(c, jnp.result_type(float)))
    if c.ndim != 1:
        raise ValueError(f"cosine_series: c must be 1-D, got shape {c.shape}")
    if is_concrete(c):
        cv = np.asarray(c)
        # sum |c_n| < 1 keeps r > 0 everywhere: the curve is star-shaped about its origin
        if not np.all(np.isfinite(cv)) or np.sum(np.abs(cv)) >= 1.0:
            raise ValueError(f"cosine_series: c = {cv.tolist()} must be finite with sum |c_n| < 1")
    return PolarCurve(c, jnp.asarray(_ORIENT[orientation], c.dtype))


def circle_curve(orientation: str = "down") -> PolarCurve:
    """The unit circle (the a <= 0.4 mm row of Table 3.1), as a :class:`PolarCurve`."""
    return cosine_series(jnp.zeros(8), orientation)


def beard_chuang_coefficients(radius_mm):
    """c_0..c_7 of Table 3.1 at equal-volume radius ``radius_mm`` (mm), linearly interpolated
    between rows: all zero (a sphere) for a <= 0.4 mm; clamped to the 3.0 mm row above 3.0 mm
    (with a warning when the radius is concrete). Differentiable in the radius inside the
    table (piecewise linear)."""
    a = jnp.asarray(radius_mm, jnp.result_type(float))
    if is_concrete(a):
        av = np.asarray(a)
        if av.ndim != 0 or not np.isfinite(av) or av <= 0:
            raise ValueError(f"beard_chuang: radius_mm = {av} must be one finite number > 0")
        if av > BEARD_CHUANG_RADII_MM[-1]:
            warnings.warn(f"beard_chuang: radius_mm = {float(av)} is beyond Table 3.1 (3.0 mm); "
                          "the 3.0 mm shape is used", stacklevel=2)
    xp = jnp.asarray(BEARD_CHUANG_RADII_MM, a.dtype)
    tab = jnp.asarray(BEARD_CHUANG_TABLE, a.dtype)
    return jnp.stack([jnp.interp(a, xp, tab[:, n]) for n in range(tab.shape[1])])


def beard_chuang(radius_mm, orientation: str = "down") -> PolarCurve:
    """The Beard–Chuang meridian of a raindrop of equal-volume radius ``radius_mm`` (mm), in
    units of that radius (Sadeghi Eq. 3.1 with Table 3.1)."""
    return cosine_series(beard_chuang_coefficients(radius_mm), orientation)


def _cheb_to_power(m: int) -> np.ndarray:
    """(m, m) matrix P with T_n(mu) = sum_k P[n, k] mu^k."""
    P = np.zeros((m, m))
    P[0, 0] = 1.0
    if m > 1:
        P[1, 1] = 1.0
    for n in range(2, m):
        P[n, 1:] = 2.0 * P[n - 1, :-1]
        P[n] -= P[n - 2]
    return P


def _cheb(c, mu):
    """R(mu) = 1 + sum c_n T_n(mu) and R'(mu), by Horner in the power basis (degree <= 7 in
    Table 3.1: the basis change loses nothing measurable and keeps the compiled graph small)."""
    m = c.shape[0]
    b = jnp.asarray(_cheb_to_power(m), c.dtype).T @ c
    R = jnp.full_like(mu, b[m - 1])
    dR = jnp.zeros_like(mu)
    for k in range(m - 2, -1, -1):
        dR = dR * mu + R
        R = R * mu + b[k]
    return 1.0 + R, dR


def radius(curve: PolarCurve, theta):
    """r(theta) / a."""
    return _cheb(curve.c, jnp.cos(theta))[0]


def point(curve: PolarCurve, theta):
    """(x, z) of the curve at polar angle ``theta`` (signed: x has the sign of sin theta)."""
    r = radius(curve, theta)
    return r * jnp.sin(theta), curve.orient * r * jnp.cos(theta)


def _rho_mu(curve, x, z):
    rho = jnp.sqrt(x * x + z * z)
    ok = rho > 0
    rs = jnp.where(ok, rho, 1.0)
    mu = jnp.where(ok, jnp.clip(curve.orient * z / rs, -1.0, 1.0), 1.0)
    return rho, rs, mu


def level(curve: PolarCurve, x, z):
    """F(x, z) = |x| - r(theta(x)): negative inside, zero on the curve."""
    rho, _, mu = _rho_mu(curve, x, z)
    return rho - _cheb(curve.c, mu)[0]


def _level_grad(curve, x, z):
    """F and its gradient (one Chebyshev evaluation)."""
    rho, rs, mu = _rho_mu(curve, x, z)
    R, dR = _cheb(curve.c, mu)
    gx = x / rs + dR * mu * x / (rs * rs)
    gz = z / rs - dR * (curve.orient / rs - mu * z / (rs * rs))
    return rho - R, gx, gz


def _grad_level(curve, x, z):
    return _level_grad(curve, x, z)[1:]


def normal(curve: PolarCurve, x, z):
    """Outward unit normal at a point (x, z) on (or near) the curve."""
    gx, gz = _grad_level(curve, x, z)
    inv = 1.0 / jnp.sqrt(gx * gx + gz * gz)
    return gx * inv, gz * inv


def volume(curve: PolarCurve, n: int = 4097):
    """Volume of the axisymmetric body (2 pi / 3) int_0^pi r^3 sin theta d theta, in units of a^3
    (4 pi / 3 for an equal-volume Beard–Chuang drop; Simpson's rule on ``n`` points)."""
    n = n + (n + 1) % 2
    th = jnp.linspace(0.0, jnp.pi, n)
    f = radius(curve, th) ** 3 * jnp.sin(th)
    w = jnp.ones(n).at[1:-1:2].set(4.0).at[2:-1:2].set(2.0) * (jnp.pi / (n - 1) / 3.0)
    return 2.0 * jnp.pi / 3.0 * jnp.sum(w * f)


@partial(jax.jit, static_argnames=("n", "iters"))
def extent(curve: PolarCurve, ux, uz, n: int = 1024, iters: int = 48):
    """(min, max) of x . u over the curve for a unit vector u = (ux, uz): the projected extent,
    i.e. the range of impact parameters of rays perpendicular to u that hit the curve."""
    th = jnp.linspace(-jnp.pi, jnp.pi, n, endpoint=False)

    def proj(t):
        x, z = point(curve, t)
        return x * ux + z * uz

    def refine(sign):
        g = lambda t: sign * proj(t)
        j = jnp.argmax(g(th))
        h = 2.0 * jnp.pi / n
        lo, hi = th[j] - h, th[j] + h
        gr = 0.5 * (np.sqrt(5.0) - 1.0)

        def body(_, lh):
            lo, hi = lh
            m1, m2 = hi - gr * (hi - lo), lo + gr * (hi - lo)
            left = g(m1) > g(m2)
            return jnp.where(left, lo, m1), jnp.where(left, m2, hi)

        lo, hi = jax.lax.fori_loop(0, iters, body, (lo, hi))
        return proj(0.5 * (lo + hi))

    return refine(-1.0), refine(1.0)


def _golden_min(f, lo, hi, iters):
    gr = 0.5 * (np.sqrt(5.0) - 1.0)

    def body(_, lh):
        lo, hi = lh
        m1, m2 = hi - gr * (hi - lo), lo + gr * (hi - lo)
        left = f(m1) < f(m2)
        return jnp.where(left, lo, m1), jnp.where(left, m2, hi)

    lo, hi = jax.lax.fori_loop(0, iters, body, (lo, hi))
    return 0.5 * (lo + hi)


def _newton(fd, t_neg, t_pos, iters):
    """Safeguarded Newton on f with f(t_neg) < 0 < f(t_pos): a Newton step that leaves the
    bracket is replaced by bisection; the bracket shrinks on the sign of f."""

    def body(_, st):
        t, f, d, tn, tp = st
        lo, hi = jnp.minimum(tn, tp), jnp.maximum(tn, tp)
        step = t - f / jnp.where(d != 0, d, 1.0)
        inside = (d != 0) & (step > lo) & (step < hi)
        t_new = jnp.where(inside, step, 0.5 * (tn + tp))
        t_new = jnp.where(f == 0, t, t_new)
        f_new, d_new = fd(t_new)
        neg = f_new < 0
        return t_new, f_new, d_new, jnp.where(neg, t_new, tn), jnp.where(neg, tp, t_new)

    f0, d0 = fd(t_pos)
    t, _, _, _, _ = jax.lax.fori_loop(0, iters, body, (t_pos, f0, d0, t_neg, t_pos))
    return t


def _along(curve, px, pz, dx, dz):
    f = lambda t: level(curve, px + t * dx, pz + t * dz)

    def fd(t):
        x, z = px + t * dx, pz + t * dz
        F, gx, gz = _level_grad(curve, x, z)
        return F, gx * dx + gz * dz

    return f, fd


def _implicit_step(curve, px, pz, dx, dz, t):
    """The root's value with implicit-function-theorem derivatives (see the module docstring)."""
    t0 = sg(t)
    x, z = px + t0 * dx, pz + t0 * dz
    gx, gz = _grad_level(sg(curve), sg(x), sg(z))
    den = gx * sg(dx) + gz * sg(dz)
    return t0 - level(curve, x, z) / jnp.where(den != 0, den, 1.0)


def hit_from_outside(curve: PolarCurve, px, pz, dx, dz, t_max, *, n_samples: int = 64,
                     iters: int = 40):
    """First hit of the ray (px, pz) + t (dx, dz), 0 <= t <= t_max, that starts outside the
    curve: returns (t, hit). ``t_max`` must reach past the curve (e.g. the origin's distance
    plus the curve's largest radius)."""
    f, fd = _along(sg(curve), sg(px), sg(pz), sg(dx), sg(dz))
    ts = jnp.linspace(0.0, 1.0, n_samples)[:, None] * sg(t_max)
    fs = f(ts)
    inside = fs <= 0
    found = jnp.any(inside, axis=0)
    k = jnp.argmax(inside, axis=0)
    j = jnp.argmin(fs, axis=0)
    h = sg(t_max) / (n_samples - 1)
    # rays too close to grazing for the samples: refine the minimum of F near the best sample
    tm = _golden_min(f, jnp.maximum((j - 1) * h, 0.0), (j + 1) * h, 40)
    hit = found | (f(tm) <= 0)
    t_pos = jnp.where(found, (k - 1) * h, jnp.maximum(tm - h, 0.0))
    t_neg = jnp.where(found, k * h, tm)
    t = _newton(fd, t_neg, t_pos, iters)
    t = jnp.where(hit, t, 0.0)
    return _implicit_step(curve, px, pz, dx, dz, t), hit


def hit_from_inside(curve: PolarCurve, px, pz, dx, dz, t_max, *, n_samples: int = 48,
                    iters: int = 40):
    """Next hit of the ray that starts on (or inside) the curve at (px, pz) and travels into
    it along (dx, dz): returns (t, ok). ``t_max`` >= the curve's diameter. ``ok`` is False
    for rays that do not enter (tangent or outward)."""
    f, fd = _along(sg(curve), sg(px), sg(pz), sg(dx), sg(dz))
    h = sg(t_max) / n_samples
    ts = jnp.arange(1, n_samples + 1)[:, None] * h
    fs = f(ts)
    out = fs > 0
    k = jnp.argmax(out, axis=0)                      # first sample outside (0-based)
    # a chord shorter than one sample: the minimum of F on (0, h) is the inner bracket end
    tm = _golden_min(f, 0.0 * k, h + 0.0 * k, 40)
    first = k == 0
    ok = jnp.any(out, axis=0) & (~first | (f(tm) < 0))
    t_neg = jnp.where(first, tm, k * h)
    t_pos = (k + 1) * h
    t = _newton(fd, t_neg, t_pos, iters)
    t = jnp.where(ok, t, h)
    return _implicit_step(curve, px, pz, dx, dz, t), ok
