"""From a feather's barb curves to the local frame of :mod:`appearance_jax.bsdf.rock_dove`.

Huang's pipeline (Ch. 5.4.2, [T:1690-1704]; spec seed-001 §1.4.7) grooms a feather as barb curves
(vertex chains) whose vertex normals give the local barbule orientation; each curve segment is a
"barb" primitive whose shading frame is the local barb plane. Barbules and ramus are not geometry:
the angle between the barbules and the ramus is a shift of the shading frame ([T:1792]), and the
barbules' random orientation is noise added to mu per barb when the geometry is exported, not a
term of the BSDF ([T:1750]). This module is that bookkeeping:

- :func:`barb_frame`: the frame (s, t, n) of rock_dove's local coordinates at a point of a barb:
  n = the vertex normal made orthogonal to the curve tangent T (the barb-plane normal), t = the
  barbule axis, at ``barbule_angle`` from the ramus within the barb plane,
  ``t = cos(a) T' + sin(a) (n x T')`` (T' = T made orthogonal to n), and s = t x n, across the
  barbules. At the default a = pi/2 the barbules stand perpendicular to the ramus and s = T': the
  neighbours, H apart, follow each other along the ramus. ``frame.to_local(w)`` gives the
  directions that rock_dove evaluates.
- :func:`barb_mu`: mu per barb with Gaussian noise of ``sigma`` rad (one draw per barb from a key),
  clipped to rock_dove's open range (-pi/2, pi/2).

Example::

    import jax
    from appearance_jax.bsdf import barb_frames, rock_dove
    from appearance_jax.core.vec import Vec3
    frame = barb_frames.barb_frame(Vec3(1.0, 0.0, 0.0), Vec3(0.0, 0.2, 1.0))  # tangent, vertex normal
    mu = barb_frames.barb_mu(-0.35, 0.05, jax.random.PRNGKey(0), 100)       # 100 barbs
    f = rock_dove.eval(rock_dove.Params(mu=mu[0]), frame.to_local(wi_world), frame.to_local(wo_world))
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..core import vec as V
from ..core.frame import Frame
from ..core.params import check_int
from ..core.vec import Vec3

# keeps a perturbed mu inside rock_dove's open range (-pi/2, pi/2)
_MU_LIMIT = 0.5 * math.pi - 1e-6


def barb_frame(tangent: Vec3, normal: Vec3, barbule_angle=0.5 * math.pi) -> Frame:
    """rock_dove's local frame at a barb point (module docstring): ``tangent`` along the barb curve,
    ``normal`` the vertex normal (any lengths, not parallel), ``barbule_angle`` (rad) between the
    barbule axis and the ramus in the barb plane. Arrays of any common shape."""
    for name, w in (("tangent", tangent), ("normal", normal)):
        comps = [np.asarray(c, float) for c in w if not isinstance(c, jax.core.Tracer)]
        if len(comps) == 3 and (not all(np.all(np.isfinite(c)) for c in comps)
                                or np.any(sum(c * c for c in comps) == 0)):
            raise ValueError(f"barb_frame: {name} = {[c.tolist() for c in comps]} must be finite and non-zero")
    n = V.normalize(normal)
    tp = tangent - n * V.dot(n, tangent)
    lt = V.norm(tp)
    if not isinstance(lt, jax.core.Tracer) and np.any(np.asarray(lt) <= 1e-9 * np.asarray(V.norm(tangent))):
        raise ValueError("barb_frame: the tangent is parallel to the vertex normal (no barb plane)")
    tp = tp * (1.0 / lt)
    a = jnp.asarray(barbule_angle, jnp.result_type(float))
    t = tp * jnp.cos(a) + V.cross(n, tp) * jnp.sin(a)
    return Frame(V.cross(t, n), t, n)


def barb_mu(mu, sigma, key, n_barbs: int):
    """``n_barbs`` values of mu (rad): ``mu + sigma N(0, 1)``, one per barb, clipped to (-pi/2, pi/2)."""
    n_barbs = check_int("barb_mu.n_barbs", n_barbs, 1)
    s = float(sigma) if not isinstance(sigma, jax.core.Tracer) else None
    if s is not None and not (math.isfinite(s) and s >= 0):
        raise ValueError(f"barb_mu: sigma = {sigma!r} rad must be finite and >= 0")
    m = float(mu) if not isinstance(mu, jax.core.Tracer) else None
    if m is not None and not abs(m) < 0.5 * math.pi:
        raise ValueError(f"barb_mu: mu = {mu!r} rad must lie in (-pi/2, pi/2)")
    z = jax.random.normal(key, (n_barbs,), jnp.result_type(float))
    return jnp.clip(mu + sigma * z, -_MU_LIMIT, _MU_LIMIT)
