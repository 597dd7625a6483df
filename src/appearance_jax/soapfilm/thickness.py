"""Film-thickness fields on a spherical bubble (Huang 2022, Ch. 3, seed 001).

Conventions
-----------
* The bubble is the unit sphere; a point on it is identified with its outward unit normal
  ``n`` (a :class:`~appearance_jax.core.vec.Vec3`).
* **World +z is up** (gravity points along -z). The polar angle theta is measured from
  the top, cos(theta) = n . up, so theta = 0 is the top of the bubble and theta = pi the
  bottom; the azimuth phi = atan2(n.y, n.x) in [0, 2 pi). This is the (theta, phi) grid of
  the thesis' simulation ([T:620-640]; Huang Eq. 3.33 has gravity g sin(theta) pulling towards
  theta = pi).
* The thesis' film variable eta is the **half** thickness (the film is 2 eta thick, Huang Fig. 3.2,
  [T:502]; optical path difference 4 eta n cos(theta_s), [T:753]). The shading
  (:mod:`appearance_jax.soapfilm.bubble`, :func:`appearance_jax.optics.thinfilm.airy`)
  takes the **full** thickness d = 2 eta in nm. The field builders below return full
  thicknesses in nm and take the mean *half* thickness eta_0 in nm (Huang Table 3.1 lists
  eta_0 = 4e-7 ... 1e-6 m, i.e. 400 ... 1000 nm, hence full thicknesses 800 ... 2000 nm).

Contents
--------
* :func:`equilibrium_thickness`: the gravity-only equilibrium profile, Huang Eq. 3.36, in units
  of the mean half thickness, with the printed normalisation (mean over theta) or a
  volume-conserving one (area mean over the sphere).
* :func:`dimensionless_numbers`: Huang Table 3.2 from the dimensional constants of Huang Table 3.1
  (with the drag-coefficient misprint fixed: bubble radius R, not the gas constant).
* :func:`latlong_thickness`: bilinear lookup of an equirectangular (n_theta, n_phi) map.
* field builders (callables ``Vec3 -> thickness_nm`` for
  :func:`appearance_jax.soapfilm.bubble.shade`): :func:`uniform_field`,
  :func:`equilibrium_field`, :func:`latlong_field`.

Everything is pure ``jnp`` (jittable, differentiable in the profile parameter, the map
values and the normal).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import jax.scipy.special as jsp
import numpy as np

from ..core.special import safe_acos, safe_atan2
from ..core.vec import Vec3, dot, normalize

NORMALIZATIONS = ("printed", "volume")


def _is_traced(x) -> bool:
    return isinstance(x, jax.core.Tracer)


def _concrete(x):
    """A numpy array of ``x`` or None where ``x`` is traced (checks happen eagerly only)."""
    if _is_traced(x):
        return None
    try:
        return np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"not numeric: {x!r}") from None


def _check_finite(name, x):
    a = _concrete(x)
    if a is not None and not np.all(np.isfinite(a)):
        raise ValueError(f"{name} = {a[~np.isfinite(a)].flat[0]:g} is not finite")


def _check_positive(name, x, unit=""):
    a = _concrete(x)
    if a is not None and (not np.all(np.isfinite(a)) or np.any(a <= 0)):
        bad = a[~(np.isfinite(a) & (a > 0))].flat[0]
        raise ValueError(f"{name} = {bad:g} is outside the valid range (0, inf){unit}")


def _check_nonnegative(name, x, unit=""):
    a = _concrete(x)
    if a is not None and (not np.all(np.isfinite(a)) or np.any(a < 0)):
        bad = a[~(np.isfinite(a) & (a >= 0))].flat[0]
        raise ValueError(f"{name} = {bad:g} is outside the valid range [0, inf){unit}")


# --------------------------------------------------------------------------------------
# Equilibrium profile (Huang Eq. 3.36)
# --------------------------------------------------------------------------------------


def _printed_profile(a, c):
    """e^{-a c} / I_0(a) = pi e^{-a c} / int_0^pi e^{-a cos t} dt, stable for any a.

    |a| < 1: the plain form with I_0 from its power series sum_k (a^2/4)^k / (k!)^2
    (11 terms, error < 1e-19; ``jax.scipy.special.i0`` is exp(|a|) i0e(a) and its
    gradient at a = 0 is wrong); otherwise e^{-a c - |a|} / i0e(|a|) (no overflow). The
    branches are selected with double-wheres, so the gradient is exact everywhere.
    """
    small = jnp.abs(a) < 1.0
    a_s = jnp.where(small, a, 0.0)
    a_b = jnp.where(small, 1.0, a)
    x_b = jnp.abs(a_b)
    q = 0.25 * a_s * a_s
    i0 = jnp.ones_like(q)
    term = jnp.ones_like(q)
    for k in range(1, 11):
        term = term * q / (k * k)
        i0 = i0 + term
    plain = jnp.exp(-a_s * c) / i0
    scaled = jnp.exp(-a_b * c - x_b) / jsp.i0e(x_b)
    return jnp.where(small, plain, scaled)


def _volume_profile(a, c):
    """(a / sinh a) e^{-a c}: int_0^pi (.) sin t dt = 2; limit e^{-a c} (1 - a^2/6) at a -> 0.

    |a| >= 1: 2|a| e^{-a c - |a|} / (1 - e^{-2|a|}) (no overflow); 1e-4 <= |a| < 1: plain;
    |a| < 1e-4: the series a / sinh a = 1 - a^2/6 + 7 a^4/360.
    """
    x = jnp.abs(a)
    tiny = x < 1e-4
    big = x >= 1.0
    a_m = jnp.where(tiny | big, 0.5, a)
    a_b = jnp.where(big, a, 1.0)
    x_b = jnp.abs(a_b)
    a_t = jnp.where(tiny, a, 0.0)
    plain = a_m / jnp.sinh(a_m) * jnp.exp(-a_m * c)
    scaled = 2.0 * x_b / (-jnp.expm1(-2.0 * x_b)) * jnp.exp(-a_b * c - x_b)
    series = (1.0 - a_t * a_t / 6.0 + 7.0 * a_t ** 4 / 360.0) * jnp.exp(-a_t * c)
    return jnp.where(tiny, series, jnp.where(big, scaled, plain))


def equilibrium_thickness(theta, g_over_M, normalization: str = "printed"):
    """Gravity-only equilibrium half thickness eta(theta) / eta_0, Huang Eq. 3.36.

    Balancing the Marangoni force against gravity with Gamma = eta initially (Huang Eqs.
    3.33-3.35, [T:840-860]): -(M / eta) d(eta)/d(theta) + g sin(theta) = 0, so

        eta(theta) = C exp(-(g / M) cos(theta)),

    thinnest at the top (theta = 0) and thickest at the bottom (theta = pi).

    Args:
        theta: polar angle from the **top** of the bubble (radians, [0, pi]).
        g_over_M: the ratio g / M of the scaled gravity g = G R / U^2 and the Marangoni
            number M (Huang Table 3.2); dimensionless, any real (0 gives a uniform film).
        normalization: how C is fixed.
            ``"printed"`` (as printed in Huang Eq. 3.36): C = pi / int_0^pi e^{-(g/M) cos t} dt
            = 1 / I_0(g/M): the plain mean over theta is 1.
            ``"volume"``: int_0^pi eta sin(theta) d(theta) = 2, i.e. the area mean over the
            sphere is 1 (volume of liquid conserved): C = (g/M) / sinh(g/M).

    Returns:
        eta / eta_0 (dimensionless), broadcast over ``theta`` and ``g_over_M``.
        Multiply by the mean half thickness eta_0, and by 2 for the full thickness.

    Both constants are closed forms (Bessel I_0 via the exponentially scaled ``i0e``), so
    the profile is differentiable in ``g_over_M``. Reference values (spec SS-2, Huang Fig. 3.13
    setting): g/M = 0.473 -> eta(top) = 0.590, eta(bottom) = 1.518 (printed).
    """
    if normalization not in NORMALIZATIONS:
        raise ValueError(f"normalization = {normalization!r}: must be one of {', '.join(NORMALIZATIONS)}")
    _check_finite("g_over_M", g_over_M)
    _check_finite("theta", theta)
    a = jnp.asarray(g_over_M, dtype=jnp.result_type(g_over_M, float))
    return _equilibrium(jnp.asarray(theta, dtype=a.dtype), a, normalization)


@functools.partial(jax.jit, static_argnames=("normalization",))
def _equilibrium(theta, a, normalization):
    c = jnp.cos(theta)
    if normalization == "printed":
        return _printed_profile(a, c)
    return _volume_profile(a, c)


# --------------------------------------------------------------------------------------
# Huang Tables 3.1 / 3.2
# --------------------------------------------------------------------------------------


class Constants(NamedTuple):
    """Dimensional constants of Huang Table 3.1 ([T:796-812]); SI units."""

    gamma_a: float = 7.275e-2  # N/m, surface tension of the water-air interface
    R_gas: float = 8.3144598  # J/(mol K), gas constant (printed as R-bar)
    T: float = 298.15  # K, room temperature
    rho: float = 997.0  # kg/m^3, water mass density
    mu: float = 8.9e-4  # Pa s, water dynamic viscosity
    rho_a: float = 1.184  # kg/m^3, air density
    nu_a: float = 1.562e-5  # m^2/s, air kinematic viscosity
    G: float = 9.8  # m/s^2, gravitational acceleration


TABLE_3_1 = Constants()


class DimensionlessNumbers(NamedTuple):
    """Huang Table 3.2 ([T:814-826])."""

    epsilon: jax.Array  # expansion parameter eta_0 / R
    M: jax.Array  # Marangoni number Gamma_0 R_gas T / (rho eta_0 U^2)
    Re: jax.Array  # Reynolds number U R rho / mu
    Cr: jax.Array  # drag coefficient rho_a sqrt(nu_a R) / (rho eta_0 sqrt(U))
    g: jax.Array  # scaled gravitational acceleration G R / U^2

    @property
    def g_over_M(self):
        """The one parameter of the equilibrium profile, Huang Eq. 3.36."""
        return self.g / self.M


def dimensionless_numbers(R=0.05, eta0=5e-7, U=1.0, Gamma0=1.669e-7,
                          constants: Constants = TABLE_3_1) -> DimensionlessNumbers:
    """Huang Table 3.2 from the dimensional parameters ([T:814-826]).

    Args:
        R: bubble radius (m), Huang Table 3.1 range 0.02-0.1.
        eta0: mean **half** thickness (m), range 4e-7-1e-6.
        U: characteristic velocity (m/s), 1 in the thesis.
        Gamma0: mean surfactant concentration (mol/m^2), range 1e-8-1e-6.
        constants: the remaining constants of Huang Table 3.1.

    Returns:
        :class:`DimensionlessNumbers` (epsilon, M, Re, Cr, g; ``.g_over_M``).

    The drag coefficient is printed as rho_a sqrt(nu_a R-bar) / (rho eta_0 sqrt U) with
    the gas constant R-bar [T:825]; that is a misprint for the bubble radius R (spec
    §0.4.2): with R the tabulated 2.1 is reproduced. The defaults (R = 0.05 m,
    eta_0 = 5e-7 m, U = 1 m/s, Gamma_0 = 1.669e-7 mol/m^2) reproduce the values of
    Huang Table 3.2 (epsilon 1e-5, M 0.83, Re 5.6e4, Cr 2.1, g 0.49); the thesis does not state
    them (spec §1.2.11 [DERIVED]).
    """
    for name, v in (("R", R), ("eta0", eta0), ("U", U), ("Gamma0", Gamma0)):
        _check_positive(name, v)
    k = constants
    R, eta0, U, Gamma0 = (jnp.asarray(v, dtype=jnp.result_type(v, float)) for v in (R, eta0, U, Gamma0))
    return DimensionlessNumbers(
        epsilon=eta0 / R,
        M=Gamma0 * k.R_gas * k.T / (k.rho * eta0 * U * U),
        Re=U * R * k.rho / k.mu,
        Cr=k.rho_a * jnp.sqrt(k.nu_a * R) / (k.rho * eta0 * jnp.sqrt(U)),
        g=k.G * R / (U * U),
    )


def gamma0_for_marangoni(M, eta0=5e-7, U=1.0, constants: Constants = TABLE_3_1):
    """The surfactant concentration Gamma_0 (mol/m^2) giving Marangoni number ``M``.

    Inverse of M = Gamma_0 R_gas T / (rho eta_0 U^2) (Huang Table 3.2); M = 0.83 with the
    defaults gives 1.669e-7 mol/m^2 (spec SS-1).
    """
    _check_positive("M", M)
    _check_positive("eta0", eta0)
    _check_positive("U", U)
    k = constants
    return jnp.asarray(M) * k.rho * jnp.asarray(eta0) * jnp.asarray(U) ** 2 / (k.R_gas * k.T)


# --------------------------------------------------------------------------------------
# Equirectangular maps
# --------------------------------------------------------------------------------------


def _polar_angles(normal: Vec3):
    n = normalize(normal)
    theta = safe_acos(jnp.clip(n.z, -1.0, 1.0))
    phi = jnp.mod(safe_atan2(n.y, n.x), 2.0 * jnp.pi)
    return theta, phi


def latlong_thickness(values, normal: Vec3):
    """Bilinear lookup of an equirectangular map at unit normals.

    Args:
        values: ``(n_theta, n_phi, ...)`` samples (any trailing channel axes). Row i is
            cell-centred at theta = (i + 1/2) pi / n_theta from +z (the top), column j at
            phi = (j + 1/2) 2 pi / n_phi, phi = atan2(y, x) in [0, 2 pi).
        normal: points on the sphere (``Vec3`` of shape S; normalised here).

    Returns:
        ``S + values.shape[2:]``.

    phi wraps around; across a pole the neighbouring row is the first (last) row on the
    opposite meridian (phi + pi), so the lookup is continuous through the poles
    (cf. the pole crossing of Huang Fig. 3.8). Jittable, differentiable in ``values`` and
    (almost everywhere) in ``normal``.
    """
    v = jnp.asarray(values)
    if v.ndim < 2:
        raise ValueError(f"values: need shape (n_theta, n_phi, ...), got {v.shape}")
    return _latlong(v, normal)


@jax.jit
def _latlong(v, normal):
    n_t, n_p = v.shape[0], v.shape[1]
    theta, phi = _polar_angles(normal)
    ti = theta / jnp.pi * n_t - 0.5
    tp = phi / (2.0 * jnp.pi) * n_p - 0.5
    i0 = jnp.floor(ti)
    ft = ti - i0
    i0 = i0.astype(jnp.int32)
    extra = (None,) * (v.ndim - 2)

    def row(i):
        # rows outside [0, n_t - 1] continue across the pole on the opposite meridian
        over_top = i < 0
        over_bot = i > n_t - 1
        r = jnp.where(over_top, -1 - i, jnp.where(over_bot, 2 * n_t - 1 - i, i))
        r = jnp.clip(r, 0, n_t - 1)
        tpr = tp + jnp.where(over_top | over_bot, 0.5 * n_p, 0.0)
        j0f = jnp.floor(tpr)
        fp = tpr - j0f
        j0 = jnp.mod(j0f.astype(jnp.int32), n_p)
        j1 = jnp.mod(j0 + 1, n_p)
        fp = fp[(...,) + extra]
        return v[r, j0] * (1.0 - fp) + v[r, j1] * fp

    ft = ft[(...,) + extra]
    return row(i0) * (1.0 - ft) + row(i0 + 1) * ft


def latlong_grid(n_theta: int, n_phi: int):
    """Cell-centre angles (theta, phi), each ``(n_theta, n_phi)``, of :func:`latlong_thickness` maps."""
    t = (jnp.arange(n_theta) + 0.5) * jnp.pi / n_theta
    p = (jnp.arange(n_phi) + 0.5) * 2.0 * jnp.pi / n_phi
    return jnp.meshgrid(t, p, indexing="ij")


# --------------------------------------------------------------------------------------
# Field builders: callables normal -> full thickness (nm)
# --------------------------------------------------------------------------------------


def uniform_field(thickness_nm):
    """A film of constant **full** thickness ``thickness_nm`` (nm) everywhere."""
    _check_nonnegative("thickness_nm", thickness_nm, " nm")

    def field(normal: Vec3):
        return jnp.broadcast_to(jnp.asarray(thickness_nm, dtype=jnp.result_type(thickness_nm, float)),
                                normal.shape)

    return field


def equilibrium_field(g_over_M, eta0_nm=400.0, normalization: str = "printed", up=(0.0, 0.0, 1.0)):
    """The equilibrium film of Huang Eq. 3.36 as a field ``normal -> full thickness (nm)``.

    d(n) = 2 eta0_nm * eta(theta) / eta_0 with cos(theta) = n . up (theta from the top).

    Args:
        g_over_M: g / M of Huang Table 3.2 (see :func:`dimensionless_numbers`); may be traced.
        eta0_nm: mean **half** thickness eta_0 in nm (Huang Table 3.1: 400-1000 nm); the full
            thickness is twice it (the film is 2 eta thick, [T:502]).
        normalization: ``"printed"`` or ``"volume"`` (see :func:`equilibrium_thickness`).
        up: the world up direction (opposite to gravity), default +z.
    """
    if normalization not in NORMALIZATIONS:
        raise ValueError(f"normalization = {normalization!r}: must be one of {', '.join(NORMALIZATIONS)}")
    _check_finite("g_over_M", g_over_M)
    _check_nonnegative("eta0_nm", eta0_nm, " nm")
    upv = normalize(Vec3(*(jnp.asarray(u, dtype=float) for u in up)))

    def field(normal: Vec3):
        c = jnp.clip(dot(normalize(normal), upv), -1.0, 1.0)
        return 2.0 * jnp.asarray(eta0_nm) * equilibrium_thickness(safe_acos(c), g_over_M, normalization)

    return field


def latlong_field(values_nm):
    """A field ``normal -> full thickness (nm)`` from an equirectangular map (see :func:`latlong_thickness`)."""
    v = jnp.asarray(values_nm)
    if v.ndim != 2:
        raise ValueError(f"values_nm: need shape (n_theta, n_phi), got {v.shape}")
    _check_nonnegative("values_nm", values_nm, " nm")

    def field(normal: Vec3):
        return latlong_thickness(v, normal)

    return field


__all__ = [
    "NORMALIZATIONS",
    "equilibrium_thickness",
    "Constants",
    "TABLE_3_1",
    "DimensionlessNumbers",
    "dimensionless_numbers",
    "gamma0_for_marangoni",
    "latlong_thickness",
    "latlong_grid",
    "uniform_field",
    "equilibrium_field",
    "latlong_field",
]
