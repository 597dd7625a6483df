"""The deterministic cosmetic solver (cosmetics_ordinates) against the random walk (cosmetics)
at equal error, and against the HG adding-doubling on an HG-only medium (issue 25).

Prints, for an in-plane table of 136 cells (Padrón Fig. 4.4: theta_i 0..70 step 10, theta_o
-80..80 step 10), in one run:
- the solver: compile time, eval time, forward-mode Jacobian over the 12 medium values (float32,
  the fitting precision), with and without the tilt correction;
- its error: the median and max |f_solver / f_walk - 1| against a long walk, and the walk's
  cost to reach the same median standard error (timed at n paths, scaled by se ~ 1/sqrt(n));
- HG-only medium (c_d = 1) in float64: the solver vs layered.adding_doubling.brdf (zero-weight
  query nodes) on the same table.

    python3 benchmarks/cosmetics_ordinates.py [--preset matte1] [--walk-paths 4096]
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np


def table():
    from appearance_jax.core.frame import in_plane_directions
    ti = np.repeat(np.arange(0.0, 71.0, 10.0), 17)
    to = np.tile(np.arange(-80.0, 81.0, 10.0), 8)
    return in_plane_directions(jnp.deg2rad(jnp.asarray(ti)), jnp.deg2rad(jnp.asarray(to)))


def best(fn, repeats=5):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t)
    return min(times)


def solver_block(p, wi, wo, tilt):
    from appearance_jax.bsdf import cosmetics_ordinates as co
    p = p.replace(tilt_correction=tilt)
    k = jax.jit(co.MODEL.eval.kernel)
    t = time.perf_counter()
    f = jax.block_until_ready(k(p, wi, wo))
    compile_s = time.perf_counter() - t
    eval_s = best(lambda: k(p, wi, wo))
    names = ("c_d", "albedo_d", "albedo_p", "w_g", "g1", "g2", "alpha", "theta")
    J = jax.jit(jax.jacfwd(lambda v: co.MODEL.eval.kernel(p.replace(**dict(zip(names, v))), wi, wo)))
    vals = [getattr(p, n) for n in names]
    t = time.perf_counter()
    jax.block_until_ready(J(vals))
    jcompile_s = time.perf_counter() - t
    jac_s = best(lambda: J(vals), 3)
    return np.asarray(f), compile_s, eval_s, jcompile_s, jac_s


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--preset", default="matte1")
    ap.add_argument("--walk-paths", type=int, default=1024, help="paths per cell of the timed walk")
    ap.add_argument("--reference-paths", type=int, default=16384, help="paths per cell of the reference walk")
    ap.add_argument("--max-bounces", type=int, default=128, help="steps of the walks (Matte 1 loses < 0.05 %% at 64)")
    args = ap.parse_args()

    from appearance_jax.bsdf import cosmetics
    from appearance_jax.bsdf import cosmetics_ordinates as co
    wi, wo = table()
    p = co.PRESETS[args.preset]
    print(f"# {args.preset}, 136-cell in-plane table, azimuth averaged, float32; jax {jax.__version__}, "
          f"{jax.devices()[0].device_kind}")
    rows = {}
    for tilt in (False, True):
        f, c, e, jc, js = solver_block(p, wi, wo, tilt)
        rows[tilt] = f
        print(f"solver (tilt correction {'on ' if tilt else 'off'}): compile {c:.2f} s, eval {1e3 * e:.1f} ms, "
              f"Jacobian (12 values) compile {jc:.1f} s, run {js:.3f} s")

    # the walk: a long reference, and the cost of a given standard error
    pw = cosmetics.PRESETS[args.preset].replace(azimuth="averaged", max_bounces=args.max_bounces)
    ref = pw.replace(n_samples=args.reference_paths)
    fr, ser = (np.asarray(v) for v in cosmetics.eval(ref, wi, wo, key=jax.random.key(1)))
    ok = fr > 0
    for tilt in (False, True):
        rel = np.abs(rows[tilt][ok] / fr[ok] - 1.0)
        z = np.abs(rows[tilt][ok] - fr[ok]) / ser[ok]
        print(f"solver vs walk ({args.reference_paths} paths, median se {np.median(ser[ok] / fr[ok]):.2%}), tilt "
              f"{'on ' if tilt else 'off'}: median |rel| {np.median(rel):.2%}, max {np.max(rel):.2%}, max |z| "
              f"{np.max(z):.1f}")
    pt = pw.replace(n_samples=args.walk_paths)
    k = jax.jit(cosmetics.MODEL.eval.kernel)
    jax.block_until_ready(k(pt, wi, wo, jax.random.key(2)))
    walk_s = best(lambda: k(pt, wi, wo, jax.random.key(2)), 2)
    fw, sew = (np.asarray(v) for v in k(pt, wi, wo, jax.random.key(3)))
    se_rel = np.median(sew[ok] / np.maximum(fw[ok], 1e-12))
    target = max(np.median(np.abs(rows[True][ok] / fr[ok] - 1.0)), 1e-4)
    n_equal = args.walk_paths * (se_rel / target) ** 2
    t_equal = walk_s * n_equal / args.walk_paths
    solver_s = best(lambda: jax.jit(co.MODEL.eval.kernel)(p, wi, wo), 3)
    print(f"walk: {args.walk_paths} paths/cell {walk_s:.2f} s (median se {se_rel:.2%}); equal error "
          f"({target:.2%}) needs ~{n_equal:.0f} paths/cell ~ {t_equal:.1f} s: solver {t_equal / solver_s:.0f}x faster")

    # HG only: the solver vs the HG adding-doubling, float64
    jax.config.update("jax_enable_x64", True)
    from appearance_jax.layered import adding_doubling as ad
    wi64, wo64 = table()
    hg = co.Params(c_d=1.0, albedo_d=(0.95, 0.9, 0.8), g1=0.6, g2=-0.3, w_g=0.7, thickness=4.0,
                   base_reflectance=0.3)
    layer = ad.HGLayer(albedo=jnp.array([0.95, 0.9, 0.8]), thickness=4.0, g1=0.6, g2=-0.3, w_g=0.7)
    kd = jax.jit(co.MODEL.eval.kernel)
    t = time.perf_counter()
    fd = np.asarray(kd(hg, wi64, wo64))
    cd = time.perf_counter() - t
    td = best(lambda: kd(hg, wi64, wo64), 3)
    t = time.perf_counter()
    fa = np.asarray(ad.brdf(layer, 0.3, wi64, wo64))
    ca = time.perf_counter() - t
    ta = best(lambda: ad.brdf(layer, 0.3, wi64, wo64), 2)
    diff = np.max(np.abs(fd / fa - 1))
    print(f"HG only, float64: solver compile {cd:.2f} s, eval {1e3 * td:.1f} ms; adding_doubling compile {ca:.2f} s, "
          f"eval {1e3 * ta:.1f} ms: solver {ta / td:.1f}x faster; max |rel| difference {diff:.1e}")


if __name__ == "__main__":
    main()
