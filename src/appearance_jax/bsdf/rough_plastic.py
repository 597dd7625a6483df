"""Rough plastic: a rough dielectric coat over a Lambertian base (Mitsuba 3's ``roughplastic``).

The coat is a single rough interface (relative index ``eta`` = eta_coat / eta_exterior,
microfacet roughness ``alpha``) on top of a diffuse base of albedo rho, with no absorption
in between. For wi, wo both above the surface (else 0):

    f(wi, wo) = f_spec + f_diff

    f_spec = k_s F(wi.h; eta) D(h) G2(wi, wo, h) / (4 cos theta_i cos theta_o),     h = (wi + wo)/|wi + wo|

    f_diff = rho / (1 - r R_int) * T(cos theta_i) T(cos theta_o) / (pi eta^2),      r = 1 (linear) or rho (nonlinear)

f_spec is the Cook-Torrance / Walter et al. (2007, Eq. 20) microfacet reflection of the
coat. f_diff is the light that enters through the rough interface, is reflected by the
base, bounces between base and coat (the geometric series 1 / (1 - rho R_int) of Williams &
Clapper 1953, "Multiple internal reflections in photographic color prints", JOSA 43; with
``nonlinear=False`` Mitsuba drops the rho of the series so that the base colour is
preserved as given) and leaves through the interface; 1/eta^2 is the change of radiance on
leaving the denser coat (L / n^2 is invariant along a refracted ray) (Williams & Clapper;
Jakob, Mitsuba documentation of ``plastic``/``roughplastic``). T(mu) is the coat's
external transmittance and R_int the cosine average of its reflectance seen from inside,
single-scattering integrals over the visible normals with the separable Smith G1, as in
Mitsuba (:mod:`appearance_jax.microfacet.interface_integrals`): light masked by the
microsurface is lost, so the albedo is < 1 even for a white base (about 0.55 at
alpha = 0.5). Both depend only on (alpha, eta, distribution): once per parameter set
(:func:`coat_tables`; differentiable in alpha and eta, float32 or float64) they give T as
64 Chebyshev coefficients in sqrt(mu) (or Mitsuba's 64 node values), then looked up per
direction. Spatially varying alpha / eta (leading axes) cost one set of tables per element.

``tables`` chooses how T(mu) and R_int are obtained:

- ``"precomputed"`` (default): the ``"accurate"`` integrals, computed once by this
  project's quadrature on a grid over (ln alpha, eta) and shipped with the package
  (:mod:`appearance_jax.microfacet.coat_tables`), interpolated by a cubic B-spline (C2 in
  alpha and eta). Measured error against ``"accurate"``: <= 8e-5 absolute for T(mu) and
  R_int over the whole parameter range; their derivatives w.r.t. alpha and eta within
  6e-3 absolute (of derivatives up to ~14) for eta >= 1.01 and alpha >= 0.01, less close in
  the corner eta -> 1, alpha -> 1e-3 where T changes on the scale eta - 1 ~ alpha^2
  (docs/microfacet.md). Cost: a 4 x 4 spline lookup per parameter set, then a linear
  lookup in sqrt(mu) per direction.
- ``"accurate"``: the quadrature inside the jitted function (~5e5 integrand evaluations
  per parameter set): T is a Chebyshev interpolant on 64 nodes in sqrt(mu), R_int a
  Gauss-Legendre integral over mu split at the critical cosine.
- ``"mitsuba"``: Mitsuba 3's discretisation (T linear in mu between 64 equispaced nodes,
  R_int an equal-weight mean over them, about 1% low), by the same quadrature; use it to
  reproduce Mitsuba.

Sampling (as Mitsuba): the specular lobe (visible normals of wi, then mirror) with
probability P_s = (1 - T_i) w_s / ((1 - T_i) w_s + T_i (1 - w_s)), w_s = mean(k_s) /
(mean(rho) + mean(k_s)), else the cosine-weighted hemisphere;
pdf = P_s D(h) G1(wi, h) / (4 cos theta_i) + (1 - P_s) cos theta_o / pi. ``sample`` takes a
PRNG key or 3 uniform arrays (lobe choice, then two for the direction).

| parameter            | default       | range                          | unit | meaning                                      |
|----------------------|---------------|--------------------------------|------|----------------------------------------------|
| alpha                | 0.1           | [1e-3, 2]                      | 1    | coat roughness (isotropic)                   |
| diffuse_reflectance  | 0.5           | [0, 1]                         | 1    | albedo rho of the base, per band             |
| specular_reflectance | 1             | [0, 1]                         | 1    | scale k_s of the coat reflection, per band   |
| eta                  | 1.5           | [1, 3]                         | 1    | relative index eta_coat / eta_exterior       |
| distribution         | "ggx"         | ggx, beckmann                  | -    | microfacet normal distribution               |
| nonlinear            | False         | False, True                    | -    | tint every internal bounce (r = rho)         |
| shadowing            | "correlated"  | correlated, separable          | -    | Smith G2 of the specular lobe                |
| tables               | "precomputed" | precomputed, accurate, mitsuba | -    | how T(mu) and R_int are obtained (see above) |

Range of eta: 1 (index-matched coat: no specular lobe, T = G1, R_int = 0, the limit of a
bare rough diffuse base) to 3 (beyond rutile TiO2, n ~ 2.6-2.9, the densest coating
materials); below 1 the coat would be optically thinner than the exterior, which is not
the layered "plastic" configuration (total internal reflection on entry). Roughness range
as ``rough_conductor``: below 1e-3 use a smooth coat; above 2 the microsurface model is
far outside measured materials. Output bands: those of diffuse_reflectance and
specular_reflectance (broadcast).

Differences from Mitsuba 3's ``roughplastic``: its default distribution is ``beckmann``
(here ``ggx``), its Smith G is separable (``shadowing="separable"``; here height-correlated
by default; the coat integrals always use the separable form, as Mitsuba), its Beckmann
G1 is Walter's rational approximation (rel. error < 0.35%; here the exact erf form), its
default ``int_ior`` is polypropylene 1.49 over air 1.000277 (eta 1.48959; here 1.5), its
discretisation of the coat integrals is ``tables="mitsuba"``, and its ``eval`` returns
f cos theta_o.

Measured accuracy of the coat tables, the quadrature's design and cost: docs/microfacet.md.

Example::

    from appearance_jax.bsdf import rough_plastic
    from appearance_jax.core.frame import spherical_direction
    p = rough_plastic.Params(alpha=0.2, diffuse_reflectance=(0.8, 0.1, 0.1))
    wi = spherical_direction(0.3, 0.0); wo = spherical_direction(0.5, 2.0)
    f = rough_plastic.eval(p, wi, wo)                       # shape (3,), 1/sr
    tab = rough_plastic.coat_tables(p)                      # T at the nodes, R_int
"""

from __future__ import annotations

import jax.numpy as jnp

from ..core import warp
from ..core.frame import reflect
from ..core.fusion import materialize
from ..core.model import Model, as_bands, boundary, with_bands
from ..core.params import Bands, param, params_class, Real, static
from ..core.rng import uniforms
from ..core.vec import Vec3, dot, normalize
from ..microfacet import coat_tables as ct
from ..microfacet import distribution as md
from ..microfacet.coat_tables import TABLES
from ..microfacet.interface_integrals import CoatTables
from ..optics.fresnel import fresnel_dielectric_terms


@params_class
class Params:
    alpha: Real = param(0.1, lo=1e-3, hi=2.0, unit="1", doc="coat roughness (isotropic)")
    diffuse_reflectance: Bands = param(0.5, lo=0.0, hi=1.0, unit="1", doc="albedo of the diffuse base", bands=True)
    specular_reflectance: Bands = param(1.0, lo=0.0, hi=1.0, unit="1", doc="scale of the coat reflection", bands=True)
    eta: Real = param(1.5, lo=1.0, hi=3.0, unit="1", doc="relative index eta_coat / eta_exterior")
    distribution: str = static("ggx", choices=md.KINDS, doc="microfacet normal distribution")
    nonlinear: bool = static(False, choices=(False, True), doc="tint every internal bounce by the base albedo")
    shadowing: str = static("correlated", choices=("correlated", "separable"), doc="Smith G2 of the specular lobe")
    tables: str = static("precomputed", choices=TABLES, doc="how the coat integrals T(mu), R_int are obtained")


def _tables(p: Params) -> CoatTables:
    return ct.tabulate(p.distribution, p.alpha, p.eta, p.tables)


def coat_tables(p: Params) -> CoatTables:
    """The coat integrals of ``p`` (validated, jitted): T at the scheme's nodes and R_int."""
    return _coat_tables_public(p)


def _transmittance_at(p: Params, tab: CoatTables, mu):
    """T(mu) from the tables, for mu in [0, 1] (any shape broadcasting with the params)."""
    return ct.transmittance_at(p.tables, tab, mu)


# ----------------------------------------------------------------------------------------
# the BRDF


def _active(wi: Vec3, wo: Vec3):
    return (wi.z > 0) & (wo.z > 0)


def _specular_weight(p: Params):
    """w_s = mean(k_s) / (mean(rho) + mean(k_s)) over the bands (Mitsuba's steering weight)."""
    ks = jnp.mean(as_bands(p.specular_reflectance), axis=-1)
    kd = jnp.mean(as_bands(p.diffuse_reflectance), axis=-1)
    tot = ks + kd
    ok = tot > 0
    return jnp.where(ok, ks / jnp.where(ok, tot, 1.0), 0.5)


def _lobe_probability(p: Params, T_i):
    """P_s: probability of sampling the specular lobe (Mitsuba's roughplastic)."""
    ws = _specular_weight(p)
    ps = (1.0 - T_i) * ws
    pd = T_i * (1.0 - ws)
    tot = ps + pd
    ok = tot > 0
    return jnp.where(ok, ps / jnp.where(ok, tot, 1.0), 0.5)


def _eval_with(p: Params, tab: CoatTables, wi: Vec3, wo: Vec3):
    """f(wi, wo) given the coat tables (used by eval/sample, and by tests to inject tables)."""
    kind, alpha, eta = p.distribution, jnp.asarray(p.alpha), jnp.asarray(p.eta)
    active = _active(wi, wo)
    h = normalize(wi + wo)
    # F D G2 / (4 cos_i cos_o) as one quotient: F, D and G2 / (cos_i cos_o) are fractions whose
    # denominators multiply into one division per pair (as rough_dielectric; issue 20)
    r, _, d = fresnel_dielectric_terms(jnp.clip(dot(wi, h), 0.0, 1.0), eta)
    d_num, d_den = md.D_terms(kind, h, alpha)
    # reflection only: no transmission branch (its Beta function would be computed and discarded)
    g_num, g_den = md.G2_terms(kind, wi, wo, h, alpha, correlated=p.shadowing == "correlated",
                               reflection_only=True)
    q = 4.0 * d * d_den * g_den
    ok = active & (q > 0)
    # safe-where: the masked branch divides by 1, so gradients stay finite at grazing
    spec = jnp.where(ok, r * d_num * g_num / jnp.where(ok, q, 1.0), 0.0)
    transmittance = ct.transmittance_lookup(p.tables, tab)  # resampled once, looked up twice
    diff_geom = jnp.where(active, transmittance(wi.z) * transmittance(wo.z) * (1.0 / (jnp.pi * eta * eta)), 0.0)
    # the per-pair values are stored before the broadcast over the bands: XLA:CPU does not fuse
    # a gather or a quotient into a consumer that reads it once per band, and left to itself
    # split the evaluation into 15 kernels (about 2x slower; issue 20)
    spec, diff_geom = materialize((spec, diff_geom))
    rho = as_bands(p.diffuse_reflectance)
    r_int = rho if p.nonlinear else 1.0
    diff = rho / (1.0 - r_int * with_bands(tab.internal_reflectance))
    return with_bands(spec) * as_bands(p.specular_reflectance) + diff * with_bands(diff_geom)


def _pdf_with(p: Params, tab: CoatTables, wi: Vec3, wo: Vec3):
    kind, alpha = p.distribution, jnp.asarray(p.alpha)
    active = _active(wi, wo)
    h = normalize(wi + wo)
    # D(h) G1(wi, h) / (4 cos_i) = pdf_visible(wi, h) / (4 wi.h) = D(h) / (4 a(wi))
    spec = md.D(kind, h, alpha) / (4.0 * md.projected_area(kind, wi, alpha))
    spec = jnp.where(dot(wi, h) > 0, spec, 0.0)
    diff = warp.square_to_cosine_hemisphere_pdf(wo)
    P_s = _lobe_probability(p, _transmittance_at(p, tab, wi.z))
    return jnp.where(active, P_s * spec + (1.0 - P_s) * diff, 0.0)


def _eval(p: Params, wi: Vec3, wo: Vec3):
    return _eval_with(p, _tables(p), wi, wo)


def _pdf(p: Params, wi: Vec3, wo: Vec3):
    return _pdf_with(p, _tables(p), wi, wo)


def _sample_with(p: Params, tab: CoatTables, wi: Vec3, u):
    kind, alpha = p.distribution, jnp.asarray(p.alpha)
    shape = jnp.broadcast_shapes(jnp.shape(wi.z), jnp.shape(alpha), jnp.shape(p.eta))
    u0, u1, u2 = uniforms(u, shape, 3)
    P_s = _lobe_probability(p, _transmittance_at(p, tab, wi.z))
    m = md.sample_visible(kind, wi, alpha, alpha, u1, u2)
    wo_s = reflect(wi, m)
    wo_d = warp.square_to_cosine_hemisphere(u1, u2)
    choose_spec = u0 < P_s
    wo = Vec3(*(jnp.where(choose_spec, a, b) for a, b in zip(wo_s, wo_d)))
    pdf = _pdf_with(p, tab, wi, wo)
    ok = _active(wi, wo) & (pdf > 0)
    pdf = jnp.where(ok, pdf, 0.0)
    f = _eval_with(p, tab, wi, wo)
    scale = jnp.where(ok, wo.z / jnp.where(ok, pdf, 1.0), 0.0)
    return wo, f * with_bands(scale), pdf


def _sample(p: Params, wi: Vec3, u):
    return _sample_with(p, _tables(p), wi, u)


eval = boundary(_eval, Params)
pdf = boundary(_pdf, Params)
sample = boundary(_sample, Params)
_coat_tables_public = boundary(_tables, Params)

MODEL = Model(
    name="rough_plastic",
    kind="bsdf",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="rough dielectric coat over a diffuse base (Mitsuba 3 roughplastic)",
    source="Weidlich & Wilkie 2007; Walter et al. 2007; Jakob, Mitsuba roughplastic",
    reciprocal=True,
    # a free coat index trades against specular_reflectance and the base albedo (fabrics drift to 2.1-2.5)
    fit_fixed={"eta": (1.5, "coat index of common polymers and varnishes, 1.45-1.6")},
    # the base albedo and the lobe scale multiply finished terms: their tangents skip the coat tables
    jacobian_apart=("diffuse_reflectance", "specular_reflectance"),
    band_separable=True,
    presets={
        "white_plastic": Params(),
        "mitsuba_default": Params(
            alpha=0.1, eta=1.48958738, distribution="beckmann", shadowing="separable", tables="mitsuba"
        ),
        "red_glossy": Params(alpha=0.05, diffuse_reflectance=(0.6, 0.05, 0.05), eta=1.5),
    },
)
