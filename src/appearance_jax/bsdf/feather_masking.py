"""Barbule masking of Padrón's feather model (Padrón 2025 Ch. 5, App. B.2.1; spec seed-000 M23, D8).

Seen in the cross-section of a row of barbules (the proximal or distal barbules' own frame, the
barbule axis dropped: a 2D viewing direction w' = (w_x, w_y), x along the row, y the vane normal),
the barbules are ellipses of horizontal semi-axis a_x = 1/2 (sizes relative to a barbule's width) and
vertical semi-axis a_y = e_bb / 2, separated by gaps delta_bb: the row's period is P = 1 + delta_bb.
Padrón casts rays from the ellipses' tangent points (B.11-B.13) to find

- w'_bb, the fraction of the row's projected period covered by barbules (1 - w'_bb is seen through
  the gaps), and
- [h-, h+], the part of a barbule's projected diameter not hidden by its neighbour (the range of its
  BCSDF's offset h, Padrón Eq. 5.1).

For this geometry the ray casts have a closed form (spec M23, derived): with W = 2 sqrt(a_x^2 w_y^2 +
a_y^2 w_x^2) the projected width of a barbule and P |w_y| the projected period (w' normalised),

    w'_bb = min(1, W / (P |w_y|)),   visible length of a diameter = 2 min(1, P |w_y| / W).

The neighbour nearer the viewer (at +P when w_x > 0) hides one end of the diameter; further
neighbours hide nothing more. Offsets h follow flatland's convention (:func:`flatland.geometry.
tangent_points`): h in [-1, 1] runs to the left of the ray's direction of travel -w', so the hidden end
is h = +1 when w_x w_y > 0 (visible [-1, h+]) and h = -1 when w_x w_y < 0 (visible [h-, 1]).
Padrón's text always cuts h- (choosing the casting ellipse "depending on the quadrant"); which end is
cut matters for the barbule's BCSDF, and here it is the geometric one.

Edge cases: a view along the barbule axis (w' = 0) has no transverse direction and is taken as the
normal view (w' = (0, 1)); at grazing (w_y = 0) the row is fully covered and a barbule's visible
range is empty (h- = h+ at the unhidden end): finite values throughout.

Example::

    from appearance_jax.bsdf import feather_masking
    w, h_lo, h_hi = feather_masking.barbule_masking(0.5, 0.8660254, e_bb=1.0, delta_bb=1.0)  # 30 deg
    # w = 1 / (2 cos 30 deg) = 0.577, the whole diameter visible
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..core.special import safe_sqrt


def _check(label, value, lo, lo_open):
    if isinstance(value, jax.core.Tracer):
        return
    v = np.asarray(value, float)
    bad = ~np.isfinite(v) | ((v <= lo) if lo_open else (v < lo))
    if np.any(bad):
        rng = f"({lo}, inf)" if lo_open else f"[{lo}, inf)"
        raise ValueError(f"feather_masking.barbule_masking: {label} = {value!r}: valid range {rng}")


def projected_width(wx, wy, e_bb):
    """W: the projected width of a barbule (horizontal width 1, height e_bb) seen along the unit 2D
    direction (wx, wy)."""
    ax, ay = 0.5, 0.5 * jnp.asarray(e_bb)
    return 2.0 * safe_sqrt(ax * ax * wy * wy + ay * ay * wx * wx)


def barbule_masking(wx, wy, e_bb, delta_bb):
    """(w'_bb, h_lo, h_hi) of the barbule row seen along the 2D direction (wx, wy) (any length; x along
    the row, y the vane normal; either side of the row), for the axis ratio ``e_bb`` > 0 and the
    relative separation ``delta_bb`` >= 0 (module docstring). Arrays broadcast; branch-free."""
    _check("e_bb", e_bb, 0.0, True)
    _check("delta_bb", delta_bb, 0.0, False)
    wx, wy = jnp.asarray(wx, jnp.result_type(float)), jnp.asarray(wy, jnp.result_type(float))
    r = safe_sqrt(wx * wx + wy * wy)
    along = r == 0  # a view along the barbule axis: the normal view
    inv = jnp.where(along, 0.0, 1.0 / jnp.where(along, 1.0, r))
    dx, dy = jnp.where(along, 0.0, wx * inv), jnp.where(along, 1.0, wy * inv)
    W = projected_width(dx, dy, e_bb)
    period = (1.0 + jnp.asarray(delta_bb)) * jnp.abs(dy)
    ok = W > period
    w = jnp.where(ok, 1.0, W / jnp.where(ok | (period == 0), 1.0, period))
    visible = jnp.where(ok, 2.0 * period / jnp.where(ok, W, 1.0), 2.0)  # length in h units
    cut_high = dx * dy > 0
    h_lo = jnp.where(cut_high, -1.0, 1.0 - visible)
    h_hi = jnp.where(cut_high, -1.0 + visible, 1.0)
    return w, h_lo, h_hi
