"""The staggered spherical grid of the soap-film flow (Huang 2022, Sec. 3.4.1, Figs. 3.5-3.7).

Layout (``n_theta x n_phi`` cells, dtheta = pi / n_theta, dphi = 2 pi / n_phi):

* scalars (the half thickness eta and the surfactant concentration Gamma) at cell centres
  ``(theta_i, phi_j) = ((i + 1/2) dtheta, (j + 1/2) dphi)``, shape ``(n_theta, n_phi)``;
* ``u_phi`` on the phi-faces ``(theta_i, j dphi)`` (between cells ``j - 1`` and ``j``), shape
  ``(n_theta, n_phi)``;
* ``u_theta`` on the theta-faces ``((i + 1) dtheta, (j + 1/2) dphi)`` (between rows ``i`` and
  ``i + 1``), shape ``(n_theta - 1, n_phi)``; nothing is stored at the poles.

Conventions are those of :mod:`appearance_jax.soapfilm.thickness`: the bubble is the unit sphere,
world +z is up, theta is measured from the top (theta = 0 the north pole), phi = atan2(y, x),
e_theta = d p / d theta points downhill, e_phi = d p / (sin theta d phi). Velocities are the
thesis' dimensionless (u_theta, u_phi) = (d theta / dt, sin theta d phi / dt) (Huang Eq. A.2).

Across a pole the neighbour of row 0 at phi is row 0 at phi + pi, and both e_theta and e_phi
change sign there, so velocity components read from across a pole are negated (Huang Fig. 3.7).
``n_phi`` must be even so that phi + pi falls on a grid column.

The difference operators are the central differences of Huang Eqs. 3.13-3.16 on this layout
(no checkerboard modes); :func:`divergence` of :func:`gradient` is the 5-point Laplacian whose
sin(theta)-scaled form is the symmetric matrix of Huang App. C.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from ..core.special import safe_atan2, safe_sqrt
from ..core.vec import Vec3, dot

__all__ = ["SphereGrid", "point", "angles", "basis", "tangent", "components", "cell_weights"]


@dataclasses.dataclass(frozen=True)
class SphereGrid:
    """An ``n_theta x n_phi`` staggered grid on the unit sphere (hashable: a static argument).

    Args:
        n_theta: cells from pole to pole (>= 4).
        n_phi: cells around the equator (even, >= 4). ``n_phi = 2 n_theta`` gives square cells
            at the equator (dtheta = dphi), the thesis' 1024 x 2048 layout.
    """

    n_theta: int
    n_phi: int

    def __post_init__(self):
        for name in ("n_theta", "n_phi"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                raise TypeError(f"{name} = {v!r}: must be an int")
        if self.n_theta < 4:
            raise ValueError(f"n_theta = {self.n_theta}: must be >= 4")
        if self.n_phi < 4 or self.n_phi % 2:
            raise ValueError(f"n_phi = {self.n_phi}: must be even and >= 4 (phi + pi must be a grid column)")
        object.__setattr__(self, "n_theta", int(self.n_theta))
        object.__setattr__(self, "n_phi", int(self.n_phi))

    @classmethod
    def parse(cls, text: str) -> "SphereGrid":
        """``"256x512"`` -> ``SphereGrid(256, 512)`` (for the command line)."""
        try:
            a, b = (int(s) for s in str(text).lower().split("x"))
        except ValueError:
            raise ValueError(f"grid = {text!r}: must be N_THETAxN_PHI, e.g. 256x512") from None
        return cls(a, b)

    # -- spacing and coordinates (numpy, float64; cast where used) --------------------
    @property
    def dtheta(self) -> float:
        return float(np.pi / self.n_theta)

    @property
    def dphi(self) -> float:
        return float(2.0 * np.pi / self.n_phi)

    @property
    def shape(self) -> tuple:
        """Shape of the cell-centred fields (and of ``u_phi``)."""
        return (self.n_theta, self.n_phi)

    @property
    def theta_shape(self) -> tuple:
        """Shape of ``u_theta``."""
        return (self.n_theta - 1, self.n_phi)

    def theta_centres(self) -> np.ndarray:
        return (np.arange(self.n_theta) + 0.5) * self.dtheta

    def phi_centres(self) -> np.ndarray:
        return (np.arange(self.n_phi) + 0.5) * self.dphi

    def theta_faces(self) -> np.ndarray:
        """theta of the ``u_theta`` rows (interior faces, no poles)."""
        return (np.arange(1, self.n_theta)) * self.dtheta

    def phi_faces(self) -> np.ndarray:
        """phi of the ``u_phi`` columns."""
        return np.arange(self.n_phi) * self.dphi

    def centres(self):
        """``(theta, phi)`` of the cell centres, each ``(n_theta, n_phi)``."""
        return np.meshgrid(self.theta_centres(), self.phi_centres(), indexing="ij")

    def u_theta_points(self):
        """``(theta, phi)`` of the ``u_theta`` samples, each ``(n_theta - 1, n_phi)``."""
        return np.meshgrid(self.theta_faces(), self.phi_centres(), indexing="ij")

    def u_phi_points(self):
        """``(theta, phi)`` of the ``u_phi`` samples, each ``(n_theta, n_phi)``."""
        return np.meshgrid(self.theta_centres(), self.phi_faces(), indexing="ij")

    def cell_areas(self) -> np.ndarray:
        """Exact areas of the cells on the unit sphere, ``(n_theta, n_phi)``; they sum to 4 pi."""
        edges = np.arange(self.n_theta + 1) * self.dtheta
        band = (np.cos(edges[:-1]) - np.cos(edges[1:])) * self.dphi
        return np.broadcast_to(band[:, None], self.shape).copy()

    def check_field(self, name: str, a, kind: str = "centre"):
        """Raise a ValueError naming ``name`` unless ``a`` has the shape of a ``kind`` field
        ("centre", "u_theta" or "u_phi")."""
        want = {"centre": self.shape, "u_phi": self.shape, "u_theta": self.theta_shape}[kind]
        shape = tuple(np.shape(a))
        if shape != want:
            raise ValueError(f"{name}: shape {shape}, expected {want} for a {kind} field of the "
                             f"{self.n_theta}x{self.n_phi} grid")

    # -- sampling ------------------------------------------------------------------
    def sample(self, field, theta, phi):
        """Bilinear value of a cell-centred scalar ``field`` at ``(theta, phi)`` (pole-aware)."""
        return _bilinear(self.pad_rows(field, 1.0), theta / self.dtheta + 0.5, phi / self.dphi - 0.5)

    def sample_u_phi(self, u_phi, theta, phi):
        """Bilinear ``u_phi`` at ``(theta, phi)``; rows across a pole are negated (Huang Fig. 3.7)."""
        return _bilinear(self.pad_rows(u_phi, -1.0), theta / self.dtheta + 0.5, phi / self.dphi)

    def sample_u_theta(self, u_theta, theta, phi):
        """Bilinear ``u_theta`` at ``(theta, phi)``. Between the first row and the pole it
        interpolates linearly towards the negated row across the pole (Huang Fig. 3.7), which is
        the same as a pole row holding the mean of the two."""
        return _bilinear(self.pad_u_theta(u_theta), theta / self.dtheta, phi / self.dphi - 0.5)

    def sample_vector(self, u_theta, u_phi, p: Vec3) -> Vec3:
        """The velocity at the unit vectors ``p`` as a tangent Vec3 (components sampled bilinearly
        on their own staggered grids, then combined in the basis at ``p``)."""
        th, ph = angles(p)
        return tangent(self.sample_u_theta(u_theta, th, ph), self.sample_u_phi(u_phi, th, ph), th, ph)

    def pad_u_theta(self, u_theta):
        """``u_theta`` with a pole row at theta = 0 and at theta = pi: ``(n_theta + 1, n_phi)``,
        row k at theta = k dtheta. A pole row holds the mean of the first row and its negated
        mirror across the pole."""
        h = self.n_phi // 2
        top = 0.5 * (u_theta[0] - jnp.roll(u_theta[0], -h))
        bot = 0.5 * (u_theta[-1] - jnp.roll(u_theta[-1], -h))
        return jnp.concatenate([top[None], u_theta, bot[None]], axis=0)

    def pad_rows(self, f, sign):
        """A cell-row field with the row across each pole added (row 0 / the last row rolled by
        half a turn, times ``sign``: -1 for velocity components), ``(n_theta + 2, n_phi)``, row k
        at theta = (k - 1/2) dtheta."""
        h = self.n_phi // 2
        top = sign * jnp.roll(f[0], -h)
        bot = sign * jnp.roll(f[-1], -h)
        return jnp.concatenate([top[None], f, bot[None]], axis=0)

    # -- staggered averages ----------------------------------------------------------
    def u_phi_at_theta_faces(self, u_phi):
        """Mean of the four ``u_phi`` around each ``u_theta`` sample, ``(n_theta - 1, n_phi)``."""
        a = 0.5 * (u_phi + jnp.roll(u_phi, -1, axis=1))
        return 0.5 * (a[:-1] + a[1:])

    def u_theta_at_phi_faces(self, u_theta):
        """Mean of the four ``u_theta`` around each ``u_phi`` sample (pole rows as in
        :meth:`pad_u_theta`), ``(n_theta, n_phi)``."""
        p = self.pad_u_theta(u_theta)
        a = 0.5 * (p[:-1] + p[1:])
        return 0.5 * (a + jnp.roll(a, 1, axis=1))

    def centre_to_theta_faces(self, f):
        """Mean of the two cells beside each ``u_theta`` face."""
        return 0.5 * (f[:-1] + f[1:])

    def centre_to_phi_faces(self, f):
        """Mean of the two cells beside each ``u_phi`` face."""
        return 0.5 * (f + jnp.roll(f, 1, axis=1))

    def velocity_at_centres(self, u_theta, u_phi):
        """``(u_theta, u_phi)`` at the cell centres (means of the two faces each)."""
        ut = self.pad_u_theta(u_theta)
        return 0.5 * (ut[:-1] + ut[1:]), 0.5 * (u_phi + jnp.roll(u_phi, -1, axis=1))

    # -- difference operators (Huang Eqs. 3.13-3.16) ----------------------------------
    def gradient(self, f):
        """Central-difference gradient of a cell-centred field: ``(d_theta f on the theta faces,
        d_phi f / (sin theta dphi) on the phi faces)`` (Huang Eq. 3.14)."""
        sin_c = jnp.asarray(np.sin(self.theta_centres()), f.dtype)[:, None]
        g_theta = (f[1:] - f[:-1]) / self.dtheta
        g_phi = (f - jnp.roll(f, 1, axis=1)) / (sin_c * self.dphi)
        return g_theta, g_phi

    def divergence(self, u_theta, u_phi):
        """Central-difference divergence at the cell centres (Huang Eq. 3.13); no flux crosses
        the poles (the face there has zero length)."""
        dt = u_theta.dtype
        sin_c = jnp.asarray(np.sin(self.theta_centres()), dt)[:, None]
        sin_f = jnp.asarray(np.sin(self.theta_faces()), dt)[:, None]
        flux = sin_f * u_theta
        zero = jnp.zeros((1, self.n_phi), dt)
        flux = jnp.concatenate([zero, flux, zero], axis=0)
        d_theta = (flux[1:] - flux[:-1]) / self.dtheta
        d_phi = (jnp.roll(u_phi, -1, axis=1) - u_phi) / self.dphi
        return (d_theta + d_phi) / sin_c

    def laplacian(self, f):
        """5-point Laplace-Beltrami of a cell-centred field (Huang Eq. 3.16)."""
        return self.divergence(*self.gradient(f))

    def integral(self, f):
        """Area integral of a cell-centred field over the unit sphere (midpoint rule with the
        exact cell areas)."""
        return jnp.sum(f * jnp.asarray(self.cell_areas(), f.dtype))


def cell_weights(n_rows: int, n_cols: int, r, c):
    """``(i0, j0, j1, fr, fc)`` of a bilinear lookup at fractional row ``r`` (clamped to the
    ``n_rows`` rows) and column ``c`` (periodic over ``n_cols``): it reads rows i0, i0 + 1 and
    columns j0, j1 with weights ``fr`` and ``fc`` on the second of each."""
    r = jnp.clip(r, 0.0, n_rows - 1.0)
    i0 = jnp.clip(jnp.floor(r), 0, n_rows - 2).astype(jnp.int32)
    cf = jnp.floor(c)
    j0 = jnp.mod(cf.astype(jnp.int32), n_cols)
    return i0, j0, jnp.mod(j0 + 1, n_cols), r - i0, c - cf


def _bilinear(padded, r, c):
    """Bilinear lookup in ``padded`` (rows clamped, columns periodic) at fractional row ``r``
    and column ``c``."""
    i0, j0, j1, fr, fc = cell_weights(*padded.shape, r, c)
    a = padded[i0, j0] * (1 - fc) + padded[i0, j1] * fc
    b = padded[i0 + 1, j0] * (1 - fc) + padded[i0 + 1, j1] * fc
    return a * (1 - fr) + b * fr


# -- coordinates on the unit sphere -------------------------------------------------------
def point(theta, phi) -> Vec3:
    """The unit vector at polar angle ``theta`` (from +z) and azimuth ``phi``."""
    s = jnp.sin(theta)
    return Vec3(s * jnp.cos(phi), s * jnp.sin(phi), jnp.cos(theta))


def angles(p: Vec3):
    """``(theta, phi)`` of unit vectors ``p``; phi in [0, 2 pi)."""
    # atan2(rho, z), not acos(z): acos loses ~eps / theta near the poles (1 % of a first-row cell
    # in float32 at 1024 x 2048)
    theta = safe_atan2(safe_sqrt(p.x * p.x + p.y * p.y), p.z)
    phi = safe_atan2(p.y, p.x)
    return theta, jnp.mod(phi, 2.0 * jnp.pi)


def basis(theta, phi):
    """``(e_theta, e_phi)`` at ``(theta, phi)``."""
    ct, st, cp, sp = jnp.cos(theta), jnp.sin(theta), jnp.cos(phi), jnp.sin(phi)
    return Vec3(ct * cp, ct * sp, -st), Vec3(-sp, cp, jnp.zeros_like(sp))


def tangent(u_theta, u_phi, theta, phi) -> Vec3:
    """The tangent vector ``u_theta e_theta + u_phi e_phi`` at ``(theta, phi)``."""
    et, ep = basis(theta, phi)
    return et * u_theta + ep * u_phi


def components(v: Vec3, theta, phi):
    """``(v . e_theta, v . e_phi)`` at ``(theta, phi)``."""
    et, ep = basis(theta, phi)
    return dot(v, et), dot(v, ep)
