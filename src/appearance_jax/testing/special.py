"""Special directions: values and gradients where the formulas are singular or 0/0.

The directions a fuzzer or a measured table hits exactly (the local frame of
:mod:`appearance_jax.core.frame`, z = normal; for fibers x = the fiber tangent):

- ``normal`` (0, 0, 1) and ``antinormal`` (0, 0, -1);
- the horizon ``horizon_x`` (1, 0, 0) (a fiber's tangent) and ``horizon_y`` (0, 1, 0);
- ``grazing_above`` / ``grazing_below``: (sqrt(1 - c^2), 0, +-c) with c = 1e-7, one float32
  rounding away from the horizon.

:func:`check_special_directions` evaluates the model at every ``(wi, wo)`` pair among
them (36 pairs) and differentiates the sum of the values with respect to every
floating-point field of ``params`` (one compiled ``jax.value_and_grad`` for all pairs; a
failing gradient is then traced to its pairs one pair at a time). It passes when

- every value (and, with ``pdf=True``, every ``pdf``) is finite;
- for reflection-only BSDFs (:func:`.directions.incident_domain` ``== "upper"``) the value
  is exactly 0 wherever ``wi`` or ``wo`` is strictly below the horizon (z < 0). Fibers,
  phase functions and transmissive BSDFs live on the whole sphere: finiteness only;
- every gradient is finite. A NaN in one pair's gradient makes a whole fit's gradient
  NaN (a sum of residuals), even where that pair's value is 0; the usual cause is a
  ``sqrt``/``norm``/``atan2``/division evaluated at 0 in a branch that ``jnp.where``
  masks (the masked branch gets a zero cotangent, and 0 times its infinite local
  derivative is NaN). Fix it with the double ``where``: make the unsafe operand safe
  where masked, ``jnp.where(ok, x / jnp.where(ok, d, 1.0), 0.0)``.

``dtype`` picks float32 or float64: the check runs inside ``jax.enable_x64(dtype ==
float64)`` with the directions and the floating-point fields of ``params`` cast to it.
Stochastic models (``Model.stochastic``: ``eval(params, wi, wo, key=...)`` returns
``(estimate, stderr)``) are evaluated with the fixed ``key``; both outputs must be finite,
the estimate is differentiated. Keep their sample counts (static fields) small.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ..core.vec import Vec3
from .directions import as_key, incident_domain
from .results import CheckResult

GRAZING = 1e-7
_G = math.sqrt(1.0 - GRAZING * GRAZING)

#: name -> unit direction (x, y, z)
SPECIAL_DIRECTIONS = {
    "normal": (0.0, 0.0, 1.0),
    "antinormal": (0.0, 0.0, -1.0),
    "horizon_x": (1.0, 0.0, 0.0),
    "horizon_y": (0.0, 1.0, 0.0),
    "grazing_above": (_G, 0.0, GRAZING),
    "grazing_below": (_G, 0.0, -GRAZING),
}


def special_pairs(directions=None) -> tuple[list[tuple[str, str]], np.ndarray, np.ndarray]:
    """Every ``(wi, wo)`` pair of ``directions`` (default :data:`SPECIAL_DIRECTIONS`):
    their names and two ``(n_pairs, 3)`` float64 arrays."""
    d = SPECIAL_DIRECTIONS if directions is None else directions
    names = [(a, b) for a in d for b in d]
    wi = np.array([d[a] for a, _ in names], dtype=np.float64)
    wo = np.array([d[b] for _, b in names], dtype=np.float64)
    return names, wi, wo


@dataclass(frozen=True)
class SpecialDirectionsResult(CheckResult):
    dtype: str
    pairs: tuple  # (wi name, wo name) per pair
    value: np.ndarray  # (n_pairs, bands) eval (the estimate of a stochastic model)
    nonfinite: tuple  # pairs with a non-finite value, stderr or pdf
    nonzero_below: tuple  # pairs below the horizon with a value != 0 (reflection BSDFs)
    nonfinite_grad: tuple  # (field, pairs) with a non-finite gradient


def _cast(params, dtype):
    def cast(v):
        a = np.asarray(v)
        return jnp.asarray(a, dtype) if np.issubdtype(a.dtype, np.floating) else v

    return jax.tree_util.tree_map(cast, params)


def _float_fields(params):
    """Key paths and values of the floating-point leaves of ``params``."""
    leaves, treedef = jax.tree_util.tree_flatten_with_path(params)
    floating = [jnp.issubdtype(jnp.asarray(v).dtype, jnp.floating) for _, v in leaves]
    names = [jax.tree_util.keystr(p) for (p, _), f in zip(leaves, floating) if f]

    def rebuild(values):
        it = iter(values)
        return jax.tree_util.tree_unflatten(treedef, [next(it) if f else v for (_, v), f in zip(leaves, floating)])

    return names, [v for (_, v), f in zip(leaves, floating) if f], rebuild


def check_special_directions(model, params, *, dtype=np.float64, key=0, directions=None,
                             pdf: bool = False, compiler_options: dict | None = None) -> SpecialDirectionsResult:
    """Finite values and gradients (and 0 below the horizon) at the special directions.

    ``model``: a record with the fields of :class:`appearance_jax.core.model.Model`;
    ``params`` must broadcast against directions of shape ``(n_pairs,)``. See the module
    docstring for what is checked; ``directions`` replaces :data:`SPECIAL_DIRECTIONS`
    (name -> unit ``(x, y, z)``); ``pdf=True`` also requires a finite ``pdf`` (same pairs).
    ``compiler_options``: XLA options for the one compiled program (``jax.jit``'s), e.g. to check
    the code path users get when the process runs with other ``XLA_FLAGS``.
    """
    dtype = np.dtype(dtype)
    if dtype not in (np.float32, np.float64):
        raise ValueError(f"dtype = {dtype}: float32 or float64")
    names, wi_np, wo_np = special_pairs(directions)
    stochastic = bool(getattr(model, "stochastic", False))
    upper = incident_domain(model) == "upper"
    label = getattr(model, "name", "model")
    with jax.enable_x64(dtype == np.float64):
        p = _cast(params, dtype)
        wi = Vec3(*(jnp.asarray(wi_np[:, k], dtype) for k in range(3)))
        wo = Vec3(*(jnp.asarray(wo_np[:, k], dtype) for k in range(3)))
        k = as_key(key)

        fields, values, rebuild = _float_fields(p)
        has_pdf = pdf and not stochastic and getattr(model, "pdf", None) is not None

        def total(vals, a, b):
            q = rebuild(vals)
            if stochastic:
                est, se = model.eval(q, a, b, key=k)
            else:
                est, se = model.eval(q, a, b), None
            return jnp.sum(est), (est, se, model.pdf(q, a, b) if has_pdf else None)

        # value, pdf and gradient from one compiled function (compilation is most of the cost)
        value_and_grad = jax.jit(jax.value_and_grad(total, has_aux=True), compiler_options=compiler_options)
        (_, (f, se, pd)), grads = value_and_grad(values, wi, wo)
        n = len(names)
        f = np.asarray(f)
        bad = ~np.isfinite(f.reshape(n, -1)).all(axis=1)
        for extra in (se, pd):
            if extra is not None:
                bad |= ~np.isfinite(np.asarray(extra).reshape(n, -1)).all(axis=1)
        below = (wi_np[:, 2] < 0) | (wo_np[:, 2] < 0)
        nonzero = (np.abs(np.nan_to_num(f.reshape(n, -1), nan=1.0)) > 0).any(axis=1) & below & upper
        grads = [np.asarray(g) for g in grads]
        grad_bad = []
        if not all(np.isfinite(g).all() for g in grads):
            # which pairs: one pair at a time (one more compile, for shape (1,)), only on failure
            per_field = {name: [] for name in fields}
            for j, pair in enumerate(names):
                _, one = value_and_grad(values, wi.map(lambda c: c[j:j + 1]), wo.map(lambda c: c[j:j + 1]))
                for name, g in zip(fields, one):
                    if not np.isfinite(np.asarray(g)).all():
                        per_field[name].append(pair)
            grad_bad = [(name, tuple(per_field[name])) for name, g in zip(fields, grads) if not np.isfinite(g).all()]

    pairs = tuple(names)
    nonfinite = tuple(pr for pr, b in zip(pairs, bad) if b)
    nonzero_below = tuple(pr for pr, b in zip(pairs, nonzero) if b)
    passed = not (nonfinite or nonzero_below or grad_bad)
    problems = []
    if nonfinite:
        problems.append(f"non-finite value at {_fmt_pairs(nonfinite)}")
    if nonzero_below:
        problems.append(f"value != 0 below the horizon at {_fmt_pairs(nonzero_below)}")
    for n, prs in grad_bad:
        problems.append(f"non-finite d/d{n} at {_fmt_pairs(prs) if prs else 'the sum only'}")
    msg = (f"{label}: special directions ({dtype.name}, {len(pairs)} pairs, {len(fields)} fields) "
           f"{'passed' if passed else 'FAILED'}" + ("" if passed else ": " + "; ".join(problems)))
    return SpecialDirectionsResult("special_directions", passed, msg, dtype.name, pairs, f, nonfinite,
                                   nonzero_below, tuple(grad_bad))


def _fmt_pairs(prs, limit: int = 8) -> str:
    s = ", ".join(f"({a}, {b})" for a, b in prs[:limit])
    return s + (f" and {len(prs) - limit} more" if len(prs) > limit else "")


def assert_special_directions(model, params, **kw) -> SpecialDirectionsResult:
    return check_special_directions(model, params, **kw).raise_if_failed()
