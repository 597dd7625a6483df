"""Warps from the unit square to directions and points, with their densities.

Each ``square_to_X(u1, u2)`` maps uniforms in [0, 1)^2 to X; ``square_to_X_pdf`` gives the
density of the result with respect to solid angle (directions) or area (disk). They are
smooth in (u1, u2), so sampled directions can be differentiated (reparameterisation).
"""

from __future__ import annotations

import jax.numpy as jnp

from .special import safe_sqrt
from .vec import Vec3

INV_PI = 1.0 / jnp.pi
INV_2PI = 0.5 / jnp.pi
INV_4PI = 0.25 / jnp.pi


def square_to_uniform_disk_concentric(u1, u2):
    """Shirley-Chiu concentric map of the square onto the unit disk (area density 1/pi)."""
    a = 2.0 * u1 - 1.0
    b = 2.0 * u2 - 1.0
    first = jnp.abs(a) > jnp.abs(b)
    safe_a = jnp.where(a == 0, 1.0, a)
    safe_b = jnp.where(b == 0, 1.0, b)
    r = jnp.where(first, a, b)
    phi = jnp.where(first, (jnp.pi / 4) * (b / safe_a), jnp.pi / 2 - (jnp.pi / 4) * (a / safe_b))
    zero = (a == 0) & (b == 0)
    r = jnp.where(zero, 0.0, r)
    return r * jnp.cos(phi), r * jnp.sin(phi)


def square_to_uniform_disk_concentric_pdf(x, y):
    return jnp.where(x * x + y * y <= 1.0, INV_PI, 0.0)


def square_to_uniform_sphere(u1, u2) -> Vec3:
    z = 1.0 - 2.0 * u1
    r = safe_sqrt(1.0 - z * z)
    phi = 2.0 * jnp.pi * u2
    return Vec3(r * jnp.cos(phi), r * jnp.sin(phi), z)


def square_to_uniform_sphere_pdf(w: Vec3):
    return jnp.full(jnp.shape(w.z), INV_4PI, dtype=jnp.result_type(w.z, jnp.float32))


def square_to_uniform_hemisphere(u1, u2) -> Vec3:
    z = u1
    r = safe_sqrt(1.0 - z * z)
    phi = 2.0 * jnp.pi * u2
    return Vec3(r * jnp.cos(phi), r * jnp.sin(phi), z)


def square_to_uniform_hemisphere_pdf(w: Vec3):
    return jnp.where(w.z > 0, INV_2PI, 0.0)


def square_to_cosine_hemisphere(u1, u2) -> Vec3:
    """Malley's method: project the concentric disk up to the hemisphere (pdf cos/pi)."""
    x, y = square_to_uniform_disk_concentric(u1, u2)
    z = safe_sqrt(1.0 - x * x - y * y)
    return Vec3(x, y, z)


def square_to_cosine_hemisphere_pdf(w: Vec3):
    return jnp.where(w.z > 0, w.z * INV_PI, 0.0)
