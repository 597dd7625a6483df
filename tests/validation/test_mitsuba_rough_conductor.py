"""rough_conductor against Mitsuba 3's ``roughconductor`` (scalar_rgb variant).

Convention mapping (checked here):
- Mitsuba's ``eval`` returns f |cos theta_o|; ours returns f. Reflection is symmetric, so
  Mitsuba's ``si.wi`` is our wi and its ``wo`` our wo.
- Mitsuba's Smith G is separable: ``shadowing="separable"``; ``alpha_u``/``alpha_v`` are
  our ``alpha``/``alpha_v``; ``sample_visible=True`` (its default) is our sampler, so its
  ``pdf`` is our ``pdf``.
- Mitsuba's Beckmann G1 is Walter et al.'s (2007, Eq. 27) rational approximation
  (3.535 a + 2.181 a^2) / (1 + 2.276 a + 2.577 a^2) for a < 1.6, else 1 (rel. error
  < 0.35%); we use the exact erf form. For Beckmann the comparison multiplies our values by
  the ratio approximate/exact of the G1 factors (written out below), so that everything
  else is compared at 1e-4; the uncorrected difference is checked to be < 1%.

Error metric: relative error max |ours - mitsuba| / |mitsuba| over all entries (pairs x
bands) whose Mitsuba value is not tiny, tiny meaning < 1e-3 x the maximum over the batch;
the tiny entries must agree to 1e-6 x that maximum in absolute terms. Mitsuba computes in
float32, so the directions are rounded to float32 before both evaluations.
"""

import zlib

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba")
mi.set_variant("scalar_rgb")

import jax.numpy as jnp  # noqa: E402

from appearance_jax.bsdf import rough_conductor as rc  # noqa: E402
from appearance_jax.core.vec import Vec3  # noqa: E402
from appearance_jax.microfacet import distribution as md  # noqa: E402
from mitsuba_common import as_vec3, max_rel_error, reflection_pairs, walter_beckmann_g1  # noqa: E402

N_PAIRS = 1200
REL_TOL = 1e-4
TINY = 1e-3

GOLD = (rc.AU_ETA_RGB, rc.AU_K_RGB)
COPPERISH = ((0.27, 1.12, 1.25), (3.4, 2.6, 2.4))

CONFIGS = [
    # distribution, alpha_u, alpha_v, (eta, k), specular_reflectance
    ("ggx", 0.1, 0.1, GOLD, (1.0, 1.0, 1.0)),
    ("ggx", 0.3, 0.6, COPPERISH, (0.9, 0.8, 1.0)),
    ("ggx", 0.02, 0.05, GOLD, (1.0, 1.0, 1.0)),
    ("beckmann", 0.2, 0.2, GOLD, (1.0, 1.0, 1.0)),
    ("beckmann", 0.1, 0.4, COPPERISH, (1.0, 0.7, 0.5)),
    ("beckmann", 0.8, 0.8, GOLD, (1.0, 1.0, 1.0)),
]

@pytest.mark.parametrize("cfg", CONFIGS, ids=[f"{c[0]}-{c[1]}-{c[2]}" for c in CONFIGS])
def test_eval_and_pdf_match_mitsuba(cfg):
    dist, au, av, (eta, k), spec = cfg
    rng = np.random.default_rng(zlib.crc32(repr(cfg).encode()))  # fixed per configuration
    wi, wo = reflection_pairs(rng, N_PAIRS, au, av)
    bsdf = mi.load_dict({
        "type": "roughconductor", "distribution": dist, "alpha_u": au, "alpha_v": av,
        "eta": {"type": "rgb", "value": list(eta)}, "k": {"type": "rgb", "value": list(k)},
        "specular_reflectance": {"type": "rgb", "value": list(spec)},
    })
    ctx = mi.BSDFContext()
    si = mi.SurfaceInteraction3f()
    f_mi = np.zeros((N_PAIRS, 3))
    p_mi = np.zeros(N_PAIRS)
    for j in range(N_PAIRS):
        si.wi = mi.Vector3f(*wi[j])
        w = mi.Vector3f(*wo[j])
        f_mi[j] = np.array(bsdf.eval(ctx, si, w))
        p_mi[j] = bsdf.pdf(ctx, si, w)

    p = rc.Params(alpha=au, alpha_v=av, eta=eta, k=k, specular_reflectance=spec, distribution=dist,
                  shadowing="separable")
    Wi, Wo = as_vec3(wi), as_vec3(wo)
    f = np.asarray(rc.eval(p, Wi, Wo)) * wo[:, 2:3].astype(np.float64)
    pdf = np.asarray(rc.pdf(p, Wi, Wo))
    if dist == "beckmann":
        n = Vec3(jnp.zeros(N_PAIRS), jnp.zeros(N_PAIRS), jnp.ones(N_PAIRS))
        g1i = np.asarray(md.G1("beckmann", Wi, n, au, av))
        g1o = np.asarray(md.G1("beckmann", Wo, n, au, av))
        ci = walter_beckmann_g1(wi.astype(float), au, av) / g1i
        co = walter_beckmann_g1(wo.astype(float), au, av) / g1o
        raw_rel, _, _ = max_rel_error(f, f_mi, TINY)
        assert raw_rel < 1e-2  # the approximation's own error, < 0.35% per G1 factor
        f = f * (ci * co)[:, None]
        pdf = pdf * ci

    rel_f, tiny_f, nf = max_rel_error(f, f_mi, TINY)
    rel_p, tiny_p, npdf = max_rel_error(pdf, p_mi, TINY)
    print(f"\n{dist} au={au} av={av}: max rel err f {rel_f:.2e} ({nf} entries), pdf {rel_p:.2e} ({npdf})")
    assert nf > 300 and npdf > 100  # the lobe was actually sampled
    assert rel_f < REL_TOL and rel_p < REL_TOL
    assert tiny_f < 1e-6 and tiny_p < 1e-6
