"""In-plane geometry of the report's figures: the in-plane points of a table and their images.

A table's in-plane directions (:meth:`Table.in_plane_rows`, above the horizon) are addressed by
theta_i and the **signed** theta_o (:meth:`Table.signed_theta_o`, > 0 forward, < 0 retro side),
as in Fig. 4.4 of Padrón 2025. :func:`plane_points` averages repeated directions and decides
how a map draws them: cells of a theta_i x theta_o grid, or nearest-sample pixels of scattered
points (:func:`raster_images`). :func:`eval_in_plane` evaluates a model at in-plane directions
(the report's dense curves and the ``appearance-jax eval`` grid). :func:`reciprocity_fill`
adds, by reciprocity f(wi, wo) = f(wo, wi), the in-plane points a table lacks but whose
mirror (theta_i and theta_o swapped) it has: the wedge a MERL table stores only once.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import jax
import numpy as np

from ...core import compile_cache
from ...core.frame import in_plane_directions
from ...core.model import estimate_of
from ...core.params import validate
from ..solve import reuse
from ..tables.table import Table

__all__ = ["eval_in_plane", "PlanePoints", "plane_points", "reciprocity_fill", "cell_edges", "grid_image",
           "raster_images"]


# one compiled program per shape (op by op the two directions take six small ones)
_in_plane_directions = jax.jit(in_plane_directions)


def eval_in_plane(model, params, theta_i, theta_o, n_bands: int | None = None) -> np.ndarray:
    """A model's values (M, B) at in-plane directions, as numpy (a stochastic model's estimate).

    Args:
        theta_i: (M,) incidence angles [rad].
        theta_o: (M,) **signed** outgoing angles [rad] (theta_o = theta_i is the mirror direction,
            < 0 the retro side), as :func:`~appearance_jax.core.frame.in_plane_directions` takes them.
        n_bands: broadcast the bands axis to this many bands (a grey model on a colour table).
    """
    wi, wo = _in_plane_directions(np.asarray(theta_i), np.asarray(theta_o))
    out = np.asarray(estimate_of(_evaluate(model, params, wi, wo)))
    if out.ndim == 1:
        out = out[:, None]
    return out if n_bands is None else np.broadcast_to(out, (out.shape[0], n_bands))


def _evaluate(model, params, wi, wo):
    """``model.eval(params, wi, wo)``; for a registered deterministic model through a compiled
    program kept in memory and on disk (:mod:`~appearance_jax.fit.solve.reuse`): a report
    re-drawn in a new process then does not trace the model again."""
    name = reuse.registered_name(model)
    kernel = getattr(model.eval, "kernel", None)
    if name is None or kernel is None or model.stochastic:
        return model.eval(params, wi, wo)
    validate(params, model.Params)  # what model.eval checks (the directions are ours)
    make = lambda: compile_cache.compile_lowered(jax.jit(kernel).lower(params, wi, wo))  # noqa: E731
    return reuse.cached("eval_in_plane", reuse.identity(model), make, params, wi, wo, disk=name)(params, wi, wo)


@dataclass
class PlanePoints:
    """De-duplicated in-plane points of a table: angles [deg] and linear-RGB f (not f cos).

    ``filled``: (M,) True for points added by :func:`reciprocity_fill` (not measured there).
    """

    ti: np.ndarray
    to: np.ndarray
    meas: np.ndarray  # (M, 3), NaN = no measurement
    fit: np.ndarray  # (M, 3)
    n_rows: int
    regular: bool
    enough: bool
    filled: np.ndarray = field(default=None)

    def __post_init__(self):
        if self.filled is None:
            self.filled = np.zeros(np.shape(self.ti), bool)


def plane_points(t: Table, meas_rgb, fit_rgb) -> PlanePoints:
    """The in-plane directions of ``t`` above the horizon, repeated ones averaged, with their
    linear-RGB f from ``meas_rgb`` and ``fit_rgb`` (N, 3). ``enough``: at least 10 measured
    points over 2 theta_i and 3 theta_o values; ``regular``: they fill at least half of their
    theta_i x theta_o grid (drawn as cells, else as nearest-sample pixels)."""
    rows = t.in_plane_rows() & t.above_horizon()
    ti = np.round(np.rad2deg(t.theta_i[rows]), 6)
    to = np.round(np.rad2deg(t.signed_theta_o(strict=False))[rows], 6)
    if rows.sum() == 0:
        e = np.zeros((0, 3))
        return PlanePoints(np.zeros(0), np.zeros(0), e, e, 0, False, False)
    keys, inv = np.unique(np.stack([ti, to], axis=1), axis=0, return_inverse=True)
    inv = inv.ravel()

    def avg(v):
        v = v[rows]
        ok = np.isfinite(v)
        s = np.zeros((len(keys), 3))
        c = np.zeros((len(keys), 3))
        np.add.at(s, inv, np.where(ok, v, 0.0))
        np.add.at(c, inv, ok)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(c > 0, s / np.maximum(c, 1), np.nan)

    meas, fit = avg(meas_rgb), avg(fit_rgb)
    uti, uto = np.unique(keys[:, 0]), np.unique(keys[:, 1])
    have = np.isfinite(meas).all(axis=1)
    enough = bool(have.sum() >= 10 and np.unique(keys[have, 0]).size >= 2 and np.unique(keys[have, 1]).size >= 3)
    regular = len(keys) >= 0.5 * len(uti) * len(uto)
    return PlanePoints(keys[:, 0], keys[:, 1], meas, fit, int(rows.sum()), bool(regular), enough)


def _key(ti, to):
    return np.round(ti, 6) + 0.0, np.round(to, 6) + 0.0  # + 0.0: -0.0 -> 0.0


def _mirrors(ti, to):
    """Reciprocal partners (theta_i, signed theta_o) [deg] of in-plane points: swapping wi and wo
    keeps the side (forward stays forward, retro stays retro), so (a, s b) -> (b, s a). theta_o = 0
    has no side: both (0, a) and (0, -a) are its partner. Returns (which point, ti', to')."""
    s = np.where(to < 0, -1.0, 1.0)
    idx = np.arange(ti.size)
    zero = to == 0
    return (np.concatenate([idx, idx[zero]]), np.concatenate([np.abs(to), np.abs(to[zero])]),
            np.concatenate([s * ti, -ti[zero]]))


def reciprocity_fill(p: PlanePoints) -> PlanePoints:
    """``p`` with the in-plane points it lacks but whose reciprocal partner it has measured, by
    f(wi, wo) = f(wo, wi) (Helmholtz reciprocity): a point (theta_i = a, signed theta_o = s b) takes
    the measured and fitted values of (b, s a). Added points have ``filled`` True.

    A regular (grid) ``p`` gets the cells of its theta_i x theta_o grid that are absent or not
    measured in every channel; a scattered one (MERL grid) gets the partner of every measured
    point with no measured point within half a typical spacing (median nearest-neighbour
    distance) of it (a MERL table stores each reciprocal pair once, so half the plane lies there).
    """
    have = np.isfinite(p.meas).all(axis=1)
    if not have.any():
        return p
    src, mti, mto = _mirrors(p.ti[have], p.to[have])
    src = np.flatnonzero(have)[src]
    if p.regular:
        uti, uto = np.unique(p.ti), np.unique(p.to)
        measured = set(zip(*_key(p.ti[have], p.to[have])))
        cells = set(zip(*_key(*[g.ravel() for g in np.meshgrid(uti, uto, indexing="ij")])))
        take, seen = [], set()
        for j, k in enumerate(zip(*_key(mti, mto))):
            if k in cells and k not in measured and k not in seen:
                seen.add(k)
                take.append(j)
        take = np.asarray(take, np.intp)
        keep = ~np.array([k in seen for k in zip(*_key(p.ti, p.to))], bool)  # unmeasured cells now filled
    else:
        pts = np.stack([p.to[have], p.ti[have]], axis=1)
        spacing, _ = _nearest(pts, pts, exclude_self=True)
        spacing = float(np.median(spacing[np.isfinite(spacing)])) if np.isfinite(spacing).any() else 1.0
        d, _ = _nearest(np.stack([mto, mti], axis=1), pts)
        take = np.flatnonzero(d > 0.5 * spacing)
        keep = np.ones(p.ti.size, bool)
    if take.size == 0:
        return p
    s = src[take]
    cat = lambda a, b: np.concatenate([a[keep], b])  # noqa: E731
    return replace(p, ti=cat(p.ti, mti[take]), to=cat(p.to, mto[take]), meas=cat(p.meas, p.meas[s]),
                   fit=cat(p.fit, p.fit[s]), filled=cat(p.filled, np.ones(take.size, bool)))


def cell_edges(c):
    c = np.asarray(c, np.float64)
    if c.size == 1:
        return np.array([c[0] - 2.5, c[0] + 2.5])
    mid = 0.5 * (c[1:] + c[:-1])
    return np.concatenate([[c[0] - (mid[0] - c[0])], mid, [c[-1] + (c[-1] - mid[-1])]])


def grid_image(p: PlanePoints, values):
    """(ti_edges, to_edges, image (n_ti, n_to, k)) of the regular in-plane points; NaN = no sample."""
    uti, uto = np.unique(p.ti), np.unique(p.to)
    img = np.full((uti.size, uto.size, values.shape[1]), np.nan)
    img[np.searchsorted(uti, p.ti), np.searchsorted(uto, p.to)] = values
    return np.clip(cell_edges(uti), 0.0, 90.0), np.clip(cell_edges(uto), -90.0, 90.0), img


def _nearest(queries, pts, exclude_self=False):
    """(distance, index) of the nearest of ``pts`` (M, 2) to each query (Q, 2)."""
    try:
        from scipy.spatial import cKDTree
    except ImportError:  # brute force in chunks of ~16 MB
        cKDTree = None
    if cKDTree is not None:
        d, i = cKDTree(pts).query(queries, k=2 if exclude_self else 1)
        return (d[:, 1], i[:, 1]) if exclude_self else (d, i)
    dist = np.empty(len(queries))
    idx = np.empty(len(queries), np.intp)
    step = max(1, 1_000_000 // max(len(pts), 1))
    for s in range(0, len(queries), step):
        d = np.hypot(*(queries[s:s + step, None, :] - pts[None, :, :]).transpose(2, 0, 1))
        if exclude_self:
            d[np.arange(d.shape[0]), np.arange(s, s + d.shape[0])] = np.inf
        idx[s:s + step] = d.argmin(axis=1)
        dist[s:s + step] = d[np.arange(d.shape[0]), idx[s:s + step]]
    return dist, idx


def raster_images(p: PlanePoints, *values, step=0.5):
    """Nearest-point rasters of scattered in-plane points, NaN (black) beyond 1.5 typical spacings.

    Returns (ti_edges, to_edges, image per ``values`` array (n_ti, n_to, k)).
    """
    pts = np.stack([p.to, p.ti], axis=1)
    x = np.arange(max(-90.0, p.to.min() - 2), min(90.0, p.to.max() + 2) + step / 2, step)
    y = np.arange(max(0.0, p.ti.min() - 2), min(90.0, p.ti.max() + 2) + step / 2, step)
    gx, gy = np.meshgrid(x, y)
    g = np.stack([gx.ravel(), gy.ravel()], axis=1)
    # typical spacing: median distance of a point to its nearest neighbour
    nn, _ = _nearest(pts, pts, exclude_self=True)
    radius = 1.5 * max(float(np.median(nn[np.isfinite(nn)])) if np.isfinite(nn).any() else step, step)
    dist, idx = _nearest(g, pts)
    far = dist > radius
    imgs = []
    for v in values:
        img = v[idx].copy()
        img[far] = np.nan
        imgs.append(img.reshape(y.size, x.size, v.shape[1]))
    return (cell_edges(y), cell_edges(x), *imgs)
