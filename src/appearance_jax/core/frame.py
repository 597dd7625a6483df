"""Local frames and the library's angle conventions (defined here once).

Surfaces: directions point **away** from the surface, unit length, in the local frame
with z = normal, x = tangent, y = z x x. ``cos_theta(w) = w.z``; a direction with
``w.z <= 0`` is below the horizon (or exactly grazing) and every surface model returns 0
for it.

Fibers: x = fiber tangent. The longitudinal angle theta is measured from the normal
plane (``sin theta = w.x``, in [-pi/2, pi/2]) and the azimuth phi lies in the normal
plane, ``phi = atan2(w.z, w.y)`` (Marschner / pbrt convention).

Rusinkiewicz (1998) half/difference angles parametrise a pair of directions by the half
vector h (theta_h, phi_h) and the incident direction expressed in a frame where h is the
pole (theta_d, phi_d).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .special import safe_acos, safe_atan2, safe_sqrt
from .vec import Vec3, cross, dot, normalize, where

# ----------------------------------------------------------------------------------
# surface frame: z is the normal


def cos_theta(w: Vec3):
    return w.z


def cos2_theta(w: Vec3):
    return w.z * w.z


def sin2_theta(w: Vec3):
    return jnp.maximum(0.0, 1.0 - w.z * w.z)


def sin_theta(w: Vec3):
    return safe_sqrt(sin2_theta(w))


def tan2_theta(w: Vec3):
    """tan^2 theta; +inf-free: returns a large finite value at grazing."""
    c2 = cos2_theta(w)
    return jnp.where(c2 > 0, sin2_theta(w) / jnp.where(c2 > 0, c2, 1.0), 1e30)


def cos_sin_phi(w: Vec3):
    """(cos phi, sin phi) of the azimuth; (1, 0) at the pole."""
    s2 = w.x * w.x + w.y * w.y
    ok = s2 > 0
    inv = jnp.where(ok, 1.0 / safe_sqrt(jnp.where(ok, s2, 1.0)), 0.0)
    return jnp.where(ok, w.x * inv, 1.0), jnp.where(ok, w.y * inv, 0.0)


def same_hemisphere(a: Vec3, b: Vec3):
    return a.z * b.z > 0


def spherical_direction(theta, phi, xp=jnp) -> Vec3:
    """Unit vector with polar angle ``theta`` from +z and azimuth ``phi`` from +x (radians);
    ``xp=np`` computes it in numpy (on the host, no XLA program)."""
    st = xp.sin(theta)
    return Vec3(st * xp.cos(phi), st * xp.sin(phi), xp.cos(theta))


@jax.jit
def spherical_directions(theta_i, phi_i, theta_o, phi_o):
    """(wi, wo) of :func:`spherical_direction`, as one compiled program: for tables converted
    eagerly (op by op, the two directions take six small XLA programs)."""
    return spherical_direction(theta_i, phi_i), spherical_direction(theta_o, phi_o)


def spherical_angles(w: Vec3):
    """(theta, phi) of a unit vector; phi in (-pi, pi]."""
    return safe_acos(w.z), safe_atan2(w.y, w.x)


def orthonormal_basis(n: Vec3):
    """Two unit tangents (s, t) with (s, t, n) right-handed, continuous except at n.z = -1.

    The branch-free construction of Duff et al. (2017, "Building an orthonormal basis,
    revisited"), so it vectorises without data-dependent control flow.
    """
    sign = jnp.where(n.z >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n.z)
    b = n.x * n.y * a
    s = Vec3(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x)
    t = Vec3(b, sign + n.y * n.y * a, -n.y)
    return s, t


class Frame:
    """An orthonormal frame (s, t, n); ``to_local``/``to_world`` change coordinates."""

    def __init__(self, s: Vec3, t: Vec3, n: Vec3):
        self.s, self.t, self.n = s, t, n

    @classmethod
    def from_normal(cls, n: Vec3) -> "Frame":
        s, t = orthonormal_basis(n)
        return cls(s, t, n)

    @classmethod
    def from_normal_tangent(cls, n: Vec3, tangent: Vec3) -> "Frame":
        """Frame with z = n and x = the tangent projected orthogonal to n (Gram-Schmidt)."""
        s = normalize(tangent - n * dot(n, tangent))
        return cls(s, cross(n, s), n)

    def to_local(self, v: Vec3) -> Vec3:
        return Vec3(dot(v, self.s), dot(v, self.t), dot(v, self.n))

    def to_world(self, v: Vec3) -> Vec3:
        return self.s * v.x + self.t * v.y + self.n * v.z


# ----------------------------------------------------------------------------------
# reflection and refraction (directions pointing away from the surface)


def reflect(w: Vec3, n: Vec3) -> Vec3:
    """Mirror ``w`` about ``n``: 2 (w.n) n - w. Both point away from the surface."""
    return n * (2.0 * dot(w, n)) - w


def refract(w: Vec3, n: Vec3, eta):
    """Refract ``w`` (pointing away, on the side n points to) through an interface.

    ``eta`` = eta_transmitted / eta_incident (relative index). Returns ``(wt, valid)``:
    the transmitted direction pointing away on the other side, and ``False`` under total
    internal reflection (where ``wt`` is 0). If ``w`` is on the side opposite ``n`` the
    interface is seen from inside: the caller passes ``-n`` and ``1/eta``.
    """
    cos_i = dot(w, n)
    sin2_t = jnp.maximum(0.0, 1.0 - cos_i * cos_i) / (eta * eta)
    valid = sin2_t < 1.0
    cos_t = safe_sqrt(1.0 - sin2_t)
    inv_eta = 1.0 / eta
    wt = (-w) * inv_eta + n * (cos_i * inv_eta - cos_t)
    zero = jnp.zeros_like(cos_t)
    return where(valid, wt, Vec3(zero, zero, zero)), valid


# ----------------------------------------------------------------------------------
# half vectors and Rusinkiewicz coordinates


def half_vector(wi: Vec3, wo: Vec3) -> Vec3:
    """Reflection half vector normalize(wi + wo), flipped into the upper hemisphere."""
    h = normalize(wi + wo)
    flip = jnp.where(h.z < 0, -1.0, 1.0)
    return h * flip


def rotate_z(v: Vec3, angle) -> Vec3:
    """v turned by ``angle`` (radians, broadcasts) about z; ``rotate_z(v, -a)`` gives v's coordinates in
    the frame turned by ``a``."""
    c, s = jnp.cos(angle), jnp.sin(angle)
    return Vec3(c * v.x - s * v.y, s * v.x + c * v.y, v.z)


def _rotate_y(v: Vec3, angle) -> Vec3:
    c, s = jnp.cos(angle), jnp.sin(angle)
    return Vec3(c * v.x + s * v.z, v.y, -s * v.x + c * v.z)


def to_half_diff(wi: Vec3, wo: Vec3):
    """Rusinkiewicz angles ``(theta_h, phi_h, theta_d, phi_d)`` of a direction pair."""
    h = half_vector(wi, wo)
    theta_h, phi_h = spherical_angles(h)
    d = _rotate_y(rotate_z(wi, -phi_h), -theta_h)
    theta_d, phi_d = spherical_angles(d)
    return theta_h, phi_h, theta_d, phi_d


def from_half_diff(theta_h, phi_h, theta_d, phi_d):
    """Inverse of :func:`to_half_diff`: returns ``(wi, wo)``."""
    d = spherical_direction(theta_d, phi_d)
    wi = rotate_z(_rotate_y(d, theta_h), phi_h)
    h = spherical_direction(theta_h, phi_h)
    wo = reflect(wi, h)
    return wi, wo


# ----------------------------------------------------------------------------------
# fiber coordinates: x is the fiber tangent


def fiber_angles(w: Vec3):
    """(theta, phi) of a direction w.r.t. a fiber along +x.

    theta in [-pi/2, pi/2] is the longitudinal angle from the normal plane
    (sin theta = w.x); phi = atan2(w.z, w.y) is the azimuth in the normal plane.
    """
    from .special import safe_asin

    return safe_asin(w.x), safe_atan2(w.z, w.y)


def fiber_direction(theta, phi) -> Vec3:
    """Inverse of :func:`fiber_angles`."""
    ct = jnp.cos(theta)
    return Vec3(jnp.sin(theta), ct * jnp.cos(phi), ct * jnp.sin(phi))


# ----------------------------------------------------------------------------------
# in-plane gonioreflectometer geometry


def meso_normal(n_y, n_z, tilt):
    """Outward mesonormal of a cuticle tilted by ``tilt`` at the point whose outward in-plane
    normal is (0, n_y, n_z): (sin tilt, n_y cos tilt, n_z cos tilt) (Eq. 4.39, Huang 2022;
    tilt > 0 leans it towards the tip, +x)."""
    c, s = jnp.cos(tilt), jnp.sin(tilt)
    return Vec3(s * jnp.ones_like(n_y), c * n_y, c * n_z)


def in_plane_directions(theta_i, theta_o):
    """Directions of an in-plane measurement with signed outgoing angle (radians).

    wi = (sin theta_i, 0, cos theta_i) and wo = (-sin theta_o, 0, cos theta_o), so that
    theta_o = theta_i is the mirror direction and theta_o = -theta_i is retro-reflection
    (the convention of Padrón Fig. 4.4; spec D12).
    """
    wi = Vec3(jnp.sin(theta_i), jnp.zeros_like(jnp.asarray(theta_i, dtype=float)), jnp.cos(theta_i))
    wo = Vec3(-jnp.sin(theta_o), jnp.zeros_like(jnp.asarray(theta_o, dtype=float)), jnp.cos(theta_o))
    return wi, wo
