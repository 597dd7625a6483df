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
    retro-reflection side; theta_i vertical), as in Fig. 4.4 of Padrón 2025. Brightness is
    linear in log10 of the luminance of f cos theta_o over a range stated in the colour bar
    (:mod:`~appearance_jax.fit.report.tonemap`: the measured peak down to at most 6 decades
    below it; dark grey = the bottom of the range, black = no sample), hue and saturation
    kept; measured and fitted panels share one mapping. A third panel shows
    log10(fitted / measured) of the luminance with symmetric limits stated in its title. Cells
    missing at (a, b) but measured at (b, a) are filled by reciprocity and hatched
    (:func:`~appearance_jax.fit.report.geometry.reciprocity_fill`). Spectral tables are shown
    in linear sRGB (:meth:`Table.to_rgb`), single-band tables in grey. Which samples are drawn:

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
    One Cartesian panel per theta_i (up to 4): f cos theta_o (per channel, 1/sr, log y axis)
    against signed theta_o; measured in-plane points (markers; squares where filled by
    reciprocity) and the fitted model evaluated densely in-plane (lines). Every measured point
    is inside the frame (zeros and points more than 8 decades below the peak are drawn at the
    floor as triangles and counted); the mirror (theta_o = theta_i, dashed) and
    retro-reflection (theta_o = -theta_i, dotted) directions are marked. For a table without
    in-plane samples only the model is drawn.
``scatter.png``
    Fitted against measured BRDF per band, log-log, over the fitted entries, with the y = x line.

Figures use matplotlib's Agg backend (no display needed).

Modules: ``records`` (params.json, residuals.csv and which entries were fitted), ``figures``
(maps, slices, scatter; ``*_figure`` return the matplotlib Figure), ``tonemap`` (the maps'
log mapping), ``geometry`` (a table's in-plane points, their images, the reciprocity fill) and ``write``
(:func:`write_report`).
"""

from .figures import maps_figure, plot_maps, plot_scatter, plot_slices, scatter_figure, slices_figure
from .records import FIT, entry_status, write_params_json, write_residuals_csv
from .write import write_report

__all__ = ["write_report", "write_params_json", "write_residuals_csv", "entry_status", "plot_maps",
           "plot_slices", "plot_scatter", "maps_figure", "slices_figure", "scatter_figure", "FIT"]
