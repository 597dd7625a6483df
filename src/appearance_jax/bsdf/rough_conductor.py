"""Rough conductor: Cook-Torrance microfacet reflection with conductor Fresnel.

    f(wi, wo) = R F(wi.h; eta + i k) D(h) G2(wi, wo, h) / (4 cos theta_i cos theta_o),
    h = (wi + wo) / |wi + wo|

(Cook & Torrance 1982; Walter et al. 2007, Eq. 20; Padrón 2025 spec M08 with the Fresnel
term taken at the microfacet angle wi.h), for wi, wo both above the surface, else 0.
D and G2 come from :mod:`appearance_jax.microfacet.distribution`; F is the exact
unpolarised conductor reflectance (:func:`~appearance_jax.optics.fresnel.fresnel_conductor`).

Sampling: visible normals of wi, then mirror (:mod:`appearance_jax.microfacet.cook_torrance`,
shared with the other microfacet reflectors): pdf(wi, wo) = D(h) / (4 mu(wi)) and
weight = f cos theta_o / pdf = R F G2 / G1(wi).
``sample(params, wi, u_or_key)`` takes a PRNG key or 2 uniform arrays (the visible normal).

| parameter            | default                  | range      | unit | meaning                                   |
|----------------------|--------------------------|------------|------|-------------------------------------------|
| alpha                | 0.1                      | [1e-3, 2]  | 1    | roughness along x (u); isotropic if alone |
| alpha_v              | None (= alpha)           | [1e-3, 2]  | 1    | roughness along y (v), anisotropic        |
| eta                  | (0.1556, 0.8031, 1.2703) | [0, 20]    | 1    | real part of the conductor's index, bands |
| k                    | (3.6024, 1.9729, 1.8466) | [0, 50]    | 1    | extinction coefficient, per band          |
| specular_reflectance | 1                        | [0, 1]     | 1    | scale of the reflectance, per band        |
| distribution         | "ggx"                    | ggx, beckmann | - | microfacet normal distribution         |
| shadowing            | "correlated"             | correlated, separable | - | Smith G2 form                  |

Defaults: eta and k are gold (Johnson & Christy 1972, ``data/refractive_index/Au_Johnson.yml``,
linearly interpolated at 650, 510, 475 nm, the R, G, B wavelengths used by the Padrón 2025
thesis [T:526]); eta and k are relative to the outside medium (air).

Roughness range: alpha is the RMS slope (x sqrt(2) for Beckmann). Below 1e-3 the lobe is
narrower than the angular resolution of float32 unit vectors (~3e-4 rad near the normal)
and D overflows its useful range, so a smooth (delta) conductor should be used instead;
above 2 (mean facet slope > 60 deg) the Smith microsurface model is far outside the range
of measured materials, and fits that run there are better served by a diffuse term.

Derivatives: ``eval`` carries :func:`~appearance_jax.core.autodiff.forward_jacobian_rule`, so
a reverse-mode gradient with respect to one scalar (alpha, say) costs one forward-mode pass
and stores one output-sized column instead of the whole graph; with respect to more inputs
it is JAX's native reverse mode. ``eval.kernel.unwrapped`` is the kernel without the rule.

Differences from Mitsuba 3's ``roughconductor``: Mitsuba defaults to ``beckmann`` and always
uses the separable Smith G (``shadowing="separable"`` here); its Beckmann G1 is Walter's
rational approximation (rel. error < 0.35%) where we use the exact erf form; its ``eval``
returns f cos theta_o where ours returns f.
"""

from __future__ import annotations

import functools

from ..core.autodiff import forward_jacobian_rule
from ..core.model import Model, as_bands, boundary, with_bands
from ..core.params import Bands, param, params_class, Real, static
from ..core.vec import Vec3
from ..microfacet import cook_torrance as ct
from ..microfacet import distribution as md
from ..optics.fresnel import fresnel_conductor

AU_ETA_RGB = (0.1556, 0.8031, 1.2703)
AU_K_RGB = (3.6024, 1.9729, 1.8466)


@params_class
class Params:
    alpha: Real = param(0.1, lo=1e-3, hi=2.0, unit="1", doc="microfacet roughness (RMS slope) along x / u")
    alpha_v: Real | None = param(None, lo=1e-3, hi=2.0, unit="1", doc="roughness along y / v (None: isotropic)")
    eta: Bands = param(AU_ETA_RGB, lo=0.0, hi=20.0, unit="1", doc="real part of the relative complex index",
                        bands=True)
    k: Bands = param(AU_K_RGB, lo=0.0, hi=50.0, unit="1", doc="extinction coefficient (imaginary part)", bands=True)
    specular_reflectance: Bands = param(1.0, lo=0.0, hi=1.0, unit="1", doc="reflectance scale per band", bands=True)
    distribution: str = static("ggx", choices=md.KINDS, doc="microfacet normal distribution")
    shadowing: str = static("correlated", choices=("correlated", "separable"), doc="Smith G2 form")


def _fresnel(p: Params, cos_h):
    """R * F(cos_h) over the bands axis."""
    eta, k, r = as_bands(p.eta), as_bands(p.k), as_bands(p.specular_reflectance)
    return r * fresnel_conductor(with_bands(cos_h), eta, k)


def _eval(p: Params, wi: Vec3, wo: Vec3):
    return ct.reflection(p, wi, wo, functools.partial(_fresnel, p))


def _pdf(p: Params, wi: Vec3, wo: Vec3):
    return ct.pdf(p, wi, wo)


def _sample(p: Params, wi: Vec3, u):
    return ct.sample_reflection(p, wi, u, functools.partial(_fresnel, p))


# one differentiated scalar (a roughness fit, a reverse-mode gradient w.r.t. alpha) costs one
# forward-mode pass instead of JAX's stored reverse graph (core.autodiff)
eval = boundary(forward_jacobian_rule(_eval), Params)
pdf = boundary(_pdf, Params)
sample = boundary(_sample, Params)

MODEL = Model(
    name="rough_conductor",
    kind="bsdf",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="Cook-Torrance rough conductor (GGX/Beckmann, Smith G, conductor Fresnel)",
    source="Cook & Torrance 1982; Walter et al. 2007; Heitz 2014, 2018",
    reciprocal=True,
    jacobian_apart=("specular_reflectance",),  # scales the finished lobe: its tangents skip D and G2
    band_separable=True,
    presets={
        "gold": Params(),
        "gold_rough_beckmann": Params(alpha=0.3, distribution="beckmann"),
    },
)
