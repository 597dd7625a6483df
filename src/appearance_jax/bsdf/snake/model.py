"""Snake skin: a smooth iridescent thin film over an absorbing diffuse layer (Padrón 2025, Ch. 3).

Two layers, nothing between them, everything azimuth-independent (spec M26/M38, §2.1):

* **Layer 0, the film** (Padrón Eqs. 3.4-3.5): a smooth delta interface that mirrors
  with the Airy reflectance R(mu, lambda) and transmits **straight through** (no refraction,
  the thesis' convention) with T = 1 - R:

      f_0(wi, wo) = R(mu_i) delta(wo - mirror(wi)) + (1 - R(mu_i)) delta(wo + wi)

  R is :func:`appearance_jax.optics.thinfilm.airy` for the film (eta_1, thickness delta_0)
  between eta_0 (above) and eta_2 (below), unpolarised, one value per wavelength. (The
  printed Padrón Eq. 3.1 is the film's *transmittance*; the spec's M10 correction is used.)
* **Layer 1, the absorbing diffuse BRDF** (Padrón Eq. 3.6), mu = |n . w|:

      "product" (printed, default):  f_1 = k_d / pi exp(-sigma_a delta_1 / (mu_i mu_o))
      "beer_sum" (physical double pass, spec [OCR-FIX]):
                                    f_1 = k_d / pi exp(-sigma_a delta_1 (1 / mu_i + 1 / mu_o))

  Both coincide at mu_i = mu_o = 1/2. Only the optical depth sigma_a delta_1 matters (the
  thesis prints delta_1 in "nm"; the unit of sigma_a is whatever makes the product
  dimensionless). Albedo of f_1: 2 k_d E_3(tau / mu_i) (product) or
  2 k_d e^{-tau / mu_i} E_3(tau) (beer_sum), tau = sigma_a delta_1.

**Composition** (spec M26 [DERIVED]). Light enters through the film (T(mu_i)), bounces
between f_1 and the film's underside (reflectance R_u(mu)) any number of times and leaves
through the film (T_u(mu_o) = 1 - R_u(mu_o)):

    f(wi, wo) = R(mu_i) delta_mirror + f_d(wi, wo),     f_d = T(mu_i) F(mu_i, mu_o) T_u(mu_o)
    F(mu_i, mu_o) = f_1(mu_i, mu_o) + 2 pi int_0^1 f_1(mu_i, mu') mu' R_u(mu') F(mu', mu_o) dmu'

**Nyström solution** (spec M38, :mod:`.solver`): the integral equation is collocated at
the nodes of a Gauss-Legendre rule on [0, 1] (split at the cosine of total internal
reflection under the film), one (n, n) solve per band and parameter set, then O(n^2) per
direction pair; F is symmetric (reciprocity to rounding), exact to the quadrature,
jittable, vmappable and differentiable. Thick films (R oscillating many times over mu)
need more nodes: raise ``n_nodes``.

**What ``eval`` returns.** ``eval`` is the *non-delta* part f_d (1/sr, bands trailing); the
mirror lobe's weight R(mu_i) is :func:`specular` (the spec's ``delta_weight``). A path
tracer picks the mirror with probability R / (R + A_d) (band averages; A_d = :func:`albedo`,
the directional albedo of f_d, spec §2.1.4) -- :func:`sample_full` does that. ``sample`` /
``pdf`` cover f_d only: cosine-weighted hemisphere, pdf = mu_o / pi, weight = pi f_d.
mu <= 0 (below the horizon or grazing) gives exactly 0 with finite gradients.

**Underside reflectance** (static ``underside``): ``"top"`` (default, spec decision D14)
reuses the top-side R(mu); ``"airy"`` takes the Airy R seen from the eta_2 side (total
internal reflection for eta_2 > eta_0), which conserves energy but is **not reciprocal**
when eta_2 != eta_0. ``Model.reciprocal`` refers to the default.

**Colour** (static ``color``, :data:`appearance_jax.core.spectral.COLOR_MODES`):
``"rgb3"`` evaluates at 650/510/475 nm (R, G, B; [T:526], prone to spectral aliasing);
``"spectral"`` at the static ``wavelengths`` (one band each); ``"cie"`` on the 380-780 nm
5-nm grid, converted to linear sRGB under D65 at the end (``to_bands``; f is linear in the
spectrum, so the conversion of the BSDF value is exact). ``kd`` and ``sigma_a`` live on the
wavelengths of the computation: a scalar, or one value per wavelength (3 for rgb3,
``len(wavelengths)`` for spectral, 81 for cie).

With k_d = 0 (Padrón Figs. 3.5 and 3.6(d)) f_d = 0 and the absorption has no
effect (flagged Q-S5).

| parameter  | default    | range       | unit           | meaning                                          |
|------------|------------|-------------|----------------|--------------------------------------------------|
| thickness  | 900        | [0, 5000]   | nm             | film thickness delta_0                           |
| eta0       | 1.0        | [1, 3]      | 1              | index of the top medium (air)                    |
| eta1       | 1.56       | [1, 3]      | 1              | film index (keratin; Padrón Table 3.1 prints 1.53) |
| eta2       | 1.0        | [1, 3]      | 1              | index of the medium below the film               |
| sigma_a    | 0.7        | [0, inf)    | 1/depth unit   | absorption coefficient, per wavelength           |
| depth      | 2.0        | [0, inf)    | "nm" (thesis)  | absorbing-layer thickness delta_1 (*)            |
| kd         | 0.3        | [0, 1]      | 1              | albedo of the diffuse reflector, per wavelength  |
| absorption | "product"  | product, beer_sum | -        | Padrón Eq. 3.6 as printed, or the Beer double pass |
| underside  | "top"      | top, airy   | -              | film reflectance seen from below (D14)           |
| color      | "rgb3"     | rgb3, cie, spectral | -      | output bands                                     |
| wavelengths| (650, 510, 475) | > 0    | nm             | wavelengths of the "spectral" mode               |
| n_nodes    | 48         | [8, 1024]   | -              | quadrature nodes of the Nyström solve            |

Defaults: the values of Padrón Sec. 3.5.2 (eta_1 = 1.56, sigma_a = 0.7, delta_1 = 2,
delta_0 = 900 nm of Padrón Fig. 3.6(c)) with k_d = 0.3 (the diffuse baseline of Padrón
Fig. 3.6(a)) so that the layer is visible. (*) Only the optical depth sigma_a delta_1 enters.

Public functions (all ``snake.<name>``): ``eval`` / ``sample`` / ``pdf`` (the model protocol,
non-delta part), :func:`specular` (delta weight), :func:`albedo` (directional albedo of f_d),
:func:`components` (all three from one solve), and in :mod:`.mc` :func:`sample_full` (delta +
diffuse, for a path tracer) and :func:`eval_mc`, an independent position-free random walk (next-event
estimation at every bottom vertex, cosine-sampled bounces, the underside reflection taken
as a weight or by Russian roulette) that returns the estimate of f_d and its standard error.

Measured accuracy of the quadrature, the decisions (D14, Q-S5) and their history, cost
notes: docs/thin_films.md.

Example::

    from appearance_jax.bsdf import snake
    from appearance_jax.core.frame import spherical_direction
    p = snake.Params()                      # or snake.PRESETS["table_3_1"]
    wi, wo = spherical_direction(0.3, 0.0), spherical_direction(0.6, 2.0)
    f_d = snake.eval(p, wi, wo)             # (3,) 1/sr, the non-delta part
    R = snake.specular(p, wi)               # (3,) weight of the mirror lobe
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ...core import spectral, warp
from ...core.model import Model, boundary, with_bands
from ...core.params import Bands, integer, param, params_class, Real, static
from ...core.rng import uniforms
from ...core.vec import Vec3
from .solver import _f1, _film_R, _out, _quad_form, _safe_mu, _solve, _u, _wavelengths

ABSORPTION_FORMS = ("product", "beer_sum")
UNDERSIDE_MODES = ("top", "airy")


@params_class
class Params:
    thickness: Real = param(900.0, lo=0.0, hi=5000.0, unit="nm", doc="film thickness delta_0")
    eta0: Real = param(1.0, lo=1.0, hi=3.0, unit="1", doc="index of the top medium")
    eta1: Real = param(1.56, lo=1.0, hi=3.0, unit="1", doc="index of the film (keratin)")
    eta2: Real = param(1.0, lo=1.0, hi=3.0, unit="1", doc="index of the medium below the film")
    sigma_a: Bands = param(0.7, lo=0.0, unit="1/depth unit", doc="absorption coefficient, per wavelength",
                            bands=True)
    depth: Real = param(2.0, lo=0.0, unit="nm (thesis)",
                          doc="absorbing-layer thickness delta_1 (only sigma_a * depth matters)")
    kd: Bands = param(0.3, lo=0.0, hi=1.0, unit="1", doc="albedo of the diffuse reflector", bands=True)
    absorption: str = static("product", choices=ABSORPTION_FORMS,
                             doc="f_1 absorption: Padrón Eq. 3.6 as printed, or the Beer double pass")
    underside: str = static("top", choices=UNDERSIDE_MODES,
                            doc="film reflectance from below: top-side R (D14) or Airy from eta2")
    color: str = static("rgb3", choices=spectral.COLOR_MODES, doc="output bands: rgb3, cie or spectral")
    wavelengths: tuple = static(spectral.RGB_WAVELENGTHS, convert=spectral.wavelengths_tuple,
                                doc="wavelengths (nm) of the 'spectral' colour mode")
    n_nodes: int = static(48, convert=integer(8, 1024), doc="Gauss-Legendre nodes of the Nyström solve")

    def _validate(self):
        n_wl = spectral.band_wavelengths_np(self.color, self.wavelengths).size
        for name in ("kd", "sigma_a"):
            v = np.atleast_1d(np.asarray(getattr(self, name)))
            if v.shape[-1] not in (1, n_wl):
                raise ValueError(
                    f"snake.Params.{name} has {v.shape[-1]} values on its trailing (wavelength) axis; "
                    f"color={self.color!r} computes on {n_wl} wavelengths: give a scalar or {n_wl} values")


# --------------------------------------------------------------------------------------
# kernels


def _components_spectral(p: Params, wi: Vec3, wo: Vec3):
    """(f_d(wi, wo), R(mu_i), A_d(mu_i)) on the computation's wavelengths: one solve, one airy."""
    ok_i = wi.z > 0
    ok = ok_i & (wo.z > 0)
    mi, mo = _safe_mu(wi.z), _safe_mu(wo.z)
    (mu_k, kd, tau, M, Q, wl), (R_i, R_o) = _solve(p, [(mi, "top"), (mo, "under")])
    L = wl.shape[0]
    ui = _u(p, kd, tau, mu_k, mi, L)
    uo = _u(p, kd, tau, mu_k, mo, L)
    F = _f1(p.absorption, kd[..., 0], tau[..., 0], with_bands(mi), with_bands(mo)) + _quad_form(ui, M, uo)
    f = (1.0 - R_i) * F * (1.0 - R_o)
    A = (1.0 - R_i) * jnp.sum(ui * Q, axis=-1)
    zero = lambda ok, x: jnp.where(with_bands(ok), x, 0.0)  # noqa: E731
    return zero(ok, f), zero(ok_i, R_i), zero(ok_i, A)


def _components(p: Params, wi: Vec3, wo: Vec3):
    return tuple(_out(p, x) for x in _components_spectral(p, wi, wo))


def _eval(p: Params, wi: Vec3, wo: Vec3):
    return _components(p, wi, wo)[0]


def _specular(p: Params, wi: Vec3):
    ok = wi.z > 0
    R = _film_R(p, with_bands(_safe_mu(wi.z)), _wavelengths(p), 1, "top")
    return _out(p, jnp.where(with_bands(ok), R, 0.0))


def _albedo(p: Params, wi: Vec3):
    return _components(p, wi, wi)[2]


def _pdf(p: Params, wi: Vec3, wo: Vec3):
    ok = (wi.z > 0) & (wo.z > 0)
    return jnp.where(ok, warp.square_to_cosine_hemisphere_pdf(wo), 0.0)


def _sample(p: Params, wi: Vec3, u):
    shape = jnp.shape(wi.z)
    u1, u2 = uniforms(u, shape, 2)
    wo = warp.square_to_cosine_hemisphere(u1, u2)
    ok = (wi.z > 0) & (wo.z > 0)
    pdf = jnp.where(ok, warp.square_to_cosine_hemisphere_pdf(wo), 0.0)
    # weight = f_d cos_o / pdf = pi f_d
    weight = jnp.where(with_bands(ok), jnp.pi * _eval(p, wi, wo), 0.0)
    return wo, weight, pdf


# --------------------------------------------------------------------------------------
# public functions

eval = boundary(_eval, Params)
pdf = boundary(_pdf, Params)
sample = boundary(_sample, Params)
specular = boundary(_specular, Params)
specular.__doc__ = """Weight of the mirror (delta) lobe, R(mu_i) per band: the spec's ``delta_weight``.

``eval`` excludes it. 0 for mu_i <= 0."""
albedo = boundary(_albedo, Params)
albedo.__doc__ = """Directional albedo of the non-delta part, 2 pi int f_d(mu_i, mu_o) mu_o dmu_o (bands).

Quadrature over the Nyström nodes with the Nyström-interpolated F; deterministic and
differentiable. With k_d = 1, sigma_a = 0: specular + albedo = 1 to rounding."""
components = boundary(_components, Params)
components.__doc__ = """``(f_d(wi, wo), delta_weight(wi), albedo(wi))`` from one Nyström solve (bands each).

What a renderer needs at a vertex: the non-delta value (= ``eval``), the mirror lobe's
weight R(mu_i) (= ``specular``) and the non-delta albedo (= ``albedo``, for lobe selection),
with one solve and one film evaluation (one compiled program)."""


PRESETS = {
    # Padrón Table 3.1 [T:480-489]: eta_0 = 1, eta_1 = 1.53; the table prints no delta_0, eta_2 or
    # k_d: delta_0 = 900 nm and eta_2 = 1 from Padrón Fig. 3.6(c), sigma_a = 0.7, delta_1 = 2 and
    # k_d = 0 from Padrón Sec. 3.5.2 (so f_d = 0: Q-S5)
    "table_3_1": Params(thickness=900.0, eta0=1.0, eta1=1.53, eta2=1.0, sigma_a=0.7, depth=2.0, kd=0.0),
    # Padrón Fig. 3.5 defaults [T:540, 547] (rows vary delta_0, columns eta_2; values not printed)
    "fig_3_5": Params(thickness=900.0, eta0=1.0, eta1=1.56, eta2=1.0, sigma_a=0.7, depth=2.0, kd=0.0),
    # Padrón Fig. 3.6(a): the plain diffuse baseline k_d = 0.3, written as a film-less stack
    # (delta_0 = 0, eta_0 = eta_1 = eta_2 = 1 => R = 0, T = 1; sigma_a = 0 => f = k_d / pi)
    "fig_3_6a_diffuse": Params(thickness=0.0, eta0=1.0, eta1=1.0, eta2=1.0, sigma_a=0.0, depth=2.0, kd=0.3),
    # Padrón Fig. 3.6(d) [T:550]: the film (smooth here; rough in the figure) with absorption and k_d = 0
    "fig_3_6d": Params(thickness=900.0, eta0=1.0, eta1=1.56, eta2=1.0, sigma_a=0.7, depth=2.0, kd=0.0),
    # the configuration of the spec's M26 check table (= the defaults)
    "spec_m26_check": Params(),
}

MODEL = Model(
    name="snake",
    kind="bsdf",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="snake skin: smooth Airy thin film over an absorbing diffuse layer (Nyström-solved, non-delta part)",
    source="Padrón Griffé 2025, Ch. 3 (Padrón-Griffé et al. CEIG 2023)",
    reciprocal=True,
    fit_fixed={"eta0": (1.0, "the top medium is air"),
               "eta1": (1.56, "the film is keratin (Padrón Sec. 3.5.2; Table 3.1 prints 1.53)"),
               "depth": (2.0, "only the optical depth sigma_a * depth enters; sigma_a carries it")},
    presets=PRESETS,
    band_separable=True,
)

__all__ = ["Params", "eval", "pdf", "sample", "components", "specular", "albedo", "MODEL", "PRESETS",
           "ABSORPTION_FORMS", "UNDERSIDE_MODES"]
