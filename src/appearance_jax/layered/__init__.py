"""Plane-parallel layered media: the cosmetic medium (M15) and deterministic references.

- :mod:`.medium`: the anisotropic medium of the cosmetic foundations (diffusers + SGGX
  platelets; Padrón Eqs. 4.3-4.10): extinction, albedo, phase function, collision kernel.
- :mod:`.single_scattering`: the closed-form single-scattering BRDF of a slab (spec M35).
- :mod:`.h_function`: Chandrasekhar's H-function, semi-infinite isotropic media (spec M34).
- :mod:`.adding_doubling`: adding-doubling solver for stacks of HG-mixture slabs over a
  Lambertian bottom (spec M36): deterministic and differentiable.

The Monte Carlo random walk that evaluates any stack is :mod:`appearance_jax.mc.layered`.
"""
