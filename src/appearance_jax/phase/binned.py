"""Sampling a phase function from a density that is piecewise constant in mu = cos(theta)
over fixed bins (theta from the propagation direction d = -wi): the tabulated-CDF sampler
shared by :mod:`.mie` and :mod:`.tabulated`.

Bins are given by decreasing ``edges`` in mu (from 1 to -1) and their probabilities; inside
bin j the density over the sphere is ``prob[j] / (2 pi (edges[j] - edges[j+1]))``. Mixing a
little of the uniform density (:func:`probabilities`) keeps it positive everywhere, so
``weight = f / pdf`` is unbiased whatever the bins' resolution.
"""

from __future__ import annotations

import jax.numpy as jnp

from ..core.rng import uniforms
from ..core.vec import dot
from .henyey_greenstein import direction_about

#: weight of the uniform density mixed into the bin probabilities
UNIFORM_MIX = 0.01


def probabilities(mass, edges, mix=UNIFORM_MIX):
    """Bin probabilities from (unnormalised) bin masses, mixed with ``mix`` of the uniform density."""
    width = edges[:-1] - edges[1:]
    prob = (1.0 - mix) * mass / jnp.sum(mass) + mix * 0.5 * width
    return prob / jnp.sum(prob)


def density(edges, prob, mu):
    """Density over the sphere [1/sr] at ``mu`` (any shape)."""
    # bin j holds edges[j] >= mu > edges[j + 1]
    j = jnp.clip(jnp.searchsorted(-edges, -jnp.clip(mu, -1.0, 1.0), side="right") - 1, 0, prob.shape[0] - 1)
    return prob[j] / (2.0 * jnp.pi * (edges[j] - edges[j + 1]))


def sample(edges, prob, wi, u):
    """``(wo, mu)``: a direction about ``d = -wi`` drawn from the binned density (three uniforms
    of ``u``, or a key), with ``mu = -(wi . wo)`` recomputed from ``wo`` so that the density
    and the phase function see the same cosine."""
    u1, u2, u3 = uniforms(u, jnp.shape(wi.z), 3)
    cdf = jnp.concatenate([jnp.zeros((1,), prob.dtype), jnp.cumsum(prob)])
    j = jnp.clip(jnp.searchsorted(cdf, u1 * cdf[-1], side="right") - 1, 0, prob.shape[0] - 1)
    mu = jnp.clip(edges[j] - u2 * (edges[j] - edges[j + 1]), -1.0, 1.0)
    sin_t = jnp.sqrt(jnp.maximum((1.0 - mu) * (1.0 + mu), 0.0))
    wo = direction_about(wi, mu, sin_t, 2.0 * jnp.pi * u3)
    return wo, jnp.clip(-dot(wi, wo), -1.0, 1.0)
