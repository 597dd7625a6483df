"""Recipe: fit three analytic BRDFs to the seven MERL fabric **proxies**.

The MERL fabrics (beige, black, blue, dark-specular, pink, red, white) are available here as
Neural-BRDF proxies (Sztrajman et al. 2021; neural fits of the MERL measurements of Matusik
et al. 2003, see ``data/nbrdf/PROVENANCE.md``): every number below describes a fit to a
proxy, not to the raw measurement.

Each proxy is sampled on the same out-of-plane gonioreflectometer grid (theta_i in
{0, 20, 40, 60, 75} deg, theta_o 0..80 deg every 10, phi_o - phi_i 0..180 deg every 30: 315
directions x RGB), and each model is fitted to all seven tables at once with
:func:`appearance_jax.fit.solve.batch.fit_batch` (one batched program per model) in the
cosine-weighted log metric (Löw et al. 2012; the loss the proxies were trained with):

==========================  ==========================================================  =========
model                       free parameters                                             fixed
==========================  ==========================================================  =========
lambert                     reflectance[RGB]                                            -
rough_plastic               alpha, diffuse_reflectance[RGB], specular_reflectance[RGB]  eta = 1.5
rough_conductor+lambert     alpha, specular_reflectance[RGB], reflectance[RGB]          eta = 0.15, k = 4
==========================  ==========================================================  =========

For the Cook-Torrance-plus-Lambert baseline the conductor is achromatic and nearly perfect
(eta = 0.15, k = 4: F0 = 0.965, nearly flat in angle), so the strength of the specular lobe
is its scale specular_reflectance per channel, from 0 to 0.965. (Tried and rejected: eta =
1.5 with k = 0, a dielectric Fresnel factor, caps the lobe at F0 = 0.04 and pinned
specular_reflectance at 1 for the bright fabrics; eta = 1.5 with k fitted puts a floor of
0.04 under F0 and pinned k at 0 for the dark ones.)

Errors (on the valid samples, see :func:`appearance_jax.fit.solve.residuals.error_metrics`):
``cos_log_rmse`` = RMS of log(1 + f_fit cos th_i) - log(1 + f_proxy cos th_i), and
``log_rmse`` = RMS of ln(f_fit + 1e-3) - ln(f_proxy + 1e-3).

    python3 fitting/merl_fabrics.py --out out/merl_fabrics

writes ``results.csv`` (one row per fabric and model: parameters, 1-sigma, errors,
iterations), ``results.md`` (the same as a Markdown table) and prints it.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time

import numpy as np

MODELS = {
    "lambert": dict(init={}, fix=None),
    "rough_plastic": dict(init=dict(alpha=0.3, diffuse_reflectance=0.3, specular_reflectance=0.5), fix={"eta": 1.5}),
    "rough_conductor+lambert": dict(init=dict(alpha=0.3, specular_reflectance=0.3, reflectance=0.3),
                                    fix={"eta": (0.15, 0.15, 0.15), "k": (4.0, 4.0, 4.0)}),
}


def fit_fabrics(fabrics, models, metric="cos_log", progress=print):
    """Fit every model to every fabric proxy; returns a list of row dicts."""
    import jax

    jax.config.update("jax_enable_x64", True)
    from appearance_jax import registry
    from appearance_jax.fit import proxy
    from appearance_jax.fit.solve.batch import fit_batch

    tables = [proxy.proxy_table(name, "gonio") for name in fabrics]
    base = tables[0]
    values = np.stack([t.values for t in tables])
    rows = []
    for model_name in models:
        cfg = MODELS[model_name]
        model = registry.get(model_name)
        t0 = time.perf_counter()
        res = fit_batch(model, base, values, init=model.Params(**cfg["init"]), fix=cfg["fix"], metric=metric,
                        max_steps=1000)
        progress(f"{model_name}: {len(fabrics)} proxies fitted in {time.perf_counter() - t0:.1f} s "
                 f"({res.compile_time:.1f} s compile, {res.wall_time:.2f} s solve)")
        rows += result_rows(res, fabrics, model_name)
    return rows


def result_rows(res, fabrics, model_label):
    """One row dict per fabric of a batched fit: errors in both metrics, parameters and 1-sigma."""
    rows = []
    for k, fabric in enumerate(fabrics):
        item = res.item(k)
        row = dict(fabric=fabric, model=model_label, converged=bool(item.converged),
                   iterations=int(res.iterations[k]), **{m: item.metrics[m] for m in ("cos_log_rmse", "log_rmse")},
                   at_bound=" ".join(item.at_bound))
        for lab, v, s in zip(item.labels, item.x, item.sigma):
            row[lab] = float(v)
            row[f"sigma({lab})"] = float(s)
        rows.append(row)
    return rows


def _fmt(v):
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def write_results(rows, out):
    os.makedirs(out, exist_ok=True)
    keys = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(os.path.join(out, "results.csv"), "w", newline="") as fh:
        fh.write("# fits of analytic BRDFs to Neural-BRDF PROXIES of the MERL fabrics (see fitting/merl_fabrics.py)\n")
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    lines = ["| fabric (proxy) | model | cos-log RMSE | log-RMSE | parameters (± 1σ) |", "|---|---|---|---|---|"]
    for r in rows:
        params = ", ".join(f"{k} {r[k]:.3g} ± {r['sigma(' + k + ')']:.1g}" + (" (at bound)" if k in r["at_bound"] else "")
                           for k in r
                           if k not in ("fabric", "model", "converged", "iterations", "cos_log_rmse", "log_rmse",
                                        "at_bound")
                           and not k.startswith("sigma("))
        lines.append(f"| {r['fabric']} | {r['model']} | {r['cos_log_rmse']:.4f} | {r['log_rmse']:.3f} | {params} |")
    md = "\n".join(lines) + "\n"
    with open(os.path.join(out, "results.md"), "w") as fh:
        fh.write(md)
    return md


def main(argv=None) -> int:
    from appearance_jax.fit import proxy

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="out/merl_fabrics")
    ap.add_argument("--fabrics", nargs="*", default=list(proxy.FABRICS))
    ap.add_argument("--models", nargs="*", default=list(MODELS), choices=list(MODELS))
    ap.add_argument("--metric", default="cos_log", choices=("l2", "cos_log", "relative"))
    args = ap.parse_args(argv)
    rows = fit_fabrics(args.fabrics, args.models, args.metric)
    print(write_results(rows, args.out))
    print(f"wrote {args.out}/results.csv and results.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
