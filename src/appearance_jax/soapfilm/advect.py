"""Semi-Lagrangian advection on the sphere along great circles (Huang 2022, Sec. 3.4.2, App. B).

Scalars (Huang Eqs. 3.18-3.19): the value at a grid point is the value found a time step
back along the flow. Vectors (the thesis' scheme, Huang Eqs. 3.20-3.21 and the five steps of
Sec. 3.4.2): at each sample point x with velocity u, the great circle
C(s) = sin(s) u_hat + cos(s) w_hat (w_hat = x, u_hat = u / |u|) is followed back by
Delta s = |u| Delta t; the velocity found there is split into its components along C and along
the binormal v_hat = w_hat x u_hat, carried back to x unchanged (parallel transport along a
great circle) and projected on (e_theta, e_phi). The geometric terms of Huang Eq. 3.12
(-u_phi^2 / tan theta, u_theta u_phi / tan theta) are thereby handled implicitly and the poles
need no special case.

``order=2`` (default, the thesis' choice for all its results) is the half step of Huang App. B:
a half step back along the first circle, the velocity found there carried back to x defines a
second circle, and the full step is taken along that one. ``order=1`` is the single step.

``scheme="latlong"`` is a baseline for comparisons: the trajectory is integrated in (theta,
phi) coordinates (Euler), scalars are looked up there and velocities are advected like
scalars with the geometric terms added afterwards as a backward-Euler body force (Yang et al.,
the variant the thesis rejects, Huang Sec. 3.4.2). Near the poles it shows the artefacts of
Huang Fig. 3.8.

Everything here is pure jnp on fixed shapes: jit, vmap and grad pass through.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax.numpy as jnp

from ..core.vec import Vec3, cross, dot
from .grid import SphereGrid, angles, components, point, tangent

__all__ = ["Circle", "great_circle", "backtrace", "transport", "advect_scalar", "advect_velocity",
           "ORDERS", "SCHEMES"]

ORDERS = (1, 2)
SCHEMES = ("great_circle", "latlong")


class Circle(NamedTuple):
    """A great circle through ``p`` (unit) with unit tangent ``u_hat`` there, followed back by
    the arc length ``s`` (radians; negative = forwards)."""

    p: Vec3
    u_hat: Vec3
    s: object

    def at(self, s) -> Vec3:
        """C(s) = sin(s) u_hat + cos(s) p (Huang Eq. 3.20)."""
        return self.u_hat * jnp.sin(s) + self.p * jnp.cos(s)

    def tangent_at(self, s) -> Vec3:
        """dC/ds at s."""
        return self.u_hat * jnp.cos(s) - self.p * jnp.sin(s)

    @property
    def binormal(self) -> Vec3:
        """v_hat = w_hat x u_hat, constant along the circle."""
        return cross(self.p, self.u_hat)

    @property
    def departure(self) -> Vec3:
        """C(-s) (Huang Eq. 3.21)."""
        return self.at(-self.s)


def _fallback_tangent(p: Vec3) -> Vec3:
    """Some unit tangent at ``p`` (used where the velocity is 0 and the direction is moot)."""
    use_z = jnp.abs(p.z) < 0.9
    a = Vec3(jnp.where(use_z, 0.0, 1.0), jnp.zeros_like(p.z), jnp.where(use_z, 1.0, 0.0))
    t = cross(a, p)
    return t / jnp.sqrt(dot(t, t))


def great_circle(p: Vec3, u: Vec3, dt) -> Circle:
    """The circle through ``p`` along the tangent velocity ``u``, followed back for ``dt``."""
    sq = dot(u, u)
    moving = sq > 1e-30
    speed = jnp.sqrt(jnp.where(moving, sq, 1.0))  # double where: finite gradients at u = 0
    u_hat = Vec3(*(jnp.where(moving, c / speed, f) for c, f in zip(u, _fallback_tangent(p))))
    return Circle(p, u_hat, jnp.where(moving, speed, 0.0) * dt)


def transport(v: Vec3, c: Circle) -> Vec3:
    """Carry the tangent vector ``v`` at ``c.departure`` back to ``c.p`` along ``c``, keeping its
    components along the circle and along the binormal (steps 3-4 of Huang Sec. 3.4.2)."""
    b = c.binormal
    return c.u_hat * dot(v, c.tangent_at(-c.s)) + b * dot(v, b)


def backtrace(p: Vec3, u: Vec3, velocity: Callable, dt, order: int = 2) -> Circle:
    """The circle whose departure point is where the fluid at ``p`` was ``dt`` earlier.

    Args:
        p: unit vectors (the sample points).
        u: the velocity at ``p`` (tangent Vec3).
        velocity: ``Vec3 -> Vec3``, the velocity field at arbitrary unit vectors (used by the
            half step only).
        dt: time step (dimensionless; negative traces forwards).
        order: 1 (single step, Huang Eq. 3.21) or 2 (half step, Huang App. B).
    """
    c1 = great_circle(p, u, dt)
    if order == 1:
        return c1
    if order != 2:
        raise ValueError(f"order = {order!r}: must be one of {ORDERS}")
    half = Circle(p, c1.u_hat, 0.5 * c1.s)
    u_half = transport(velocity(half.departure), half)
    return great_circle(p, u_half, dt)


def _check(order, scheme):
    if order not in ORDERS:
        raise ValueError(f"order = {order!r}: must be one of {ORDERS}")
    if scheme not in SCHEMES:
        raise ValueError(f"scheme = {scheme!r}: must be one of {SCHEMES}")


def _velocity_fn(grid: SphereGrid, u_theta, u_phi):
    return lambda q: grid.sample_vector(u_theta, u_phi, q)


def departure_points(grid: SphereGrid, u_theta, u_phi, theta, phi, ut_here, up_here, dt, order=2):
    """Departure points (Vec3) of the samples at ``(theta, phi)`` whose velocity there is
    ``(ut_here, up_here)``, with the circles used."""
    p = point(theta, phi)
    c = backtrace(p, tangent(ut_here, up_here, theta, phi), _velocity_fn(grid, u_theta, u_phi), dt, order)
    return c.departure, c


def advect_scalar(grid: SphereGrid, f, u_theta, u_phi, dt, order: int = 2, scheme: str = "great_circle"):
    """Advect the cell-centred scalar ``f`` by ``dt`` (Huang Eqs. 3.18-3.19)."""
    _check(order, scheme)
    th, ph = (jnp.asarray(a, f.dtype) for a in grid.centres())
    ut, up = grid.velocity_at_centres(u_theta, u_phi)
    if scheme == "latlong":
        th_d, ph_d = _latlong_departure(th, ph, ut, up, dt)
        return grid.sample(f, th_d, ph_d)
    q, _ = departure_points(grid, u_theta, u_phi, th, ph, ut, up, dt, order)
    return grid.sample(f, *angles(q))


def advect_velocity(grid: SphereGrid, u_theta, u_phi, dt, order: int = 2, scheme: str = "great_circle"):
    """Advect the staggered velocity by itself over ``dt``; returns ``(u_theta*, u_phi*)``."""
    _check(order, scheme)
    dtype = u_theta.dtype
    tt, pt = (jnp.asarray(a, dtype) for a in grid.u_theta_points())
    tp, pp = (jnp.asarray(a, dtype) for a in grid.u_phi_points())
    up_at_t = grid.u_phi_at_theta_faces(u_phi)
    ut_at_p = grid.u_theta_at_phi_faces(u_theta)
    if scheme == "latlong":
        return _yang(grid, u_theta, u_phi, (tt, pt, u_theta, up_at_t), (tp, pp, ut_at_p, u_phi), dt)
    out = []
    for th, ph, ut, up, pick in ((tt, pt, u_theta, up_at_t, 0), (tp, pp, ut_at_p, u_phi, 1)):
        q, c = departure_points(grid, u_theta, u_phi, th, ph, ut, up, dt, order)
        v = transport(grid.sample_vector(u_theta, u_phi, q), c)
        out.append(components(v, th, ph)[pick])
    return out[0], out[1]


# -- the latlong baseline ------------------------------------------------------------------
def _latlong_departure(th, ph, ut, up, dt):
    """Euler step back in (theta, phi); a departure beyond a pole is reflected across it."""
    sin_t = jnp.maximum(jnp.sin(th), 1e-6)
    th_d = th - dt * ut
    ph_d = ph - dt * up / sin_t
    over_n = th_d < 0
    over_s = th_d > jnp.pi
    th_d = jnp.where(over_n, -th_d, jnp.where(over_s, 2 * jnp.pi - th_d, th_d))
    ph_d = jnp.where(over_n | over_s, ph_d + jnp.pi, ph_d)
    return th_d, jnp.mod(ph_d, 2 * jnp.pi)


def _yang(grid, u_theta, u_phi, at_t, at_p, dt):
    """Yang et al.'s variant: (u_theta, u_phi) looked up like scalars at the (theta, phi) Euler
    departure point (sign flips across a pole kept), then the geometric terms of Huang Eq. 3.12
    as a body force, integrated by backward Euler. The terms rotate (u_theta, u_phi) at the rate
    w = u_phi cot(theta), so backward Euler is the linear solve below."""
    out = []
    for (th, ph, ut, up), pick in ((at_t, 0), (at_p, 1)):
        th_d, ph_d = _latlong_departure(th, ph, ut, up, dt)
        a = grid.sample_u_theta(u_theta, th_d, ph_d)
        b = grid.sample_u_phi(u_phi, th_d, ph_d)
        w = b * jnp.cos(th) / jnp.maximum(jnp.sin(th), 1e-6) * dt
        # (1 + W) u_new = u*, W = [[0, -w], [w, 0]]
        den = 1.0 + w * w
        ut_new = (a + w * b) / den
        up_new = (b - w * a) / den
        out.append(ut_new if pick == 0 else up_new)
    return out[0], out[1]
