"""chiang_hair against Mitsuba 3's ``hair`` BSDF (scalar_rgb variant), pointwise.

Convention mapping (checked here):
- Frames: Mitsuba's hair plugin works in the shading frame with **y = fiber tangent**
  (sin theta = w.y) and azimuth phi = atan2(w.z, w.x); z is the shading normal at the hit.
  Ours has x = tangent, phi = atan2(w.z, w.y). So a direction w (ours) is
  (w.y, w.x, w.z) in Mitsuba's frame: theta and phi are the same numbers on both sides.
- Offset h: Mitsuba takes no h from the intersection; it derives it from ``si.wi`` as
  h = sin(gamma_i) with gamma_i the angle between the normal z and wi projected into the normal
  plane, signed so that h = -x_M / sqrt(x_M^2 + z_M^2). In our frame that is
  :func:`chiang.offset_from_normal` (wi) = -wi.y / sqrt(wi.y^2 + wi.z^2) (the R lobe is then
  centred on the mirror direction about +z). We pass that h explicitly (near field); the far
  field (``Params(far_field=True)``) is not what Mitsuba computes and is not compared here.
  Only wi on the front side (wi.z > 0, the normal faces the incoming ray) is a geometric hit:
  for wi.z < 0 Mitsuba uses gamma_i = acos(...) beyond pi/2 (an impossible hit) in
  Phi = 2p gamma_t - 2 gamma_i + p pi, which no h in [-1, 1] reproduces; wi is drawn with
  wi.z > 0 (wo anywhere on the sphere). At the silhouette (|h| -> 1) Mitsuba's float32
  h = sin(gamma_i) rounds to 1 while it keeps gamma_i itself for Phi, so our asin(h) and its
  gamma_i part by up to ~1e-5 rad where dPhi/dh is unbounded (3e-4 relative seen at
  wi.z = 7e-6): wi is drawn with wi.z >= 0.05 |(wi.y, wi.z)| (|h| <= 0.9987). We use h
  computed as Mitsuba does (float32 acos, :func:`mitsuba_offset`): near h = 0 its float32
  acos(z/r) is off by up to ~3e-4 rad, which alone gives 3e-4 relative differences.
- Roles and cosines: Mitsuba's ``eval(ctx, si, wo)`` with ``si.wi`` = our wi returns
  sum_p A_p M_p N_p = our S(wi, wo) cos(theta_o) (its BSDF values carry the projection cosine;
  our S carries 1/cos(theta_o) so that int S cos(theta_o) dwo = sum A_p). wi is the given
  direction (it fixes h, A_p and the tilt). ``pdf`` is the same solid-angle density as ours
  (lobe choice by Rec. 709 luminance of A_p). ``sample`` returns weight = eval / pdf = our
  S cos(theta_o) / pdf.
- Parameters: ``int_ior`` = eta with ``ext_ior`` = 1 (Mitsuba's default exterior is air,
  1.000277), ``scale_tilt`` in degrees = alpha, ``longitudinal_roughness`` = beta_m,
  ``azimuthal_roughness`` = beta_n, ``eumelanin``/``pheomelanin`` with the same RGB
  coefficients as :func:`fiber.melanin_sigma_a_rgb`.
- Mitsuba's M_p uses approximations of I0 (a 10-term power series for arguments <= 12, and
  log I0(x) ~ x + (log(1/(2 pi x)) + 1/(8x))/2 beyond; ln 2 written as 0.6931) that are off by
  up to ~0.6 % where kappa cos(theta_i) cos(theta_o) is near 10-12; ours is exact (I0e). As in
  the Beckmann-G1 case of test_mitsuba_rough_dielectric, each of our lobes is multiplied by
  the ratio (Mitsuba's approximate M_p) / (exact M_p), computed here in float64 from the same
  formulas, and the uncorrected difference is checked to stay below 1 %.

Error metric (tests/validation/mitsuba_common.py): max |ours - mitsuba| / |mitsuba| over the
pairs whose Mitsuba value is >= 1e-3 x the batch maximum; the tiny ones must agree to 1e-6 x the
maximum absolutely. Directions are rounded to float32 (Mitsuba's precision) before both
evaluations; ours run in float64. Tolerance 1e-4 for the rough settings; 2e-4 where the
longitudinal lobe is narrow (beta_m = 0.1: kappa_TT ~ 600, so float32 rounding of the exponent
-kappa (1 - cos(theta_i + theta_o)) alone is ~4e-5).

Sampling: with the same uniforms (Mitsuba's ``sample1`` picks the lobe and, rescaled, the
azimuth; ``sample2`` drives the longitudinal lobe) our sampler returns the same directions;
at Mitsuba's sampled directions our pdf and weight equal Mitsuba's.
"""

import zlib

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba")
mi.set_variant("scalar_rgb")

import jax.numpy as jnp  # noqa: E402

from appearance_jax.bcsdf import chiang  # noqa: E402
from appearance_jax.core.vec import Vec3  # noqa: E402
from mitsuba_common import (  # noqa: E402
    MITSUBA_LUMINANCE, hair_front, hair_ours, hair_pairs, hair_to_mitsuba, max_rel_error, mitsuba_offset)

N_PAIRS = 1200
TINY = 1e-3

CONFIGS = [
    # name, beta_m, beta_n, alpha (deg), eumelanin, pheomelanin, rel tol
    ("brown", 0.3, 0.3, 2.0, 1.3, 0.0, 1e-4),
    ("blond_tilt", 0.1, 0.2, 3.0, 0.3, 0.1, 2e-4),
    ("black_rough", 0.6, 0.8, 2.0, 8.0, 0.0, 1e-4),
    ("white_tilt", 0.25, 0.4, -4.0, 0.0, 0.0, 1e-4),
]

@pytest.mark.parametrize("cfg", CONFIGS, ids=[c[0] for c in CONFIGS])
def test_eval_pdf_sample_match_mitsuba(cfg):
    name, bm, bn, alpha_deg, eu, pheo, tol = cfg
    rng = np.random.default_rng(zlib.crc32(repr(cfg).encode()))
    params = chiang.Params.from_melanin(eu, pheo, beta_m=bm, beta_n=bn, alpha=np.radians(alpha_deg))
    bsdf = mi.load_dict({"type": "hair", "eumelanin": eu, "pheomelanin": pheo, "int_ior": 1.55, "ext_ior": 1.0,
                         "longitudinal_roughness": bm, "azimuthal_roughness": bn, "scale_tilt": alpha_deg})
    wi, wo = hair_pairs(rng, params, N_PAIRS)
    ctx = mi.BSDFContext()
    si = mi.SurfaceInteraction3f()
    f_mi = np.zeros((N_PAIRS, 3))
    p_mi = np.zeros(N_PAIRS)
    for j in range(N_PAIRS):
        si.wi = hair_to_mitsuba(wi[j])
        b = hair_to_mitsuba(wo[j])
        f_mi[j] = np.array(bsdf.eval(ctx, si, b))
        p_mi[j] = bsdf.pdf(ctx, si, b)

    f, pdf, f_corr, pdf_corr, _ = hair_ours(params, wi, wo)
    out = {
        "eval": max_rel_error(f_corr, f_mi, TINY),
        "pdf": max_rel_error(pdf_corr, p_mi, TINY),
        "eval_uncorrected": max_rel_error(f, f_mi, TINY),
        "pdf_uncorrected": max_rel_error(pdf, p_mi, TINY),
    }
    print(f"\n{name}: " + ", ".join(f"{k} {v[0]:.2e} ({v[2]})" for k, v in out.items()))
    for key in ("eval", "pdf"):
        rel, tiny_abs, count = out[key]
        assert count > 300, key
        assert rel < tol, (key, rel)
        assert tiny_abs < 1e-6, (key, tiny_abs)
    assert out["eval_uncorrected"][0] < 1e-2 and out["pdf_uncorrected"][0] < 1e-2


def _repeat(a):
    """``a`` (n, ...) repeated along its first axis to N_PAIRS rows (n <= N_PAIRS)."""
    return np.resize(a, (N_PAIRS,) + a.shape[1:])


@pytest.mark.parametrize("cfg", CONFIGS[:3], ids=[c[0] for c in CONFIGS[:3]])
def test_sampling_matches_mitsuba(cfg):
    """Same uniforms -> same directions; at Mitsuba's samples, our pdf and weight equal its."""
    name, bm, bn, alpha_deg, eu, pheo, tol = cfg
    n = 400
    rng = np.random.default_rng(zlib.crc32(repr(cfg).encode()) + 1)
    params = chiang.Params.from_melanin(eu, pheo, beta_m=bm, beta_n=bn, alpha=np.radians(alpha_deg))
    bsdf = mi.load_dict({"type": "hair", "eumelanin": eu, "pheomelanin": pheo, "int_ior": 1.55, "ext_ior": 1.0,
                         "longitudinal_roughness": bm, "azimuthal_roughness": bn, "scale_tilt": alpha_deg})
    wi = rng.normal(size=(n, 3))
    wi = hair_front(wi).astype(np.float32)
    u = rng.uniform(size=(n, 3)).astype(np.float32)
    ctx = mi.BSDFContext()
    si = mi.SurfaceInteraction3f()
    wo_mi = np.zeros((n, 3))
    p_mi = np.zeros(n)
    w_mi = np.zeros((n, 3))
    for j in range(n):
        si.wi = hair_to_mitsuba(wi[j])
        bs, w = bsdf.sample(ctx, si, float(u[j, 0]), mi.Point2f(float(u[j, 1]), float(u[j, 2])))
        wo_mi[j] = [bs.wo[1], bs.wo[0], bs.wo[2]]  # back to our frame
        p_mi[j] = bs.pdf
        w_mi[j] = np.array(w)
    wo32 = wo_mi.astype(np.float32)
    # ours on the n pairs repeated to N_PAIRS: the compiled programs of the eval test (one shape)
    f, pdf, f_corr, pdf_corr, A = hair_ours(params, _repeat(wi), _repeat(wo32))
    f, pdf, f_corr, pdf_corr, A = f[:n], pdf[:n], f_corr[:n], pdf_corr[:n], A[:, :n]
    ok = p_mi > 0
    assert ok.mean() > 0.99
    rel_pdf = np.abs(pdf_corr[ok] - p_mi[ok]) / p_mi[ok]
    w_ours = f_corr[ok] / pdf_corr[ok, None]
    rel_w = np.abs(w_ours - w_mi[ok]) / np.maximum(np.abs(w_mi[ok]), 1e-3 * np.abs(w_mi).max())

    # our sampler driven by Mitsuba's uniforms: lobe from u0, the azimuth from u0 rescaled
    # within the chosen lobe's interval (Mitsuba's reuse), the longitudinal lobe from u1, u2
    lum = A @ np.asarray(MITSUBA_LUMINANCE)  # A of (wi, anything): depends on wi only
    P = lum / lum.sum(0)
    C = np.cumsum(P, axis=0)
    u0 = u[:, 0].astype(float)
    lobe = np.sum(u0[None] >= C[:3], axis=0)
    lo = np.where(lobe > 0, np.take_along_axis(C, np.maximum(lobe - 1, 0)[None], 0)[0], 0.0)
    u_phi = (u0 - lo) / np.take_along_axis(P, lobe[None], 0)[0]
    uu = (u0, u[:, 1].astype(float), u[:, 2].astype(float), np.clip(u_phi, 0, 1 - 1e-12), np.zeros(n))
    Wi = Vec3(*(jnp.asarray(_repeat(c)) for c in wi.T.astype(np.float64)))  # N_PAIRS, as above
    ws, _, _ = chiang.sample(params, Wi, tuple(jnp.asarray(_repeat(a)) for a in uu),
                             h=jnp.asarray(mitsuba_offset(_repeat(wi))))
    ws = np.stack([np.asarray(c)[:n] for c in ws], axis=1)
    ang = np.arccos(np.clip(np.sum(ws * wo_mi, axis=1), -1, 1))
    # away from a lobe boundary (where float32 rounding of u0 may pick the neighbour lobe)
    # and not the residual lobe: Mitsuba 3.9's sampler leaves its tilted sin/cos(theta_i) at 0
    # for p = 3, so its residual samples all have theta_o = 0 (while its pdf uses M_3)
    margin = (np.min(np.abs(u0[None] - C[:3]), axis=0) > 1e-5) & (lobe < 3)
    resid = lobe == 3
    print(f"\n{name}: {resid.sum()} residual-lobe samples, Mitsuba's max |sin theta_o| there: "
          f"{np.abs(wo_mi[resid, 0]).max(initial=0):.1e}")
    print(f"\n{name}: sampled pdf rel err {rel_pdf.max():.2e}, weight rel err {rel_w.max():.2e}, "
          f"direction max angle {np.degrees(ang[margin]).max():.2e} deg, median {np.degrees(np.median(ang)):.1e}")
    assert rel_pdf.max() < 5 * tol
    assert rel_w.max() < 5 * tol
    assert np.quantile(ang[margin], 0.99) < 1e-3 and margin.mean() > 0.9
