"""Closed-form single scattering of an index-matched slab (seed-000 spec M35, derived from the
RTE with the cosmetic medium of Padrón Eqs. 4.3-4.10).

For collimated light from wi on a slab of thickness t (in base mean free paths, sigma_base
= 1) over nothing, the once-scattered light leaving towards wo is

    f_ss(wi, wo) = sigma_t(wi) Lambda(wi) f(wi -> wo)
                   [1 - exp(-t (sigma_t(wi) / mu_i + sigma_t(wo) / mu_o))]
                   / (sigma_t(wi) mu_o + sigma_t(wo) mu_i)                         [1/sr]

(integrate the collision density sigma_t(wi)/mu_i exp(-sigma_t(wi) z / mu_i) over depth z
against the scattering Lambda f and the escape exp(-sigma_t(wo) z / mu_o)). It is
reciprocal because sigma_s f is (Padrón Eq. 4.8 discussion, [T:710]) and is the first-order term
of the random walk :func:`appearance_jax.layered.random_walk.walk` (checked in tests/layered). For pure
platelets aligned with the normal and t -> infinity it tends to Lambda_p D(wh) / (8 mu_i mu_o).
"""

from __future__ import annotations

import jax.numpy as jnp

from ..core.model import with_bands
from ..core.vec import Vec3
from . import medium


def brdf(m, thickness, wi: Vec3, wo: Vec3):
    """f_ss(wi, wo) in 1/sr (bands last) of a slab of medium ``m`` (:mod:`.medium` fields).

    ``thickness`` >= 0 in mean free paths (``jnp.inf`` for a half-space). Directions at or
    below the horizon give 0.
    """
    ok = (wi.z > 0) & (wo.z > 0)
    mi = jnp.where(ok, wi.z, 1.0)
    mo = jnp.where(ok, wo.z, 1.0)
    si = medium.extinction(m, wi)
    so = medium.extinction(m, wo)
    tau = thickness * (si / mi + so / mo)
    escape = -jnp.expm1(-tau)
    value = with_bands(si * escape / (si * mo + so * mi)) * medium.scattering(m, wi, wo)
    return jnp.where(with_bands(ok), value, 0.0)
