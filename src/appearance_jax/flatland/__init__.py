"""Flatland (2.5D) tracer: 2D cross-sections with 3D directions, the ground truth for fiber,
drop and barbule models (spec seed-001 §4, seed-000 §5 and M22, seed-002 §1.2.5).

- :mod:`.geometry`: exact ellipse / arc / segment intersection (no epsilons), normals, tangent
  points.
- :mod:`.section`: cross-sections (:class:`Section`), builders :func:`fiber`,
  :func:`cylinder`, :func:`ellipse_row`, :func:`segment`; semi-transparent shapes (an
  interface's ``coverage``).
- :mod:`.interfaces`: the scattering events (smooth / rough dielectric, thin film, diffuse).
- :mod:`.tracer`: :func:`trace`, the scan over events with per-lobe emissions.
- :mod:`.tallies`: far-field histograms and the BCSDF (:func:`trace_fiber`,
  :func:`bcsdf_from_histogram`), per-lobe albedo, the deterministic smooth mode
  (:func:`smooth_lobes`), the camera-side next-event estimator (:func:`nee_bcsdf`), masking
  tallies of periodic rows (:func:`first_hits`: per-shape first-hit fractions and offsets).
- :mod:`.polar_curve`, :mod:`.drop`: water drops (a circle or the Beard–Chuang meridian,
  Sadeghi Eq. 3.1) and the deterministic fan tracer :func:`trace_drop` returning a
  :class:`Fan` (:mod:`.fan`: amplitudes, optical paths, foci and axis counts per path family).
- :mod:`.feather`: the feather mode, a row of rock-dove barbule arcs with a random longitudinal
  tilt per hit (:func:`barbule_row`, :func:`feather_histogram`), the reference of
  :mod:`appearance_jax.bsdf.rock_dove`.
- :mod:`.farfield`: far-field collectors of a fan (coherent, incoherent, KDE; cylinder and
  axisymmetric sphere lifts): :func:`far_field`, :func:`far_field_amplitude`,
  :func:`family_energy`.
"""

from .section import Interface, Medium, Section, Shape, cylinder, ellipse_row, fiber, segment
from .tracer import Records, launch, n_bands, trace
from .tallies import (BCSDF, FirstHits, Histogram, SmoothLobes, bcsdf_from_histogram, first_hits,
                      masking_fraction, nee_bcsdf, smooth_lobes, trace_fiber)
from .caustics import Caustics, caustics
from .fan import Fan
from .polar_curve import PolarCurve, beard_chuang, beard_chuang_coefficients, circle_curve, cosine_series
from .drop import impact_grid, trace_drop
from .farfield import far_field, far_field_amplitude, family_energy
from .feather import FeatherHistogram, barbule_row, feather_histogram
