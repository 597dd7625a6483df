"""Huang's importance sampler of the microfacet hair BCSDF and its stochastic pdf (Huang 2022,
Sec. 4.3.4 [T:1194-1209] and Huang Eq. 4.33; spec seed-001 §1.3.11). The model, its parameters and
conventions: :mod:`appearance_jax.bcsdf.huang`, which exposes ``sample`` and ``pdf`` (built on the
kernels here; this module does not import it).

Sampling: the offset h uniform over the projected width [-D_i, D_i], visible microfacet normals
at every interface, and the lobe with probability proportional to the luminance of Huang's
attenuations A_p; the weight is unbiased for S cos(theta_o) (E[weight; wo in dw] = S cos dw,
circles and ellipses, any tilt) but is not S cos / pdf pointwise. The pdf is the stochastic
Huang Eq. 4.33 (Monte Carlo-Simpson over the entry point, the same ``n_intervals`` / ``n_paths`` as
``eval``), returned as ``(estimate, stderr)``. The kernels take ``p``, a
:class:`appearance_jax.bcsdf.huang.Params`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..core import vec as V
from ..core.frame import fiber_angles, reflect, refract
from ..core.model import as_bands
from ..core.quadrature import simpson, simpson_mc
from ..core.rng import is_prng_key, uniforms
from ..core.spectral import luminance_or_mean
from ..core.vec import Vec3
from ..microfacet import distribution as mf
from ..optics.fresnel import fresnel_dielectric
from .fiber import (arc_element, ellipse_chord, ellipse_normal, ellipse_point, entry_gamma, half_width, meso_frame,
                    meso_normal, minor_axis, visible_gamma_interval)

_TINY = 1e-12


def _default_key(key):
    return jax.random.PRNGKey(0) if key is None else key


def _finite(x):
    return jnp.where(jnp.isfinite(x), x, 0.0)


def _ex(v: Vec3):
    """Two trailing axes (Simpson nodes, paths) on the components of ``v``."""
    return Vec3(v.x[..., None, None], v.y[..., None, None], v.z[..., None, None])




def _lobe_probabilities(A):
    """P_p = lum(A_p) / sum_q lum(A_q), shape (n_lobes, ...); all zero when every A_p is 0."""
    lum = luminance_or_mean(A)  # Huang's code: the luminance of the spectral attenuation
    tot = jnp.sum(lum, axis=0)
    return jnp.where(tot > 0, lum / jnp.where(tot > 0, tot, 1.0), 0.0)


def _walk(p, wi: Vec3, g, us, wo: Vec3 | None = None, connect=None):
    """One path of Huang's sampler (Sec. 4.3.4, [T:1194-1209]) entering at ellipse parameter g.

    At interface 1 a microfacet h_1 is drawn from the visible normals of w_i about the
    mesonormal m_1 (Huang Eq. 4.39); R leaves by reflection, the refracted ray crosses the fiber
    (exact chord, absorption exp(-sigma_a s), Huang Eq. 4.17) and at every further interface k a
    microfacet h_k is drawn from the visible normals of the arriving ray: lobe k - 1 leaves by
    refraction through it, the next one continues by reflection. ``us`` holds two uniforms per
    interface.

    Returns ``(A, Vis, dirs, dens)``:

    - ``A`` (n_lobes, ..., bands): Huang's lobe attenuations A_R = R_1, A_TT = T_1 T_2 A_t,
      A_TRT = T_1 R_2 T_3 A_t A_tr (, A_TRRT = T_1 R_2 R_3 T_4 A_t A_tr A_trr): Fresnel products
      and absorption, 0 once the path prefix is invalid (TIR kills TT: T_2 = 0).
    - ``Vis`` (n_lobes, ...): the visibility of lobe p's outgoing path: Smith G1 of every
      outgoing leg about its mesonormal, the meso/macro area ratios |w.m|/|w.n| of the thesis's
      macro-cosine semantics (1 without tilt; what :func:`_exit_pdf` and the flatland tracer
      carry) and the hard macro/meso side tests. Times A_p it is the analog path weight.
    - ``dirs``: the n_lobes sampled outgoing directions (fiber frame, pointing away).
    - ``dens`` (with ``wo`` and ``connect``, an integer array broadcasting against ``g``):
      where ``connect == p`` the microfacet at the interface where lobe p leaves is not drawn
      but the (generalised) half vector of ``wo``, and ``dens`` is the density per sr of ``wo``
      given the rest of the path, D_vis(h) |dh/dwo| (Walter et al. 2007 Jacobians; the
      D G1 / (4 |w_i.m_1|) and D G |w.h||o.h| / (eta^2 |h|^2 |w.m|) terms of Huang Eq. 4.33), 0 where
      that sample would fail. One graph serves all lobes (a leading lobe axis in ``g``):
      a third of the compile time of one walk per lobe.
    """
    kind, beta, alpha, eta = p.distribution, p.roughness, p.tilt, p.eta
    b = minor_axis(p.eccentricity)
    sig = as_bands(p.sigma_a)
    one = jnp.ones_like(g * us[0])
    z = Vec3(0.0 * one, 0.0 * one, one)
    bands = jnp.ones_like(sig)
    dens = None
    # interface 1: entry (reflection = R)
    py, pz = ellipse_point(g, b)
    ny, nz = ellipse_normal(py, pz, b)
    n1 = Vec3(0.0 * ny, ny, nz)
    fr = meso_frame(meso_normal(ny, nz, alpha))
    il = fr.to_local(wi)
    cin = V.dot(wi, n1)
    ok = (il.z > 0) & (cin > _TINY)
    il = V.where(ok, il, z)
    # h is uniform over the projected width (d h ~ |w_i.n| dl) while the thesis's flux per macro
    # arc length is |w_i.m_1| (Huang Eq. 4.31): the ratio (1 without tilt) keeps the sampler unbiased
    vis = jnp.where(ok, il.z / jnp.where(ok, cin, 1.0), 0.0)
    h = mf.sample_visible(kind, il, beta, beta, us[0], us[1])
    if connect is not None:
        ol = fr.to_local(wo)
        hc = V.normalize(il + ol)
        okc = ok & (ol.z > 0) & (V.dot(wo, n1) > 0) & (hc.z > 0)
        hc = V.where(okc, hc, z)
        co = jnp.where(okc, V.dot(ol, hc), 1.0)
        dens = jnp.where((connect == 0) & okc & (co > 0),
                         mf.pdf_visible(kind, il, hc, beta) / (4.0 * jnp.abs(co)), 0.0)
        h = V.where(connect == 0, hc, h)
    ci = V.dot(il, h)
    ok = ok & (ci > 0)
    F, _, _, _ = fresnel_dielectric(jnp.clip(ci, 0.0, 1.0), eta)
    rl = reflect(il, h)
    r = fr.to_world(rl)
    ok_r = ok & (rl.z > 0) & (V.dot(r, n1) > 0)
    A = [jnp.where(ok, F, 0.0)[..., None] * bands]
    Vis = [jnp.where(ok_r, vis * mf.G1(kind, V.where(ok_r, rl, z), h, beta), 0.0)]
    dirs = [r]
    tl, ok_t = refract(il, h, eta)
    ok = ok & ok_t & (tl.z < 0)
    tl = V.where(ok, tl, -z)
    d = fr.to_world(tl)
    ok = ok & (V.dot(d, n1) < 0)
    vis = jnp.where(ok, vis * mf.G1(kind, tl, h, beta), 0.0)
    thr = jnp.where(ok, 1.0 - F, 0.0)[..., None] * bands       # Fresnel products x absorption
    qy, qz = py, pz
    for k in range(1, p.n_lobes):
        s = ellipse_chord(qy, qz, d, b)
        qy, qz = qy + s * d.y, qz + s * d.z
        my, mz = ellipse_normal(qy, qz, b)
        n_in = Vec3(0.0 * my, -my, -mz)
        fr = meso_frame(-meso_normal(my, mz, alpha))          # inward mesonormal (§1.3.8)
        thr = thr * jnp.exp(-sig * s[..., None])
        wl = fr.to_local(-d)
        cwn = V.dot(-d, n_in)
        ok = ok & (wl.z > 0) & (cwn > _TINY)
        wl = V.where(ok, wl, z)
        area = wl.z / jnp.where(ok, cwn, 1.0)
        h = mf.sample_visible(kind, wl, beta, beta, us[2 * k], us[2 * k + 1])
        if connect is not None:
            ol = fr.to_local(wo)
            H = wl * (-eta) - ol
            hc = V.normalize(H)
            hc = hc * jnp.where(hc.z < 0, -1.0, 1.0)
            den2 = V.dot(H, H)
            okc = (ok & (hc.z > 0) & (V.dot(wo, n_in) < 0) & (ol.z < 0) & (V.dot(wl, hc) > 0)
                   & (V.dot(ol, hc) < 0) & (den2 > _TINY))
            hc = V.where(okc, hc, z)
            dc = mf.pdf_visible(kind, wl, hc, beta) * jnp.abs(V.dot(ol, hc)) / jnp.where(okc, den2, 1.0)
            dens = jnp.where((connect == k) & okc, dc, dens)
            h = V.where(connect == k, hc, h)
        ci = V.dot(wl, h)
        ok = ok & (ci > 0)
        F, _, _, _ = fresnel_dielectric(jnp.clip(ci, 0.0, 1.0), 1.0 / eta)
        # lobe k leaves by refraction (T_k = 0 under total internal reflection)
        ol_, ok_o = refract(wl, h, 1.0 / eta)
        o = fr.to_world(ol_)
        ok_o = ok & ok_o & (ol_.z < 0) & (V.dot(o, n_in) < 0)
        A.append(thr * jnp.where(ok, 1.0 - F, 0.0)[..., None])
        Vis.append(jnp.where(ok_o, vis * area * mf.G1(kind, V.where(ok_o, ol_, -z), h, beta), 0.0))
        dirs.append(o)
        if k == p.n_lobes - 1:
            break
        rl = reflect(wl, h)
        ok = ok & (rl.z > 0)
        rl = V.where(ok, rl, z)
        d = fr.to_world(rl)
        ok = ok & (V.dot(d, n_in) > 0)
        vis = jnp.where(ok, vis * area * mf.G1(kind, rl, h, beta), 0.0)
        thr = thr * jnp.where(ok, F, 0.0)[..., None]
    return jnp.stack(A), jnp.stack(Vis), dirs, dens


def _n_uniforms(p):
    return 2 + 2 * p.n_lobes  # offset h, lobe, two per interface (8 for R, TT, TRT)


def _sample_path(p, wi: Vec3, u):
    """Huang's sampler with its internals: (wo, weight, lobe, probabilities, A, Vis)."""
    shape = jnp.shape(wi.x)
    us = uniforms(u, shape, _n_uniforms(p))
    u_h, u_lobe, us = us[0], us[1], us[2:]
    b = minor_axis(p.eccentricity)
    thi, phii = fiber_angles(wi)
    D_i = half_width(p.eccentricity, phii)
    g, ok = entry_gamma(wi, D_i * (2.0 * u_h - 1.0), b)
    A, Vis, dirs, _ = _walk(p, wi, g, us)
    P = _lobe_probabilities(A)
    cdf = jnp.cumsum(P, axis=0)
    lobe = jnp.minimum(jnp.sum(u_lobe[None] >= cdf[:-1], axis=0), p.n_lobes - 1)
    onehot = (jnp.arange(p.n_lobes).reshape((-1,) + (1,) * len(shape)) == lobe[None])
    pick = lambda x: jnp.sum(jnp.where(onehot, x, 0.0), axis=0)  # noqa: E731
    wo = Vec3(*(pick(jnp.stack([getattr(d, c) for d in dirs])) for c in "xyz"))
    P_k, Vis_k = pick(P), pick(Vis)
    A_k = jnp.sum(jnp.where(onehot[..., None], A, 0.0), axis=0)
    tho, pho = fiber_angles(wo)
    D_o = half_width(p.eccentricity, pho)
    good = ok & (P_k > 0) & (Vis_k > 0) & (jnp.cos(thi) > _TINY)
    # analog weight sum_q A_q Vis_p (for gray A); D_i / D_o converts the flux density into
    # S cos(theta_o) (Huang Eq. 4.27), so that E[weight delta(wo)] = S cos(theta_o)
    scale = jnp.where(good, Vis_k * D_i / jnp.where(good, P_k * D_o, 1.0), 0.0)
    weight = _finite(A_k * scale[..., None])
    wo = V.where(good, wo, Vec3(jnp.zeros(shape), jnp.zeros(shape), jnp.ones(shape)) * jnp.ones(shape))
    return wo, weight, lobe, P, A, Vis, good


def _pdf(p, wi: Vec3, wo: Vec3, key=None):
    """Stochastic estimate of the density (1/sr) of the successful samples of :func:`sample`
    at ``wo``, Huang Eq. 4.33 (Huang 2022), and its standard error.

    P(w_o) = int dh / (2 D_i) sum_p E[A_p / sum_q A_q] p_p(w_o | h, path), written as an
    integral over the visible entry arc (dh = |w_i.n| dl / cos th_i) and evaluated like ``eval``:
    composite Simpson over the entry parameter (``n_intervals``) and, at every node,
    ``n_paths`` random internal paths per lobe (the microfacet where lobe p leaves is fixed by
    ``wo``, the others are drawn; A uses luminance as in the sampler). An unbiased estimate up
    to the Simpson error (not an exact density: the thesis evaluates it the same way), so it
    takes a ``key`` (default: fixed, common random numbers) and returns ``(pdf, stderr)``.
    """
    key = _default_key(key)
    dtype = jnp.result_type(float)
    b = minor_axis(p.eccentricity)
    thi, phii = fiber_angles(wi)
    lo, hi = visible_gamma_interval(thi, phii, p.tilt, b)
    n = p.n_intervals
    t, w = simpson(n)
    us = uniforms(key, (n + 1, p.n_paths), 2 * p.n_lobes, dtype)
    g = lo[..., None, None] + t[:, None] * (hi - lo)[..., None, None]
    wi_, wo_ = _ex(wi), _ex(wo)
    # a leading axis: which lobe's exit is connected to wo (one walk graph for all lobes)
    lobes = jnp.arange(p.n_lobes).reshape((-1,) + (1,) * g.ndim)
    A, _, _, dens = _walk(p, wi_, g[None] + 0.0 * lobes, us, wo_, connect=lobes)
    P = _lobe_probabilities(A)                          # (lobes A, connected lobe, ...)
    x = sum(P[k, k] * dens[k] for k in range(p.n_lobes))
    py, pz = ellipse_point(g, b)
    ny, nz = ellipse_normal(py, pz, b)
    cin = jnp.maximum(wi_.y * ny + wi_.z * nz, 0.0)
    arc = arc_element(g, b)
    x = (x * cin * arc)[..., None]
    ok = jnp.cos(thi) > _TINY
    scale = jnp.where(ok, (hi - lo) / (2.0 * jnp.where(ok, jnp.cos(thi), 1.0) * half_width(p.eccentricity, phii)), 0.0)
    val, se = simpson_mc(x, w[:, None], scale[..., None], p.n_paths)
    return _finite(jnp.maximum(val[..., 0], 0.0)), _finite(se[..., 0])


def _sample(p, wi: Vec3, u_or_key, with_pdf=True, pdf_key=None):
    """Huang's importance sampler (Sec. 4.3.4 [T:1194-1209]; spec seed-001 §1.3.11).

    Offset h uniform over the projected width [-D_i, D_i], microfacets from the visible
    normals at every interface (refract, reflect, ...), lobe p chosen with probability
    P_p = lum(A_p) / sum_q lum(A_q), weight (per band) A_p Vis_p / P_p x D_i / D_o
    (= (A_R + A_TT + A_TRT) x G of the outgoing direction for gray A, no tilt, circle).
    Uniforms, in order: h, lobe, then two per interface (8 for n_lobes = 3, as in the thesis);
    ``u_or_key`` is a PRNG key or that many arrays.

    The weight is unbiased, E[weight delta(w - wo)] = S(wi, w) cos(theta_w) (the model's eval,
    same microfacet semantics), but it is not the ratio S cos / pdf of the exact density:
    neither is available in closed form. ``pdf`` (with ``with_pdf=True``, static) is the
    stochastic Huang Eq. 4.33 estimate :func:`_pdf` at the sampled direction (key ``pdf_key``, by
    default derived from ``u_or_key`` when it is a key; costly: n_lobes x (n_intervals + 1) x
    n_paths paths per sample); ``with_pdf=False`` returns ``None`` in its place. Failed samples
    (invalid path, masked or below the horizon) have weight 0 and pdf 0.
    """
    wo, weight, _, _, _, _, good = _sample_path(p, wi, u_or_key)
    if not with_pdf:
        return wo, weight, None
    if pdf_key is None:
        pdf_key = jax.random.fold_in(u_or_key, 1) if is_prng_key(u_or_key) else _default_key(None)
    pdf, _ = _pdf(p, wi, wo, pdf_key)
    return wo, weight, jnp.where(good, pdf, 0.0)


_sample_path_jit = jax.jit(_sample_path)
