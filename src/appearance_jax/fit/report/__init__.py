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

Modules: ``records`` (params.json, residuals.csv and which entries were fitted), ``figures``
(maps, slices, scatter), ``geometry`` (a table's in-plane points and their images) and ``write``
(:func:`write_report`).
"""

from .figures import plot_maps, plot_scatter, plot_slices
from .records import FIT, entry_status, write_params_json, write_residuals_csv
from .write import write_report

__all__ = ["write_report", "write_params_json", "write_residuals_csv", "entry_status", "plot_maps",
           "plot_slices", "plot_scatter", "FIT"]
