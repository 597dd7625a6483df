"""The ``appearance-jax`` command line.

    appearance-jax models [NAME]        list the models with their parameter tables
    appearance-jax eval --model NAME [--param name=value ...] --theta-i DEG [...] --out DIR
                                        evaluate a BSDF on an in-plane grid; write CSV + PNG
    appearance-jax demo --out DIR       the evaluation demo of the README

Angles are in degrees at this boundary (radians inside the library). In-plane tables use a
signed theta_o: theta_o = theta_i is the mirror direction, theta_o = -theta_i retro-reflection
(:func:`appearance_jax.core.frame.in_plane_directions`).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys

import numpy as np


def _fmt_default(v) -> str:
    if v is None:
        return "None"
    if isinstance(v, tuple):
        return "(" + ", ".join(f"{x:g}" for x in v) + ")"
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return f"{v:g}"
    return str(v)


def format_model_table(model) -> str:
    from .core.params import describe

    rows = describe(model.Params)
    head = ["parameter", "default", "range", "unit", "meaning"]
    body = [[r["name"] + (" [bands]" if r["bands"] else ""), _fmt_default(r["default"]), r["range"], r["unit"], r["doc"]]
            for r in rows]
    widths = [max(len(h), *(len(b[i]) for b in body)) if body else len(h) for i, h in enumerate(head)]
    line = lambda cells: "  " + "  ".join(c.ljust(w) for c, w in zip(cells, widths))  # noqa: E731
    flags = []
    if model.sample is not None:
        flags.append("sample/pdf")
    flags.append("reciprocal" if model.reciprocal else "not reciprocal")
    if model.transmissive:
        flags.append("transmissive")
    out = [f"{model.name}  ({model.kind}; {', '.join(flags)})", f"  {model.summary}", f"  source: {model.source}",
           line(head), line(["-" * w for w in widths])]
    out += [line(b) for b in body]
    if model.presets:
        out.append("  presets: " + ", ".join(model.presets))
    return "\n".join(out)


def _parse_value(text: str):
    text = text.strip()
    if "," in text:
        return tuple(float(x) for x in text.split(","))
    try:
        return float(text)
    except ValueError:
        if text.lower() in ("true", "false"):
            return text.lower() == "true"
        return text


def _parse_params(model, assignments: list[str]):
    kw = {}
    for a in assignments or []:
        if "=" not in a:
            raise SystemExit(f"--param {a!r}: expected name=value (e.g. alpha=0.2 or reflectance=0.8,0.5,0.2)")
        k, v = a.split("=", 1)
        kw[k.strip()] = _parse_value(v)
    if model.presets and "preset" in kw:
        base = model.presets[kw.pop("preset")]
        return base.replace(**kw)
    try:
        return model.Params(**kw)
    except TypeError as e:
        names = [r for r in model.Params.__dataclass_fields__]
        raise SystemExit(f"{model.name}: {e}; parameters are {', '.join(names)}") from e


def _parse_range(text: str) -> np.ndarray:
    """'a:b:step' (inclusive) or a comma list, in degrees."""
    if ":" in text:
        a, b, s = (float(x) for x in text.split(":"))
        return np.arange(a, b + 0.5 * s, s)
    return np.array([float(x) for x in text.split(",")])


def evaluate_in_plane(model, params, theta_i_deg, theta_o_deg):
    """BSDF values on an in-plane grid; returns (theta_i, theta_o, f[..., bands]) as numpy."""
    import jax.numpy as jnp

    from .core.frame import in_plane_directions

    ti, to = np.meshgrid(theta_i_deg, theta_o_deg, indexing="ij")
    wi, wo = in_plane_directions(jnp.deg2rad(ti.ravel()), jnp.deg2rad(to.ravel()))
    f = np.asarray(model.eval(params, wi, wo))
    return ti.ravel(), to.ravel(), f


def write_table(path, theta_i, theta_o, f, quantity="BRDF"):
    nb = f.shape[-1]
    names = ["R", "G", "B"] if nb == 3 else [f"band{i}" for i in range(nb)]
    with open(path, "w", newline="") as fh:
        fh.write(f"# quantity: {quantity} [1/sr]; in-plane, signed theta_o (theta_o = theta_i is the mirror direction)\n")
        w = csv.writer(fh)
        w.writerow(["theta_i", "phi_i", "theta_o", "phi_o", *names])
        for a, b, row in zip(theta_i, theta_o, f):
            w.writerow([f"{a:g}", "0", f"{abs(b):g}", "180" if b >= 0 else "0", *(f"{x:.8g}" for x in row)])


def plot_in_plane(path, curves, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=110)
    for label, x, y in curves:
        ax.semilogy(x, np.maximum(y, 1e-6), label=label)
    ax.set_xlabel(r"signed $\theta_o$ [deg]  ($\theta_o=\theta_i$: mirror)")
    ax.set_ylabel(r"$f \cos\theta_o$ (luminance) [1/sr]")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _luminance(f):
    if f.shape[-1] == 3:
        return f @ np.array([0.2126, 0.7152, 0.0722])
    return f.mean(axis=-1)


def cmd_models(args) -> int:
    from . import registry

    models = [registry.get(args.name)] if args.name else registry.models()
    print("\n\n".join(format_model_table(m) for m in models))
    return 0


def cmd_eval(args) -> int:
    from . import registry

    model = registry.get(args.model)
    if model.kind != "bsdf":
        raise SystemExit(f"eval: {model.name} is a {model.kind}; in-plane evaluation is for BSDFs")
    params = _parse_params(model, args.param)
    th_i = _parse_range(args.theta_i)
    th_o = _parse_range(args.theta_o)
    for name, arr in (("theta-i", th_i), ("theta-o", th_o)):
        if np.any(np.abs(arr) > 90):
            raise SystemExit(f"--{name}: angles must lie in [-90, 90] degrees, got {arr.min():g}..{arr.max():g}")
    os.makedirs(args.out, exist_ok=True)
    ti, to, f = evaluate_in_plane(model, params, th_i, th_o)
    write_table(os.path.join(args.out, f"{model.name}.csv"), ti, to, f)
    cos_o = np.cos(np.deg2rad(to))
    curves = [(f"theta_i = {a:g}", to[ti == a], _luminance(f[ti == a]) * cos_o[ti == a]) for a in th_i]
    plot_in_plane(os.path.join(args.out, f"{model.name}.png"), curves, f"{model.name} (in-plane)")
    print(f"wrote {args.out}/{model.name}.csv ({len(ti)} rows) and {model.name}.png")
    return 0


def cmd_demo(args) -> int:
    """Evaluate every registered BSDF in-plane and one gradient; write CSV, PNG and a JSON summary."""
    import jax

    from . import registry
    from .core.frame import in_plane_directions

    os.makedirs(args.out, exist_ok=True)
    th_i = np.array([0.0, 30.0, 60.0])
    th_o = np.arange(-89.0, 89.5, 1.0)
    summary = {}
    curves = []
    for model in registry.models():
        if model.kind != "bsdf":
            continue
        params = model.Params()
        ti, to, f = evaluate_in_plane(model, params, th_i, th_o)
        write_table(os.path.join(args.out, f"{model.name}.csv"), ti, to, f)
        sel = ti == 30.0
        curves.append((model.name, to[sel], _luminance(f[sel]) * np.cos(np.deg2rad(to[sel]))))
        summary[model.name] = {"max_f_theta_i_30": float(f[sel].max())}
    plot_in_plane(os.path.join(args.out, "demo.png"), curves, r"default parameters, $\theta_i = 30°$")
    # A gradient, as a fit would use it: d(mirror-direction value)/d(roughness).
    rc = registry.get("rough_conductor")
    wi, wo = in_plane_directions(np.deg2rad(30.0), np.deg2rad(30.0))
    g = jax.grad(lambda p: rc.eval(p, wi, wo).mean())(rc.Params())
    summary["rough_conductor"]["d_f_mirror_d_alpha"] = float(g.alpha)
    with open(os.path.join(args.out, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=2)
    print(json.dumps(summary, indent=2))
    print(f"wrote {args.out}/demo.png, summary.json and one CSV per model")
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="appearance-jax", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    pm = sub.add_parser("models", help="list models and their parameters")
    pm.add_argument("name", nargs="?", help="one model name")
    pm.set_defaults(fn=cmd_models)
    pe = sub.add_parser("eval", help="evaluate a BSDF on an in-plane grid")
    pe.add_argument("--model", required=True)
    pe.add_argument("--param", action="append", metavar="NAME=VALUE", help="repeatable; bands as a,b,c")
    pe.add_argument("--theta-i", default="0,30,60", help="degrees: list a,b,c or range a:b:step")
    pe.add_argument("--theta-o", default="-89:89:1", help="signed degrees (negative = retro side)")
    pe.add_argument("--out", default="out")
    pe.set_defaults(fn=cmd_eval)
    pd = sub.add_parser("demo", help="evaluation demo of all BSDFs + a gradient")
    pd.add_argument("--out", default="out/demo")
    pd.set_defaults(fn=cmd_demo)
    args = p.parse_args(argv)
    try:
        return args.fn(args)
    except (ValueError, KeyError) as e:
        print(f"appearance-jax {args.cmd}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
