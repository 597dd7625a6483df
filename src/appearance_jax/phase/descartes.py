"""Geometric rainbow optics of a sphere (or circle): Descartes angles, Airy maxima, diffraction blur.

A ray enters a drop of relative index n at incidence angle i (impact parameter s = b/a = sin i,
refraction angle r with sin r = sin i / n), makes p chords inside (p - 1 internal reflections)
and leaves. Its total deviation is (Descartes; seed-002 spec §1.2.5, §1.2.8)

    D_0 = pi - 2 i                                   (p = 0: external reflection)
    D_p = 2 (i - r) + (p - 1) (pi - 2 r)             (p >= 1)

and its scattering angle is theta = arccos(cos D_p) in [0, pi]. For p >= 2, D_p has a minimum
(the rainbow ray) at cos^2 i_R = (n^2 - 1) / (p^2 - 1); the rays pile up at theta_R there:
p = 2 is the primary bow (137.63 deg for n = 1.331), p = 3 the secondary (129.63 deg).
Sadeghi 2011 quotes these angles (§3.2.1, L1057-1062) but derives them by ray tracing; the
formulas here are the standard ones ([EXT], e.g. Nussenzveig 1977, Adam 2002).

Airy theory (Airy 1838; spec §1.2.5) puts the intensity maxima near the bow at

    theta_k = theta_R +- z_k (D''_s / 2)^(1/3) (ka)^(-2/3)          (radians)

with z_k = -a'_k the negatives of the zeros of Ai' (:data:`AIRY_ZK`), ka = 2 pi a / lambda the
size parameter and D''_s = d^2 D / ds^2 at the rainbow ray. The sign puts the maxima on the
bright (illuminated) side: larger theta for the primary, smaller for the secondary. Against
Lorenz-Mie (a = 400 um, 650 nm, n = 1.331; miepython as the oracle in
tests/phase/test_descartes.py) the maxima beyond the first agree to 0.025 deg and the first
(the main bow) to 0.004 deg.

Sadeghi's diffraction approximation (§3.4.4, L1277-1292, Table 3.3) blurs the phase function
with a Gaussian of standard deviation sigma(a) (twice that on the secondary side, below
:func:`theta_split`; decision D-R5): :func:`diffraction_sigma`.

Conventions: angles in radians (inputs and outputs); n is the drop's index relative to the
surrounding medium; p counts chords. Everything is jittable and differentiable in n (and in
ka, radius); p may be a Python int or an integer array. Concrete inputs are checked eagerly
(a ``ValueError`` names the parameter, its value and the valid range); traced ones are not.

| function                   | returns                                       | valid input            |
|----------------------------|-----------------------------------------------|------------------------|
| rainbow_incidence(n, p)    | (i_R, s_R): incidence angle [rad], sin i_R    | 1 < n < p, p >= 2      |
| deviation(i, n, p)         | D_p(i) [rad], unwrapped                       | 0 <= i <= pi/2, n > 1, p >= 0 |
| rainbow_angle(n, p)        | theta_R [rad] in [0, pi]                      | 1 < n < p, p >= 2      |
| deviation_curvature(n, p)  | D''_s = d^2 D / ds^2 at the rainbow ray [rad] | 1 < n < p, p >= 2      |
| airy_maxima(n, p, ka, k)   | the first k Airy maxima [rad], trailing axis  | ka > 0, 1 <= k <= 10   |
| size_parameter(a_mm, wl)   | ka = 2 pi a / lambda                          | a > 0 mm, wl > 0 nm    |
| diffraction_sigma(a_mm)    | sigma(a) [rad] (Sadeghi Table 3.3)            | a > 0 mm               |
| theta_split(n)             | midpoint of the primary and secondary [rad]   | 1 < n < 2              |

Example::

    import numpy as np
    from appearance_jax.phase import descartes
    from appearance_jax.optics.water import water_ior
    n = water_ior(650.0)                                         # 1.331 (Table 3.2)
    np.degrees(descartes.rainbow_angle(n, 2))                    # 137.630
    np.degrees(descartes.rainbow_angle(n, 3))                    # 129.635
    x = descartes.size_parameter(0.4, 650.0)                     # a = 0.4 mm
    np.degrees(descartes.airy_maxima(n, 2, x, 5))                # 138.03, 138.92, 139.54, ...
    np.degrees(descartes.diffraction_sigma(0.4))                 # 0.25 (Table 3.3)
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..core.params import ParamSpec, check_value

#: Negatives of the first ten zeros a'_k of the derivative of the Airy function Ai
#: (Abramowitz & Stegun Table 10.13): the Airy maxima sit at z = z_k.
AIRY_ZK = (1.0187929716474715, 3.2481975821798375, 4.820099211178738, 6.163307355639325,
           7.372177255049634, 8.488486734019721, 9.535449052433547, 10.527660396957407,
           11.475056633480245, 12.384788371845747)

#: Sadeghi 2011 Table 3.3: drop radius (mm) ...
SIGMA_TABLE_RADIUS_MM = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
#: ... and the standard deviation (degrees) of the Gaussian diffraction filter.
SIGMA_TABLE_DEG = (0.70, 0.45, 0.30, 0.25, 0.22, 0.20, 0.18, 0.17, 0.16, 0.15)
#: sigma = SIGMA_LAW_DEG * (a / 1 mm)^(-2/3): the Airy scaling fitted to Table 3.3 (within 8 %;
#: spec §1.2.4 (i), check C10).
SIGMA_LAW_DEG = 0.144

_N_SPEC = ParamSpec(1.0, math.inf, lo_open=True, doc="relative refractive index of the drop")
_KA_SPEC = ParamSpec(0.0, math.inf, lo_open=True, doc="size parameter 2 pi a / lambda")
_RADIUS_SPEC = ParamSpec(0.0, math.inf, lo_open=True, unit="mm", doc="drop radius")
_WL_SPEC = ParamSpec(0.0, math.inf, lo_open=True, unit="nm", doc="wavelength")
_I_SPEC = ParamSpec(0.0, math.pi / 2, unit="rad", doc="incidence angle")


def _concrete(x):
    """``x`` as a numpy array, or None if it is traced (checks then do not apply)."""
    if isinstance(x, jax.core.Tracer):
        return None
    return np.asarray(x)


def _check_p(label: str, p, lo: int):
    a = _concrete(p)
    if a is None:
        return
    bad = ~np.isfinite(a) | (a != np.round(a)) | (a < lo)
    if np.any(bad):
        first = a[bad].flat[0] if a.ndim else a
        raise ValueError(f"{label} = {float(first):g} is not a valid number of chords: expected an "
                         f"integer >= {lo} (2 = primary bow, 3 = secondary bow)")


def _check_rainbow(label: str, n, p):
    """1 < n < p: a rainbow ray of p chords exists (cos^2 i_R <= 1) only for n < p."""
    _check_p(f"{label}: p", p, 2)
    check_value(f"{label}: n", n, _N_SPEC)
    a, q = _concrete(n), _concrete(p)
    if a is None or q is None:
        return
    a, q = np.broadcast_arrays(a, q)
    bad = a >= q
    if np.any(bad):
        raise ValueError(f"{label}: n = {float(a[bad].flat[0]):g} is outside the valid range "
                         f"(1, {float(q[bad].flat[0]):g}) for p = {int(q[bad].flat[0])}: a rainbow "
                         f"of p chords needs 1 < n < p")


def _f(x):
    return jnp.asarray(x, dtype=jnp.result_type(float))


@jax.jit
def _rainbow_ray(n, p):
    """(i_R, s_R, r_R, D_R) of the rainbow ray, from closed forms that stay accurate near n -> 1."""
    p2 = p * p
    c = jnp.sqrt((n * n - 1.0) / (p2 - 1.0))        # cos i_R
    s = jnp.sqrt((p2 - n * n) / (p2 - 1.0))         # sin i_R, without the cancellation of 1 - c^2
    i = jnp.arctan2(s, c)
    r = jnp.arctan2(s, p * c)                      # n cos r_R = p cos i_R (dr/di = 1/p there)
    d = 2.0 * (i - r) + (p - 1.0) * (jnp.pi - 2.0 * r)
    return i, s, r, d


def _scattering_angle(d):
    """arccos(cos D) in [0, pi], with exact derivatives (+-1) where sin D != 0."""
    return jnp.abs(jnp.arctan2(jnp.sin(d), jnp.cos(d)))


def rainbow_incidence(n, p=2):
    """Incidence angle i_R [rad] and impact parameter s_R = sin i_R of the rainbow ray.

    cos^2 i_R = (n^2 - 1) / (p^2 - 1) (the minimum of the deviation D_p; spec §1.2.8).
    ``n``: relative index, 1 < n < p; ``p``: number of chords (2 primary, 3 secondary).
    Arrays broadcast. Example: ``rainbow_incidence(1.331, 2)`` -> (1.03894 rad, 0.86187).
    """
    _check_rainbow("rainbow_incidence", n, p)
    i, s, _, _ = _rainbow_ray(_f(n), _f(p))
    return i, s


@jax.jit
def _deviation(i, n, p):
    sin_r = jnp.sin(i) / n
    r = jnp.arctan2(sin_r, jnp.sqrt(1.0 - sin_r * sin_r))
    return jnp.where(p == 0, jnp.pi - 2.0 * i, 2.0 * (i - r) + (p - 1.0) * (jnp.pi - 2.0 * r))


def deviation(i, n, p):
    """Total deviation D_p(i) [rad] of a ray of p chords at incidence angle ``i`` [rad].

    D_0 = pi - 2 i; D_p = 2 (i - r) + (p - 1)(pi - 2 r) for p >= 1, sin r = sin i / n (spec
    §1.2.5). Not wrapped: the scattering angle is arccos(cos D_p). ``i`` in [0, pi/2],
    ``n`` > 1, ``p`` an integer >= 0; arrays broadcast.
    """
    check_value("deviation: i", i, _I_SPEC)
    check_value("deviation: n", n, _N_SPEC)
    _check_p("deviation: p", p, 0)
    return _deviation(_f(i), _f(n), _f(p))


def rainbow_angle(n, p=2):
    """Geometric (Descartes) rainbow angle theta_R = arccos(cos D_p(i_R)) [rad], in [0, pi].

    The scattering angle measured from the forward direction (180 deg = back to the source):
    137.630 deg (primary) and 129.635 deg (secondary) for n = 1.331 (Sadeghi Table 3.2 at
    650 nm; spec §1.2.8, check C2). ``n``: 1 < n < p; ``p``: chords (2, 3, ...).
    """
    _check_rainbow("rainbow_angle", n, p)
    return _scattering_angle(_rainbow_ray(_f(n), _f(p))[3])


@jax.jit
def _curvature(n, p):
    _, s, _, _ = _rainbow_ray(n, p)
    c2 = (n * n - 1.0) / (p * p - 1.0)
    # Spec §1.2.5: D''_s = D''_i / cos^2 i_R, D''_i = 2p (sin i_R - cos i_R tan r_R / p) / (n cos r_R).
    # With n cos r_R = p cos i_R and tan r_R = s_R / (p cos i_R) this is the form below.
    return 2.0 * s * (1.0 - 1.0 / (p * p)) / (c2 * jnp.sqrt(c2))


def deviation_curvature(n, p=2):
    """D''_s = d^2 D_p / ds^2 at the rainbow ray (s = sin i, the impact parameter in radii).

    Closed form (spec §1.2.5): D''_s = D''_i / cos^2 i_R with
    D''_i = 2p (sin i_R - cos i_R tan r_R / p) / (n cos r_R), which simplifies to
    D''_s = 2 s_R (1 - 1/p^2) / cos^3 i_R. Positive (D_p has a minimum). For n = 1.331:
    9.912 (primary) and 56.42 (secondary). ``n``: 1 < n < p; ``p``: chords.
    """
    _check_rainbow("deviation_curvature", n, p)
    return _curvature(_f(n), _f(p))


@jax.jit
def _airy_maxima(n, p, ka, z):
    d = _rainbow_ray(n, p)[3]
    theta = _scattering_angle(d)
    # The bright side is D > D_R (a minimum); theta = |wrap(D)| moves with D where sin D > 0
    # (primary) and against it where sin D < 0 (secondary).
    side = jnp.sign(jnp.sin(d))
    step = jnp.cbrt(_curvature(n, p) / 2.0) * ka ** (-2.0 / 3.0)
    return theta[..., None] + (side * step)[..., None] * z


def airy_maxima(n, p, ka, count=5):
    """The first ``count`` Airy intensity maxima theta_k [rad] near the rainbow angle.

    theta_k = theta_R +- z_k (D''_s / 2)^(1/3) (ka)^(-2/3) (spec §1.2.5), + for the primary
    (maxima above theta_R), - for the secondary (below). k = 1 is the main bow, k >= 2 the
    supernumeraries. Returns shape ``broadcast(n, p, ka) + (count,)``.

    | parameter | range       | unit | meaning                                  |
    |-----------|-------------|------|------------------------------------------|
    | n         | (1, p)      | 1    | relative index of the drop               |
    | p         | 2, 3, ...   | 1    | chords (2 primary, 3 secondary)          |
    | ka        | (0, inf)    | 1    | size parameter 2 pi a / lambda           |
    | count     | 1 ... 10    | 1    | number of maxima (static)                |

    Airy theory is the large-ka limit: for water drops of a >= 0.1 mm in visible light the
    supernumeraries agree with Lorenz-Mie to a few hundredths of a degree (check C7).
    Example: ``np.degrees(airy_maxima(1.331, 2, size_parameter(0.4, 650.0), 3))`` ->
    [138.03, 138.92, 139.54].
    """
    _check_rainbow("airy_maxima", n, p)
    check_value("airy_maxima: ka", ka, _KA_SPEC)
    if not isinstance(count, (int, np.integer)) or isinstance(count, bool) or not 1 <= count <= len(AIRY_ZK):
        raise ValueError(f"airy_maxima: count = {count!r} is outside the valid range "
                         f"[1, {len(AIRY_ZK)}] (an integer: the tabulated zeros of Ai')")
    z = jnp.asarray(AIRY_ZK[:count], dtype=jnp.result_type(float))
    return _airy_maxima(_f(n), _f(p), _f(ka), z)


def size_parameter(radius_mm, wavelength_nm):
    """Size parameter ka = 2 pi a / lambda of a drop of radius ``radius_mm`` (mm) at ``wavelength_nm`` (nm).

    Both positive; arrays broadcast. Example: ``size_parameter(0.4, 650.0)`` -> 3866.6.
    """
    check_value("size_parameter: radius_mm", radius_mm, _RADIUS_SPEC)
    check_value("size_parameter: wavelength_nm", wavelength_nm, _WL_SPEC)
    return 2e6 * jnp.pi * _f(radius_mm) / _f(wavelength_nm)


@jax.jit
def _sigma_deg(a, continuous):
    ra = jnp.asarray(SIGMA_TABLE_RADIUS_MM, dtype=a.dtype)
    sd = jnp.asarray(SIGMA_TABLE_DEG, dtype=a.dtype)
    law = a ** (-2.0 / 3.0)
    below = jnp.where(continuous, sd[0] * (a / ra[0]) ** (-2.0 / 3.0), SIGMA_LAW_DEG * law)
    above = jnp.where(continuous, sd[-1] * (a / ra[-1]) ** (-2.0 / 3.0), SIGMA_LAW_DEG * law)
    inside = jnp.interp(a, ra, sd)
    return jnp.where(a < ra[0], below, jnp.where(a > ra[-1], above, inside))


def diffraction_sigma(radius_mm, extrapolation: str = "law"):
    """Standard deviation [rad] of Sadeghi's Gaussian diffraction filter for drops of radius ``radius_mm``.

    Sadeghi 2011 Table 3.3 (0.1-1.0 mm, sigma in degrees, fitted by hand to Lorenz-Mie),
    interpolated linearly inside the table. Outside it sigma follows the Airy scaling
    a^(-2/3) (the size of the Airy pattern, :func:`airy_maxima`; spec §1.2.4 (i)):

    - ``extrapolation="law"`` (default, as issue 23 and spec §1.2.4 (i) word it): sigma =
      0.144 deg (a / 1 mm)^(-2/3), the law fitted to the whole table (within 8 %, check C10).
      It jumps by 4-5 % at the table's ends (0.668 vs 0.70 deg at 0.1 mm, 0.144 vs 0.15 deg at
      1 mm), where sigma then *grows* with the radius;
    - ``extrapolation="continuous"``: the a^(-2/3) law through the nearest end row,
      sigma(0.1 mm) (a / 0.1 mm)^(-2/3) below the table and sigma(1 mm) (a / 1 mm)^(-2/3)
      above it, so sigma(a) is continuous and decreasing (for fits of the radius that may
      cross the table's ends).

    The two differ by < 5 %, e.g. 3.25 vs 3.10 deg for a fog drop of 10 um. The thesis doubles
    sigma on the secondary bow's side (below :func:`theta_split`). ``radius_mm`` > 0, any shape.
    Example: ``np.degrees(diffraction_sigma(0.4))`` -> 0.25.
    """
    check_value("diffraction_sigma: radius_mm", radius_mm, _RADIUS_SPEC)
    if extrapolation not in ("law", "continuous"):
        raise ValueError(f"diffraction_sigma: extrapolation = {extrapolation!r} is unknown; "
                         f"choose 'continuous' or 'law'")
    return jnp.deg2rad(_sigma_deg(_f(radius_mm), extrapolation == "continuous"))


def theta_split(n):
    """Midpoint [rad] of the primary and secondary rainbow angles at index ``n`` (1 < n < 2).

    Sadeghi's diffraction filter uses sigma above this angle and 2 sigma below it (decision
    D-R5, spec §1.2.4 (i)): 133.63 deg for n = 1.331 (650 nm).
    """
    _check_rainbow("theta_split", n, 2)
    n = _f(n)
    return 0.5 * (_scattering_angle(_rainbow_ray(n, 2.0)[3]) + _scattering_angle(_rainbow_ray(n, 3.0)[3]))


__all__ = [
    "AIRY_ZK",
    "SIGMA_TABLE_RADIUS_MM",
    "SIGMA_TABLE_DEG",
    "SIGMA_LAW_DEG",
    "rainbow_incidence",
    "deviation",
    "rainbow_angle",
    "deviation_curvature",
    "airy_maxima",
    "size_parameter",
    "diffraction_sigma",
    "theta_split",
]
