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

Ray-ellipse intersection is :func:`appearance_jax.flatland.geometry.intersect`; ray-segment intersection
(:func:`segment_hit`) is flatland's segment primitive. Independent of the masking's interval solver,
which cuts the screen into pieces and composites them analytically.

Example::

    import jax
    from appearance_jax.flatland import vane
    r = vane.vane_masking((0.5, 0.8660254), e_b=1.6, l_bb=1.0, theta_bb=0.26, w_bp=0.6, w_bd=0.6,
                          key=jax.random.PRNGKey(0))
    r.weights, r.stderr   # (w_b, w_bp, w_bd, w_t) and their binomial standard errors
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..core.params import check_int
from . import geometry as G


class VaneMasking(NamedTuple):
    """What :func:`vane_masking` returns."""

    weights: jax.Array     # (4,): fractions of the rays stopped by a barb, a proximal, a distal barbule, none
    stderr: jax.Array      # (4,): binomial standard errors
    h_range: jax.Array     # (2,): min and max offset h at which rays meet their first barb (barbules ignored)
    truncated: jax.Array   # fraction of rays whose path through the vane runs past the copies traced


def segment_hit(py, pz, dy, dz, p, q):
    """Distance t > 0 along the ray ``(py, pz) + t (dy, dz)`` to the segment p-q (2-tuples) and whether
    it crosses it (``inf`` and False otherwise; a ray along the segment does not cross it)."""
    ey, ez = q[0] - p[0], q[1] - p[1]
    den = dy * ez - dz * ey                          # cross(d, e)
    ok = den != 0
    inv = 1.0 / jnp.where(ok, den, 1.0)
    wy, wz = p[0] - py, p[1] - pz
    t = (wy * ez - wz * ey) * inv                    # cross(w, e) / cross(d, e)
    s = (wy * dz - wz * dy) * inv                    # cross(w, d) / cross(d, e)
    hit = ok & (t > 0) & (s >= 0) & (s <= 1)
    return jnp.where(hit, t, jnp.inf), hit


@partial(jax.jit, static_argnames=("n_rays", "corner", "copies"))
def _vane(wy, wz, e_b, l_bb, theta_bb, w_bp, w_bd, key, n_rays, corner, copies):
    dtype = jnp.result_type(float)
    r = jnp.hypot(wy, wz)
    dx, dy = wy / r, wz / r                            # the 2D view direction (x across, y normal)
    X = 1.0 + 2.0 * l_bb * jnp.cos(theta_bb)
    cy = corner * l_bb * jnp.sin(theta_bb)
    period = X * jnp.abs(dy)
    k_m, k_u = jax.random.split(key)
    u = (jnp.arange(n_rays, dtype=dtype) + jax.random.uniform(k_m, (n_rays,), dtype)) / n_rays
    m = (u - 0.5) * period                             # screen coordinate along (dy, -dx)
    height = 2.0 + e_b + 2.0 * l_bb                    # well above everything
    depth = height / jnp.abs(dy)
    py, pz = m * dy + depth * dx, -m * dx + depth * dy  # origins: m (dy, -dx) + depth (dx, dy)
    ry, rz = -dx, -dy                                  # travel
    k = jnp.arange(-copies, copies + 1, dtype=dtype)[None, :]
    cx = k * X
    P = lambda a: a[:, None]  # noqa: E731
    t_b, _ = G.intersect(P(py), P(pz), ry, rz, cx, 0.0, 0.5, 0.5 * e_b, 0.0, 0.0, 2.0 * jnp.pi,
                         jnp.zeros(cx.shape, bool))
    zero = jnp.zeros_like(cx)
    t_p, _ = segment_hit(P(py), P(pz), ry, rz, (cx + 0.5, zero), (cx + 0.5 * X, cy + zero))
    t_d, _ = segment_hit(P(py), P(pz), ry, rz, (cx + 0.5 * X, cy + zero), (cx + X - 0.5, zero))
    # semi-transparent barbules: an independent coin per crossing; the ray stops at the nearest stop
    c_p, c_d = jax.random.uniform(k_u, (2,) + t_p.shape, dtype)
    t_p = jnp.where(c_p < w_bp, t_p, jnp.inf)
    t_d = jnp.where(c_d < w_bd, t_d, jnp.inf)
    best = jnp.stack([jnp.min(t_b, axis=1), jnp.min(t_p, axis=1), jnp.min(t_d, axis=1)])   # (3, n)
    stop = jnp.isfinite(jnp.min(best, axis=0))
    kind = jnp.where(stop, jnp.argmin(best, axis=0), 3)
    frac = jnp.stack([jnp.mean((kind == j).astype(dtype)) for j in range(4)])
    se = jnp.sqrt(frac * (1.0 - frac) / max(n_rays - 1, 1))
    # the first barb met (barbules ignored): its offset h across the projected diameter
    kb = jnp.argmin(t_b, axis=1)
    met = jnp.isfinite(jnp.min(t_b, axis=1))
    half = G.half_width(dx, dy, 0.5, 0.5 * e_b, 0.0)   # projected half width of a barb
    h = (m - jnp.take(cx[0], kb) * dy) / half
    h_range = jnp.stack([jnp.min(jnp.where(met, h, jnp.inf)), jnp.max(jnp.where(met, h, -jnp.inf))])
    # truncated: the ray's crossing of the vane's band |y| <= height leaves the copies traced
    reach = jnp.abs(m * dy) + height * jnp.abs(dx / dy) + X
    trunc = jnp.mean((reach > copies * X).astype(dtype))
    return VaneMasking(frac, se, h_range, trunc)


def vane_masking(w, e_b, l_bb, theta_bb, w_bp, w_bd, key, *, n_rays: int = 2**17, corner: int = 1,
                 copies: int = 24) -> VaneMasking:
    """Monte Carlo barb-scale masking of the vane seen along the 2D direction ``w`` = (x across the vane,
    y its normal; above or below, not in the vane plane): :class:`VaneMasking` (module docstring).
    ``e_b`` > 0, ``l_bb`` >= 0, ``theta_bb`` in [0, pi/2), ``w_bp``, ``w_bd`` in [0, 1] (the barbule
    coverages), ``corner`` +1 or -1, ``copies`` barbs traced on each side."""
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
    f = lambda v: jnp.asarray(v, jnp.result_type(float))  # noqa: E731
    return _vane(f(wy), f(wz), f(e_b), f(l_bb), f(theta_bb), f(w_bp), f(w_bd), key, int(n_rays), int(corner),
                 int(copies))
