"""Parameter pytrees with metadata (bounds, unit, meaning) and eager validation.

A model's ``Params`` is a frozen dataclass registered as a JAX pytree. Each numeric field is
declared with :func:`param`, which records its default, valid range, unit and a one-line
meaning; configuration that selects code paths (the microfacet distribution, say) is
declared with :func:`static` and is not a pytree leaf.

Shapes: a field declared ``bands=True`` may carry a trailing bands axis (RGB or
wavelengths) that broadcasts against the model's output bands; other fields broadcast
against the direction arrays. Both may have leading axes for spatially varying parameters. A field may default to
``None`` (an optional parameter, e.g. the second roughness of an anisotropic model): it is
then no pytree leaf, is not validated and is not fitted.

Validation happens when a ``Params`` is constructed (``Params(...)``, ``replace``) with
concrete values, and again at the public boundary of every model (:func:`validate`) for
objects that were not (pytree rebuilds):

- a value that is not a number (``alpha="x"``, a dict) raises a ``ValueError`` naming the
  field and the expected type;
- a value that is NaN, infinite or out of range raises a ``ValueError`` naming the class,
  the field, the value and the valid range (:func:`check_value`);
- band fields whose trailing (bands) lengths disagree (``eta`` with 2 values, ``k`` with 3)
  raise naming both fields and lengths; a length of 1 (or a scalar) broadcasts to any;
- a class's own cross-field checks (a ``_validate(self)`` method, e.g. the band count that a
  spectral model computes on) run too.

Traced values (inside ``jit``/``vmap``/``grad``) and abstract ones (``jax.ShapeDtypeStruct``)
are not checked, so kernels stay branch-free. Pytree unflattening (``jax.tree.map``,
``jax.eval_shape``, Jacobians, ``vmap`` axis specs such as ``jax.tree.map(lambda _: 0, p)``)
rebuilds a ``Params`` without converting or checking its leaves (so build a per-field axis
spec with ``jax.tree_util.tree_map_with_path``, not ``Params(alpha=0, ...)``, which is checked). Under ``jit``, where
eager checks cannot run, :func:`check_traced` emits :mod:`jax.experimental.checkify`
checks of the same ranges, and :func:`checked` wraps a function so that they are raised.
"""

from __future__ import annotations

import contextvars
import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

_META_KEY = "appearance_jax"
# instance attribute set on a Params whose concrete values passed every check at construction
_CHECKED = "_appearance_jax_checked"

# Annotations of numeric parameter fields. Both are jax arrays of the default float dtype
# once a Params is constructed (python numbers, sequences and numpy arrays are converted).
#: A real parameter: a scalar, or an array that broadcasts against the direction arrays
#: (leading axes for spatially varying parameters). Declared with ``param(...)``.
Real = float | jax.Array
#: A band-valued parameter (``param(..., bands=True)``): a scalar (the same in every band)
#: or a trailing bands axis (RGB or wavelengths), optionally with leading axes.
Bands = float | tuple[float, ...] | jax.Array


@dataclass(frozen=True)
class ParamSpec:
    """Metadata of one numeric parameter."""

    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = False
    unit: str = "1"
    doc: str = ""
    bands: bool = False

    def range_str(self) -> str:
        left = "(" if self.lo_open or self.lo == -math.inf else "["
        right = ")" if self.hi_open or self.hi == math.inf else "]"
        return f"{left}{_fmt(self.lo)}, {_fmt(self.hi)}{right}"

    def contains(self, v: np.ndarray) -> np.ndarray:
        ok = (v > self.lo) if self.lo_open else (v >= self.lo)
        ok &= (v < self.hi) if self.hi_open else (v <= self.hi)
        return ok


@dataclass(frozen=True)
class StaticSpec:
    """Metadata of a static (non-differentiable, code-path selecting) field."""

    choices: tuple | None = None
    doc: str = ""
    # called on the value at construction: returns the normalised (hashable) value or raises
    # ValueError naming the problem (e.g. wavelengths must be positive)
    convert: Any = None


def _fmt(x: float) -> str:
    if x == math.inf:
        return "inf"
    if x == -math.inf:
        return "-inf"
    return f"{x:g}"


def param(default, *, lo=-math.inf, hi=math.inf, lo_open=False, hi_open=False, unit="1", doc="", bands=False):
    """Declare a numeric parameter field (a pytree leaf) with its range and unit."""
    spec = ParamSpec(float(lo), float(hi), lo_open, hi_open, unit, doc, bands)
    return dataclasses.field(default=default, metadata={_META_KEY: spec})


def static(default, *, choices=None, doc="", convert=None):
    """Declare a static configuration field (hashable; not a pytree leaf).

    ``convert(value)`` (optional) normalises the value at construction (e.g. a list of
    wavelengths to a tuple of floats) and raises ``ValueError`` for invalid values; the
    error is re-raised naming the class and the field.
    """
    spec = StaticSpec(tuple(choices) if choices is not None else None, doc, convert)
    return dataclasses.field(default=default, metadata={_META_KEY: spec})


def _to_array(v):
    """Convert python / numpy numbers to jax arrays; leave arrays, tracers, others alone."""
    if isinstance(v, (bool, int, float, tuple, list, np.ndarray, np.generic)):
        return jnp.asarray(v, dtype=jnp.result_type(float))
    if isinstance(v, jax.Array) and not isinstance(v, jax.core.Tracer) and v.weak_type:
        # jnp.full(n, 1.5) is weakly typed: a strong copy keeps jit caches from splitting on it
        return jnp.asarray(v, dtype=v.dtype)
    return v


_HOST_NUMERIC = (bool, int, float, np.ndarray, np.generic)
_EXPECTED = "a real number, a sequence of real numbers or a real array"


def _host_value(label: str, v):
    """A concrete field value as a numpy array (floating arrays keep their precision, which
    :func:`_check_array` compares in), or None when it cannot be checked eagerly (None,
    tracers, abstract values such as ``jax.ShapeDtypeStruct``). Raises ``ValueError`` naming
    ``label`` and the expected type for a non-number."""
    if v is None or _is_traced(v):
        return None
    if isinstance(v, (jax.Array, np.ndarray, np.generic)) and v.dtype.kind in "fc":
        if v.dtype.kind == "c":
            raise ValueError(f"{label} has dtype {v.dtype}: expected {_EXPECTED}")
        return np.asarray(v)
    if isinstance(v, jax.Array):
        if v.dtype.kind not in "biu" and not jnp.issubdtype(v.dtype, jnp.floating):
            raise ValueError(f"{label} has dtype {v.dtype}: expected {_EXPECTED}")
        return np.asarray(v, dtype=float)  # (bfloat16, kind "V", too)
    if isinstance(v, (tuple, list)) or isinstance(v, _HOST_NUMERIC):
        try:
            a = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            a = None
        if a is None or (isinstance(v, np.ndarray) and v.dtype.kind not in "biuf"):
            raise ValueError(f"{label} = {v!r} is not numeric: expected {_EXPECTED}") from None
        return a
    if hasattr(v, "shape") and hasattr(v, "dtype"):  # abstract (ShapeDtypeStruct) or array-like
        return None
    raise ValueError(f"{label} = {v!r} is not numeric ({type(v).__name__}): expected {_EXPECTED}")


def _n_bands(shape: tuple) -> int:
    return shape[-1] if shape else 1


def _check_bands(label: str, lengths: dict[str, int]) -> None:
    """Band fields (name -> trailing length) must agree on their length (1 broadcasts)."""
    first = None
    for name, n in lengths.items():
        if n == 1:
            continue
        if first is None:
            first = (name, n)
        elif n != first[1]:
            raise ValueError(
                f"{label}.{name} has {n} bands (trailing axis) but {label}.{first[0]} has {first[1]}: "
                "band fields must have the same number of bands, or 1 (a scalar broadcasts to every band)")


_PY_REAL = (float, int)


def _fast_length(v, spec: ParamSpec) -> int | None:
    """Trailing length of a python number or flat sequence of numbers that is finite and in
    range (checked without numpy: construction from literals stays cheap); None otherwise
    (then the numpy path checks, or raises with the message)."""
    t = type(v)
    if t in _PY_REAL:
        vals, n = (v,), 1
    elif (t is tuple or t is list) and v and all(type(c) in _PY_REAL for c in v):
        vals, n = v, len(v)
    else:
        return None
    return n if all(_in_range(c, spec) for c in vals) else None


def _in_range(c: float, spec: ParamSpec, lo=None, hi=None) -> bool:
    """Finite and inside the spec's range (a NaN is neither); ``lo``/``hi``: the bounds rounded
    to the value's precision (default: the declared ones)."""
    lo = spec.lo if lo is None else lo
    hi = spec.hi if hi is None else hi
    return math.isfinite(c) and (c > lo if spec.lo_open else c >= lo) and (c < hi if spec.hi_open else c <= hi)


def owner_name(cls) -> str:
    """The name of the module that defines a params class, for messages: "rough_conductor"
    (a model that is a package, ``bsdf/cloth/model.py``, by its package: "cloth")."""
    parts = cls.__module__.split(".")
    return parts[-2] if parts[-1] == "model" and len(parts) > 1 else parts[-1]


def _label(cls) -> str:
    """"rough_conductor.Params": every model's class is called Params, so name its module too."""
    return f"{owner_name(cls)}.{cls.__name__}"


def params_class(cls):
    """Class decorator: frozen dataclass + pytree registration + conversions.

    Numeric fields given as python numbers, tuples or numpy arrays are converted to jax
    arrays of the default float dtype; static fields are checked against their choices.
    """
    user_post_init = cls.__dict__.get("__post_init__")

    # Installed before the dataclass is made, so that the generated __init__ calls it.
    def __post_init__(self):
        klass = type(self)
        label = _label(klass)
        specs = klass.__dataclass_fields__
        concrete, bands = True, {}
        trusted = _TRUSTED.get()
        for name in klass._data_fields:
            v = getattr(self, name)
            spec = specs[name].metadata.get(_META_KEY)
            if spec is None:  # a nested pytree (e.g. another Params), checked by its own class
                concrete = concrete and (v is None or getattr(v, _CHECKED, False))
                object.__setattr__(self, name, _to_array(v))
                continue
            n = _n_bands(np.shape(v)) if id(v) in trusted else _fast_length(v, spec)
            if n is None:
                a = _host_value(f"{label}.{name}", v)
                if a is None:
                    concrete = concrete and v is None
                else:
                    _check_array(f"{label}.{name}", a, spec)
                    n = _n_bands(a.shape)
            if spec.bands and n is not None:
                bands[name] = n
            object.__setattr__(self, name, _to_array(v))
        _check_bands(label, bands)
        for name in klass._static_fields:
            spec = specs[name].metadata[_META_KEY]
            v = getattr(self, name)
            if spec.convert is not None:
                try:
                    v = spec.convert(v)
                except (TypeError, ValueError) as e:
                    raise ValueError(f"{label}.{name} = {v!r}: {e}") from None
                object.__setattr__(self, name, v)
            if spec.choices is not None and v not in spec.choices:
                raise ValueError(
                    f"{label}.{name} = {v!r} is not one of the valid choices {list(spec.choices)}"
                )
        if user_post_init is not None:
            user_post_init(self)
        if concrete:
            extra = getattr(self, "_validate", None)
            if extra is not None:
                extra()
            # every check passed on concrete values: validate() at the public boundary skips them
            object.__setattr__(self, _CHECKED, True)

    cls.__post_init__ = __post_init__
    dc = dataclass(frozen=True)(cls)
    data, meta = [], []
    for f in dataclasses.fields(dc):
        spec = f.metadata.get(_META_KEY)
        (meta if isinstance(spec, StaticSpec) else data).append(f.name)
    dc._data_fields = tuple(data)
    dc._static_fields = tuple(meta)
    dc.replace = _replace
    _register(dc, tuple(data), tuple(meta))
    return dc


# ids of field values that an in-progress replace() carries over from a checked Params
_TRUSTED: contextvars.ContextVar[frozenset] = contextvars.ContextVar("appearance_jax_trusted", default=frozenset())


def _replace(self, **kw):
    """A copy with some fields changed (``dataclasses.replace``), checked like a construction;
    the values carried over from an already checked ``self`` are not checked again."""
    if not getattr(self, _CHECKED, False):
        return dataclasses.replace(self, **kw)
    token = _TRUSTED.set(frozenset(id(getattr(self, n)) for n in type(self)._data_fields if n not in kw))
    try:
        return dataclasses.replace(self, **kw)
    finally:
        _TRUSTED.reset(token)


def replace_unchecked(params, **values):
    """A copy of ``params`` with ``values`` set as given: no conversion and no check, as JAX's
    pytree rebuilds make them (for values the library computed inside their ranges, e.g. a fit's
    parameters from its transforms, and for tests of the checks at the public boundary, which still
    run on such an object; :func:`validate`)."""
    cls = type(params)
    unknown = set(values) - set(cls._data_fields) - set(cls._static_fields)
    if unknown:
        raise TypeError(f"{_label(cls)} has no field(s) {', '.join(sorted(unknown))}")
    obj = object.__new__(cls)
    for n in cls._static_fields + cls._data_fields:
        object.__setattr__(obj, n, values.get(n, getattr(params, n)))
    return obj


def _register(dc, data: tuple, meta: tuple) -> None:
    """Pytree registration whose unflatten bypasses ``__init__``: JAX rebuilds a Params from
    leaves that are no parameter values (tracers, ``ShapeDtypeStruct``, the ints and Nones of
    a ``vmap`` axis spec, Jacobian blocks), which must be neither converted nor checked.
    Keys are attribute names (``keystr`` gives ``.alpha``), as ``register_dataclass`` has them."""
    keys = tuple(jax.tree_util.GetAttrKey(n) for n in data)

    def flatten_with_keys(x):
        return tuple((k, getattr(x, n)) for k, n in zip(keys, data)), tuple(getattr(x, n) for n in meta)

    def flatten(x):
        return tuple(getattr(x, n) for n in data), tuple(getattr(x, n) for n in meta)

    def unflatten(aux, children):
        obj = object.__new__(dc)
        for n, v in zip(meta, aux):
            object.__setattr__(obj, n, v)
        for n, v in zip(data, children):
            object.__setattr__(obj, n, v)
        return obj

    jax.tree_util.register_pytree_with_keys(dc, flatten_with_keys, unflatten, flatten)


def param_specs(params_or_cls) -> dict[str, ParamSpec | StaticSpec]:
    """Field name -> spec, in declaration order."""
    cls = params_or_cls if isinstance(params_or_cls, type) else type(params_or_cls)
    return {f.name: f.metadata[_META_KEY] for f in dataclasses.fields(cls) if _META_KEY in f.metadata}


def _is_traced(v) -> bool:
    return isinstance(v, jax.core.Tracer)


def validate(params, expected_cls: type | None = None) -> None:
    """Raise ``ValueError`` if any concrete numeric field is non-finite or out of range.

    Traced values are skipped (checks happen eagerly, at the public boundary). A Params
    that passed every check at construction is not checked again (it is immutable).
    Classes may add cross-field checks in a ``_validate(self)`` method that raises.
    """
    if expected_cls is not None and not isinstance(params, expected_cls):
        raise TypeError(
            f"expected parameters of type {expected_cls.__qualname__}, got {type(params).__qualname__}"
        )
    if getattr(params, _CHECKED, False):
        return
    cls = type(params)
    label = _label(cls)
    bands, concrete = {}, True
    for name, spec in param_specs(cls).items():
        if isinstance(spec, ParamSpec):
            v = getattr(params, name)
            a = _host_value(f"{label}.{name}", v)
            if a is None:
                concrete = concrete and v is None
                continue
            _check_array(f"{label}.{name}", a, spec)
            if spec.bands:
                bands[name] = _n_bands(a.shape)
    _check_bands(label, bands)
    extra = getattr(params, "_validate", None)
    if extra is not None and concrete:
        extra()


def check_value(label: str, v, spec: ParamSpec) -> None:
    """Raise ``ValueError`` naming ``label`` if a concrete ``v`` is non-finite or outside ``spec``'s range.

    ``None``, traced and abstract values pass (checks happen eagerly, at public boundaries).
    Used by :func:`validate` and by functions that take bare numbers (e.g. the layered references).
    """
    a = _host_value(label, v)
    if a is not None:
        _check_array(label, a, spec)


def _check_array(label: str, a: np.ndarray, spec: ParamSpec) -> None:
    # compared in the value's precision: a float32 pi/2 (1.5707964) is on the bound [0, pi/2]
    t = a.dtype.type if a.dtype.kind == "f" else float
    lo, hi = float(t(spec.lo)), float(t(spec.hi))
    if a.size == 0 or (_in_range(float(a.min()), spec, lo, hi) and _in_range(float(a.max()), spec, lo, hi)):
        return  # min/max propagate NaN: two reductions decide the common, valid case
    ok = (a > lo) if spec.lo_open else (a >= lo)
    ok &= (a < hi) if spec.hi_open else (a <= hi)
    bad = ~np.isfinite(a) | ~ok
    if np.any(bad):
        first = a[bad].flat[0] if a.ndim else a
        what = "is not finite; valid range" if not np.isfinite(first) else "is outside the valid range"
        shown = f"{float(first):g}"
        if shown in (_fmt(spec.lo), _fmt(spec.hi)):  # just past a bound: show the digits that matter
            shown = f"{float(first):.9g}"
        raise ValueError(
            f"{label} = {shown} {what} {spec.range_str()}"
            + (f" [{spec.unit}]" if spec.unit not in ("", "1") else "")
            + (f" ({spec.doc})" if spec.doc else "")
        )


def check_traced(params) -> None:
    """Emit :mod:`jax.experimental.checkify` checks that ``params``' fields are finite and in range.

    The traced counterpart of :func:`validate`, for code under ``jit``/``vmap`` where eager
    checks cannot run. Call it inside a function that is transformed by ``checkify``::

        def f(p, wi, wo):
            check_traced(p)
            return rough_conductor.eval(p, wi, wo)

        err, out = checkify.checkify(jax.jit(f))(p, wi, wo)
        err.throw()  # ValueError: "rough_conductor.Params.alpha = nan is not finite or outside ..."

    (or wrap ``f`` with :func:`checked`). Outside ``checkify`` a traced check is an error (JAX
    cannot stage it). Band lengths are shapes, known while tracing: a mismatch raises at once.
    """
    from jax.experimental import checkify

    cls = type(params)
    label = _label(cls)
    bands = {}
    for name, spec in param_specs(cls).items():
        v = getattr(params, name)
        if not isinstance(spec, ParamSpec) or v is None:
            continue
        x = jnp.asarray(v)
        if spec.bands:
            bands[name] = _n_bands(np.shape(x))
        ok = jnp.isfinite(x)
        ok &= (x > spec.lo) if spec.lo_open else (x >= spec.lo)
        ok &= (x < spec.hi) if spec.hi_open else (x <= spec.hi)
        ok = jnp.ravel(ok)
        first_bad = jnp.ravel(x)[jnp.argmin(ok)] if ok.size else jnp.zeros((), x.dtype)
        unit = f" [{spec.unit}]" if spec.unit not in ("", "1") else ""
        checkify.check(jnp.all(ok), f"{label}.{name} = {{}} is not finite or outside the valid range "
                       f"{spec.range_str()}{unit}", first_bad)
    _check_bands(label, bands)


def _is_params(x) -> bool:
    return hasattr(type(x), "_data_fields") and dataclasses.is_dataclass(x)


def checked(fn):
    """``fn`` jitted, with every ``Params`` among its arguments checked by :func:`check_traced`.

    ``checked(f)(p, ...)`` runs ``checkify.checkify(jax.jit(...))`` and raises the first failed
    check as a ``ValueError`` (``checkify.JaxRuntimeError``) that names the class, the field and
    the offending value, like the eager checks do; otherwise it returns ``f(p, ...)``. Use it
    for parameters that are computed inside ``jit`` (e.g. from a network or an optimiser).
    Arguments must be pytrees of arrays (no static arguments).
    """
    from jax.experimental import checkify

    def inner(*args, **kwargs):
        for leaf in jax.tree_util.tree_leaves((args, kwargs), is_leaf=_is_params):
            if _is_params(leaf):
                check_traced(leaf)
        return fn(*args, **kwargs)

    run = checkify.checkify(jax.jit(inner))

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        err, out = run(*args, **kwargs)
        err.throw()
        return out

    return wrapper


def _as_int(v, strict: bool):
    """``int(v)`` if ``v`` is an integer (``strict``: of an integer type), else None."""
    if isinstance(v, (bool, np.bool_)):
        return None
    if isinstance(v, (int, np.integer)):
        return int(v)
    if strict:
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return int(f) if f.is_integer() else None


def _int_range(lo: int, hi: int | None) -> str:
    return f"in [{lo}, {hi}]" if hi is not None else f">= {lo}"


def check_int(label: str, v, lo: int = 1, hi: int | None = None) -> int:
    """A count argument (of an integer type) in [lo, hi]; ``ValueError`` naming ``label`` otherwise."""
    n = _as_int(v, strict=True)
    if n is None or n < lo or (hi is not None and n > hi):
        raise ValueError(f"{label} = {v!r} must be an integer {_int_range(lo, hi)}")
    return n


def integer(lo: int, hi: int | None = None):
    """``static(convert=integer(lo, hi))``: an integer setting (integral floats and strings accepted)."""
    def convert(v):
        n = _as_int(v, strict=False)
        if n is None or n < lo or (hi is not None and n > hi):
            raise ValueError(f"must be an integer {_int_range(lo, hi)}")
        return n
    return convert


def describe(params_or_cls) -> list[dict[str, Any]]:
    """Rows of the parameter table: name, default, range, unit, meaning (for the CLI and docs)."""
    cls = params_or_cls if isinstance(params_or_cls, type) else type(params_or_cls)
    rows = []
    for f in dataclasses.fields(cls):
        spec = f.metadata.get(_META_KEY)
        default = f.default if f.default is not dataclasses.MISSING else None
        if isinstance(spec, ParamSpec):
            rows.append(dict(name=f.name, default=default, range=spec.range_str(), unit=spec.unit,
                             doc=spec.doc, bands=spec.bands))
        elif isinstance(spec, StaticSpec):
            rows.append(dict(name=f.name, default=default,
                             range="{" + ", ".join(map(str, spec.choices)) + "}" if spec.choices else "static",
                             unit="-", doc=spec.doc, bands=False))
    return rows
