"""A feather geometry texture from Bézier curves (Padrón App. B.3, M30): writes docs/img/feather-texture.png.

An illustrative contour feather (not a measured one): the rachis, two vane contours fitted to landmark
points by least squares (``fit_bezier``), 60 barbs per vane at 40 degrees bending towards the tip, and
the R (barb angle), G (barb length) and B (mask) channels that the feather BSDF reads.

    python3 tools/feather_texture.py [--out docs/img/feather-texture.png] [--size 400 240]
"""

import argparse
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from appearance_jax.bsdf import feather_texture as ft  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
EXTENT = (-3.5, 3.5, -0.5, 11.2)


def outline():
    """Vane contours fitted to landmarks, as one would click them on a photograph [T:1377]."""
    s = np.linspace(0, 1, 25)
    left = np.stack([-2.9 * np.sin(np.pi * s) ** 0.8 * (1 - 0.25 * s), 0.8 + 9.8 * s], -1)
    right = np.stack([2.2 * np.sin(np.pi * s) ** 0.8 * (1 - 0.1 * s), 0.8 + 9.8 * s], -1)
    return ft.Outline(rachis=[[0, 0], [0.3, 4], [0.2, 8], [0, 10.6]], left=ft.fit_bezier(left, 4),
                      right=ft.fit_bezier(right, 4), shaft_width=(0.25, 0.04))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "img" / "feather-texture.png"))
    ap.add_argument("--size", type=int, nargs=2, default=(400, 240), metavar=("ROWS", "COLS"))
    args = ap.parse_args()
    o = outline()
    b = np.concatenate([ft.barbs(o, 60, 40.0, side=side, bend=0.08, jitter=0.02, t_range=(0.08, 0.97), seed=i)
                        for i, side in enumerate(("left", "right"))])
    tex = ft.rasterize(o, b, tuple(args.size), EXTENT)
    vane = tex[..., 2] == ft.VANE
    fig, ax = plt.subplots(1, 4, figsize=(12, 5.2))
    for c in b:
        xy = ft.bezier(c, np.linspace(0, 1, 30))
        ax[0].plot(xy[:, 0], xy[:, 1], lw=0.5, c="k")
    for c in (o.rachis, o.left, o.right):
        xy = ft.bezier(c, np.linspace(0, 1, 100))
        ax[0].plot(xy[:, 0], xy[:, 1], c="C3")
    ax[0].set(aspect="equal", xlim=EXTENT[:2], ylim=EXTENT[2:], title="Bézier rachis, contours, barbs")
    panels = ((np.degrees(np.where(vane, tex[..., 0], np.nan)), "twilight", "R: barb angle [deg]"),
              (np.where(vane, tex[..., 1], np.nan), "viridis", "G: barb length from the rachis"),
              (tex[..., 2], "gray", "B: mask (background 0, shaft 1, vane 2)"))
    for a, (img, cmap, label) in zip(ax[1:], panels):
        im = a.imshow(img, extent=EXTENT, cmap=cmap)
        fig.colorbar(im, ax=a, shrink=0.6)
        a.set_title(label, fontsize=9)
    fig.tight_layout()
    fig.savefig(args.out, dpi=90)
    print(f"wrote {args.out}: {vane.sum()} vane, {(tex[..., 2] == ft.SHAFT).sum()} shaft pixels")


if __name__ == "__main__":
    main()
