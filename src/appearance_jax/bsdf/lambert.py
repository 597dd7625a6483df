"""Lambertian (ideal diffuse) reflector: f = rho / pi.

Energy conserving for rho <= 1 (white furnace: the albedo equals rho exactly), reciprocal,
importance-sampled with the cosine-weighted hemisphere (weight = rho).

| parameter   | default | range  | unit | meaning                                   |
|-------------|---------|--------|------|-------------------------------------------|
| reflectance | 0.5     | [0, 1] | 1    | diffuse albedo per band (RGB or spectral) |

Example::

    from appearance_jax.bsdf import lambert
    from appearance_jax.core.frame import spherical_direction
    wi = spherical_direction(0.3, 0.0); wo = spherical_direction(0.5, 2.0)
    f = lambert.eval(lambert.Params(reflectance=(0.8, 0.5, 0.2)), wi, wo)   # shape (3,), 1/sr
"""

from __future__ import annotations

import jax.numpy as jnp

from ..core import warp
from ..core.model import Model, as_bands, boundary, with_bands
from ..core.params import Bands, param, params_class
from ..core.rng import uniforms
from ..core.vec import Vec3


@params_class
class Params:
    reflectance: Bands = param(0.5, lo=0.0, hi=1.0, unit="1", doc="diffuse albedo per band", bands=True)


def _active(wi: Vec3, wo: Vec3):
    return (wi.z > 0) & (wo.z > 0)


def _eval(p: Params, wi: Vec3, wo: Vec3):
    rho = as_bands(p.reflectance)
    return jnp.where(with_bands(_active(wi, wo)), rho / jnp.pi, 0.0)


def _pdf(p: Params, wi: Vec3, wo: Vec3):
    return jnp.where(_active(wi, wo), warp.square_to_cosine_hemisphere_pdf(wo), 0.0)


def _sample(p: Params, wi: Vec3, u):
    u1, u2 = uniforms(u, jnp.shape(wi.z), 2)
    wo = warp.square_to_cosine_hemisphere(u1, u2)
    ok = _active(wi, wo)
    pdf = jnp.where(ok, warp.square_to_cosine_hemisphere_pdf(wo), 0.0)
    weight = jnp.where(with_bands(ok), as_bands(p.reflectance), 0.0)
    return wo, weight, pdf


eval = boundary(_eval, Params)
pdf = boundary(_pdf, Params)
sample = boundary(_sample, Params)

MODEL = Model(
    name="lambert",
    kind="bsdf",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="ideal diffuse reflector f = rho / pi",
    source="Lambert (1760); background model in all three theses",
    reciprocal=True,
    jacobian_apart=("reflectance",),  # next to another lobe in a sum (alone it is the only field)
    band_separable=True,
)
