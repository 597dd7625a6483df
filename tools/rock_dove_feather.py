"""rock_dove against the flatland feather mode: the figure and the numbers of docs/rock_dove.md.

    python3 tools/rock_dove_feather.py [--out docs/img] [--paths 262144]

Traces ``--paths`` rays from w_i = (theta 0.5, phi 0.3) through the row of barbule arcs of Huang's
fit (``flatland.feather``: flatland's intersection code, a uniform longitudinal position per hit)
and compares what leaves after one scattering with the model, over bins uniform in y_o (the
sine of the longitudinal angle) and psi_o = atan2(x_o, z_o):

1. mirror arcs (reflectance 1) against ``rock_dove.reflection_geometry`` (S_R with I_R = 1);
2. the film without melanin against ``rock_dove.eval`` (S_R with Airy I_R), per band;
3. the film over melanin (R + TRT) against ``rock_dove.eval``: the TRT totals and where they go.

The model's bin integrals use 256 jittered points per bin. Prints totals with standard errors,
the largest bin z-score and chi^2 per bin, and writes ``rock-dove-feather.png`` (panel rows:
flatland, model, z-score; columns: the three cases, band 510 nm). About two minutes on 2 cores.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from appearance_jax.bsdf import rock_dove as rd  # noqa: E402
from appearance_jax.core.frame import spherical_direction  # noqa: E402
from appearance_jax.flatland import feather  # noqa: E402


def model_bins(f, p, wi, hist):
    return feather.bin_average(lambda a, b: f(p, a, b), wi, hist)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/img")
    ap.add_argument("--paths", type=int, default=2 ** 18)
    a = ap.parse_args()
    p = rd.PRESETS["thesis_fit"]
    wi = spherical_direction(0.5, 0.3)
    cases = [("mirror arcs vs S_R (I_R = 1)", dict(mirror=1.0), rd.reflection_geometry, p),
             ("film, no melanin vs S_R", dict(melanin=0.0), rd.eval, p.replace(melanin_reflectance=0.0)),
             ("film over melanin vs S_R + S_TRT", dict(), rd.eval, p)]
    fig, axes = plt.subplots(3, 3, figsize=(11, 9), sharex=True, sharey=True)
    print(f"w_i = (theta 0.5, phi 0.3), thesis_fit, {a.paths} paths per case; bands 650 / 510 / 475 nm")
    for c, (name, kw, f, q) in enumerate(cases):
        sec = feather.barbule_row(p.b, p.phi0, p.phi1, p.H, p.mu, p.theta_d, **kw)
        h = feather.feather_histogram(sec, wi, jax.random.PRNGKey(c), a.paths, n_y=32, n_psi=24, max_events=2)
        mean, se = (np.asarray(v[1]) for v in h.density())
        mm, ms = model_bins(f, q, wi, h)
        area = (np.diff(np.asarray(h.y_edges))[:, None] * np.diff(np.asarray(h.psi_edges))[None, :])[..., None]
        sd = np.sqrt(se ** 2 + ms ** 2)
        live = (mean > 0) | (mm > 0)
        z = np.where(live, (mean - mm) / np.where(sd > 0, sd, 1.0), 0.0)
        tf, tm = (mean * area).sum((0, 1)), (mm * area).sum((0, 1))
        sf, sm = np.sqrt(((se * area) ** 2).sum((0, 1))), np.sqrt(((ms * area) ** 2).sum((0, 1)))
        print(f"{name}: passed {float(h.fraction[0, 0]):.4f} (model T {float(rd.transmission(p, wi)):.4f}), "
              f"truncated {float(h.truncated):.3f}")
        for b in range(mean.shape[-1]):
            zb = z[..., b][live[..., b]]
            print(f"  band {b}: flatland {tf[b]:.5f} +- {sf[b]:.5f}, model {tm[b]:.5f} +- {sm[b]:.5f}; "
                  f"{zb.size} bins, max |z| {np.abs(zb).max():.2f}, mean z^2 {np.mean(zb ** 2):.2f}")
        b = min(1, mean.shape[-1] - 1)
        ext = (-90, 90, -1, 1)
        vmax = np.percentile(np.concatenate([mean[..., b].ravel(), mm[..., b].ravel()]), 99.5)
        for r, (img, title) in enumerate(((mean[..., b], "flatland"), (mm[..., b], "model"))):
            axes[r, c].imshow(img, origin="lower", extent=ext, aspect="auto", vmin=0, vmax=vmax, cmap="magma")
            axes[r, c].set_title(f"{title}: {name}" if r == 0 else title, fontsize=8)
        im = axes[2, c].imshow(z[..., b], origin="lower", extent=ext, aspect="auto", vmin=-5, vmax=5, cmap="coolwarm")
        axes[2, c].set_title("z = (flatland - model) / se", fontsize=8)
    for ax in axes[2]:
        ax.set_xlabel("psi_o = atan2(x_o, z_o) [deg]")
    for ax in axes[:, 0]:
        ax.set_ylabel("y_o (along the barbule)")
    fig.colorbar(im, ax=axes[2].tolist(), shrink=0.8)
    fig.suptitle("rock_dove vs flatland feather mode: S <w_o, n> after one scattering (510 nm band)", fontsize=10)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "rock-dove-feather.png", dpi=110)
    print(f"wrote {out / 'rock-dove-feather.png'}")


if __name__ == "__main__":
    main()
