"""Physically known parameters: the values ``appearance-jax fit`` holds fixed unless ``--free NAME``.

A model declares them in its record (:attr:`appearance_jax.core.model.Model.fit_fixed`,
``name -> (value, reason)``); a sum of lobes inherits its components' (under the composite's
field names, :mod:`appearance_jax.bsdf.sum`). :func:`resolve` merges them with the user's
``--fix`` and ``--free`` into the ``fix`` argument of :func:`appearance_jax.fit.fit` and a record
of where each fixed value came from (params.json ``fixed_by``).
"""

from __future__ import annotations

from .checks import UsageError


def fit_fixed(model) -> dict[str, tuple[object, str]]:
    """name -> (value, reason) of ``model``'s physically known parameters (composites: its components')."""
    from .. import registry

    own = dict(getattr(model, "fit_fixed", None) or {})
    components = getattr(model.Params, "components", None)
    if own or not components:
        return own
    out = {}
    for comp, pairs in zip(components, model.Params.field_map):
        known = fit_fixed(registry.get(comp))
        for composite_name, component_name in pairs:
            if component_name in known:
                out[composite_name] = known[component_name]
    return out


def _fmt(v) -> str:
    if isinstance(v, (tuple, list)):
        return ",".join(f"{x:g}" for x in v)
    return f"{v:g}" if isinstance(v, (int, float)) else str(v)


def describe(model) -> str | None:
    """The line of ``appearance-jax models NAME`` (None for a model without such parameters)."""
    known = fit_fixed(model)
    if not known:
        return None
    items = "; ".join(f"{k} = {_fmt(v)} ({why})" for k, (v, why) in known.items())
    return f"  held fixed by `fit` unless --free NAME: {items}"


def resolve(model, fix: dict, free: list[str], user_set: set[str]) -> tuple[dict, dict]:
    """The ``fix`` argument of the fitter and the origin of each fixed parameter.

    Args:
        fix: the user's ``--fix`` ({name: value or None = at the start value}).
        free: the ``--free`` names (``all`` releases every physically known parameter).
        user_set: names whose start value the user chose (``--param``, ``--preset``): a
            physically known parameter among them is held at that start value.

    Returns:
        (fix for :func:`~appearance_jax.fit.fit`, {name: {"by": "--fix" | "default", "reason": ...}}).
    """
    known = fit_fixed(model)
    free = list(free or [])
    released = set(known) if "all" in free else set()
    for name in free:
        if name == "all":
            continue
        if name not in known:
            what = f"{model.name}'s are {', '.join(known)}" if known else f"{model.name} has none"
            raise UsageError(f"--free {name}: not a parameter that fit holds fixed by default ({what}; "
                             "every other parameter is fitted unless --fix holds it)")
        if name in fix:
            raise UsageError(f"--free {name} and --fix {name}: give one of them")
        released.add(name)
    out = dict(fix)
    origin = {name: {"by": "--fix"} for name in fix}
    for name, (value, why) in known.items():
        if name in fix or name in released:
            continue
        out[name] = None if name in user_set else value
        origin[name] = {"by": "default", "reason": why}
    return out, origin


def markdown_table(models) -> str:
    """The table of every model's physically known parameters (docs/cli.md)."""
    rows = ["| model | parameter | held at | why |", "|---|---|---|---|"]
    for m in models:
        for name, (value, why) in fit_fixed(m).items():
            rows.append(f"| `{m.name}` | `{name}` | {_fmt(value)} | {why} |")
    return "\n".join(rows)
