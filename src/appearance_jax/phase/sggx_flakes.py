"""Specular SGGX microflake phase function of the cosmetic platelets (Padrón Eq. 4.10;
SGGX: Heitz, Dupuy, Crassin & Dachsbacher 2015; seed-000 spec M14).

    f_p(wi, wo) = D(wh) / (4 sigma(wi)),   wh = (wi + wo) / |wi + wo|              [1/sr]

with the flake SGGX matrix ``S = alpha^2 I + (1 - alpha^2) w3 w3^T`` of roughness alpha and
mean normal ``w3 = (0, -sin theta, cos theta)`` (a rotation by theta about the tangent x:
[ASSUMPTION, spec M14]), ``D`` and ``sigma(w) = sqrt(w^T S w)`` from
:mod:`appearance_jax.microfacet.sggx`. "Without Fresnel effects" [T:724-726]: purely
reflective flakes; the albedo Lambda_p is applied by the caller (the cosmetic medium, M15).

Conventions: both wi and wo point **away** from the scattering point (light travels along
d = -wi). The thesis' normalised projected area Ĉ_p(w) = C_p(w) / max C_p equals sigma(w)
here because max_w sigma = 1 (along w3): :func:`sigma` is that Ĉ_p, the directional factor of
the platelet extinction (Padrón Eq. 4.5).

Properties: f_p integrates to 1 over the sphere (it is a phase function, no cosine);
it is **not** symmetric in (wi, wo) (``Model.reciprocal = False``), but
``f_p(wi, wo) sigma(wi) = D(wh)/4`` is: the reciprocity of the anisotropic RTE is
f(w -> wo) sigma_s(w) = f(wo -> w) sigma_s(wo) [T:710]. alpha = 1 gives the isotropic
1/(4 pi). Sampling draws a visible normal m (Heitz et al. 2015) and reflects wi about it;
the density is exactly f_p, so ``weight = f / pdf = 1`` (0 for a failed sample).

| parameter | default | range      | unit | meaning                                                    |
|-----------|---------|------------|------|------------------------------------------------------------|
| alpha     | 0.3     | (0, 1]     | 1    | platelet roughness alpha_p (flake thickness / width; 1 = isotropic) |
| theta     | 0.0     | [0, pi/2]  | rad  | tilt theta_p of the mean flake normal about the tangent x  |

Padrón Table A.1 (seeds/000 [T:1203-1204]; spec §2.2.4) gives theta_p in **degrees**;
the presets below are converted to radians. Accuracy: the sampler uses the generic SGGX
formulas (see :mod:`appearance_jax.microfacet.sggx`); in float64 they are accurate down to
alpha = 1e-3 (the ``dewy2`` preset has alpha = 0.002); in float32 prefer alpha >= 0.03.
``eval`` and ``pdf`` use the flake closed forms, accurate in both precisions.

Example::

    from appearance_jax.phase import sggx_flakes as sf
    p = sf.Params(alpha=0.13, theta=jnp.deg2rad(1.47))     # or sf.MODEL.presets["dewy1"]
    f = sf.eval(p, wi, wo)                                  # shape wi.shape + (1,), 1/sr
    wo, weight, pdf = sf.sample(p, wi, jax.random.key(0))   # weight == 1
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from ..core.frame import reflect
from ..core.model import Model, boundary, with_bands
from ..core.params import param, params_class, Real
from ..core.rng import uniforms
from ..core.vec import Vec3, dot, normalize
from ..microfacet import sggx


@params_class
class Params:
    alpha: Real = param(0.3, lo=0.0, hi=1.0, lo_open=True, unit="1",
                          doc="platelet SGGX roughness alpha_p (1 = isotropic flakes)")
    theta: Real = param(0.0, lo=0.0, hi=math.pi / 2, unit="rad",
                          doc="tilt theta_p of the mean flake normal about the tangent x (Padrón Table A.1: degrees)")


# ------------------------------------------------------------------------------------
# building blocks


def sigma(p: Params, w: Vec3):
    """Normalised projected area Ĉ_p(w) = sigma(w) = sqrt(w^T S w), in [alpha, 1]; even in w."""
    return sggx.flake_projected_area(p.alpha, sggx.mean_normal(p.theta), w)


def phase_value(alpha, theta, wi: Vec3, wo: Vec3):
    """f_p(wi, wo) = D(wh) / (4 sigma(wi)) per direction pair (no bands axis); 0 at wo = -wi."""
    w3 = sggx.mean_normal(theta)
    h = normalize(wi + wo)
    d = sggx.flake_D(alpha, w3, h)
    return 0.25 * d / sggx.flake_projected_area(alpha, w3, wi)


# ------------------------------------------------------------------------------------
# kernels


def _eval(p: Params, wi: Vec3, wo: Vec3):
    return with_bands(phase_value(p.alpha, p.theta, wi, wo))


def _pdf(p: Params, wi: Vec3, wo: Vec3):
    return phase_value(p.alpha, p.theta, wi, wo)


def _sample(p: Params, wi: Vec3, u):
    shape = jnp.broadcast_shapes(jnp.shape(wi.z), jnp.shape(p.alpha), jnp.shape(p.theta))
    u1, u2 = uniforms(u, shape, 2)
    S = sggx.flake_matrix(p.alpha, p.theta)
    m = sggx.sample_visible_normal(S, wi, u1, u2)
    wo = normalize(reflect(wi, m))
    pdf = phase_value(p.alpha, p.theta, wi, wo)
    ok = (pdf > 0) & (dot(wi, m) > 0)
    pdf = jnp.where(ok, pdf, 0.0)
    weight = with_bands(jnp.where(ok, 1.0, 0.0))
    return wo, weight, pdf


eval = boundary(_eval, Params)
pdf = boundary(_pdf, Params)
sample = boundary(_sample, Params)

_DEG = math.pi / 180.0
#: Padrón Table A.1 (seeds/000 [T:1203-1204], spec §2.2.4): (alpha_p, theta_p in degrees)
TABLE_A1 = {"dewy1": (0.13, 1.47), "dewy2": (0.002, 5.5), "matte1": (0.15, 2.01), "matte2": (0.49, 52.2)}
PRESETS = {k: dict(alpha=a, theta=t * _DEG) for k, (a, t) in TABLE_A1.items()}

MODEL = Model(
    name="sggx_flakes",
    kind="phase",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="specular SGGX microflake (platelet) phase function D(wh) / (4 sigma(wi)), roughness alpha, tilt theta",
    source="Eq. 4.10, Padrón 2025 (seed-000 spec M14); Heitz et al. 2015 (SGGX); Table A.1 presets",
    reciprocal=False,  # f(wi, wo) sigma(wi) is symmetric, f is not
    transmissive=True,
    presets={k: Params(**v) for k, v in PRESETS.items()},
)
