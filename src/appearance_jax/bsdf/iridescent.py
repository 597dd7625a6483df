"""Iridescent microfacet BRDF: Cook-Torrance with an Airy thin film on every facet.

A film of index eta_film and thickness d covers a substrate of complex index
eta_substrate + i k_substrate, under an incidence medium eta_outside. Every microfacet
reflects like the flat film at the facet angle theta_d, cos theta_d = wi.h
(Belcour & Barla 2017, "A practical extension to microfacet theory for the modeling of
varying iridescence", ACM TOG 36(4); spec M11 of Padrón Griffé 2025, which uses it for the
"rough thin-film" snake of Padrón Fig. 3.6(c), [T:550]):

    f(wi, wo) = s R(lambda, wi.h) D(h) G2(wi, wo, h) / (4 cos theta_i cos theta_o),
    h = (wi + wo) / |wi + wo|

for wi, wo both above the surface, else 0; s = specular_reflectance. D, G2 (Smith,
height-correlated or separable), the visible-normal sampler and the pdf are those of
:mod:`appearance_jax.bsdf.rough_conductor` (Cook & Torrance 1982; Walter et al. 2007;
Heitz 2014, 2018): ``pdf(wi, wo) = D(h) / (4 mu(wi))`` and
``weight = f cos theta_o / pdf = s R G2 / G1(wi)``.

R is the unpolarised Airy reflectance (R_s + R_p) / 2 of
:func:`appearance_jax.optics.thinfilm.airy` (spec M10): per polarisation, with signed
complex interface amplitudes r_01 (outside | film) and r_12 (film | substrate),

    r = (r_01 + r_12 e^{i phi}) / (1 + r_01 r_12 e^{i phi}),
    phi = (4 pi / lambda) d eta_film cos theta_1,   R = |r|^2,

theta_1 the refraction angle in the film. The substrate may absorb (k_substrate > 0: a
conductor, or melanin); d = 0 gives the bare outside | substrate Fresnel reflectance, so
the model reduces to ``rough_conductor`` with eta = eta_substrate / eta_outside and
k = k_substrate / eta_outside (tested to 1e-10). R is periodic in d with period
lambda / (2 eta_film cos theta_1) (:func:`~appearance_jax.optics.thinfilm.film_period_nm`):
fits of the thickness need several starts.

Misprint in the thesis: Padrón Eq. 3.1 ([T:461] of seed 000), printed as the reflected
intensity I_R, is the film's *transmittance*; :func:`~appearance_jax.optics.thinfilm.airy`
implements the corrected form (tested against ``tmm``), and this model only calls it.

Colour (static ``color``, :data:`appearance_jax.core.spectral.COLOR_MODES`):

- ``"rgb3"`` (default): 3 bands, R at the single wavelengths 650, 510, 475 nm that stand for
  R, G, B in Padrón Griffé 2025 ([T:526]): 3 Airy evaluations per pair. Cheap, but a
  point sample of an oscillating spectrum aliases ([T:526]): for films thicker than ~1 um
  the spectrum oscillates faster than 3 samples can represent and the colours are wrong
  (spurious saturated hues) rather than the near-white of higher-order interference.
- ``"cie"``: 3 bands of linear sRGB: the spectrum on a 380-780 nm grid by 5 nm (81 Airy
  evaluations per pair) integrated with the CIE 1931 colour-matching functions under D65
  (:func:`~appearance_jax.core.spectral.spectrum_to_linear_srgb`; a perfect reflector gives
  (1, 1, 1)). Out-of-gamut film colours have negative linear sRGB components; they are
  clipped to 0 (a BRDF is non-negative), the only non-linearity of this mode.
- ``"spectral"``: one band per wavelength of the static ``wavelengths`` (nm).

Differences from Belcour & Barla 2017 (their analytic spectral anti-aliasing is not used)
and the history of the colour modes: docs/microfacet.md.

| parameter            | default      | range              | unit | meaning                                          |
|----------------------|--------------|--------------------|------|--------------------------------------------------|
| alpha                | 0.1          | [1e-3, 2]          | 1    | roughness along x (u); isotropic if alone        |
| alpha_v              | None (=alpha)| [1e-3, 2]          | 1    | roughness along y (v), anisotropic               |
| thickness            | 500          | [0, 5000]          | nm   | film thickness d                                 |
| eta_film             | 1.33         | [1, 3]             | 1    | film index (real, no dispersion)                 |
| eta_substrate        | 1.0          | [0, 20]            | 1    | real part of the substrate index                 |
| k_substrate          | 0.0          | [0, 50]            | 1    | substrate extinction (0: dielectric)             |
| eta_outside          | 1.0          | [1, 3]             | 1    | index of the incidence medium (real)             |
| specular_reflectance | 1            | [0, 1]             | 1    | scale per output band                            |
| distribution         | "ggx"        | ggx, beckmann      | -    | microfacet normal distribution                   |
| shadowing            | "correlated" | correlated, separable | - | Smith G2 form                                    |
| color                | "rgb3"       | rgb3, cie, spectral| -    | output bands (above)                             |
| wavelengths          | (650, 510, 475) | > 0             | nm   | the bands of ``color="spectral"``                |

Indices are absolute (eta_outside = 1 is air) and the same at every wavelength; they and
the thickness broadcast against the directions (spatially varying films), while
``specular_reflectance`` carries the output bands axis. eta_substrate = k_substrate = 0 is
rejected (no medium has index 0). At k_substrate = 0 (its bound) ``jax.grad`` is the
derivative from the k > 0 side; k < 0 (a gain medium) is outside the model: the forward
branch of the substrate's normal index flips there, so central finite differences across 0
are meaningless.

Defaults: a free-standing water/soap film (eta_film = 1.33 between air and air, the
setting of Huang 2022 for bubbles and of :func:`~appearance_jax.optics.thinfilm.color_chart`)
500 nm thick, where the interference colours are vivid low-order ones. Only the
reflected part is modelled: the transmitted 1 - R leaves through the film (a BTDF this
model does not have), so the white furnace is far below 1. Thickness range: 0 (no film) to
5 um; beyond a few um the colours of a real (not perfectly uniform, not coherent over the
whole band) film wash out to white, which a coherent Airy film does not reproduce.
"""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np

from ..core import spectral
from ..core.model import Model, as_bands, boundary, with_bands
from ..core.params import Bands, param, params_class, Real, static
from ..core.vec import Vec3
from ..microfacet import cook_torrance as ct
from ..microfacet import distribution as md
from ..optics.thinfilm import airy


@params_class
class Params:
    alpha: Real = param(0.1, lo=1e-3, hi=2.0, unit="1", doc="microfacet roughness (RMS slope) along x / u")
    alpha_v: Real | None = param(None, lo=1e-3, hi=2.0, unit="1", doc="roughness along y / v (None: isotropic)")
    thickness: Real = param(500.0, lo=0.0, hi=5000.0, unit="nm", doc="film thickness")
    eta_film: Real = param(1.33, lo=1.0, hi=3.0, unit="1", doc="refractive index of the film (real)")
    eta_substrate: Real = param(1.0, lo=0.0, hi=20.0, unit="1", doc="real part of the substrate's index")
    k_substrate: Real = param(0.0, lo=0.0, hi=50.0, unit="1", doc="extinction coefficient of the substrate")
    eta_outside: Real = param(1.0, lo=1.0, hi=3.0, unit="1", doc="refractive index of the incidence medium")
    specular_reflectance: Bands = param(1.0, lo=0.0, hi=1.0, unit="1", doc="reflectance scale per band", bands=True)
    distribution: str = static("ggx", choices=md.KINDS, doc="microfacet normal distribution")
    shadowing: str = static("correlated", choices=("correlated", "separable"), doc="Smith G2 form")
    color: str = static("rgb3", choices=spectral.COLOR_MODES, doc="output bands: rgb3, cie (linear sRGB), spectral")
    wavelengths: tuple = static(spectral.RGB_WAVELENGTHS, convert=spectral.wavelengths_tuple,
                                doc="wavelengths (nm) of color='spectral'")

    def _validate(self):
        both_zero = (np.asarray(self.eta_substrate) == 0) & (np.asarray(self.k_substrate) == 0)
        if np.any(both_zero):
            raise ValueError("iridescent.Params.eta_substrate = 0 with k_substrate = 0: the substrate index "
                             "eta_substrate + i k_substrate must not be 0 (need eta_substrate > 0 or k_substrate > 0)")


# --------------------------------------------------------------------------------------
# The film
# --------------------------------------------------------------------------------------


def film_reflectance(p: Params, cos_h):
    """s R(lambda, cos_h) over the output bands of ``p.color``: ``cos_h.shape + (n_bands,)``."""
    wl = spectral.band_wavelengths(p.color, p.wavelengths)
    eta2 = jnp.asarray(p.eta_substrate) + 1j * jnp.asarray(p.k_substrate)
    R = airy(with_bands(cos_h), wl, with_bands(p.thickness), with_bands(p.eta_outside),
             with_bands(p.eta_film), with_bands(eta2)).R
    bands = spectral.to_bands(R, p.color, p.wavelengths, illuminant="D65")
    if p.color == "cie":
        bands = jnp.maximum(bands, 0.0)  # out-of-gamut colours: no negative reflectance
    return as_bands(p.specular_reflectance) * bands


def _eval(p: Params, wi: Vec3, wo: Vec3):
    return ct.reflection(p, wi, wo, functools.partial(film_reflectance, p))


def _sample(p: Params, wi: Vec3, u):
    return ct.sample_reflection(p, wi, u, functools.partial(film_reflectance, p))


def _pdf(p: Params, wi: Vec3, wo: Vec3):
    """D(h) / (4 mu(wi)): the visible-normal density (as ``rough_conductor``, same roughness)."""
    return ct.pdf(p, wi, wo)


eval = boundary(_eval, Params)
pdf = boundary(_pdf, Params)
sample = boundary(_sample, Params)

# Presets. Thesis values are marked [T:n] (line n of the seed text); everything else is our choice.
PRESETS = {
    # A free-standing soap film (water 1.33 between air and air: Huang 2022 shades bubbles
    # with "air on both sides", seed 001 §1.1.5); ~1 um thick as the simulated films of Huang
    # 2022 (2 eta_0 = 1 um, Huang Table 3.2, [T:502-506] of seed 001): pale higher-order colours,
    # best rendered with color="cie" (rgb3 aliases at this thickness). alpha = 0.05 is ours (a
    # nearly smooth film, wide enough for the microfacet model).
    "soap_film": Params(alpha=0.05, thickness=1000.0, eta_film=1.33, eta_substrate=1.0, k_substrate=0.0),
    # Keratin film over an absorbing melanin layer (the structure of rock-dove barbules, Huang
    # 2022, and of the snake skin's eumelanin pigment layer, Padrón 2025 Ch. 3): eta_film = 1.56
    # (keratin, Padrón Sec. 3.5.2 [T:540, 547, 550]); melanin 1.648 + 0.0632 i as printed
    # by Huang 2022 ([T:307], [T:2286] of seed 001; his code's Cauchy law gives n = 1.716 at
    # 589 nm, see spec 001 §0.4 item 11); d = 595 nm, the green upper-neck rock dove
    # ([T:1517-1519] of seed 001). alpha = 0.15 is ours. Treating melanin as a semi-infinite
    # absorber keeps only the film's own reflection (weakly modulated, |r_12| ~ 0.03).
    "keratin_on_melanin": Params(alpha=0.15, thickness=595.0, eta_film=1.56, eta_substrate=1.648,
                                 k_substrate=0.0632),
    # Padrón Fig. 3.6(c), "rough thin-film interference" [T:550]: eta_0 = 1 (air),
    # eta_1 = 1.56, eta_2 = 1.0, delta = 900 nm, RGB at 650/510/475 nm [T:526]. The thesis
    # never gives the roughness (spec 000 §0.4 item 7): alpha = 0.1 (GGX) is ours.
    "snake_fig_3_6c": Params(alpha=0.1, thickness=900.0, eta_film=1.56, eta_substrate=1.0, k_substrate=0.0,
                             color="rgb3"),
}

MODEL = Model(
    name="iridescent",
    kind="bsdf",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="Microfacet thin-film BRDF (Cook-Torrance with Airy film reflectance; rgb3/CIE/spectral)",
    source="Belcour & Barla 2017; Padrón Griffé 2025 Fig. 3.6(c)",
    reciprocal=True,
    fit_fixed={"eta_outside": (1.0, "the incidence medium is air")},
    jacobian_apart=("specular_reflectance",),  # scales the finished lobe: its tangents skip the film
    band_separable=True,
    presets=PRESETS,
)
