"""Figure of docs/rock_dove.md: scatterogram-like maps of the rock-dove barbule BSDF.

    python3 tools/rock_dove_figures.py [--out docs/img] [--size 121]

``rock-dove-scatterograms.png``: S <w_o, n> over the upper hemisphere (azimuthal equidistant
projection: the radius is theta_o, 90 deg at the rim; +x right = across the barbules in the barb
plane, +y up = along the barbule), linear sRGB from the CIE-integrated spectrum (color="cie"),
each panel scaled to its own 99th percentile and sRGB-encoded. Rows: Huang's fit with the green
upper-neck film (595 nm) and the purple lower-neck film (530 nm) [T:1517-1519]; columns: light
along the barb-plane normal, and 30 deg off it across the barbules (+x and -x). The mirror
direction of w_i is marked (+). Takes about a minute on 2 cores.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from appearance_jax.bsdf import rock_dove  # noqa: E402
from appearance_jax.core import spectral  # noqa: E402
from appearance_jax.core.vec import Vec3  # noqa: E402


def hemisphere(size):
    u = np.linspace(-1.0, 1.0, size)
    x, y = np.meshgrid(u, u[::-1])
    r = np.hypot(x, y)
    inside = r < 1.0
    theta = r * (math.pi / 2)
    phi = np.arctan2(y, x)
    d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
    return d, inside


def panel(p, theta_i, size):
    d, inside = hemisphere(size)
    comps = (np.where(inside, d[0], 0.0), np.where(inside, d[1], 0.0), np.where(inside, d[2], 1.0))
    wo = Vec3(*(jnp.asarray(c.ravel()) for c in comps))
    wi = Vec3(*(jnp.full(wo.x.shape, v) for v in (math.sin(theta_i), 0.0, math.cos(theta_i))))
    f = np.asarray(rock_dove.eval(p, wi, wo)) * np.asarray(wo.z)[:, None]
    img = np.where(inside.ravel()[:, None], np.maximum(f, 0.0), 0.0).reshape(size, size, 3)
    return img, inside


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="docs/img")
    ap.add_argument("--size", type=int, default=121)
    args = ap.parse_args()
    rows = [("green neck, d = 595 nm", 595.0), ("purple neck, d = 530 nm", 530.0)]
    cols = [("w_i = n", 0.0), ("w_i 30 deg towards +x", math.radians(30)), ("w_i 30 deg towards -x", math.radians(-30))]
    fig, axes = plt.subplots(len(rows), len(cols), figsize=(3.3 * len(cols), 3.5 * len(rows)), dpi=110)
    for r, (rname, d) in enumerate(rows):
        p = rock_dove.Params(thickness=d, color="cie", n_phi=6)
        for c, (cname, ti) in enumerate(cols):
            img, inside = panel(p, ti, args.size)
            scale = np.percentile(img[inside].max(axis=-1), 99) or 1.0
            rgb = np.asarray(spectral.linear_to_srgb(jnp.clip(img / scale, 0.0, 1.0)))
            ax = axes[r, c]
            ax.imshow(rgb, extent=(-90, 90, -90, 90))
            ax.add_patch(plt.Circle((0, 0), 90, fill=False, color="0.5", lw=0.6))
            mx = -math.degrees(ti)  # mirror direction about n: theta_o = theta_i on the other side
            ax.plot([mx], [0], "+", color="white", ms=8, mew=1.0)
            ax.set_xticks([-90, 0, 90])
            ax.set_yticks([-90, 0, 90])
            ax.set_title(f"{rname}\n{cname} (x{1 / scale:.2g})", fontsize=8)
            if r == len(rows) - 1:
                ax.set_xlabel("across barbules [deg]", fontsize=8)
            if c == 0:
                ax.set_ylabel("along barbule [deg]", fontsize=8)
    fig.suptitle("rock_dove, Huang's fit: S <w_o, n>, CIE sRGB, own scale per panel", fontsize=9)
    fig.tight_layout()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "rock-dove-scatterograms.png")
    print(out / "rock-dove-scatterograms.png")


if __name__ == "__main__":
    main()
