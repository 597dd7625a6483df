"""``appearance-jax models [NAME]``: the registered models with their parameter tables."""

from __future__ import annotations

import numpy as np

from . import known

NAME = "models"


def _fmt_default(v) -> str:
    """A default for the parameter table: numbers with %g, nested tuples (cloth's per-family
    curves) recursively, anything else by str."""
    if v is None:
        return "None"
    if isinstance(v, (tuple, list)):
        return "(" + ", ".join(_fmt_default(x) for x in v) + ")"
    if isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_)):
        return f"{v:g}"
    return str(v)


def format_model_table(model) -> str:
    """A model's header (kind, flags, summary, source), its parameter table, presets and the
    parameters that ``fit`` holds fixed by default."""
    from ..core.params import describe

    rows = describe(model.Params)
    head = ["parameter", "default", "range", "unit", "meaning"]
    body = [[r["name"] + (" [bands]" if r["bands"] else ""), _fmt_default(r["default"]), r["range"], r["unit"], r["doc"]]
            for r in rows]
    widths = [max(len(h), *(len(b[i]) for b in body)) if body else len(h) for i, h in enumerate(head)]
    line = lambda cells: ("  " + "  ".join(c.ljust(w) for c, w in zip(cells, widths))).rstrip()  # noqa: E731
    flags = []
    if model.sample is not None:
        flags.append("sample/pdf")
    flags.append("reciprocal" if model.reciprocal else "not reciprocal")
    if model.transmissive:
        flags.append("transmissive")
    if model.stochastic:
        flags.append("Monte Carlo: eval(..., key=) returns (estimate, stderr)")
    out = [f"{model.name}  ({model.kind}; {', '.join(flags)})", f"  {model.summary}", f"  source: {model.source}",
           line(head), line(["-" * w for w in widths])]
    out += [line(b) for b in body]
    if model.presets:
        out.append("  presets: " + ", ".join(model.presets))
    held = known.describe(model)
    if held:
        out.append(held)
    return "\n".join(out)


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(NAME, help="list the models and their parameters (defaults, ranges, units)",
                              description="Print every registered model (or one) with its parameter table, "
                                          "presets and the parameters that fit holds fixed by default.")
    p.add_argument("name", nargs="?", help="one model name (e.g. rough_plastic or rough_conductor+lambert)")
    p.set_defaults(fn=run)


def run(args) -> int:
    from .. import registry
    from .checks import model

    if args.name:
        models = [model(args.name, option="models")]
    else:
        models = registry.models()
    print("\n\n".join(format_model_table(m) for m in models))
    return 0
