"""Beckmann microfacet distribution (anisotropic), its Smith projected area and a
visible-normal sampler.

Use through :mod:`appearance_jax.microfacet.distribution` (``kind="beckmann"``).
Roughnesses ``ax, ay`` > 0 are the RMS slopes times sqrt(2) along x and y.

Equations:

    D(m) = exp(-(m_x^2/ax^2 + m_y^2/ay^2) / m_z^2) / (pi ax ay m_z^4)          (m_z > 0)

(Walter et al. 2007, Eq. 25; Heitz 2014, anisotropic form), and the Smith
Lambda with a = 1 / (alpha_w tan theta) = |w_z| / sqrt(ax^2 w_x^2 + ay^2 w_y^2)
(Walter et al. 2007, Eq. 27; Heitz 2014):

    Lambda(w) = (erf(a) - 1) / 2 + exp(-a^2) / (2 a sqrt(pi)).

The kernels use the projected area mu(w) = |w_z| (1 + Lambda(w)), which simplifies to

    mu(w) = (|w_z| (1 + erf(a)) + sqrt(ax^2 w_x^2 + ay^2 w_y^2) exp(-a^2) / sqrt(pi)) / 2,

finite and positive at grazing incidence (a = 0), where Lambda diverges. We use the exact
erf form, not Walter's rational approximation of G1 (their Eq. 27, rel. error < 0.35%),
which Mitsuba 3 uses.

Visible normals are sampled by inverting the CDF of the visible slopes in the stretched
(alpha = 1) configuration (Heitz & d'Eon 2014, Sec. 4; Jakob 2014, "An improved
visible normal sampling routine for the Beckmann distribution"): along the incident
azimuth the marginal slope density is (cos t - x sin t) exp(-x^2) / sqrt(pi) on
x <= cot t, with CDF

    C(x) = cos t (1 + erf x) / 2 + sin t exp(-x^2) / (2 sqrt(pi)),

and the transverse slope is independent, exp(-y^2)/sqrt(pi). C(x) = u C(cot t) is solved for
erf(x) by a bracketed Newton iteration (in the variable erf(x) the derivative is simply
(cos t - x sin t)/2 and the function is concave, so Newton converges monotonically once
it has overshot once); the last step is differentiated implicitly.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..core.special import erf, erfinv, safe_sqrt
from ..core.vec import Vec3, normalize

_SQRT_PI = 1.7724538509055159
_A_MAX = 30.0  # beyond a = 30, erf(a) = 1 and exp(-a^2) = 0 in double precision
_NEWTON_ITERS = 24


def D_terms(m: Vec3, ax, ay):
    """``(num, den)`` with D(m) = num / den: (exp(-tan^2 / alpha^2), pi ax ay m_z^4), and (0, 1)
    for m_z <= 0 (see :func:`appearance_jax.microfacet.ggx.D_terms`)."""
    z2 = m.z * m.z
    up = (m.z > 0) & (z2 > 0)
    z2s = jnp.where(up, z2, 1.0)
    iax, iay = 1.0 / ax, 1.0 / ay
    e = ((m.x * iax) ** 2 + (m.y * iay) ** 2) / z2s
    # exp(-e) underflows to 0 before 1/z^4 overflows for directions near the horizon
    return jnp.where(up, jnp.exp(-e), 0.0), jnp.pi * ax * ay * z2s * z2s


def D(m: Vec3, ax, ay):
    """Beckmann normal distribution D(m) in 1/sr; 0 for m_z <= 0 (Walter et al. 2007, Eq. 25)."""
    num, den = D_terms(m, ax, ay)
    return num / den


def projected_area(w: Vec3, ax, ay):
    """mu(w) = |w_z| (1 + Lambda(w)) = int max(0, w.m) D(m) dm (Heitz 2014).

    Finite and > 0 for every unit ``w`` when ax, ay > 0; symmetric in the sign of w_z.
    """
    z = jnp.abs(w.z)
    q = (ax * w.x) ** 2 + (ay * w.y) ** 2  # = (alpha_w sin theta)^2
    # safe-where: a > _A_MAX (including q = 0, normal incidence) takes the limit branch,
    # so the gradient never sees |z| / sqrt(q) with q -> 0
    big = q * (_A_MAX * _A_MAX) <= z * z
    qs = jnp.where(big, 1.0, q)
    sq = safe_sqrt(qs)
    a = jnp.where(big, _A_MAX, z / sq)
    mu = 0.5 * (z * (1.0 + erf(a)) + sq * jnp.exp(-a * a) / _SQRT_PI)
    return jnp.where(big, z, mu)


def _slope_cdf_solve(cos_t, sin_t, u):
    """Solve C(x) = u C(cot t) for x (see module docstring); returns x <= cot t."""
    dtype = jnp.result_type(cos_t, u)
    eps = 4.0 * jnp.finfo(dtype).eps
    has_sin = sin_t > 0
    sin_s = jnp.where(has_sin, sin_t, 1.0)
    cot = jnp.where(has_sin, cos_t / sin_s, _A_MAX)
    cot = jnp.minimum(cot, _A_MAX)
    t_hi = jnp.minimum(erf(cot), 1.0 - eps)
    t_lo = -1.0 + eps

    def C(t, c, s):
        x = erfinv(t)
        return 0.5 * c * (1.0 + t) + 0.5 * s * jnp.exp(-x * x) / _SQRT_PI, x

    def solve(c, s, uu, lo_t, hi_t):
        target = uu * C(hi_t, c, s)[0]
        t0 = jnp.clip(2.0 * uu - 1.0, lo_t, hi_t)

        def body(_, st):
            t, lo, hi = st
            g, x = C(t, c, s)
            g = g - target
            lo = jnp.where(g <= 0, t, lo)
            hi = jnp.where(g > 0, t, hi)
            dg = 0.5 * (c - x * s)
            step_ok = dg > 0
            tn = t - g / jnp.where(step_ok, dg, 1.0)
            inside = step_ok & (tn > lo) & (tn < hi)
            return jnp.where(inside, tn, 0.5 * (lo + hi)), lo, hi

        t, _, _ = jax.lax.fori_loop(0, _NEWTON_ITERS, body, (t0, lo_t * jnp.ones_like(t0), hi_t * jnp.ones_like(t0)))
        return t

    sg = jax.lax.stop_gradient
    t_star = sg(solve(sg(cos_t), sg(sin_t), sg(u), sg(t_lo), sg(t_hi)))
    # one Newton step outside the stop_gradient: value unchanged (g(t*) = 0), derivative
    # = -dg/dp / g'(t*), the implicit-function derivative of the root
    g, x = C(t_star, cos_t, sin_t)
    g = g - u * C(t_hi, cos_t, sin_t)[0]
    dg = 0.5 * (cos_t - x * sin_t)
    dg_ok = dg > 0
    t = t_star - jnp.where(dg_ok, g / jnp.where(dg_ok, dg, 1.0), 0.0)
    t = jnp.clip(t, t_lo, t_hi)
    return erfinv(t)


def sample_visible(w: Vec3, ax, ay, u1, u2) -> Vec3:
    """Sample m with density G1(w, m) max(0, w.m) D(m) / w_z, for w_z >= 0.

    Stretch w to the alpha = 1 configuration, sample the visible slopes there (module
    docstring), rotate them to the azimuth of w, unstretch them by (ax, ay) and turn the
    slope into a normal m = normalize(-s_x, -s_y, 1).
    """
    ws = normalize(Vec3(ax * w.x, ay * w.y, w.z))
    cos_t = jnp.clip(ws.z, 0.0, 1.0)
    sin_t = safe_sqrt(1.0 - cos_t * cos_t)
    s2 = ws.x * ws.x + ws.y * ws.y
    ok = s2 > 0
    inv = jnp.where(ok, 1.0 / safe_sqrt(jnp.where(ok, s2, 1.0)), 0.0)
    cphi = jnp.where(ok, ws.x * inv, 1.0)
    sphi = jnp.where(ok, ws.y * inv, 0.0)

    x = _slope_cdf_solve(cos_t, sin_t, u1)
    dtype = jnp.result_type(cos_t, u2)
    eps = 4.0 * jnp.finfo(dtype).eps
    y = erfinv(jnp.clip(2.0 * u2 - 1.0, -1.0 + eps, 1.0 - eps))

    sx = ax * (cphi * x - sphi * y)
    sy = ay * (sphi * x + cphi * y)
    return normalize(Vec3(-sx, -sy, jnp.ones_like(sx)))


def sample_slopes(ax, ay, u1, u2):
    """Slopes distributed as P22, i.e. m ~ D(m) m_z (Walter et al. 2007, Eq. 28-29).

    Isotropic alpha = 1 slope radius r^2 = -log(1 - u1), then stretched by (ax, ay).
    """
    u1 = jnp.minimum(u1, 1.0 - jnp.finfo(jnp.result_type(u1, float)).eps)
    r = safe_sqrt(-jnp.log1p(-u1))
    phi = 2.0 * jnp.pi * u2
    return ax * r * jnp.cos(phi), ay * r * jnp.sin(phi)
