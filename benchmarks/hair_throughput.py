"""Throughput of chiang_hair eval (near field, h from the shading normal) vs Mitsuba 3's ``hair``.

    python benchmarks/hair_throughput.py [--n 1000000] [--repeats 10] [--devices 2]

Prints evaluations per second for appearance-jax (float32, jit, Vec3-of-arrays) and, in the
same run, for Mitsuba 3 ``llvm_ad_rgb`` (vectorised over all pairs; DRJIT_LIBLLVM_PATH is
pointed at a system libLLVM >= 16 when found), and the ratio ours / Mitsuba. Same
configuration on both sides: eumelanin 1.3, beta_m = beta_n = 0.3, tilt 2 deg, eta 1.55, RGB;
h = sin(gamma_i) derived from wi as Mitsuba does (:func:`chiang.offset_from_normal`); wi on the
front side (z > 0), wo uniform on the sphere. Mitsuba's eval returns S cos(theta_o); we time our
``eval`` (S) -- the extra multiply is negligible. Timings are the best of ``--repeats`` after a
warm-up (compilation excluded). ``--devices N`` shards the batch over N JAX CPU devices, as in
benchmarks/bsdf_throughput.py. Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import numpy as np
from _common import best_time, mitsuba_llvm, sharded_vec3, throughput_args

BETA_M, BETA_N, ALPHA_DEG, EU = 0.3, 0.3, 2.0, 1.3


def random_pairs(n, seed=0):
    rng = np.random.default_rng(seed)
    wi = rng.normal(size=(3, n))
    wi /= np.linalg.norm(wi, axis=0)
    wi[2] = np.abs(wi[2])
    wo = rng.normal(size=(3, n))
    wo /= np.linalg.norm(wo, axis=0)
    return wi.astype(np.float32), wo.astype(np.float32)


def bench_jax(wi_np, wo_np, repeats, n_devices=1):
    import jax

    from appearance_jax.bcsdf import chiang

    wi, wo = sharded_vec3(wi_np, n_devices), sharded_vec3(wo_np, n_devices)
    params = chiang.Params.from_melanin(EU, 0.0, beta_m=BETA_M, beta_n=BETA_N, alpha=np.radians(ALPHA_DEG))
    kernel = chiang.eval.kernel
    f_eval = jax.jit(lambda p, wi, wo: kernel(p, wi, wo, chiang.offset_from_normal(wi)))
    return best_time(lambda: f_eval(params, wi, wo).block_until_ready(), repeats), jax.__version__


def bench_mitsuba(wi_np, wo_np, repeats):
    dr, mi = mitsuba_llvm()
    if dr is None:
        return None, f"{mi}"
    n = wi_np.shape[1]
    bsdf = mi.load_dict({"type": "hair", "eumelanin": EU, "pheomelanin": 0.0, "int_ior": 1.55, "ext_ior": 1.0,
                         "longitudinal_roughness": BETA_M, "azimuthal_roughness": BETA_N, "scale_tilt": ALPHA_DEG})
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    # our frame (x = tangent) -> Mitsuba's hair frame (y = tangent)
    si.wi = mi.Vector3f(wi_np[1], wi_np[0], wi_np[2])
    wo = mi.Vector3f(wo_np[1], wo_np[0], wo_np[2])
    ctx = mi.BSDFContext()

    def run_eval():
        v = bsdf.eval(ctx, si, wo)
        dr.eval(v)
        dr.sync_thread()

    return best_time(run_eval, repeats), f"mitsuba {mi.__version__} llvm_ad_rgb hair"


def main():
    args = throughput_args(__doc__)
    wi, wo = random_pairs(args.n)
    rows = []
    for nd in sorted({1, args.devices}):
        t, jv = bench_jax(wi, wo, args.repeats, nd)
        rows.append((f"appearance-jax chiang_hair, {nd} device(s) (jax {jv})", t))
    tm, mv = bench_mitsuba(wi, wo, args.repeats)
    rows.append((mv, tm))
    print(f"{'implementation':64s} {'eval [M/s]':>11s}")
    for name, t in rows:
        print(f"{name:64s} {'-' if t is None else f'{args.n / t / 1e6:11.2f}':>11s}")
    if tm is not None:
        for name, t in rows[:-1]:
            print(f"ratio ours/mitsuba [{name.split(' (')[0]}]: eval {tm / t:.2f}")


if __name__ == "__main__":
    main()
