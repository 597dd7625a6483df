"""``appearance-jax eval``: a BSDF on an in-plane grid (CSV + PNG) or at a table's directions (CSV).

Both write the one table format the fitters read (``appearance-jax table v1``,
:func:`appearance_jax.fit.tables.io.write_table`), so ``appearance-jax fit`` takes the CSV back.
"""

from __future__ import annotations

import os

import numpy as np

from . import checks

NAME = "eval"


def evaluate_in_plane(model, params, theta_i_deg, theta_o_deg):
    """BSDF values on an in-plane grid (degrees, signed theta_o); returns (theta_i, theta_o, f[..., bands])."""
    import jax.numpy as jnp

    from ..fit.report.geometry import eval_in_plane

    ti, to = np.meshgrid(theta_i_deg, theta_o_deg, indexing="ij")
    f = eval_in_plane(model, params, jnp.deg2rad(ti.ravel()), jnp.deg2rad(to.ravel()))
    return ti.ravel(), to.ravel(), np.asarray(f, np.float64)


def grid_table(model, params, theta_i_deg, theta_o_deg, f):
    """The in-plane BRDF table of :func:`evaluate_in_plane`'s output (a one-band BSDF, the same in
    every band, is written as R = G = B; a spectral one at its ``wavelengths``)."""
    from ..fit.tables.table import Table

    f = np.asarray(f, np.float64)
    if f.ndim == 1:
        f = f[:, None]
    kw = {}
    wl = getattr(params, "wavelengths", None)
    if getattr(params, "color", None) == "spectral" and wl is not None and len(wl) == f.shape[1]:
        kw = dict(bands=tuple(f"{w:g}" for w in wl), wavelengths=np.asarray(wl, np.float64))
    elif f.shape[1] == 1:
        f = np.repeat(f, 3, axis=1)
    elif f.shape[1] != 3:
        raise ValueError(f"{model.name} gives {f.shape[1]} bands, neither RGB nor wavelengths; the table "
                         "format has no columns for them")
    return Table.in_plane(np.deg2rad(theta_i_deg), np.deg2rad(theta_o_deg), f, quantity="brdf",
                          source=f"{model.name} (appearance-jax eval)", **kw)


def plot_in_plane(path, curves, title):
    """Curves (label, signed theta_o in degrees, f cos theta_o) on a log axis, saved as PNG."""
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


def luminance(f):
    from ..core.spectral import luminance_or_mean

    return np.asarray(luminance_or_mean(np.asarray(f, np.float64)))


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        NAME, help="evaluate a BSDF on an in-plane grid or at a table's directions; write a CSV",
        description="Evaluate a BSDF and write its values as an appearance-jax table v1 CSV (the format "
                    "fit reads): on an in-plane grid (quantity brdf, plus a PNG of the curves), or with "
                    "--table at that table's directions, in its quantity, printing the error against it.")
    p.add_argument("--model", required=True, help="a BSDF (appearance-jax models lists them)")
    p.add_argument("--param", action="append", metavar="NAME=VALUE",
                   help="parameter value (repeatable; bands as a,b,c; preset=P starts from a preset)")
    p.add_argument("--theta-i", default=None, metavar="DEG",
                   help="incidence angles in degrees: list a,b,c or range a:b:step (default 0,30,60)")
    p.add_argument("--theta-o", default=None, metavar="DEG",
                   help="signed outgoing angles in degrees, negative = retro side (default -89:89:1)")
    p.add_argument("--table", default=None, metavar="TABLE",
                   help="evaluate at this table's directions instead (.csv, .binary, proxy:NAME[:GRID]); "
                        "writes a CSV in the table's quantity and prints the error against it")
    p.add_argument("--stride", type=int, default=None, metavar="S",
                   help="MERL bin stride for --table (.binary: default 3; proxy:NAME:merl: default 5)")
    p.add_argument("--out", default="out", metavar="DIR", help="output folder, created if needed (default out)")
    p.set_defaults(fn=run)


def run(args) -> int:
    model = checks.model(args.model, "evaluation on angles is for")
    params = checks.params(model, args.param)
    checks.out_folder("--out", args.out)
    checks.stride(args.stride)
    if args.table is not None:
        if args.theta_i is not None or args.theta_o is not None:
            raise checks.UsageError("--theta-i/--theta-o select the in-plane grid; with --table the table's "
                                    "angles are used")
        checks.table_spec(args.table, args.stride)
        return _eval_on_table(model, params, args)
    if args.stride is not None:
        raise checks.UsageError(f"--stride {args.stride}: applies to --table (MERL .binary files, proxy:NAME:merl)")
    th_i = np.unique(checks.angle_list("--theta-i", args.theta_i or "0,30,60", 0.0, 90.0))
    th_o = np.unique(checks.angle_list("--theta-o", args.theta_o or "-89:89:1"))
    os.makedirs(args.out, exist_ok=True)
    ti, to, f = evaluate_in_plane(model, params, th_i, th_o)
    from ..fit.tables.io import write_table

    path = os.path.join(args.out, f"{model.name}.csv")
    write_table(grid_table(model, params, ti, to, f), path, in_plane=True)
    cos_o = np.cos(np.deg2rad(to))
    curves = [(f"theta_i = {a:g}", to[ti == a], luminance(f[ti == a]) * cos_o[ti == a]) for a in th_i]
    plot_in_plane(os.path.join(args.out, f"{model.name}.png"), curves, f"{model.name} (in-plane)")
    print(f"wrote {path} ({len(ti)} rows, quantity brdf) and {model.name}.png")
    return 0


def _eval_on_table(model, params, args) -> int:
    """eval --table: the model at the table's directions, written in the table's quantity."""
    from ..core.model import estimate_of
    from ..fit.solve.residuals import error_metrics
    from ..fit.tables.io import read_table, write_table

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
    write_table(out, path)
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
