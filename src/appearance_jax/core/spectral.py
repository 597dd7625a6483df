"""Spectra and colour: wavelength grids, CIE 1931 XYZ, linear sRGB, the sRGB transfer curve.

Bands are a trailing axis everywhere: a spectrum is ``values[..., n_wavelengths]`` sampled at
``wavelengths_nm[n_wavelengths]``; colours are ``[..., 3]``. All functions are pure ``jnp`` and
jittable and differentiable (with respect to the spectral values and to the wavelengths).

Data: the CIE 1931 2-degree colour-matching functions (360-830 nm, 1 nm) and the CIE
illuminants D65 and A (300-780 nm, 5 nm) come from ``colour-science``
(``colour.MSDS_CMFS`` / ``colour.SDS_ILLUMINANTS``), loaded lazily on first use and linearly
interpolated to the requested wavelengths; outside their tables the CMFs are 0 and the
illuminants hold their end values (as colour-science extrapolates).

Integration over wavelength uses the cell widths of the sample grid (for a uniform grid
this is the rectangle rule, Delta-lambda * sum, i.e. colour-science's "Integration" method):

    emissive:     XYZ = sum_j S_j cmf_j w_j                 (units of S times nm)
    reflectance:  XYZ = sum_j R_j I_j cmf_j w_j / sum_j I_j ybar_j w_j
                  (CIE 15:2004 §7.1 with k = 1/sum I ybar: a perfect white reflector has Y = 1)

Linear sRGB (IEC 61966-2-1): primaries R (0.64, 0.33), G (0.30, 0.60), B (0.15, 0.06) and the
D65 white point (0.3127, 0.3290); the XYZ <-> RGB matrices are derived from them (exact
inverses of each other; the 4-digit matrices printed in the standard differ by < 1e-4), so
XYZ of the D65 white point maps to RGB (1, 1, 1). The transfer function (the "gamma"):

    srgb = 12.92 L                       for L <= 0.0031308
         = 1.055 L^(1/2.4) - 0.055       otherwise

RGB_WAVELENGTHS are the three wavelengths standing for R, G, B in the thin-film models of
Padrón Griffé 2025 ([T:526] of seed 000): (650, 510, 475) nm.
"""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np

from .arrays import namespace

RGB_WAVELENGTHS = (650.0, 510.0, 475.0)  # nm, [T:526] of seed 000 (snake-skin thin film)

# How a wavelength-dependent model (thin films) produces its output bands:
#   "rgb3":     3 bands R, G, B, one wavelength each (RGB_WAVELENGTHS; the thesis' cheap mode)
#   "cie":      3 bands of linear sRGB: the spectrum on CIE_GRID_NM integrated with the CIE 1931
#               colour-matching functions under D65 (a perfect reflector -> (1, 1, 1))
#   "spectral": one band per wavelength of the model's ``wavelengths`` field (nm)
COLOR_MODES = ("rgb3", "cie", "spectral")
CIE_GRID_NM = (380.0, 780.0, 5.0)  # start, stop, step: 5 nm as Huang 2022 [T:742] of seed 001

CMFS_NAME = "CIE 1931 2 Degree Standard Observer"

# sRGB primaries and white point (IEC 61966-2-1:1999), CIE xy chromaticities
SRGB_PRIMARIES_XY = ((0.64, 0.33), (0.30, 0.60), (0.15, 0.06))
SRGB_WHITE_XY = (0.3127, 0.3290)

_SRGB_THRESHOLD = 0.0031308  # linear value where the transfer curve switches branch
_SRGB_THRESHOLD_ENCODED = 0.04045  # the same point, encoded (12.92 * 0.0031308 ~ 0.04045)


def wavelength_grid(start: float = 360.0, stop: float = 830.0, step: float = 5.0) -> jnp.ndarray:
    """Uniform wavelengths in nm from ``start`` to ``stop`` inclusive (default: CIE 360-830 by 5)."""
    if step <= 0 or stop < start:
        raise ValueError(f"wavelength_grid: need step > 0 and stop >= start, got {start}, {stop}, {step}")
    n = int(np.floor((stop - start) / step + 1e-9)) + 1
    return jnp.asarray(start + step * np.arange(n), dtype=jnp.result_type(float))


def wavelengths_tuple(v) -> tuple:
    """Normalise a wavelength list (nm) to a tuple of floats; raise if not finite and > 0.

    The ``convert`` hook of the static ``wavelengths`` field of spectral models.
    """
    a = np.atleast_1d(np.asarray(v, dtype=float))
    if a.ndim != 1 or a.size == 0:
        raise ValueError("need a non-empty 1-D list of wavelengths in nm")
    if not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise ValueError("wavelengths must be finite and > 0 nm")
    return tuple(float(x) for x in a)


def band_wavelengths_np(color: str, wavelengths=RGB_WAVELENGTHS) -> np.ndarray:
    """The wavelengths (nm, float64 numpy) at which a model computes its spectrum for a colour mode.

    numpy, so that their number is known when parameters are validated (outside any trace).
    """
    if color == "rgb3":
        return np.asarray(RGB_WAVELENGTHS, dtype=float)
    if color == "cie":
        start, stop, step = CIE_GRID_NM
        return start + step * np.arange(int(round((stop - start) / step)) + 1)
    if color == "spectral":
        return np.asarray(wavelengths, dtype=float)
    raise ValueError(f"color = {color!r}: must be one of {', '.join(COLOR_MODES)}")


def band_wavelengths(color: str, wavelengths=RGB_WAVELENGTHS) -> jnp.ndarray:
    """:func:`band_wavelengths_np` as a jax array of the default float dtype."""
    return jnp.asarray(band_wavelengths_np(color, wavelengths), dtype=jnp.result_type(float))


def to_bands(values, color: str, wavelengths=RGB_WAVELENGTHS, illuminant: str = "D65") -> jnp.ndarray:
    """Output bands of a spectrum sampled at :func:`band_wavelengths` (trailing axis).

    "rgb3" and "spectral" return the samples as they are; "cie" returns linear sRGB of the
    reflectance-type spectrum under ``illuminant``, white-balanced so that a spectrum of 1
    maps to exactly (1, 1, 1) (:func:`cie_rgb_matrix`).
    """
    if color == "cie":
        v = jnp.asarray(values)
        return v @ jnp.asarray(cie_rgb_matrix(illuminant), dtype=v.dtype)
    band_wavelengths(color, wavelengths)  # validates the mode
    return values


@functools.lru_cache(maxsize=None)
def cie_rgb_matrix(illuminant: str = "D65") -> np.ndarray:
    """(n, 3) matrix: a reflectance spectrum on the CIE_GRID_NM grid -> white-balanced linear sRGB.

    Row j is :func:`spectrum_to_linear_srgb` of a unit reflectance at wavelength j alone;
    each column is then divided by its sum, so that a perfect reflector (1 everywhere) maps
    to exactly (1, 1, 1). Without that, the 5-nm D65 integration gives (1.00004, 1.00001,
    0.99973): the CIE D65 table's chromaticity (0.31272, 0.32903) is not exactly the rounded
    sRGB white point (0.3127, 0.3290). Computed in numpy (float64) once per illuminant, so
    it is a constant inside any trace.
    """
    wl_tab, cm = _cmfs_table()
    wl = np.arange(CIE_GRID_NM[0], CIE_GRID_NM[1] + 1e-9, CIE_GRID_NM[2])
    cmf = np.stack([np.interp(wl, wl_tab, cm[:, i], left=0.0, right=0.0) for i in range(3)], axis=-1)
    if illuminant == "E":
        ill = np.ones_like(wl)
    else:
        wl_i, v_i = _illuminant_table(illuminant)
        ill = np.interp(wl, wl_i, v_i)
    w = np.full_like(wl, CIE_GRID_NM[2])
    w[0] = w[-1] = CIE_GRID_NM[2]  # uniform grid: the rectangle rule (integration_weights)
    xyz = cmf * (ill * w)[:, None]  # (n, 3): XYZ of a unit reflectance at each wavelength
    rgb = xyz @ XYZ_TO_RGB.T
    return rgb / rgb.sum(axis=0, keepdims=True)


# --------------------------------------------------------------------------------------
# Tables (lazy: importing colour-science takes about a second)
# --------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=None)
def _cmfs_table():
    import colour

    cmfs = colour.MSDS_CMFS[CMFS_NAME]
    return np.asarray(cmfs.wavelengths, dtype=float), np.asarray(cmfs.values, dtype=float)


@functools.lru_cache(maxsize=None)
def _illuminant_table(name: str):
    import colour

    if name not in colour.SDS_ILLUMINANTS:
        raise ValueError(f"unknown illuminant {name!r}; use 'E', 'D65', 'A', ... "
                         "(a name of colour.SDS_ILLUMINANTS) or an array of values")
    sd = colour.SDS_ILLUMINANTS[name]
    return np.asarray(sd.wavelengths, dtype=float), np.asarray(sd.values, dtype=float)


def cmfs(wavelengths_nm) -> jnp.ndarray:
    """CIE 1931 2-degree colour-matching functions (xbar, ybar, zbar) at ``wavelengths_nm``.

    Shape ``wavelengths.shape + (3,)``; 0 outside 360-830 nm; linear interpolation of the
    1-nm table.
    """
    wl_tab, v = _cmfs_table()
    wl = jnp.asarray(wavelengths_nm, dtype=jnp.result_type(float))
    return jnp.stack([jnp.interp(wl, wl_tab, v[:, i], left=0.0, right=0.0) for i in range(3)], axis=-1)


def illuminant_spd(name: str, wavelengths_nm) -> jnp.ndarray:
    """Relative spectral power of a CIE illuminant ('E', 'D65', 'A', ...) at ``wavelengths_nm``.

    'E' is the equal-energy illuminant (1 everywhere); others come from colour-science
    (normalised there to 100 at 560 nm) and are linearly interpolated.
    """
    wl = jnp.asarray(wavelengths_nm, dtype=jnp.result_type(float))
    if name == "E":
        return jnp.ones_like(wl)
    wl_tab, v = _illuminant_table(name)
    return jnp.interp(wl, wl_tab, v)  # holds the end values outside the table


def integration_weights(wavelengths_nm) -> jnp.ndarray:
    """Cell widths (nm) of a sorted wavelength grid: the rectangle rule on uniform grids.

    w_0 = l_1 - l_0, w_j = (l_{j+1} - l_{j-1}) / 2 inside, w_last = l_last - l_{last-1};
    a single wavelength gets weight 1 (only ratios matter then).
    """
    wl = jnp.asarray(wavelengths_nm, dtype=jnp.result_type(float))
    if wl.shape[-1] == 1:
        return jnp.ones_like(wl)
    d = jnp.diff(wl, axis=-1)
    inner = 0.5 * (d[..., 1:] + d[..., :-1])
    return jnp.concatenate([d[..., :1], inner, d[..., -1:]], axis=-1)


def spectrum_to_xyz(values, wavelengths_nm, illuminant=None) -> jnp.ndarray:
    """CIE XYZ of a spectrum (trailing axis = wavelengths) -> ``[..., 3]``.

    ``illuminant=None``: ``values`` is an emitted spectral radiance; XYZ = sum S cmf w
    (no luminous efficacy factor: multiply by 683 lm/W for photometric units).
    ``illuminant`` given (a name, see :func:`illuminant_spd`, or an array of values at the same
    wavelengths): ``values`` is a reflectance (or transmittance) factor; XYZ is normalised
    so that a perfect white reflector (values = 1) has Y = 1.
    """
    wl = jnp.asarray(wavelengths_nm, dtype=jnp.result_type(float))
    v = jnp.asarray(values)
    if v.shape[-1:] != wl.shape[-1:]:
        raise ValueError(f"spectrum_to_xyz: values have {v.shape[-1:]} samples on the trailing axis "
                         f"but there are {wl.shape[-1]} wavelengths")
    w = integration_weights(wl)
    cmf = cmfs(wl)  # (n, 3)
    if illuminant is None:
        return jnp.einsum("...j,jc->...c", v, cmf * w[:, None])
    ill = illuminant_spd(illuminant, wl) if isinstance(illuminant, str) else jnp.asarray(illuminant)
    ill = jnp.broadcast_to(ill, wl.shape)
    weights = cmf * (ill * w)[:, None]  # (n, 3)
    return jnp.einsum("...j,jc->...c", v, weights) / jnp.sum(weights[:, 1])


def spectrum_to_linear_srgb(values, wavelengths_nm, illuminant=None) -> jnp.ndarray:
    """Linear sRGB of a spectrum: :func:`spectrum_to_xyz` followed by :func:`xyz_to_linear_srgb`."""
    return xyz_to_linear_srgb(spectrum_to_xyz(values, wavelengths_nm, illuminant))


# --------------------------------------------------------------------------------------
# XYZ <-> linear sRGB
# --------------------------------------------------------------------------------------


def _xy_to_xyz(x, y):
    return np.array([x / y, 1.0, (1.0 - x - y) / y])


def _rgb_to_xyz_matrix(primaries_xy, white_xy) -> np.ndarray:
    """RGB -> XYZ matrix whose columns are the primaries scaled so that RGB (1,1,1) -> white (Y = 1).

    The standard derivation (e.g. SMPTE RP 177-1993 §3.3).
    """
    P = np.stack([_xy_to_xyz(*p) for p in primaries_xy], axis=1)
    scale = np.linalg.solve(P, _xy_to_xyz(*white_xy))
    return P * scale[None, :]


RGB_TO_XYZ = _rgb_to_xyz_matrix(SRGB_PRIMARIES_XY, SRGB_WHITE_XY)
XYZ_TO_RGB = np.linalg.inv(RGB_TO_XYZ)
# Relative luminance of linear sRGB: the Y row of RGB_TO_XYZ from the sRGB primaries and the D65
# white (0.2126390, 0.7151687, 0.0721923; IEC 61966-2-1 rounds them to 0.2126, 0.7152, 0.0722).
# The one definition in the library: reports, the CLI and the hair samplers' lobe choice use it.
LUMINANCE_WEIGHTS = RGB_TO_XYZ[1].copy()


def xyz_to_linear_srgb(xyz) -> jnp.ndarray:
    """CIE XYZ (Y = 1 for the white) -> linear sRGB, trailing axis of 3. No clipping."""
    return jnp.einsum("...c,rc->...r", jnp.asarray(xyz), jnp.asarray(XYZ_TO_RGB, dtype=jnp.result_type(float)))


def linear_srgb_to_xyz(rgb) -> jnp.ndarray:
    """Linear sRGB -> CIE XYZ, trailing axis of 3."""
    return jnp.einsum("...c,rc->...r", jnp.asarray(rgb), jnp.asarray(RGB_TO_XYZ, dtype=jnp.result_type(float)))


def luminance(rgb) -> jnp.ndarray:
    """Relative luminance Y of linear sRGB values (trailing axis of 3 dropped)."""
    return jnp.asarray(rgb) @ jnp.asarray(LUMINANCE_WEIGHTS, dtype=jnp.result_type(float))


def luminance_or_mean(x) -> jnp.ndarray:
    """A band-valued quantity as one number: the relative luminance when it has 3 bands
    (linear sRGB), the band mean otherwise (e.g. spectral bands). Trailing axis dropped.

    Used where a sampler chooses among band-valued lobes by their weight (hair).
    """
    x = jnp.asarray(x)
    if x.shape[-1] == 3:
        return x @ jnp.asarray(LUMINANCE_WEIGHTS, dtype=x.dtype)
    return jnp.mean(x, axis=-1)


def linear_to_srgb(linear) -> jnp.ndarray:
    """The sRGB transfer function (encoding, IEC 61966-2-1), elementwise; no clipping; numpy for
    numpy input, jax.numpy for jax arrays.

    Values at or below 0.0031308 (negative ones included) use the linear segment; the
    power branch is evaluated on a clamped argument so its gradient stays finite at 0.
    """
    xp = namespace(linear)  # numpy in, numpy out (report figures): no XLA programs
    x = xp.asarray(linear)
    hi = x > _SRGB_THRESHOLD
    xs = xp.where(hi, x, _SRGB_THRESHOLD)
    return xp.where(hi, 1.055 * xs ** (1.0 / 2.4) - 0.055, 12.92 * x)


def srgb_to_linear(encoded) -> jnp.ndarray:
    """Inverse of :func:`linear_to_srgb` (decoding), elementwise; no clipping."""
    xp = namespace(encoded)
    v = xp.asarray(encoded)
    hi = v > _SRGB_THRESHOLD_ENCODED
    vs = xp.where(hi, v, _SRGB_THRESHOLD_ENCODED)
    return xp.where(hi, ((vs + 0.055) / 1.055) ** 2.4, v / 12.92)


__all__ = [
    "RGB_WAVELENGTHS",
    "wavelength_grid",
    "cmfs",
    "illuminant_spd",
    "integration_weights",
    "spectrum_to_xyz",
    "spectrum_to_linear_srgb",
    "xyz_to_linear_srgb",
    "linear_srgb_to_xyz",
    "luminance",
    "linear_to_srgb",
    "srgb_to_linear",
    "RGB_TO_XYZ",
    "XYZ_TO_RGB",
    "LUMINANCE_WEIGHTS",
    "luminance_or_mean",
]
