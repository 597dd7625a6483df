"""Dual scattering: multiple scattering in a hair volume by Sadeghi's artist-friendly lobes
(Sadeghi 2011 §4.6.2, §4.7, Eqs. 4.17-4.37, Table 4.1, App. C, after Zinke et al. 2008), on top of
the single-scattering model :mod:`appearance_jax.bcsdf.sadeghi` (its ``Params``, the *single* and
*multiple* AFC sets; the tables also accept a :class:`marschner.Params`). Spec seed-002
§1.3.9-1.3.10.

Dual scattering (Sadeghi Table 4.1 names). For the light inclination theta (decision D-H7: the
tables are indexed by theta_i) the tables are computed in JAX by Gauss-Legendre quadrature
of the *normalized* single scattering f_s'^norm = f'_s / int f'_s cos theta_o dw_o (Sadeghi Eq. 4.17;
D-H4: per theta_i, measure cos theta_o dw_o, so a_f + a_b = 1) of the *multiple* parameter
set: a_f / a_b (front |phi| > pi/2 / back |phi| < pi/2 attenuation, Zinke 2008 Eq. 6),
alpha_f / alpha_b and beta_f / beta_b (lobe-weighted shifts and standard deviations,
Sadeghi Eqs. 4.30-4.33), A_b (Sadeghi Eq. 4.27 with Zinke's cube, D-H1), Delta_b (4.28), sigma_b (4.29
with sqrt(2 beta_f^2 + 3 beta_b^2), D-H2; the odd (2 beta_f + 3 beta_b) term in the
denominator is kept as in the source) and N^G_X = (2/pi) int_{pi/2}^{pi} N'_X dphi (4.35,
in closed form). a_f is clamped to <= 0.99 inside A_b, Delta_b, sigma_b (poles at 1).
Then (Sadeghi §4.7.2 pseudo code, cleaned; D-H3 sigma_f^2 in the *scatter* back term):

    T_f = d_f a_f^n,  sigma_f^2 = beta_f^2 n                         (4.23-4.24)
    f_back^direct  = C_Back I_Back 2 A_b g(theta_h - Delta_b + alpha_Back, sigma_b^2 + beta_Back) / (pi cos^2 theta_d)
    f_back^scatter = same with variance sigma_b^2 + sigma_f^2 + beta_Back
    f_s^direct  = f'_s (single set)
    f_s^scatter = C_Fwd I_Fwd sum_X C_X I_X g'(theta_h - alpha_X, beta_X^2 + sigma_f^2) N^G_X / cos^2 theta_d
    F^direct  = directFraction (f_s^direct + d_b f_back^direct)
    F^scatter = max(T_f - directFraction, 0) d_f (f_s^scatter + pi d_b f_back^scatter)   (D-H5)

``dual_scattering`` returns F^direct + F^scatter in 1/sr; the thesis' shader returns it
times cos theta_i (multiply by the light's curve irradiance as for any BCSDF). Inputs:
``n_forward`` = number of hairs in front of the shading point along the light path
(dimensionless, >= 0; the RSL's shadow opacity x hairs_that_cast_full_shadow, see
:func:`from_shadow`), ``direct_fraction`` = 1 - shadow opacity in [0, 1]; or an explicit
``forward=(T_f, sigma_f^2)`` e.g. from :func:`forward_from_inclinations` (the exact
alternative with the inclinations theta^k of the occluding hairs, Sadeghi Eqs. 4.19-4.22).
The double d_f (inside T_f and again in F^scatter) follows Zinke's Fig. 5 and is kept.

The decisions D-H1 ... D-H9 (the spec's register), their history and the validation: docs/hair.md.

Example::

    from appearance_jax.bcsdf import dual_scattering as ds, sadeghi
    from appearance_jax.core.frame import fiber_direction
    wi = fiber_direction(0.3, 0.0); wo = fiber_direction(-0.2, 2.5)
    F = ds.dual_scattering(sadeghi.Params(), ds.DualParams(), wi, wo,
                           n_forward=5.0, direct_fraction=0.5)  # (3,), 1/sr
    tab = ds.precompute(sadeghi.Params(), ds.DualParams())       # reuse: ds.dual_scattering(..., tables=tab)
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..core.frame import fiber_angles
from ..core.model import as_bands
from ..core.params import Bands, integer, param, params_class, Real, static, validate
from ..core.quadrature import gauss_legendre
from ..core.special import erf
from ..core.vec import as_directions, Vec3
from . import marschner
from .sadeghi import colors, lobes, Params, shifts

A_F_MAX = 0.99


@params_class
class DualParams:
    """Dual-scattering densities, artist adjusters (Sadeghi §4.6.2, L1750-1755) and decisions."""

    d_f: Real = param(0.7, lo=0.0, hi=1.0, doc="forward-scattering density factor d_f")
    d_b: Real = param(0.7, lo=0.0, hi=1.0, doc="backscattering density factor d_b")
    color_forward: Bands = param((1.0, 1.0, 1.0), lo=0.0, doc="C_Forward colour adjust", bands=True)
    intensity_forward: Real = param(1.0, lo=0.0, doc="I_Forward intensity adjust")
    color_back: Bands = param((1.0, 1.0, 1.0), lo=0.0, doc="C_Back colour adjust", bands=True)
    intensity_back: Real = param(1.0, lo=0.0, doc="I_Back intensity adjust")
    alpha_back: Real = param(0.0, lo=-math.pi / 4, hi=math.pi / 4, unit="rad", doc="alpha_Back shift adjust")
    beta_back: Real = param(0.0, lo=0.0, unit="rad^2", doc="beta_Back variance adjust (added to sigma_b^2)")
    a_b_denominator: str = static("cube", choices=("cube", "square"),
                                  doc="Sadeghi Eq. 4.27 second denominator: Zinke's cube (D-H1) or the thesis' square")
    clamp: str = static("clamp", choices=("clamp", "raw"), doc="max(T_f - directFraction, 0) (D-H5)")
    scatter_color: str = static("include", choices=("include", "exclude"), doc="C_X I_X in f_s^scatter (D-H6)")
    table_angle: str = static("theta_i", choices=("theta_i", "theta_h"), doc="table index angle (D-H7)")
    normalize: str = static("per_theta", choices=("per_theta", "dtheta_dphi", "none"),
                            doc="Sadeghi Eq. 4.17 normalization (D-H4)")
    n_quad: int = static(64, convert=integer(4, 512), doc="Gauss-Legendre nodes per axis for the tables")


def gaussian(x, var):
    """g(var; x), unit integral (Sadeghi Eq. 4.8); the RSL's g(variance; x)."""
    var = jnp.maximum(var, 1e-300)
    return jnp.exp(-0.5 * x * x / var) / jnp.sqrt(2.0 * jnp.pi * var)


# ---------------------------------------------------------------------------------------
# dual scattering tables


def azimuthal_global(p: Params):
    """N^G_X = (2/pi) int_{pi/2}^{pi} N'_X dphi (Sadeghi Eq. 4.35), closed form, shape (3,)."""
    s2 = math.sqrt(2.0)
    n_r = 4.0 / jnp.pi * (1.0 - s2 / 2.0)
    g = p.gamma_tt
    n_tt = 2.0 / jnp.pi * g * math.sqrt(jnp.pi / 2.0) * erf(jnp.pi / (2.0 * s2 * g))
    gg, G = p.glint_width, p.glint_angle
    glint = 2.0 / jnp.pi * gg * math.sqrt(jnp.pi / 2.0) * (erf((jnp.pi - G) / (s2 * gg))
                                                           - erf((jnp.pi / 2 - G) / (s2 * gg)))
    return jnp.stack([n_r * jnp.ones_like(n_tt), n_tt, n_r + p.glint_intensity * glint])


class Tables(NamedTuple):
    """Dual-scattering tables at light inclinations ``theta`` (Sadeghi Table 4.1 names); band-valued
    entries have a trailing bands axis."""

    theta: jax.Array
    a_f: jax.Array       # average forward attenuation
    a_b: jax.Array       # average backward attenuation
    alpha_f: jax.Array   # forward / backward lobe-weighted shifts (rad)
    alpha_b: jax.Array
    beta_f2: jax.Array   # squared lobe-weighted standard deviations (rad^2)
    beta_b2: jax.Array
    A_b: jax.Array       # backscattering attenuation (Sadeghi Eq. 4.27)
    delta_b: jax.Array   # backscattering shift (Sadeghi Eq. 4.28, rad)
    sigma_b2: jax.Array  # backscattering variance (Sadeghi Eq. 4.29 squared, rad^2)


def _nodes(n):
    to, wt = gauss_legendre(n, -math.pi / 2, math.pi / 2)
    pb, wb = gauss_legendre(n, 0.0, math.pi / 2)
    pf, wf = gauss_legendre(n, math.pi / 2, math.pi)
    return [jnp.asarray(v) for v in (to, wt, pb, wb, pf, wf)]


def lobe_integrals(lobe_fn, theta, n: int = 64, cos_power: int = 2):
    """Per-lobe integrals of ``lobe_fn(theta_i, theta_o, phi) -> (3, ..., bands)`` over the
    back (|phi| < pi/2) and front (|phi| > pi/2) half spaces, with the measure
    cos^cos_power(theta_o) dtheta_o dphi (cos_power = 2: cos theta_o dw_o), by n x n
    Gauss-Legendre per half; lobes are assumed even in phi. Returns (back, front), each
    (3,) + theta.shape + bands."""
    to, wt, pb, wb, pf, wf = _nodes(n)
    theta = jnp.asarray(theta, dtype=jnp.result_type(float))

    def one(th):
        def half(ph, wp):
            T, P = jnp.meshgrid(to, ph, indexing="ij")
            v = lobe_fn(th, T, P)                                  # (3, n, n, bands)
            w = (wt[:, None] * wp[None, :]) * jnp.cos(T) ** cos_power * 2.0
            return jnp.einsum("lijb,ij->lb", v, w)
        return half(pb, wb), half(pf, wf)

    b, f = jax.lax.map(one, theta.reshape(-1))
    shp = theta.shape
    return (jnp.moveaxis(b, 0, 1).reshape((3,) + shp + b.shape[-1:]),
            jnp.moveaxis(f, 0, 1).reshape((3,) + shp + f.shape[-1:]))


def backscatter_terms(a_f, a_b, alpha_f, alpha_b, beta_f, beta_b, d_b, a_b_denominator="cube"):
    """A_b, Delta_b, sigma_b^2 from the averages (Sadeghi Eqs. 4.27-4.29, Zinke 2008 Eqs. 11-14)."""
    af = jnp.minimum(a_f, A_F_MAX)
    af2 = af * af
    one = 1.0 - af2
    ab3 = a_b ** 3
    p2 = 3 if a_b_denominator == "cube" else 2
    A_b = a_b * af2 / one + ab3 * af2 / one ** p2
    delta_b = (alpha_b * (1.0 - 2.0 * a_b * a_b / one ** 2)
               + alpha_f * ((2.0 * one ** 2 + 4.0 * af2 * a_b * a_b) / one ** 3))
    bf2, bb2 = beta_f * beta_f, beta_b * beta_b
    num = a_b * jnp.sqrt(2.0 * bf2 + bb2) + ab3 * jnp.sqrt(2.0 * bf2 + 3.0 * bb2)
    den = a_b + ab3 * (2.0 * beta_f + 3.0 * beta_b)
    ok = den > 1e-300
    ratio = jnp.where(ok, num / jnp.where(ok, den, 1.0), jnp.sqrt(2.0 * bf2 + bb2))
    sigma_b = (1.0 + d_b * af2) * ratio
    return A_b, delta_b, sigma_b * sigma_b


def _lobe_fn_and_shifts(model):
    if isinstance(model, marschner.Params):
        al, be = marschner.lobe_shifts(model)
        return (lambda ti, to, ph: marschner.lobes(model, ti, to, ph)), al, be
    al, be = shifts(model)
    return (lambda ti, to, ph: lobes(model, ti, to, ph)), al, be


def tables_kernel(model, dual: DualParams, theta):
    """Dual-scattering tables at ``theta`` from ``model`` (artist-friendly :class:`Params`,
    normalized per ``dual.normalize``; or a :class:`marschner.Params`, physical f_s, never
    normalized). Sadeghi App. C order: a_f, a_b -> alpha -> beta -> Delta_b -> sigma_b^2 -> A_b."""
    fn, al, be = _lobe_fn_and_shifts(model)
    back, front = lobe_integrals(fn, theta, dual.n_quad, 2)
    norm = dual.normalize if isinstance(model, Params) else "none"
    if norm == "per_theta":
        Z = jnp.sum(back + front, axis=0)
    elif norm == "dtheta_dphi":
        b0, f0 = lobe_integrals(fn, theta, dual.n_quad, 0)
        Z = jnp.sum(b0 + f0, axis=0)
    else:
        Z = jnp.ones_like(back[0])
    Z = jnp.where(Z > 0, Z, 1.0)
    a_f = jnp.sum(front, axis=0) / Z
    a_b = jnp.sum(back, axis=0) / Z
    shp = (3,) + (1,) * (front.ndim - 1)
    al = jnp.stack([jnp.asarray(a) for a in al]).reshape(shp)
    be = jnp.stack([jnp.asarray(b) for b in be]).reshape(shp)

    def avg(w, x):
        s = jnp.sum(w, axis=0)
        return jnp.sum(w * x, axis=0) / jnp.where(s > 0, s, 1.0)

    alpha_f, alpha_b = avg(front, al), avg(back, al)
    beta_f, beta_b = avg(front, be), avg(back, be)
    A_b, delta_b, sigma_b2 = backscatter_terms(a_f, a_b, alpha_f, alpha_b, beta_f, beta_b, dual.d_b,
                                               dual.a_b_denominator)
    return Tables(jnp.asarray(theta), a_f, a_b, alpha_f, alpha_b, beta_f * beta_f, beta_b * beta_b,
                  A_b, delta_b, sigma_b2)


def tables(model, dual: DualParams, theta):
    """Validated, jitted :func:`tables_kernel`."""
    validate(model)
    validate(dual, DualParams)
    return _tables_jit(model, dual, theta)


_tables_jit = jax.jit(tables_kernel)


def interp_tables(tab: Tables, theta):
    """Linear interpolation of tables precomputed on a sorted grid ``tab.theta`` (1D)."""
    theta = jnp.asarray(theta)

    def it(v):
        f = jax.vmap(lambda col: jnp.interp(theta.reshape(-1), tab.theta, col), in_axes=-1, out_axes=-1)
        return f(v).reshape(theta.shape + v.shape[-1:])

    return Tables(theta, *(it(v) for v in tab[1:]))


def precompute(model, dual: DualParams, n_theta: int = 64):
    """Tables on a uniform grid of n_theta light inclinations in [-pi/2, pi/2] (the RSL
    constructor), to be used with ``dual_scattering(..., tables=...)``."""
    return tables(model, dual, jnp.linspace(-math.pi / 2, math.pi / 2, n_theta))


# ---------------------------------------------------------------------------------------
# dual scattering


def from_shadow(shadow, hairs_that_cast_full_shadow):
    """(n_forward, direct_fraction) from a deep-shadow-map opacity (Sadeghi App. C RSL):
    n = shadow * hairs_that_cast_full_shadow, directFraction = 1 - shadow."""
    shadow = jnp.asarray(shadow)
    return shadow * hairs_that_cast_full_shadow, 1.0 - shadow


def forward_scattering(tab: Tables, d_f, n_forward):
    """T_f = d_f a_f^n and sigma_f^2 = beta_f^2 n (Sadeghi Eqs. 4.23-4.24)."""
    n = jnp.asarray(n_forward)[..., None]
    return d_f * tab.a_f ** n, tab.beta_f2 * n


def forward_from_inclinations_kernel(model, dual: DualParams, theta_k, mask=None):
    """T_f = d_f prod_k a_f(theta^k), sigma_f^2 = sum_k beta_f^2(theta^k) (Sadeghi Eqs. 4.19-4.22):
    the exact alternative with the inclinations ``theta_k`` (last axis = occluding hairs,
    ``mask`` marks real ones). Returns shapes theta_k.shape[:-1] + bands."""
    theta_k = jnp.asarray(theta_k, dtype=jnp.result_type(float))
    tab = tables_kernel(model, dual, theta_k)
    m = jnp.ones(theta_k.shape, bool) if mask is None else jnp.asarray(mask, bool)
    m = m[..., None]
    log_a = jnp.where(m, jnp.log(jnp.maximum(tab.a_f, 1e-300)), 0.0)
    return dual.d_f * jnp.exp(jnp.sum(log_a, axis=-2)), jnp.sum(jnp.where(m, tab.beta_f2, 0.0), axis=-2)


class DualTerms(NamedTuple):
    T_f: jax.Array
    sigma_f2: jax.Array
    f_back_direct: jax.Array
    f_back_scatter: jax.Array
    f_s_direct: jax.Array
    f_s_scatter: jax.Array
    F_direct: jax.Array
    F_scatter: jax.Array


def dual_scattering_terms_kernel(p: Params, dual: DualParams, wi: Vec3, wo: Vec3, n_forward=0.0,
                                 direct_fraction=1.0, multiple: Params | None = None, forward=None,
                                 tables: Tables | None = None):
    """All intermediate quantities of the dual-scattering shader (Sadeghi §4.7.2); shapes wi.shape + bands."""
    mp = p if multiple is None else multiple
    th_i, ph_i = fiber_angles(wi)
    th_o, ph_o = fiber_angles(wo)
    th_h = 0.5 * (th_i + th_o)
    th_d = 0.5 * (th_o - th_i)
    c2 = jnp.cos(th_d) ** 2
    ok = c2 > 1e-12
    inv_c2 = jnp.where(ok, 1.0 / jnp.where(ok, c2, 1.0), 0.0)[..., None]
    angle = th_i if dual.table_angle == "theta_i" else th_h
    tab = tables_kernel(mp, dual, angle) if tables is None else interp_tables(tables, angle)
    if forward is None:
        n = jnp.broadcast_to(jnp.asarray(n_forward, dtype=jnp.result_type(float)), th_i.shape)
        T_f, sigma_f2 = forward_scattering(tab, dual.d_f, n)
    else:
        T_f, sigma_f2 = (jnp.asarray(v) for v in forward)
    th_hb = th_h[..., None]
    back = as_bands(dual.color_back) * dual.intensity_back * 2.0 * tab.A_b / jnp.pi * inv_c2
    x = th_hb - tab.delta_b + dual.alpha_back
    f_back_direct = back * gaussian(x, tab.sigma_b2 + dual.beta_back)
    f_back_scatter = back * gaussian(x, tab.sigma_b2 + sigma_f2 + dual.beta_back)
    f_s_direct = jnp.sum(lobes(p, th_i, th_o, ph_o - ph_i), axis=0)
    # indirect single scattering (Sadeghi Eqs. 4.34-4.35): widened unit-height M, front-averaged N
    al, be = shifts(mp)
    NG = azimuthal_global(mp)
    C = colors(mp) if dual.scatter_color == "include" else jnp.ones_like(colors(mp))
    f_s_scatter = 0.0
    for k in range(3):
        MG = jnp.exp(-0.5 * (th_hb - al[k]) ** 2 / (be[k] ** 2 + sigma_f2))
        f_s_scatter = f_s_scatter + C[k] * MG * NG[k]
    f_s_scatter = as_bands(dual.color_forward) * dual.intensity_forward * f_s_scatter * inv_c2
    df = jnp.asarray(direct_fraction, dtype=jnp.result_type(float))[..., None]
    F_direct = df * (f_s_direct + dual.d_b * f_back_direct)
    w = T_f - df
    w = jnp.maximum(w, 0.0) if dual.clamp == "clamp" else w
    F_scatter = w * dual.d_f * (f_s_scatter + jnp.pi * dual.d_b * f_back_scatter)
    return DualTerms(T_f, sigma_f2, f_back_direct, f_back_scatter, f_s_direct, f_s_scatter, F_direct, F_scatter)


def _dual_kernel(p, dual, wi, wo, n_forward=0.0, direct_fraction=1.0, multiple=None, forward=None, tables=None):
    t = dual_scattering_terms_kernel(p, dual, wi, wo, n_forward, direct_fraction, multiple, forward, tables)
    return t.F_direct + t.F_scatter


_terms_jit = jax.jit(dual_scattering_terms_kernel)
_dual_jit = jax.jit(_dual_kernel)


def _check(p, dual, multiple):
    validate(p, Params)
    validate(dual, DualParams)
    if multiple is not None:
        validate(multiple, Params)


def dual_scattering_terms(p: Params, dual: DualParams, wi: Vec3, wo: Vec3, n_forward=0.0, direct_fraction=1.0,
                          multiple: Params | None = None, forward=None, tables: Tables | None = None) -> DualTerms:
    """Validated :func:`dual_scattering_terms_kernel`."""
    _check(p, dual, multiple)
    wi, wo = as_directions(wi=wi, wo=wo)
    return _terms_jit(p, dual, wi, wo, n_forward, direct_fraction, multiple, forward, tables)


def dual_scattering(p: Params, dual: DualParams, wi: Vec3, wo: Vec3, n_forward=0.0, direct_fraction=1.0,
                    multiple: Params | None = None, forward=None, tables: Tables | None = None):
    """F^direct + F^scatter (1/sr), shape wi.shape + bands: single + multiple scattering of a
    hair at depth ``n_forward`` hairs inside a volume (Sadeghi §4.7.2). ``multiple`` is the second
    AFC set that feeds the multiple-scattering part (Sadeghi §4.6.3; None = same as ``p``)."""
    _check(p, dual, multiple)
    wi, wo = as_directions(wi=wi, wo=wo)
    return _dual_jit(p, dual, wi, wo, n_forward, direct_fraction, multiple, forward, tables)


def forward_from_inclinations(model, dual: DualParams, theta_k, mask=None):
    """Validated :func:`forward_from_inclinations_kernel`."""
    validate(model)
    validate(dual, DualParams)
    return jax.jit(forward_from_inclinations_kernel)(model, dual, theta_k, mask)
