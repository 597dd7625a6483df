"""Henyey-Greenstein phase function (Padrón Eq. C.2; Henyey & Greenstein 1941).

    f_HG(wi, wo) = 1/(4 pi) * (1 - g^2) / (1 + g^2 + 2 g cos)^(3/2),   cos = wi . wo    [1/sr]

Convention (seed-000 spec M12, "convention warning"): both directions point **away** from
the scattering point, so light propagates along d = -wi and ``cos = wi . wo = -(d . wo)``.
With the "+2g cos" sign of the thesis the lobe is forward (peak at wo = -wi) for g > 0,
backward for g < 0, isotropic (1/(4 pi)) for g = 0, and the mean cosine of the scattered
direction with the propagation direction, <d . wo>, equals g. This is the pbrt-v3/v4 and
Mitsuba 3 convention (Mitsuba's ``MediumInteraction3f.wi`` also points away from the
scatterer, so ``hg.eval(ctx, mi, wo)`` with ``mi.wi = wi`` equals ``eval(params, wi, wo)``;
checked in tests/validation/test_mitsuba_hg.py).

Phase functions are defined over the whole sphere: no horizon, no cosine factor;
``sample`` returns ``weight = f / pdf``.

| parameter | default | range   | unit | meaning                                                   |
|-----------|---------|---------|------|-----------------------------------------------------------|
| g         | 0.0     | (-1, 1) | 1    | asymmetry = mean cosine <d . wo>; per band (RGB/spectral) |

Sampling (CDF inversion, "usual" in the thesis [T:736]; derivation here). With a = 2 xi - 1
and D = 1 + g a, the textbook inversion
``mu = (1 + g^2 - ((1 - g^2) / D)^2) / (2 g)`` of ``mu = cos(d, wo)`` can be rewritten as

    1 + mu = 2 xi (1 + g)^2 (1 - g (1 - xi)) / D^2
    1 - mu = 2 (1 - xi) (1 - g)^2 (1 + g xi) / D^2

(factor the numerators; every factor is positive for |g| < 1). This form has no 1/g, so it
needs no |g| < eps switch: it is exact at g = 0 (mu = 2 xi - 1) and smooth in g, which gives
sampled directions finite, exact gradients w.r.t. g (reparameterisation); it also computes
sin(theta) = sqrt((1 - mu)(1 + mu)) without cancellation near the poles.

Band-valued g: ``eval`` is per band. The sampler needs one density, so it samples the HG
lobe of the **band mean** ``g_s = mean(g)`` and returns ``pdf = f_HG(g_s)`` and the per-band
``weight = f_HG(g_b) / f_HG(g_s)`` (1 up to rounding when g has a single band). ``pdf(params, ...)``
is that same density. The estimator stays unbiased per band, with higher variance the more
the bands' g differ.

Example::

    from appearance_jax.phase import henyey_greenstein as hg
    from appearance_jax.core.frame import spherical_direction
    wi = spherical_direction(0.3, 0.0); wo = spherical_direction(2.5, 3.0)
    f = hg.eval(hg.Params(g=0.7), wi, wo)                 # shape (1,), 1/sr
    wo, w, pdf = hg.sample(hg.Params(g=0.7), wi, jax.random.key(0))
"""

from __future__ import annotations

import jax.numpy as jnp

from ..core.frame import orthonormal_basis
from ..core.model import Model, as_bands, boundary, with_bands
from ..core.params import Bands, param, params_class
from ..core.rng import uniforms
from ..core.special import safe_sqrt
from ..core.vec import Vec3, dot

INV_4PI = 0.25 / jnp.pi


@params_class
class Params:
    g: Bands = param(0.0, lo=-1.0, hi=1.0, lo_open=True, hi_open=True, unit="1",
                      doc="asymmetry parameter (mean cosine); > 0 forward, < 0 backward", bands=True)


# ------------------------------------------------------------------------------------
# building blocks, shared with the HG mixture (phase/hg_mixture.py)


def hg_value(g, cos_wi_wo):
    """f_HG for asymmetry ``g`` and ``cos = wi . wo`` (both pointing away), Padrón Eq. C.2 [1/sr].

    Broadcasts ``g`` against ``cos``. ``1 + g^2 + 2 g cos >= (1 - |g|)^2 > 0`` for |g| < 1,
    so no guard is needed; ``cos`` is clipped to [-1, 1] because a dot product of
    unit vectors rounds slightly outside it.
    """
    c = jnp.clip(cos_wi_wo, -1.0, 1.0)
    base = 1.0 + g * g + 2.0 * g * c
    return INV_4PI * (1.0 - g * g) / (base * jnp.sqrt(base))


def sample_cos(g, xi):
    """Invert the HG CDF: ``(mu, sin_theta)`` of the scattered direction about d = -wi.

    ``mu = d . wo`` is distributed with density proportional to f_HG (see the module
    docstring for the cancellation-free form used here). ``g`` and ``xi`` broadcast.
    """
    d = 1.0 + g * (2.0 * xi - 1.0)
    inv_d2 = 1.0 / (d * d)
    one_plus = 2.0 * xi * (1.0 + g) ** 2 * (1.0 - g * (1.0 - xi)) * inv_d2
    one_minus = 2.0 * (1.0 - xi) * (1.0 - g) ** 2 * (1.0 + g * xi) * inv_d2
    mu = jnp.clip(0.5 * (one_plus - one_minus), -1.0, 1.0)
    sin_theta = safe_sqrt(one_plus * one_minus)
    return mu, jnp.minimum(sin_theta, 1.0)


def direction_about(wi: Vec3, mu, sin_theta, phi) -> Vec3:
    """The direction at polar cosine ``mu`` and azimuth ``phi`` about the propagation d = -wi."""
    d = -wi
    s, t = orthonormal_basis(d)
    return s * (sin_theta * jnp.cos(phi)) + t * (sin_theta * jnp.sin(phi)) + d * mu


def sampling_g(g):
    """The single asymmetry a band-valued ``g`` is sampled with: the band mean."""
    return jnp.mean(as_bands(g), axis=-1)


# ------------------------------------------------------------------------------------
# kernels


def _eval(p: Params, wi: Vec3, wo: Vec3):
    return hg_value(as_bands(p.g), with_bands(dot(wi, wo)))


def _pdf(p: Params, wi: Vec3, wo: Vec3):
    return hg_value(sampling_g(p.g), dot(wi, wo))


def _sample(p: Params, wi: Vec3, u):
    shape = jnp.broadcast_shapes(jnp.shape(wi.z), jnp.shape(sampling_g(p.g)))
    u1, u2 = uniforms(u, shape, 2)
    gs = sampling_g(p.g)
    mu, sin_theta = sample_cos(gs, u1)
    wo = direction_about(wi, mu, sin_theta, 2.0 * jnp.pi * u2)
    # pdf from the same cosine the evaluation sees, so weight = f / pdf holds to rounding
    c = dot(wi, wo)
    pdf = hg_value(gs, c)
    weight = hg_value(as_bands(p.g), with_bands(c)) / with_bands(pdf)
    return wo, weight, pdf


eval = boundary(_eval, Params)
pdf = boundary(_pdf, Params)
sample = boundary(_sample, Params)

MODEL = Model(
    name="henyey_greenstein",
    kind="phase",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="Henyey-Greenstein phase function, asymmetry g (both directions point away; g > 0 forward)",
    source="Eq. C.2, Padrón 2025 (seed-000 spec M12); Henyey & Greenstein 1941",
    reciprocal=True,
    transmissive=True,
    presets={"isotropic": Params(g=0.0), "forward": Params(g=0.7), "backward": Params(g=-0.3)},
)
