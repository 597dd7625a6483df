"""Weaves for the cloth model: tangent curves (App. E), masking/shadowing (Sadeghi Eqs. 5.14-5.16) and
reweighting (Sadeghi Eqs. 5.18-5.19) of Sadeghi 2011, Ch. 5 (spec seed-002 §1.4.3-1.4.4).

**Tangent curve** (App. E, L2872-2875). One thread family of the smallest repeating patch is
described by its tangent offset alpha (degrees, the inclination of the thread tangent from the
surface plane) as a piecewise-linear function of the length along the thread: control-point
offsets o_0..o_{K-1} and the lengths l_0..l_{K-2} of the segments between consecutive points.
A zero-length segment is a jump (a discontinuity of the curve), which also joins disjoint
sub-curves (Polyester back side, velvet). Curves of different K are padded to a common K by
repeating the last offset with zero-length segments (they are never sampled). T equidistant
samples at the segment midpoints s_k = (k + 1/2) L / T, k = 0..T-1 (L = sum of lengths),
are located by counting cumulative lengths <= s_k (the branch-free ``searchsorted(side=right)``:
a zero-length segment is never selected, no division by its length), then interpolated.
Gradients: smooth in the offsets, piecewise smooth in the lengths.

**Frame** of a tangent sample (decision D-C6, ``sign = +1``): with the surface normal N and the
family's nominal direction u (in the surface plane), t(alpha) = cos(alpha) u + sin(alpha) N,
n(alpha) = -sin(alpha) u + cos(alpha) N (the local normal tilts with the tangent, L2441) and
v = N x u. ``sign = -1`` negates alpha (the thesis does not state the sign; symmetric curves
do not care).

**Masking/shadowing** (Sadeghi Eqs. 5.14-5.16), between threads of the same family only:
M(t, w) = max(cos phi, 0) with phi the azimuth of w about t from n(alpha), and
M(t, w_i, w_r) = (1 - u(phi_d)) M_i M_r + u(phi_d) min(M_i, M_r) with u a unit-*height*
Gaussian of std ``width`` (15-25 deg in Ashikhmin et al. 2000; default 20 deg, D-C5) of
phi_d = phi_i - phi_r wrapped to [-pi, pi]. **Reweighting** (Sadeghi Eqs. 5.18-5.19): the same blend of
P(t, w) = max(cos psi, 0), psi = atan2(w.t, w.n) the angle between n and w projected onto the
(t, n) plane (projected length of the tangent sample). Both are symmetric in (w_i, w_r).

**Weave builders** (continuous arguments in degrees / relative lengths; numpy arrays for
concrete arguments, jnp arrays when an argument is traced, so a fitter may differentiate through
them): :func:`plain` (a ramp: Linen), :func:`crossing` (two flat sections joined by a ramp: Silk crepe flat threads, Silk Shot), :func:`satin` (flat sections at
-alpha, 0, +alpha with an optional knee: Polyester front flat threads), :func:`join` (disjoint
sub-curves: Polyester back) and :func:`twill`.

Twill is **not in the thesis**; this library's construction: in an over/under twill each
thread of a family floats over ``over`` crossing threads and dives under ``under``; its visible
part rises from -alpha to 0 over half a crossing pitch, stays flat (0) for the float,
(over - 1) pitches, and falls from 0 to +alpha over half a pitch:
offsets {-alpha, 0, 0, alpha}, lengths {pitch/2, (over - 1) pitch, pitch/2}. The diagonal
shift of the floats from row to row does not change a family's distribution of tangents,
which is all this model sees (no masking between families), so it is not modelled. The
coverages are over/(over + under) and under/(over + under). ``over = 1`` gives :func:`plain`
(a zero-length float).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax.numpy as jnp

from ...core.arrays import namespace
from ...core.special import safe_atan2, safe_sqrt

DEG = math.pi / 180.0


class Curve(NamedTuple):
    """A tangent curve: K offsets (deg) and K - 1 segment lengths (relative units)."""

    offsets: object
    lengths: object


def _arr(*xs):
    xp = namespace(*xs)
    return xp.stack([xp.asarray(x, dtype=jnp.result_type(float)) for x in xs])


def plain(alpha=25.0, length=1.0) -> Curve:
    """A linear ramp {-alpha, alpha} of one segment (plain weave, Linen of Table E.1)."""
    return Curve(_arr(-alpha, alpha), _arr(length))


def straight(length=1.0) -> Curve:
    """A straight thread {0, 0} (twisted threads of Table E.1)."""
    return Curve(_arr(0.0, 0.0), _arr(length))


def crossing(alpha=35.0, flat=1.0, ramp=1.0, flat2=None) -> Curve:
    """Flat at -alpha, ramp, flat at +alpha: {-a, -a, a, a}, {flat, ramp, flat2 (= flat)}."""
    flat2 = flat if flat2 is None else flat2
    return Curve(_arr(-alpha, -alpha, alpha, alpha), _arr(flat, ramp, flat2))


def satin(alpha=32.0, knee=18.0, edge=1.33, ramp_outer=0.66, ramp_inner=2.0, float_length=2.0) -> Curve:
    """Flat sections at -alpha, 0, +alpha (three highlights) with a knee at +-``knee``:
    {-a, -a, -k, 0, 0, k, a, a}, {edge, ramp_outer, ramp_inner, float, ramp_inner, ramp_outer, edge}.
    The defaults are the Polyester Satin Charmeuse front flat thread (Table E.1)."""
    return Curve(_arr(-alpha, -alpha, -knee, 0.0, 0.0, knee, alpha, alpha),
                 _arr(edge, ramp_outer, ramp_inner, float_length, ramp_inner, ramp_outer, edge))


def twill(alpha=25.0, over=2, pitch=1.0) -> Curve:
    """This library's twill tangent curve (module docstring): {-a, 0, 0, a}, {p/2, (over-1) p, p/2}."""
    return Curve(_arr(-alpha, 0.0, 0.0, alpha), _arr(0.5 * pitch, (over - 1) * pitch, 0.5 * pitch))


def twill_coverage(over=2, under=1):
    """Coverages (a_1, a_2) of an over/under twill without gaps."""
    return over / (over + under), under / (over + under)


def join(*curves: Curve) -> Curve:
    """Disjoint sub-curves joined by zero-length segments (jumps)."""
    xp = namespace(curves)
    offs = xp.concatenate([xp.asarray(c.offsets) for c in curves])
    parts = []
    for k, c in enumerate(curves):
        if k:
            parts.append(xp.zeros((1,), offs.dtype))
        parts.append(xp.asarray(c.lengths, dtype=offs.dtype))
    return Curve(offs, xp.concatenate(parts))


def pad(curve: Curve, k: int) -> Curve:
    """Pad a curve to ``k`` control points: repeat the last offset with zero-length segments."""
    xp = namespace(curve)
    o, ln = xp.asarray(curve.offsets), xp.asarray(curve.lengths)
    n = o.shape[-1]
    if n > k:
        raise ValueError(f"tangent curve has {n} control points, more than {k}")
    if ln.shape[-1] != n - 1:
        raise ValueError(f"tangent curve: {n} offsets need {n - 1} segment lengths, got {ln.shape[-1]}")
    o = xp.concatenate([o, xp.broadcast_to(o[..., -1:], o.shape[:-1] + (k - n,))], axis=-1)
    ln = xp.concatenate([ln, xp.zeros(ln.shape[:-1] + (k - n,), ln.dtype)], axis=-1)
    return Curve(o, ln)


def stack(curves) -> Curve:
    """Families' curves -> offsets (J, K), lengths (J, K - 1), padded to the largest K."""
    k = max(int(jnp.shape(c.offsets)[-1]) for c in curves)
    padded = [pad(c, k) for c in curves]
    xp = namespace(padded)
    return Curve(xp.stack([c.offsets for c in padded], axis=-2), xp.stack([c.lengths for c in padded], axis=-2))


def sample_curve(offsets, lengths, n: int):
    """Tangent offsets (same unit as ``offsets``) at the n midpoints of equal arc length.

    ``offsets`` (..., K), ``lengths`` (..., K - 1) -> (..., n). Zero-length segments are jumps.
    """
    offsets = jnp.asarray(offsets)
    lengths = jnp.asarray(lengths, dtype=offsets.dtype)
    cum = jnp.concatenate([jnp.zeros_like(lengths[..., :1]), jnp.cumsum(lengths, axis=-1)], axis=-1)  # (..., K)
    total = cum[..., -1:]
    s = (jnp.arange(n, dtype=offsets.dtype) + 0.5) / n * total  # (..., n)
    kmax = offsets.shape[-1] - 2
    # segment index: last m with cum_m <= s (a zero-length segment m has cum_m = cum_{m+1} <= s: skipped)
    idx = jnp.sum(cum[..., None, :] <= s[..., :, None], axis=-1) - 1
    idx = jnp.clip(idx, 0, kmax)
    c0 = jnp.take_along_axis(cum, idx, axis=-1)
    c1 = jnp.take_along_axis(cum, idx + 1, axis=-1)
    o0 = jnp.take_along_axis(offsets, idx, axis=-1)
    o1 = jnp.take_along_axis(offsets, idx + 1, axis=-1)
    d = c1 - c0
    ok = d > 0
    frac = jnp.where(ok, (s - c0) / jnp.where(ok, d, 1.0), 0.0)
    return o0 + (o1 - o0) * frac


def unit_gaussian(x, width):
    """Unit-height Gaussian u(x) = exp(-x^2 / (2 width^2)) (Eq. 5.16; x, width in radians)."""
    return jnp.exp(-0.5 * (x / width) ** 2)


def _normalised_cos(a, b):
    """a / sqrt(a^2 + b^2) (1 where both vanish), and the norm."""
    r = safe_sqrt(a * a + b * b)
    ok = r > 1e-12
    return jnp.where(ok, a / jnp.where(ok, r, 1.0), 1.0), r


def blend(x_i, x_r, diff, width):
    """(1 - u(diff)) x_i x_r + u(diff) min(x_i, x_r) (Eqs. 5.16, 5.19)."""
    uu = unit_gaussian(diff, width)
    return (1.0 - uu) * x_i * x_r + uu * jnp.minimum(x_i, x_r)


def masking(in_, iv, on, ov, width):
    """M(t, w_i, w_r) from the components of w_i, w_r along n(alpha) and v (Eqs. 5.14-5.16).

    phi_d = atan2(sin, cos) of the angle between the projections onto the normal plane,
    in [-pi, pi] (wrapped by construction).
    """
    ci, _ = _normalised_cos(in_, iv)
    cr, _ = _normalised_cos(on, ov)
    phi_d = safe_atan2(in_ * ov - iv * on, in_ * on + iv * ov)
    return blend(jnp.maximum(ci, 0.0), jnp.maximum(cr, 0.0), phi_d, width)


def reweighting(it, in_, ot, on, width):
    """P(t, w_i, w_r) from the components along t and n(alpha) (Eqs. 5.18-5.19).

    psi = atan2(w.t, w.n); psi_d = psi_i - psi_r as the angle between the projections onto
    the (t, n) plane, in [-pi, pi].
    """
    ci, _ = _normalised_cos(in_, it)
    cr, _ = _normalised_cos(on, ot)
    psi_d = safe_atan2(it * on - in_ * ot, in_ * on + it * ot)
    return blend(jnp.maximum(ci, 0.0), jnp.maximum(cr, 0.0), psi_d, width)


def single(it, in_, iv):
    """M(t, w) and P(t, w) of one direction (Eqs. 5.14, 5.18)."""
    cm, _ = _normalised_cos(in_, iv)
    cp, _ = _normalised_cos(in_, it)
    return jnp.maximum(cm, 0.0), jnp.maximum(cp, 0.0)
