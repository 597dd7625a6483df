"""The advection half of one flow step, with every trajectory traced in one pass.

A step of :mod:`.flow` traces trajectories from four sets of points: the ``u_theta`` faces and
the ``u_phi`` faces (vector advection), the cell centres (eta and Gamma, or the BiMocq^2
backward map) and the forward map's points (traced forwards). Tracing each set with its own
copy of the great-circle half step (as separate calls of :mod:`.advect` and :mod:`.bimocq` would)
repeats the same program four times; concatenated into one flat set with a per-point time step
(+dt backwards, -dt forwards), XLA compiles one copy. The results are those of
:func:`~.advect.advect_velocity`, :func:`~.advect.advect_scalar` and
:func:`~.bimocq.advance` (tested against them).
"""

from __future__ import annotations

import jax.numpy as jnp

from ..core.vec import Vec3
from . import bimocq as _bimocq
from .advect import backtrace, transport
from .grid import SphereGrid, angles, components, point, tangent


def _flat(v: Vec3) -> Vec3:
    return Vec3(*(jnp.ravel(c) for c in v))


def _cat(vs) -> Vec3:
    return Vec3(*(jnp.concatenate([getattr(v, a) for v in vs]) for a in ("x", "y", "z")))


def advect_step(grid: SphereGrid, u_theta, u_phi, centre_fields, maps, dt, order: int = 2):
    """Advect the staggered velocity by itself and carry the cell-centred quantities.

    Args:
        u_theta, u_phi: the velocity (also the advected vector field).
        centre_fields: cell-centred fields looked up at the centres' departure points (used
            when ``maps`` is None), stacked ``(K, n_theta, n_phi)``.
        maps: :class:`~.bimocq.Maps` to advance instead (or None).
        dt: time step; order: 1 or 2.

    Returns:
        ``(u_theta*, u_phi*, fields*, maps)``: ``fields*`` the looked-up fields (None with maps),
        ``maps`` the advanced maps (None without).
    """
    dtype = u_theta.dtype
    n_t = grid.theta_shape[0] * grid.n_phi
    n_c = grid.n_theta * grid.n_phi
    tt, pt = (jnp.asarray(a, dtype) for a in grid.u_theta_points())
    tp, pp = (jnp.asarray(a, dtype) for a in grid.u_phi_points())
    tc, pc = (jnp.asarray(a, dtype) for a in grid.centres())
    ut_c, up_c = grid.velocity_at_centres(u_theta, u_phi)
    sets = [(tt, pt, u_theta, grid.u_phi_at_theta_faces(u_phi)),
            (tp, pp, grid.u_theta_at_phi_faces(u_theta), u_phi),
            (tc, pc, ut_c, up_c)]
    points = [_flat(point(th, ph)) for th, ph, _, _ in sets]
    vels = [_flat(tangent(ut, up, th, ph)) for th, ph, ut, up in sets]
    dts = [jnp.full((a.size,), 1.0, dtype) for a, _, _, _ in sets]

    def velocity(q):
        return grid.sample_vector(u_theta, u_phi, q)

    if maps is not None:  # the forward map's points, traced forwards
        Y = _flat(maps.forward)
        points.append(Y)
        vels.append(velocity(Y))
        dts.append(jnp.full((n_c,), -1.0, dtype))
    c = backtrace(_cat(points), _cat(vels), velocity, jnp.concatenate(dts) * dt, order)
    q = c.departure
    # the vector step: sample, carry back along the circle, project
    n_f = n_t + n_c
    faces = c._replace(p=Vec3(*(a[:n_f] for a in c.p)), u_hat=Vec3(*(a[:n_f] for a in c.u_hat)), s=c.s[:n_f])
    v = transport(velocity(Vec3(*(a[:n_f] for a in q))), faces)
    th_f = jnp.concatenate([tt.ravel(), tp.ravel()])
    ph_f = jnp.concatenate([pt.ravel(), pp.ravel()])
    a_t, a_p = components(v, th_f, ph_f)
    ut_s = a_t[:n_t].reshape(grid.theta_shape)
    up_s = a_p[n_t:].reshape(grid.shape)
    qc = Vec3(*(a[n_f:n_f + n_c].reshape(grid.shape) for a in q))
    th_d, ph_d = angles(qc)
    if maps is None:
        fields = jnp.stack([grid.sample(f, th_d, ph_d) for f in centre_fields])
        return ut_s, up_s, fields, None
    X = _bimocq.sample_points(grid, maps.backward, th_d, ph_d)
    Y = Vec3(*(a[n_f + n_c:].reshape(grid.shape) for a in q))
    return ut_s, up_s, None, maps._replace(backward=X, forward=Y)

