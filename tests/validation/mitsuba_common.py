"""Shared helpers of the Mitsuba 3 cross-checks (imported by the test_mitsuba_* files and
test_export_mitsuba.py). Mitsuba itself is imported inside the functions that need it (the
caller has set the variant)."""

import jax
import jax.numpy as jnp
import numpy as np

from appearance_jax.bcsdf import chiang
from appearance_jax.core.vec import Vec3


def walter_beckmann_g1(w, au, av=None):
    """Walter et al. 2007, Eq. 27: the rational Beckmann G1 that Mitsuba 3 uses.

    ``w`` is an (N, 3) array of directions; the facet-side check is left to the caller.
    Written from the paper (rel. error < 0.35 % against the exact erf form).
    """
    av = au if av is None else av
    a = np.abs(w[:, 2]) / np.sqrt(np.maximum((au * w[:, 0]) ** 2 + (av * w[:, 1]) ** 2, 1e-300))
    return np.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a))


def max_rel_error(ours, ref, tiny):
    """(max relative error where |ref| > tiny * max|ref|, max abs error elsewhere / max|ref|, count)."""
    ours, ref = np.asarray(ours, float), np.asarray(ref, float)
    scale = np.max(np.abs(ref))
    big = np.abs(ref) > tiny * scale
    rel = np.max(np.abs(ours[big] - ref[big]) / np.abs(ref[big]))
    tiny_abs = np.max(np.abs(ours[~big] - ref[~big]), initial=0.0) / scale
    return rel, tiny_abs, int(big.sum())


def as_vec3(a):
    """(N, 3) rows -> float64 Vec3 (our side of a comparison runs in float64)."""
    from appearance_jax.core.vec import Vec3

    return Vec3.from_array(np.asarray(a, dtype=np.float64))


def reflection_pairs(rng, n, au, av):
    """Half uniform pairs, half near the specular peak (mirror about a jittered normal)."""
    wi = rng.normal(size=(n, 3))
    wi[:, 2] = np.abs(wi[:, 2])
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo = rng.normal(size=(n, 3))
    wo[:, 2] = np.abs(wo[:, 2])
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    half = n // 2
    h = np.stack([au * rng.normal(size=half), av * rng.normal(size=half), np.ones(half)], axis=1)
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    spec = 2 * np.sum(wi[:half] * h, axis=1, keepdims=True) * h - wi[:half]
    ok = spec[:, 2] > 1e-3
    wo[:half][ok] = spec[ok]
    return wi.astype(np.float32), wo.astype(np.float32)


def dielectric_pairs(rng, n, au, av, eta):
    """A third uniform pairs over the sphere, a third near the specular reflection, a third
    near the refraction (about a jittered microfacet normal); wi on both sides."""
    wi = rng.normal(size=(n, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo = rng.normal(size=(n, 3))
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    h = np.stack([au * rng.normal(size=n), av * rng.normal(size=n), np.ones(n)], axis=1)
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    h *= np.sign(wi[:, 2:3])  # the normal on wi's side
    c = np.sum(wi * h, axis=1, keepdims=True)
    refl = 2 * c * h - wi
    e = np.where(wi[:, 2:3] > 0, 1.0 / eta, eta)  # eta_i / eta_t seen from wi
    s2 = e * e * (1 - c * c)
    tir = s2 >= 1
    ct = np.sqrt(np.maximum(1 - s2, 0.0))
    refr = -e * wi + (e * c - ct) * h
    third = n // 3
    sel_r = np.zeros(n, bool)
    sel_r[third:2 * third] = True
    sel_t = np.zeros(n, bool)
    sel_t[2 * third:] = True
    ok_r = sel_r & (refl[:, 2] * wi[:, 2] > 1e-3)
    ok_t = sel_t & ~tir[:, 0] & (refr[:, 2] * wi[:, 2] < -1e-3)
    wo[ok_r] = refl[ok_r]
    wo[ok_t] = refr[ok_t]
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    return wi.astype(np.float32), wo.astype(np.float32)


def mi_eval_pdf(bsdf, wi, wo, ctx=None, to_mitsuba=None):
    """Mitsuba's eval (f |cos theta_o|, (N, 3)) and pdf (N,) at (N, 3) direction pairs, one call per
    pair; ``ctx`` defaults to ``BSDFContext()`` (radiance), ``to_mitsuba`` maps a row to a Vector3f."""
    import mitsuba as mi

    ctx = mi.BSDFContext() if ctx is None else ctx
    vec = (lambda w: mi.Vector3f(*w)) if to_mitsuba is None else to_mitsuba
    si = mi.SurfaceInteraction3f()
    f = np.zeros((len(wi), 3))
    pdf = np.zeros(len(wi))
    for k in range(len(wi)):
        si.wi = vec(wi[k])
        v = vec(wo[k])
        f[k] = np.array(bsdf.eval(ctx, si, v))
        pdf[k] = bsdf.pdf(ctx, si, v)
    return f, pdf


# ---- chiang_hair against Mitsuba's hair plugin (conventions: test_mitsuba_hair.py)

# Mitsuba 3's (and pbrt's) luminance() weights, which its hair sampler uses to choose a lobe; the
# library uses core.spectral.LUMINANCE_WEIGHTS (exact sRGB, up to 3e-5 different)
MITSUBA_LUMINANCE = (0.212671, 0.715160, 0.072169)


def mitsuba_i0(x):
    """Mitsuba's / pbrt's 10-term power series of I0."""
    res, x2 = np.ones_like(x), x * x
    xi, den = x2.copy(), 4.0
    for i in range(1, 11):
        res = res + xi / den
        xi = xi * x2
        den = den * 4.0 * (i + 1.0) ** 2
    return res


def mitsuba_log_i0(x):
    big = x > 12.0
    xs = np.where(big, x, 1.0)
    return np.where(big, xs + 0.5 * (np.log(1.0 / (2 * np.pi * xs)) + 1.0 / (8.0 * xs)), np.log(mitsuba_i0(x)))


def mitsuba_hair_mp(theta_i, theta_o, v):
    """Mitsuba's longitudinal lobe times 2 pi (float64), with its I0 approximations."""
    k = 1.0 / v
    c = np.sin(theta_i) * np.sin(theta_o) * k
    s = np.cos(theta_i) * np.cos(theta_o) * k
    with np.errstate(over="ignore"):
        small = np.exp(-c) * mitsuba_i0(s) * k / (2.0 * np.sinh(np.minimum(k, 700.0)))
    large = np.exp(-c + mitsuba_log_i0(s) - k + 0.6931 + np.log(k / 2.0))
    return np.where(k > 10.0, large, small)


def hair_to_mitsuba(w):
    """Our direction (x = fiber tangent) as a Mitsuba vector in its hair frame (y = tangent)."""
    import mitsuba as mi

    return mi.Vector3f(float(w[1]), float(w[0]), float(w[2]))


def hair_front(wi):
    """Unit wi on the front side, away from the silhouette: wi.z >= 0.05 |(wi.y, wi.z)|
    (|h| <= 0.9987; module docstring)."""
    wi = wi / np.linalg.norm(wi, axis=1, keepdims=True)
    wi[:, 2] = np.maximum(np.abs(wi[:, 2]), 0.05 * np.abs(wi[:, 1]))
    return wi / np.linalg.norm(wi, axis=1, keepdims=True)


def hair_pairs(rng, params, n):
    """wi uniform on the front hemisphere z > 0; wo: a third uniform, two thirds from our sampler at h(wi)."""
    wi = rng.normal(size=(n, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wi = hair_front(wi)
    wo = rng.normal(size=(n, 3))
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    Wi = Vec3(*(jnp.asarray(c) for c in wi.T))
    ws, _, pdf = chiang.sample(params, Wi, jax.random.key(int(rng.integers(1 << 30))),
                               h=chiang.offset_from_normal(Wi))
    ws = np.stack([np.asarray(c) for c in ws], axis=1)
    use = (np.arange(n) % 3 != 0) & (np.asarray(pdf) > 0)
    wo[use] = ws[use]
    return wi.astype(np.float32), wo.astype(np.float32)


def mitsuba_offset(wi):
    """h = sin(gamma_i) as Mitsuba computes it, in float32 (module docstring)."""
    x, z = wi[:, 1].astype(np.float32), wi[:, 2].astype(np.float32)  # Mitsuba's x, z
    r = np.sqrt(x * x + z * z)
    g = np.arccos(np.clip(z / np.where(r > 0, r, np.float32(1)), -1, 1)).astype(np.float32)
    g = np.where(r > 0, g, np.float32(0))
    return np.sin(np.where(x < 0, g, -g)).astype(np.float32).astype(np.float64)


def hair_ours(params, wi, wo):
    """Our S cos(theta_o), pdf, and the same with Mitsuba's I0 approximations (float64)."""
    Wi = Vec3(*(jnp.asarray(c, dtype=jnp.float64) for c in wi.T))
    Wo = Vec3(*(jnp.asarray(c, dtype=jnp.float64) for c in wo.T))
    h = jnp.asarray(mitsuba_offset(wi))
    # the same h as chiang.offset_from_normal up to Mitsuba's float32 acos near gamma = 0
    assert np.max(np.abs(h - np.asarray(chiang.offset_from_normal(Wi)))) < 1e-3
    S = np.asarray(chiang.eval(params, Wi, Wo, h=h))
    pdf = np.asarray(chiang.pdf(params, Wi, Wo, h=h))
    A, M, N = (np.asarray(a) for a in chiang.lobes(params, Wi, Wo, h=h))
    theta_i = np.arcsin(np.clip(wi[:, 0].astype(float), -1, 1))
    theta_o = np.arcsin(np.clip(wo[:, 0].astype(float), -1, 1))
    ti_p = np.asarray(chiang.tilted_angles(jnp.asarray(theta_i), params.alpha))
    v = np.stack([np.broadcast_to(np.asarray(x), theta_i.shape) for x in chiang.longitudinal_variances(params.beta_m)])
    ratio = np.where(M > 0, mitsuba_hair_mp(ti_p, theta_o[None], v) / np.where(M > 0, M, 1.0), 1.0)
    cos_o = np.sqrt(np.maximum(1 - wo[:, 0].astype(float) ** 2, 0))
    f_corr = np.sum(A * (M * ratio * N)[..., None], axis=0)
    lum = A @ np.asarray(MITSUBA_LUMINANCE)
    pdf_corr = np.sum(lum / lum.sum(0) * M * ratio * N, axis=0)
    return S * cos_o[:, None], pdf, f_corr, pdf_corr, A


def mitsuba_beckmann_g1_ratio(w, au, av=None):
    """Per direction, Mitsuba's rational Beckmann G1 over our exact one (Smith factor about the
    geometric normal): multiply our Beckmann values by it once per G1 factor."""
    from appearance_jax.microfacet import distribution as md

    av = au if av is None else av
    w = np.asarray(w, dtype=np.float64)
    n = Vec3(jnp.zeros(len(w)), jnp.zeros(len(w)), jnp.ones(len(w)))
    return walter_beckmann_g1(w, au, av) / np.asarray(md.G1("beckmann", as_vec3(w), n, au, av))
