"""Melanin as an absorber and a weak reflector (Huang 2022 App. G; rock-dove barbules, Ch. 5).

- :func:`absorption_coefficient`: alpha = 4 pi k / lambda (1/nm for lambda in nm). Huang App. G
  ([T:2286] of seed 001): n = 1.648 + 0.0632 i at 589 nm gives alpha = 0.0632 x 4 pi / 589 nm =
  1.348e-3 nm^-1.
- :func:`transmittance`: exp(-alpha L): after 2 um of melanin granules 6.7 % of the light is
  left (Huang App. G), why the rock-dove model keeps only one melanin bounce (TRT).
- :func:`normal_reflectance`: |r_am|^2 of an air | melanin interface at normal incidence,
  ((n - 1)^2 + k^2) / ((n + 1)^2 + k^2) = 0.0604 for 1.648 + 0.0632 i, the "about 5 %"
  melanin reflectance Huang cites ([T:1525]). The granules are randomly arranged, so the
  rock-dove model reads r_am as a diffuse (angle-free) reflectance: this normal-incidence
  value is our choice (docs/rock_dove.md).

Lengths in nm; everything broadcasts and is differentiable.
"""

from __future__ import annotations

import jax.numpy as jnp

# Huang 2022 [T:2286] (seed 001), after Stavenga et al.: melanin at 589 nm
MELANIN_N = 1.648
MELANIN_K = 0.0632


def absorption_coefficient(k, wavelength_nm):
    """alpha = 4 pi k / lambda, in 1/nm for lambda in nm."""
    return 4.0 * jnp.pi * jnp.asarray(k) / jnp.asarray(wavelength_nm)


def transmittance(k, wavelength_nm, length_nm):
    """Beer-Lambert exp(-alpha L) through ``length_nm`` of a medium of extinction ``k``."""
    return jnp.exp(-absorption_coefficient(k, wavelength_nm) * jnp.asarray(length_nm))


def normal_reflectance(n, k=0.0, n_outside=1.0):
    """Fresnel reflectance at normal incidence of ``n_outside | n + i k``."""
    n, k, n0 = jnp.asarray(n), jnp.asarray(k), jnp.asarray(n_outside)
    return ((n - n0) ** 2 + k * k) / ((n + n0) ** 2 + k * k)


__all__ = ["MELANIN_N", "MELANIN_K", "absorption_coefficient", "transmittance", "normal_reflectance"]
