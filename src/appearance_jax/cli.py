"""The ``appearance-jax`` command line.

    appearance-jax models [NAME]        list the models with their parameter tables
    appearance-jax eval --model NAME [--param name=value ...] --theta-i DEG [...] --out DIR
                                        evaluate a BSDF on an in-plane grid; write CSV + PNG
    appearance-jax eval --model NAME [--param ...] --table TABLE --out DIR
                                        evaluate a BSDF at a table's directions; write a CSV
                                        in the table's quantity, print the error against it
    appearance-jax fit TABLE --model NAME [--preset P] [--fix NAME[=VALUE] ...]
                       [--param NAME=VALUE ...] [--loss l2|cos_log|relative] [--solver S]
                       [--starts N] [--max-theta DEG] [--stride S] [--max-steps N]
                       [--float32] [--out DIR] [--quiet]
                                        fit a BSDF to a table; write params.json,
                                        residuals.csv and figures (fit.report)
    appearance-jax demo --out DIR       the evaluation demo of the README

TABLE is a ``.csv`` file (appearance-jax table v1), a MERL ``.binary`` file (every
``--stride``-th bin, default 3) or ``proxy:NAME[:GRID]`` (a Neural-BRDF proxy of a MERL
material, GRID gonio|in_plane|merl); see :func:`appearance_jax.fit.tables.io.read_table`.

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
    from .core.params import describe

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


def _assignments(option: str, items) -> dict:
    kw = {}
    for a in items or []:
        if "=" not in a or not a.split("=", 1)[0].strip():
            raise ValueError(f"{option} {a!r}: expected name=value (e.g. alpha=0.2 or reflectance=0.8,0.5,0.2)")
        k, v = a.split("=", 1)
        kw[k.strip()] = _parse_value(v)
    return kw


def _parse_params(model, assignments: list[str], preset: str | None = None):
    """Params from ``--param name=value`` (``preset=P`` among them, or ``preset``, picks the base)."""
    kw = _assignments("--param", assignments)
    preset = kw.pop("preset", preset)
    names = list(model.Params.__dataclass_fields__)
    if preset is not None:
        if preset not in model.presets:
            raise ValueError(f"{model.name}: no preset {preset!r}; presets: {', '.join(model.presets) or 'none'}")
        base = model.presets[preset]
    else:
        base = model.Params()
    unknown = [k for k in kw if k not in names]
    if unknown:
        raise ValueError(f"{model.name}: unknown parameter(s) {', '.join(unknown)}; parameters are {', '.join(names)}")
    from .core.params import validate

    params = base.replace(**kw) if kw else base
    validate(params)
    return params


def _parse_fix(items) -> dict:
    """``--fix name=value`` (fix at value) and ``--fix name`` (fix at the start value) -> {name: value|None}."""
    fix = {}
    for a in items or []:
        if "=" in a:
            k, v = a.split("=", 1)
            if not k.strip():
                raise ValueError(f"--fix {a!r}: expected name or name=value")
            fix[k.strip()] = _parse_value(v)
        elif a.strip():
            fix[a.strip()] = None
        else:
            raise ValueError("--fix: empty parameter name")
    return fix


def _check_fix(model, fix: dict) -> None:
    """Fail early (before reading a table and compiling) on a --fix name the model does not have."""
    from .core.params import StaticSpec, param_specs

    specs = param_specs(model.Params)
    for name in fix:
        if name not in specs:
            raise ValueError(f"--fix {name}: {model.name} has no parameter {name!r}; "
                             f"parameters are {', '.join(specs)}")
        if isinstance(specs[name], StaticSpec):
            raise ValueError(f"--fix {name}: a static (configuration) field is not fitted; "
                             f"set it with --param {name}=VALUE instead")


def _max_theta(text: str):
    if text.strip().lower() in ("none", "off", "no"):
        return None
    v = float(text)
    if not 0 < v <= 90:
        raise argparse.ArgumentTypeError(f"{text}: must lie in (0, 90] degrees, or 'none'")
    return v


def _parse_range(text: str) -> np.ndarray:
    """'a:b:step' (inclusive) or a comma list, in degrees."""
    if ":" in text:
        a, b, s = (float(x) for x in text.split(":"))
        return np.arange(a, b + 0.5 * s, s)
    return np.array([float(x) for x in text.split(",")])


def evaluate_in_plane(model, params, theta_i_deg, theta_o_deg):
    """BSDF values on an in-plane grid; returns (theta_i, theta_o, f[..., bands]) as numpy."""
    import jax.numpy as jnp

    from .fit.report.geometry import eval_in_plane

    ti, to = np.meshgrid(theta_i_deg, theta_o_deg, indexing="ij")
    f = eval_in_plane(model, params, jnp.deg2rad(ti.ravel()), jnp.deg2rad(to.ravel()))
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
    from .core.spectral import luminance_or_mean

    return np.asarray(luminance_or_mean(np.asarray(f, np.float64)))


def cmd_models(args) -> int:
    from . import registry

    models = [registry.get(args.name)] if args.name else registry.models()
    print("\n\n".join(format_model_table(m) for m in models))
    return 0


def cmd_eval(args) -> int:
    from . import registry

    model = registry.get(args.model)
    if model.kind != "bsdf":
        raise ValueError(f"{model.name} is a {model.kind}; evaluation on angles is for BSDFs")
    params = _parse_params(model, args.param)
    if args.table is not None:
        if args.theta_i is not None or args.theta_o is not None:
            raise ValueError("--theta-i/--theta-o select the in-plane grid; with --table the table's angles are used")
        return _eval_on_table(model, params, args)
    if args.stride is not None:
        raise ValueError("--stride applies to --table (MERL .binary files, proxy:NAME:merl)")
    th_i = _parse_range(args.theta_i if args.theta_i is not None else "0,30,60")
    th_o = _parse_range(args.theta_o if args.theta_o is not None else "-89:89:1")
    for name, arr in (("theta-i", th_i), ("theta-o", th_o)):
        if np.any(np.abs(arr) > 90):
            raise ValueError(f"--{name}: angles must lie in [-90, 90] degrees, got {arr.min():g}..{arr.max():g}")
    os.makedirs(args.out, exist_ok=True)
    ti, to, f = evaluate_in_plane(model, params, th_i, th_o)
    write_table(os.path.join(args.out, f"{model.name}.csv"), ti, to, f)
    cos_o = np.cos(np.deg2rad(to))
    curves = [(f"theta_i = {a:g}", to[ti == a], _luminance(f[ti == a]) * cos_o[ti == a]) for a in th_i]
    plot_in_plane(os.path.join(args.out, f"{model.name}.png"), curves, f"{model.name} (in-plane)")
    print(f"wrote {args.out}/{model.name}.csv ({len(ti)} rows) and {model.name}.png")
    return 0


def _eval_on_table(model, params, args) -> int:
    """eval --table: the model at the table's directions, written in the table's quantity."""
    from .core.model import estimate_of
    from .fit.solve.residuals import error_metrics
    from .fit.tables.csv_table import write_csv
    from .fit.tables.io import read_table

    table = read_table(args.table, stride=args.stride)
    wi, wo = table.directions()
    f = np.asarray(estimate_of(model.eval(params, wi, wo)), np.float64)
    if f.ndim == 1:
        f = f[:, None]
    if f.shape[1] not in (1, table.n_bands):
        raise ValueError(f"{model.name} gives {f.shape[1]} bands, the table has {table.n_bands} "
                         f"({', '.join(table.bands[:5])}{', ...' if table.n_bands > 5 else ''}); "
                         "give band parameters with one value per table band")
    f = np.broadcast_to(f, table.values.shape)
    # rows at or below the horizon (kept, masked, in MERL-grid tables) have no place in a table file
    above = table.above_horizon()
    sub = table.select(above)
    out = sub.with_values(sub.from_brdf(f[above])).replace(source=f"{model.name} at the directions of {table.source}")
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, f"{model.name}.csv")
    write_csv(out, path)
    data, _ = table.brdf()
    e = error_metrics(f, data, table.mask, np.cos(table.theta_i)[:, None])
    dropped = f", {int((~above).sum())} below-horizon directions left out" if (~above).any() else ""
    print(f"wrote {path} ({out.n_samples} directions, quantity {table.quantity}{dropped})")
    if e["n"]:
        print(f"{model.name} vs {table.source}: rmse {e['rmse']:.4g} 1/sr, cos_log_rmse {e['cos_log_rmse']:.4g}, "
              f"log_rmse {e['log_rmse']:.4g}, rel_rmse {e['rel_rmse']:.4g} over {e['n']} values")
    else:
        print(f"{model.name} vs {table.source}: no valid values to compare")
    return 0


def cmd_fit(args) -> int:
    """Fit a BSDF to a table and write the report (float64 unless --float32)."""
    import jax

    previous = bool(jax.config.jax_enable_x64)
    jax.config.update("jax_enable_x64", not args.float32)
    try:
        return _fit(args)
    finally:  # main() may run inside a larger program (tests, notebooks): leave its setting alone
        jax.config.update("jax_enable_x64", previous)


def _fit(args) -> int:
    import shlex

    from . import registry
    from .fit.report import write_report
    from .fit.solve import fit
    from .fit.tables.io import read_table

    say = (lambda *a: None) if args.quiet else (lambda *a: print(*a, flush=True))  # noqa: E731
    model = registry.get(args.model)
    if model.kind != "bsdf":
        raise ValueError(f"{model.name} is a {model.kind}; tables are fitted with BSDFs")
    if args.starts < 1 or args.max_steps < 1:
        raise ValueError("--starts and --max-steps must be >= 1")
    init = _parse_params(model, args.param, args.preset)
    fix = _parse_fix(args.fix)
    _check_fix(model, fix)
    table = read_table(args.table, stride=args.stride)
    say(f"table: {table.summary()}")
    say(f"fitting {model.name} ({args.loss} metric, solver {args.solver}, {args.starts} start(s), "
        f"{'float32' if args.float32 else 'float64'}"
        + (f", fixed: {', '.join(fix)}" if fix else "") + ")")
    say("compiling the solve with XLA (one-off, can take tens of seconds) ...")
    result = fit(model, table, init=init, fix=fix, metric=args.loss, max_theta_deg=args.max_theta,
                 use_sigma=not args.ignore_sigma, solver=args.solver, max_steps=args.max_steps,
                 n_starts=args.starts, seed=args.seed, verbose=0 if args.quiet else args.progress_every)
    print(result.summary(), flush=True)
    argv = list(args._argv)
    options = {k: v for k, v in vars(args).items() if k not in ("fn", "_argv")}
    extra = dict(command="appearance-jax " + shlex.join(argv), argv=argv, options=options)
    say(f"writing the report to {args.out}:")
    paths = write_report(result, args.out, model=model, progress=say, extra=extra, plots=not args.no_plots)
    if args.quiet:
        print(f"wrote {', '.join(paths.values())}")
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
    pe = sub.add_parser("eval", help="evaluate a BSDF on an in-plane grid or at a table's directions")
    pe.add_argument("--model", required=True)
    pe.add_argument("--param", action="append", metavar="NAME=VALUE",
                    help="repeatable; bands as a,b,c; preset=P starts from a preset")
    pe.add_argument("--theta-i", default=None, help="degrees: list a,b,c or range a:b:step (default 0,30,60)")
    pe.add_argument("--theta-o", default=None,
                    help="signed degrees, negative = retro side (default -89:89:1)")
    pe.add_argument("--table", default=None, metavar="TABLE",
                    help="evaluate at this table's directions instead (.csv, .binary, proxy:NAME[:GRID]); "
                         "writes a CSV in the table's quantity and prints the error against it")
    pe.add_argument("--stride", type=int, default=None, help="MERL bin stride for --table (default 3)")
    pe.add_argument("--out", default="out")
    pe.set_defaults(fn=cmd_eval)
    from .fit.solve import SOLVERS
    from .fit.solve.residuals import METRICS

    pf = sub.add_parser("fit", help="fit a BSDF to a measured (or proxy) table; write parameters, residuals, figures",
                        description="Fit a BSDF to a table and write params.json, residuals.csv, maps.png, "
                                    "slices.png and scatter.png (appearance_jax.fit.report).")
    pf.add_argument("table", metavar="TABLE", help="PATH.csv | PATH.binary | proxy:NAME[:gonio|in_plane|merl]")
    pf.add_argument("--model", required=True, help="a BSDF (appearance-jax models lists them)")
    pf.add_argument("--preset", default=None, help="start from this preset of the model")
    pf.add_argument("--param", action="append", metavar="NAME=VALUE",
                    help="start value (repeatable; bands as a,b,c; static fields such as distribution=beckmann)")
    pf.add_argument("--fix", action="append", metavar="NAME[=VALUE]",
                    help="hold a parameter fixed, at VALUE or at its start value (repeatable)")
    pf.add_argument("--loss", choices=METRICS, default="l2", help="fit metric (default l2)")
    pf.add_argument("--solver", choices=SOLVERS, default="lm", help="default lm (Levenberg-Marquardt)")
    pf.add_argument("--starts", type=int, default=1, help="number of starts (> 1 adds random starts; default 1)")
    pf.add_argument("--seed", type=int, default=0, help="seed of the random starts")
    pf.add_argument("--max-theta", type=_max_theta, default=85.0, metavar="DEG",
                    help="mask samples with theta_i or theta_o above DEG (default 85; 'none' keeps all)")
    pf.add_argument("--stride", type=int, default=None,
                    help="MERL bin stride for .binary (default 3) and proxy:NAME:merl (default 5)")
    pf.add_argument("--max-steps", type=int, default=400, help="solver step limit (default 400)")
    pf.add_argument("--ignore-sigma", action="store_true", help="do not weight by the table's uncertainties")
    pf.add_argument("--float32", action="store_true", help="fit in float32 (default: float64)")
    pf.add_argument("--progress-every", type=int, default=10, metavar="K", help="print the loss every K steps")
    pf.add_argument("--no-plots", action="store_true", help="write params.json and residuals.csv only")
    pf.add_argument("--out", default="out/fit", help="report folder (default out/fit)")
    pf.add_argument("--quiet", action="store_true", help="print only the result and the files written")
    pf.set_defaults(fn=cmd_fit)
    pd = sub.add_parser("demo", help="evaluation demo of all BSDFs + a gradient")
    pd.add_argument("--out", default="out/demo")
    pd.set_defaults(fn=cmd_demo)
    argv = sys.argv[1:] if argv is None else list(argv)
    args = p.parse_args(argv)
    args._argv = argv
    try:
        return args.fn(args)
    except (ValueError, KeyError, OSError) as e:  # TableError is a ValueError; OSError: missing file, unwritable --out
        msg = e.args[0] if isinstance(e, KeyError) and e.args else str(e)  # KeyError's str() adds quotes
        print(f"appearance-jax {args.cmd}: error: {msg}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
