"""Airy thin-film evaluations per second: appearance-jax vs `tmm` (coh_tmm), same run.

    python benchmarks/thinfilm_vs_tmm.py [--n 100000] [--tmm-n 2000] [--repeats 10]

Workload: a keratin film (eta 1.56, 900 nm) in air, unpolarised reflectance R and
transmittance T at ``--n`` (angle, wavelength) samples (angles uniform in 0-89 deg,
wavelengths uniform in 380-780 nm). Ours: one jitted call on the whole batch
(:func:`appearance_jax.optics.thinfilm.airy`, s and p, amplitudes and powers), float32 and
float64, best of ``--repeats`` after a warm-up (compilation excluded). tmm: ``coh_tmm``
for s and p per sample (it is a scalar function), timed on ``--tmm-n`` samples and
reported per sample. Also a 4-layer stack (``multilayer`` vs ``coh_tmm``). Prints the
ratio ours / tmm; the issue's target is >= 100x on batches of 1e5 samples.

For context (no peer implements these BSDFs: Mitsuba 3 has no thin-film plugin) it also
times the thin-film BSDFs on ``--pairs`` random direction pairs, float32: ``iridescent``
(rgb3 and cie colour modes), ``snake`` (Nyström, 48 nodes) and ``rough_conductor`` (the
same microfacet code with a conductor Fresnel term), in pairs per second.
Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np


def best(fn, repeats):
    fn()
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        ts.append(time.perf_counter() - t0)
    return min(ts)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--tmm-n", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--pairs", type=int, default=1_000_000)
    args = ap.parse_args()

    import tmm

    from appearance_jax.optics import thinfilm as tf

    rng = np.random.default_rng(0)
    th = np.radians(rng.uniform(0.0, 89.0, args.n))
    wl = rng.uniform(380.0, 780.0, args.n)
    stack_n = np.array([1.0, 2.0, 1.3 + 0.2j, 1.7, 0.5 + 3.0j])
    stack_d = np.array([90.0, 245.0, 400.0])

    print(f"batch {args.n} (angle, wavelength) samples; jax {jax.__version__}, backend {jax.default_backend()}")
    rows = []
    for x64 in (False, True):
        jax.config.update("jax_enable_x64", x64)
        dt = np.float64 if x64 else np.float32
        # on the device once: a numpy argument would be copied to a GPU at every call
        c, w = jax.device_put(np.cos(th).astype(dt)), jax.device_put(wl.astype(dt))
        film = jax.jit(lambda c, w: (lambda r: (r.R, r.T))(tf.airy(c, w, 900.0, 1.0, 1.56, 1.0)))
        stack = jax.jit(lambda c, w: (lambda r: (r.R, r.T))(tf.multilayer(c, w, stack_n, stack_d)))
        t_film = best(lambda: film(c, w), args.repeats)
        t_stack = best(lambda: stack(c, w), args.repeats)
        rows.append(("float64" if x64 else "float32", args.n / t_film, args.n / t_stack))
    jax.config.update("jax_enable_x64", False)

    m = min(args.tmm_n, args.n)

    def run_tmm(n_list, d_list):
        t0 = time.perf_counter()
        for i in range(m):
            for pol in "sp":
                tmm.coh_tmm(pol, n_list, d_list, th[i], wl[i])
        return (time.perf_counter() - t0) / m

    t_tmm_film = run_tmm([1.0, 1.56, 1.0], [np.inf, 900.0, np.inf])
    t_tmm_stack = run_tmm(list(stack_n), [np.inf, *stack_d, np.inf])
    tmm_film, tmm_stack = 1.0 / t_tmm_film, 1.0 / t_tmm_stack

    print(f"\n{'implementation':34s} {'film [samples/s]':>18s} {'4-layer [samples/s]':>20s} {'ratio film':>11s} {'ratio 4-layer':>14s}")
    for name, a, b in rows:
        print(f"{'appearance-jax ' + name:34s} {a:18.3e} {b:20.3e} {a / tmm_film:11.0f} {b / tmm_stack:14.0f}")
    print(f"{'tmm coh_tmm (s+p per sample)':34s} {tmm_film:18.3e} {tmm_stack:20.3e} {1:11d} {1:14d}")

    bsdf_throughput(args.pairs, args.repeats)


def bsdf_throughput(n, repeats):
    """Thin-film BSDF evaluations per second (float32), rough_conductor for context."""
    from appearance_jax.bsdf import iridescent, rough_conductor, snake
    from appearance_jax.core.vec import Vec3

    rng = np.random.default_rng(1)

    def hemi():
        v = rng.normal(size=(3, n))
        v /= np.linalg.norm(v, axis=0)
        v[2] = np.abs(v[2])
        return Vec3(*(jax.device_put(c) for c in v.astype(np.float32)))

    wi, wo = hemi(), hemi()
    cases = [
        ("rough_conductor (context)", rough_conductor, rough_conductor.Params(alpha=0.3)),
        ("iridescent rgb3", iridescent, iridescent.Params(alpha=0.3)),
        ("iridescent cie (81 wavelengths)", iridescent, iridescent.Params(alpha=0.3, color="cie")),
        ("snake rgb3 (Nystrom, 48 nodes)", snake, snake.Params()),
    ]
    print(f"\n{n} random direction pairs, float32")
    print(f"{'BSDF eval':34s} {'pairs/s':>12s}")
    for name, mod, p in cases:
        fn = jax.jit(mod.eval.kernel)
        t = best(lambda: fn(p, wi, wo), repeats)
        print(f"{name:34s} {n / t:12.3e}")


if __name__ == "__main__":
    main()
