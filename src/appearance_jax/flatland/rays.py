"""Small helpers on rays shared by the flatland tracers: direction checks, the default incident field,
and the meridional focus test of the wave mode (:mod:`.tracer`, :mod:`.drop`)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..core import vec as V
from ..core.vec import Vec3


def _crossing(f, tf, length, mask):
    """1 where the neighbouring ray crosses this one at 0 < s < length along the segment."""
    ny, nz = -f["dz"], f["dy"]                  # 2D normal of the direction (sign irrelevant)
    a = tf["py"] * ny + tf["pz"] * nz           # transverse offset at s = 0
    b = tf["dy"] * ny + tf["dz"] * nz           # its rate of change
    ok = b != 0
    s = jnp.where(ok, -a / jnp.where(ok, b, 1.0), -1.0)
    return (mask & ok & (s > 0) & (s < length)).astype(jnp.int32)


def check_direction(label: str, w: Vec3) -> None:
    """Eager check that a concrete direction is a single finite unit vector."""
    comps = tuple(w)
    if any(isinstance(c, jax.core.Tracer) for c in comps):
        return
    import numpy as np

    v = np.array([np.asarray(c, float) for c in comps])
    if v.shape != (3,) or not np.all(np.isfinite(v)) or abs(np.linalg.norm(v) - 1.0) > 1e-4:
        raise ValueError(f"{label} = {v.tolist()} must be one finite unit vector (|w| = 1), e.g. "
                         "core.frame.fiber_direction(theta, phi)")


def _default_field(wi: Vec3, N):
    """Unit field perpendicular to the propagation -wi, as close to the fiber axis as
    possible (TM for a cylinder at normal incidence: E parallel to the axis)."""
    d = -wi
    x = Vec3(jnp.ones(()), jnp.zeros(()), jnp.zeros(()))
    e = V.normalize(x - d * V.dot(x, d))
    cdt = jnp.complex64 if jnp.result_type(float) == jnp.float32 else jnp.complex128
    return Vec3(*(jnp.broadcast_to(jnp.asarray(c, cdt), (N,)) for c in e))
