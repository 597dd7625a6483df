"""The report's figures: ``maps.png``, ``slices.png`` and ``scatter.png`` (see :mod:`~appearance_jax.fit.report`).

Figures use matplotlib's Agg backend (no display needed).
"""

from __future__ import annotations

import math

import numpy as np

from ...core.spectral import LUMINANCE_WEIGHTS, linear_to_srgb
from ..solve.residuals import FLOOR
from ..tables.table import HORIZON_COS
from .geometry import cell_edges, eval_in_plane, grid_image, plane_points, raster_images
from .records import FIT, entry_status

__all__ = ["plot_maps", "plot_slices", "plot_scatter", "get_model"]


def _srgb(linear):
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
    meas_rgb = t.linear_rgb(np.where(t.mask, f_data, np.nan))
    fit_rgb = t.linear_rgb(np.asarray(result.fitted, np.float64))
    p = plane_points(t, meas_rgb, fit_rgb)
    if p.enough:
        cos_o = np.cos(np.deg2rad(p.to))[:, None]
        k = _exposure(p.meas * cos_o)
        if p.regular:
            ye, xe, m_img = grid_image(p, p.meas * cos_o)
            _, _, f_img = grid_image(p, p.fit * cos_o)
            _, _, e_img = grid_image(p, _log_err(p.fit, p.meas)[:, None])
            how = "cells of the in-plane grid"
        else:
            ye, xe, m_img, f_img, e_img = raster_images(p, p.meas * cos_o, p.fit * cos_o,
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
        mdl = get_model(result, model)
        tid = np.arange(0.0, 86.0, 1.0)
        tod = np.arange(-89.0, 90.0, 1.0)
        gi, go = np.meshgrid(tid, tod, indexing="ij")
        f = eval_in_plane(mdl, result.params, np.deg2rad(gi.ravel()), np.deg2rad(go.ravel()), t.n_bands)
        rgb = t.linear_rgb(f) * np.cos(np.deg2rad(go.ravel()))[:, None]
        ok = t.mask.all(axis=1)
        k = _exposure(meas_rgb[ok] * np.abs(np.cos(t.theta_o[ok]))[:, None])
        fig, axes = plt.subplots(1, 2, figsize=(13, 4.9), dpi=100, constrained_layout=True,
                                 gridspec_kw=dict(width_ratios=[1, 1.6]))
        _scatter_axes(axes[0], t, result, lum=True)
        axes[1].pcolormesh(cell_edges(tod), cell_edges(tid), _srgb(k * rgb.reshape(gi.shape + (3,))), shading="flat")
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
    mdl = get_model(result, model)
    f_data, _ = t.brdf()
    meas_rgb = t.linear_rgb(np.where(t.mask, f_data, np.nan))
    p = plane_points(t, meas_rgb, t.linear_rgb(np.asarray(result.fitted, np.float64)))
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
        above = np.cos(t.theta_i) > HORIZON_COS
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
        f = eval_in_plane(mdl, result.params, np.full(tod.shape, np.deg2rad(ti)), np.deg2rad(tod), t.n_bands)
        curve = t.linear_rgb(f) * np.cos(np.deg2rad(tod))[:, None]
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
