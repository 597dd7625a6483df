"""Numpy reference :class:`~appearance_jax.flatland.fan.Fan` for a circle of radius 1 (test
helper; spec seed-002 §1.2.5).

Closed forms: incidence angle ``i = asin|s|``, ``sin r = sin i / n``; deviation
``D_0 = pi - 2i``, ``D_p = 2(i - r) + (p - 1)(pi - 2r)``; optical path between the two
reference planes through the centre ``L = -2 cos i + 2 p n cos r``; amplitudes ``A_0 = rho``,
``A_p = (1 - rho^2)(-rho)^(p-1)`` with ``rho`` the library's signed Fresnel reflection
amplitudes (⊥ = s, ∥ = p). The foci and axis counts are *not* closed forms: they are counted
on the polylines (entry point, internal vertices, outgoing half-line) of each ray and its
forward neighbour in the fan, the way a tracer would (the last ray copies its predecessor).

Geometry: propagation along +x, ``s`` is the y of the incoming ray (positive side = +90°
from the propagation direction), ``psi`` the signed outgoing angle from +x.
"""

from __future__ import annotations

import numpy as np

from appearance_jax.flatland.fan import Fan


def _wrap(a):
    return np.angle(np.exp(1j * a))


def _fresnel_rho(cos_i, n):
    """(rho_perp, rho_par) for external incidence from index 1 onto n (library signs)."""
    sin_i = np.sqrt(np.maximum(1.0 - cos_i ** 2, 0.0))
    cos_t = np.sqrt(1.0 - (sin_i / n) ** 2)
    r_s = (cos_i - n * cos_t) / (cos_i + n * cos_t)
    r_p = (n * cos_i - cos_t) / (n * cos_i + cos_t)
    return r_s, r_p


def _cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def segments_cross(p0, p1, q0, q1):
    """Proper intersection of segments p0-p1 and q0-q1 (arrays of 2-vectors)."""
    d1, d2 = p1 - p0, q1 - q0
    den = _cross2(d1, d2)
    den_safe = np.where(den == 0, 1.0, den)
    w = q0 - p0
    t = _cross2(w, d2) / den_safe
    u = _cross2(w, d1) / den_safe
    return (den != 0) & (t > 0) & (t < 1) & (u > 0) & (u < 1)


def halflines_cross(p0, dp, q0, dq):
    den = _cross2(dp, dq)
    den_safe = np.where(den == 0, 1.0, den)
    w = q0 - p0
    t = _cross2(w, dq) / den_safe
    u = _cross2(w, dp) / den_safe
    return (den != 0) & (t > 0) & (u > 0)


def circle_polylines(s, n, p):
    """Vertices (N, p + 1, 2) and outgoing directions (N, 2) of family ``p`` for a unit circle."""
    s = np.asarray(s, float)
    sg = np.where(s >= 0, 1.0, -1.0)
    i = np.arcsin(np.abs(s))
    r = np.arcsin(np.abs(s) / n)
    # vertex k sits at polar angle sg * (pi - i - k (pi - 2r)); the ray turns clockwise (s > 0)
    k = np.arange(max(p, 0) + 1)
    phi = sg[:, None] * (np.pi - i[:, None] - k[None, :] * (np.pi - 2 * r[:, None]))
    verts = np.stack([np.cos(phi), np.sin(phi)], -1)
    psi = psi_closed_form(s, n, p)
    return verts, np.stack([np.cos(psi), np.sin(psi)], -1)


def psi_closed_form(s, n, p):
    s = np.asarray(s, float)
    sg = np.where(s >= 0, 1.0, -1.0)
    i = np.arcsin(np.abs(s))
    r = np.arcsin(np.abs(s) / n)
    if p == 0:
        return sg * (np.pi - 2 * i)
    D = 2 * (i - r) + (p - 1) * (np.pi - 2 * r)
    return _wrap(-sg * D)


def circle_fan(s, n=1.331, families=4):
    """Fan (numpy arrays) of a unit circle at impact parameters ``s`` (sorted, in (-1, 1))."""
    s = np.asarray(s, float)
    N = s.size
    cos_i = np.sqrt(1.0 - s ** 2)
    cos_r = np.sqrt(1.0 - (s / n) ** 2)
    rho = np.stack(_fresnel_rho(cos_i, n), -1)  # (N, 2)
    psi = np.zeros((families, N))
    amp = np.zeros((families, N, 2), complex)
    opl = np.zeros((families, N))
    foci = np.zeros((families, N), int)
    axis = np.zeros((families, N), int)
    for p in range(families):
        psi[p] = psi_closed_form(s, n, p)
        amp[p] = rho if p == 0 else (1 - rho ** 2) * (-rho) ** (p - 1)
        opl[p] = -2 * cos_i + 2 * p * n * cos_r
        verts, out = circle_polylines(s, n, p)
        if p == 0:
            # the polyline of a reflected ray is its hit point plus the half-line
            verts = verts[:, :1]
        pair = np.zeros(N - 1, int)
        for c in range(verts.shape[1] - 1):
            pair += segments_cross(verts[:-1, c], verts[:-1, c + 1], verts[1:, c], verts[1:, c + 1])
        pair += halflines_cross(verts[:-1, -1], out[:-1], verts[1:, -1], out[1:])
        foci[p, :-1] = pair
        foci[p, -1] = pair[-1]
        # axis crossings: sign changes of y along the polyline (incoming half-line has y = s)
        y = np.concatenate([s[:, None], verts[..., 1]], 1)
        ax = np.sum(np.signbit(y[:, 1:]) != np.signbit(y[:, :-1]), 1)
        ax += (out[:, 1] * verts[:, -1, 1] < 0)  # the outgoing half-line heads across y = 0
        axis[p] = ax
    valid = np.ones((families, N), bool)
    return Fan(s=s, psi=psi, amp=amp, opl=opl, foci=foci, axis=axis, valid=valid)


def energy_fraction(n, p, lift, npts=200001):
    """Closed-form geometric energy fraction of family ``p`` (unpolarised), by quadrature in i.

    ``lift="sphere"``: 2 ∫_0^1 s |A|^2 ds; ``"cylinder"``: ∫_0^1 |A|^2 ds (both /2 pols).
    """
    i = np.linspace(0, np.pi / 2, npts)
    s, cos_i = np.sin(i), np.cos(i)
    rho = np.stack(_fresnel_rho(cos_i, n), -1)
    A2 = (rho ** 2 if p == 0 else ((1 - rho ** 2) * rho ** (p - 1)) ** 2).mean(-1)
    f = (2 * s * A2 if lift == "sphere" else A2) * cos_i  # ds = cos i di
    return np.trapz(f, i) if hasattr(np, "trapz") else np.trapezoid(f, i)
