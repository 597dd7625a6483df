"""Angle grids on which tables are measured or proxies evaluated (all angles in radians).

- :func:`merl_angles`: the MERL half/difference grid (Matusik et al. 2003): 90 theta_h
  bins with theta_h = (i / 90)^2 pi/2 (denser near the highlight), 90 theta_d bins
  theta_d = j pi/180 and 180 phi_d bins phi_d = k pi/180 in [0, pi) (phi_d is folded by
  reciprocity, f(phi_d) = f(phi_d + pi)); phi_h = 0 (isotropy). Node = lower edge of the
  bin, the value MERL's own lookup (floor of the index) maps to that entry.
- :func:`in_plane_angles`: theta_i x signed theta_o, the in-plane gonioreflectometer of
  Padrón 2025 §4.5 (theta_o < 0: retro-reflection side).
- :func:`gonio_angles`: theta_i x theta_o x (phi_o - phi_i), an out-of-plane gonioreflectometer.
"""

from __future__ import annotations

import numpy as np

from .table import HORIZON_COS

MERL_SHAPE = (90, 90, 180)  # (theta_h, theta_d, phi_d) bins


def merl_angles(stride: int = 1):
    """(theta_h, theta_d, phi_d) node arrays of shape ``MERL_SHAPE // stride`` (every ``stride``-th bin)."""
    if stride < 1 or any(n % stride for n in MERL_SHAPE):
        raise ValueError(f"merl_angles: stride = {stride} must be >= 1 and divide 90 and 180")
    i = np.arange(0, 90, stride)
    j = np.arange(0, 90, stride)
    k = np.arange(0, 180, stride)
    theta_h = (i / 90.0) ** 2 * (np.pi / 2)
    theta_d = j * (np.pi / 180.0)
    phi_d = k * (np.pi / 180.0)
    return np.meshgrid(theta_h, theta_d, phi_d, indexing="ij")


def half_diff_to_angles(theta_h, theta_d, phi_d):
    """(theta_i, phi_i, theta_o, phi_o, above) of Rusinkiewicz angles with phi_h = 0 (float64 numpy).

    ``above`` is True where both directions are strictly above the horizon.
    """
    import jax

    from ...core.frame import from_half_diff, spherical_angles

    # float64 on the CPU whatever the global setting: these are file coordinates, not kernels
    with jax.enable_x64(True), jax.default_device(jax.devices("cpu")[0]):
        th = np.asarray(theta_h, np.float64)
        wi, wo = from_half_diff(th, np.zeros_like(th), np.asarray(theta_d, np.float64),
                                np.asarray(phi_d, np.float64))
        ti, pi_ = (np.asarray(a, np.float64) for a in spherical_angles(wi))
        to, po = (np.asarray(a, np.float64) for a in spherical_angles(wo))
        above = (np.asarray(wi.z) > HORIZON_COS) & (np.asarray(wo.z) > HORIZON_COS)
    return ti, np.mod(pi_, 2 * np.pi), to, np.mod(po, 2 * np.pi), above


def in_plane_angles(theta_i_deg, theta_o_deg):
    """Flattened (theta_i, signed theta_o) in radians of the grid theta_i x theta_o (degrees in)."""
    ti, to = np.meshgrid(np.asarray(theta_i_deg, float), np.asarray(theta_o_deg, float), indexing="ij")
    return np.deg2rad(ti.ravel()), np.deg2rad(to.ravel())


def gonio_angles(theta_i_deg, theta_o_deg, dphi_deg):
    """Flattened (theta_i, phi_i, theta_o, phi_o) radians of theta_i x theta_o x (phi_o - phi_i); phi_i = 0."""
    ti, to, dp = np.meshgrid(np.asarray(theta_i_deg, float), np.asarray(theta_o_deg, float),
                             np.asarray(dphi_deg, float), indexing="ij")
    return np.deg2rad(ti.ravel()), np.zeros(ti.size), np.deg2rad(to.ravel()), np.deg2rad(np.mod(dp.ravel(), 360.0))
