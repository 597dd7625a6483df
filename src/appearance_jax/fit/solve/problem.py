"""A fit's problem: a model, its free parameters and a table's data as arrays, and its residuals.

:func:`build_problem` validates a fit's inputs eagerly (model kind, metric, start, fixed fields,
enough valid values) and turns the table into per-entry arrays (:func:`entry_arrays`): the BRDF
data, 1/sigma of each residual carried through the metric, sqrt(sample weight) x mask and the
reasons entries were left out. :class:`Problem` evaluates the model and the flat residual vector
at a free-parameter vector; the solvers (:mod:`~appearance_jax.fit.solve.solvers`) minimise it.

A model whose ``eval`` returns ``(estimate, standard_error)`` (``Model.stochastic``) is fitted on
its estimate, with the same PRNG ``key`` at every iterate (common random numbers).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ...core.model import estimate_of
from ...core.params import validate
from ..tables.table import Table
from .residuals import FLOOR, check_metric, residual, residual_scale
from .transforms import ParamSpace

@dataclass
class Problem:
    """A model, its free parameters and a table's data, ready for a solver.

    ``data`` is a dict of arrays (a pytree, batchable with vmap): wi, wo (Vec3 (N,)),
    f (N, B) BRDF data, inv_scale (N, B) 1/sigma of the residual (1 without sigma),
    weight (N, B) = sqrt(sample weight) x mask (0 for masked entries), cos_i (N, 1);
    :func:`build_problem` makes them numpy arrays of JAX's default float dtype.
    """

    model: Any
    space: ParamSpace
    data: dict
    metric: str
    floor: float
    key: Any = None
    model_kwargs: dict = field(default_factory=dict)
    absolute_sigma: bool = False
    masked: dict = field(default_factory=dict)

    def evaluate(self, params, data):
        """Model BRDF (N, B) at the data's directions (kernel: no validation, traceable)."""
        kw = dict(self.model_kwargs)
        if self.key is not None:
            kw["key"] = self.key
        out = estimate_of(self.model.eval.kernel(params, data["wi"], data["wo"], **kw))
        return jnp.broadcast_to(out, data["f"].shape)

    def residuals_x(self, x, data):
        """Flat residual vector (N*B,) at physical free-parameter vector x."""
        return self.residuals_params(self.space.params_from_x(x), data)

    def residuals_params(self, params, data):
        """Flat residual vector (N*B,) of the model with ``params``."""
        f = self.evaluate(params, data)
        r = residual(f, data["f"], data["cos_i"], self.metric, floor=self.floor)
        r = r * data["inv_scale"] * data["weight"]
        return jnp.where(data["weight"] > 0, r, 0.0).ravel()

    def residuals_z(self, z, data):
        return self.residuals_x(self.space.x_from_z(z), data)

    def jacobian_z(self, z, data):
        """d residuals_z / dz (N*B, p) by forward mode, with two savings a model may allow:

        - ``Model.jacobian_apart``: fields that enter f only after the model's costly per-parameter
          work (e.g. a base albedo multiplying a coat's finished terms). When both they and other
          fields are free, their columns come from a forward pass of their own, whose tangents
          skip that work (rough_plastic's Jacobian ~1.5x faster).
        - ``Model.band_separable``: output band b depends on a band field only through its entry b.
          Then one tangent (every entry at once) gives all of a band field's columns: entry b's
          column is that derivative on the rows of band b and 0 elsewhere (an RGB albedo: 1
          tangent instead of 3).

        The same Jacobian to rounding either way (tests/fit/solve/test_solve.py)."""
        sp = self.space
        n = len(sp.fields)
        apart = [i for i, f in enumerate(sp.fields) if f.name in getattr(self.model, "jacobian_apart", ())]
        bands = int(data["f"].shape[-1])
        collapse = {i for i, f in enumerate(sp.fields)
                    if getattr(self.model, "band_separable", False) and f.spec.bands and f.size == bands > 1}
        groups = [list(range(n))] if not apart or len(apart) == n else [[i for i in range(n) if i not in apart], apart]
        if len(groups) == 1 and not collapse:
            return jax.jacfwd(self.residuals_z)(z, data)
        parts = sp.z_parts(z)
        cols = {}
        for group in groups:
            cols.update(self._columns(parts, group, collapse, bands, data))
        return jnp.concatenate([cols[i] for i in range(n)], axis=1)

    def _columns(self, parts, group, collapse, bands, data):
        """{field index: its Jacobian columns (N*B, size)} of the fields ``group`` from one forward
        pass (vmapped JVPs; the other fields' parts held, so they carry no tangent), one tangent per
        entry, or per field for those in ``collapse`` (see :meth:`jacobian_z`)."""
        sp = self.space

        def fn(*sub):
            full = list(parts)
            for i, v in zip(group, sub):
                full[i] = v
            return self.residuals_params(sp.params_from_z_parts(full), data)

        rows = [(g, k) for g, i in enumerate(group) for k in ([None] if i in collapse else range(sp.fields[i].size))]
        basis = [np.zeros((len(rows), sp.fields[i].size)) for i in group]
        for r, (g, k) in enumerate(rows):
            basis[g][r, slice(None) if k is None else k] = 1.0
        primals = tuple(parts[i] for i in group)
        dt = primals[0].dtype
        out = jax.vmap(lambda *t: jax.jvp(fn, primals, t)[1])(*(jnp.asarray(b, dt) for b in basis))  # (rows, N*B)
        band_of_row = np.arange(out.shape[1]) % bands  # r is the ravel of (N, B)
        result, r = {}, 0
        for i in group:
            if i in collapse:
                result[i] = out[r][:, None] * jnp.asarray(band_of_row[:, None] == np.arange(bands)[None, :], dt)
                r += 1
            else:
                result[i] = out[r:r + sp.fields[i].size].T
                r += sp.fields[i].size
        return result


def _sigma_scale(metric, f, sigma, cos_i, floor):
    s = np.asarray(residual_scale(f, sigma, cos_i, metric, floor=floor))
    return np.where(np.isfinite(s) & (s > 0), 1.0 / np.where(s > 0, s, 1.0), 0.0)


def entry_arrays(table: Table, values, sigma, mask, *, metric, weights, max_theta_deg, use_sigma, floor):
    """Per-entry data of a fit, in numpy: ``(f, inv_scale, weight, masked, absolute)``.

    ``values``, ``sigma`` (or None) and ``mask`` are in the table's quantity with its (N, B)
    shape, optionally with leading batch axes (K, N, B) on the table's angles, so that a batch
    is prepared in one vectorised pass. ``f`` is the BRDF (0 where not fitted), ``weight`` =
    sqrt(sample weight) x mask, ``masked`` maps each reason added here (grazing, bad sigma) to
    its count: an int, or a (K,) array with a batch axis.
    """
    k = table.brdf_factor()
    f = np.asarray(values, np.float64) * k
    sigma = None if sigma is None else np.asarray(sigma, np.float64) * k
    mask = np.asarray(mask, bool) & np.isfinite(f)
    masked = {}
    if max_theta_deg is not None:
        lim = np.deg2rad(max_theta_deg)
        grazing = ((table.theta_i > lim) | (table.theta_o > lim))[:, None] & mask
        if grazing.any():
            masked[f"grazing (theta > {max_theta_deg:g} deg)"] = grazing.sum(axis=(-2, -1))
            mask &= ~grazing
    cos_i = np.cos(table.theta_i)[:, None]
    w = np.ones_like(f) if weights is None else np.broadcast_to(np.asarray(weights, np.float64), f.shape)
    if np.any(~np.isfinite(w)) or np.any(w < 0):
        raise ValueError("weights must be finite and >= 0")
    if use_sigma and sigma is not None:
        bad = mask & ~(np.isfinite(sigma) & (sigma > 0))
        if bad.any():
            masked["sigma <= 0 or missing"] = bad.sum(axis=(-2, -1))
            mask &= ~bad
        inv = _sigma_scale(metric, np.where(mask, f, 0.0), np.where(mask, sigma, 1.0), cos_i, floor)
        absolute = True
    else:
        inv, absolute = np.ones_like(f), False
    weight = np.where(mask, np.sqrt(w), 0.0)
    return np.where(mask, f, 0.0), inv, weight, masked, absolute


def match_spectral_bands(params, table: Table):
    """Point a wavelength-dependent model at a spectral table's wavelengths.

    Models whose ``Params`` have the static fields ``color`` and ``wavelengths`` (thin films:
    :data:`appearance_jax.core.spectral.COLOR_MODES`) evaluate one band per wavelength in
    ``color="spectral"``; a spectral table switches them to that mode at its wavelengths.
    An RGB table keeps the model's mode ("rgb3" or "cie"), but refuses "spectral".
    """
    names = getattr(type(params), "_static_fields", ())
    if "color" not in names or "wavelengths" not in names:
        return params
    if table.wavelengths is not None:
        return params.replace(color="spectral", wavelengths=tuple(float(w) for w in table.wavelengths))
    if params.color == "spectral":
        raise ValueError(f"{table.source}: the table is RGB ({', '.join(table.bands)}) but the model's "
                         "color = 'spectral'; use color='rgb3' (650/510/475 nm) or 'cie'")
    return params


def start_params(model, init):
    """A start (Params or preset name) of ``model``, validated."""
    if isinstance(init, str):
        if init not in model.presets:
            raise ValueError(f"preset {init!r} is not a preset of {model.name}; presets: "
                             f"{', '.join(model.presets) or 'none'}")
        init = model.presets[init]
    params = init if init is not None else model.Params()
    validate(params, model.Params)
    return params


def build_problem(model, table: Table, *, init=None, fix=None, metric="l2", weights=None,
                  max_theta_deg: float | None = 85.0, use_sigma: bool = True, floor: float = FLOOR,
                  key=None, model_kwargs=None) -> Problem:
    """Assemble a :class:`Problem` (validates everything eagerly, with clear errors)."""
    from ... import registry

    model = registry.get(model) if isinstance(model, str) else model
    if model.kind != "bsdf":
        raise ValueError(f"fit: {model.name} is a {model.kind}; tables are fitted with BSDFs")
    check_metric(metric)
    params = match_spectral_bands(start_params(model, init), table)
    space = ParamSpace(params, table.n_bands, fix=fix, band_names=table.bands)

    f, inv, weight, extra, absolute = entry_arrays(table, table.values, table.sigma, table.mask, metric=metric,
                                                    weights=weights, max_theta_deg=max_theta_deg,
                                                    use_sigma=use_sigma, floor=floor)
    masked = dict(table.masked)
    masked.update({why: int(n) for why, n in extra.items() if n})
    n_valid = int((weight > 0).sum())
    if n_valid < space.size:
        raise ValueError(f"{table.source}: {n_valid} valid values for {space.size} free parameters "
                         f"({', '.join(space.labels)}); masked: {masked or 'none'}")
    cos_i = np.cos(table.theta_i)[:, None]
    # numpy arrays: a compiled program moves them to the device in one call of its own, several
    # times faster than a device_put per array (a warm fit's set-up was mostly those transfers)
    dt = np.dtype(jnp.result_type(float))
    wi, wo = table.directions(dt, host=True)
    data = dict(wi=wi, wo=wo, f=f.astype(dt), inv_scale=inv.astype(dt), weight=weight.astype(dt),
                cos_i=cos_i.astype(dt))
    return Problem(model, space, data, metric, floor, key, dict(model_kwargs or {}), absolute, masked)


__all__ = ["Problem", "build_problem", "entry_arrays", "match_spectral_bands"]
