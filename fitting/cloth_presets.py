"""Recipe: in-plane BRDF slices of every cloth preset (Sadeghi 2011, Table 5.2 / E.1), in the
thesis' measurement geometry (Figs. 5.10-5.16: light and camera in one plane, incidence 0, 30
and 60 deg, signed outgoing angle), along both thread directions.

For each preset one PNG with two panels: the plane through family 1's direction u (x, "along
the flat threads" for the measured fabrics) and through family 2's (y). The curves are the
BRDF f = R / (N.w_i) of :func:`appearance_jax.bsdf.cloth.eval` (luminance-free: mean of R, G,
B), in 1/sr on a log axis, against the signed outgoing angle theta_o in degrees: the light is
at -theta_i in the plane, the camera at theta_o, so theta_o = theta_i is the mirror direction
and a flat tangent section at offset alpha peaks near theta_o = theta_i - 2 alpha (the spec's
"2 alpha - theta_in" with the opposite sign convention; the orange lines mark theta_i).

    python3 fitting/cloth_presets.py --out out/cloth_presets [--samples 64] [--presets silk_shot,velvet]
"""

from __future__ import annotations

import argparse
import os

import numpy as np

INCIDENCE_DEG = (0.0, 30.0, 60.0)


def slices(params, plane_deg: float, theta_o_deg: np.ndarray, incidence=INCIDENCE_DEG):
    """BRDF (len(incidence), n, bands) in the plane at azimuth ``plane_deg``; theta_o signed:
    w_o = (sin theta_o cos p, sin theta_o sin p, cos theta_o), w_i at -theta_i in the same plane."""
    import jax.numpy as jnp

    from appearance_jax.bsdf import cloth
    from appearance_jax.core.vec import Vec3

    p = np.deg2rad(plane_deg)
    ti = np.deg2rad(np.asarray(incidence))[:, None] * np.ones_like(theta_o_deg)[None, :]
    to = np.deg2rad(theta_o_deg)[None, :] * np.ones((len(incidence), 1))
    wi = Vec3(*(jnp.asarray(c) for c in (-np.sin(ti) * np.cos(p), -np.sin(ti) * np.sin(p), np.cos(ti))))
    wo = Vec3(*(jnp.asarray(c) for c in (np.sin(to) * np.cos(p), np.sin(to) * np.sin(p), np.cos(to))))
    return np.asarray(cloth.eval(params, wi, wo))


def plot_preset(name, params, out: str, n: int = 141) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    theta_o = np.linspace(-85.0, 85.0, n)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    angles = np.asarray(params.family_angle) + float(params.rotation)
    for ax, fam in zip(axes, (0, 1)):
        f = slices(params, float(angles[fam]), theta_o)
        for k, ti in enumerate(INCIDENCE_DEG):
            ax.semilogy(theta_o, np.maximum(f[k].mean(axis=-1), 1e-5), label=f"θ_i = {ti:g}°")
            ax.axvline(ti, color="orange", lw=0.6, ls=":")
        ax.set_xlabel("signed outgoing angle θ_o (deg); mirror at θ_o = θ_i")
        ax.set_title(f"{name}: plane of thread family {fam + 1}")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("BRDF f, mean of RGB (1/sr)")
    axes[0].legend()
    fig.tight_layout()
    path = os.path.join(out, f"{name}.png")
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def main(argv=None):
    from appearance_jax.bsdf import cloth

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/cloth_presets")
    ap.add_argument("--samples", type=int, default=64, help="T, tangent samples per curve")
    ap.add_argument("--presets", default=",".join(cloth.PRESETS), help="comma-separated preset names")
    ap.add_argument("--points", type=int, default=141, help="outgoing angles per slice")
    a = ap.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    paths = []
    for name in a.presets.split(","):
        p = cloth.PRESETS[name].replace(n_samples=a.samples)
        paths.append(plot_preset(name, p, a.out, a.points))
        print(paths[-1])
    return paths


if __name__ == "__main__":
    main()
