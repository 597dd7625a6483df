"""Thin-film shading of a spherical soap bubble (Huang 2022 Sec. 3.5, Eqs. 3.27-3.32, seed 001).

A view ray hits the bubble (the unit sphere) at the point with outward normal n^(0). Part
of the light is reflected there (path 0); the rest is transmitted undeviated (parallel
film interfaces, [T:749]) and bounces inside the sphere along chords. Path k >= 1 is the
light that entered the film at interaction 0, was reflected at interactions 1 .. k-1 and
leaves through interaction k ([T:766-772], Huang Fig. 3.11):

    weight^(0) = R^(0),     weight^(k) = T^(0) (prod_{i=1}^{k-1} R^(i)) T^(k)      (Huang Eq. 3.29)

R^(i), T^(i) are the Airy reflectance and transmittance of the free-standing film (air |
soap | air, Huang Eqs. 3.27/3.28, computed by :func:`appearance_jax.optics.thinfilm.airy`) at the
local film thickness of interaction i. They differ only through the thickness: every
chord of a sphere meets the surface at the same angle at both ends, so all interactions
of a path have the same incidence cosine ("all angles marked in red are equal", Huang Fig. 3.11).

Polarisation ([T:774]): all interactions of a path lie in one plane (the plane through
the sphere's centre spanned by n^(0) and the view direction), so the s/p basis never
rotates: Huang Eq. 3.29 is evaluated for s and p separately and the two weights are averaged
(which differs from multiplying unpolarised R and T).

Direction conventions (Huang Eq. 3.30, [T:776-782])
---------------------------------------------
Directions point away from the surface (DESIGN.md), the bubble is the unit sphere centred
at the origin, and the point of interaction i is p_i = n^(i).

* ``o^(0) = view``: the unit direction from the bubble towards the observer, the
  library's omega_o. This is the only choice for which the recursion's
  i^(1) = -o^(0) is the direction in which the *transmitted* path 1 sees the environment
  (straight through the bubble, -view), as Huang Fig. 3.11 requires.
* ``o^(i)`` (the thesis' "(virtual) viewing direction") is the unit vector along the
  chord from p_{i+1} to p_i: the camera ray traced backwards travels along -o^(i) from p_i
  to p_{i+1}. It points to the outside of the film at p_i: n^(i) . o^(i) = cos(theta) > 0
  for every i, and n^(i+1) . o^(i) = -cos(theta).
* ``n^(i+1) = n^(i) - 2 (n^(i) . o^(i)) o^(i)`` is the far end of that chord (the
  reflection of -n^(i) about o^(i); invariant under o -> -o).
* ``i^(i)`` is the direction towards the light of path i (where the environment map is
  looked up), pointing away from the film at p_i: i^(0) = 2 (n^(0) . o^(0)) n^(0) - o^(0)
  (mirror reflection of the view direction; Huang Eq. 3.30 gives only i >= 1), and
  i^(k) = -o^(k-1) for k >= 1 (the light crosses the film at p_k undeviated).
* ``o^(i+1) = o^(i) - 2 (o^(i) . n^(i+1)) n^(i+1)`` = reflect(i^(i+1), n^(i+1)), so
  o^(i) = reflect(i^(i), n^(i)) holds for every i, i = 0 included.

With ``n_paths = N`` the paths 0 .. N-1 are evaluated, which need the thickness at the N
interactions 0 .. N-1 (the thesis keeps the first N = 8 light paths, [T:778]; its
Huang Eq. 3.32 writes the sum to N). For a uniform lossless film the weights then sum to
1 - T R^(N-1) per wavelength and polarisation (spec SB-1).

The cosine of every interaction is |n^(0) . o^(0)| (the film has air on both sides, so
its response depends only on |cos|). ``shade`` expects n^(0) . view >= 0 (a point the
observer sees from outside).

Colour (Huang Eqs. 3.31/3.32): the environment is an RGB map, so its spectrum is taken as
constant per channel and each path's spectral weight is integrated against the output
colour space's matching functions: with ``color="cie"`` the path weights on the
380-780 nm grid (5 nm, [T:742]) go through
:func:`appearance_jax.core.spectral.to_bands` (CIE 1931 -> linear sRGB under D65) and each
channel is white-balanced so that a unit spectrum maps to (1, 1, 1)
(:func:`appearance_jax.core.spectral.cie_rgb_matrix`). That normalisation is what Huang Eq. 3.32
assumes (int s_j d lambda = 1, so that a path of weight 1 -- a film of zero thickness --
passes the RGB environment through unchanged). ``"rgb3"`` samples
one wavelength per channel (650, 510, 475 nm); ``"spectral"`` keeps the wavelengths
(then the environment must return one band per wavelength).

Units: thicknesses are the **full** film thickness d = 2 eta in nm (the thesis writes the
half thickness eta, Delta psi = 2 pi 4 eta n_s cos(theta_s) / lambda, [T:753]);
wavelengths in nm; radiances in the environment's units.
"""

from __future__ import annotations

import functools
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..core import spectral
from ..core.vec import Vec3, cross, dot, normalize
from ..optics.thinfilm import airy
from .thickness import _check_nonnegative, _check_positive, _concrete

COLORS = ("cie", "rgb3", "spectral")


# --------------------------------------------------------------------------------------
# validation helpers
# --------------------------------------------------------------------------------------


def _check_n_paths(n_paths):
    if isinstance(n_paths, bool) or not isinstance(n_paths, (int, np.integer)):
        raise ValueError(f"n_paths = {n_paths!r}: must be a Python int >= 1 (a static path count)")
    if n_paths < 1:
        raise ValueError(f"n_paths = {n_paths}: must be >= 1")


def _check_color(color):
    if color not in COLORS:
        raise ValueError(f"color = {color!r}: must be one of {', '.join(COLORS)}")


def _check_indices(eta_film, eta_air):
    _check_positive("eta_film", eta_film)
    _check_positive("eta_air", eta_air)


def _as_vec3(v, name) -> Vec3:
    if isinstance(v, Vec3):
        return v
    a = jnp.asarray(v, dtype=jnp.result_type(float))
    if a.shape[-1:] != (3,):
        raise ValueError(f"{name}: need a Vec3 or an array with a trailing axis of 3, got shape {a.shape}")
    return Vec3.from_array(a)


# --------------------------------------------------------------------------------------
# Path weights (Huang Eq. 3.29)
# --------------------------------------------------------------------------------------


class PathWeights(NamedTuple):
    """Huang Eq. 3.29 path weights, ``(..., N, n_wavelengths)``: the polarisation average and s, p."""

    mean: jax.Array
    s: jax.Array
    p: jax.Array


def _chain(R, T):
    """weight^(0) = R_0, weight^(k) = T_0 prod_{i=1}^{k-1} R_i T_k along axis -2 (length N)."""
    first = R[..., :1, :]
    if R.shape[-2] == 1:
        return first
    inner = jnp.cumprod(R[..., 1:-1, :], axis=-2)  # prod_{i=1}^{j} R_i, j = 1 .. N-2
    P = jnp.concatenate([jnp.ones_like(first), inner], axis=-2)  # prod_{i=1}^{k-1}, k = 1 .. N-1
    return jnp.concatenate([first, T[..., :1, :] * P * T[..., 1:, :]], axis=-2)


def path_weights(cos_theta, thicknesses_nm, wavelengths_nm, eta_film=1.33, eta_air=1.0, *,
                 per_polarization: bool = False):
    """Spectral weights of the first N light paths through a bubble, Huang Eq. 3.29.

    Args:
        cos_theta: ``(...)`` cosine of the incidence angle, shared by all interactions of
            a path (Huang Fig. 3.11), in [0, 1].
        thicknesses_nm: ``(..., N)`` **full** film thickness (nm, >= 0) at interactions
            0 .. N-1 of the path (2 eta of the thesis).
        wavelengths_nm: ``(n_wavelengths,)`` vacuum wavelengths (nm, > 0).
        eta_film: film index (soap water 1.33, [T:744]).
        eta_air: index of the medium on both sides (air, 1).
        per_polarization: also return the s and p weights.

    Returns:
        ``(..., N, n_wavelengths)``: weight^(k)(lambda) for paths k = 0 .. N-1, the average of
        Huang Eq. 3.29 evaluated for s and p separately ([T:774]); or a :class:`PathWeights`
        ``(mean, s, p)`` if ``per_polarization``. Fractions of power (dimensionless).

    R^(i), T^(i) are :func:`appearance_jax.optics.thinfilm.airy` (Huang Eqs. 3.27/3.28); the
    products are cumulative products (no loop over paths). Zero thickness gives R = 0,
    T = 1: only path 1 (straight through) carries light.
    """
    _check_indices(eta_film, eta_air)
    _check_nonnegative("thicknesses_nm", thicknesses_nm, " nm")
    _check_positive("wavelengths_nm", wavelengths_nm, " nm")
    d = jnp.asarray(thicknesses_nm, dtype=jnp.result_type(thicknesses_nm, float))
    if d.ndim < 1:
        raise ValueError("thicknesses_nm: need a trailing axis of N >= 1 interactions, got a scalar")
    wl = jnp.asarray(wavelengths_nm, dtype=jnp.result_type(wavelengths_nm, float))
    if wl.ndim != 1:
        raise ValueError(f"wavelengths_nm: need a 1-D array, got shape {wl.shape}")
    c = jnp.asarray(cos_theta, dtype=jnp.result_type(cos_theta, float))
    out = _path_weights(c, d, wl, eta_film, eta_air)
    return out if per_polarization else out.mean


@jax.jit
def _path_weights(c, d, wl, eta_film, eta_air) -> PathWeights:
    resp = airy(c[..., None, None], wl, d[..., :, None], eta_air, eta_film, eta_air)
    ws = _chain(resp.R_s, resp.T_s)
    wp = _chain(resp.R_p, resp.T_p)
    return PathWeights(0.5 * (ws + wp), ws, wp)


def path_colors(cos_theta, thicknesses_nm, eta_film=1.33, eta_air=1.0, color: str = "cie", wavelengths=None):
    """Colour of each path's weight, the integrals int s_j(lambda) weight_n(lambda) d lambda of Huang Eq. 3.32.

    Returns ``(..., N, 3)`` for ``color`` "cie" (linear sRGB under D65, each channel
    normalised so that a weight of 1 at every wavelength maps to exactly (1, 1, 1)) or
    "rgb3", ``(..., N, n_wavelengths)`` for "spectral" (``wavelengths`` in nm). See
    :func:`path_weights` for the arguments.
    """
    _check_color(color)
    wl = spectral.band_wavelengths(color, spectral.RGB_WAVELENGTHS if wavelengths is None else wavelengths)
    w = path_weights(cos_theta, thicknesses_nm, wl, eta_film, eta_air)
    if color != "cie":
        return w
    # CIE 1931 -> white-balanced linear sRGB under D65: one matrix whose columns (the
    # channels' matching functions) have unit sum (module docstring)
    return spectral.to_bands(w, "cie")


# --------------------------------------------------------------------------------------
# Directions (Huang Eq. 3.30)
# --------------------------------------------------------------------------------------


class PathDirections(NamedTuple):
    """Directions of the first N interactions; Vec3 components ``(..., N)``.

    normal: n^(i), the interaction point on the unit sphere (where the thickness is sampled).
    incident: i^(i), towards the light of path i (where the environment is sampled).
    outgoing: o^(i), the (virtual) viewing direction at interaction i; o^(0) = view.
    cos_theta: ``(...)``, |n^(0) . o^(0)|, the incidence cosine shared by all interactions.
    """

    normal: Vec3
    incident: Vec3
    outgoing: Vec3
    cos_theta: jax.Array


def path_directions(normal, view, n_paths: int = 8) -> PathDirections:
    """The direction recursion of Huang Eq. 3.30 for the first ``n_paths`` interactions.

    Args:
        normal: outward unit normal n^(0) at the point seen (``Vec3`` or ``(..., 3)``;
            normalised here).
        view: direction from that point towards the observer, o^(0) (normalised here).
        n_paths: number N of interactions / light paths (static int >= 1).

    Returns:
        :class:`PathDirections` with n^(i), i^(i), o^(i) for i = 0 .. N-1 stacked on a
        trailing axis, and cos_theta = |n^(0) . o^(0)|.

    Recursion (``lax.scan``): n^(i+1) = n^(i) - 2 (n^(i) . o^(i)) o^(i),
    i^(i+1) = -o^(i), o^(i+1) = o^(i) - 2 (o^(i) . n^(i+1)) n^(i+1); i^(0) is the mirror
    direction 2 (n^(0) . o^(0)) n^(0) - o^(0). See the module docstring for why o^(0) = view.
    n^(i+1) and o^(i+1) are renormalised at every step: the recursion amplifies a vector's norm
    error ~18x per interaction.
    """
    _check_n_paths(n_paths)
    return _path_directions(_as_vec3(normal, "normal"), _as_vec3(view, "view"), int(n_paths))


@functools.partial(jax.jit, static_argnames=("n_paths",))
def _path_directions(normal, view, n_paths):
    n0 = normalize(normal)
    o0 = normalize(view)
    shape = jnp.broadcast_shapes(n0.shape, o0.shape)
    n0 = n0.map(lambda a: jnp.broadcast_to(a, shape))
    o0 = o0.map(lambda a: jnp.broadcast_to(a, shape))
    i0 = n0 * (2.0 * dot(n0, o0)) - o0

    def step(carry, _):
        n, inc, o = carry
        # renormalised: a reflection about a vector of norm 1 + e changes the reflected vector's
        # squared norm by ~4 e, so without it a 1-ulp error in the inputs grows ~18x per
        # interaction (1.6e-7 at the 8th in float64, machine-dependent)
        n_next = normalize(n - o * (2.0 * dot(n, o)))
        o_next = normalize(o - n_next * (2.0 * dot(o, n_next)))
        return (n_next, -o, o_next), (n, inc, o)

    _, (ns, incs, os) = jax.lax.scan(step, (n0, i0, o0), None, length=n_paths)
    last = lambda v: v.map(lambda a: jnp.moveaxis(a, 0, -1))  # noqa: E731
    return PathDirections(last(ns), last(incs), last(os), jnp.abs(dot(n0, o0)))


# --------------------------------------------------------------------------------------
# Shading (Huang Eq. 3.32)
# --------------------------------------------------------------------------------------


def shade(view_dir, normal, environment: Callable, thickness: Callable, n_paths: int = 8,
          eta_film=1.33, eta_air=1.0, color: str = "cie", wavelengths=None):
    """Radiance of a soap-bubble point, Huang Eq. 3.32 : sum_n L_i^(n) int s_j weight_n d lambda.

    Args:
        view_dir: direction from the point towards the observer (``Vec3`` or ``(..., 3)``).
        normal: outward unit normal of the bubble at the point (the point itself on the
            unit sphere), with normal . view_dir >= 0.
        environment: distant illumination, ``Vec3 -> (..., 3)`` linear RGB radiance in the
            direction towards the light (``(..., n_wavelengths)`` for ``color="spectral"``).
        thickness: film thickness field, ``Vec3`` (unit normal on the sphere) ``-> (...)``
            **full** thickness in nm (e.g. :func:`appearance_jax.soapfilm.thickness.equilibrium_field`).
        n_paths: number of light paths N (the thesis uses 8, [T:778]); static int >= 1.
        eta_film, eta_air: refractive indices of the soap water (1.33) and the air (1).
        color: "cie" (default, CIE integration on 380-780 nm by 5 nm), "rgb3" or "spectral".
        wavelengths: the wavelengths (nm) of "spectral" mode.

    Returns:
        ``(..., 3)`` linear RGB radiance (``(..., n_wavelengths)`` for "spectral").

    Pure and jittable when ``environment`` and ``thickness`` are (close over them, or pass
    them as static arguments); differentiable in everything the callables depend on.
    Thicknesses are checked (>= 0) when concrete.
    """
    _check_n_paths(n_paths)
    _check_indices(eta_film, eta_air)
    _check_color(color)
    dirs = path_directions(normal, view_dir, n_paths)
    d = jnp.asarray(thickness(dirs.normal))
    if d.shape != dirs.normal.shape:
        d = jnp.broadcast_to(d, dirs.normal.shape)
    if _concrete_or_none(d) is not None:
        _check_nonnegative("thickness", d, " nm")
    F = path_colors(dirs.cos_theta, d, eta_film, eta_air, color, wavelengths)  # (..., N, bands)
    L = jnp.asarray(environment(dirs.incident))  # (..., N, bands)
    return jnp.sum(L * F, axis=-2)


def _concrete_or_none(x):
    try:
        return _concrete(x)
    except ValueError:
        return None


# --------------------------------------------------------------------------------------
# Rendering
# --------------------------------------------------------------------------------------


def camera_basis(view=(0.0, -1.0, 0.0), up=(0.0, 0.0, 1.0)):
    """Orthonormal (right, up, view) of the orthographic camera of :func:`render`."""
    v = normalize(_as_vec3(view, "view"))
    u = _as_vec3(up, "up")
    r = cross(u, v)
    rn = _concrete(jnp.sqrt(dot(r, r)))
    if rn is not None and np.any(rn < 1e-9):
        raise ValueError(f"up = {tuple(np.asarray(u.to_array()))}: must not be parallel to view")
    r = normalize(r)
    return r, cross(v, r), v


def image_plane(resolution):
    """Pixel-centre coordinates (x right, y up) of :func:`render`, each ``(H, W)``, in bubble radii."""
    H, W = _resolution(resolution)
    s = min(H, W)
    x = ((jnp.arange(W) + 0.5) - 0.5 * W) * (2.0 / s)
    y = (0.5 * H - (jnp.arange(H) + 0.5)) * (2.0 / s)
    return jnp.meshgrid(x, y, indexing="xy")


def _resolution(resolution):
    if isinstance(resolution, (int, np.integer)) and not isinstance(resolution, bool):
        resolution = (int(resolution), int(resolution))
    try:
        H, W = (int(r) for r in resolution)
    except (TypeError, ValueError):
        raise ValueError(f"resolution = {resolution!r}: must be an int or (height, width)") from None
    if H < 1 or W < 1:
        raise ValueError(f"resolution = {resolution!r}: must be >= 1 pixel")
    return H, W


def render(resolution, environment: Callable, thickness: Callable, *, view=(0.0, -1.0, 0.0),
           up=(0.0, 0.0, 1.0), n_paths: int = 8, eta_film=1.33, eta_air=1.0, color: str = "cie",
           background=0.0, chunk_size: int = 16384):
    """Orthographic image of a unit soap bubble (Huang 2022, Sec. 3.5).

    Args:
        resolution: ``H`` (square) or ``(H, W)`` pixels; the bubble's disc (radius 1)
            fills the shorter side.
        environment, thickness: as in :func:`shade`. Both must be hashable callables (they
            are static arguments of the internal ``jit``; reuse the same objects to reuse
            the compiled image).
        view: direction from the bubble towards the (distant, orthographic) camera.
            Default: a side view from -y, so that with ``up = +z`` the top of the bubble
            (theta = 0 of :mod:`appearance_jax.soapfilm.thickness`) is at the top of the
            image and the image's x axis is the world x axis.
        up: world direction shown upwards in the image (not parallel to ``view``).
        n_paths, eta_film, eta_air, color: as in :func:`shade`.
        background: value of the pixels outside the disc (a number or a colour), or
            ``"environment"`` for the environment seen straight through (direction -view).
        chunk_size: pixels shaded at once (bounds the memory: N x n_wavelengths complex
            numbers per pixel); the chunks run in a ``lax.map``.

    Returns:
        ``(image, mask)``: ``(H, W, bands)`` linear radiance (RGB for "cie"/"rgb3") and the
        ``(H, W)`` boolean disc. Pixel (row, col) sees the sphere point
        n = x right + y up' + sqrt(1 - x^2 - y^2) view, (x, y) from :func:`image_plane`.
    """
    _check_n_paths(n_paths)
    _check_indices(eta_film, eta_air)
    _check_color(color)
    if color == "spectral":
        raise ValueError("color = 'spectral': render produces RGB images; use 'cie' or 'rgb3'")
    H, W = _resolution(resolution)
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1:
        raise ValueError(f"chunk_size = {chunk_size!r}: must be an int >= 1")
    bg_env = isinstance(background, str)
    if bg_env and background != "environment":
        raise ValueError(f"background = {background!r}: must be a number, a colour or 'environment'")
    if color == "cie":
        spectral.cie_rgb_matrix()  # build the colour table outside the jit
    right, upv, v = camera_basis(view, up)
    basis = tuple(jnp.asarray(a, dtype=jnp.result_type(float)) for b in (right, upv, v) for a in b)
    bg = jnp.zeros(()) if bg_env else jnp.asarray(background, dtype=jnp.result_type(float))
    return _render(basis, eta_film, eta_air, bg, H=H, W=W, environment=environment, thickness=thickness,
                   n_paths=int(n_paths), color=color, bg_env=bg_env, chunk_size=int(chunk_size))


@functools.partial(jax.jit, static_argnames=("H", "W", "environment", "thickness", "n_paths", "color",
                                             "bg_env", "chunk_size"))
def _render(basis, eta_film, eta_air, bg, *, H, W, environment, thickness, n_paths, color, bg_env, chunk_size):
    right, upv, v = Vec3(*basis[0:3]), Vec3(*basis[3:6]), Vec3(*basis[6:9])
    x, y = image_plane((H, W))
    r2 = x * x + y * y
    mask = r2 < 1.0
    x = jnp.where(mask, x, 0.0)
    y = jnp.where(mask, y, 0.0)
    z = jnp.sqrt(jnp.maximum(1.0 - x * x - y * y, 0.0))
    normal = right * x.reshape(-1) + upv * y.reshape(-1) + v * z.reshape(-1)  # (P,)
    P = H * W
    n_chunks = -(-P // chunk_size)
    size = -(-P // n_chunks)  # balanced chunks
    pad = n_chunks * size - P

    def prep(a):
        return jnp.pad(a, (0, pad), mode="edge").reshape(n_chunks, size)

    def one(nc):
        view = v.map(lambda a: jnp.broadcast_to(a, nc.shape))
        return shade(view, nc, environment, thickness, n_paths, eta_film, eta_air, color)

    chunks = normal.map(prep)
    if n_chunks == 1:
        rgb = one(chunks.map(lambda a: a[0]))[None]
    else:
        rgb = jax.lax.map(one, chunks)  # (n_chunks, size, bands)
    rgb = rgb.reshape(n_chunks * size, -1)[:P].reshape(H, W, -1)
    if bg_env:
        back = jnp.asarray(environment(-v))
    else:
        back = bg
    image = jnp.where(mask[..., None], rgb, back)
    return image, mask


__all__ = [
    "COLORS",
    "PathWeights",
    "PathDirections",
    "path_weights",
    "path_colors",
    "path_directions",
    "shade",
    "camera_basis",
    "image_plane",
    "render",
]
