"""Feather geometry textures from Bézier curves: Padrón's authoring pipeline, App. B.3 [T:1373-1381].

Padrón's feather BSDF (Eq. 5.4) shades a flat feather whose geometry lives in a 2D texture [T:889, 1381]:

- **R**: the tangent angle of the barb through the pixel (here radians, counter-clockwise from +x,
  pointing away from the rachis), which orients the barb frame of the BSDF;
- **G**: the barb's curve length from its rachis point to the pixel (units of the outline);
- **B**: the mask, :data:`BACKGROUND` (0), :data:`SHAFT` (1, the rachis: a diffuse BRDF) or
  :data:`VANE` (2, the feather BSDF).

The pipeline (numpy only, no JAX: authoring runs once, offline):

1. :func:`fit_bezier`: vane contours and the shaft as Bézier curves fitted to landmarks by linear least
   squares with the Moore–Penrose pseudoinverse [T:1377], chord-length parametrised.
2. :func:`barbs`: each barb is a cubic Bézier from a rachis point to where a line, rotated by the barb
   angle from the rachis tangent, meets the vane contour; its two inner control points sit on the chord
   at 1/3 and 2/3, displaced sideways ("slightly distorted" [T:1379]).
3. :func:`rasterize`: the mask (the shaft width is interpolated linearly from base to tip along the
   rachis parameter [T:1377]) and, for each vane pixel, the angle and length at the nearest point of
   the nearest barb.

:func:`encode_rgb8` / :func:`decode_rgb8` store a texture as 8-bit RGB and read it back.

Coordinates: a point is (x, y) with y up, in any length unit (the outline's). A texture covers
``extent = (x0, x1, y0, y1)``; pixel ``[row, col]`` is centred at ``x = x0 + (col + 0.5) dx``,
``y = y1 - (row + 0.5) dy`` (row 0 at the top, as images are stored).
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb

import numpy as np

BACKGROUND, SHAFT, VANE = 0, 1, 2
_POLYLINE = 512  # points per curve when a curve is cut into segments (intersections, polygons)


def _control(control, name="control") -> np.ndarray:
    c = np.asarray(control, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != 2 or c.shape[0] < 2:
        raise ValueError(f"{name} has shape {c.shape}: expected (n + 1, 2) control points of a degree n >= 1 curve")
    if not np.all(np.isfinite(c)):
        raise ValueError(f"{name} has non-finite control points")
    return c


def bezier(control, t) -> np.ndarray:
    """Points of the Bézier curve with control points ``control`` (n + 1, 2) at parameters ``t`` in
    [0, 1] (Bernstein form): shape ``t.shape + (2,)``."""
    c = _control(control)
    t = np.asarray(t, dtype=np.float64)
    n = c.shape[0] - 1
    k = np.arange(n + 1)
    basis = comb_row(n) * t[..., None] ** k * (1.0 - t[..., None]) ** (n - k)
    return basis @ c


def comb_row(n: int) -> np.ndarray:
    """The binomial coefficients C(n, k), k = 0..n."""
    return np.array([comb(n, k) for k in range(n + 1)], dtype=np.float64)


def bezier_tangent(control, t) -> np.ndarray:
    """d/dt of :func:`bezier` (not normalised): the degree n - 1 Bézier on n (c[k+1] - c[k])."""
    c = _control(control)
    d = (c.shape[0] - 1) * np.diff(c, axis=0)
    if d.shape[0] == 1:  # a straight segment: a constant tangent
        return np.broadcast_to(d[0], np.shape(t) + (2,)).copy()
    return bezier(d, t)


def fit_bezier(points, degree: int = 3) -> np.ndarray:
    """Control points (degree + 1, 2) of the Bézier curve closest to ``points`` (m, 2) in least squares,
    parametrised by normalised chord length, solved with the Moore–Penrose pseudoinverse [T:1377].
    The first and last points are not pinned. Needs m >= degree + 1 distinct points."""
    p = np.asarray(points, dtype=np.float64)
    if int(degree) != degree or degree < 1:
        raise ValueError(f"degree = {degree!r}: an integer >= 1")
    degree = int(degree)
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < degree + 1:
        raise ValueError(f"points has shape {p.shape}: expected (m, 2) with m >= degree + 1 = {degree + 1}")
    if not np.all(np.isfinite(p)):
        raise ValueError("points has non-finite entries")
    seg = np.hypot(*np.diff(p, axis=0).T)
    if seg.sum() <= 0:
        raise ValueError("points are all the same point: no curve to fit")
    t = np.concatenate([[0.0], np.cumsum(seg)]) / seg.sum()
    k = np.arange(degree + 1)
    A = comb_row(degree) * t[:, None] ** k * (1.0 - t[:, None]) ** (degree - k)
    return np.linalg.pinv(A) @ p


def _polyline(control, n=_POLYLINE):
    return bezier(control, np.linspace(0.0, 1.0, n))


def _ray_polyline(origin, direction, poly):
    """Nearest forward intersection (distance s > 0) of rays origin + s direction, (k, 2) each, with the
    polyline ``poly`` (m, 2); inf where a ray misses it."""
    a, b = poly[:-1], poly[1:]                                  # segments a + u (b - a), u in [0, 1]
    e = b - a
    o, d = origin[:, None, :], direction[:, None, :]
    denom = d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]
    w = a[None] - o
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (w[..., 0] * e[..., 1] - w[..., 1] * e[..., 0]) / denom
        u = (w[..., 0] * d[..., 1] - w[..., 1] * d[..., 0]) / denom
    ok = (np.abs(denom) > 1e-300) & (s > 1e-12) & (u >= 0.0) & (u <= 1.0)
    return np.where(ok, s, np.inf).min(axis=1)


@dataclass(frozen=True)
class Outline:
    """A pennaceous feather's outline: the rachis from base to tip and the two vane contours (Bézier
    control points, (n + 1, 2) each, in the outline's length unit), each contour from the base of the
    vane to the tip; ``shaft_width`` = (base, tip) full width of the rachis."""

    rachis: np.ndarray
    left: np.ndarray
    right: np.ndarray
    shaft_width: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self):
        for name in ("rachis", "left", "right"):
            object.__setattr__(self, name, _control(getattr(self, name), name))
        w = tuple(float(v) for v in np.broadcast_to(np.asarray(self.shaft_width, dtype=np.float64), (2,)))
        if not all(np.isfinite(v) and v >= 0 for v in w):
            raise ValueError(f"shaft_width = {w}: two finite widths >= 0 (base, tip)")
        object.__setattr__(self, "shaft_width", w)

    def vane_polygon(self, side: str) -> np.ndarray:
        """The closed vane region of ``side`` ("left" or "right"): rachis base -> tip, contour tip -> base."""
        return np.concatenate([_polyline(self.rachis), _polyline(_side(self, side))[::-1]])


def _side(outline, side):
    if side not in ("left", "right"):
        raise ValueError(f"side = {side!r}: 'left' or 'right'")
    return outline.left if side == "left" else outline.right


def barbs(outline: Outline, n_barbs: int, barb_angle_deg, *, side: str = "left", t_range=(0.02, 0.98),
          bend: float = 0.0, jitter: float = 0.0, seed: int = 0) -> np.ndarray:
    """Cubic Bézier barbs (n, 4, 2) of one vane [T:1379].

    Barb i starts on the rachis at parameter t_i, evenly spaced in ``t_range``; it leaves along the
    rachis tangent rotated by ``barb_angle_deg`` (degrees in (0, 180); scalar or one per barb) towards
    ``side`` (counter-clockwise for "left", clockwise for "right"), and ends where that line meets the
    vane contour. The inner control points lie on the chord at 1/3 and 2/3, moved sideways by
    ``bend`` (a fraction of the chord length, positive towards the feather's tip) plus a uniform
    random ``jitter`` in [-jitter, jitter] (same unit, numpy ``seed``). A barb whose line misses the
    contour raises (the angle or ``t_range`` does not fit the outline).
    """
    if int(n_barbs) != n_barbs or n_barbs < 1:
        raise ValueError(f"n_barbs = {n_barbs!r}: an integer >= 1")
    n_barbs = int(n_barbs)
    ang = np.broadcast_to(np.asarray(barb_angle_deg, dtype=np.float64), (n_barbs,))
    if not np.all((ang > 0) & (ang < 180)):
        raise ValueError(f"barb_angle_deg = {barb_angle_deg!r}: in (0, 180) degrees from the rachis tangent")
    t0, t1 = (float(v) for v in t_range)
    if not 0.0 <= t0 < t1 <= 1.0:
        raise ValueError(f"t_range = {t_range!r}: 0 <= start < end <= 1 along the rachis")
    for name, v in (("bend", bend), ("jitter", jitter)):
        if not np.isfinite(v) or (name == "jitter" and v < 0):
            raise ValueError(f"{name} = {v!r}: a finite number{' >= 0' if name == 'jitter' else ''}")
    contour = _side(outline, side)
    t = np.linspace(t0, t1, n_barbs)
    start = bezier(outline.rachis, t)
    tan = bezier_tangent(outline.rachis, t)
    tan = tan / np.linalg.norm(tan, axis=-1, keepdims=True)
    a = np.radians(ang) * (1.0 if side == "left" else -1.0)
    d = np.stack([np.cos(a) * tan[:, 0] - np.sin(a) * tan[:, 1], np.sin(a) * tan[:, 0] + np.cos(a) * tan[:, 1]], -1)
    s = _ray_polyline(start, d, _polyline(contour))
    if not np.all(np.isfinite(s)):
        bad = np.flatnonzero(~np.isfinite(s))
        raise ValueError(f"barbs {bad.tolist()} of the {side} vane (rachis t = {np.round(t[bad], 3).tolist()}) never "
                         f"meet the vane contour at barb_angle_deg = {ang[bad].tolist()}")
    end = start + s[:, None] * d
    chord = end - start
    # sideways unit vector that turns towards the tip: the rachis tangent's component normal to the chord
    nrm = np.stack([-chord[:, 1], chord[:, 0]], -1) / s[:, None]
    nrm *= np.sign(np.sum(nrm * tan, -1, keepdims=True) + 1e-300)
    rng = np.random.default_rng(seed)
    off = (bend + jitter * rng.uniform(-1.0, 1.0, (n_barbs, 2))) * s[:, None]
    p1 = start + chord / 3 + off[:, :1] * nrm
    p2 = start + 2 * chord / 3 + off[:, 1:] * nrm
    return np.stack([start, p1, p2, end], axis=1)


def pixel_centres(shape, extent) -> tuple[np.ndarray, np.ndarray]:
    """x, y of the pixel centres (each ``shape``) of a texture covering ``extent = (x0, x1, y0, y1)``."""
    h, w = (int(v) for v in shape)
    x0, x1, y0, y1 = (float(v) for v in extent)
    if h < 1 or w < 1 or not (x1 > x0 and y1 > y0):
        raise ValueError(f"shape = {shape!r}, extent = {extent!r}: positive sizes and x1 > x0, y1 > y0")
    x = x0 + (np.arange(w) + 0.5) * (x1 - x0) / w
    y = y1 - (np.arange(h) + 0.5) * (y1 - y0) / h
    return np.meshgrid(x, y)


def rasterize(outline: Outline, barb_curves, shape, extent, *, samples_per_barb: int = 64) -> np.ndarray:
    """The texture (h, w, 3), float64: [..., 0] barb angle [rad, in (-pi, pi]], [..., 1] barb length from
    the rachis [outline units], [..., 2] mask (:data:`BACKGROUND`, :data:`SHAFT`, :data:`VANE`).

    ``barb_curves``: (n, 4, 2) cubic Béziers (:func:`barbs`; both vanes concatenated). A pixel is shaft
    when it lies within half the local shaft width of the rachis (width linear in the rachis parameter;
    round caps at the rachis' ends), vane when it lies inside a vane polygon
    (:meth:`Outline.vane_polygon`) and not in the shaft. Angle and length are those of the nearest of
    ``samples_per_barb`` points along each barb, 0 off the vane.
    """
    from matplotlib.path import Path  # a dependency of the package; only polygon containment is used

    curves = np.asarray(barb_curves, dtype=np.float64)
    if curves.ndim != 3 or curves.shape[1:] != (4, 2) or curves.shape[0] < 1:
        raise ValueError(f"barb_curves has shape {curves.shape}: expected (n >= 1, 4, 2) cubic Béziers")
    X, Y = pixel_centres(shape, extent)
    pts = np.stack([X.ravel(), Y.ravel()], -1)
    # shaft: distance to the rachis polyline against the interpolated half width
    tr = np.linspace(0.0, 1.0, _POLYLINE)
    rach = bezier(outline.rachis, tr)
    half = 0.5 * ((1 - tr) * outline.shaft_width[0] + tr * outline.shaft_width[1])
    shaft = np.zeros(len(pts), bool)
    vane = np.zeros(len(pts), bool)
    for side in ("left", "right"):
        vane |= Path(outline.vane_polygon(side)).contains_points(pts)
    # barb samples: positions, tangent angle, arc length from the rachis point (trapezoid on the polyline)
    if int(samples_per_barb) != samples_per_barb or samples_per_barb < 2:
        raise ValueError(f"samples_per_barb = {samples_per_barb!r}: an integer >= 2")
    u = np.linspace(0.0, 1.0, int(samples_per_barb))
    k = np.arange(4)
    B = comb_row(3) * u[:, None] ** k * (1 - u[:, None]) ** (3 - k)              # (m, 4)
    dB = 3 * comb_row(2) * u[:, None] ** k[:3] * (1 - u[:, None]) ** (2 - k[:3])   # (m, 3)
    P = np.einsum("mk,nkd->nmd", B, curves)
    D = np.einsum("mk,nkd->nmd", dB, np.diff(curves, axis=1))
    ang = np.arctan2(D[..., 1], D[..., 0]).ravel()
    length = np.concatenate([np.zeros((len(curves), 1)), np.cumsum(np.hypot(*np.diff(P, axis=1).T).T, axis=1)], 1)
    P, length = P.reshape(-1, 2), length.ravel()
    out = np.zeros((len(pts), 3))
    P2 = np.sum(P * P, -1)
    chunk = max(1, int(2e7 // max(len(P), len(rach))))  # pixels per block: ~160 MB of distances at most
    for i in range(0, len(pts), chunk):
        q = pts[i:i + chunk]
        dr = np.hypot(q[:, None, 0] - rach[None, :, 0], q[:, None, 1] - rach[None, :, 1])
        shaft[i:i + chunk] = np.any(dr <= half[None], axis=1)
        sel = np.flatnonzero(vane[i:i + chunk] & ~shaft[i:i + chunk])
        if sel.size:
            j = np.argmin(P2[None] - 2.0 * q[sel] @ P.T, axis=1)  # nearest sample: |q|^2 is common
            out[i + sel, 0], out[i + sel, 1] = ang[j], length[j]
    out[:, 2] = np.where(shaft, SHAFT, np.where(vane, VANE, BACKGROUND))
    return out.reshape(tuple(int(v) for v in shape) + (3,))


def encode_rgb8(texture, max_length: float) -> np.ndarray:
    """8-bit RGB of a :func:`rasterize` texture: R = (angle + pi) / (2 pi) * 256 (mod 256), G = length /
    ``max_length`` * 255 (clipped), B = mask * 127 (0, 127, 254)."""
    tex = np.asarray(texture, dtype=np.float64)
    if tex.ndim != 3 or tex.shape[2] != 3:
        raise ValueError(f"texture has shape {tex.shape}: expected (h, w, 3)")
    if not (np.isfinite(max_length) and max_length > 0):
        raise ValueError(f"max_length = {max_length!r}: a finite length > 0")
    r = np.round((tex[..., 0] + np.pi) / (2 * np.pi) * 256) % 256
    g = np.clip(np.round(tex[..., 1] / max_length * 255), 0, 255)
    b = np.round(tex[..., 2]) * 127
    return np.stack([r, g, b], -1).astype(np.uint8)


def decode_rgb8(rgb, max_length: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """angle [rad, in [-pi, pi)], length [units of ``max_length``], mask (int) of an :func:`encode_rgb8`
    image. Angle resolution 2 pi / 256 (1.4 degrees), length resolution max_length / 255."""
    a = np.asarray(rgb)
    if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"rgb has dtype {a.dtype} and shape {a.shape}: expected uint8 (h, w, 3)")
    if not (np.isfinite(max_length) and max_length > 0):
        raise ValueError(f"max_length = {max_length!r}: a finite length > 0")
    a = a.astype(np.float64)
    mask = np.clip(np.round(a[..., 2] / 127), 0, 2).astype(int)
    return a[..., 0] / 256 * 2 * np.pi - np.pi, a[..., 1] / 255 * max_length, mask
