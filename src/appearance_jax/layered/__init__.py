"""Plane-parallel layered media: the cosmetic medium (M15), its random walk and deterministic references.

- :mod:`.medium`: the anisotropic medium of the cosmetic foundations (diffusers + SGGX
  platelets; Padrón Eqs. 4.3-4.10): extinction, albedo, phase function, collision kernel.
- :mod:`.single_scattering`: the closed-form single-scattering BRDF of a slab (spec M35).
- :mod:`.h_function`: Chandrasekhar's H-function, semi-infinite isotropic media (spec M34).
- :mod:`.adding_doubling`: adding-doubling solver for stacks of HG-mixture slabs over a
  Lambertian bottom (spec M36): deterministic and differentiable.
- :mod:`.random_walk`: the position-free Monte Carlo random walk (Padrón Ch. 4) that evaluates
  any stack: the reference of the cosmetics BSDF.
"""
