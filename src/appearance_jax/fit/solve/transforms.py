"""Parameter spaces for fitting: which fields are free, their shapes, and the map to R^n.

Solvers work on an unconstrained vector z in R^n; models take a ``Params`` pytree whose
fields live in bounded ranges (``core.params.param``). :class:`ParamSpace` owns that map,
one scalar entry at a time, from the field's declared range [lo, hi]:

==========================  ===============================  ==============================
declared range              x(z)                             why
==========================  ===============================  ==============================
[lo, hi] both finite        lo + (hi - lo) (1 + sin z) / 2   never leaves the range, and never
                                                             saturates: a bound is reached at
                                                             finite z and passed by reflection
                                                             (the transform of MINUIT, James &
                                                             Roos 1975); a sigmoid would leave
                                                             a parameter near a bound on a flat
                                                             plateau where LM stalls
[lo, inf)                   lo + exp(z)                      scale-like: steps are relative
(-inf, hi]                  hi - exp(-z)
(-inf, inf)                 z
==========================  ===============================  ==============================

A start value on a bound (e.g. ``specular_reflectance = 1``) sits where dx/dz = 0, so a
gradient solver could never leave it; it is moved inside by ``EDGE`` of the range (1e-3
relative, dx/dz then 6 % of its maximum). Only the start is moved; the fit may return to
the bound, which the result then reports.

Band fields (``bands=True``, e.g. a reflectance per colour channel) are fitted per band of
the table: a scalar default is broadcast to the table's band count. Fields set to ``None``
(optional parameters such as ``alpha_v``) and static fields are not fitted. Any other
field can be fixed (``fix={"eta": 1.5}`` or ``fix=["eta"]``, the latter at its start value).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ...core.params import owner_name, param_specs, ParamSpec, replace_unchecked, validate

EDGE = 1e-3  # start values are kept this fraction of the range away from a finite bound


@dataclass(frozen=True)
class FreeField:
    """One fitted field: its name, spec and the shape it is fitted with (() or (n_bands,))."""

    name: str
    spec: ParamSpec
    shape: tuple

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=int))


def _kind(spec: ParamSpec) -> str:
    lo_f, hi_f = math.isfinite(spec.lo), math.isfinite(spec.hi)
    return "box" if lo_f and hi_f else "lower" if lo_f else "upper" if hi_f else "free"


def _forward(spec: ParamSpec, z):
    k = _kind(spec)
    if k == "box":
        return _inside(spec, spec.lo + (spec.hi - spec.lo) * 0.5 * (1.0 + jnp.sin(z)))
    if k == "lower":
        return _inside(spec, spec.lo + jnp.exp(z))
    if k == "upper":
        return _inside(spec, spec.hi - jnp.exp(-z))
    return z


def _inside(spec: ParamSpec, x):
    """``x`` clipped to the declared range in its own precision, one ulp inside an open bound:
    rounding (or exp underflowing to 0) must not leave the range, so every Params the fitters
    build passes the construction checks of :mod:`appearance_jax.core.params`. The identity
    (value and gradient) inside the range."""
    t = np.dtype(jnp.result_type(x)).type
    lo, hi = t(spec.lo), t(spec.hi)
    tiny = np.finfo(t).tiny  # the next float after 0 is subnormal: flushed to 0 by XLA
    if spec.lo_open and np.isfinite(lo):
        lo = tiny if lo == 0 else np.nextafter(lo, t(np.inf))
    if spec.hi_open and np.isfinite(hi):
        hi = -tiny if hi == 0 else np.nextafter(hi, t(-np.inf))
    return jnp.clip(x, lo, hi)


def _inverse(spec: ParamSpec, x):
    x = np.asarray(x, dtype=np.float64)
    k = _kind(spec)
    if k == "box":
        w = spec.hi - spec.lo
        t = np.clip((x - spec.lo) / w, EDGE, 1 - EDGE)
        return np.arcsin(2.0 * t - 1.0)
    if k == "lower":
        return np.log(np.maximum(x - spec.lo, EDGE * max(1.0, abs(spec.lo))))
    if k == "upper":
        return -np.log(np.maximum(spec.hi - x, EDGE * max(1.0, abs(spec.hi))))
    return x


class ParamSpace:
    """The free parameters of a model fitted to a table with ``n_bands`` bands.

    Args:
        params: the start ``Params`` (fixed fields keep these values).
        n_bands: number of bands of the data (band fields are fitted with this many entries).
        fix: field names to hold at their start value, or a mapping name -> value.

    The flat vectors (``z`` unconstrained, ``x`` physical) list the free fields in declaration
    order, band fields band by band; :attr:`labels` names every entry (``"alpha"``,
    ``"diffuse_reflectance[G]"``).
    """

    def __init__(self, params, n_bands: int, fix=None, band_names=None):
        cls = type(params)
        specs = param_specs(cls)
        fix = fix or {}
        if not isinstance(fix, dict):
            fix = {name: None for name in fix}
        unknown = [k for k in fix if k not in specs]
        if unknown:
            raise ValueError(f"fix: unknown parameter(s) {', '.join(unknown)} of {owner_name(cls)}; "
                             f"parameters are {', '.join(specs)}")
        for k in fix:
            if not isinstance(specs[k], ParamSpec):
                raise ValueError(f"fix: {k} is a static (configuration) field; set it in the start parameters instead")
        band_names = tuple(band_names) if band_names is not None else tuple(str(i) for i in range(n_bands))
        values = {k: v for k, v in fix.items() if v is not None}
        params = params.replace(**values) if values else params
        validate(params)
        free, start = [], {}
        for name, spec in specs.items():
            if isinstance(spec, ParamSpec) and spec.bands and name in fix:
                v = getattr(params, name)
                n = np.shape(v)[-1] if np.ndim(v) else 1
                if v is not None and n not in (1, n_bands):
                    raise ValueError(f"{name} (fixed) has {n} bands but the table has {n_bands}: give one value "
                                     f"or one per band ({', '.join(band_names[:4])}{', ...' if n_bands > 4 else ''})")
            if not isinstance(spec, ParamSpec) or name in fix:
                continue
            v = getattr(params, name)
            if v is None:
                continue
            v = np.asarray(v, dtype=np.float64)
            if spec.bands:
                if v.ndim > 1:
                    raise ValueError(f"{name}: spatially varying start values are not supported by fit(); "
                                     "use fit_batch for many texels")
                v = np.broadcast_to(v, (n_bands,)).copy() if v.size in (1, n_bands) else None
                if v is None:
                    raise ValueError(f"{name}: start value has {np.size(getattr(params, name))} bands, "
                                     f"the table has {n_bands}")
            elif v.ndim != 0:
                raise ValueError(f"{name}: expected a scalar start value, got shape {v.shape}")
            free.append(FreeField(name, spec, v.shape))
            start[name] = v
        if not free:
            raise ValueError("nothing to fit: every parameter is fixed")
        self.template = params
        self.fields = tuple(free)
        self.start = start
        self.band_names = band_names
        self.fixed = tuple(fix)
        self.labels = tuple(
            f.name if f.shape == () else f"{f.name}[{band_names[b]}]" for f in free for b in range(f.size or 1)
        )

    @property
    def size(self) -> int:
        return sum(f.size for f in self.fields)

    # flat physical vector <-> Params
    def x_start(self) -> np.ndarray:
        return np.concatenate([np.ravel(self.start[f.name]) for f in self.fields])

    def _split(self, x, reshape):
        """{field name: its entries of the flat vector x, reshaped by ``reshape(part, shape)``}."""
        kw, i = {}, 0
        for f in self.fields:
            kw[f.name] = reshape(x[i:i + f.size], f.shape)
            i += f.size
        return kw

    def params_from_x(self, x):
        return self.template.replace(**self._split(x, jnp.reshape))

    def params_from_x_host(self, x):
        """:meth:`params_from_x` of a concrete x (numpy slices, then device arrays): compiles
        nothing, where the traced slices and reshapes would each be an XLA program. Unchecked, as
        a jitted :meth:`params_from_x` returns it: the transforms keep x in its ranges."""
        kw = self._split(np.asarray(x), lambda part, shape: jnp.asarray(np.reshape(part, shape)))
        return replace_unchecked(self.template, **kw)

    def x_from_params(self, params) -> np.ndarray:
        return np.concatenate([np.ravel(np.broadcast_to(np.asarray(getattr(params, f.name), np.float64), f.shape))
                               for f in self.fields])

    # unconstrained <-> physical
    def x_from_z(self, z):
        parts, i = [], 0
        for f in self.fields:
            parts.append(_forward(f.spec, z[..., i:i + f.size]))
            i += f.size
        return jnp.concatenate(parts, axis=-1)

    def z_from_x(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        parts, i = [], 0
        for f in self.fields:
            parts.append(_inverse(f.spec, x[..., i:i + f.size]))
            i += f.size
        return np.concatenate(parts, axis=-1)

    def params_from_z(self, z):
        return self.params_from_x(self.x_from_z(z))

    def z_parts(self, z) -> list:
        """z split into one array per free field (the order of :attr:`fields`)."""
        return list(self._split(z, lambda part, shape: part).values())

    def params_from_z_parts(self, parts):
        """:meth:`params_from_z` of z given as :meth:`z_parts`, the same values; no field's value
        depends on another field's part (no concatenation), so a derivative taken with respect to
        some parts carries no tangent, not even zeros, into the fields of the others."""
        return self.template.replace(**{f.name: jnp.reshape(_forward(f.spec, part), f.shape)
                                        for f, part in zip(self.fields, parts)})

    def random_z(self, key, n: int) -> jax.Array:
        """``n`` random starts in z: uniform over the middle 90 % of box ranges, start * e^N(0,1) otherwise."""
        z0 = jnp.asarray(self.z_from_x(self.x_start()))
        parts, i = [], 0
        k1, k2 = jax.random.split(key)
        u = jax.random.uniform(k1, (n, self.size), minval=0.05, maxval=0.95, dtype=z0.dtype)
        g = jax.random.normal(k2, (n, self.size), dtype=z0.dtype)
        for f in self.fields:
            sl = slice(i, i + f.size)
            if _kind(f.spec) == "box":
                parts.append(jnp.arcsin(2.0 * u[:, sl] - 1.0))
            else:
                parts.append(z0[sl] + g[:, sl])
            i += f.size
        return jnp.concatenate(parts, axis=-1)

    def at_bound(self, x, rel: float = 1e-3) -> np.ndarray:
        """Bool per entry: within ``rel`` of the range (or of |x| for one-sided bounds) of a finite bound."""
        x = np.asarray(x, dtype=np.float64)
        out, i = [], 0
        for f in self.fields:
            v = x[..., i:i + f.size]
            s = f.spec
            scale = (s.hi - s.lo) if _kind(s) == "box" else np.maximum(np.abs(v), 1e-12)
            near = np.zeros(v.shape, bool)
            if math.isfinite(s.lo):
                near |= (v - s.lo) <= rel * scale
            if math.isfinite(s.hi):
                near |= (s.hi - v) <= rel * scale
            out.append(near)
            i += f.size
        return np.concatenate(out, axis=-1)

    def units(self) -> tuple:
        return tuple(f.spec.unit for f in self.fields for _ in range(f.size or 1))
