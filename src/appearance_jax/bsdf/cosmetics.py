"""Cosmetic foundation: layers of diffusers and platelets over a base (Ch. 4, Padrón 2025;
Lanza, Padrón-Griffé et al. 2024; seed-000 spec §2.2, M15, M16).

Each cosmetic layer is an index-matched, laterally infinite slab of thickness ``t`` (base
mean free paths) filled with spherical diffusers (two-lobe HG, Padrón Eq. 4.9) and SGGX
platelets (specular microflakes, Padrón Eq. 4.10) with direction-dependent extinction and
albedo (Padrón Eqs. 4.3-4.8: :mod:`appearance_jax.layered.medium`). Below the layer lies a Lambertian base of
albedo ``base_reflectance`` (0: the black matte polymer of the thesis' measurements [T:749])
or, through :func:`eval_stack`, any BSDF of this library and any number of cosmetic layers
(dewy over matte, Padrón Fig. 4.11).

The BSDF has no closed form: :func:`eval` runs the position-free random walk of
:mod:`appearance_jax.layered.random_walk` and returns the estimate **and** its standard error. The
same ``key`` gives the same numbers (common random numbers), so a fit's Jacobian is
consistent; the autodiff derivative is an unbiased estimate of the derivative of f (score
terms for the discrete choices, spec §6.4).

| parameter        | default | range     | unit | meaning                                            |
|------------------|---------|-----------|------|----------------------------------------------------|
| c_d              | 0.9     | [0, 1]    | 1    | relative diffuser concentration (1 - c_d: platelets)|
| albedo_d         | 0.95    | [0, 1]    | 1    | diffuser single-scattering albedo Lambda_d (RGB)   |
| albedo_p         | 0.9     | [0, 1]    | 1    | platelet single-scattering albedo Lambda_p (RGB)   |
| w_g              | 1.0     | [0, 1]    | 1    | weight of the diffusers' HG lobe 1                 |
| g1               | 0.5     | (-1, 1)   | 1    | asymmetry of HG lobe 1                             |
| g2               | -0.2    | (-1, 1)   | 1    | asymmetry of HG lobe 2                             |
| alpha            | 0.2     | (0, 1]    | 1    | platelet roughness alpha_p: highlight shape        |
| theta            | 0.0     | [0, pi/2] | rad  | platelet mean-normal tilt theta_p about x          |
| thickness        | 16      | [0, 1e3]  | mfp  | layer thickness t in base mean free paths          |
| base_reflectance | 0.0     | [0, 1]    | 1    | albedo of the Lambertian base (RGB)                |

Static settings: ``n_samples`` (paths per direction pair, 128 as in the thesis' fits
[T:774]), ``max_bounces`` (steps of the walk; the thesis used up to 512 [T:774]; the energy
lost to truncation is reported in tests/layered/test_random_walk.py), ``azimuth`` ("fixed": the
sample as given, tilt axis x; "averaged": the sample rotated uniformly about the normal, for
in-plane measurements of tilted platelets, decision D4).

Presets: ``dewy1``, ``dewy2``, ``matte1``, ``matte2``: Padrón Table A.1 [T:1202-1213] (t = 16,
black base; theta_p converted from degrees). The thesis' fitted RGB values are linear RGB.

Example::

    import jax
    from appearance_jax.bsdf import cosmetics
    from appearance_jax.core.frame import in_plane_directions
    p = cosmetics.PRESETS["dewy1"]
    wi, wo = in_plane_directions(jnp.deg2rad(30.0), jnp.deg2rad(30.0))   # mirror direction
    f, se = cosmetics.eval(p, wi, wo, key=jax.random.key(0))             # (3,), (3,) in 1/sr

Decisions and their history, validation: docs/cosmetics.md.
"""

from __future__ import annotations

import math
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ..core.model import Model, boundary
from ..core.params import Bands, integer, param, params_class, Real, static, validate
from ..core.vec import as_directions, Vec3
from ..layered import medium
from ..layered.random_walk import Bottom, walk
from ..layered.random_walk import albedo as albedo_walk
from . import lambert

AZIMUTH_MODES = ("fixed", "averaged")
N_BANDS = 3


@params_class
class Params(medium.Params):
    """Padrón Table 4.1: the medium's fields (:class:`appearance_jax.layered.medium.Params`: c_d, albedo_d,
    albedo_p, w_g, g1, g2, alpha, theta), the layer thickness and the base."""

    thickness: Real = param(16.0, lo=0.0, hi=1e3, unit="mfp", doc="layer thickness t in base mean free paths")
    base_reflectance: Bands = param(0.0, lo=0.0, hi=1.0, unit="1", doc="albedo of the Lambertian base",
                                     bands=True)
    n_samples: int = static(128, convert=integer(2, 2**20), doc="random-walk paths per direction pair")
    max_bounces: int = static(256, convert=integer(1, 4096), doc="steps of each random walk")
    azimuth: str = static("fixed", choices=AZIMUTH_MODES,
                          doc="'fixed' sample, or 'averaged' over rotations about the normal")

    def _validate(self):
        check_bands(self, "cosmetics")


def check_bands(p, model: str):
    """The band fields of a cosmetic layer hold a scalar or N_BANDS values (linear RGB)."""
    for name in ("albedo_d", "albedo_p", "base_reflectance"):
        v = np.atleast_1d(np.asarray(getattr(p, name)))
        if v.shape[-1] not in (1, N_BANDS):
            raise ValueError(f"{model}.Params.{name} has {v.shape[-1]} values on its trailing (band) axis: "
                             f"give a scalar or {N_BANDS} (linear RGB)")


def _stack(layers: Sequence[Params]):
    """The walk's inputs: the layers' medium fields stacked along a leading layer axis (band
    fields broadcast to RGB) and their thicknesses (L,)."""
    def field(name):
        vals = [jnp.asarray(getattr(p, name), jnp.result_type(float)) for p in layers]
        if name in medium.BAND_FIELDS:
            vals = [jnp.broadcast_to(jnp.atleast_1d(v), (N_BANDS,)) for v in vals]
        return jnp.stack(vals)
    return medium.Params(**{n: field(n) for n in medium.FIELDS}), field("thickness")


def _walk(layers, base: Bottom | None, wi, wo, key, n_samples, max_bounces, azimuth):
    key = jax.random.key(0) if key is None else key
    media, thickness = _stack(layers)
    return walk(media, thickness, wi, wo, key, bottom=base, n_samples=n_samples,
                max_bounces=max_bounces, azimuth_average=azimuth == "averaged", n_bands=N_BANDS)


def _lambert_base(p: Params) -> Bottom:
    return Bottom(lambert.MODEL, lambert.Params(reflectance=p.base_reflectance))


def _eval(p: Params, wi: Vec3, wo: Vec3, key=None):
    return _walk([p], _lambert_base(p), wi, wo, key, p.n_samples, p.max_bounces, p.azimuth)


eval = boundary(_eval, Params)


def _albedo(p: Params, wi: Vec3, key=None, n_samples: int = 4096):
    key = jax.random.key(0) if key is None else key
    media, thickness = _stack([p])
    a, se, _ = albedo_walk(media, thickness, wi, key, bottom=_lambert_base(p), n_samples=n_samples,
                           max_bounces=p.max_bounces, n_bands=N_BANDS)
    return a, se


albedo = boundary(_albedo, Params, static_argnames=("n_samples",))
albedo.__doc__ = """Directional albedo (diffuse reflectance, 1) of the layer over its base, by counting the
paths that escape (:func:`appearance_jax.layered.random_walk.albedo`): ``(albedo, stderr)``, bands last."""


def eval_stack(layers: Sequence[Params], wi: Vec3, wo: Vec3, key=None, *, base=None):
    """BSDF (estimate, stderr) [1/sr] of cosmetic ``layers`` (top first) over a base.

    ``base``: ``None`` for the Lambertian ``base_reflectance`` of the last layer, or a pair
    ``(model, params)`` of any BSDF of this library (a registry model, e.g.
    ``registry.get("rough_plastic")``), evaluated with its kernels. The sampling settings
    (``n_samples``, ``max_bounces``, ``azimuth``) are the top layer's. Each layer's
    ``thickness`` is its own; the others' base_reflectance is ignored.
    """
    layers = list(layers)
    if not layers:
        raise ValueError("eval_stack needs at least one cosmetic layer")
    for q in layers:
        validate(q, Params)
    if base is None:
        bottom = _lambert_base(layers[-1])
    else:
        model, bp = base
        validate(bp, model.Params)
        if model.sample is None:
            raise ValueError(f"base model {model.name!r} has no sampler; the random walk needs one")
        bottom = Bottom(model, bp)
    wi, wo = as_directions(wi=wi, wo=wo)
    top = layers[0]  # layered.random_walk.walk is jitted: one compilation per base model and settings
    return _walk(layers, bottom, wi, wo, key, top.n_samples, top.max_bounces, top.azimuth)


_DEG = math.pi / 180.0
#: Padrón Table A.1 [T:1202-1213] (verbatim; theta_p in degrees; t = 16)
TABLE_A1 = {
    "dewy1": dict(alpha=0.13, theta=1.47, albedo_p=(0.75, 0.85, 0.99), c_d=0.90, albedo_d=(0.99, 0.98, 0.95),
                  g1=0.55, g2=0.09, w_g=1.0, thickness=16.0),
    "dewy2": dict(alpha=0.002, theta=5.5, albedo_p=(0.8, 0.8, 0.8), c_d=0.99, albedo_d=(0.97, 0.93, 0.87),
                  g1=0.77, g2=-0.23, w_g=0.79, thickness=16.0),
    "matte1": dict(alpha=0.15, theta=2.01, albedo_p=(0.91, 0.89, 0.85), c_d=0.89, albedo_d=(0.95, 0.94, 0.91),
                   g1=0.37, g2=-0.25, w_g=0.62, thickness=16.0),
    "matte2": dict(alpha=0.49, theta=52.2, albedo_p=(0.93, 0.83, 0.71), c_d=0.29, albedo_d=(0.9, 0.9, 0.84),
                   g1=0.24, g2=-0.22, w_g=0.51, thickness=16.0),
}
PRESETS = {k: Params(**{**v, "theta": v["theta"] * _DEG}) for k, v in TABLE_A1.items()}

MODEL = Model(
    name="cosmetics",
    kind="bsdf",
    Params=Params,
    eval=eval,
    sample=None,
    pdf=None,
    summary="cosmetic foundation: diffusers (2-lobe HG) + SGGX platelets in an index-matched slab over a "
            "Lambertian base, position-free Monte Carlo (returns estimate, stderr)",
    source="Ch. 4 and Table A.1, Padrón 2025 (seed-000 spec M15, M16, §2.2); Lanza et al. 2024",
    reciprocal=True,  # within Monte Carlo noise: tests/bsdf/test_cosmetics.py
    stochastic=True,
    presets=PRESETS,
)
