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


def _unit_2d(wx, wy):
    """(wx, wy) normalised; a view along the barbule axis (0, 0) is taken as the normal view (0, 1)."""
    r = safe_sqrt(wx * wx + wy * wy)
    along = r == 0
    inv = jnp.where(along, 0.0, 1.0 / jnp.where(along, 1.0, r))
    return jnp.where(along, 0.0, wx * inv), jnp.where(along, 1.0, wy * inv)


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
    dx, dy = _unit_2d(jnp.asarray(wx, jnp.result_type(float)), jnp.asarray(wy, jnp.result_type(float)))
    W = projected_width(dx, dy, e_bb)
    period = (1.0 + jnp.asarray(delta_bb)) * jnp.abs(dy)
    ok = W > period
    w = jnp.where(ok, 1.0, W / jnp.where(ok | (period == 0), 1.0, period))
    visible = jnp.where(ok, 2.0 * period / jnp.where(ok, W, 1.0), 2.0)  # length in h units
    cut_high = dx * dy > 0
    h_lo = jnp.where(cut_high, -1.0, 1.0 - visible)
    h_hi = jnp.where(cut_high, -1.0 + visible, 1.0)
    return w, h_lo, h_hi


# --------------------------------------------------------------------------------------
# Barb masking (large scale)
# --------------------------------------------------------------------------------------

#: barb copies on each side of the central one that a view ray is tested against (enough unless the
#: view is within a few degrees of the vane plane; see :func:`barb_masking`)
BARB_COPIES = 6


def _ellipse_hit(m, dx, dy, cx, a, b):
    """The depth of the entry (nearest the viewer) of the view ray at screen coordinate m into the
    ellipse centred at (cx, 0) with semi-axes (a, b), and whether it hits. The ray: m (dy, -dx) + t (dx, dy)."""
    px, py = m * dy - cx, -m * dx
    A = dx * dx / (a * a) + dy * dy / (b * b)
    B = 2.0 * (px * dx / (a * a) + py * dy / (b * b))
    C = px * px / (a * a) + py * py / (b * b) - 1.0
    disc = B * B - 4.0 * A * C
    t = (-B + safe_sqrt(disc)) / (2.0 * A)  # the larger root: nearest the viewer
    return t + cx * dx, disc > 0  # depth = position . (dx, dy)


def _segment_hit(m, dx, dy, p, q):
    """Depth where the view ray at screen coordinate m crosses the segment p-q, and whether it does."""
    sp, sq = p[0] * dy - p[1] * dx, q[0] * dy - q[1] * dx
    dp, dq = p[0] * dx + p[1] * dy, q[0] * dx + q[1] * dy
    ds = sq - sp
    f = jnp.where(ds != 0, (m - sp) / jnp.where(ds != 0, ds, 1.0), -1.0)
    return dp + f * (dq - dp), (f > 0) & (f < 1)


def barb_masking(wx, wy, e_b, l_bb, theta_bb, w_bp, w_bd, *, corner: int = 1, copies: int = BARB_COPIES,
                 occlusions=None):
    """Barb masking (Padrón App. B.2.2, B.14-B.18; spec seed-000 M24, layout D9), exactly.

    In the barb cross-section (x across the vane, y its normal) barb k is an opaque ellipse centred
    at (k X, 0) with semi-axes (1/2, e_b / 2); its proximal barbules are the segment from (k X + 1/2, 0)
    to the corner c = (k X + X / 2, corner l_bb sin theta_bb) and the next barb's distal barbules the
    segment from c to ((k + 1) X - 1/2, 0), X = 1 + 2 l_bb cos theta_bb (``corner`` = +1: a V opening
    towards +y, -1: inverted). A barbule segment covers the fraction ``w_bp`` / ``w_bd`` of what is
    behind it (the barbule masking w'_bb of its own frame, :func:`barbule_masking`; scalars or arrays
    that broadcast with the directions).

    Returns ``(w_b, w_bp, w_bd, w_t, h_lo, h_hi)``: the fractions of the projected period (sum 1) where
    the viewer along (wx, wy) sees a barb, a proximal barbule, a distal one, or through the vane; and
    the visible offset range of a barb's diameter, barbule occlusion ignored as in [T:1369]
    (:func:`barbule_masking` of the barb row). Where Padrón casts rays case by case and approximates the
    barbules' repeated occlusion at grazing views by one ([T:1371]), this cuts one period of the
    screen line at every silhouette and segment end (the central copy's, modulo the screen period), and
    composites the crossings with ``copies`` neighbours on each side front to back on each piece (the
    order is constant there): exact up to views so close
    to the vane plane that a ray crosses more than ``copies`` periods (|wy| / |wx| < ~ (1 + e_b) /
    (2 copies X)). Branch-free; (wx, wy) scalars or arrays.

    ``occlusions`` = n (an int; default None = exact) reproduces Padrón's simplification for comparison
    [T:1371]: only the first n barbule layers in front of a crossing attenuate it (he approximates the
    "infinite sequence of partial occlusions" at grazing views by one, n = 1), and the areas are then
    normalised as in B.18.
    """
    _check("e_b", e_b, 0.0, True)
    _check("l_bb", l_bb, 0.0, False)
    for name, v in (("w_bp", w_bp), ("w_bd", w_bd)):
        _check(name, v, 0.0, False)
        if not isinstance(v, jax.core.Tracer) and np.any(np.asarray(v, float) > 1):
            raise ValueError(f"feather_masking.barb_masking: {name} = {v!r}: valid range [0, 1]")
    if not isinstance(theta_bb, jax.core.Tracer) and not 0 <= float(theta_bb) < 0.5 * np.pi:
        raise ValueError(f"feather_masking.barb_masking: theta_bb = {theta_bb!r} rad: valid range [0, pi/2)")
    if corner not in (1, -1):
        raise ValueError(f"feather_masking.barb_masking: corner = {corner!r}: +1 or -1")
    if occlusions is not None and (int(occlusions) != occlusions or occlusions < 1):
        raise ValueError(f"feather_masking.barb_masking: occlusions = {occlusions!r}: None (exact) or an integer >= 1")
    f = jnp.result_type(float)
    wx, wy, w_bp, w_bd = jnp.broadcast_arrays(*(jnp.asarray(v, f) for v in (wx, wy, w_bp, w_bd)))
    shape = wx.shape
    dx, dy = _unit_2d(wx.reshape(-1, 1), wy.reshape(-1, 1))
    a, b = 0.5, 0.5 * jnp.asarray(e_b, f)
    X = 1.0 + 2.0 * jnp.asarray(l_bb, f) * jnp.cos(theta_bb)
    cy = corner * jnp.asarray(l_bb, f) * jnp.sin(theta_bb)
    k = jnp.arange(-copies, copies + 1, dtype=f)[None, :]
    cx = k * X
    # primitives (per copy): barb ellipse, proximal segment p0-c, distal segment c-p1
    zero = jnp.zeros_like(cx)
    p0, c, p1 = (cx + 0.5, zero), (cx + 0.5 * X, cy + zero), (cx + X - 0.5, zero)
    half = 0.5 * projected_width(dx, dy, e_b)  # of a barb
    # the screen is periodic (period X |w_y|): every copy's silhouette and segment ends fall, modulo the
    # period, on those of the central copy, so its five ends cut one period into at most six pieces
    # (cutting at every copy's ends gave ~60 pieces, nearly all empty, and sorted depths in each)
    ends = [-half, half] + [q[0][:, copies:copies + 1] * dy - q[1][:, copies:copies + 1] * dx for q in (p0, c, p1)]
    period = X * jnp.abs(dy)
    lo_w = -0.5 * period
    safe = jnp.where(period > 0, period, 1.0)
    cuts = jnp.concatenate([lo_w + jnp.mod(e - lo_w, safe) * (period > 0) for e in ends] + [lo_w, lo_w + period],
                           axis=1)
    cuts = jnp.clip(jnp.sort(cuts, axis=1), lo_w, lo_w + period)
    m = 0.5 * (cuts[:, 1:] + cuts[:, :-1])[..., None]           # (n, pieces, 1)
    length = (cuts[:, 1:] - cuts[:, :-1])
    e = lambda v: v[:, None, :]  # noqa: E731  copies on the last axis
    d_b, h_b = _ellipse_hit(m, dx[..., None], dy[..., None], e(cx), a, b)
    d_p, h_p = _segment_hit(m, dx[..., None], dy[..., None], (e(p0[0]), e(p0[1])), (e(c[0]), e(c[1])))
    d_d, h_d = _segment_hit(m, dx[..., None], dy[..., None], (e(c[0]), e(c[1])), (e(p1[0]), e(p1[1])))
    depth = jnp.concatenate([jnp.where(h, d, -jnp.inf) for d, h in ((d_b, h_b), (d_p, h_p), (d_d, h_d))], axis=-1)
    n = cx.shape[1]
    kind = jnp.repeat(jnp.arange(3), n)                           # 0 barb, 1 proximal, 2 distal
    order = jnp.argsort(-depth, axis=-1)                          # nearest the viewer first
    hit = jnp.take_along_axis(jnp.isfinite(depth), order, axis=-1)
    kd = kind[order]
    w_p, w_d = w_bp.reshape(-1, 1, 1), w_bd.reshape(-1, 1, 1)     # per direction
    cov = jnp.where(hit, jnp.where(kd == 0, 1.0, jnp.where(kd == 1, w_p, w_d)), 0.0)
    passing = 1.0 - cov
    if occlusions is not None:  # Padrón's approximation [T:1371]: only the first barbule layers attenuate
        barbule = hit & (kd != 0)
        rank = jnp.cumsum(barbule, axis=-1) - barbule             # barbule layers in front of each crossing
        passing = jnp.where(barbule & (rank >= occlusions), 1.0, passing)
    trans = jnp.cumprod(passing, axis=-1)
    before = jnp.concatenate([jnp.ones_like(trans[..., :1]), trans[..., :-1]], axis=-1)
    seen = before * cov                                           # what each crossing contributes
    areas = [jnp.sum(jnp.sum(jnp.where(kd == j, seen, 0.0), axis=-1) * length, axis=-1) for j in range(3)]
    areas.append(jnp.sum(trans[..., -1] * length, axis=-1))
    tot = jnp.where(period[:, 0] > 0, period[:, 0], 1.0)
    if occlusions is not None:  # B.18: normalise the projected areas (exactly, they sum to the period)
        tot = jnp.where(period[:, 0] > 0, sum(areas), 1.0)
    grazing = period[:, 0] == 0                                   # in the vane plane: the barbs cover all
    w = [jnp.where(grazing, 1.0 if j == 0 else 0.0, v / tot).reshape(shape) for j, v in enumerate(areas)]
    _, h_lo, h_hi = barbule_masking(dx[:, 0], dy[:, 0], e_b, X - 1.0)
    return (*w, h_lo.reshape(shape), h_hi.reshape(shape))
