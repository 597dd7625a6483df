"""Write a fit's whole report: records and figures in one folder (see :mod:`~appearance_jax.fit.report`)."""

from __future__ import annotations

import os

from .figures import get_model, plot_maps, plot_scatter, plot_slices
from .records import entry_status, write_params_json, write_residuals_csv

__all__ = ["write_report"]


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
        mdl = get_model(result, model)
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
    d = write_params_json(result, q, extra=extra, status=status, figures=figures)
    paths["params"] = q
    n_warn = len(d.get("warnings") or [])
    say(f"  {q}" + (f": {n_warn} warning{'s' if n_warn > 1 else ''} (see 'warnings')" if n_warn else ""))
    return {k: paths[k] for k in ("params", "residuals", "maps", "slices", "scatter") if k in paths}
