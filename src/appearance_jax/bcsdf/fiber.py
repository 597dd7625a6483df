"""Fiber geometry and absorption shared by the hair BCSDFs (one convention, defined once).

Frame (:mod:`appearance_jax.core.frame`): x is the fiber tangent (root -> tip), the normal
plane is (y, z); a direction has longitudinal angle theta in [-pi/2, pi/2] (sin theta = w.x)
and azimuth phi = atan2(w.z, w.y) (:func:`core.frame.fiber_angles`). Both omega_i (to the
light) and omega_o (to the viewer) point away from the fiber. The offset h in [-1, 1] is the
signed impact parameter of the incident ray on the unit-radius cross-section (h = sin gamma_i),
oriented as in :mod:`appearance_jax.flatland` so that lobe p leaves at
phi_o - phi_i = Phi(p, h) = 2 p gamma_t - 2 gamma_i + p pi (d'Eon et al. 2011; pbrt-v3).
Lengths, and so absorption coefficients, are per unit **radius**.

Contents: Bravais' effective indices (Marschner et al. 2003, App. B), the projected half
width of an elliptical fiber (Huang Eq. 4.27) and the geometry of its cross-section (points,
normals, arc length, chords, entry points and visible arcs; Huang 2022 Sec. 4.3), the smooth-cylinder exit azimuths and
lobe attenuations (spec seed-000 M18, with the corrected chord 2 cos(gamma_t)/cos(theta_t),
Eq. 4.17 / [T:1110], Huang 2022), and absorption from melanin concentrations or from a
desired colour.
"""

from __future__ import annotations

import jax.numpy as jnp

from ..core.frame import Frame, meso_normal  # noqa: F401  (meso_normal: defined with the fibre frame)
from ..core.fusion import materialize
from ..core.special import safe_acos, safe_asin, safe_sqrt
from ..core.vec import Vec3
from .fast32 import fresnel_outside

# Chiang et al. 2016 (as in pbrt-v3): absorption per unit radius of one unit of eumelanin /
# pheomelanin concentration, linear RGB
EUMELANIN_RGB = (0.419, 0.697, 1.37)
PHEOMELANIN_RGB = (0.187, 0.4, 1.05)
# wavelengths (nm) of the RGB channels in the spectral form (Huang 2022's code)
RGB_WAVELENGTHS_NM = (612.0, 549.0, 465.0)


def wrap_pi(x):
    """Angle wrapped to [-pi, pi) (up to rounding at the ends).

    By floor rather than ``jnp.mod``: XLA:CPU lowers the remainder to a scalar libm ``fmod``
    call per element (~70 ns), the floor form vectorises (~0.1 ns)."""
    two_pi = 2.0 * jnp.pi
    return x - two_pi * jnp.floor((x + jnp.pi) / two_pi)


def bravais_eta(eta, theta):
    """Effective index eta' = sqrt(eta^2 - sin^2 theta) / cos theta for the 2D refraction in
    the normal plane (Bravais; Marschner et al. 2003, App. B; perpendicular polarisation)."""
    return bravais_eta_sc(eta, jnp.sin(theta), jnp.cos(theta))


def bravais_eta_sc(eta, sin_theta, cos_theta):
    """:func:`bravais_eta` from sin(theta) and cos(theta) (no trigonometric calls: for kernels
    that start from direction components, sin(theta) = w.x)."""
    return safe_sqrt(eta * eta - sin_theta * sin_theta) / jnp.maximum(cos_theta, 1e-12)


def bravais_eta_parallel(eta, theta):
    """Second Bravais index eta'' = eta^2 cos theta / sqrt(eta^2 - sin^2 theta) (parallel
    polarisation; Marschner et al. 2003, App. B)."""
    s = jnp.sin(theta)
    return eta * eta * jnp.cos(theta) / jnp.maximum(safe_sqrt(eta * eta - s * s), 1e-12)


def half_width(eccentricity, phi):
    """Projected half width D(phi) = sqrt(1 - e^2 sin^2 phi) of an elliptical fiber with
    semi-axis 1 along z and sqrt(1 - e^2) along y, seen from azimuth phi (Eq. 4.27,
    Huang 2022; the same ellipse as :func:`flatland.fiber`)."""
    s = jnp.sin(phi)
    return safe_sqrt(1.0 - eccentricity * eccentricity * s * s)


# ----------------------------------------------------------------------------------
# the elliptical cross-section y^2 / b^2 + z^2 = 1 (Huang 2022, Sec. 4.3.3): points
# (b cos g, sin g) of the ellipse parameter g (Huang's gamma), b = sqrt(1 - e^2)

_TINY = 1e-12


def minor_axis(eccentricity):
    """b = sqrt(1 - e^2): the semi-axis along y of the cross-section (semi-major axis 1 along z)."""
    return safe_sqrt(1.0 - eccentricity * eccentricity)


def to_gamma(phi, b):
    """Ellipse parameter gamma of the point whose outward normal has azimuth phi."""
    return jnp.arctan2(jnp.sin(phi), b * jnp.cos(phi))


def to_phi(gamma, b):
    """Azimuth of the outward normal at parameter gamma: atan2(b sin g, cos g)."""
    return jnp.arctan2(b * jnp.sin(gamma), jnp.cos(gamma))


def ellipse_point(g, b):
    """(y, z) of the point of parameter g: (b cos g, sin g)."""
    return b * jnp.cos(g), jnp.sin(g)


def ellipse_normal(py, pz, b):
    """Outward unit normal (n_y, n_z) (the macronormal) at the point (py, pz) of the ellipse."""
    ny, nz = py / (b * b), pz
    r = jnp.sqrt(ny * ny + nz * nz)
    return ny / r, nz / r


def arc_element(g, b):
    """dl / dg = sqrt(1 - e^2 sin^2 g): arc length per unit ellipse parameter (Huang Eq. 4.26)."""
    return safe_sqrt(1.0 - (1.0 - b * b) * jnp.sin(g) ** 2)


def ellipse_chord(py, pz, d: Vec3, b):
    """Parameter s of the second intersection of p + s (d.y, d.z) with the ellipse (p on it).
    For a unit 3D direction d this is the 3D path length."""
    A = d.y * d.y / (b * b) + d.z * d.z
    B = 2.0 * (py * d.y / (b * b) + pz * d.z)
    ok = A > _TINY
    s = jnp.where(ok, -B / jnp.where(ok, A, 1.0), 0.0)
    return jnp.maximum(s, 0.0)


def entry_gamma(wi: Vec3, h, b):
    """Ellipse parameter of the entry point of the ray from ``wi`` at signed offset
    ``h`` in [-D_i, D_i] (2D line-ellipse intersection on the lit side; for a circle
    gamma = phi_i + asin h, spec seed-001 §1.3.2). Returns (gamma, valid)."""
    r = jnp.sqrt(wi.y * wi.y + wi.z * wi.z)
    ok = r > _TINY
    r = jnp.where(ok, r, 1.0)
    uy, uz = wi.y / r, wi.z / r           # towards the light
    vy, vz = -uz, uy
    A = uy * uy / (b * b) + uz * uz
    B = 2.0 * h * (vy * uy / (b * b) + vz * uz)
    C = h * h * (vy * vy / (b * b) + vz * vz) - 1.0
    s = (-B + safe_sqrt(B * B - 4.0 * A * C)) / (2.0 * A)
    py, pz = h * vy + s * uy, h * vz + s * uz
    return jnp.arctan2(pz, py / b), ok


def visible_gamma_interval(theta, phi, tilt, b):
    """Entry parameters gamma seen by direction (theta, phi) from both the macro- and the
    mesonormal of cuticle tilt ``tilt``: cos(phi - phi_m) > max(0, -tan(tilt) tan(theta))
    (spec seed-001 §1.3.3). Returns (lo, hi) with hi >= lo (empty: hi = lo) and lo unwrapped
    near gamma(phi)."""
    c = jnp.maximum(0.0, -jnp.tan(tilt) * jnp.tan(theta))
    w, gc = materialize((safe_acos(jnp.minimum(c, 1.0)), to_gamma(phi, b)))  # used 3x each: compute once
    lo = gc - jnp.mod(gc - to_gamma(phi - w, b), 2.0 * jnp.pi)
    hi = gc + jnp.mod(to_gamma(phi + w, b) - gc, 2.0 * jnp.pi)
    # w = 0: the mods may return 2 pi - eps; collapse
    lo = jnp.where(w > 0, lo, gc)
    hi = jnp.where(w > 0, hi, gc)
    return materialize((lo, hi))


def intersect_intervals(lo1, hi1, lo2, hi2):
    """Intersection of two intervals of the ellipse parameter, the second shifted by a multiple
    of 2 pi towards the first; (lo, hi) with hi >= lo (empty: hi = lo)."""
    m1, m2 = 0.5 * (lo1 + hi1), 0.5 * (lo2 + hi2)
    shift = wrap_pi(m2 - m1) - (m2 - m1)
    lo2, hi2 = lo2 + shift, hi2 + shift
    lo, hi = jnp.maximum(lo1, lo2), jnp.minimum(hi1, hi2)
    return lo, jnp.maximum(hi, lo)


def meso_frame(m: Vec3):
    """Local frame with normal ``m`` (a mesonormal) and tangent along the fiber axis x."""
    one = jnp.ones_like(m.x)
    return Frame.from_normal_tangent(m, Vec3(one, 0.0 * one, 0.0 * one))


def exit_azimuth(p, h, eta_prime):
    """Phi(p, h) = 2 p gamma_t - 2 gamma_i + p pi: the exit azimuth of lobe p relative to
    phi_i, for a smooth circular fiber (spec M18; unwrapped)."""
    return exit_azimuth_of(p, safe_asin(h), safe_asin(h / eta_prime))


def exit_azimuth_of(p, gamma_i, gamma_t):
    """Phi(p, h) of :func:`exit_azimuth` from gamma_i = asin(h) and gamma_t = asin(h / eta')."""
    return 2.0 * p * gamma_t - 2.0 * gamma_i + p * jnp.pi


def smooth_attenuation(h, theta_i, eta, sigma_a, p_max: int = 4):
    """Lobe attenuations A_p(h), p = 0 .. p_max - 1, of a smooth circular fiber, plus the
    residual sum of all higher lobes as a last entry (spec M18; d'Eon et al. 2011;
    Chiang et al. 2016): A_0 = f, A_1 = (1 - f)^2 T, A_p = A_{p-1} T f, residual
    A_{p_max-1} f T / (1 - f T), with f the dielectric Fresnel at cos(theta_i) cos(gamma_i)
    (true 3D angle, true index) and T = exp(-sigma_a 2 cos(gamma_t) / cos(theta_t)).

    ``sigma_a`` may carry a trailing bands axis; the result has shape
    ``(p_max + 1,) + broadcast(h, theta_i) + bands``.
    """
    theta_i = jnp.asarray(theta_i)
    return smooth_attenuation_sc(h, jnp.sin(theta_i), jnp.cos(theta_i), eta, sigma_a, p_max)


def smooth_attenuation_sc(h, sin_ti, cos_ti, eta, sigma_a, p_max: int = 4):
    """:func:`smooth_attenuation` from sin(theta_i) and cos(theta_i) >= 0 (no trigonometric
    calls: cos(gamma_t) = sqrt(1 - (h / eta')^2))."""
    h = jnp.asarray(h)
    sigma_a = jnp.atleast_1d(jnp.asarray(sigma_a))
    f, chord = attenuation_factors(h, sin_ti, cos_ti, eta)
    return jnp.stack(lobe_attenuations(f[..., None], jnp.exp(-sigma_a * chord[..., None]), p_max))


def attenuation_factors(h, sin_ti, cos_ti, eta):
    """(f, l): the dielectric Fresnel reflectance f at cos(theta_i) cos(gamma_i) (true 3D angle,
    true index) and the path length l = 2 cos(gamma_t) / cos(theta_t) through the fiber, so
    that the transmittance of one pass is T = exp(-sigma_a l) (spec M18; see
    :func:`smooth_attenuation`). cos_ti >= 0. In float32 the Fresnel term is
    :func:`fast32.fresnel_outside`'s short form."""
    cos_gi = safe_sqrt(1.0 - h * h)
    f = fresnel_outside(cos_ti * cos_gi, eta)
    sin_gt = h / bravais_eta_sc(eta, sin_ti, cos_ti)
    cos_gt = safe_sqrt(1.0 - sin_gt * sin_gt)
    sin_tt = sin_ti / eta
    cos_tt = safe_sqrt(1.0 - sin_tt * sin_tt)
    return f, 2.0 * cos_gt / cos_tt


def lobe_attenuations(f, T, p_max: int = 4):
    """[A_0, ..., A_{p_max-1}, A_residual] from the Fresnel reflectance f and the one-pass
    transmittance T (broadcasting, e.g. f (..., 1) against T (..., bands)): A_0 = f,
    A_1 = (1 - f)^2 T, A_p = A_{p-1} T f, residual A_{p_max-1} f T / (1 - f T)."""
    A = [f * jnp.ones_like(T), (1.0 - f) ** 2 * T]
    for _ in range(2, p_max):
        A.append(A[-1] * T * f)
    ft = f * T
    return A[:p_max] + [A[p_max - 1] * ft / jnp.where(ft < 1, 1.0 - ft, 1.0)]


def melanin_sigma_a_rgb(eumelanin, pheomelanin):
    """Absorption per unit radius (linear RGB) of eumelanin / pheomelanin concentrations
    (Chiang et al. 2016, Sec. 4.2; the parametrisation of pbrt-v3 and Mitsuba 3's ``hair``)."""
    e = jnp.asarray(eumelanin)[..., None]
    p = jnp.asarray(pheomelanin)[..., None]
    return e * jnp.asarray(EUMELANIN_RGB) + p * jnp.asarray(PHEOMELANIN_RGB)


def melanin_sigma_a_spectral(eumelanin, pheomelanin, wavelength_nm=RGB_WAVELENGTHS_NM):
    """Spectral absorption per unit radius: rho_e 6.6e8 lambda^-3.33 + rho_p 2.9e12
    lambda^-4.75 (lambda in nm; the Donner-Jensen melanin spectra as scaled in Huang 2022's
    code, spec seed-001 §1.3.13). At rho_e = rho_p = 0.6: (0.309, 0.467, 0.891) at
    (612, 549, 465) nm."""
    lam = jnp.asarray(wavelength_nm, dtype=jnp.result_type(float))
    e = jnp.asarray(eumelanin)[..., None]
    p = jnp.asarray(pheomelanin)[..., None]
    return e * 6.6e8 * lam ** -3.33 + p * 2.9e12 * lam ** -4.75


def sigma_a_from_color(color, beta_n):
    """Absorption per unit radius that gives a fiber of azimuthal roughness ``beta_n`` the
    multiply scattered colour ``color`` (linear RGB in (0, 1]; Chiang et al. 2016, Eq. 9):
    sigma_a = (ln c / (5.969 - 0.215 b + 2.532 b^2 - 10.73 b^3 + 5.574 b^4 + 0.245 b^5))^2."""
    c = jnp.clip(jnp.asarray(color, dtype=jnp.result_type(float)), 1e-6, 1.0)
    b = jnp.asarray(beta_n)[..., None] if jnp.ndim(beta_n) else jnp.asarray(beta_n)
    den = 5.969 - 0.215 * b + 2.532 * b ** 2 - 10.73 * b ** 3 + 5.574 * b ** 4 + 0.245 * b ** 5
    return (jnp.log(c) / den) ** 2
