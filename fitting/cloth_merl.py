"""Recipe: fit Sadeghi's cloth model to the seven MERL fabric **proxies**, next to the simple models.

The MERL fabrics (beige, black, blue, dark-specular, pink, red, white) are available here only as
Neural-BRDF proxies (neural fits of the MERL measurements; ``data/nbrdf/PROVENANCE.md``): every
number below describes a fit to a proxy, not to the raw measurement. The proxies are sampled on
the out-of-plane gonioreflectometer grid of :mod:`merl_fabrics` (theta_i in {0, 20, 40, 60, 75}
deg, theta_o 0..80 deg, phi_o - phi_i 0..180 deg: 315 directions x RGB).

Models (each fitted to all seven tables at once, :func:`appearance_jax.fit.solve.batch.fit_batch`, in the
cosine-weighted log metric; both error metrics are reported):

* ``rough_plastic`` (eta = 1.5 fixed) and ``rough_conductor+lambert``: the baselines of
  :mod:`merl_fabrics`;
* ``cloth_weave`` (:mod:`appearance_jax.bsdf.cloth.weaves`) with the weave family ``plain``,
  ``satin`` and ``twill``; 14 free parameters: per thread family the RGB albedo, k_d, gamma_s,
  gamma_v, the weave angle alpha and the threads' index eta (the only scale of the Fresnel
  surface lobe, as in Table 5.2 where it is fitted per fabric).

MERL measures isotropic BRDFs (the fabric wrapped around a sphere shows every orientation), so the
cloth model is averaged over 6 weave orientations (``n_rotations``). The weave family of each
fabric is *chosen* by the fit: the family with the lowest cosine-weighted log error.

    python3 fitting/cloth_merl.py --out out/cloth_merl            # ~25 min on 2 cores
    python3 fitting/cloth_merl.py --fabrics red-fabric --weaves satin --steps 40   # quick look

writes ``results.csv`` / ``results.md`` (one row per fabric and model: errors, parameters, 1-sigma),
``best.md`` (per fabric: the best model in each metric, and cloth vs rough_plastic) and
``errors.png`` (both metrics per fabric and model). Results and what they show: ``fitting/README.md``
(the cloth model loses to rough_plastic on all seven proxies).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import merl_fabrics  # noqa: E402  (the baselines, the table format and the results writer)

WEAVES = ("plain", "satin", "twill")
CLOTH_INIT = dict(eta=1.46, albedo_1=0.3, albedo_2=0.3, k_d_1=0.3, k_d_2=0.3, gamma_s_1=8.0, gamma_s_2=8.0,
                  gamma_v_1=16.0, gamma_v_2=16.0, alpha=25.0)
BASELINES = ("rough_plastic", "rough_conductor+lambert")


def fit_cloth(fabrics, weaves, metric="cos_log", steps=100, n_rotations=6, n_samples=16, progress=print):
    """Fit cloth_weave (one weave family at a time) to every fabric proxy; row dicts as merl_fabrics."""
    import jax

    jax.config.update("jax_enable_x64", True)
    from appearance_jax.bsdf.cloth import weaves as cloth_weaves
    from appearance_jax.fit import proxy
    from appearance_jax.fit.solve.batch import fit_batch

    tables = [proxy.proxy_table(name, "gonio") for name in fabrics]
    values = np.stack([t.values for t in tables])
    rows = []
    for kind in weaves:
        init = cloth_weaves.Params(weave=kind, n_rotations=n_rotations, n_samples=n_samples, **CLOTH_INIT)
        t0 = time.perf_counter()
        res = fit_batch(cloth_weaves.MODEL, tables[0], values, init=init, metric=metric, max_steps=steps)
        progress(f"cloth_weave[{kind}]: {len(fabrics)} proxies fitted in {time.perf_counter() - t0:.1f} s "
                 f"({res.compile_time:.1f} s compile)")
        rows += merl_fabrics.result_rows(res, fabrics, f"cloth_weave[{kind}]")
    return rows


def best_per_fabric(rows):
    """Per fabric: the best model in each metric, the best cloth weave, and cloth vs rough_plastic."""
    out = []
    for fabric in dict.fromkeys(r["fabric"] for r in rows):
        mine = [r for r in rows if r["fabric"] == fabric]
        cloth = [r for r in mine if r["model"].startswith("cloth_weave")]
        plastic = [r for r in mine if r["model"] == "rough_plastic"]
        entry = dict(fabric=fabric,
                     best_cos_log=min(mine, key=lambda r: r["cos_log_rmse"])["model"],
                     best_log=min(mine, key=lambda r: r["log_rmse"])["model"])
        if cloth:
            c = min(cloth, key=lambda r: r["cos_log_rmse"])
            entry.update(cloth_weave=c["model"], cloth_cos_log=c["cos_log_rmse"], cloth_log=c["log_rmse"])
        if plastic:
            entry.update(plastic_cos_log=plastic[0]["cos_log_rmse"], plastic_log=plastic[0]["log_rmse"])
        out.append(entry)
    return out


def write_best(best, out):
    lines = ["| fabric (proxy) | best (cos-log) | best (log) | chosen weave | cloth cos-log / log | "
             "rough_plastic cos-log / log | cloth beats rough_plastic (cos-log, log) |",
             "|---|---|---|---|---|---|---|"]
    for b in best:
        if "cloth_cos_log" in b and "plastic_cos_log" in b:
            beats = (f"{'yes' if b['cloth_cos_log'] < b['plastic_cos_log'] else 'no'}, "
                     f"{'yes' if b['cloth_log'] < b['plastic_log'] else 'no'}")
            cl = f"{b['cloth_cos_log']:.4f} / {b['cloth_log']:.3f}"
            pl = f"{b['plastic_cos_log']:.4f} / {b['plastic_log']:.3f}"
        else:
            beats, cl, pl = "-", "-", "-"
        lines.append(f"| {b['fabric']} | {b['best_cos_log']} | {b['best_log']} | {b.get('cloth_weave', '-')} "
                     f"| {cl} | {pl} | {beats} |")
    md = "\n".join(lines) + "\n"
    with open(os.path.join(out, "best.md"), "w") as fh:
        fh.write(md)
    return md


def plot_errors(rows, out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fabrics = list(dict.fromkeys(r["fabric"] for r in rows))
    models = list(dict.fromkeys(r["model"] for r in rows))
    fig, axes = plt.subplots(1, 2, figsize=(12, 4), constrained_layout=True)
    width = 0.8 / len(models)
    for ax, metric, label in zip(axes, ("cos_log_rmse", "log_rmse"),
                                 ("cosine-weighted log RMSE", "log RMSE, ln(f + 1e-3)")):
        for m, model in enumerate(models):
            err = [next((r[metric] for r in rows if r["fabric"] == f and r["model"] == model), np.nan) for f in fabrics]
            ax.bar(np.arange(len(fabrics)) + (m - (len(models) - 1) / 2) * width, err, width, label=model)
        ax.set_xticks(np.arange(len(fabrics)), fabrics, rotation=30, ha="right")
        ax.set_ylabel(label + " (dimensionless)")
        ax.set_title(f"{label}: fits to MERL fabric proxies")
    axes[0].legend(fontsize=7)
    path = os.path.join(out, "errors.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv=None) -> int:
    from appearance_jax.fit import proxy

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="out/cloth_merl")
    ap.add_argument("--fabrics", nargs="*", default=list(proxy.FABRICS))
    ap.add_argument("--weaves", nargs="*", default=list(WEAVES), choices=WEAVES)
    ap.add_argument("--baselines", nargs="*", default=list(BASELINES), choices=list(merl_fabrics.MODELS))
    ap.add_argument("--steps", type=int, default=100, help="solver steps for the cloth fits")
    ap.add_argument("--rotations", type=int, default=6, help="weave orientations averaged (isotropic data)")
    ap.add_argument("--samples", type=int, default=16, help="tangent samples T per curve")
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    rows = merl_fabrics.fit_fabrics(args.fabrics, args.baselines) if args.baselines else []
    rows += fit_cloth(args.fabrics, args.weaves, steps=args.steps, n_rotations=args.rotations,
                      n_samples=args.samples)
    print(merl_fabrics.write_results(rows, args.out))
    print(write_best(best_per_fabric(rows), args.out))
    print(f"wrote {args.out}/results.csv, results.md, best.md and {plot_errors(rows, args.out)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
