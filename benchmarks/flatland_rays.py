"""Rays per second of the flatland (2.5D) tracer on this CPU.

What is measured (compilation excluded: a warm-up call, whose time is printed; best of
``--repeats``; nothing asserted):

- ``smooth split``: a smooth circular fiber (eta 1.55, RGB absorption) traced in split mode
  with ``--events`` events per ray: every ray carries all its lobes (R, TT, TRT, ...), the
  deterministic mode used by :func:`flatland.smooth_lobes`;
- ``rough histogram``: :func:`flatland.trace_fiber` on a rough (GGX 0.15, tilt 2 deg)
  absorbing fiber, ``--events`` events, tallied into a 90 x 180 x 4-lobe histogram in chunks
  of 2^15 rays (what a BCSDF reference costs per ray, tallies included);
- ``rough ellipse + medulla``: the same with an e = 0.8 cortex and an off-centre diffuse
  medulla (two shapes per event);
- ``camera NEE``: :func:`flatland.nee_bcsdf` for one (omega_i, omega_o) pair;
- a baseline for the smooth split mode: the same algorithm in vectorised numpy (float64,
  circle, closed-form chords), checked to give the same lobe weights.

Throughput = rays x events / time is also printed as events/s (every ray runs every event
of the fixed-length scan: alive masks, no early exit).

    python3 benchmarks/flatland_rays.py [--rays 262144] [--events 8] [--repeats 3] [--x64]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np


def timed(fn, repeats):
    import jax

    t0 = time.perf_counter()
    out = jax.block_until_ready(fn())
    first = time.perf_counter() - t0
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn())
        best = min(best, time.perf_counter() - t0)
    return out, best, first


def numpy_smooth_circle(h, theta_i, eta, sigma, events):
    """Split-mode tracer for a smooth unit circle at incidence (theta_i, phi_i = 0), numpy."""
    st, ct = np.sin(theta_i), np.cos(theta_i)
    # 3D propagation d = -omega_i = (-st, -ct, 0) in the fiber frame (x = axis)
    dx = -st
    n2 = ct                       # |d_yz|
    eta_p = math.sqrt(eta * eta - st * st) / ct   # Bravais index for the 2D refraction
    out = np.zeros((events, h.size, sigma.size))
    # entry at offset h on the unit circle, 2D angle of incidence gamma_i
    gi = np.arcsin(h)
    cos_i3 = ct * np.cos(gi)      # 3D cosine
    sin_t3 = np.sqrt(1 - cos_i3 ** 2) / eta
    cos_t3 = np.sqrt(1 - sin_t3 ** 2)

    def fres(ci, et):
        s2 = (1 - ci * ci) / (et * et)
        ok = s2 < 1
        cti = np.sqrt(np.maximum(1 - s2, 0))
        rs = (ci - et * cti) / (ci + et * cti)
        rp = (et * ci - cti) / (et * ci + cti)
        return np.where(ok, 0.5 * (rs * rs + rp * rp), 1.0)

    F = fres(cos_i3, eta)
    gt = np.arcsin(h / eta_p)
    cos_theta_t = math.sqrt(1 - (st / eta) ** 2)
    chord3 = 2 * np.cos(gt) / cos_theta_t
    w = np.ones((h.size, sigma.size))
    out[0] = (w * F[:, None])
    w = w * (1 - F)[:, None]
    # inside: every chord has the same internal cosine (circle), Fresnel from inside
    F_in = fres(cos_t3, 1.0 / eta)
    T = np.exp(-sigma[None, :] * chord3[:, None])
    for k in range(1, events):
        w = w * T
        out[k] = w * (1 - F_in)[:, None]
        w = w * F_in[:, None]
    del dx, n2
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rays", type=int, default=2 ** 18)
    ap.add_argument("--events", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--x64", action="store_true")
    a = ap.parse_args()
    import jax
    import jax.numpy as jnp

    if a.x64:
        jax.config.update("jax_enable_x64", True)
    from appearance_jax import flatland as fl
    from appearance_jax.core.frame import fiber_direction

    print(f"jax {jax.__version__}, devices {jax.devices()}, dtype {jnp.result_type(float)}, "
          f"rays {a.rays}, events {a.events}")
    key = jax.random.PRNGKey(0)
    sigma = jnp.array([0.2, 0.5, 1.0])
    wi = fiber_direction(0.3, 0.0)
    h = (jnp.arange(a.rays) + 0.5) / a.rays * 2 - 1   # midpoints (h = +-1 is a tangent ray)
    rows = []

    smooth = fl.fiber(1.55, sigma)
    rec, t, first = timed(lambda: fl.trace(smooth, wi, h, key, max_events=a.events).weight, a.repeats)
    rows.append(("smooth split (circle)", t, first))

    hn = np.asarray(h, float)
    t0 = time.perf_counter()
    for _ in range(a.repeats):
        ref = numpy_smooth_circle(hn, 0.3, 1.55, np.asarray(sigma, float), a.events)
    t_np = (time.perf_counter() - t0) / a.repeats
    err = float(np.max(np.abs(np.asarray(rec) - ref)))
    rows.append(("  numpy baseline (same algorithm)", t_np, 0.0))

    rough = fl.fiber(1.55, sigma, roughness=0.15, tilt=np.radians(2.0))
    _, t, first = timed(lambda: fl.trace_fiber(rough, wi, key, a.rays, max_events=a.events, chunk=2 ** 15).power,
                        a.repeats)
    rows.append(("rough histogram (circle)", t, first))

    med = fl.fiber(1.55, sigma, roughness=0.15, tilt=np.radians(2.0), eccentricity=0.8,
                   medulla=(0.1, -0.1, 0.4, 0.5))
    _, t, first = timed(lambda: fl.trace_fiber(med, wi, key, a.rays, max_events=a.events, chunk=2 ** 15).power,
                        a.repeats)
    rows.append(("rough histogram (ellipse + medulla)", t, first))

    wo = fiber_direction(-0.35, 2.2)
    _, t, first = timed(lambda: fl.nee_bcsdf(rough, wi, wo, key, a.rays, max_events=a.events, chunk=2 ** 15)[0],
                        a.repeats)
    rows.append(("camera NEE (one direction pair)", t, first))

    print(f"{'configuration':40s} {'time [s]':>9s} {'M rays/s':>9s} {'M events/s':>11s} {'compile [s]':>11s}")
    for name, t, first in rows:
        print(f"{name:40s} {t:9.3f} {a.rays / t / 1e6:9.2f} {a.rays * a.events / t / 1e6:11.2f} {first - t:11.1f}")
    print(f"smooth split: jax / numpy speed ratio {t_np / rows[0][1]:.2f}; max |weight difference| {err:.2e}")


if __name__ == "__main__":
    main()
