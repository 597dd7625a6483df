"""The SGGX microflake distribution (Heitz, Dupuy, Crassin & Dachsbacher 2015, "The SGGX
microflake distribution", ACM TOG 34(4); seed-000 spec M14).

An SGGX distribution is a symmetric positive-definite 3x3 matrix S. It is stored here as a
:class:`SMatrix` of its six independent components ``(xx, yy, zz, xy, xz, yz)``, each an
array of the same (broadcastable) shape: a structure of arrays like
:class:`~appearance_jax.core.vec.Vec3`, never a trailing 3x3 axis. ``SMatrix`` is a
NamedTuple, hence a JAX pytree.

Definitions (unit directions ``m``, ``w``; D is even, D(-m) = D(m)):

    D(m)     = 1 / (pi sqrt|S| (m^T S^-1 m)^2)                               [1/sr]
    sigma(w) = sqrt(w^T S w) = int_{S^2} max(0, w.m) D(m) dm                 (projected area)
    D_w(m)   = max(0, w.m) D(m) / sigma(w)          (visible normals; integrates to 1)

**Normalisation:** int_{S^2} D dm is *not* 1 but the total flake area: 4 for S = I, 2 in the
flat-flake limit, and for the flake matrix below 2 + (alpha^2/sqrt(k)) ln((1+sqrt k)/(1-sqrt k))
with k = 1 - alpha^2 (2.760 for alpha = 0.5). With |w.m| instead of max(0, w.m) the
projected-area integral is 2 sigma(w).

``m^T S^-1 m`` is computed as ``m^T adj(S) m / |S|`` (no matrix inverse), so
``D = |S|^{3/2} / (pi (m^T adj(S) m)^2)``.

Flake (surface-like) distributions (:func:`flake_matrix`): mean normal w3 and roughness alpha,
``S = Q diag(alpha^2, alpha^2, 1) Q^T = alpha^2 I + (1 - alpha^2) w3 w3^T``. The platelet tilt
theta rotates the mean normal about the tangent x [ASSUMPTION of spec M14]:
``w3 = R_x(theta) (0, 0, 1) = (0, -sin theta, cos theta)``. Then max_w sigma(w) = 1 (along w3).
For flakes the closed forms :func:`flake_D` and :func:`flake_projected_area` avoid the
cancellations of the generic determinant/adjugate (``D = alpha^2 / (pi (alpha^2 c^2 + s^2)^2)``
with c = m.w3, s^2 = |m x w3|^2; ``sigma = sqrt(alpha^2 + (1 - alpha^2)(w.w3)^2)``).

Accuracy: the generic S formulas (|S|, the adjugate and the 2x2 minors of the sampler) lose
about eps / alpha^2 relative accuracy for near-flat flakes. In float64 they are good to
~1e-10 down to alpha = 1e-3, the documented lower bound of this module; in float32 use
alpha >= ~0.03 with the generic forms (the flake closed forms stay accurate to alpha = 1e-3).

Visible-normal sampling (:func:`sample_visible_normal`) is the algorithm of Heitz et al. 2015
(supplemental; spec M14 steps 1-6): uniform point on the unit disk, lifted to the
hemisphere, mapped by the Cholesky-like factor of S expressed in a basis (wk, wj, wi) about
the incident direction. Sampled normals satisfy wi.m >= 0, and their density per sr is
:func:`visible_normal_pdf`. Everything is branch-free, jittable and differentiable.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax.numpy as jnp

from ..core.frame import orthonormal_basis
from ..core.special import safe_sqrt
from ..core.vec import Vec3, cross, dot, normalize

Array = Any

INV_PI = 1.0 / jnp.pi

#: smallest flake roughness for which the module's accuracy claims hold (float64)
ALPHA_MIN = 1e-3


class SMatrix(NamedTuple):
    """Symmetric 3x3 matrix as six same-shaped component arrays (structure of arrays)."""

    xx: Array
    yy: Array
    zz: Array
    xy: Array
    xz: Array
    yz: Array

    def mul(self, w: Vec3) -> Vec3:
        """The product S w."""
        return Vec3(self.xx * w.x + self.xy * w.y + self.xz * w.z,
                    self.xy * w.x + self.yy * w.y + self.yz * w.z,
                    self.xz * w.x + self.yz * w.y + self.zz * w.z)

    def quad(self, a: Vec3, b: Vec3 | None = None):
        """The bilinear form a^T S b (b = a by default)."""
        return dot(a, self.mul(a if b is None else b))

    def det(self):
        return (self.xx * (self.yy * self.zz - self.yz * self.yz)
                - self.xy * (self.xy * self.zz - self.yz * self.xz)
                + self.xz * (self.xy * self.yz - self.yy * self.xz))

    def adjugate(self) -> "SMatrix":
        """adj(S) = |S| S^-1 (symmetric)."""
        return SMatrix(self.yy * self.zz - self.yz * self.yz,
                       self.xx * self.zz - self.xz * self.xz,
                       self.xx * self.yy - self.xy * self.xy,
                       self.xz * self.yz - self.xy * self.zz,
                       self.xy * self.yz - self.xz * self.yy,
                       self.xy * self.xz - self.xx * self.yz)

    def to_array(self):
        """Dense ``(..., 3, 3)`` array (for tests, I/O and plotting only)."""
        c = jnp.broadcast_arrays(*self)
        xx, yy, zz, xy, xz, yz = c
        return jnp.stack([jnp.stack([xx, xy, xz], -1), jnp.stack([xy, yy, yz], -1),
                          jnp.stack([xz, yz, zz], -1)], -2)


def identity(shape=()) -> SMatrix:
    one, zero = jnp.ones(shape), jnp.zeros(shape)
    return SMatrix(one, one, one, zero, zero, zero)


def mean_normal(theta) -> Vec3:
    """The tilted mean flake normal w3 = R_x(theta) z = (0, -sin theta, cos theta)."""
    theta = jnp.asarray(theta)
    return Vec3(jnp.zeros_like(theta), -jnp.sin(theta), jnp.cos(theta))


def flake_matrix(alpha, theta) -> SMatrix:
    """S = Q diag(alpha^2, alpha^2, 1) Q^T with mean normal w3 = (0, -sin theta, cos theta).

    ``alpha`` (roughness, (0, 1]) and ``theta`` (tilt about x, radians) broadcast.
    Equal to alpha^2 I + (1 - alpha^2) w3 w3^T.
    """
    alpha, theta = jnp.broadcast_arrays(jnp.asarray(alpha, jnp.result_type(float)), jnp.asarray(theta))
    a2 = alpha * alpha
    k = 1.0 - a2
    s, c = jnp.sin(theta), jnp.cos(theta)
    zero = jnp.zeros_like(a2)
    return SMatrix(a2, a2 + k * s * s, a2 + k * c * c, zero, zero, -k * s * c)


# ----------------------------------------------------------------------------------------
# generic S


def D(S: SMatrix, m: Vec3):
    """D(m) = 1 / (pi sqrt|S| (m^T S^-1 m)^2) in 1/sr (0 for the zero vector)."""
    det = jnp.maximum(S.det(), 0.0)
    q = S.adjugate().quad(m)  # = |S| m^T S^-1 m
    ok = q > 0
    qs = jnp.where(ok, q, 1.0)
    return jnp.where(ok, det * safe_sqrt(det) * INV_PI / (qs * qs), 0.0)


def projected_area(S: SMatrix, w: Vec3):
    """sigma(w) = sqrt(w^T S w) = int max(0, w.m) D(m) dm (even in w)."""
    return safe_sqrt(S.quad(w))


def visible_normal_pdf(S: SMatrix, wi: Vec3, m: Vec3):
    """Density per sr of the visible normals seen from wi: max(0, wi.m) D(m) / sigma(wi)."""
    sig = projected_area(S, wi)
    ok = sig > 0
    return jnp.where(ok, jnp.maximum(dot(wi, m), 0.0) * D(S, m) / jnp.where(ok, sig, 1.0), 0.0)


def sample_visible_normal(S: SMatrix, wi: Vec3, u1, u2) -> Vec3:
    """Draw m with density :func:`visible_normal_pdf` (Heitz et al. 2015, spec M14 steps 1-6).

    ``u1, u2`` in [0, 1) broadcast against ``wi``. Returns a unit Vec3 with wi.m >= 0.
    """
    # 1. uniform point on the unit disk, lifted to the hemisphere
    r = jnp.sqrt(u1)
    phi = 2.0 * jnp.pi * u2
    u, v = r * jnp.cos(phi), r * jnp.sin(phi)
    w = safe_sqrt(1.0 - u * u - v * v)
    # 2. orthonormal basis (wk, wj, wi)
    wk, wj = orthonormal_basis(wi)
    # 3. S in that basis
    Swi, Swk, Swj = S.mul(wi), S.mul(wk), S.mul(wj)
    s_kk, s_jj, s_ii = dot(wk, Swk), dot(wj, Swj), dot(wi, Swi)
    s_kj, s_ki, s_ji = dot(wk, Swj), dot(wk, Swi), dot(wj, Swi)
    # 4. sqrt(det S_kji) and the (j, i) minor
    sqrt_det = jnp.sqrt(jnp.abs(s_kk * s_jj * s_ii - s_kj * s_kj * s_ii - s_ki * s_ki * s_jj
                                - s_ji * s_ji * s_kk + 2.0 * s_kj * s_ki * s_ji))
    tmp = safe_sqrt(s_jj * s_ii - s_ji * s_ji)
    tmp = jnp.maximum(tmp, jnp.finfo(jnp.result_type(tmp)).tiny)
    inv_sqrt_sii = 1.0 / safe_sqrt(jnp.maximum(s_ii, jnp.finfo(jnp.result_type(s_ii)).tiny))
    # 5. the rows M_k, M_j, M_i; 6. m_kji = normalize(u M_k + v M_j + w M_i)
    mk = Vec3(sqrt_det / tmp, 0.0, 0.0)
    mj = Vec3(-(s_ki * s_ji - s_kj * s_ii) / tmp * inv_sqrt_sii, tmp * inv_sqrt_sii, 0.0)
    mi = Vec3(s_ki * inv_sqrt_sii, s_ji * inv_sqrt_sii, s_ii * inv_sqrt_sii)
    m = normalize(mk * u + mj * v + mi * w)
    return wk * m.x + wj * m.y + wi * m.z


# ----------------------------------------------------------------------------------------
# flake closed forms (accurate for small alpha in any precision)


def flake_D(alpha, w3: Vec3, m: Vec3):
    """D(m) of the flake matrix: alpha^2 / (pi (alpha^2 c^2 + s^2)^2), c = m.w3, s^2 = |m x w3|^2.

    Equals :func:`D` of ``alpha^2 I + (1 - alpha^2) w3 w3^T`` for unit m, w3 (0 for m = 0).
    """
    a2 = alpha * alpha
    c = dot(m, w3)
    s2 = dot(cross(m, w3), cross(m, w3))
    den = a2 * c * c + s2
    ok = den > 0
    dens = jnp.where(ok, den, 1.0)
    return jnp.where(ok, a2 * INV_PI / (dens * dens), 0.0)


def flake_projected_area(alpha, w3: Vec3, w: Vec3):
    """sigma(w) of the flake matrix: sqrt(alpha^2 + (1 - alpha^2)(w.w3)^2), in [alpha, 1]."""
    a2 = alpha * alpha
    c = dot(w, w3)
    return safe_sqrt(a2 + (1.0 - a2) * c * c)


def flake_total_area(alpha):
    """int_{S^2} D dm of the flake matrix (closed form; 4 at alpha = 1, -> 2 as alpha -> 0)."""
    alpha = jnp.asarray(alpha, jnp.result_type(float))
    a2 = alpha * alpha
    rk = safe_sqrt(1.0 - a2)
    small = rk < 1e-4  # alpha -> 1: (1/rk) ln((1+rk)/(1-rk)) -> 2 + 2 rk^2 / 3
    rks = jnp.where(small, 0.5, rk)
    term = jnp.where(small, 2.0 + 2.0 * rk * rk / 3.0, jnp.log((1.0 + rks) / (1.0 - rks)) / rks)
    return 2.0 + a2 * term
