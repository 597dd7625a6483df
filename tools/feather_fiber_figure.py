"""Lat-long plots of Padrón's feather fibre BCSDF (Fig. 5.7's four variants): writes docs/img/feather-fiber.png.

phi_i = 0, theta_i = 45 deg, red channel of S cos(theta_o) over (phi_o, theta_o), for a circular cortex, an
elliptical one (e_b = 1.6), a concentric circular medulla of radius 0.6 and the same medulla at
(-0.1, 0.1); sigma_c,a = (0.133, 1.967, 2.1), eta = 1.53, beta_m = 0.13, beta_n = 0.12 [T:1069].

    python3 tools/feather_fiber_figure.py [--n-h 512] [--out docs/img/feather-fiber.png]
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

from appearance_jax.bcsdf import feather_fiber as ff  # noqa: E402
from appearance_jax.core.frame import fiber_direction  # noqa: E402
from appearance_jax.core.vec import Vec3  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
VARIANTS = {
    "circular cortex": dict(),
    "elliptical cortex, e = 1.6": dict(eccentricity=1.6),
    "concentric medulla r = 0.6": dict(medulla=True),
    "medulla at (-0.1, 0.1)": dict(medulla=True, medulla_y=-0.1, medulla_z=0.1),
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n-h", type=int, default=512, help="offsets per direction (the medulla lobes are a Monte Carlo estimate)")
    ap.add_argument("--out", default=str(ROOT / "docs" / "img" / "feather-fiber.png"))
    args = ap.parse_args()
    th = np.linspace(-math.pi / 2, math.pi / 2, 47)[1:-1]
    ph = np.linspace(-math.pi, math.pi, 91)[:-1]
    T, P = np.meshgrid(th, ph, indexing="ij")
    wi = fiber_direction(math.pi / 4, 0.0)
    wo = fiber_direction(jnp.asarray(T.ravel()), jnp.asarray(P.ravel()))
    fig, axes = plt.subplots(1, 4, figsize=(14, 3.4), sharey=True)
    for ax, (name, kw) in zip(axes, VARIANTS.items()):
        p = ff.Params(n_h=args.n_h, **kw)
        # chunks of equal size (one compiled program) keep the traced rays' memory bounded
        chunk = 450
        S = np.concatenate([np.asarray(ff.eval(p, wi, Vec3(*(c[i:i + chunk] for c in wo)))[0])
                            for i in range(0, T.size, chunk)])
        img = (S[:, 0] * np.cos(T.ravel())).reshape(T.shape)
        im = ax.imshow(img, extent=(-180, 180, -90, 90), origin="lower", aspect="auto", cmap="magma",
                       vmax=np.percentile(img, 99.7))
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("phi_o [deg]")
        fig.colorbar(im, ax=ax, shrink=0.8)
        print(f"{name}: albedo (red) = {np.sum(img * np.cos(T) * (th[1] - th[0]) * (ph[1] - ph[0])):.4f}")
    axes[0].set_ylabel("theta_o [deg]")
    fig.suptitle("feather_fiber, red channel of S cos(theta_o); theta_i = 45 deg, phi_i = 0 (Padrón Fig. 5.7 setting)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(args.out, dpi=90)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
