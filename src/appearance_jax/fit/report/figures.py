"""The report of a fit: parameters as JSON, residuals as CSV and diagnostic figures.

    result = fit("lambert", table)
    paths = write_report(result, "out/fit")   # {"params": ..., "residuals": ..., "maps": ..., ...}

Files (in ``out_dir``):

``params.json``
    :meth:`FitResult.to_dict` (parameters with 1-sigma, flags, errors, solver statistics) plus
    ``table`` (summary, quantity, bands, what was masked), ``params`` (every field of the fitted
    ``Params``: fitted, fixed, static and unset ones), ``static``, ``entries`` (how many
    (direction, band) entries were fitted and why the others were not), ``figures`` (how the
    maps were built) and ``command`` (the ``extra`` dict: command line, options) with
    ``environment`` (versions, precision). Non-finite numbers are written as ``null``.
``residuals.csv``
    One row per (direction, band) entry of the table, valid or not (see the comment header
    of the file): angles in degrees, measured and fitted BRDF in 1/sr, the residual in the
    fit metric and a ``status`` column: ``fit`` for the entries the fit used, otherwise the
    reason they were left out (below horizon, missing value, grazing, no sigma).
``maps.png``
    Measured and fitted theta_i x signed theta_o maps (theta_o horizontal, negative on the
    retro-reflection side; theta_i vertical; black = no sample), as in Fig. 4.4 of Padrón
    2025: colour = sRGB of f cos theta_o per channel with **one** exposure common to both
    panels (the 99th percentile of the measured f cos theta_o maps to white), and a third
    panel with log10(fitted / measured) of the luminance. Spectral tables are shown in
    linear sRGB (:meth:`Table.to_rgb`), single-band tables in grey.
    Which samples are drawn:

    - an in-plane table: all its samples;
    - any other table (MERL grid, out-of-plane gonioreflectometer): its **in-plane subset**,
      the directions with phi_o - phi_i = 0 or 180 degrees (within 1e-6 rad) or theta_o = 0,
      when that subset has at least 10 measured points over at least 2 theta_i and 3 theta_o
      values. Points on a (mostly filled) theta_i x theta_o product grid are drawn as cells;
      scattered points (the MERL grid's in-plane nodes, phi_d = 90 degrees, lie on a skewed
      lattice) as nearest-sample pixels within 1.5 sample spacings, black further away.
      Repeated directions (e.g. theta_o = 0 for every azimuth) are averaged.
    - otherwise: the fitted model rendered densely in-plane (1 degree steps) next to a
      measured-vs-fitted scatter of all valid entries; the title says so.
``slices.png``
    Polar plots of f cos theta_o (per channel, 1/sr) against signed theta_o for up to 4 theta_i
    values: measured in-plane points (markers) and the fitted model evaluated densely in-plane
    (lines, :func:`~appearance_jax.core.frame.in_plane_directions`); the incident direction is
    marked. For a table without in-plane samples only the model is drawn.
``scatter.png``
    Fitted against measured BRDF per band, log-log, over the fitted entries, with the y = x line.

Figures use matplotlib's Agg backend (no display needed).
"""

from __future__ import annotations

import json
import math
import os
import platform
import re
import sys
from dataclasses import dataclass

import numpy as np

from .residuals import residual, residual_scale
from .table import Table

__all__ = ["write_report", "write_params_json", "write_residuals_csv", "entry_status", "plot_maps",
           "plot_slices", "plot_scatter", "in_plane_rows", "FIT"]

FIT = "fit"  # status of an entry the fit used
_HORIZON_COS = 1e-12
_PLANE_TOL = 1e-6
_EPS = 1e-3  # 1/sr: floor of the log error (as residuals.error_metrics)
_FLOOR = 1e-3  # the relative metric's floor (solve.build_problem's default)
_Y = np.array([0.2126, 0.7152, 0.0722])  # linear sRGB luminance


# ---------------------------------------------------------------------------------------
# which entries were fitted


def entry_status(result) -> np.ndarray:
    """(N, B) array of str: ``"fit"`` for the entries the fit used, else why it left them out.

    Rebuilt from the table and ``result.masked`` (the reasons :func:`~appearance_jax.fit.solve.fit`
    records): the table's own mask (``"below horizon"`` for directions at or below the horizon,
    the table's other reason otherwise), ``"grazing (theta > X deg)"`` and
    ``"sigma <= 0 or missing"``. Entries excluded only by a sample weight of 0 cannot be told
    apart and stay ``"fit"``; :func:`write_report` notes the difference to ``result.n_valid``.
    """
    t = result.table
    status = np.full(t.values.shape, FIT, dtype=object)
    below = ((np.cos(t.theta_i) <= _HORIZON_COS) | (np.cos(t.theta_o) <= _HORIZON_COS))[:, None]
    below = np.broadcast_to(below, t.values.shape)
    reasons = list(t.masked)
    horizon = [r for r in reasons if "horizon" in r]
    other = [r for r in reasons if "horizon" not in r]
    off = ~t.mask
    status[off & below] = horizon[0] if horizon else "below horizon"
    status[off & ~below] = other[0] if len(other) == 1 else (
        "masked in table (" + "; ".join(other) + ")" if other else "masked in table")
    ok = t.mask.copy()
    for key in result.masked:
        m = re.fullmatch(r"grazing \(theta > (.+) deg\)", key)
        if m:
            lim = np.deg2rad(float(m.group(1)))
            g = ok & ((t.theta_i > lim) | (t.theta_o > lim))[:, None]
            status[g] = key
            ok &= ~g
    key = "sigma <= 0 or missing"
    if key in result.masked and t.sigma is not None:
        f, sigma = t.brdf()
        bad = ok & ~(np.isfinite(sigma) & (sigma > 0))
        status[bad] = key
        ok &= ~bad
    fit_mask = getattr(result, "fit_mask", None)
    if fit_mask is not None and fit_mask.shape == ok.shape:
        status[ok & ~fit_mask] = "weight 0"
    return status


def _counts(status) -> dict:
    keys, n = np.unique(status.astype(str), return_counts=True)
    return {str(k): int(c) for k, c in zip(keys, n)}


# ---------------------------------------------------------------------------------------
# params.json


def _jsonable(v):
    """numpy / jax values -> plain JSON types; non-finite floats -> None."""
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, (str, bool)) or v is None:
        return v
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v) if math.isfinite(v) else None
    if hasattr(v, "__array__"):
        a = np.asarray(v)
        if a.dtype == bool:
            return a.tolist()
        if np.issubdtype(a.dtype, np.number):
            return _jsonable(a.astype(np.float64).tolist())
        return _jsonable(a.tolist())
    return str(v)


def _params_record(params) -> tuple[dict, dict]:
    """(every field -> value, static fields -> value) of a Params instance."""
    from ..core.params import StaticSpec, param_specs

    specs = param_specs(params)
    every, static = {}, {}
    for name, spec in specs.items():
        v = getattr(params, name)
        if isinstance(spec, StaticSpec):
            static[name] = v
            every[name] = v
        else:
            every[name] = None if v is None else np.asarray(v, np.float64).tolist()
    return _jsonable(every), _jsonable(static)


def _environment() -> dict:
    import jax

    from .. import __version__

    return dict(appearance_jax=__version__, jax=jax.__version__, numpy=np.__version__,
                python=sys.version.split()[0], platform=platform.platform(),
                x64=bool(jax.config.jax_enable_x64), backend=jax.default_backend())


def _table_record(t: Table) -> dict:
    rec = dict(source=t.source, summary=t.summary(), n_directions=t.n_samples, n_bands=t.n_bands,
               bands=list(t.bands), quantity=t.quantity, in_plane=t.is_in_plane, n_valid=t.n_valid,
               masked=t.masked, sigma=t.sigma is not None)
    if t.spectral:
        rec["wavelengths_nm"] = t.wavelengths
    if t.quantity == "reflectance_factor":
        rec["white_reference"] = t.white_reference
    return _jsonable(rec)


def write_params_json(result, path, *, extra=None, status=None, figures=None) -> dict:
    """Write ``params.json`` (see the module docstring); returns the record written."""
    d = result.to_dict()
    if result.table is not None:
        d["table"] = _table_record(result.table)
        st = entry_status(result) if status is None else status
        d["entries"] = _counts(st)
    every, static = _params_record(result.params)
    d["params"] = every
    d["static"] = static
    if figures:
        d["figures"] = figures
    d["command"] = dict(extra or {})
    d["environment"] = _environment()
    d = _jsonable(d)
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(d, fh, indent=2, allow_nan=False)
        fh.write("\n")
    return d


# ---------------------------------------------------------------------------------------
# residuals.csv


def _metric_residuals(result, f_data, sigma):
    """(residual, residual / its sigma or None) in the fit metric, numpy float64."""
    import jax

    t = result.table
    cos_i = np.cos(t.theta_i)[:, None]
    with jax.enable_x64(True):
        r = np.asarray(residual(result.fitted, f_data, cos_i, result.metric, floor=_FLOOR), np.float64)
        z = None
        if sigma is not None:
            s = np.asarray(residual_scale(f_data, sigma, cos_i, result.metric, floor=_FLOOR), np.float64)
            with np.errstate(divide="ignore", invalid="ignore"):
                z = np.where(np.isfinite(s) & (s > 0), r / s, np.nan)
    return r, z


def _fmt_col(a, spec=".9g"):
    return [format(v, spec) if math.isfinite(v) else "" for v in np.asarray(a, np.float64).tolist()]


def write_residuals_csv(result, path, *, status=None) -> int:
    """Write ``residuals.csv``; returns the number of entries with status ``"fit"``."""
    t = result.table
    n, b = t.values.shape
    st = entry_status(result) if status is None else status
    f_data, sigma = t.brdf()
    fitted = np.broadcast_to(np.asarray(result.fitted, np.float64), (n, b))
    r, z = _metric_residuals(result, np.where(t.mask, f_data, np.nan), sigma)
    plane = in_plane_rows(t, above_only=False)
    signed = np.where(plane, _signed_deg(t), np.nan) + 0.0  # + 0.0: no "-0"
    deg = [np.rad2deg(a) for a in (t.theta_i, t.phi_i, t.theta_o, t.phi_o)]
    rep = lambda a: np.repeat(np.asarray(a), b)  # noqa: E731  per direction -> per entry
    cols = [[str(i) for i in rep(np.arange(n)).tolist()]]
    cols += [_fmt_col(rep(a), ".10g") for a in deg + [signed]]
    cols.append(list(np.tile(np.asarray(t.bands, dtype=object), n)))
    cols.append(_fmt_col(t.values.ravel()))
    cols.append(_fmt_col(np.where(t.mask, f_data, np.nan).ravel()))
    cols.append(_fmt_col(sigma.ravel()) if sigma is not None else [""] * (n * b))
    cols.append(_fmt_col(fitted.ravel()))
    cols.append(_fmt_col(r.ravel()))
    cols.append(_fmt_col(z.ravel()) if z is not None else [""] * (n * b))
    cols.append([str(s).replace(",", ";") for s in st.ravel().tolist()])
    names = ["row", "theta_i", "phi_i", "theta_o", "phi_o", "theta_o_signed", "band", "value", "measured",
             "sigma", "fitted", "residual", "residual_over_sigma", "status"]
    n_fit = int((st == FIT).sum())
    unit = {"brdf": "1/sr", "cosine_weighted_brdf": "1, f |cos theta_o|",
            "reflectance_factor": f"1, R = pi f / {t.white_reference:g}"}[t.quantity]
    metric_text = {"l2": "f_fitted - f_measured [1/sr]",
                   "cos_log": "log(1 + f_fitted cos theta_i) - log(1 + f_measured cos theta_i)",
                   "relative": f"(f_fitted - f_measured) / (|f_measured| + {_FLOOR:g} 1/sr)"}[result.metric]
    head = [
        f"residuals of {result.model} fitted to {' '.join(str(t.source).split())}",
        f"metric {result.metric}, loss {result.loss:.6g} (mean squared residual over the {result.n_valid} fitted entries)",
        "one row per (direction, band) entry of the table, in table order; columns:",
        "  row: direction index in the table (0-based)",
        "  theta_i, phi_i, theta_o, phi_o: directions [deg] (theta from the normal, phi azimuth)",
        "  theta_o_signed: signed theta_o [deg] for in-plane directions (> 0 forward/mirror side, < 0 retro side),"
        " empty out of plane",
        f"  band: band name; value: the table's value in its own quantity, {t.quantity} [{unit}]",
        "  measured, fitted: BRDF f [1/sr] of the table and of the fitted model; empty = no measurement",
        "  sigma: 1-s.d. uncertainty of measured [1/sr], empty without one",
        f"  residual: in the fit metric, {metric_text} (unweighted)",
        "  residual_over_sigma: residual / its propagated sigma (chi), empty without sigma",
        "  status: fit = used by the fit; otherwise why the entry was left out",
        "entries: " + ", ".join(f"{k} {v}" for k, v in _counts(st).items()),
    ]
    if n_fit != result.n_valid:
        head.append(f"note: {n_fit} entries pass the masks but the fit used {result.n_valid} "
                    "(sample weights of 0 are not visible here)")
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write("".join(f"# {h}\n" for h in head))
        fh.write(",".join(names) + "\n")
        fh.write("".join(",".join(row) + "\n" for row in zip(*cols)))
    return n_fit


# ---------------------------------------------------------------------------------------
# geometry and colour helpers


def in_plane_rows(t: Table, *, above_only: bool = True) -> np.ndarray:
    """(N,) bool: directions in the plane of incidence (phi_o - phi_i = 0 or pi, or theta_o = 0).

    An in-plane table (:attr:`Table.is_in_plane`) counts as in-plane everywhere. ``above_only``
    drops directions at or below the horizon.
    """
    if t.is_in_plane:
        rows = np.ones(t.n_samples, bool)
    else:
        d = np.mod(t.phi_o - t.phi_i, 2 * np.pi)
        rows = (d < _PLANE_TOL) | (np.abs(d - np.pi) < _PLANE_TOL) | (d > 2 * np.pi - _PLANE_TOL)
        rows |= t.theta_o < _PLANE_TOL
    if above_only:
        rows &= (np.cos(t.theta_i) > _HORIZON_COS) & (np.cos(t.theta_o) > _HORIZON_COS)
    return rows


def _signed_deg(t: Table) -> np.ndarray:
    """Signed theta_o [deg] as :meth:`Table.signed_theta_o` defines it (meaningful for in-plane rows)."""
    return np.rad2deg(np.where(np.cos(t.phi_o - t.phi_i) > 0, -t.theta_o, t.theta_o))


def _rgb(t: Table, f: np.ndarray) -> np.ndarray:
    """(N, 3) linear sRGB of BRDF values f (N, B) on table t's bands; NaN where unknown."""
    f = np.asarray(f, np.float64)
    if t.spectral:  # as Table.to_rgb: reflectance-like spectra under D65; a gap in a spectrum -> unknown colour
        from ..core.spectral import spectrum_to_linear_srgb

        ok = np.isfinite(f).all(axis=1, keepdims=True)
        rgb = np.asarray(spectrum_to_linear_srgb(np.where(np.isfinite(f), f, 0.0), t.wavelengths, "D65"), np.float64)
        return np.where(ok, rgb, np.nan)
    if f.shape[1] == 3:
        return f
    return np.repeat(f.mean(axis=1, keepdims=True), 3, axis=1)  # grey (NaN if any band is)


def _srgb(linear):
    from ..core.spectral import linear_to_srgb

    x = np.clip(np.nan_to_num(np.asarray(linear, np.float64), nan=0.0), 0.0, 1.0)
    return np.clip(np.asarray(linear_to_srgb(x), np.float64), 0.0, 1.0)


def _exposure(fcos_rgb) -> float:
    v = np.asarray(fcos_rgb, np.float64)
    v = np.nanmax(np.where(np.isfinite(v), v, -np.inf), axis=-1) if v.size else v
    v = v[np.isfinite(v) & (v > 0)]
    if v.size == 0:
        return 1.0
    return float(1.0 / np.percentile(v, 99))


def _log_err(fit_rgb, meas_rgb):
    with np.errstate(invalid="ignore"):
        yf = np.maximum(fit_rgb @ _Y, 0.0)
        ym = np.maximum(meas_rgb @ _Y, 0.0)
        return np.log10((yf + _EPS) / (ym + _EPS))


def _eval_model(model, params, ti_rad, to_rad, n_bands):
    """Model BRDF (M, n_bands) at in-plane directions (signed theta_o), numpy float64."""
    import jax.numpy as jnp

    from ..core.frame import in_plane_directions

    wi, wo = in_plane_directions(jnp.asarray(ti_rad), jnp.asarray(to_rad))
    out = model.eval(params, wi, wo)
    if isinstance(out, tuple):
        out = out[0]
    out = np.asarray(out, np.float64)
    if out.ndim == 1:
        out = out[:, None]
    return np.broadcast_to(out, (out.shape[0], n_bands))


def _get_model(result, model):
    if model is None:
        from .. import registry

        return registry.get(result.model)
    if isinstance(model, str):
        from .. import registry

        return registry.get(model)
    return model


@dataclass
class _Plane:
    """De-duplicated in-plane points of a table: angles [deg] and linear-RGB f (not f cos)."""

    ti: np.ndarray
    to: np.ndarray
    meas: np.ndarray  # (M, 3), NaN = no measurement
    fit: np.ndarray  # (M, 3)
    n_rows: int
    regular: bool
    enough: bool


def _plane_points(t: Table, meas_rgb, fit_rgb) -> _Plane:
    rows = in_plane_rows(t)
    ti = np.round(np.rad2deg(t.theta_i[rows]), 6)
    to = np.round(_signed_deg(t)[rows], 6)
    if rows.sum() == 0:
        e = np.zeros((0, 3))
        return _Plane(np.zeros(0), np.zeros(0), e, e, 0, False, False)
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
    return _Plane(keys[:, 0], keys[:, 1], meas, fit, int(rows.sum()), bool(regular), enough)


def _edges(c):
    c = np.asarray(c, np.float64)
    if c.size == 1:
        return np.array([c[0] - 2.5, c[0] + 2.5])
    mid = 0.5 * (c[1:] + c[:-1])
    return np.concatenate([[c[0] - (mid[0] - c[0])], mid, [c[-1] + (c[-1] - mid[-1])]])


def _grid_image(p: _Plane, values):
    """(ti_edges, to_edges, image (n_ti, n_to, k)) of the regular in-plane points; NaN = no sample."""
    uti, uto = np.unique(p.ti), np.unique(p.to)
    img = np.full((uti.size, uto.size, values.shape[1]), np.nan)
    img[np.searchsorted(uti, p.ti), np.searchsorted(uto, p.to)] = values
    return np.clip(_edges(uti), 0.0, 90.0), np.clip(_edges(uto), -90.0, 90.0), img


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


def _raster_images(p: _Plane, *values, step=0.5):
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
    return (_edges(y), _edges(x), *imgs)


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _short(text, n=70):
    text = " ".join(str(text).split())
    return text if len(text) <= n else text[: n - 3] + "..."


def _title(result) -> str:
    return (f"{result.model} fit ({result.metric} metric, {result.solver}): loss {result.loss:.3g}, "
            f"{result.n_valid} values\n{_short(result.table.source, 90)}")


def _style_map_axes(ax, title):
    ax.set_title(title, fontsize=10)
    ax.set_xlabel(r"signed $\theta_o$ [deg]  (< 0: retro side, > 0: forward)")
    ax.set_ylabel(r"$\theta_i$ [deg]")
    ax.set_facecolor("black")


# ---------------------------------------------------------------------------------------
# figures


def plot_maps(result, path, *, model=None) -> str:
    """Write ``maps.png``; returns a one-line description of what was drawn (for params.json)."""
    plt = _plt()
    t = result.table
    f_data, _ = t.brdf()
    meas_rgb = _rgb(t, np.where(t.mask, f_data, np.nan))
    fit_rgb = _rgb(t, np.asarray(result.fitted, np.float64))
    p = _plane_points(t, meas_rgb, fit_rgb)
    if p.enough:
        cos_o = np.cos(np.deg2rad(p.to))[:, None]
        k = _exposure(p.meas * cos_o)
        if p.regular:
            ye, xe, m_img = _grid_image(p, p.meas * cos_o)
            _, _, f_img = _grid_image(p, p.fit * cos_o)
            _, _, e_img = _grid_image(p, _log_err(p.fit, p.meas)[:, None])
            how = "cells of the in-plane grid"
        else:
            ye, xe, m_img, f_img, e_img = _raster_images(p, p.meas * cos_o, p.fit * cos_o,
                                                         _log_err(p.fit, p.meas)[:, None])
            how = "nearest in-plane sample (scattered points)"
        which = ("all samples (in-plane table)" if t.is_in_plane else
                 f"in-plane subset: {p.n_rows} of {t.n_samples} directions")
        fig, axes = plt.subplots(1, 3, figsize=(17, 4.9), dpi=100, constrained_layout=True)
        for ax, img, name in ((axes[0], m_img, "measured"), (axes[1], f_img, "fitted")):
            ax.pcolormesh(xe, ye, _srgb(k * img), shading="flat")
            _style_map_axes(ax, rf"{name}: sRGB of $f\cos\theta_o$ (exposure x{k:.3g})")
        e = e_img[..., 0]
        fin = np.abs(e[np.isfinite(e)])
        lim = float(np.clip(np.percentile(fin, 99) if fin.size else 1.0, 0.05, 1.0))
        cmap = plt.get_cmap("RdBu_r").with_extremes(bad="black")
        im = axes[2].pcolormesh(xe, ye, np.ma.masked_invalid(e), cmap=cmap, vmin=-lim, vmax=lim, shading="flat")
        _style_map_axes(axes[2], "log10(fitted / measured), luminance")
        fig.colorbar(im, ax=axes[2], label=r"$\log_{10}$ ratio (+: model too bright)")
        for ax in axes:
            lo, hi = ax.get_xlim()
            ax.plot([0, 90], [0, 90], color="white", lw=0.6, ls=":", alpha=0.5)  # mirror direction
            ax.set_xlim(lo, hi)
            ax.set_ylim(ye[0], ye[-1])
        fig.suptitle(_title(result) + f"  [{which}; {how}]", fontsize=10)
        desc = f"{which}; {how}; exposure {k:.4g} (99th percentile of measured f cos theta_o -> 1)"
    else:
        mdl = _get_model(result, model)
        tid = np.arange(0.0, 86.0, 1.0)
        tod = np.arange(-89.0, 90.0, 1.0)
        gi, go = np.meshgrid(tid, tod, indexing="ij")
        f = _eval_model(mdl, result.params, np.deg2rad(gi.ravel()), np.deg2rad(go.ravel()), t.n_bands)
        rgb = _rgb(t, f) * np.cos(np.deg2rad(go.ravel()))[:, None]
        ok = t.mask.all(axis=1)
        k = _exposure(meas_rgb[ok] * np.abs(np.cos(t.theta_o[ok]))[:, None])
        fig, axes = plt.subplots(1, 2, figsize=(13, 4.9), dpi=100, constrained_layout=True,
                                 gridspec_kw=dict(width_ratios=[1, 1.6]))
        _scatter_axes(axes[0], t, result, lum=True)
        axes[1].pcolormesh(_edges(tod), _edges(tid), _srgb(k * rgb.reshape(gi.shape + (3,))), shading="flat")
        _style_map_axes(axes[1], rf"fitted model, dense in-plane: sRGB of $f\cos\theta_o$ (exposure x{k:.3g})")
        fig.suptitle(_title(result) + "  [no in-plane samples to map: model rendered densely]", fontsize=10)
        desc = (f"table has too few in-plane samples ({p.n_rows} directions): fitted model rendered densely "
                f"in-plane, measured vs fitted scatter of all valid entries; exposure {k:.4g}")
    fig.savefig(path)
    plt.close(fig)
    return desc


def _scatter_axes(ax, t, result, lum=False):
    f_data, _ = t.brdf()
    fitted = np.broadcast_to(np.asarray(result.fitted, np.float64), f_data.shape)
    used = entry_status(result) == FIT
    if lum:
        m = _rgb(t, np.where(t.mask, f_data, np.nan)) @ _Y
        f = _rgb(t, fitted) @ _Y
        sel = used.all(axis=1) & np.isfinite(m) & np.isfinite(f)
        series = [("luminance", "k", m[sel], f[sel])]
    else:
        colours = dict(R="tab:red", G="tab:green", B="tab:blue")
        cmap = _plt().get_cmap("viridis")
        series = []
        for j, band in enumerate(t.bands):
            sel = used[:, j] & np.isfinite(f_data[:, j]) & np.isfinite(fitted[:, j])
            c = colours.get(band, cmap(j / max(t.n_bands - 1, 1)))
            series.append((band, c, f_data[sel, j], fitted[sel, j]))
    allv = np.concatenate([np.concatenate([a, b]) for _, _, a, b in series]) if series else np.zeros(0)
    pos = allv[allv > 0]
    floor = (pos.max() * 1e-5) if pos.size else 1e-6
    lo, hi = (max(pos.min(), floor) / 1.5, pos.max() * 1.5) if pos.size else (1e-3, 1.0)
    for label, c, a, b in series:
        ax.loglog(np.maximum(a, floor), np.maximum(b, floor), ".", ms=3, alpha=0.5, color=c,
                  label=label if len(series) <= 6 else None)
    ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_xlabel("measured f [1/sr]")
    ax.set_ylabel("fitted f [1/sr]")
    e = result.metrics
    ax.set_title(f"fitted vs measured ({sum(a.size for *_, a, _ in series)} values)\n"
                 f"rmse {e.get('rmse', np.nan):.3g} 1/sr, log_rmse {e.get('log_rmse', np.nan):.3g}", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    if len(series) <= 6:
        ax.legend(fontsize=8, markerscale=3)


def plot_scatter(result, path) -> None:
    """Write ``scatter.png``: fitted vs measured BRDF per band, log-log."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5.6, 5.4), dpi=100, constrained_layout=True)
    _scatter_axes(ax, result.table, result)
    fig.suptitle(_title(result), fontsize=9)
    fig.savefig(path)
    plt.close(fig)


def _pick(values, n=4):
    v = np.unique(values)
    if v.size <= n:
        return v
    return np.unique(v[np.round(np.linspace(0, v.size - 1, n)).astype(int)])


def plot_slices(result, path, *, model=None) -> str:
    """Write ``slices.png`` (polar f cos theta_o against signed theta_o); returns a description."""
    plt = _plt()
    t = result.table
    mdl = _get_model(result, model)
    f_data, _ = t.brdf()
    meas_rgb = _rgb(t, np.where(t.mask, f_data, np.nan))
    p = _plane_points(t, meas_rgb, _rgb(t, np.asarray(result.fitted, np.float64)))
    have = np.isfinite(p.meas).all(axis=1) if p.ti.size else np.zeros(0, bool)
    if p.enough and p.regular:
        targets, tol = _pick(p.ti[have]), 1e-6
    elif p.enough:  # scattered (MERL grid): round incidence angles with enough samples near them
        tol = 2.5
        near = [a for a in (0.0, 15.0, 30.0, 45.0, 60.0, 75.0) if (have & (np.abs(p.ti - a) <= tol)).sum() >= 5]
        targets = _pick(np.array(near)) if near else _pick(np.round(p.ti[have]))
    if p.enough:
        desc = "measured in-plane samples" + ("" if p.regular else f" within {tol:g} deg of each theta_i")
    else:
        above = np.cos(t.theta_i) > _HORIZON_COS
        targets = _pick(np.round(np.rad2deg(t.theta_i[above]), 1)) if above.any() else np.array([0.0, 30.0, 60.0])
        targets = targets[targets < 89.0]
        tol = None
        desc = "no in-plane samples: fitted model only"
    tod = np.linspace(-89.0, 89.0, 357)
    rgb_bands = t.spectral or t.n_bands == 3
    chans = [("R", "tab:red", 0), ("G", "tab:green", 1), ("B", "tab:blue", 2)] if rgb_bands else [("f", "k", 0)]
    ncol = min(len(targets), 2) or 1
    nrow = int(math.ceil(len(targets) / ncol)) or 1
    from matplotlib.ticker import MaxNLocator

    # Polar axes keep a square box and draw the upper half disc in its middle half, so the
    # boxes are placed by hand (overlapping) to pack the half discs tightly.
    cw, side, ch, top, bottom = 5.2, 4.3, 3.0, 0.95, 0.45  # inches: cell width, box side, cell height
    fig_w, fig_h = cw * ncol, ch * nrow + top + bottom
    fig = plt.figure(figsize=(fig_w, fig_h), dpi=100)
    for i, ti in enumerate(targets):
        r, c = divmod(i, ncol)
        y_base = bottom + (nrow - 1 - r) * ch + 0.55  # the wedge's flat edge (theta_o = +-90)
        rect = [(c * cw + (cw - side) / 2) / fig_w, (y_base - side / 4) / fig_h, side / fig_w, side / fig_h]
        ax = fig.add_axes(rect, projection="polar")
        ax.set_theta_zero_location("N")
        ax.set_theta_direction(-1)  # positive (forward) theta_o to the right, as on the maps
        ax.set_thetamin(-90)
        ax.set_thetamax(90)
        f = _eval_model(mdl, result.params, np.full(tod.shape, np.deg2rad(ti)), np.deg2rad(tod), t.n_bands)
        curve = _rgb(t, f) * np.cos(np.deg2rad(tod))[:, None]
        rmax = np.nanmax(curve) if np.isfinite(curve).any() else 1.0
        if tol is not None:
            sel = have & (np.abs(p.ti - ti) <= tol)
            pts = p.meas[sel] * np.cos(np.deg2rad(p.to[sel]))[:, None]
            if pts.size:
                rmax = max(rmax, np.nanmax(pts))
        for name, c, j in chans:
            ax.plot(np.deg2rad(tod), curve[:, j], color=c, lw=1.3, label=f"model {name}" if i == 0 else None)
            if tol is not None and pts.size:
                ax.plot(np.deg2rad(p.to[sel]), pts[:, j], "o", ms=3, color=c, mfc="none",
                        label=f"measured {name}" if i == 0 else None)
        rmax = float(rmax) * 1.08 if np.isfinite(rmax) and rmax > 0 else 1.0
        ax.set_rlim(0, rmax)
        ax.yaxis.set_major_locator(MaxNLocator(3))
        ax.tick_params(axis="y", labelsize=7)
        ax.tick_params(axis="x", labelsize=8, pad=1)
        ax.plot([np.deg2rad(-ti)] * 2, [0, rmax], color="0.4", lw=1, ls="--")  # the incident direction
        ax.annotate(r"$\omega_i$", (np.deg2rad(-ti), rmax * 0.92), color="0.3", fontsize=9)
        ax.annotate(rf"$\theta_i$ = {ti:g}°", (0.5, 0.75), xycoords="axes fraction", xytext=(0, 22),
                    textcoords="offset points", ha="center", va="bottom", fontsize=10)
        ax.annotate(r"$f\cos\theta_o$ [1/sr] against signed $\theta_o$", (0.5, 0.25), xycoords="axes fraction",
                    xytext=(0, -16), textcoords="offset points", ha="center", va="top", fontsize=8)
    fig.legend(loc="lower center", ncol=6, fontsize=8)
    fig.suptitle(_title(result) + f"\n{desc}; retro side left, forward right", fontsize=10,
                 y=1 - 0.08 / fig_h, va="top")
    fig.savefig(path)
    plt.close(fig)
    return desc


# ---------------------------------------------------------------------------------------
# all of it


def write_report(result, out_dir, *, model=None, progress=print, extra=None, plots: bool = True) -> dict:
    """Write params.json, residuals.csv, maps.png, slices.png and scatter.png to ``out_dir``.

    Args:
        result: a :class:`~appearance_jax.fit.solve.FitResult` with its ``table`` and ``fitted``.
        out_dir: folder (created if needed).
        model: the fitted model (a Model or a registered name; default ``registry.get(result.model)``),
            needed to draw the model densely in-plane.
        progress: called with one line per file written (``None``: silent).
        extra: recorded as ``command`` in params.json (command line, options, ...).
        plots: False writes only params.json and residuals.csv.

    Returns:
        {"params": path, "residuals": path, "maps": path, "slices": path, "scatter": path}
        (the figures only with ``plots``).
    """
    if result.table is None or result.fitted is None:
        raise ValueError("write_report: the FitResult has no table/fitted values (fit() sets them)")
    os.makedirs(out_dir, exist_ok=True)
    say = progress or (lambda *_: None)
    paths = {}
    status = entry_status(result)
    p = os.path.join(out_dir, "residuals.csv")
    n = write_residuals_csv(result, p, status=status)
    paths["residuals"] = p
    say(f"  {p}: {status.size} entries ({n} fitted)")
    figures = {}
    if plots:
        mdl = _get_model(result, model)
        for name, fn in (("maps", lambda q: plot_maps(result, q, model=mdl)),
                         ("slices", lambda q: plot_slices(result, q, model=mdl)),
                         ("scatter", lambda q: plot_scatter(result, q))):
            q = os.path.join(out_dir, f"{name}.png")
            d = fn(q)
            paths[name] = q
            if d:
                figures[name] = d
            say(f"  {q}" + (f": {d}" if d else ""))
    q = os.path.join(out_dir, "params.json")
    write_params_json(result, q, extra=extra, status=status, figures=figures)
    paths["params"] = q
    say(f"  {q}")
    return {k: paths[k] for k in ("params", "residuals", "maps", "slices", "scatter") if k in paths}
