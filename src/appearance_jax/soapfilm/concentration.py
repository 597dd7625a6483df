"""The implicit surfactant solve of the soap-film flow ("concentration splitting", Huang 2022,
Sec. 3.4.3, Eqs. 3.24-3.26, App. C).

After advection (u*, Gamma*, eta*), Huang Eq. 3.26 multiplied by sin(theta) is the symmetric
positive definite system A Gamma = b with, per cell (Huang App. C, with the A_down misprint fixed
by symmetry: it couples the cell below through the face at theta + ds/2),

    A Gamma = sin(theta) [ Gamma / (dt Gamma*) - div( k grad Gamma ) ],   k = M dt / (eta*_f + Cr dt)
    b       = sin(theta) [ 1/dt - div( F ) ],   F = (eta*_f u* + Cr dt u_air + dt eta*_f g) / (eta*_f + Cr dt)

on the staggered grid (eta*_f = mean of the two cells beside a face; div and grad the central
differences of :mod:`~appearance_jax.soapfilm.grid`, whose sin(theta)-weighted composition is
the 5-point stencil of App. C; with dtheta = dphi = ds the entries are the thesis' exactly).
No face couples across a pole (its length sin(0) is 0).

It is solved matrix-free by conjugate gradients, preconditioned by the exact inverse of the
row-averaged operator (FFT in phi, tridiagonal in theta; :func:`row_mean_preconditioner`) or by
Jacobi, in a
``lax.while_loop`` with a fixed maximum: the iteration count and the final relative residual
are returned so that a caller can refuse an unconverged step. Then (Huang Eqs. 3.24a, c)
u = F - k grad Gamma on the faces and eta = eta* (1 - dt div u), Gamma = Gamma* (1 - dt div u).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .grid import SphereGrid

__all__ = ["Faces", "face_terms", "apply", "diagonal", "row_mean_preconditioner", "rhs", "cg", "CGInfo", "project",
           "PRECONDITIONERS"]

PRECONDITIONERS = ("fft", "jacobi")


class Faces(NamedTuple):
    """Face coefficients of one step: k = M dt / (eta*_f + Cr dt) on the theta and phi faces,
    and the explicit face velocity F of Huang Eq. 3.25."""

    k_theta: jax.Array
    k_phi: jax.Array
    F_theta: jax.Array
    F_phi: jax.Array


def face_terms(grid: SphereGrid, eta_s, u_theta_s, u_phi_s, air_theta, air_phi, M, Cr, g, dt) -> Faces:
    """The coefficients of the step from the advected fields (``*_s``), the air velocity on the
    faces and the numbers M, Cr, g (gravity g sin(theta) along e_theta, Huang Sec. 3.3)."""
    dtype = eta_s.dtype
    eta_t = grid.centre_to_theta_faces(eta_s)
    eta_p = grid.centre_to_phi_faces(eta_s)
    sin_t = jnp.asarray(np.sin(grid.theta_faces()), dtype)[:, None]
    den_t = eta_t + Cr * dt
    den_p = eta_p + Cr * dt
    F_t = (eta_t * u_theta_s + Cr * dt * air_theta + dt * eta_t * g * sin_t) / den_t
    F_p = (eta_p * u_phi_s + Cr * dt * air_phi) / den_p
    return Faces(M * dt / den_t, M * dt / den_p, F_t, F_p)


def _sin_c(grid, dtype):
    return jnp.asarray(np.sin(grid.theta_centres()), dtype)[:, None]


def apply(grid: SphereGrid, faces: Faces, gamma_s, dt, x):
    """A x (the sin(theta)-scaled operator of Huang App. C)."""
    gt, gp = grid.gradient(x)
    return _sin_c(grid, x.dtype) * (x / (dt * gamma_s) - grid.divergence(faces.k_theta * gt, faces.k_phi * gp))


def diagonal(grid: SphereGrid, faces: Faces, gamma_s, dt):
    """diag(A) (A_mid of Huang App. C)."""
    dtype = gamma_s.dtype
    s_c = _sin_c(grid, dtype)
    s_f = jnp.asarray(np.sin(grid.theta_faces()), dtype)[:, None]
    zero = jnp.zeros((1, grid.n_phi), dtype)
    flux = jnp.concatenate([zero, s_f * faces.k_theta, zero], axis=0)
    theta_part = (flux[:-1] + flux[1:]) / grid.dtheta**2
    phi_part = (faces.k_phi + jnp.roll(faces.k_phi, -1, axis=1)) / (s_c * grid.dphi**2)
    return s_c / (dt * gamma_s) + theta_part + phi_part


def rhs(grid: SphereGrid, faces: Faces, dt):
    """b of Huang App. C."""
    div_F = grid.divergence(faces.F_theta, faces.F_phi)
    return _sin_c(grid, div_F.dtype) * (1.0 / dt - div_F)


def row_mean_preconditioner(grid: SphereGrid, faces: Faces, gamma_s, dt):
    """z = A_bar^-1 r, A_bar = A with every coefficient replaced by its mean over its row of cells.

    A_bar is circulant along phi, so an FFT in phi splits it into n_phi/2 + 1 tridiagonal
    systems in theta (one per azimuthal mode m, eigenvalue 2 - 2 cos(2 pi m / n_phi) of the
    phi second difference), solved exactly. It captures what Jacobi cannot: the strong
    azimuthal coupling k / (sin(theta) dphi^2) near the poles and the global coupling in theta.
    A_bar is symmetric positive definite, so it is a valid preconditioner for CG; the solve
    converges in few iterations when eta* varies mostly with theta (gravity bands) and in more
    when it varies strongly along rows.
    """
    dtype = gamma_s.dtype
    s_c = np.sin(grid.theta_centres())
    s_f = jnp.asarray(np.sin(grid.theta_faces()), dtype)
    d = jnp.mean(jnp.asarray(s_c, dtype)[:, None] / (dt * gamma_s), axis=1)  # (n_theta,)
    kt = s_f * jnp.mean(faces.k_theta, axis=1) / grid.dtheta**2  # (n_theta - 1,)
    kp = jnp.mean(faces.k_phi, axis=1) / (jnp.asarray(s_c, dtype) * grid.dphi**2)  # (n_theta,)
    m = np.arange(grid.n_phi // 2 + 1)
    lam = jnp.asarray(2.0 - 2.0 * np.cos(2.0 * np.pi * m / grid.n_phi), dtype)  # (n_modes,)
    zero = jnp.zeros((1,), dtype)
    kt_pad = jnp.concatenate([zero, kt, zero])
    diag = (d + kt_pad[:-1] + kt_pad[1:])[None, :] + lam[:, None] * kp[None, :]  # (n_modes, n_theta)
    off = -kt
    lower = jnp.broadcast_to(jnp.concatenate([zero, off]), diag.shape)
    upper = jnp.broadcast_to(jnp.concatenate([off, zero]), diag.shape)

    def apply_inverse(r):
        rh = jnp.fft.rfft(r, axis=1).T  # (n_modes, n_theta) complex
        rhs2 = jnp.stack([rh.real, rh.imag], axis=-1)  # (n_modes, n_theta, 2)
        sol = jax.lax.linalg.tridiagonal_solve(lower, diag, upper, rhs2)
        zh = (sol[..., 0] + 1j * sol[..., 1]).T
        return jnp.fft.irfft(zh, n=grid.n_phi, axis=1).astype(dtype)

    return apply_inverse


class CGInfo(NamedTuple):
    """How the solve went: iterations used and the final relative residual |b - A x| / |b|."""

    iterations: jax.Array
    residual: jax.Array


def cg(matvec, b, x0, precond, rtol, max_iter: int):
    """Preconditioned conjugate gradients (``lax.while_loop``, at most ``max_iter`` iterations,
    stops when |r| <= rtol |b|); ``precond(r)`` applies the (SPD) preconditioner. Returns
    ``(x, CGInfo)``."""
    bnorm = jnp.sqrt(jnp.sum(b * b))
    r = b - matvec(x0)
    z = precond(r)
    p = z
    rz = jnp.sum(r * z)

    def cond(c):
        k, x, r, p, rz = c
        return (k < max_iter) & (jnp.sqrt(jnp.sum(r * r)) > rtol * bnorm)

    def body(c):
        k, x, r, p, rz = c
        Ap = matvec(p)
        alpha = rz / jnp.sum(p * Ap)
        x = x + alpha * p
        r = r - alpha * Ap
        z = precond(r)
        rz_new = jnp.sum(r * z)
        p = z + (rz_new / rz) * p
        return k + 1, x, r, p, rz_new

    k, x, r, _, _ = jax.lax.while_loop(cond, body, (jnp.zeros((), jnp.int32), x0, r, p, rz))
    res = jnp.sqrt(jnp.sum(r * r)) / jnp.where(bnorm > 0, bnorm, 1.0)
    return x, CGInfo(k, res)


def project(grid: SphereGrid, faces: Faces, gamma):
    """The new face velocity u = F - k grad Gamma (Huang Eq. 3.24a solved for u)."""
    gt, gp = grid.gradient(gamma)
    return faces.F_theta - faces.k_theta * gt, faces.F_phi - faces.k_phi * gp
