"""Flatland vane: a Monte Carlo reference for the barb-scale masking of Padrón's feather BSDF (spec seed-000
§5.2, M33; checks :func:`appearance_jax.bsdf.feather_masking.barb_masking`).

The barb cross-section of a vane (spec D9; x across the vane, y its normal): an infinite row of opaque barb
ellipses centred at (k X, 0), semi-axes (1/2, e_b / 2), joined by barbule **segments**, the proximal one
from (k X + 1/2, 0) to the corner c = (k X + X / 2, corner l_bb sin theta_bb) and the distal one from c to
((k + 1) X - 1/2, 0), X = 1 + 2 l_bb cos theta_bb. A barbule segment is **semi-transparent**: a ray
crossing it stops there with probability w' (the barbule row's coverage, w_bp or w_bd) and passes
straight on otherwise; a barb stops every ray.

:func:`vane_masking` launches rays towards -w' from far above the vane, uniformly (stratified) over one
projected period X |w'_y| of the screen line, and classifies each by where it stops: a barb, a proximal
barbule, a distal barbule, or nowhere (transmitted). The coin flips are independent per crossing, so the
stop is the nearest crossing whose coin says stop: no ordering of the crossings is needed. It also
records the offset h (flatland's convention: across the projected diameter, to the left of the ray's
travel) at which each ray meets the first barb on its way, barbule occlusion ignored, whose range is
the barb's visible offset range of the masking.

The scene is a periodic :class:`~appearance_jax.flatland.section.Section` of flatland's general tracer
(:func:`vane_section`: an absorbing ellipse and two semi-transparent absorbing segments, vane x = the
section's y, vane y = its z), and the tallies are :func:`~appearance_jax.flatland.tallies.first_hits`; the
barb's offset range comes from a second trace with the barbules removed (coverage 0). Independent of the
masking's interval solver, which cuts the screen into pieces and composites them analytically.

Example::

    import jax
    from appearance_jax.flatland import vane
    r = vane.vane_masking((0.5, 0.8660254), e_b=1.6, l_bb=1.0, theta_bb=0.26, w_bp=0.6, w_bd=0.6,
                          key=jax.random.PRNGKey(0))
    r.weights, r.stderr   # (w_b, w_bp, w_bd, w_t) and their binomial standard errors
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..core.params import check_int
from ..core.vec import Vec3
from .section import Interface, Medium, Section, Shape, segment
from .tallies import first_hits


class VaneMasking(NamedTuple):
    """What :func:`vane_masking` returns."""

    weights: jax.Array     # (4,): fractions of the rays stopped by a barb, a proximal, a distal barbule, none
    stderr: jax.Array      # (4,): binomial standard errors
    h_range: jax.Array     # (2,): min and max offset h at which rays meet their first barb (barbules ignored)
    truncated: jax.Array   # fraction of rays whose path through the vane runs past the copies traced


def vane_section(e_b, l_bb, theta_bb, w_bp, w_bd, *, corner: int = 1, copies: int = 24) -> Section:
    """The barb cross-section of a vane (module docstring) as a periodic flatland :class:`Section`:
    shapes (barb, proximal barbules, distal barbules), all absorbers, the barbule segments of coverage
    ``w_bp`` and ``w_bd``; period X = 1 + 2 l_bb cos theta_bb; ``copies`` neighbours traced on each side."""
    f = lambda v: jnp.asarray(v, jnp.result_type(float))  # noqa: E731
    e_b, l_bb, theta_bb = f(e_b), f(l_bb), f(theta_bb)
    X = 1.0 + 2.0 * l_bb * jnp.cos(theta_bb)
    c = (0.5 * X, corner * l_bb * jnp.sin(theta_bb))
    barb = Shape(f(0.0), f(0.0), f(0.5), 0.5 * e_b, f(0.0), Interface("absorber"), inside=1, outside=0)
    prox = segment((0.5, 0.0), c, Interface("absorber", coverage=f(w_bp)))
    dist = segment(c, (X - 0.5, 0.0), Interface("absorber", coverage=f(w_bd)))
    media = (Medium(f(1.0), f(0.0)), Medium(f(1.0), f(0.0)))
    return Section((barb, prox, dist), media, X, int(copies)).validate()


def vane_masking(w, e_b, l_bb, theta_bb, w_bp, w_bd, key, *, n_rays: int = 2**17, corner: int = 1,
                 copies: int = 24, barb_offsets: bool = True) -> VaneMasking:
    """Monte Carlo barb-scale masking of the vane seen along the 2D direction ``w`` = (x across the vane,
    y its normal; above or below, not in the vane plane): :class:`VaneMasking` (module docstring).
    ``e_b`` > 0, ``l_bb`` >= 0, ``theta_bb`` in [0, pi/2), ``w_bp``, ``w_bd`` in [0, 1] (the barbule
    coverages), ``corner`` +1 or -1, ``copies`` barbs traced on each side. ``barb_offsets=False`` skips
    the second trace that finds the barb's visible offset range (``h_range`` is then NaN)."""
    check_int("vane_masking.n_rays", n_rays, 1)
    check_int("vane_masking.copies", copies, 1)
    for name, v, lo, hi in (("e_b", e_b, 0.0, None), ("l_bb", l_bb, 0.0, None), ("w_bp", w_bp, 0.0, 1.0),
                            ("w_bd", w_bd, 0.0, 1.0)):
        v = float(v)
        if not (v == v and v >= lo and (hi is None or v <= hi)) or (name == "e_b" and v == 0):
            rng = f"[{lo}, {hi}]" if hi is not None else ("(0, inf)" if name == "e_b" else "[0, inf)")
            raise ValueError(f"vane_masking: {name} = {v!r}: valid range {rng}")
    if not 0.0 <= float(theta_bb) < 0.5 * jnp.pi:
        raise ValueError(f"vane_masking: theta_bb = {theta_bb!r} rad: valid range [0, pi/2)")
    if corner not in (1, -1):
        raise ValueError(f"vane_masking: corner = {corner!r}: +1 or -1")
    wy, wz = (float(c) for c in w)
    if not wz != 0:
        raise ValueError(f"vane_masking: w = {tuple(w)}: the view must not lie in the vane plane (w_y != 0)")
    r = (wy * wy + wz * wz) ** 0.5
    wo = Vec3(jnp.asarray(0.0), jnp.asarray(wy / r), jnp.asarray(wz / r))
    k_all, k_barb = jax.random.split(key)
    seen = first_hits(vane_section(e_b, l_bb, theta_bb, w_bp, w_bd, corner=corner, copies=copies), wo,
                      k_all, int(n_rays))
    h_range = jnp.full((2,), jnp.nan)
    if barb_offsets:  # the barb's visible offsets with the barbules ignored ([T:1369]): the row without them
        h_range = first_hits(vane_section(e_b, l_bb, theta_bb, 0.0, 0.0, corner=corner, copies=copies), wo,
                             k_barb, int(n_rays)).h_range[0]
    return VaneMasking(seen.fraction, seen.stderr, h_range, seen.truncated)
