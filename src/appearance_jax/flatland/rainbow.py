"""Rainbow phase functions of water drops: wave-optics ray tracing per wavelength, Sadeghi's
diffraction blur, polarisation and colour (Sadeghi 2011 Ch. 3, §3.4, L1168–1298; spec
seed-002 §1.2.4–§1.2.9, §4).

For each wavelength (default the 33 of Table 3.2, 380–700 nm, decision D-R2) a fan of rays is
traced through the drop's section (:func:`~appearance_jax.flatland.drop.trace_drop`), carrying
complex Fresnel amplitudes, optical paths and focal counts, and collected coherently in the
far field (:func:`appearance_jax.flatland.far_field`, the verified phase recipe of spec §1.2.5:
interference gives the supernumerary bows). The axisymmetric lift turns the 2-D section into
the 3-D drop, so for a sphere the result approximates Lorenz–Mie
(:mod:`appearance_jax.phase.mie`) away from the
forward peak; diffraction, which geometric optics lacks, is approximated by Sadeghi's
Gaussian blur (Table 3.3; σ above ``theta_split``, 2σ below it on the secondary side,
decision D-R5, blended over ±σ around the split).

It lives in ``flatland`` (not ``phase``) because it is built on the drop tracer, which sits in a
layer above the phase functions (docs/architecture.md).

Output units: ``(1 / pi a^2) dσ/dΩ`` per polarisation (⊥ and ∥ to the scattering plane), the
Mie equivalents being ``|S1|^2 / (pi x^2)`` and ``|S2|^2 / (pi x^2)``; ``a`` is the drop's
equal-volume radius. Only the orders in ``families`` are represented (default p = 0, 2, 3:
reflection and the two bows; the forward p = 1 and the diffraction peak are absent), so this
is a phase function of the rainbow region, not normalised over the sphere.

Non-spherical drops (Beard–Chuang, Sadeghi Eq. 3.1, Table 3.1; a > 0.4 mm) scatter
differently at the top, bottom and sides of the bow:

- ``view="top"`` / ``"bottom"``: the vertical meridian, rays that leave downwards (they
  reach an observer from the top of the bow) or upwards; each half of the meridian fan is
  lifted as if the drop were a body of revolution about the incident direction (exact for a
  sphere, an approximation otherwise: the bow positions are the validated content, spec
  C15). ``inclination`` is the sun's elevation (rad) in the meridian plane;
- ``view="side"``: the horizontal section through the equator, a circle of the drop's
  equatorial radius (the sides of the bow; spec §4 item 6 (c)); only for ``inclination = 0``
  (with the sun inclined that section is not a circle: out of flatland's scope).

| argument         | default            | unit | meaning                                              |
|------------------|--------------------|------|------------------------------------------------------|
| radius_mm        | —                  | mm   | equal-volume drop radius (> 0; Beard–Chuang up to 3)  |
| wavelengths_nm   | 380, 390, ..., 700 | nm   | wavelengths (380–700 for the water table)            |
| theta            | 120°–150°, 0.01°   | rad  | scattering angles of the output grid (sorted)        |
| shape            | "auto"             |      | "sphere", "beard_chuang"; auto: sphere for a <= 0.4  |
| view             | "top"              |      | "top", "bottom", "side" (ignored for spheres)        |
| inclination      | 0                  | rad  | sun elevation (non-spherical drops)                  |
| orientation      | "down"             |      | Beard–Chuang θ = 0 pole: "down" (D-R6) or "up"        |
| index            | "table"            |      | water index model (optics.water: table, cauchy3, ...)|
| families         | (0, 2, 3)          |      | path orders p included                               |
| n_rays           | 60 x (ka), clipped |      | rays in the fan (2e4 – 4e5)                          |
| blur             | True               |      | Sadeghi's diffraction blur (Table 3.3)               |
| focal_phase      | "maslov"           |      | "maslov" (D-R3) or "thesis" (literal +π/2, anti-phased)|

Example::

    import jax; jax.config.update("jax_enable_x64", True)
    import numpy as np
    from appearance_jax.flatland import rainbow
    t = rainbow.drop_phase_function(0.3)               # 33 wavelengths, sphere, blurred
    rgb = rainbow.to_srgb(t)                           # (angles, 3) linear sRGB under D65
    i = rainbow.intensity(t, filter_angle=0.0)         # sunlight behind a polariser along ⊥
    # a registered phase function of the whole drop (p = 0..3) for rendering:
    full = rainbow.drop_phase_function(0.3, theta=rainbow.full_theta(), families=(0, 1, 2, 3))
    p = rainbow.tabulated_params(full)                 # phase.tabulated.Params, 33 bands
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..core import spectral
from ..optics import water
from ..phase import descartes
from . import farfield, polar_curve as pcv
from .drop import trace_drop
from .fan import Fan

SHAPES = ("auto", "sphere", "beard_chuang")
VIEWS = ("top", "bottom", "side")
SPHERE_LIMIT_MM = 0.4  # Table 3.1: drops up to 0.4 mm are spheres


class RainbowTable(NamedTuple):
    """A tabulated drop phase function: rows = wavelengths, columns = scattering angles.

    ``perp``, ``par``: (1/pi a^2) dσ/dΩ for incident light polarised ⊥ / ∥ to the scattering
    plane (Mie's |S1|²/(pi x²), |S2|²/(pi x²)); unpolarised light gets their mean
    (:func:`intensity`). ``cross``: E⊥ E∥* for incident light polarised at 45° to the plane
    (complex; zero for ``mode="incoherent"``), for Jones/Stokes work with polarised sources.
    """

    theta: np.ndarray            # (G,) rad
    wavelength_nm: np.ndarray    # (L,)
    perp: np.ndarray             # (L, G)
    par: np.ndarray              # (L, G)
    cross: np.ndarray            # (L, G) complex
    radius_mm: float


def default_theta():
    """120°–150° in 0.01° steps (radians): both bows, Alexander's band and the supernumeraries."""
    return np.radians(np.arange(120.0, 150.0 + 1e-9, 0.01))


def _mirror(fan: Fan) -> Fan:
    """The fan reflected about the incident axis (s -> -s, psi -> -psi), re-sorted."""
    return Fan(-fan.s[::-1], -fan.psi[:, ::-1], fan.amp[:, ::-1], fan.opl[:, ::-1], fan.foci[:, ::-1],
               fan.axis[:, ::-1], fan.valid[:, ::-1])


def _leaving(fan: Fan, inclination, downward: bool) -> Fan:
    """Only the rays that leave downwards (or upwards) in the meridian plane."""
    # outgoing direction in the (x, z) frame: the propagation (cos a, -sin a) turned by psi
    z = jnp.sin(fan.psi - inclination)
    keep = (z < 0) if downward else (z > 0)
    return fan._replace(valid=fan.valid & keep)


def _blur_matrix(theta, sigma):
    d = theta[:, None] - theta[None, :]
    w = np.exp(-0.5 * (d / sigma) ** 2)
    return w / w.sum(axis=1, keepdims=True)


def blur(values, theta, radius_mm, n, *, extrapolation="law"):
    """Sadeghi's diffraction blur (§3.4.4, Table 3.3) of ``values`` (L, G) on the angle grid
    ``theta`` (G,) (rad), row l at index ``n[l]``: a Gaussian of σ(a) for output angles above
    ``theta_split(n)``, 2σ below (decision D-R5). The two results are blended with weight
    ``(1 + tanh((θ - θ_split)/σ))/2`` instead of switched: a hard switch leaves a step at
    θ_split that is invisible for rain (the dark band) but shows for fog drops, whose σ is
    several degrees. Kernels are renormalised on the grid, so let the grid extend ~6σ beyond
    the angles you use."""
    theta = np.asarray(theta, float)
    v = np.atleast_2d(np.asarray(values))
    sigma = float(descartes.diffraction_sigma(radius_mm, extrapolation))
    split = np.asarray(descartes.theta_split(np.atleast_1d(np.asarray(n, float))))[:, None]
    k1, k2 = _blur_matrix(theta, sigma), _blur_matrix(theta, 2.0 * sigma)
    w = 0.5 * (1.0 + np.tanh((theta[None, :] - split) / sigma))
    return w * (v @ k1.T) + (1.0 - w) * (v @ k2.T)


def _check(radius_mm, shape, view, inclination, families, index):
    r = float(radius_mm)
    if not (math.isfinite(r) and r > 0):
        raise ValueError(f"rainbow: radius_mm = {radius_mm!r}; valid range (0, 3] mm")
    if shape not in SHAPES:
        raise ValueError(f"rainbow: shape = {shape!r}; valid: {', '.join(SHAPES)}")
    if view not in VIEWS:
        raise ValueError(f"rainbow: view = {view!r}; valid: {', '.join(VIEWS)}")
    if index not in water.MODELS:
        raise ValueError(f"rainbow: index = {index!r}; valid: {', '.join(water.MODELS)}")
    fam = tuple(int(p) for p in families)
    if not fam or min(fam) < 0:
        raise ValueError(f"rainbow: families = {families!r} must be path orders p >= 0")
    if not (math.isfinite(float(inclination)) and abs(float(inclination)) < math.pi / 2):
        raise ValueError(f"rainbow: inclination = {inclination!r} rad; valid range (-pi/2, pi/2)")
    return fam


def equatorial_radius(radius_mm) -> float:
    """Half-width of the Beard–Chuang drop at its widest (units of the equal-volume radius)."""
    curve = pcv.beard_chuang(radius_mm)
    th = np.linspace(0.0, np.pi, 20001)
    return float(np.max(np.asarray(pcv.radius(curve, jnp.asarray(th))) * np.sin(th)))


def drop_phase_function(radius_mm, *, wavelengths_nm=None, theta=None, shape="auto", view="top",
                        inclination=0.0, orientation="down", index="table", families=(0, 2, 3),
                        n_rays=None, blur_diffraction=True, mode="coherent", focal_phase="maslov",
                        ) -> RainbowTable:
    """The per-wavelength phase function of one drop (see the module docstring).

    Returns a :class:`RainbowTable` (numpy). Float64 (``jax_enable_x64``) is needed for the
    coherent mode (phases k a L reach 1e4 rad). Cost: one trace and one collection per
    wavelength (about a second each for a 0.4 mm drop on 2 CPU cores).
    """
    fam = _check(radius_mm, shape, view, inclination, families, index)
    if not jax.config.jax_enable_x64 and mode == "coherent":
        raise ValueError("rainbow: mode='coherent' needs float64: jax.config.update('jax_enable_x64', True)")
    wl = water.WAVELENGTHS_NM if wavelengths_nm is None else np.atleast_1d(np.asarray(wavelengths_nm, float))
    theta = default_theta() if theta is None else np.asarray(theta, float)
    if theta.ndim != 1 or np.any(np.diff(theta) <= 0) or theta[0] < 0 or theta[-1] > np.pi:
        raise ValueError("rainbow: theta must be 1-D, strictly increasing, within [0, pi] rad")
    a = float(radius_mm)
    if shape == "auto":
        shape = "sphere" if a <= SPHERE_LIMIT_MM else "beard_chuang"
    spherical = shape == "sphere" or (a <= SPHERE_LIMIT_MM)
    if not spherical and view == "side" and float(inclination) != 0.0:
        raise ValueError("rainbow: view='side' of a non-spherical drop needs inclination = 0 (the "
                         "horizontal section is a circle only then)")
    section_scale = 1.0
    if spherical or view == "side":
        curve = pcv.circle_curve()
        if not spherical:
            section_scale = equatorial_radius(a)
    else:
        curve = pcv.beard_chuang(a, orientation)
    F = max(fam) + 1
    ka_max = 2.0 * np.pi * a * 1e6 * section_scale / float(np.min(wl))
    n_rays = int(np.clip(60.0 * ka_max, 2e4, 4e5)) if n_rays is None else int(n_rays)
    eta = np.asarray(water.water_ior(wl, index), float)
    circle_lift = spherical or view == "side"
    if circle_lift:
        # the sphere lift uses s >= 0 only: trace that half
        s = (np.arange(n_rays) + 0.5) / n_rays
    perp, par, cross = [], [], []
    for lam, n in zip(wl, eta):
        x = 2.0 * np.pi * a * 1e6 * section_scale / lam
        if circle_lift:
            fans = [trace_drop(curve, n, s=jnp.asarray(s), families=F)]
        else:
            fan = trace_drop(curve, n, inclination=float(inclination), n_rays=n_rays, families=F)
            half = _leaving(fan, float(inclination), downward=(view == "top"))
            fans = [half, _mirror(half)]
        # the two halves of a meridian fan leave in opposite half-planes: they add as intensities
        I = np.zeros(theta.shape + (2,))
        c = np.zeros(theta.shape, complex)
        for f in fans:
            if mode == "coherent":
                E = np.asarray(farfield.far_field_amplitude(f, theta, x, lift="sphere", focal_phase=focal_phase,
                                                            families=fam))
                I = I + np.abs(E) ** 2
                c = c + E[..., 0] * np.conj(E[..., 1])
            else:
                I = I + np.asarray(farfield.far_field(f, theta, lift="sphere", mode="incoherent", families=fam))
        perp.append(I[..., 0])
        par.append(I[..., 1])
        cross.append(c)
    scale = section_scale ** 2  # cross-section of the equatorial circle in units of pi a^2
    perp, par, cross = (np.array(v) * scale for v in (perp, par, cross))
    if blur_diffraction:
        perp, par = blur(perp, theta, a, eta), blur(par, theta, a, eta)
        cross = blur(cross.real, theta, a, eta) + 1j * blur(cross.imag, theta, a, eta)
    return RainbowTable(theta, wl, perp, par, cross, a)


def intensity(table: RainbowTable, filter_angle=None):
    """Scattered intensity (L, G) for unpolarised incident light (sunlight), in the table's
    units: ``(I⊥ + I∥) / 2`` with no polariser, ``(I⊥ cos²χ + I∥ sin²χ) / 2`` behind a
    linear polariser whose axis makes ``filter_angle`` = χ (rad) with the normal of the
    scattering plane (0 passes ⊥, pi/2 passes ∥). For unpolarised incident light the two
    scattered components are incoherent (a sphere does not mix them), so ``cross`` does not
    enter; a circular analyser passes half of the unpolarised intensity."""
    if filter_angle is None:
        return 0.5 * (table.perp + table.par)
    c, s = math.cos(filter_angle), math.sin(filter_angle)
    return 0.5 * (table.perp * c * c + table.par * s * s)


def to_srgb(table: RainbowTable, filter_angle=None, illuminant="D65"):
    """Linear sRGB (G, 3) of the bow under ``illuminant`` (a CIE name or an array over the
    table's wavelengths, e.g. D65 reddened by Rayleigh extinction for a sunset bow), normalised
    so that a flat spectrum of 1 is white with Y = 1."""
    spec = intensity(table, filter_angle).T  # (G, L)
    return np.asarray(spectral.spectrum_to_linear_srgb(jnp.asarray(spec), jnp.asarray(table.wavelength_nm),
                                                       illuminant))


def full_theta(n_angles: int = 3601):
    """``n_angles`` equally spaced scattering angles over [0, pi] (rad): the grid of
    :mod:`appearance_jax.phase.tabulated`."""
    return np.linspace(0.0, np.pi, int(n_angles))


def tabulated_params(table: RainbowTable, filter_angle=None):
    """The table as :class:`appearance_jax.phase.tabulated.Params` (one band per wavelength),
    a registered phase function (``eval``/``sample``/``pdf``, normalised over the sphere).
    ``table`` must be computed on :func:`full_theta`; include p = 1 (``families=(0, 1, 2,
    3)``) for a phase function of the whole drop (the forward diffraction peak stays absent)."""
    from ..phase import tabulated

    G = table.theta.shape[0]
    if G < 2 or not np.allclose(table.theta, full_theta(G), atol=1e-12):
        raise ValueError("rainbow.tabulated_params: the table must be computed on full_theta(n) "
                         "(equally spaced angles over [0, pi])")
    return tabulated.Params(values=np.clip(intensity(table, filter_angle), 0.0, None).T)


def peak(table: RainbowTable, lo_deg, hi_deg, row=0):
    """Angle (rad) of the maximum of the unpolarised intensity of one row within [lo, hi] degrees."""
    i = intensity(table)[row]
    sel = (table.theta >= np.radians(lo_deg)) & (table.theta <= np.radians(hi_deg))
    return float(table.theta[sel][np.argmax(i[sel])])
