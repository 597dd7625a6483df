"""The transverse section of a rock-dove barb: a row of elliptic barbule arcs (Huang 2022 Ch. 5).

Geometry of :mod:`appearance_jax.bsdf.rock_dove`, exact in 2D (Huang Fig. 5.8, [T:1616-1636]
of seed 001). Barbule frame (X, Y, Z): Y is the barbule axis, X-Z the transverse plane; a
direction is ``[sin(phi) cos(theta), sin(theta), cos(phi) cos(theta)]`` (Huang Fig. 5.7b), so
``phi`` is the azimuth of its projection onto the X-Z plane, measured from +Z towards +X.

- One barbule's exposed surface is the elliptic arc ``X^2 + Z^2 / b^2 = 1`` (semi-major axis 1
  along X, semi-minor b) whose outward normals have azimuths ``phi_m`` in ``[phi_0, phi_1]``.
  The point with normal azimuth phi is ``(sin phi, b^2 cos phi) / sqrt(sin^2 phi + b^2 cos^2 phi)``
  and its radius of curvature is ``1 / kappa = b^2 (sin^2 phi + b^2 cos^2 phi)^(-3/2)``
  (so ``H D_phi = 1 / kappa``, Huang Eq. 5.5).
- The barb plane is the X-Y plane rotated by ``mu`` about Y: its normal n has azimuth
  ``-mu`` (``<w, n> = cos(theta) cos(phi + mu)``, Huang Eq. 5.13) and its in-plane transverse
  direction is ``t = (cos mu, sin mu)`` in (X, Z). The neighbours are the same arc translated
  by ``k H t``; ``neighbours`` of them on each side are tested (2 by default: a barbule's open
  side lets rays pass under the first neighbour into the second; tests check that 4 changes
  nothing at the thesis' parameters).

Visibility (Huang's binary G, [T:1636]): a point of the central arc sees along a 2D direction
d when it faces d (cos(phi_d - phi_m) > 0) and the ray from it along d meets no neighbour
arc, on either side of the arc (an arc is an opaque shell). The set of arc points that see d
is a union of intervals of phi_m whose ends are the arc's own ends, the front-facing limits,
and the points whose ray along d grazes a neighbour's end point or silhouette or that lie on
a neighbour (arcs of overlapping ellipses cross); between consecutive candidates visibility is
constant, so one ray test per piece classifies it exactly (:func:`lit_pieces`). The projected
length of the lit pieces is Huang's valid length ``Delta h'`` ([T:1674]); a period projects to
``Delta h = H |cos(phi_d + mu)|``.

Everything is in units of the semi-major axis, branch-free and vectorised over leading axes.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from ..core.special import atan2, safe_sqrt

TWO_PI = 2.0 * math.pi


def wrap_near(phi, centre):
    """``phi + 2 pi k`` in ``[centre - pi, centre + pi)``."""
    return centre + jnp.mod(phi - centre + math.pi, TWO_PI) - math.pi


def arc_point(phi, b):
    """(X, Z) of the point of the ellipse ``X^2 + Z^2/b^2 = 1`` with outward normal azimuth ``phi``."""
    s, c = jnp.sin(phi), jnp.cos(phi)
    inv = 1.0 / jnp.sqrt(s * s + b * b * c * c)
    return s * inv, b * b * c * inv


def normal_azimuth(x, z, b):
    """Outward normal azimuth of the ellipse point (x, z) (from +Z towards +X)."""
    return atan2(x * b * b, z)


def radius_of_curvature(phi, b):
    """1 / kappa at normal azimuth phi: ``b^2 (sin^2 phi + b^2 cos^2 phi)^(-3/2)`` (Huang Eq. 5.5 x H)."""
    s, c = jnp.sin(phi), jnp.cos(phi)
    return b * b * (s * s + b * b * c * c) ** -1.5


def in_arc(phi, phi0, phi1):
    """True where the normal azimuth ``phi`` (any branch) lies on the arc ``[phi0, phi1]``."""
    return jnp.mod(phi - phi0, TWO_PI) <= (phi1 - phi0)


def offsets(H, mu, neighbours: int):
    """Centres (X, Z) of the neighbour arcs: ``k H t`` for k = +-1 .. +-neighbours, shape (2n,)."""
    k = jnp.asarray([k for k in range(-neighbours, neighbours + 1) if k != 0], jnp.result_type(float))
    H, mu = jnp.asarray(H)[..., None], jnp.asarray(mu)[..., None]
    return k * H * jnp.cos(mu), k * H * jnp.sin(mu)


def _ray_ellipse(px, pz, dx, dz, b):
    """Both roots s of ``p + s d`` on the ellipse centred at 0 (NaN-free; ``real`` masks them)."""
    ib2 = 1.0 / (b * b)
    A = dx * dx + dz * dz * ib2
    B = px * dx + pz * dz * ib2
    C = px * px + pz * pz * ib2 - 1.0
    disc = B * B - A * C
    real = (disc >= 0) & (A > 0)
    sq = safe_sqrt(jnp.where(real, disc, 0.0))  # finite derivative where the ray misses
    A = jnp.where(A > 0, A, 1.0)
    # stable roots: q = -(B + sign(B) sq); s1 = q / A, s2 = C / q
    q = -(B + jnp.where(B >= 0, sq, -sq))
    s1 = q / A
    s2 = jnp.where(q != 0, C / jnp.where(q != 0, q, 1.0), s1)
    return s1, s2, real


def occluded(px, pz, dx, dz, b, phi0, phi1, cx, cz, eps=1e-7):
    """True where the ray from (px, pz) along the 2D direction (dx, dz) meets one of the arcs
    centred at (cx, cz) (last axis: the neighbours) at a distance > eps. Arcs span at most pi."""
    px, pz, dx, dz = (jnp.asarray(v)[..., None] for v in (px, pz, dx, dz))
    b, phi0, phi1 = (jnp.asarray(v)[..., None] for v in (b, phi0, phi1))
    qx, qz = px - cx, pz - cz
    s1, s2, real = _ray_ellipse(qx, qz, dx, dz, b)

    # on the arc: the normal (x, z / b^2) between the end normals, by two cross products (an arc
    # spans at most pi); atan2 here was most of the cost of a visibility test
    s0, c0, s1_, c1 = jnp.sin(phi0), jnp.cos(phi0), jnp.sin(phi1), jnp.cos(phi1)

    def hit(s):
        nx, nz = (qx + s * dx) * b * b, qz + s * dz
        on = (nx * c0 - nz * s0 >= 0) & (nz * s1_ - nx * c1 >= 0)
        return real & (s > eps) & on

    return jnp.any(hit(s1) | hit(s2), axis=-1)


def front_point(h, dx, dz, b):
    """Normal azimuth of the point of the ellipse, facing d, on the line at offset h
    (coordinate along w = (-dz, dx)); h is clamped to the ellipse's projected half-width."""
    wx, wz = -dz, dx
    hw = safe_sqrt(wx * wx + b * b * wz * wz)  # d = 0: a direction along the barbule axis
    h = jnp.clip(h, -hw, hw)
    s1, s2, _ = _ray_ellipse(h * wx, h * wz, dx, dz, b)
    s = jnp.maximum(s1, s2)  # the root towards the light: the front-facing point
    return normal_azimuth(h * wx + s * dx, h * wz + s * dz, b)


def _crossings(cx, cz, b):
    """Normal azimuths (on the central ellipse) of the two points where it crosses its
    translate by (cx, cz) (the chord (M^2 c) . p = |M c|^2 / 2; arbitrary where they do not)."""
    gx, gz = cx, cz / (b * b)
    g2 = gx * gx + gz * gz
    rhs = 0.5 * (cx * gx + cz * gz)
    px, pz = rhs * gx / g2, rhs * gz / g2
    n = jnp.sqrt(g2)
    ex, ez = -gz / n, gx / n
    s1, s2, _ = _ray_ellipse(px, pz, ex, ez, b)
    return normal_azimuth(px + s1 * ex, pz + s1 * ez, b), normal_azimuth(px + s2 * ex, pz + s2 * ez, b)


def breakpoints(dx, dz, b, phi0, phi1, H, mu, neighbours: int):
    """Sorted candidate ends (..., 2 + 6 * 2 * neighbours) of the pieces of the central arc
    (normal azimuths, on the arc's branch) between which visibility along (dx, dz) is constant;
    all lie in the arc's front-facing range [lo, hi] (lo = hi: the arc does not face d)."""
    mid = 0.5 * (phi0 + phi1)
    phi_d = wrap_near(atan2(dx, dz), mid)
    lo = jnp.maximum(phi0, phi_d - 0.5 * math.pi)
    hi = jnp.maximum(jnp.minimum(phi1, phi_d + 0.5 * math.pi), lo)
    cx, cz = offsets(H, mu, neighbours)
    e = lambda v: jnp.asarray(v)[..., None]  # noqa: E731
    dxe, dze, be = e(dx), e(dz), e(b)
    # the shadow edges cast by the 4 feature points of each neighbour (its arc ends and its
    # silhouette points), (..., 4, 2n): one computation, not four copies of it
    ang = jnp.stack(jnp.broadcast_arrays(phi0, phi1, phi_d - 0.5 * math.pi, phi_d + 0.5 * math.pi), axis=-1)
    fx, fz = arc_point(e(ang), e(be))
    h = -e(dze) * (cx[..., None, :] + fx) + e(dxe) * (cz[..., None, :] + fz)  # offset along w = (-dz, dx)
    edges = front_point(h, e(dxe), e(dze), e(be))
    feats = [edges.reshape(edges.shape[:-2] + (-1,))] + list(_crossings(cx, cz, be))
    m = e(mid)
    feats = [wrap_near(f, m) for f in feats]
    lead = jnp.broadcast_shapes(*(f.shape[:-1] for f in feats))
    cand = jnp.concatenate([jnp.broadcast_to(f, lead + f.shape[-1:]) for f in feats], axis=-1)
    cand = jnp.clip(cand, e(lo), e(hi))
    return jnp.sort(jnp.concatenate(jnp.broadcast_arrays(e(lo), cand, e(hi)), axis=-1), axis=-1)


def projected(phi, dx, dz, b):
    """Offset h = w . p(phi) of arc points along w = (-dz, dx) (the coordinate seen from d)."""
    x, z = arc_point(phi, b)
    return -dz * x + dx * z


def lit_pieces(dx, dz, b, phi0, phi1, H, mu, neighbours: int = 2):
    """Pieces of the central arc that see the 2D direction (dx, dz) (unit; see the module).

    Returns ``(bp, lit, dh)``: the piece ends (..., m + 1) (normal azimuths), a bool (..., m) per
    piece, and each piece's projected length |h(end) - h(start)| (..., m) seen from d.
    """
    bp = breakpoints(dx, dz, b, phi0, phi1, H, mu, neighbours)
    a, c = bp[..., :-1], bp[..., 1:]
    e = lambda v: jnp.asarray(v)[..., None]  # noqa: E731
    dxe, dze, be = e(dx), e(dz), e(b)
    mx, mz = arc_point(0.5 * (a + c), be)
    cx, cz = offsets(H, mu, neighbours)  # (..., 2n): against every piece's midpoint
    blocked = occluded(mx, mz, dxe, dze, be, e(phi0), e(phi1), cx[..., None, :], cz[..., None, :])
    lit = (c > a) & ~blocked
    dh = jnp.abs(projected(c, dxe, dze, be) - projected(a, dxe, dze, be))
    return bp, lit, dh


def lit_runs(bp, lit, n_runs: int):
    """The first ``n_runs`` maximal runs of consecutive lit pieces, as (start, end) normal
    azimuths (..., n_runs) each; missing runs (and any beyond ``n_runs``) are empty (start = end).
    Empty pieces (coincident candidates) take the state of the last non-empty one before them,
    so that they do not split a run."""
    width = bp[..., 1:] > bp[..., :-1]
    idx = jax.lax.cummax(jnp.where(width, jnp.arange(lit.shape[-1]), -1), axis=lit.ndim - 1)
    lit = jnp.take_along_axis(lit, jnp.maximum(idx, 0), axis=-1) & (idx >= 0)
    prev = jnp.concatenate([jnp.zeros_like(lit[..., :1]), lit[..., :-1]], axis=-1)
    nxt = jnp.concatenate([lit[..., 1:], jnp.zeros_like(lit[..., :1])], axis=-1)
    first, last = lit & ~prev, lit & ~nxt
    r_first, r_last = jnp.cumsum(first, axis=-1), jnp.cumsum(last, axis=-1)
    starts, ends = [], []
    for k in range(1, n_runs + 1):
        i0 = jnp.argmax(first & (r_first == k), axis=-1)[..., None]
        i1 = jnp.argmax(last & (r_last == k), axis=-1)[..., None]
        have = (r_first[..., -1:] >= k)
        a = jnp.take_along_axis(bp[..., :-1], i0, axis=-1)
        c = jnp.take_along_axis(bp[..., 1:], i1, axis=-1)
        starts.append(jnp.where(have, a, 0.0))
        ends.append(jnp.where(have, c, 0.0))
    return jnp.concatenate(starts, -1), jnp.concatenate(ends, -1)


def valid_fraction(dx, dz, b, phi0, phi1, H, mu, neighbours: int = 2):
    """``Delta h' / Delta h``: the fraction of a period's rays from the 2D direction d that
    land on a front-facing, unoccluded arc point (Huang [T:1674]); 0 where d is parallel to
    the barb plane."""
    _, lit, dh = lit_pieces(dx, dz, b, phi0, phi1, H, mu, neighbours)
    valid = jnp.sum(jnp.where(lit, dh, 0.0), axis=-1)
    period = jnp.asarray(H) * jnp.abs(dz * jnp.cos(mu) - dx * jnp.sin(mu))  # H |cos(phi_d + mu)|
    ok = period > 0
    return jnp.where(ok, jnp.clip(valid / jnp.where(ok, period, 1.0), 0.0, 1.0), 0.0)
