"""The report's figures: ``maps.png``, ``slices.png`` and ``scatter.png`` (see :mod:`~appearance_jax.fit.report`).

Figures use matplotlib's Agg backend (no display needed).
"""

from __future__ import annotations

import math

import numpy as np

from ...core.spectral import LUMINANCE_WEIGHTS
from ..solve.residuals import FLOOR
from .geometry import cell_edges, eval_in_plane, grid_image, plane_points, raster_images, reciprocity_fill
from ..tables.table import HORIZON_COS
from .records import FIT, entry_status
from .tonemap import log_tone, symmetric_limit

__all__ = ["plot_maps", "maps_figure", "plot_slices", "slices_figure", "plot_scatter", "scatter_figure", "get_model"]


def _log_err(fit_rgb, meas_rgb):
    with np.errstate(invalid="ignore"):
        yf = np.maximum(fit_rgb @ LUMINANCE_WEIGHTS, 0.0)
        ym = np.maximum(meas_rgb @ LUMINANCE_WEIGHTS, 0.0)
        return np.log10((yf + FLOOR) / (ym + FLOOR))


def get_model(result, model=None):
    """The model to draw: ``model`` (a Model or a registered name), by default the one ``result`` fitted."""
    if model is None or isinstance(model, str):
        from ... import registry

        return registry.get(result.model if model is None else model)
    return model


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
            f"{result.n_valid} values\n{_short(result.table.source, 130)}")


def _style_map_axes(ax, title):
    # y=1.0 (here and below): a fixed title position; matplotlib's automatic one measures every tick
    # label of the axes at each draw to clear decorations above them, and these axes have none there
    # (the same pixels; ~5 % of the report's time)
    ax.set_title(title, fontsize=10, y=1.0)
    ax.set_xlabel(r"signed $\theta_o$ [deg]  (< 0: retro side, > 0: forward)")
    ax.set_ylabel(r"$\theta_i$ [deg]")
    ax.set_facecolor("black")


# ---------------------------------------------------------------------------------------
# figures


def _save(fig, path, dpi) -> None:
    fig.savefig(path, dpi=dpi)
    _plt().close(fig)


def _margins(fig, left, right, bottom, top, wspace=0.0, hspace=0.0):
    """A fixed layout in inches (margins; gaps between panels): the report's figures have known
    contents, and matplotlib's constrained layout draws each figure twice to find them (a quarter
    of a warm run's plotting time)."""
    w, h = fig.get_size_inches()
    gs = fig.axes[0].get_gridspec() if fig.axes else None
    ncol, nrow = (gs.ncols, gs.nrows) if gs is not None else (1, 1)
    aw = (w - left - right - wspace * (ncol - 1)) / ncol
    ah = (h - bottom - top - hspace * (nrow - 1)) / nrow
    fig.subplots_adjust(left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h,
                        wspace=wspace / aw, hspace=hspace / ah)


def _place_row(fig, axes, *, left, gaps, right, bottom, top):
    """Place ``axes`` side by side (inches): ``gaps[k]`` between panels k and k + 1."""
    w, h = fig.get_size_inches()
    aw = (w - left - right - sum(gaps)) / len(axes)
    x = left
    for ax, g in zip(axes, tuple(gaps) + (0.0,)):
        ax.set_position([x / w, bottom / h, aw / w, (h - bottom - top) / h])
        x += aw + g


def _bar_axes(fig, ax, gap=0.12, width=0.18):
    """Axes for a colour bar right of ``ax`` (inches: gap, width), as tall as ``ax``."""
    w, h = fig.get_size_inches()
    b = ax.get_position()
    return fig.add_axes([b.x1 + gap / w, b.y0, width / w, b.height])


def _sparse_log_ticks(axis, span):
    """Minor ticks of a log axis at 2 and 5 only, unlabelled, and none beyond 4 decades: the
    default (2..9 in every decade, each a labelled Tick) made drawing the report's log axes
    the slowest part of a warm run, for ticks too dense to read."""
    from matplotlib.ticker import LogLocator, NullFormatter, NullLocator

    axis.set_minor_locator(LogLocator(subs=(2.0, 5.0)) if span <= 1e4 else NullLocator())
    axis.set_minor_formatter(NullFormatter())


def _rgba(img):
    """(..., 3) sRGB with NaN -> (..., 4) RGBA, transparent where there is no value."""
    ok = np.isfinite(img).all(axis=-1, keepdims=True)
    return np.concatenate([np.where(ok, img, 0.0), ok.astype(np.float64)], axis=-1)


def _hatch(ax, xe, ye, filled_img):
    """Hatch the cells of ``filled_img`` (n_y, n_x) > 0.5: values filled by reciprocity.

    One rectangle per horizontal run of filled cells, not one per cell: on a MERL-sized grid
    (0.5 deg cells) a pcolor of single cells was 10 of the 11 s a warm report took to draw."""
    from matplotlib.collections import PolyCollection

    f = np.nan_to_num(filled_img) > 0.5
    if not f.any():
        return
    pad = np.zeros((f.shape[0], 1), bool)
    edges = np.diff(np.concatenate([pad, f, pad], axis=1).astype(np.int8), axis=1)
    rows, starts = np.nonzero(edges == 1)
    _, stops = np.nonzero(edges == -1)  # same row order as the starts: runs alternate start/stop
    x0, x1, y0, y1 = xe[starts], xe[stops], ye[rows], ye[rows + 1]
    verts = np.stack([np.stack([x0, y0], -1), np.stack([x1, y0], -1),
                      np.stack([x1, y1], -1), np.stack([x0, y1], -1)], axis=1)
    pc = PolyCollection(verts, hatch="//", facecolors="none", edgecolors=[(1, 1, 1, 0.45)],
                        linewidths=0.0)
    pc.set_gid("reciprocity_fill")
    ax.add_collection(pc, autolim=False)


def maps_figure(result, *, model=None, dpi=90):
    """The figure of ``maps.png`` and its one-line description: measured, fitted and residual
    theta_i x signed theta_o maps (see :mod:`~appearance_jax.fit.report`). Returns (Figure, str);
    the caller saves and closes it (:func:`plot_maps` does both)."""
    plt = _plt()
    t = result.table
    f_data, _ = t.brdf()
    meas_rgb = t.linear_rgb(np.where(t.mask, f_data, np.nan))
    fit_rgb = t.linear_rgb(np.asarray(result.fitted, np.float64))
    p = plane_points(t, meas_rgb, fit_rgb)
    if not p.enough:
        return _model_only_maps(result, model, p, dpi)
    p = reciprocity_fill(p)
    cos_o = np.cos(np.deg2rad(p.to))[:, None]
    mc, fc, err = p.meas * cos_o, p.fit * cos_o, _log_err(p.fit, p.meas)[:, None]
    tone = log_tone(mc)
    if p.regular:
        ye, xe, m_img = grid_image(p, mc)
        f_img, e_img, h_img = (grid_image(p, v)[2] for v in (fc, err, p.filled[:, None] * 1.0))
        how = "cells of the in-plane grid"
    else:
        ye, xe, m_img, f_img, e_img, h_img = raster_images(p, mc, fc, err, p.filled[:, None] * 1.0)
        how = "nearest in-plane sample (scattered points)"
    which = ("all samples (in-plane table)" if t.is_in_plane else
             f"in-plane subset: {p.n_rows} of {t.n_samples} directions")
    fig, axes = plt.subplots(1, 3, figsize=(17, 5.2), dpi=dpi)
    bar = 1.45  # inches right of a panel for its colour bar, ticks and (two-line) label
    _place_row(fig, axes, left=0.75, gaps=(0.7, bar + 0.6), right=bar, bottom=0.65, top=1.1)
    for ax, img, name in ((axes[0], m_img, "measured"), (axes[1], f_img, "fitted")):
        ax.pcolormesh(xe, ye, _rgba(tone(img)), shading="flat")
        _hatch(ax, xe, ye, h_img[..., 0])
        _style_map_axes(ax, rf"{name}: $f\cos\theta_o$, log-luminance brightness")
    tone.colorbar(fig, None, cax=_bar_axes(fig, axes[1]),
                  label=(r"luminance of $f\cos\theta_o$ [1/sr], log:" + "\n"
                         f"{tone.lo:.2g} to {tone.hi:.3g} ({tone.decades:.1f} decades)"))
    e = e_img[..., 0]
    lim = symmetric_limit(e)
    cmap = plt.get_cmap("RdBu_r").with_extremes(bad="black")
    im = axes[2].pcolormesh(xe, ye, np.ma.masked_invalid(e), cmap=cmap, vmin=-lim, vmax=lim, shading="flat")
    _hatch(axes[2], xe, ye, h_img[..., 0])
    _style_map_axes(axes[2], rf"$\log_{{10}}$(fitted / measured) of luminance, limits $\pm${lim:g}")
    fig.colorbar(im, cax=_bar_axes(fig, axes[2]), extend="both",
                 label=rf"$\log_{{10}}$ ratio (+: model too bright; $\pm${lim:g} = x{10 ** lim:.3g})")
    for ax in axes:
        lo, hi = ax.get_xlim()
        ax.plot([0, 90], [0, 90], color="white", lw=0.8, ls=":", alpha=0.7, gid="mirror")
        ax.set_xlim(lo, hi)
        ax.set_ylim(ye[0], ye[-1])
    axes[0].annotate(r"mirror $\theta_o=\theta_i$", (0.97, 0.03), xycoords="axes fraction", ha="right",
                     va="bottom", fontsize=8, color="white")
    fill = (f"; hatched: {int(p.filled.sum())} points filled by reciprocity f(i,o) = f(o,i)" if p.filled.any()
            else "")
    fig.suptitle(_title(result) + f"  [{which}; {how}]\nblack: no sample{fill}; "
                 f"hue = colour, brightness = log10 luminance (same scale in both panels)", fontsize=10)
    desc = f"{which}; {how}; {tone.describe()}; residual limits +-{lim:g} decades" + (
        f"; {int(p.filled.sum())} points filled by reciprocity (hatched)" if p.filled.any() else "")
    return fig, desc


def _model_only_maps(result, model, p, dpi):
    plt = _plt()
    t = result.table
    mdl = get_model(result, model)
    tid = np.arange(0.0, 86.0, 1.0)
    tod = np.arange(-89.0, 90.0, 1.0)
    gi, go = np.meshgrid(tid, tod, indexing="ij")
    f = eval_in_plane(mdl, result.params, np.deg2rad(gi.ravel()), np.deg2rad(go.ravel()), t.n_bands)
    rgb = t.linear_rgb(f) * np.cos(np.deg2rad(go.ravel()))[:, None]
    tone = log_tone(rgb)
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.9), dpi=dpi, constrained_layout=True,
                             gridspec_kw=dict(width_ratios=[1, 1.6]))
    _scatter_axes(axes[0], t, result, lum=True)
    axes[1].pcolormesh(cell_edges(tod), cell_edges(tid), _rgba(tone(rgb.reshape(gi.shape + (3,)))), shading="flat")
    _style_map_axes(axes[1], r"fitted model, dense in-plane: $f\cos\theta_o$, log-luminance brightness")
    tone.colorbar(fig, axes[1], label=(r"luminance of $f\cos\theta_o$ [1/sr], log: "
                                       f"{tone.lo:.2g} to {tone.hi:.3g}"))
    fig.suptitle(_title(result) + "  [no in-plane samples to map: model rendered densely]", fontsize=10)
    desc = (f"table has too few in-plane samples ({p.n_rows} directions): fitted model rendered densely "
            f"in-plane, measured vs fitted scatter of all valid entries; {tone.describe()}")
    return fig, desc


def plot_maps(result, path, *, model=None, dpi=90) -> str:
    """Write ``maps.png`` (:func:`maps_figure`); returns its one-line description (for params.json)."""
    fig, desc = maps_figure(result, model=model, dpi=dpi)
    _save(fig, path, dpi)
    return desc


def _scatter_axes(ax, t, result, lum=False):
    f_data, _ = t.brdf()
    fitted = np.broadcast_to(np.asarray(result.fitted, np.float64), f_data.shape)
    used = entry_status(result) == FIT
    if lum:
        m = t.linear_rgb(np.where(t.mask, f_data, np.nan)) @ LUMINANCE_WEIGHTS
        f = t.linear_rgb(fitted) @ LUMINANCE_WEIGHTS
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
    for axis in (ax.xaxis, ax.yaxis):
        _sparse_log_ticks(axis, hi / lo)
    ax.set_xlabel("measured f [1/sr]")
    ax.set_ylabel("fitted f [1/sr]")
    e = result.metrics
    ax.set_title(f"fitted vs measured ({sum(a.size for *_, a, _ in series)} values)\n"
                 f"rmse {e.get('rmse', np.nan):.3g} 1/sr, log_rmse {e.get('log_rmse', np.nan):.3g}", fontsize=10, y=1.0)
    ax.grid(True, which="both", alpha=0.3)
    if len(series) <= 6:
        ax.legend(fontsize=8, markerscale=3)


def scatter_figure(result, *, dpi=90):
    """The figure of ``scatter.png``: fitted against measured BRDF per band, log-log (a Figure)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5.6, 5.4), dpi=dpi)
    _margins(fig, left=0.85, right=0.2, bottom=0.6, top=1.0)
    _scatter_axes(ax, result.table, result)
    fig.suptitle(_title(result), fontsize=9)
    return fig


def plot_scatter(result, path, *, dpi=90) -> None:
    """Write ``scatter.png`` (:func:`scatter_figure`)."""
    _save(scatter_figure(result, dpi=dpi), path, dpi)


def _pick(values, n=4):
    v = np.unique(values)
    if v.size <= n:
        return v
    return np.unique(v[np.round(np.linspace(0, v.size - 1, n)).astype(int)])


def _slice_targets(t, p):
    """(theta_i values [deg], tolerance [deg] or None, description) of the slices."""
    have = np.isfinite(p.meas).all(axis=1) if p.ti.size else np.zeros(0, bool)
    if p.enough and p.regular:
        return _pick(p.ti[have]), 1e-6, "measured in-plane samples"
    if p.enough:  # scattered (MERL grid): round incidence angles with enough samples near them
        tol = 2.5
        near = [a for a in (0.0, 15.0, 30.0, 45.0, 60.0, 75.0) if (have & (np.abs(p.ti - a) <= tol)).sum() >= 5]
        return (_pick(np.array(near)) if near else _pick(np.round(p.ti[have]))), tol, \
            f"measured in-plane samples within {tol:g} deg of each theta_i"
    above = np.cos(t.theta_i) > HORIZON_COS
    targets = _pick(np.round(np.rad2deg(t.theta_i[above]), 1)) if above.any() else np.array([0.0, 30.0, 60.0])
    return targets[targets < 89.0], None, "no in-plane samples: fitted model only"


MODEL_DECADES = 4.0  # the y axis reaches this many decades below a slice's peak to show the model's tails
POINT_DECADES = 8.0  # measured points further below the peak are drawn at the floor (open triangles)


def _y_range(curve, pts):
    """(floor, top) of a slice's log y axis: every positive measured point lies inside unless it is
    more than POINT_DECADES below the top; the model is shown down to MODEL_DECADES below it."""
    c = curve[np.isfinite(curve) & (curve > 0)]
    q = pts[np.isfinite(pts) & (pts > 0)]
    top = max(c.max() if c.size else 0.0, q.max() if q.size else 0.0)
    if top <= 0:
        return 1e-3, 1.0
    floor = top * 10.0 ** -MODEL_DECADES
    if c.size:
        floor = max(floor, c.min())
    if q.size:
        floor = min(floor, q.min())
    return max(floor, top * 10.0 ** -POINT_DECADES), top


def slices_figure(result, *, model=None, dpi=90):
    """The figure of ``slices.png`` and its description: f cos theta_o [1/sr] per channel on a log
    axis against signed theta_o, one panel per theta_i (up to 4), measured in-plane points
    (markers) and the fitted model evaluated densely in-plane (lines), the mirror direction
    theta_o = theta_i and the retro direction theta_o = -theta_i marked. Returns (Figure, str)."""
    plt = _plt()
    t = result.table
    mdl = get_model(result, model)
    f_data, _ = t.brdf()
    meas_rgb = t.linear_rgb(np.where(t.mask, f_data, np.nan))
    p = plane_points(t, meas_rgb, t.linear_rgb(np.asarray(result.fitted, np.float64)))
    targets, tol, desc = _slice_targets(t, p)
    if p.enough:
        p = reciprocity_fill(p)
        if p.filled.any():
            desc += f"; squares: {int(p.filled.sum())} points filled by reciprocity f(i,o) = f(o,i)"
    have = np.isfinite(p.meas).any(axis=1) if p.ti.size else np.zeros(0, bool)
    tod = np.linspace(-89.5, 89.5, 359)
    chans = ([("R", "tab:red", 0), ("G", "tab:green", 1), ("B", "tab:blue", 2)] if t.spectral or t.n_bands == 3
             else [("f", "k", 0)])
    ncol = min(len(targets), 2) or 1
    nrow = int(math.ceil(len(targets) / ncol)) or 1
    fig, axes = plt.subplots(nrow, ncol, figsize=(6.2 * ncol, 3.4 * nrow + 1.3), dpi=dpi, squeeze=False)
    n_low = 0
    for ax, ti in zip(axes.ravel(), targets):
        f = eval_in_plane(mdl, result.params, np.full(tod.shape, np.deg2rad(ti)), np.deg2rad(tod), t.n_bands)
        curve = t.linear_rgb(f) * np.cos(np.deg2rad(tod))[:, None]
        sel = have & (np.abs(p.ti - ti) <= tol) if tol is not None else np.zeros(p.ti.shape, bool)
        pts = p.meas[sel] * np.cos(np.deg2rad(p.to[sel]))[:, None]
        used = [j for *_, j in chans]
        floor, top = _y_range(curve[:, used], pts[:, used])
        for name, c, j in chans:
            ax.plot(tod, curve[:, j], color=c, lw=1.3, label=f"model {name}")
            for part, marker, what in ((~p.filled[sel], "o", "measured"), (p.filled[sel], "s", "by reciprocity")):
                y = pts[:, j]
                ok = np.isfinite(y) & part
                low = ok & (y < floor)
                n_low += int(low.sum())
                if (ok & ~low).any():
                    ax.plot(p.to[sel][ok & ~low], y[ok & ~low], marker, ms=3.5 if marker == "o" else 3, color=c,
                            mfc="none", ls="none", alpha=1.0 if marker == "o" else 0.6, label=f"{what} {name}")
                if low.any():
                    ax.plot(p.to[sel][low], np.full(low.sum(), floor), "v", ms=4, color=c, mfc="none", ls="none",
                            label=f"{what} {name} <= floor")
        ax.set_yscale("log")
        ax.set_ylim(floor / 1.4, top * 1.6)
        _sparse_log_ticks(ax.yaxis, top / floor)
        ax.set_xlim(-90, 90)
        ax.set_xticks(np.arange(-90, 91, 30))
        ax.axvline(ti, color="0.25", lw=1.0, ls="--", gid="mirror", label=r"mirror $\theta_o=\theta_i$")
        if ti > 0:
            ax.axvline(-ti, color="0.55", lw=1.0, ls=":", gid="retro", label=r"retro $\theta_o=-\theta_i$")
        ax.set_title(rf"$\theta_i$ = {ti:g}°", fontsize=10, y=1.0)
        ax.set_xlabel(r"signed $\theta_o$ [deg]  (< 0: retro side, > 0: forward)", fontsize=9)
        ax.set_ylabel(r"$f\cos\theta_o$ [1/sr] (log)", fontsize=9)
        ax.grid(True, which="major", alpha=0.3)
        ax.tick_params(labelsize=8)
    for ax in axes.ravel()[len(targets):]:
        ax.set_visible(False)
    handles = {}
    for ax in axes.ravel()[:len(targets)]:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(lab, h)
    per_channel = max(sum(lab.endswith(f" {chans[0][0]}") for lab in handles), 1)  # one legend column per channel
    ncol_legend = int(math.ceil(len(handles) / per_channel))
    fig.legend(list(handles.values()), list(handles.keys()), loc="lower center", bbox_to_anchor=(0.5, 0.0),
               fontsize=8, ncol=ncol_legend)
    # inches: tick labels + x label (0.55) and the legend (0.17 per row) below, 4 title lines above
    _margins(fig, left=0.8, right=0.2, bottom=0.6 + 0.17 * per_channel + 0.05, top=1.15,
             wspace=0.9, hspace=0.85)
    if n_low:
        desc += f"; {n_low} values more than {POINT_DECADES:g} decades below the peak drawn at the floor"
    fig.suptitle(_title(result) + f"\n{desc}\neach panel: log axis from its peak down to its lowest measured "
                 f"point (the model down to {MODEL_DECADES:g} decades below the peak)", fontsize=9)
    return fig, desc


def plot_slices(result, path, *, model=None, dpi=90) -> str:
    """Write ``slices.png`` (:func:`slices_figure`); returns its description."""
    fig, desc = slices_figure(result, model=model, dpi=dpi)
    _save(fig, path, dpi)
    return desc
