"""Exact 2D geometry of cross-sections: rotated, offset ellipses, open elliptic arcs and segments.

The cross-section plane is the fiber frame's (y, z) plane (:func:`core.frame.fiber_angles`:
x is the fiber axis). A ray is a 2D origin ``(py, pz)`` and a 3D unit direction ``d``; its 2D
motion is ``p + t (d.y, d.z)``, so the ray parameter ``t`` is the **3D** path length (the
2D length is ``t |d_yz|``; ``l_3D = l_2D / cos(theta)``, spec seed-001 §4.2).

An ellipse has centre ``(cy, cz)``, semi-axes ``a`` (along its own first axis) and ``b``,
and a rotation ``psi`` of its first axis from +y towards +z. Its parametric angle ``gamma``
puts the point at ``c + R(psi) (a cos gamma, b sin gamma)`` (Padrón Eq. B.3, App. B). An
open arc keeps the points with ``gamma`` in ``[lo, lo + span]``.

A segment has centre ``(cy, cz)``, half length ``a`` and direction ``psi`` (its points are
``c + s (cos psi, sin psi)``, ``|s| <= a``); its normal is ``(-sin psi, cos psi)``.

Self-intersection is excluded exactly instead of with epsilons: a ray leaving a shape starts
on it, so one root of the quadratic is 0 and the other is ``-B/A`` (the sum of the roots); a
ray leaving a segment cannot meet it again.
"""

from __future__ import annotations

import jax.numpy as jnp

from ..core.special import atan2, safe_sqrt

_TWO_PI = 2.0 * jnp.pi


def unit_2d(dy, dz):
    """The section-plane direction (d_y, d_z) normalised; (0, 0) for a direction along the
    fiber axis (it has no projected motion)."""
    n2 = jnp.sqrt(dy * dy + dz * dz)
    inv = jnp.where(n2 > 0, 1.0 / jnp.where(n2 > 0, n2, 1.0), 0.0)
    return dy * inv, dz * inv


def to_local(py, pz, cy, cz, psi):
    """Point in the ellipse's own frame (its first axis along +y)."""
    c, s = jnp.cos(psi), jnp.sin(psi)
    dy, dz = py - cy, pz - cz
    return c * dy + s * dz, -s * dy + c * dz


def dir_to_local(dy, dz, psi):
    c, s = jnp.cos(psi), jnp.sin(psi)
    return c * dy + s * dz, -s * dy + c * dz


def dir_to_world(ly, lz, psi):
    c, s = jnp.cos(psi), jnp.sin(psi)
    return c * ly - s * lz, s * ly + c * lz


def intersect(py, pz, dy, dz, cy, cz, a, b, psi, lo, span, leaving):
    """Nearest positive hit of the ray ``p + t (dy, dz)`` with an ellipse or arc.

    Args:
        py, pz: ray origin (2D). dy, dz: 2D components of the 3D unit direction.
        cy, cz, a, b, psi: the ellipse. lo, span: the parametric range kept; ``span=None`` (static)
            for a closed ellipse, which skips the arc test (two atan2 per call, always true there).
        leaving: boolean array, True where the ray starts on this shape (it has just been
            scattered there); the root at t = 0 is then excluded exactly.

    Returns:
        ``(t, hit)``: the 3D distance to the hit (``inf`` where there is none) and a mask.
    """
    qy, qz = to_local(py, pz, cy, cz, psi)
    ey, ez = dir_to_local(dy, dz, psi)
    ia2, ib2 = 1.0 / (a * a), 1.0 / (b * b)
    A = ey * ey * ia2 + ez * ez * ib2
    B = 2.0 * (qy * ey * ia2 + qz * ez * ib2)
    C = qy * qy * ia2 + qz * qz * ib2 - 1.0
    A_safe = jnp.where(A > 0, A, 1.0)
    disc = B * B - 4.0 * A * C
    sq = safe_sqrt(disc)  # 0 (with a finite derivative) for misses
    # numerically stable roots: q = -(B + sign(B) sqrt(disc)) / 2, t1 = q / A, t2 = C / q
    qq = -0.5 * (B + jnp.where(B >= 0, sq, -sq))
    q_safe = jnp.where(qq != 0, qq, 1.0)
    r1 = qq / A_safe
    r2 = jnp.where(qq != 0, C / q_safe, r1)
    t_lo, t_hi = jnp.minimum(r1, r2), jnp.maximum(r1, r2)
    real = (disc >= 0) & (A > 0)
    # leaving the shape: the roots are exactly 0 and -B/A; keep the other one
    t_other = -B / A_safe
    t_lo = jnp.where(leaving, t_other, t_lo)
    t_hi = jnp.where(leaving, t_other, t_hi)

    def on_arc(t):
        y, z = qy + t * ey, qz + t * ez
        g = atan2(z / b, y / a)
        return jnp.mod(g - lo, _TWO_PI) <= span

    inf = jnp.inf
    ok_lo = real & (t_lo > 0)
    ok_hi = real & (t_hi > 0)
    if span is not None:
        ok_lo, ok_hi = ok_lo & on_arc(t_lo), ok_hi & on_arc(t_hi)
    t = jnp.where(ok_lo, t_lo, jnp.where(ok_hi, t_hi, inf))
    return t, ok_lo | ok_hi


def normal_at(py, pz, cy, cz, a, b, psi):
    """Outward unit normal ``(ny, nz)`` of the ellipse at a point on it (B.2)."""
    qy, qz = to_local(py, pz, cy, cz, psi)
    ly, lz = qy / (a * a), qz / (b * b)
    inv = 1.0 / jnp.sqrt(ly * ly + lz * lz)
    return dir_to_world(ly * inv, lz * inv, psi)


def parametric_angle(py, pz, cy, cz, a, b, psi):
    """Parametric angle gamma of a point on the ellipse (B.5)."""
    qy, qz = to_local(py, pz, cy, cz, psi)
    return atan2(qz / b, qy / a)


def tangent_points(uy, uz, cy, cz, a, b, psi):
    """The two points where lines of unit 2D direction ``(uy, uz)`` touch the ellipse.

    Returns ``((y0, z0), (y1, z1))`` ordered so that the offset ``h`` from -1 (first point)
    to +1 (second) runs along ``(-uz, uy)``, i.e. to the left of the direction of travel
    (B.6-B.8 with the atan2 form, seed-000 spec M22). With this orientation a circle sends
    lobe p to the azimuth Phi(p, h) = 2 p gamma_t - 2 gamma_i + p pi relative to omega_i,
    gamma_i = asin h (pbrt, d'Eon 2011; spec M18).
    """
    ey, ez = dir_to_local(uy, uz, psi)
    g = atan2(-b * ey, a * ez)  # tangent where the normal is perpendicular to e
    pts = []
    for gg in (g, g + jnp.pi):
        ly, lz = a * jnp.cos(gg), b * jnp.sin(gg)
        wy, wz = dir_to_world(ly, lz, psi)
        pts.append((cy + wy, cz + wz))
    (y0, z0), (y1, z1) = pts
    right_y, right_z = -uz, uy
    s0 = (y0 - cy) * right_y + (z0 - cz) * right_z
    swap = s0 > 0
    ya, za = jnp.where(swap, y1, y0), jnp.where(swap, z1, z0)
    yb, zb = jnp.where(swap, y0, y1), jnp.where(swap, z0, z1)
    return (ya, za), (yb, zb)


def half_width(uy, uz, a, b, psi):
    """Projected half width of the ellipse seen along the 2D unit direction ``(uy, uz)``.

    sqrt(a^2 e_z^2 + b^2 e_y^2) with e the direction in the ellipse frame (spec Q-F4); for
    a = 1 and a direction at azimuth phi this is Huang's D = sqrt(1 - e^2 sin^2 phi)
    (Huang Eq. 4.27) when the major axis is perpendicular to phi = 0.
    """
    ey, ez = dir_to_local(uy, uz, psi)
    return jnp.sqrt(a * a * ez * ez + b * b * ey * ey)


def intersect_segment(py, pz, dy, dz, cy, cz, a, psi, leaving):
    """Nearest positive hit of the ray ``p + t (dy, dz)`` with a segment (centre, half length
    ``a``, direction ``psi``): ``(t, hit)`` as :func:`intersect` (a ray along the segment's line
    does not meet it; ``leaving``: the ray starts on it, so it cannot)."""
    ey, ez = jnp.cos(psi), jnp.sin(psi)
    den = dy * ez - dz * ey                       # cross(d, e)
    ok = (den != 0) & ~leaving
    inv = 1.0 / jnp.where(ok, den, 1.0)
    wy, wz = cy - py, cz - pz
    t = (wy * ez - wz * ey) * inv                 # cross(w, e) / cross(d, e)
    s = (wy * dz - wz * dy) * inv                 # cross(w, d) / cross(d, e): along the segment
    hit = ok & (t > 0) & (jnp.abs(s) <= a)
    return jnp.where(hit, t, jnp.inf), hit


def segment_normal(psi):
    """Unit normal ``(ny, nz)`` of a segment of direction ``psi`` (its direction turned by +90 deg)."""
    return -jnp.sin(psi), jnp.cos(psi)


def segment_half_width(uy, uz, a, psi):
    """Projected half width of a segment seen along the 2D unit direction ``(uy, uz)``."""
    return a * jnp.abs(uy * jnp.sin(psi) - uz * jnp.cos(psi))
