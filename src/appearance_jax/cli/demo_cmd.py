"""``appearance-jax demo``: every registered BSDF in-plane at its defaults, and one gradient."""

from __future__ import annotations

import json
import os

import numpy as np

from . import checks
from .eval_cmd import evaluate_in_plane, grid_table, luminance, plot_in_plane

NAME = "demo"


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(NAME, help="evaluation demo of every BSDF and a gradient (the README's demo)",
                              description="Evaluate every registered BSDF in-plane at its default parameters; "
                                          "write one CSV per model, demo.png and summary.json (with "
                                          "d f / d alpha of rough_conductor at the mirror direction).")
    p.add_argument("--out", default="out/demo", metavar="DIR", help="output folder (default out/demo)")
    p.set_defaults(fn=run)


def run(args) -> int:
    import jax

    from .. import registry
    from ..core.frame import in_plane_directions
    from ..fit.tables.io import write_table

    checks.out_folder("--out", args.out)
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
        path = os.path.join(args.out, f"{model.name}.csv")
        write_table(grid_table(model, params, ti, to, f), path, in_plane=True)
        sel = ti == 30.0
        curves.append((model.name, to[sel], luminance(f[sel]) * np.cos(np.deg2rad(to[sel]))))
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
