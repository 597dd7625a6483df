"""Caustics of a smooth section: offsets where the exit direction of a lobe is stationary.

Where dPhi_p/dh = 0 the far-field intensity of lobe p is singular (geometric optics): the
rainbow angles of a water cylinder (Descartes' minimum deviation; Sadeghi 2011 §3.2, spec
seed-002 §1.2.8) and the TRT caustics of hair (Marschner et al. 2003). They are found on
the tracer itself: the exit azimuth and its exact derivative with respect to h (forward
mode through the trace) on a grid, then bisection on the derivative inside every bracket
where it changes sign.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..core import vec as V
from ..core.frame import fiber_angles
from ..core.params import check_int
from ..core.vec import Vec3
from .section import Section
from .tracer import _trace


class Caustics(NamedTuple):
    """Stationary points of lobe p (one per grid bracket; ``valid`` marks real ones)."""

    h: jax.Array                  # offsets (n_grid - 1,)
    phi: jax.Array                # exit azimuth (rad)
    scattering_angle: jax.Array   # angle between the incident and outgoing propagation (rad)
    valid: jax.Array              # bool


def caustics(section: Section, wi: Vec3, lobe: int, *, n_grid: int = 257, iters: int = 60) -> Caustics:
    """Offsets h where the exit azimuth of lobe ``lobe`` (its emission in split mode, so the
    section must be a single smooth convex shape) is stationary, to bisection precision.

    Example: ``caustics(cylinder(1.331), fiber_direction(0, 0), 2)`` gives the primary
    rainbow; its scattering angle is Descartes' 137.63 deg at n = 1.331.
    """
    section = section.validate()
    if len(section.shapes) != 1 or section.shapes[0].interface.rough or section.periodic:
        raise ValueError("flatland.caustics needs a single smooth shape (one emission per lobe)")
    lobe = check_int("flatland.caustics.lobe", lobe, 0)
    n_grid = check_int("flatland.caustics.n_grid", n_grid, 3)
    iters = check_int("flatland.caustics.iters", iters, 1)
    return _caustics(section, wi, lobe, n_grid, iters)


@partial(jax.jit, static_argnames=("lobe", "n_grid", "iters"))
def _caustics(section, wi, lobe, n_grid, iters):
    n_events = lobe + 1
    d_in = -wi

    def exit_dir(h):
        rec = _trace(section, wi, h, jax.random.PRNGKey(0), None, n_events, "split", False, False)
        return Vec3(*(c[lobe] for c in rec.direction))

    def phi_and_slope(h):
        def f(hh):
            d = exit_dir(hh)
            _, ph = fiber_angles(d)
            return ph
        ph, dph = jax.jvp(f, (h,), (jnp.ones_like(h),))
        return ph, dph

    dtype = jnp.result_type(float)
    # open grid: avoid h = +-1 exactly (grazing entry, where dPhi/dh diverges)
    g = jnp.linspace(-1.0, 1.0, n_grid, dtype=dtype) * (1.0 - 1e-9)
    _, s = phi_and_slope(g)
    lo, hi = g[:-1], g[1:]
    s_lo, s_hi = s[:-1], s[1:]
    valid = (s_lo * s_hi < 0) & jnp.isfinite(s_lo) & jnp.isfinite(s_hi)

    def bisect(carry, _):
        a, b, sa = carry
        m = 0.5 * (a + b)
        _, sm = phi_and_slope(m)
        left = sa * sm <= 0
        return (jnp.where(left, a, m), jnp.where(left, m, b), jnp.where(left, sa, sm)), None

    (a, b, _), _ = jax.lax.scan(bisect, (lo, hi, s_lo), None, length=iters)
    h = 0.5 * (a + b)
    d = exit_dir(h)
    _, ph = fiber_angles(d)
    cos_sc = jnp.clip(V.dot(d, Vec3(*(jnp.broadcast_to(c, h.shape) for c in d_in))), -1.0, 1.0)
    return Caustics(h, ph, jnp.arccos(cos_sc), valid)
