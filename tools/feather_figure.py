"""Padrón's feather surface BSDF at a glance: writes docs/img/feather.png.

Top row: the masking (Fig. 5.9's layout): w_b, w_bp, w_bd as the blue, green and red channels over the
viewer's (theta, phi) (e_bb = delta_bb = 1), and the vane's transmission w_t against its rotation about the
barb axis for Fig. 5.10's delta_bb (the backlit loss of transparency of Fig. 5.12). Bottom row: f |wo . n|
(the light per steradian of wo) over the whole sphere of wo in lat-long for a viewer at 45 deg, for the
thesis preset (white medulla) and a blue medulla, as sRGB-ish colour (the rendered bands, clipped).

    python3 tools/feather_figure.py [--n-h 64] [--out docs/img/feather.png]
"""

import argparse
import math
import pathlib

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from appearance_jax.bsdf import feather  # noqa: E402
from appearance_jax.core.frame import spherical_direction  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n-h", type=int, default=64, help="offsets per fibre and direction pair")
    ap.add_argument("--out", default=str(ROOT / "docs" / "img" / "feather.png"))
    args = ap.parse_args()

    fig, ax = plt.subplots(2, 2, figsize=(11, 7.2))
    # masking over the viewer's directions
    th = np.linspace(0.0, 0.5 * math.pi, 91)[1:]
    ph = np.linspace(-math.pi, math.pi, 181)
    T, P = np.meshgrid(th, ph, indexing="ij")
    m = feather.masking_of(feather.Params(), spherical_direction(jnp.asarray(T), jnp.asarray(P)))
    w = np.asarray(m.weight)
    rgb = np.stack([w[2], w[1], w[0]], axis=-1)  # R distal, G proximal, B barb (Fig. 5.9)
    ax[0, 0].imshow(np.clip(rgb, 0, 1), origin="lower", aspect="auto",
                    extent=[-180, 180, math.degrees(th[0]), 90])
    ax[0, 0].set(xlabel="viewer phi (deg; 0 = along the barb)", ylabel="viewer theta (deg)",
                 title="masking: barb (B), proximal (G), distal (R); black = w_t")
    # transmission against rotation about the barb axis
    rot = np.linspace(0.0, 1.5, 151)
    view = spherical_direction(jnp.asarray(rot), jnp.full(rot.shape, 0.5 * math.pi))
    for d in (0.1, 0.3, 0.5, 1.0, 3.0):
        t = np.asarray(feather.transmission(feather.Params(delta_bb=d), view))
        ax[0, 1].plot(np.degrees(rot), t, label=f"delta_bb = {d}")
    ax[0, 1].set(xlabel="rotation about the barb axis (deg)", ylabel="w_t", title="transmission (the delta's mass)")
    ax[0, 1].legend(fontsize=8)
    # f |wo . n| over the sphere of wo, viewer at 45 deg across the barb
    tho = np.linspace(0.0, math.pi, 91)[1:-1]
    pho = np.linspace(-math.pi, math.pi, 181)
    TO, PO = np.meshgrid(tho, pho, indexing="ij")
    wi = spherical_direction(math.pi / 4, 0.5 * math.pi)
    for k, (name, p) in enumerate((("thesis preset (white medulla)", feather.Params(n_h=args.n_h)),
                                   ("blue medulla d_m = (0.1, 0.3, 0.9)",
                                    feather.Params(n_h=args.n_h, medulla_albedo=(0.1, 0.3, 0.9))))):
        # in rows of wo (eval traces every pair: memory ~ pairs x n_h x events)
        rows = [feather.eval(p, wi, spherical_direction(jnp.asarray(TO[i:i + 8]), jnp.asarray(PO[i:i + 8])))
                for i in range(0, TO.shape[0], 8)]
        f, se = (np.concatenate([np.asarray(r[j]) for r in rows]) for j in (0, 1))
        img = np.asarray(f) * np.abs(np.cos(TO))[..., None]
        print(f"{name}: int f|cos| = {np.sum(img * np.sin(TO)[..., None], axis=(0, 1)) * (tho[1] - tho[0]) * (pho[1] - pho[0])}, "
              f"w_t = {float(feather.transmission(p, wi)):.3f}, median rel. stderr "
              f"{np.median(np.asarray(se)[..., 0] / np.maximum(np.asarray(f)[..., 0], 1e-12)):.2f}")
        scale = np.percentile(img, 99.5)
        ax[1, k].imshow(np.clip(img / scale, 0, 1), origin="upper", aspect="auto",
                        extent=[-180, 180, math.degrees(tho[-1]), math.degrees(tho[0])])
        ax[1, k].axhline(90, color="w", lw=0.5)
        ax[1, k].set(xlabel="light phi (deg)", ylabel="light theta (deg; > 90 behind the vane)",
                     title=f"f |wo.n|, viewer at 45 deg: {name}")
    fig.tight_layout()
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print("wrote", out)


if __name__ == "__main__":
    main()
