"""Cosmetic foundation, deterministic: the cosmetic medium of Padrón 2025 Ch. 4 solved by
discrete ordinates and adding-doubling (:mod:`appearance_jax.layered.ordinates`; issue 25).

The same material as :mod:`appearance_jax.bsdf.cosmetics` (one index-matched slab of
diffusers (two-lobe HG, Padrón Eq. 4.9) and SGGX platelets (Padrón Eq. 4.10) with
direction-dependent extinction and albedo (Padrón Eqs. 4.3-4.8) over a Lambertian base),
optionally under a smooth dielectric top interface of index ``eta``; but ``eval`` returns f
itself, with no Monte Carlo noise: smooth in every parameter (exact gradients), the same
numbers every call. It is the fitting path of cosmetic foundations; the random walk
(``cosmetics``) is its reference.

Accuracy (docs/cosmetics.md, tests/bsdf/test_cosmetics_ordinates.py): within 3 standard
errors of the walk (16-32k paths, ~0.3-0.5 %) for the four Table A.1 presets and for two
layers with an interface over a base; ~1e-5 against the HG adding-doubling reference. The platelet tilt
theta_p enters exactly in single scattering; the multiply scattered light is that of the
tilt's azimuth mixture plus a correction to the oriented medium from a coarse full-azimuth
solve (:mod:`~appearance_jax.layered.ordinates_tilt`; Matte 2, theta_p = 52 deg: +3..5 %
without it, within 3 standard errors with it).

| parameter        | default | range     | unit | meaning                                             |
|------------------|---------|-----------|------|-----------------------------------------------------|
| c_d              | 0.9     | [0, 1]    | 1    | relative diffuser concentration (1 - c_d: platelets)|
| albedo_d         | 0.95    | [0, 1]    | 1    | diffuser single-scattering albedo Lambda_d (RGB)    |
| albedo_p         | 0.9     | [0, 1]    | 1    | platelet single-scattering albedo Lambda_p (RGB)    |
| w_g              | 1.0     | [0, 1]    | 1    | weight of the diffusers' HG lobe 1                  |
| g1               | 0.5     | (-1, 1)   | 1    | asymmetry of HG lobe 1                              |
| g2               | -0.2    | (-1, 1)   | 1    | asymmetry of HG lobe 2                              |
| alpha            | 0.2     | (0, 1]    | 1    | platelet roughness alpha_p                          |
| theta            | 0.0     | [0, pi/2] | rad  | platelet mean-normal tilt theta_p about x           |
| thickness        | 16      | [0, 1e3]  | mfp  | layer thickness t in base mean free paths           |
| base_reflectance | 0.0     | [0, 1]    | 1    | albedo of the Lambertian base (RGB)                 |
| eta              | 1.0     | [1, 3]    | 1    | host index under a smooth top interface (1: none)   |

Static settings: ``azimuth`` ("averaged": over rotations of the sample about the normal, the
in-plane measurement of an unoriented sample, decision D4; "fixed": tilt about x), ``n_nodes``
(Gauss cosines per hemisphere, 24) and ``n_modes`` (azimuthal Fourier modes, 24). Presets:
Padrón Table A.1 (``dewy1``, ``dewy2``, ``matte1``, ``matte2``; t = 16, black base), as for
``cosmetics``. The sampler draws the cosine-weighted hemisphere (weight f pi).

Example::

    import jax.numpy as jnp
    from appearance_jax.bsdf import cosmetics_ordinates as co
    from appearance_jax.core.frame import in_plane_directions
    wi, wo = in_plane_directions(jnp.deg2rad(30.0), jnp.deg2rad(jnp.arange(-80.0, 81.0, 10.0)))
    f = co.eval(co.PRESETS["dewy1"], wi, wo)   # (17, 3) linear RGB, 1/sr
"""

from __future__ import annotations

import math
import warnings

import jax.numpy as jnp
import numpy as np

from ..core import warp
from ..core.model import Model, boundary, with_bands
from ..core.params import Bands, integer, param, params_class, Real, static
from ..core.rng import uniforms
from ..core.vec import Vec3
from ..layered import medium, ordinates
from .cosmetics import N_BANDS, TABLE_A1, check_bands

AZIMUTH_MODES = ("averaged", "fixed")
#: relative energy error of the discretised diffuser phase function above which Params warns
RESOLUTION_WARN = 2e-3


@params_class
class Params(medium.Params):
    """Padrón Table 4.1 (the medium's fields), the layer thickness, the base and the interface."""

    thickness: Real = param(16.0, lo=0.0, hi=1e3, unit="mfp", doc="layer thickness t in base mean free paths")
    base_reflectance: Bands = param(0.0, lo=0.0, hi=1.0, unit="1", doc="albedo of the Lambertian base",
                                     bands=True)
    eta: Real = param(1.0, lo=1.0, hi=3.0, unit="1", doc="host index under a smooth top interface (1: none)")
    azimuth: str = static("averaged", choices=AZIMUTH_MODES,
                          doc="'averaged' over rotations about the normal, or 'fixed' (tilt about x)")
    n_nodes: int = static(24, convert=integer(4, 96), doc="Gauss-Legendre polar cosines per hemisphere")
    n_modes: int = static(24, convert=integer(1, 96), doc="azimuthal Fourier modes")
    tilt_correction: bool = static(True, choices=(True, False),
                                   doc="correct the multiply scattered light of tilted platelets from their azimuth "
                                       "mixture to the oriented medium (a coarse full-azimuth solve)")

    def _validate(self):
        check_bands(self, "cosmetics_ordinates")
        err = resolution_error(self)
        if err is not None and err > RESOLUTION_WARN:
            warnings.warn(f"cosmetics_ordinates: n_nodes = {self.n_nodes}, n_modes = {self.n_modes} resolve the "
                          f"diffusers' phase function (g1 = {float(self.g1):.4g}, g2 = {float(self.g2):.4g}) with a "
                          f"relative energy "
                          f"error of {err:.2g} (> {RESOLUTION_WARN:g}); raise n_nodes and n_modes", stacklevel=3)


def settings(p: Params) -> ordinates.Settings:
    return ordinates.Settings(n_nodes=p.n_nodes, n_modes=p.n_modes, n_az=max(192, 8 * p.n_modes),
                              tilt=p.tilt_correction)


def resolution_error(p: Params):
    """Largest relative error, over the node cosines, of the discretised diffusers' phase
    function's energy (the Gauss x azimuth rule the solver uses; the mode truncation at
    ``n_modes`` adds nothing to the energy, only to the angular detail), or None for traced
    parameters. Measured at the defaults: Dewy 2 (g1 = 0.77) 4e-8; g1 = 0.95: 6e-2."""
    try:
        w, g1, g2 = (float(np.asarray(v)) for v in (p.w_g, p.g1, p.g2))
    except Exception:  # traced inside jit: nothing to measure eagerly
        return None
    s = settings(p)
    x, wq = np.polynomial.legendre.leggauss(s.n_nodes)
    mu = np.concatenate([0.5 * (x + 1.0), -0.5 * (x + 1.0)])
    wt = np.concatenate([0.5 * wq, 0.5 * wq])
    dphi = 2.0 * np.pi * np.arange(s.n_az) / s.n_az
    mi = 0.5 * (x + 1.0)
    c = (np.sqrt(1 - mi**2)[:, None, None] * np.sqrt(1 - mu**2)[None, :, None] * np.cos(dphi)[None, None, :]
         + mi[:, None, None] * mu[None, :, None])
    def hg(g):  # phase.henyey_greenstein.hg_value in numpy: no JAX dispatch when Params are built
        base = 1.0 + g * g + 2.0 * g * np.clip(c, -1.0, 1.0)
        return (1.0 - g * g) / (4.0 * np.pi * base * np.sqrt(base))

    f = w * hg(g1) + (1.0 - w) * hg(g2)
    total = np.einsum("iok,o->i", f, wt) * (2.0 * np.pi / s.n_az)
    return float(np.max(np.abs(total - 1.0)))


def _media(p: Params):
    def field(name):
        v = jnp.asarray(getattr(p, name), jnp.result_type(float))
        if name in medium.BAND_FIELDS:
            v = jnp.broadcast_to(jnp.atleast_1d(v), (N_BANDS,))
        return v[None]
    return medium.Params(**{n: field(n) for n in medium.FIELDS})


def _eval(p: Params, wi: Vec3, wo: Vec3):
    dtype = jnp.result_type(float)
    base = jnp.broadcast_to(jnp.atleast_1d(jnp.asarray(p.base_reflectance, dtype)), (N_BANDS,))
    f = ordinates.brdf_traced(_media(p), jnp.asarray(p.thickness, dtype)[None], wi, wo, base=base,
                              eta=jnp.asarray(p.eta, dtype), azimuth=p.azimuth, settings=settings(p))
    return f


def _pdf(p: Params, wi: Vec3, wo: Vec3):
    return jnp.where((wi.z > 0) & (wo.z > 0), warp.square_to_cosine_hemisphere_pdf(wo), 0.0)


def _sample(p: Params, wi: Vec3, u):
    u1, u2 = uniforms(u, jnp.shape(wi.z), 2)
    wo = warp.square_to_cosine_hemisphere(u1, u2)
    ok = (wi.z > 0) & (wo.z > 0)
    pdf = jnp.where(ok, warp.square_to_cosine_hemisphere_pdf(wo), 0.0)
    weight = jnp.where(with_bands(ok), _eval(p, wi, wo) * math.pi, 0.0)
    return wo, weight, pdf


eval = boundary(_eval, Params)
pdf = boundary(_pdf, Params)
sample = boundary(_sample, Params)

_DEG = math.pi / 180.0
PRESETS = {k: Params(**{**v, "theta": v["theta"] * _DEG}) for k, v in TABLE_A1.items()}

MODEL = Model(
    name="cosmetics_ordinates",
    kind="bsdf",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="cosmetic foundation (diffusers + SGGX platelets over a Lambertian base, optional dielectric top), "
            "deterministic: discrete ordinates x azimuthal modes, adding-doubling; exact gradients",
    source="Ch. 4 and Table A.1, Padrón 2025 (seed-000 spec M15, M35, M36); van de Hulst 1980 (adding-doubling)",
    reciprocal=True,
    presets=PRESETS,
    fit_fixed={"thickness": (16.0, "the thesis' fitted layers are optically thick (t = 16 mfp [T:774])"),
               "eta": (1.0, "index-matched cosmetic layers [T:618, 653]")},
    band_separable=True,
)
