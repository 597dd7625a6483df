"""Fiber BCSDFs (hair; later threads and barbules): functions of fiber-frame directions.

Every model here takes unit directions in the fiber frame (x = tangent, root -> tip;
:func:`appearance_jax.core.frame.fiber_direction`), returns S(omega_i, omega_o) in 1/sr with
the albedo int S cos(theta_o) d omega_o, and measures absorption per unit radius.

- :mod:`.fiber`: the shared geometry and absorption conventions (Bravais indices, projected
  width of elliptical fibers, smooth-cylinder lobes, melanin and colour -> sigma_a).
- :mod:`.chiang`: d'Eon et al. 2011 / Chiang et al. 2016, importance-sampled (``chiang_hair``).
- :mod:`.marschner`: Marschner et al. 2003 (``marschner_hair``).
- :mod:`.sadeghi`: Sadeghi 2011's artist-friendly hair (``sadeghi_hair``); :mod:`.dual_scattering`:
  its dual-scattering approximation for a hair volume (Sadeghi §4.7, Zinke et al. 2008).
- :mod:`.huang`: Huang 2022's microfacet hair, Monte Carlo-Simpson TT/TRT (``huang_hair``).

Reference for all of them: the flatland tracer, :mod:`appearance_jax.flatland`.
"""
