"""Throughput of chiang_hair eval (near field, h from the shading normal) vs Mitsuba 3's ``hair``.

    python benchmarks/hair_throughput.py [--n 1000000] [--repeats 10] [--devices 2] [--grad]

Prints evaluations per second for appearance-jax (float32, jit, Vec3-of-arrays) and, in the
same run, for Mitsuba 3 ``llvm_ad_rgb`` (vectorised over all pairs; DRJIT_LIBLLVM_PATH is
pointed at a system libLLVM >= 16 when found), and the ratio ours / Mitsuba. Same
configuration on both sides: eumelanin 1.3, beta_m = beta_n = 0.3, tilt 2 deg, eta 1.55, RGB;
h = sin(gamma_i) derived from wi as Mitsuba does (:func:`chiang.offset_from_normal`); wi on the
front side (z > 0), wo uniform on the sphere. Mitsuba's eval returns S cos(theta_o); we time our
``eval`` (S) -- the extra multiply is negligible. Timings are the best of ``--repeats`` after a
warm-up (compilation excluded), the implementations called in turn (so that a change in
machine load affects them alike). ``--devices N`` shards the batch over N JAX CPU devices, as
in benchmarks/bsdf_throughput.py. Also printed: the compile time of the 1-device eval and, with
``--grad``, the throughput of d/d(params) of sum(S) (reverse mode). Not a test: nothing here
asserts a time.
"""

from __future__ import annotations

import time

import numpy as np
from _common import best_times, mitsuba_label, mitsuba_peer, sharded_vec3, throughput_args

BETA_M, BETA_N, ALPHA_DEG, EU = 0.3, 0.3, 2.0, 1.3


def random_pairs(n, seed=0):
    rng = np.random.default_rng(seed)
    wi = rng.normal(size=(3, n))
    wi /= np.linalg.norm(wi, axis=0)
    wi[2] = np.abs(wi[2])
    wo = rng.normal(size=(3, n))
    wo /= np.linalg.norm(wo, axis=0)
    return wi.astype(np.float32), wo.astype(np.float32)


def jax_runs(wi_np, wo_np, n_devices, grad=False):
    """{name: run()} for our eval on ``n_devices`` devices (and its gradient), and the eval's
    compile time [s]."""
    import jax
    import jax.numpy as jnp

    from appearance_jax.bcsdf import chiang

    wi, wo = sharded_vec3(wi_np, n_devices), sharded_vec3(wo_np, n_devices)
    params = chiang.Params.from_melanin(EU, 0.0, beta_m=BETA_M, beta_n=BETA_N, alpha=np.radians(ALPHA_DEG))
    kernel = chiang.eval.kernel
    f_eval = jax.jit(lambda p, wi, wo: kernel(p, wi, wo, chiang.offset_from_normal(wi)))
    t0 = time.perf_counter()
    f_eval = f_eval.lower(params, wi, wo).compile()
    t_compile = time.perf_counter() - t0
    runs = {f"appearance-jax chiang_hair, {n_devices} device(s) (jax {jax.__version__})":
            lambda: f_eval(params, wi, wo).block_until_ready()}
    if grad:
        f_grad = jax.jit(jax.grad(lambda p, wi, wo: jnp.sum(kernel(p, wi, wo, chiang.offset_from_normal(wi)))))
        runs[f"  gradient d/d(params) sum S, {n_devices} device(s)"] = \
            lambda: jax.block_until_ready(f_grad(params, wi, wo))
    return runs, t_compile


def mitsuba_run(wi_np, wo_np):
    dr, mi = mitsuba_peer()
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

    return run_eval, mitsuba_label(mi, "hair")


def main():
    import sys

    grad = "--grad" in sys.argv
    if grad:
        sys.argv.remove("--grad")
    args = throughput_args(__doc__)
    wi, wo = random_pairs(args.n)
    runs, t_compile = {}, None
    for nd in sorted({1, args.devices}):
        r, t = jax_runs(wi, wo, nd, grad and nd == 1)
        runs.update(r)
        t_compile = t if t_compile is None else t_compile
    run_mi, mv = mitsuba_run(wi, wo)
    if run_mi is not None:
        runs[mv] = run_mi
    best = best_times(runs, args.repeats)
    print(f"{'implementation':64s} {'eval [M/s]':>11s}")
    for name, t in best.items():
        print(f"{name:64s} {args.n / t / 1e6:11.2f}")
    if run_mi is None:
        print(f"{mv:64s} {'-':>11s}")
    else:
        for name, t in best.items():
            if name != mv and not name.startswith("  "):
                print(f"ratio ours/mitsuba [{name.split(' (')[0]}]: eval {best[mv] / t:.2f}")
    print(f"compile time of the 1-device eval: {t_compile:.2f} s")


if __name__ == "__main__":
    main()
