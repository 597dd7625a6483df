"""Figures of docs/rainbow.md: the wave-optics drop trace against Lorenz–Mie, and bow colours.

    python3 tools/rainbow_figures.py [--out docs/img] [--wavelengths 33]

1. ``rainbow-vs-mie.png``: a 0.4 mm water drop at 650 nm (Sadeghi 2011 Fig. 3.12): the
   trace without interference (incoherent, "dispersion only"), with interference
   (coherent), with Sadeghi's diffraction blur, and Lorenz–Mie (phase/mie.py), log scale;
   plus the same for 0.1 mm (linear scale, 136–146°) where the supernumeraries are wide.
2. ``rainbow-colours.png``: the bow under D65 for drops of 1 mm (Beard–Chuang, top of the
   bow), 0.4 mm, 0.1 mm and 10 µm (fog bow), as colour strips over the scattering angle
   (each normalised to its own maximum, sRGB encoded).

Takes a few minutes on 2 cores (one trace per wavelength and drop).
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

from appearance_jax.core import spectral  # noqa: E402
from appearance_jax.flatland import rainbow  # noqa: E402
from appearance_jax.phase import mie  # noqa: E402


def mie_curve(radius_mm, theta, wl=650.0, n=1.331):
    p = mie.Params(radius_um=radius_mm * 1e3, wavelength_nm=wl, n_particle=n)
    S1, S2 = mie.amplitudes(p, np.cos(theta))
    x = 2 * np.pi * radius_mm * 1e6 / wl
    # unpolarised incident light: the mean of the two polarisations
    return 0.5 * (np.abs(np.asarray(S1)[:, 0]) ** 2 + np.abs(np.asarray(S2)[:, 0]) ** 2) / (np.pi * x * x)


def figure_vs_mie(out: Path):
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2), constrained_layout=True)
    for ax, a, lo, hi, log in ((axes[0], 0.4, 120.0, 150.0, True), (axes[1], 0.1, 134.0, 146.0, False)):
        theta = np.radians(np.arange(lo - 3.0, hi + 3.0, 0.005))
        deg = np.degrees(theta)
        kw = dict(wavelengths_nm=[650.0], theta=theta)
        inc = rainbow.drop_phase_function(a, mode="incoherent", blur_diffraction=False, **kw)
        coh = rainbow.drop_phase_function(a, blur_diffraction=False, **kw)
        blr = rainbow.drop_phase_function(a, **kw)
        ref = mie_curve(a, theta)
        sel = (deg >= lo) & (deg <= hi)
        for t, label, color, lw in ((inc, "dispersion only (incoherent trace)", "tab:purple", 0.8),
                                    (coh, "+ interference (coherent trace)", "tab:blue", 0.6),
                                    (blr, "+ diffraction blur (Table 3.3)", "tab:green", 1.6)):
            ax.plot(deg[sel], rainbow.intensity(t)[0][sel], color=color, lw=lw, label=label)
        ax.plot(deg[sel], ref[sel], color="tab:red", lw=0.8, label="Lorenz–Mie")
        if log:
            ax.set_yscale("log")
            ax.set_ylim(1.5e-4, 1.0)
        else:
            ax.set_ylim(0.0, 0.3)
        ax.set_xlim(lo, hi)
        ax.set_xlabel("scattering angle θ (deg)")
        ax.set_ylabel("(1/πa²) dσ/dΩ, unpolarised (1/sr)")
        ax.set_title(f"water drop a = {a} mm, λ = 650 nm, n = 1.331 (p = 0, 2, 3)")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper left", fontsize=8)
    fig.savefig(out / "rainbow-vs-mie.png", dpi=110)
    plt.close(fig)


def figure_colours(out: Path, n_wl: int):
    wl = np.linspace(380.0, 700.0, n_wl)
    theta = np.radians(np.arange(118.0, 146.0, 0.02))
    deg = np.degrees(theta)
    drops = ((1.0, "top", "a = 1 mm (Beard–Chuang, top of the bow)"), (0.4, "top", "a = 0.4 mm"),
             (0.1, "top", "a = 0.1 mm"), (0.01, "top", "a = 10 µm (fog bow)"))
    fig, axes = plt.subplots(len(drops), 1, figsize=(10, 1.1 * len(drops) + 0.8), constrained_layout=True)
    for ax, (a, view, label) in zip(axes, drops):
        t = rainbow.drop_phase_function(a, wavelengths_nm=wl, theta=theta, view=view)
        rgb = np.clip(rainbow.to_srgb(t), 0.0, None)
        sel = (deg > 122.0) & (deg < 145.0)
        rgb = rgb / np.percentile(rgb[sel].max(axis=1), 99.5)
        img = np.asarray(spectral.linear_to_srgb(np.clip(rgb, 0.0, 1.0)))
        ax.imshow(img[None, :, :].repeat(12, axis=0), extent=(deg[0], deg[-1], 0, 1), aspect="auto")
        ax.set_yticks([])
        ax.set_ylabel(label, rotation=0, ha="right", va="center", fontsize=9)
        ax.set_xlim(122.0, 145.0)
    axes[-1].set_xlabel("scattering angle θ (deg): secondary bow ~127–130°, Alexander's band, primary ~138–142°")
    fig.suptitle(f"Rainbow colours under D65 ({n_wl} wavelengths, 380–700 nm; each strip normalised)")
    fig.savefig(out / "rainbow-colours.png", dpi=110)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "docs" / "img"))
    ap.add_argument("--wavelengths", type=int, default=33)
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    figure_vs_mie(out)
    figure_colours(out, args.wavelengths)


if __name__ == "__main__":
    main()
