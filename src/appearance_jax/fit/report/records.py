"""The report's records: ``params.json`` and ``residuals.csv`` (see :mod:`~appearance_jax.fit.report`).

``params.json`` carries the uncertainties of :meth:`FitResult.to_dict` (docs/fitting.md): per
parameter the default ``sigma`` (``null`` with a ``sigma_note`` at a bound or in a flat
direction) and every kind computed (``sigma_iid``, ``sigma_hc1``, ``sigma_sandwich``,
``sigma_bootstrap`` with its percentile intervals); ``uncertainty`` (the default method and
its clusters), ``correlation`` (``labels``, ``matrix``), ``degeneracies`` and ``warnings``.

:func:`entry_status` says for every (direction, band) entry of the table whether the fit used it
and, if not, why; both records count the entries by it.
"""

from __future__ import annotations

import json
import math
import platform
import re
import sys

import numpy as np

from ..solve.residuals import FLOOR
from ..tables.table import Table

__all__ = ["FIT", "entry_status", "write_params_json", "write_residuals_csv"]

FIT = "fit"  # status of an entry the fit used


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
    below = np.broadcast_to(~t.above_horizon()[:, None], t.values.shape)
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
    from ...core.params import StaticSpec, param_specs

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

    from ... import __version__

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


def _fmt_col(a, spec=".9g"):
    return [format(v, spec) if math.isfinite(v) else "" for v in np.asarray(a, np.float64).tolist()]


def write_residuals_csv(result, path, *, status=None) -> int:
    """Write ``residuals.csv``; returns the number of entries with status ``"fit"``."""
    t = result.table
    n, b = t.values.shape
    st = entry_status(result) if status is None else status
    f_data, sigma = t.brdf()
    fitted = np.broadcast_to(np.asarray(result.fitted, np.float64), (n, b))
    r, z = result.entry_residuals()
    signed = np.rad2deg(t.signed_theta_o(strict=False)) + 0.0  # NaN out of the plane; + 0.0: no "-0"
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
                   "relative": f"(f_fitted - f_measured) / (|f_measured| + {FLOOR:g} 1/sr)"}[result.metric]
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
