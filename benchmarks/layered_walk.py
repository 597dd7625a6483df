"""Monte Carlo throughput of the position-free layered random walk (appearance_jax.layered.random_walk.walk).

What is measured: the cosmetics BSDF (:mod:`appearance_jax.bsdf.cosmetics`, the four Table A.1
presets, azimuth "averaged") evaluated on the in-plane table of the fitting recipe
(theta_i 0..70 step 10 x signed theta_o -80..80 step 10 = 136 direction pairs) with
``--samples`` paths per pair, at ``max_bounces`` in ``--bounces``:

- primal: steps/s = pairs x paths x max_bounces / time (every path runs every step of the
  fixed-length ``lax.scan``: the alive mask, no Russian roulette), and (pairs x paths)/s;
- forward-mode derivative: ``jax.jacfwd`` of the (136, 3) estimate with respect to the 12 free
  parameters of the fit (c_d, albedo_d RGB, albedo_p RGB, w_g, g1, g2, alpha, theta): what one
  Levenberg-Marquardt Jacobian costs; reported as time, ratio to the primal, and "tangent
  steps"/s = steps x 12 / time;
- truncation: the in-plane signal still in the stack at 64 and 128 steps relative to 512
  (same key; jax's partitionable threefry splits are prefix-stable, so the paths agree step by
  step and the difference is exactly the light the shorter walk drops);
- a baseline: there is no peer program with a position-free walker to compare against (the
  thesis used Mitsuba 0.6 / PBRT plugins that cannot run here), so a straightforward numpy
  implementation of the same algorithm (truncated-exponential collide-or-cross, next-event
  estimation towards the viewer, HG inversion, fixed length, vectorised over paths, float64)
  for a single-layer HG medium (c_d = 1, Lambda_d = 0.95, g = 0.5, t = 16, black base) is run
  against the library's walk on the same medium, same pairs, same path and step counts; the
  estimates are checked to agree within their Monte Carlo errors.

Compilation is excluded (a warm-up call; its time is printed). Timings are the best of
``--repeats``. Nothing is asserted.

    python3 benchmarks/layered_walk.py [--samples 128] [--bounces 64,128,512] [--x64] [--repeats 3]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

PRESETS = ("dewy1", "dewy2", "matte1", "matte2")
FREE = ("c_d", "albedo_d", "albedo_p", "w_g", "g1", "g2", "alpha", "theta")


def grid():
    ti, to = (a.ravel() for a in np.meshgrid(np.arange(0, 71, 10), np.arange(-80, 81, 10), indexing="ij"))
    return np.deg2rad(ti.astype(float)), np.deg2rad(to.astype(float))


def timed(fn, *args, repeats=3):
    import jax

    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t0
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - t0)
    return out, best, first


# ---------------------------------------------------------------------------- numpy baseline


def _basis(d):
    """Duff et al. 2017 orthonormal basis around unit vectors d (..., 3)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    s = np.where(z >= 0, 1.0, -1.0)
    a = -1.0 / (s + z)
    b = x * y * a
    t1 = np.stack([1.0 + s * x * x * a, s * b, -s * x], -1)
    t2 = np.stack([b, s + y * y * a, -y], -1)
    return t1, t2


def _hg(g, c):
    return (1 - g * g) / (4 * np.pi * (1 + g * g + 2 * g * np.clip(c, -1, 1)) ** 1.5)


def _hg_sample_cos(g, xi):
    # inversion of the HG CDF for mu = d . wo (forward scattering at mu = 1 for g > 0)
    s = (1 - g * g) / (1 - g + 2 * g * xi)
    return np.clip((1 + g * g - s * s) / (2 * g), -1.0, 1.0)


def numpy_walk(wi, wo, *, n_samples, max_bounces, thickness, albedo, g, seed=0):
    """f [1/sr] (P, B) and its standard error of a single index-matched HG slab over a black base."""
    rng = np.random.default_rng(seed)
    P = wi.shape[0]
    albedo = np.asarray(albedo, np.float64)
    d = np.broadcast_to(-wi[:, None, :], (P, n_samples, 3)).copy()
    wo_b = np.broadcast_to(wo[:, None, :], (P, n_samples, 3))
    mu_o = wo[:, 2][:, None]
    depth = np.zeros((P, n_samples))
    beta = np.ones((P, n_samples, albedo.size))
    acc = np.zeros_like(beta)
    for _ in range(max_bounces):
        u = rng.random((4, P, n_samples))
        dz = d[..., 2]
        down = dz < 0
        s_max = np.maximum(np.where(down, thickness - depth, depth) / np.maximum(np.abs(dz), 1e-12), 0.0)
        p_c = -np.expm1(-s_max)
        collide = u[0] < p_c
        s = -np.log1p(-u[1] * np.where(p_c > 0, p_c, 1.0))
        depth_c = np.clip(depth - s * dz, 0.0, thickness)
        # next-event estimate towards the viewer (sigma_t = 1, index-matched: no interface factors)
        c = np.sum(-d * wo_b, -1)
        nee = beta * (albedo * (_hg(g, c) * np.exp(-depth_c / mu_o))[..., None])
        acc += np.where(collide[..., None], nee, 0.0)
        # scatter about d (HG inversion); leaving the slab (top: escape, bottom: black) ends the path
        mu = _hg_sample_cos(g, u[2])
        sin_t = np.sqrt(np.maximum(1 - mu * mu, 0.0))
        phi = 2 * np.pi * u[3]
        t1, t2 = _basis(d)
        new = t1 * (sin_t * np.cos(phi))[..., None] + t2 * (sin_t * np.sin(phi))[..., None] + d * mu[..., None]
        d = np.where(collide[..., None], new, d)
        depth = np.where(collide, depth_c, depth)
        beta = np.where(collide[..., None], beta * albedo, 0.0)
    x = acc / mu_o[..., None]
    return x.mean(1), x.std(1, ddof=1) / math.sqrt(n_samples)


# ---------------------------------------------------------------------------- main


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--samples", type=int, default=128)
    ap.add_argument("--bounces", default="64,128,512")
    ap.add_argument("--grad-bounces", default="64,128,512", help="bounce counts of the jacfwd timing ('' skips)")
    ap.add_argument("--presets", default=",".join(PRESETS))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--x64", action="store_true")
    ap.add_argument("--no-numpy", action="store_true")
    args = ap.parse_args(argv)

    import jax

    if args.x64:
        jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    from appearance_jax.bsdf import cosmetics
    from appearance_jax.fit.tables.table import Table

    ti, to = grid()
    table = Table.in_plane(ti, to, np.zeros((ti.size, 3)))
    wi, wo = table.directions()
    pairs, n = ti.size, args.samples
    bounces = [int(b) for b in args.bounces.split(",") if b]
    grad_bounces = [int(b) for b in args.grad_bounces.split(",") if b]
    dt = jnp.dtype(jnp.result_type(float)).name
    key = jax.random.key(0)
    print(f"layered random walk: {pairs} in-plane direction pairs x {n} paths, {dt}, jax {jax.__version__}, "
          f"{jax.devices()[0].platform} ({len(jax.devices())} device)")

    def params_of(base, x):
        kw, i = {}, 0
        for name in FREE:
            if name in ("albedo_d", "albedo_p"):
                kw[name] = x[i:i + 3]
                i += 3
            else:
                kw[name] = x[i]
                i += 1
        return base.replace(**kw)

    def x_of(p):
        return jnp.concatenate([jnp.atleast_1d(jnp.asarray(getattr(p, k), jnp.result_type(float))) for k in FREE])

    rows, lost = [], {}
    for nb in bounces:
        prim = jax.jit(lambda x, base: cosmetics.eval.kernel(params_of(base, x), wi, wo, key=key)[0])
        jac = jax.jit(jax.jacfwd(lambda x, base: cosmetics.eval.kernel(params_of(base, x), wi, wo, key=key)[0]))
        for name in args.presets.split(","):
            base = cosmetics.PRESETS[name].replace(n_samples=n, max_bounces=nb, azimuth="averaged")
            x = x_of(base)
            f, t, first = timed(prim, x, base, repeats=args.repeats)
            row = dict(preset=name, bounces=nb, t=t, compile=first - t, steps=pairs * n * nb / t,
                       paths=pairs * n / t, f=np.asarray(f, np.float64))
            if nb in grad_bounces:
                J, tj, firstj = timed(jac, x, base, repeats=max(1, args.repeats - 1))
                row.update(tj=tj, compile_j=firstj - tj, finite_j=bool(np.all(np.isfinite(np.asarray(J)))))
            rows.append(row)
            print(f"  {name:<7} {nb:>4} steps: primal {t * 1e3:8.1f} ms  {row['steps'] / 1e6:7.2f} M steps/s  "
                  f"{row['paths'] / 1e3:8.1f} k paths/s  (compile {row['compile']:.1f} s)"
                  + (f" | jacfwd(12) {tj:6.2f} s = {tj / t:5.1f}x primal, {pairs * n * nb * 12 / tj / 1e6:6.2f} "
                     f"M tangent-steps/s (compile {row['compile_j']:.1f} s){'' if row['finite_j'] else ' NON-FINITE'}"
                     if "tj" in row else ""), flush=True)

    by = {(r["preset"], r["bounces"]): r["f"] for r in rows}
    if 512 in bounces:
        print("\nlight still in the stack (lost to truncation), relative to 512 steps, in-plane sum (same key):")
        for name in args.presets.split(","):
            ref = by[(name, 512)].sum()
            parts = [f"{nb}: {1 - by[(name, nb)].sum() / ref:.3%}" for nb in bounces if nb < 512]
            lost[name] = parts
            print(f"  {name:<7} " + "  ".join(parts))

    print("\n| preset | steps | primal [ms] | M steps/s | k paths/s | jacfwd(12) [s] | jacfwd / primal |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['preset']} | {r['bounces']} | {r['t'] * 1e3:.0f} | {r['steps'] / 1e6:.2f} | {r['paths'] / 1e3:.1f} | "
              + (f"{r['tj']:.2f} | {r['tj'] / r['t']:.1f} |" if "tj" in r else "- | - |"))

    if not args.no_numpy:
        nb = 128
        medium = dict(c_d=1.0, albedo_d=0.95, w_g=0.5, g1=0.5, g2=0.5, thickness=16.0, base_reflectance=0.0)
        p = cosmetics.Params(**medium, n_samples=n, max_bounces=nb)
        fj_fn = jax.jit(lambda p: cosmetics.eval.kernel(p, wi, wo, key=key))
        (fj, sej), tjx, _ = timed(fj_fn, p, repeats=args.repeats)
        wi_np = np.stack([np.asarray(a, np.float64) for a in (wi.x, wi.y, wi.z)], -1)
        wo_np = np.stack([np.asarray(a, np.float64) for a in (wo.x, wo.y, wo.z)], -1)
        best = math.inf
        for r in range(max(1, args.repeats - 1)):
            t0 = time.perf_counter()
            fn, sen = numpy_walk(wi_np, wo_np, n_samples=n, max_bounces=nb, thickness=16.0, albedo=[0.95] * 3,
                                 g=0.5, seed=r)
            best = min(best, time.perf_counter() - t0)
        fj, sej = np.asarray(fj, np.float64), np.asarray(sej, np.float64)
        zs = (fj - fn) / np.sqrt(sej ** 2 + sen ** 2 + 1e-30)
        print(f"\nbaseline: single-layer HG medium (c_d = 1, Lambda = 0.95, g = 0.5, t = 16, black base), "
              f"{pairs} pairs x {n} paths x {nb} steps")
        print(f"  appearance_jax walk ({dt}): {tjx * 1e3:8.1f} ms  {pairs * n * nb / tjx / 1e6:7.2f} M steps/s")
        print(f"  numpy walk (float64)      : {best * 1e3:8.1f} ms  {pairs * n * nb / best / 1e6:7.2f} M steps/s")
        print(f"  ratio (numpy time / jax time): {best / tjx:.2f}x")
        print(f"  estimates: in-plane mean f jax {fj.mean():.5f} vs numpy {fn.mean():.5f}; per-cell z-scores: "
              f"rms {np.sqrt(np.mean(zs ** 2)):.2f}, max |z| {np.max(np.abs(zs)):.2f}; median rel. stderr "
              f"jax {np.median(sej / fj):.2%} vs numpy {np.median(sen / fn):.2%}")


if __name__ == "__main__":
    main()
