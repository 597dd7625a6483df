"""``appearance-jax fit TABLE --model NAME``: fit a BSDF to a table and write the report.

Every option is checked first (:mod:`.checks`), then the table is read, the solve compiled and
run, and the report written (:func:`appearance_jax.fit.report.write_report`). The last line
printed is the status; the exit code says it too (0 converged, 3 not converged; docs/cli.md).
"""

from __future__ import annotations

import inspect
import json
import os
import shlex

from . import checks, known

NAME = "fit"


def _fit_accepts(keyword: str) -> bool:
    from ..fit.solve import solvers

    return keyword in inspect.signature(solvers.fit).parameters


def add_parser(subparsers) -> None:
    from ..fit.solve import SOLVERS
    from ..fit.solve.residuals import METRICS

    p = subparsers.add_parser(
        NAME, help="fit a BSDF to a measured (or proxy) table; write parameters, residuals, figures",
        description="Fit a BSDF to a table and write params.json, residuals.csv, maps.png, slices.png and "
                    "scatter.png (appearance_jax.fit.report). Physically known parameters (appearance-jax "
                    "models NAME lists them) are held fixed unless --free NAME. Exit status: 0 converged, "
                    "2 invalid options or input, 3 not converged (report written), 1 other failures.")
    p.add_argument("table", metavar="TABLE", help="PATH.csv | PATH.binary | proxy:NAME[:gonio|in_plane|merl]")
    p.add_argument("--model", required=True, help="a BSDF (appearance-jax models lists them)")
    p.add_argument("--preset", default=None, help="start from this preset of the model")
    p.add_argument("--param", action="append", metavar="NAME=VALUE",
                   help="start value (repeatable; bands as a,b,c; static fields such as distribution=beckmann)")
    p.add_argument("--fix", action="append", metavar="NAME[=VALUE]",
                   help="hold a parameter fixed, at VALUE or at its start value (repeatable)")
    p.add_argument("--free", action="append", metavar="NAME",
                   help="fit a parameter that is held fixed by default as physically known (repeatable; "
                        "'all' frees every one)")
    p.add_argument("--loss", choices=METRICS, default="l2", help="fit metric (default l2)")
    p.add_argument("--solver", choices=SOLVERS, default="lm", help="solver (default lm, Levenberg-Marquardt)")
    p.add_argument("--starts", type=int, default=1, metavar="N",
                   help="number of starts, >= 1 (> 1 adds random starts; default 1)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random starts and of --bootstrap, >= 0 (default 0)")
    p.add_argument("--max-theta", default="85", metavar="DEG",
                   help="mask samples with theta_i or theta_o above DEG, in (0, 90] (default 85; 'none' keeps all)")
    p.add_argument("--stride", type=int, default=None, metavar="S",
                   help="MERL bin stride for .binary (default 3) and proxy:NAME:merl (default 5)")
    p.add_argument("--max-steps", type=int, default=400, metavar="N", help="solver step limit, >= 1 (default 400)")
    if _fit_accepts("bootstrap"):
        p.add_argument("--bootstrap", type=int, default=0, metavar="B",
                       help="block-bootstrap refits over incidence directions for an honest sigma, 0 (none, "
                            "default) or >= 2 (64 is a good start; seeded by --seed)")
    p.add_argument("--ignore-sigma", action="store_true", help="do not weight by the table's uncertainties")
    p.add_argument("--float32", action="store_true", help="fit in float32 (default: float64)")
    p.add_argument("--progress-every", type=int, default=0, metavar="K",
                   help="print the loss every K steps, >= 0 (default 0: silent; a solve that prints cannot be "
                        "kept in the compile cache, so it compiles on every run)")
    p.add_argument("--no-plots", action="store_true", help="write params.json and residuals.csv only")
    p.add_argument("--out", default="out/fit", metavar="DIR", help="report folder, created if needed (default out/fit)")
    p.add_argument("--quiet", action="store_true", help="print only the result, warnings, the files and the status")
    p.set_defaults(fn=run)


def check(args) -> dict:
    """Every option, before the table is read or anything compiled: the fitter's keywords
    and what the report records (raises :class:`.checks.UsageError`)."""
    model = checks.model(args.model, "tables are fitted with")
    checks.count("--starts", args.starts)
    checks.count("--max-steps", args.max_steps)
    checks.count("--seed", args.seed, 0)
    checks.count("--progress-every", args.progress_every, 0)
    if getattr(args, "bootstrap", None) is not None:
        checks.count("--bootstrap", args.bootstrap, 2, zero=True)
    max_theta = checks.max_theta(args.max_theta)
    checks.stride(args.stride)
    checks.out_folder("--out", args.out)
    checks.table_spec(args.table, args.stride)
    init = checks.params(model, args.param, args.preset)
    fix = checks.parse_fix(args.fix)
    checks.fix(model, fix)
    user_set = set(checks.assignments("--param", args.param)) - {"preset"}
    if args.preset is not None:
        user_set |= set(known.fit_fixed(model))
    fix, origin = known.resolve(model, fix, args.free, user_set)
    free = [n for n in model.Params._data_fields if n not in fix and getattr(init, n) is not None]
    if not free:
        raise checks.UsageError(f"nothing to fit: every parameter of {model.name} is fixed "
                                f"({', '.join(fix)}); release one with --free NAME or drop a --fix")
    kw = dict(init=init, fix=fix, metric=args.loss, max_theta_deg=max_theta, use_sigma=not args.ignore_sigma,
              solver=args.solver, max_steps=args.max_steps, n_starts=args.starts, seed=args.seed,
              verbose=0 if args.quiet else args.progress_every)
    if getattr(args, "bootstrap", 0):
        kw["bootstrap"] = args.bootstrap
        if _fit_accepts("bootstrap_seed"):
            kw["bootstrap_seed"] = args.seed
    return dict(model=model, kw=kw, origin=origin)


def run(args) -> int:
    """Fit a BSDF to a table and write the report (float64 unless --float32)."""
    import jax

    plan = check(args)  # before touching jax's settings, the table or the compiler
    previous = bool(jax.config.jax_enable_x64)
    jax.config.update("jax_enable_x64", not args.float32)
    try:
        return _fit(args, plan)
    finally:  # main() may run inside a larger program (tests, notebooks): leave its setting alone
        jax.config.update("jax_enable_x64", previous)


def _warnings(result) -> list[str]:
    """The result's own warnings (FitResult.warnings) or, for a result without them, the
    parameters left at a bound."""
    own = getattr(result, "warnings", None)
    if own is not None:
        return [str(w) for w in own]
    if len(result.at_bound) >= 2:
        return [f"{len(result.at_bound)} parameters ended at a bound ({', '.join(result.at_bound)}): the model "
                "may not describe this table, or parameters trade against each other; their sigma means "
                "nothing; hold physically known values fixed (--fix) or try another model"]
    return []


def _fixed_line(fix: dict, origin: dict) -> str:
    parts = []
    for name, v in fix.items():
        value = "start value" if v is None else (",".join(f"{x:g}" for x in v) if isinstance(v, tuple) else f"{v:g}")
        why = origin.get(name, {})
        parts.append(f"{name} = {value}" + (f" (default: {why['reason']}; --free {name} fits it)"
                                            if why.get("by") == "default" else ""))
    return "fixed: " + "; ".join(parts)


def _fit(args, plan) -> int:
    from ..fit import solve
    from ..fit.report import write_report
    from ..fit.tables.io import read_table

    say = (lambda *a: None) if args.quiet else (lambda *a: print(*a, flush=True))  # noqa: E731
    model, kw, origin = plan["model"], plan["kw"], plan["origin"]
    table = read_table(args.table, stride=args.stride)
    say(f"table: {table.summary()}")
    say(f"fitting {model.name} ({args.loss} metric, solver {args.solver}, {args.starts} start(s), "
        f"{'float32' if args.float32 else 'float64'})")
    if kw["fix"]:
        say(_fixed_line(kw["fix"], origin))
    say("compiling the solve with XLA (or loading it from the compile cache) ...")
    result = solve.fit(model, table, **kw)
    print(result.summary(), flush=True)
    argv = list(getattr(args, "_argv", []))
    options = {k: v for k, v in vars(args).items() if k not in ("fn", "_argv")}
    extra = dict(command="appearance-jax " + shlex.join(argv), argv=argv, options=options)
    say(f"writing the report to {args.out}:")
    paths = write_report(result, args.out, model=model, progress=say, extra=extra, plots=not args.no_plots)
    code = checks.EXIT_OK if result.converged else checks.EXIT_NOT_CONVERGED
    status = "converged" if result.converged else "not converged"
    _annotate(paths["params"], origin, code, status)
    if args.quiet:
        print(f"wrote {', '.join(paths.values())}")
    if getattr(result, "warnings", None) is None:  # a FitResult's own warnings are in its summary already
        for w in _warnings(result):
            print(f"warning: {w}")
    if result.converged:
        print(f"status: converged in {result.iterations} steps (exit {code})", flush=True)
    else:
        print(f"status: NOT converged: the solver stopped after {result.iterations} steps (--max-steps "
              f"{args.max_steps}); the values are not a minimum; raise --max-steps, add --starts or fix "
              f"parameters (exit {code})", flush=True)
    return code


def _annotate(path: str, origin: dict, code: int, status: str) -> None:
    """Add to params.json where each fixed value came from (``fixed_by``: ``--fix`` or the model's
    physically known ``default`` with its reason) and the command's exit status (``exit``)."""
    with open(path, encoding="utf-8") as fh:
        d = json.load(fh)
    d["fixed_by"] = origin
    d["exit"] = dict(code=code, status=status)
    tmp = path + ".tmp"
    with open(tmp, "w", encoding="utf-8") as fh:
        json.dump(d, fh, indent=2, allow_nan=False)
        fh.write("\n")
    os.replace(tmp, path)
