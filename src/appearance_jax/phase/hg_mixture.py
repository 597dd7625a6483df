"""Two-lobe Henyey-Greenstein mixture (Padrón Eq. 4.9; seed-000 spec M13).

    f(wi, wo) = w_g f_HG(wi, wo | g1) + (1 - w_g) f_HG(wi, wo | g2)        [1/sr]

with f_HG of :mod:`appearance_jax.phase.henyey_greenstein` (Padrón Eq. C.2; both directions
point away from the scatterer, g > 0 scatters forward, towards wo = -wi). The phase
function of the cosmetic diffusers (Padrón Ch. 4; fitted values in Padrón Table A.1), motivated by
measured TiO2 colloids: a forward and a backward lobe. ``w_g = 1`` is the single lobe
HG(g1). Normalised (integrates to 1 over the sphere) for every parameter value.

| parameter | default | range   | unit | meaning                                  |
|-----------|---------|---------|------|------------------------------------------|
| w_g       | 0.5     | [0, 1]  | 1    | weight of lobe 1, per band               |
| g1        | 0.5     | (-1, 1) | 1    | asymmetry of lobe 1 (mean cosine), per band |
| g2        | -0.3    | (-1, 1) | 1    | asymmetry of lobe 2 (mean cosine), per band |

Presets: the diffuser lobes of the four foundations of Padrón Table A.1 (``dewy1`` ... ``matte2``).

Sampling (spec M13/M27): one uniform picks the lobe, lobe 1 with probability w_g, and is
then rescaled to [0, 1) and reused for the HG inversion of that lobe ("Shirley's
remapping"); the second uniform gives the azimuth. ``pdf = f`` for single-band parameters,
so ``weight = f / pdf = 1``.

Band-valued parameters: the sampler uses the band means of (w_g, g1, g2) for the lobe
choice and the lobe shapes, returns the density of that mixture as ``pdf`` and the
per-band ``weight = f_b / pdf`` (unbiased per band; ``pdf(params, ...)`` is the same
density).

Gradients through ``sample``: directions are reparameterised smoothly in g1, g2 (HG
inversion). The lobe choice is a discrete event whose boundary moves with w_g, which a
pathwise derivative cannot see, so it is made with ``stop_gradient(w_g)`` and the returned
weight ``f / pdf`` keeps w_g live in f only: its value is 1 and its derivative
``(d f / d w_g) / pdf`` is the score term (seed-000 spec §6.4, "discrete choices").
The sampled directions and the ``pdf`` returned by ``sample`` therefore carry no gradient
w.r.t. w_g (a finite difference of a sampled direction w.r.t. w_g is not 0: the remapped
uniform moves; that dependence is deliberately replaced by the score term); ``pdf()`` is
differentiable in all parameters. Expectations ``E[h(wo) weight]`` get unbiased gradients
in all three parameters (tests/phase/test_hg_mixture.py).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..core.model import Model, as_bands, boundary, with_bands
from ..core.params import Bands, param, params_class
from ..core.rng import uniforms
from ..core.vec import Vec3, dot
from .henyey_greenstein import direction_about, hg_value, sample_cos, sampling_g

# largest float below 1 in float32; keeps a remapped uniform inside [0, 1)
_ONE_MINUS = 1.0 - 2.0**-24


@params_class
class Params:
    w_g: Bands = param(0.5, lo=0.0, hi=1.0, unit="1", doc="weight of HG lobe 1", bands=True)
    g1: Bands = param(0.5, lo=-1.0, hi=1.0, lo_open=True, hi_open=True, unit="1",
                       doc="asymmetry of HG lobe 1", bands=True)
    g2: Bands = param(-0.3, lo=-1.0, hi=1.0, lo_open=True, hi_open=True, unit="1",
                       doc="asymmetry of HG lobe 2", bands=True)


def mixture_value(w, g1, g2, cos_wi_wo):
    """Padrón Eq. 4.9: ``w f_HG(g1) + (1 - w) f_HG(g2)`` at ``cos = wi . wo`` [1/sr] (broadcasts)."""
    return w * hg_value(g1, cos_wi_wo) + (1.0 - w) * hg_value(g2, cos_wi_wo)


def _sampling_params(p: Params):
    """One (w, g1, g2) for the sampler: the band means (see the module docstring)."""
    return sampling_g(p.w_g), sampling_g(p.g1), sampling_g(p.g2)


def _eval(p: Params, wi: Vec3, wo: Vec3):
    return mixture_value(as_bands(p.w_g), as_bands(p.g1), as_bands(p.g2), with_bands(dot(wi, wo)))


def _pdf(p: Params, wi: Vec3, wo: Vec3):
    w, g1, g2 = _sampling_params(p)
    return mixture_value(w, g1, g2, dot(wi, wo))


def _sample(p: Params, wi: Vec3, u):
    w, g1, g2 = _sampling_params(p)
    w = jax.lax.stop_gradient(w)  # discrete lobe choice: no pathwise gradient (docstring)
    shape = jnp.broadcast_shapes(jnp.shape(wi.z), jnp.shape(w), jnp.shape(g1), jnp.shape(g2))
    u1, u2 = uniforms(u, shape, 2)
    first = u1 < w
    # Shirley's remapping: rescale the part of u1 that chose the lobe back to [0, 1);
    # the inner where()s keep both branches finite at w = 0 and w = 1.
    xi = jnp.where(first, u1 / jnp.where(w > 0, w, 1.0), (u1 - w) / jnp.where(w < 1, 1.0 - w, 1.0))
    xi = jnp.clip(xi, 0.0, _ONE_MINUS)
    mu, sin_theta = sample_cos(jnp.where(first, g1, g2), xi)
    wo = direction_about(wi, mu, sin_theta, 2.0 * jnp.pi * u2)
    c = dot(wi, wo)
    pdf = mixture_value(w, g1, g2, c)
    f = mixture_value(as_bands(p.w_g), as_bands(p.g1), as_bands(p.g2), with_bands(c))
    return wo, f / with_bands(pdf), pdf


eval = boundary(_eval, Params)
pdf = boundary(_pdf, Params)
sample = boundary(_sample, Params)

# Padrón Table A.1 (diffuser lobes of the four fitted foundations, [T:1202-1213])
PRESETS = {
    "dewy1": dict(w_g=1.0, g1=0.55, g2=0.09),
    "dewy2": dict(w_g=0.79, g1=0.77, g2=-0.23),
    "matte1": dict(w_g=0.62, g1=0.37, g2=-0.25),
    "matte2": dict(w_g=0.51, g1=0.24, g2=-0.22),
}

MODEL = Model(
    name="hg_mixture",
    kind="phase",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="two-lobe Henyey-Greenstein mixture w_g HG(g1) + (1 - w_g) HG(g2)",
    source="Eq. 4.9, Padrón 2025 (seed-000 spec M13); Table A.1 presets",
    reciprocal=True,
    transmissive=True,
    presets={k: Params(**v) for k, v in PRESETS.items()},
)
