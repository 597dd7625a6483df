"""A 1-D fan of rays through a 2-D drop or fiber section, with the wave data the far-field
collectors need (Sadeghi 2011 §3.4.3, spec seed-002 §1.2.5 and §4 items 4–5).

A fan is what a tracer hands to :mod:`appearance_jax.flatland.farfield`: ``N`` rays of a
collimated beam launched at sorted impact parameters ``s`` and followed through ``F`` static
path families; family index = ``p`` = number of chords inside the drop (0 = R, 1 = TT,
2 = TRT = primary bow, 3 = TRRT = secondary bow, ..., F - 1). Adjacent rays of the same family that are both
``valid`` bound one far-field segment ("patch" in the thesis).

Conventions (shared by every producer and consumer of a :class:`Fan`):

- lengths are in units of the drop's reference radius ``a`` (the equal-volume radius for
  Beard–Chuang drops, the radius for a circle); ``s = b / a`` is the signed impact
  parameter, measured perpendicular to the incident propagation direction, positive on the
  side obtained by turning the propagation direction by +90° (counter-clockwise);
- ``psi`` is the signed outgoing angle from the incident **propagation** direction, in
  (-pi, pi], positive counter-clockwise (so the scattering angle is ``|psi|``; 0 = forward,
  ±pi = straight back);
- ``amp[..., 0]`` is the complex amplitude for the field perpendicular to the section plane
  (⊥, TE-to-the-plane-of-incidence, "s"; Mie's S1; the cylinder's TM), ``amp[..., 1]`` the
  field in the plane (∥, "p"; Mie's S2), each the product of the Fresnel amplitude
  coefficients along the path (Sadeghi Eqs. 2.9–2.10; no geometric spreading: the collectors
  add it from the fan's density). In 2-D and in the meridional plane of an axisymmetric
  drop the two never mix, so no frame rotation is needed;
- ``opl`` is the optical path (in units of ``a``) between the plane through the drop's
  centre perpendicular to the incident direction and the plane through the centre
  perpendicular to the outgoing direction (Sadeghi §3.4.3 (f)); for a circle
  ``L = -2 cos i + 2 p n cos r``;
- ``foci`` counts the meridional foci (where the ray and its neighbour in the fan cross, on
  every chord and on the outgoing half-line: the Maslov count); ``axis`` counts the
  crossings of the symmetry axis through the centre along the incident direction (used only
  by the axisymmetric 3-D lift). Each count advances the phase by -pi/2 (decision D-R3);
- ``valid`` is False where the ray missed, or where the family does not exist for it (total
  internal reflection on the way out).
"""

from __future__ import annotations

from typing import NamedTuple

import jax


class Fan(NamedTuple):
    """Rays of one collimated beam through a drop section, per path family.

    Shapes: ``s`` (N,); every other field (F, N) (``amp`` (F, N, 2), complex).
    """

    s: jax.Array       # impact parameter b / a, sorted increasing, (N,)
    psi: jax.Array     # signed outgoing angle from the propagation direction, rad, (F, N)
    amp: jax.Array     # complex amplitudes (perpendicular, parallel), (F, N, 2)
    opl: jax.Array     # optical path in units of a, (F, N)
    foci: jax.Array    # meridional foci count (int), (F, N)
    axis: jax.Array    # symmetry-axis crossings (int), (F, N)
    valid: jax.Array   # bool, (F, N)
