"""Gradients of a function of a parameter pytree vs central finite differences.

Runs in float64 (it refuses to run without ``jax_enable_x64``: float32 finite differences
cannot resolve a relative error of 1e-5). For each array leaf of ``params`` (``None``
leaves and static fields are not leaves, integer leaves are skipped), the ``jax.grad``
derivative is compared with ``(fn(p + h e) - fn(p - h e)) / (2 h)``:

- per element (``e`` = unit vectors) for leaves with at most ``max_elements`` elements;
- along ``n_directions`` random unit directions ``e`` for larger leaves.

Step: ``h = step * max(|x|, 1)`` with ``step = 1e-5`` (near the cube root of the float64
epsilon, balancing truncation error ``~h^2 f'''`` against rounding ``~eps |f| / h``).
A leaf passes when ``max |ad - fd| <= atol + rtol * max(|ad|, |fd|)`` over its elements
(a per-leaf relative error). The default ``atol`` is ``100 eps |fn(p)| / h``, the rounding
noise of the difference quotient. Monte Carlo functions must use a fixed key inside
``fn`` (common random numbers) so that ``fn`` is a deterministic function of ``params``.
Keep evaluation points away from parameter bounds by more than ``h``.

``params`` is any pytree: a model's ``Params``, a flat array (its elements are then the
variables), a tuple or dict of scalars. Options: ``fn`` may return an array (its Jacobian,
``jax.jacfwd`` or ``jax.jacrev``, is compared output element by output element); ``fields`` checks a subset
of the leaves (names as in the result's ``leaves``, e.g. ``".alpha"`` or ``"[0]"``, or a
bare field or dict key ``"alpha"``); ``step`` may be a mapping from those names to steps;
``elementwise=True`` compares every element against its own scale,
``|ad - fd| <= atol + rtol * max(|ad|, |fd|)``, instead of the leaf's largest derivative.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .directions import as_key
from .results import CheckResult, fmt, is_x64


@dataclass(frozen=True)
class GradientResult(CheckResult):
    value: float  # fn(params) (its sum for an array-valued fn)
    leaves: tuple  # leaf names (key paths)
    ad: tuple  # per leaf: AD derivatives (per element or along the probe directions) [, output shape]
    fd: tuple  # per leaf: finite differences of the same
    rel_error: tuple  # per leaf: max |ad - fd| / max(|ad|, |fd|)
    rtol: float
    atol: float


def _leaf_name_matches(path: str, names) -> bool:
    """``path`` (a key path: ``".alpha"``, ``"['alpha']"``, ``"[0]"``) is one of ``names``, given as
    key paths or bare field / dict key names (``"alpha"``)."""
    return path in names or path.lstrip(".") in names or path.strip("[]'\"") in names


def _option(value, path: str, default):
    """A per-leaf option: a number, or a mapping name -> number (``default`` for others)."""
    if isinstance(value, dict):
        for k, v in value.items():
            if _leaf_name_matches(path, (k,)):
                return v
        return default
    return value


def check_gradients(fn, params, *, rtol: float = 1e-5, atol: float | None = None, step=1e-5,
                    max_elements: int = 16, n_directions: int = 4, key=0, name: str = "fn", fields=None,
                    elementwise: bool = False, mode: str = "auto", grad_fn=None) -> GradientResult:
    """Compare the AD derivatives of ``fn(params)`` with central finite differences, leaf by leaf.

    ``fn(params) -> scalar or array``. See the module docstring for the step, the
    tolerances and the options (``fields``, per-leaf ``step``, ``elementwise``). ``mode``: how
    ``fn`` is differentiated, ``"fwd"`` (``jax.jacfwd``), ``"rev"`` (``jax.grad`` /
    ``jax.jacrev``) or ``"auto"`` (reverse for a scalar ``fn``; for an array, forward when
    ``params`` has fewer elements than the output).
    ``grad_fn(params)``, if given, supplies the derivatives under test instead (a pytree like
    ``params``; e.g. from a compiled ``value_and_grad`` that the caller shares between tests).
    """
    if mode not in ("auto", "fwd", "rev"):
        raise ValueError(f"check_gradients: mode = {mode!r}: 'auto', 'fwd' or 'rev'")
    if not is_x64():
        raise RuntimeError("check_gradients needs float64: call jax.config.update('jax_enable_x64', True) first")
    leaves_p, treedef = jax.tree_util.tree_flatten_with_path(params)
    paths = [jax.tree_util.keystr(p) for p, _ in leaves_p]
    if fields is not None:
        fields = (fields,) if isinstance(fields, str) else tuple(fields)
    for what, names_ in (("fields", fields), ("step", step if isinstance(step, dict) else None)):
        unknown = [f for f in names_ or () if not any(_leaf_name_matches(p, (f,)) for p in paths)]
        if unknown:
            raise ValueError(f"check_gradients: {what} {unknown} are not leaves of params ({paths})")
    leaves = [jnp.asarray(v, jnp.float64) if jnp.issubdtype(jnp.asarray(v).dtype, jnp.floating) else jnp.asarray(v)
              for _, v in leaves_p]
    params64 = jax.tree_util.tree_unflatten(treedef, leaves)
    out0 = np.asarray(fn(params64))
    scalar = out0.ndim == 0
    if grad_fn is not None:
        grads = jax.tree_util.tree_leaves(grad_fn(params64))
    elif scalar and mode != "fwd":
        grads = jax.tree_util.tree_leaves(jax.grad(fn)(params64))
    else:
        fwd = mode == "fwd" or (mode == "auto" and sum(np.size(x) for x in leaves) < out0.size)
        grads = jax.tree_util.tree_leaves((jax.jacfwd if fwd else jax.jacrev)(fn)(params64))
    eps = float(np.finfo(np.float64).eps)
    keys = jax.random.split(as_key(key), max(len(leaves), 1))
    names, ads, fds, rels, problems = [], [], [], [], []
    atol_used = []
    for i, (path, x, gx) in enumerate(zip(paths, leaves, grads)):
        if not jnp.issubdtype(x.dtype, jnp.floating):
            continue
        if fields is not None and not _leaf_name_matches(path, fields):
            continue
        x = np.asarray(x)
        gx = np.asarray(gx)  # out.shape + x.shape
        h = _option(step, path, 1e-5) * max(float(np.max(np.abs(x))) if x.size else 1.0, 1.0)
        if x.size <= max_elements:
            dirs = np.eye(x.size).reshape((x.size,) + x.shape)
        else:
            d = np.asarray(jax.random.normal(keys[i], (n_directions, x.size), jnp.float64))
            dirs = (d / np.linalg.norm(d, axis=1, keepdims=True)).reshape((n_directions,) + x.shape)
        ad = np.array([np.tensordot(gx, e, axes=x.ndim) for e in dirs])  # (directions,) + out.shape
        fd = np.empty_like(ad)
        for j, e in enumerate(dirs):  # a few elements per leaf, each two function calls

            def at(sign):
                new = list(leaves)
                new[i] = jnp.asarray(x + sign * h * e)
                return np.asarray(fn(jax.tree_util.tree_unflatten(treedef, new)), np.float64)

            fd[j] = (at(+1.0) - at(-1.0)) / (2.0 * h)
        a_tol = 100.0 * eps * max(float(np.max(np.abs(out0))) if out0.size else 0.0, 1e-300) / h \
            if atol is None else atol
        atol_used.append(a_tol)
        err = np.abs(ad - fd)
        scale = np.maximum(np.abs(ad), np.abs(fd))
        smax = float(scale.max()) if scale.size else 0.0
        if elementwise:
            rel = float(np.max(np.where(scale > 0, err / np.where(scale > 0, scale, 1.0), 0.0))) if err.size else 0.0
            excess = err - (a_tol + rtol * scale)
        else:
            rel = float(err.max() / smax) if smax > 0 else 0.0
            excess = err - (a_tol + rtol * smax)
        names.append(path)
        ads.append(ad if not scalar else ad.reshape(-1))
        fds.append(fd if not scalar else fd.reshape(-1))
        rels.append(rel)
        if not (np.all(np.isfinite(ad)) and np.all(np.isfinite(fd))):
            problems.append(f"{path}: non-finite derivative (AD {ad}, FD {fd})")
        elif excess.size and excess.max() > 0:
            j = np.unravel_index(int(np.argmax(excess)), excess.shape)
            problems.append(f"{path}: AD {fmt(ad[j])} vs FD {fmt(fd[j])} (relative error {rel:.3g} > {rtol:g})")
    passed = not problems
    f0 = float(out0) if scalar else float(np.sum(out0))
    msg = (f"{name}: gradient check {'passed' if passed else 'FAILED'} at "
           f"{'f = ' + fmt(f0) if scalar else 'sum f = ' + fmt(f0)} over leaves "
           + ", ".join(f"{n} (rel. err {r:.2g})" for n, r in zip(names, rels))
           + ("" if passed else ". Problems: " + "; ".join(problems)))
    return GradientResult("gradients", passed, msg, f0, tuple(names), tuple(ads), tuple(fds), tuple(rels), rtol,
                          max(atol_used) if atol_used else 0.0)


def assert_gradients(fn, params, **kw) -> GradientResult:
    return check_gradients(fn, params, **kw).raise_if_failed()
