"""Compiled fit programs kept in memory and reused by later fits in the same process.

A fit traces and compiles its solve (with ``solver="lm"`` the covariances at each start's
optimum are part of it; other solvers compile them apart) and the model's fitted values.
Across calls of :func:`~appearance_jax.fit.solve.fit` with the same model, free and fixed
parameters, metric, solver settings and array shapes, those programs are the same: only
their array arguments (the table's directions, data, weights and masks, the starts) differ. This
module keeps them, keyed by everything the traced code depends on besides those arguments, so
that a re-run, or a fit of another table of the same shape, skips tracing and compiling (the
persistent cache of :mod:`appearance_jax.core.compile_cache` saves only the compiling, and only
across processes).

The key (:func:`problem_key`) holds the model object itself (kept alive while cached), the
``Params`` template with its fixed values (leaf bytes) and static settings (tree structure),
the free fields with their bounds, the metric and its floor, whether sigma is absolute (the
covariances' scale), the PRNG key bytes of a stochastic
model and its keyword arguments. A problem with anything unhashable in them is not cached.
The shapes and dtypes of the arguments, the x64 setting, the default device and backend and the
matmul precision are part of every entry's key.

A compiled program (the solve, a batch) can also be kept on disk for later processes
(:mod:`appearance_jax.core.program_store`): its caller passes a content key (:func:`disk_key`
plus its own settings), which names a registered model by its name instead of by identity.
"""

from __future__ import annotations

import collections

import jax
import numpy as np

from ...core import compile_cache, program_store

__all__ = ["problem_key", "disk_key", "registered_name", "identity", "cached", "clear", "MAX_ENTRIES"]

MAX_ENTRIES = 64  # least recently used programs beyond this are dropped
_CACHE: "collections.OrderedDict[tuple, object]" = collections.OrderedDict()


class _Same:
    """Hashed and compared by identity (a Model holds dicts: it has no value hash); holding it
    keeps the object, and so its id, alive while the entry is kept."""

    __slots__ = ("obj",)

    def __init__(self, obj):
        self.obj = obj

    def __hash__(self):
        return id(self.obj)

    def __eq__(self, other):
        return isinstance(other, _Same) and other.obj is self.obj


def identity(obj) -> _Same:
    """A key part that stands for ``obj`` itself (compared by identity, kept alive with the entry)."""
    return _Same(obj)


def _leaf_key(x):
    a = np.asarray(x)
    return (a.dtype.str, a.shape, a.tobytes())


def _template_and_key(problem):
    """The Params template's tree structure and leaves, and the PRNG key as (implementation name
    or None, key data) or None: the parts of a problem's keys that need unpacking."""
    leaves, treedef = jax.tree_util.tree_flatten(problem.space.template)
    key = problem.key
    if key is not None and jax.dtypes.issubdtype(getattr(key, "dtype", None), jax.dtypes.prng_key):
        key = (str(jax.random.key_impl(key)), jax.random.key_data(key))
    elif key is not None:
        key = (None, key)
    return treedef, leaves, key


def problem_key(problem) -> tuple | None:
    """What a :class:`~.problem.Problem`'s traced programs depend on besides their array
    arguments (module docstring), or None when some of it is not hashable."""
    try:
        treedef, leaves, key = _template_and_key(problem)
        k = (_Same(problem.model), treedef, tuple(_leaf_key(v) for v in leaves), problem.space.fields,
             problem.metric, float(problem.floor), bool(problem.absolute_sigma),
             None if key is None else (key[0], _leaf_key(key[1])),
             tuple(sorted((n, v if not hasattr(v, "shape") else _leaf_key(v))
                          for n, v in problem.model_kwargs.items())))
        hash(k)
        return k
    except TypeError:  # an unhashable static value or keyword argument: do not reuse
        return None


def registered_name(model) -> str | None:
    """``model``'s registry name if it is the registry's own instance of that name, else None (a
    user's model or a modified copy: its programs are kept in memory only)."""
    from ... import registry

    try:
        return model.name if registry.get(model.name) is model else None
    except (KeyError, ValueError, TypeError, AttributeError):
        return None


def disk_key(problem) -> tuple | None:
    """What :func:`problem_key` holds, by content: the model as its registry name (the package's
    files are part of every stored entry's key), or None when :func:`registered_name` has none."""
    if registered_name(problem.model) is None:
        return None
    treedef, leaves, key = _template_and_key(problem)
    return (problem.model.name, treedef, tuple(np.asarray(v) for v in leaves), problem.space.fields, problem.metric,
            float(problem.floor), bool(problem.absolute_sigma), key, dict(problem.model_kwargs))


def _avals(*args):
    leaves, treedef = jax.tree_util.tree_flatten(args)
    return treedef, tuple((np.shape(v), np.dtype(v.dtype if hasattr(v, "dtype") else type(v)).str) for v in leaves)


def cached(tag, key, make, *args, disk=None):
    """The program ``make()`` (a jitted or compiled function of ``args``) for ``(tag, key)``, the
    shapes and dtypes of ``args`` and the settings below; built once and kept. ``key`` None: not
    kept. ``disk``: the same key by content (module docstring), for a ``make()`` that returns a
    compiled program: it is then looked up on disk first and written there once compiled."""
    if key is None:
        return make()
    # the settings a trace and its executable depend on beyond the key: precision and the device
    full = (tag, key, _avals(*args), bool(jax.config.jax_enable_x64), str(jax.config.jax_default_device),
            str(jax.config.jax_default_matmul_precision), jax.default_backend())
    fn = _CACHE.get(full)
    if fn is not None:
        _CACHE.move_to_end(full)
        return fn
    on_disk = disk is not None and program_store.directory() is not None
    name = program_store.entry_name(tag, disk, args) if on_disk else None
    fn = program_store.load(name, args)
    if fn is None and name is not None:
        with compile_cache.bypassed():  # a program JAX loaded from its cache cannot be stored
            fn = make()
        if isinstance(fn, jax.stages.Compiled):
            program_store.save(name, fn)
    elif fn is None:
        fn = make()
    _CACHE[full] = fn
    while len(_CACHE) > MAX_ENTRIES:
        _CACHE.popitem(last=False)
    return fn


def clear() -> None:
    """Forget every program kept in memory (they are rebuilt, or loaded from disk, on the next fit).

    Programs on disk (:mod:`~appearance_jax.core.program_store`) are keyed by this package's files,
    not by the functions' objects: code patched at run time (a test's monkeypatch of a function the
    solve traces) is not seen there. Turn the store off with the compilation cache for that
    (:func:`appearance_jax.core.compile_cache.disable`); a replaced ``solvers._solve`` is detected."""
    _CACHE.clear()
