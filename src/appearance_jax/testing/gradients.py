"""Gradients of any scalar function of a parameter pytree vs central finite differences.

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
    value: float  # fn(params)
    leaves: tuple  # leaf names (key paths)
    ad: tuple  # per leaf: AD derivatives (per element or along the probe directions)
    fd: tuple  # per leaf: finite differences of the same
    rel_error: tuple  # per leaf: max |ad - fd| / max(|ad|, |fd|)
    rtol: float
    atol: float


def check_gradients(fn, params, *, rtol: float = 1e-5, atol: float | None = None, step: float = 1e-5,
                    max_elements: int = 16, n_directions: int = 4, key=0, name: str = "fn") -> GradientResult:
    """Compare ``jax.grad(fn)(params)`` with central finite differences, leaf by leaf.

    ``fn(params) -> scalar``. See the module docstring for the step and tolerances.
    """
    if not is_x64():
        raise RuntimeError("check_gradients needs float64: call jax.config.update('jax_enable_x64', True) first")
    leaves_p, treedef = jax.tree_util.tree_flatten_with_path(params)
    paths = [jax.tree_util.keystr(p) for p, _ in leaves_p]
    leaves = [jnp.asarray(v, jnp.float64) if jnp.issubdtype(jnp.asarray(v).dtype, jnp.floating) else jnp.asarray(v)
              for _, v in leaves_p]
    params64 = jax.tree_util.tree_unflatten(treedef, leaves)
    f0 = float(fn(params64))
    grads = jax.tree_util.tree_leaves(jax.grad(fn)(params64))
    eps = float(np.finfo(np.float64).eps)
    keys = jax.random.split(as_key(key), max(len(leaves), 1))
    names, ads, fds, rels, problems = [], [], [], [], []
    atol_used = []
    for i, (path, x, gx) in enumerate(zip(paths, leaves, grads)):
        if not jnp.issubdtype(x.dtype, jnp.floating):
            continue
        x = np.asarray(x)
        gx = np.asarray(gx)
        h = step * max(float(np.max(np.abs(x))) if x.size else 1.0, 1.0)
        if x.size <= max_elements:
            dirs = np.eye(x.size).reshape((x.size,) + x.shape)
        else:
            d = np.asarray(jax.random.normal(keys[i], (n_directions, x.size), jnp.float64))
            dirs = (d / np.linalg.norm(d, axis=1, keepdims=True)).reshape((n_directions,) + x.shape)
        ad = np.array([float(np.sum(gx * e)) for e in dirs])
        fd = np.empty(len(dirs))
        for j, e in enumerate(dirs):  # a few elements per leaf, each two function calls

            def at(sign):
                new = list(leaves)
                new[i] = jnp.asarray(x + sign * h * e)
                return float(fn(jax.tree_util.tree_unflatten(treedef, new)))

            fd[j] = (at(+1.0) - at(-1.0)) / (2.0 * h)
        a_tol = 100.0 * eps * max(abs(f0), 1e-300) / h if atol is None else atol
        atol_used.append(a_tol)
        err = np.abs(ad - fd)
        scale = np.maximum(np.abs(ad), np.abs(fd))
        smax = float(scale.max()) if scale.size else 0.0
        rel = float(err.max() / smax) if smax > 0 else 0.0
        names.append(path)
        ads.append(ad)
        fds.append(fd)
        rels.append(rel)
        if not (np.all(np.isfinite(ad)) and np.all(np.isfinite(fd))):
            problems.append(f"{path}: non-finite derivative (AD {ad}, FD {fd})")
        elif err.max(initial=0.0) > a_tol + rtol * smax:
            j = int(np.argmax(err))
            problems.append(f"{path}: AD {fmt(ad[j])} vs FD {fmt(fd[j])} (relative error {rel:.3g} > {rtol:g})")
    passed = not problems
    msg = (f"{name}: gradient check {'passed' if passed else 'FAILED'} at f = {fmt(f0)} over leaves "
           + ", ".join(f"{n} (rel. err {r:.2g})" for n, r in zip(names, rels))
           + ("" if passed else ". Problems: " + "; ".join(problems)))
    return GradientResult("gradients", passed, msg, f0, tuple(names), tuple(ads), tuple(fds), tuple(rels), rtol,
                          max(atol_used) if atol_used else 0.0)


def assert_gradients(fn, params, **kw) -> GradientResult:
    return check_gradients(fn, params, **kw).raise_if_failed()
