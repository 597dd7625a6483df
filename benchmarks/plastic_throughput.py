"""Throughput of rough_plastic eval vs Mitsuba 3's ``roughplastic``.

    python benchmarks/plastic_throughput.py [--n 1000000] [--repeats 10] [--devices 2]

Prints evaluations per second of appearance-jax's ``rough_plastic.eval`` (float32, jit,
Vec3-of-arrays; the coat tables are part of every call, as in a fit) and, in the same run,
of Mitsuba 3 ``llvm_ad_rgb`` ``roughplastic`` when it is importable (see bsdf_throughput.py),
and the ratio ours / Mitsuba (> 1: ours is faster). The two are timed alternately, call by
call, so that a load on the machine hits both alike; each figure is the best of
``--repeats``. The compilation time of our first call is printed too (Mitsuba's LLVM
kernels are compiled on its first call and cached; excluded on both sides from the rates).

Configuration on both sides: GGX, alpha = 0.3, eta = 1.5 (int_ior 1.5 over ext_ior 1),
diffuse reflectance (0.8, 0.4, 0.2), specular reflectance 1, nonlinear false; 1e6 random
pairs with wi, wo in the upper hemisphere. Our lines: ``shadowing="separable"`` (Mitsuba's
G, like for like) with the default precomputed coat tables; the defaults
(``shadowing="correlated"``); and ``tables="accurate"`` (the quadrature inside every call,
the default before the precomputed tables). Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import os
import time

from _common import best_times, mitsuba_eval_fn, mitsuba_label, mitsuba_peer, sharded_vec3, throughput_args, upper_hemisphere_pairs

ALPHA = 0.3
ETA = 1.5
RHO = (0.8, 0.4, 0.2)
LINES = {
    "separable, precomputed tables": dict(shadowing="separable"),
    "defaults (correlated, precomputed)": dict(),
    "separable, accurate tables (quadrature per call)": dict(shadowing="separable", tables="accurate"),
}


def jax_runners(wi_np, wo_np, n_devices):
    """{line: (compile seconds, run())} for our configurations."""
    import jax

    from appearance_jax.bsdf import rough_plastic as rp

    wi, wo = sharded_vec3(wi_np, n_devices), sharded_vec3(wo_np, n_devices)
    out = {}
    for name, kw in LINES.items():
        params = rp.Params(alpha=ALPHA, eta=ETA, diffuse_reflectance=RHO, specular_reflectance=1.0, **kw)
        f = jax.jit(rp.eval.kernel)  # the jitted public function minus the eager validation
        t0 = time.perf_counter()
        f(params, wi, wo).block_until_ready()
        out[name] = (time.perf_counter() - t0, lambda f=f, p=params: f(p, wi, wo).block_until_ready())
    return out, jax.__version__


def mitsuba_runner(wi_np, wo_np):
    dr, mi = mitsuba_peer()
    if dr is None:
        return None, f"{mi}"
    bsdf = mi.load_dict({"type": "roughplastic", "distribution": "ggx", "alpha": ALPHA, "int_ior": ETA,
                         "ext_ior": 1.0, "nonlinear": False, "sample_visible": True,
                         "diffuse_reflectance": {"type": "rgb", "value": list(RHO)},
                         "specular_reflectance": 1.0})
    run = mitsuba_eval_fn(dr, mi, bsdf, wi_np, wo_np)
    run()  # compile its kernel
    return run, mitsuba_label(mi, "")


def main():
    args = throughput_args(__doc__)
    wi, wo = upper_hemisphere_pairs(args.n)
    mi_run, mv = mitsuba_runner(wi, wo)
    for nd in sorted({1, args.devices}):
        ours, jv = jax_runners(wi, wo, nd)
        runners = {k: fn for k, (_, fn) in ours.items()}
        if mi_run is not None:
            runners["mitsuba"] = mi_run
        best = best_times(runners, args.repeats)
        print(f"\nappearance-jax {nd} device(s) (jax {jv}) vs {mv}")
        print(f"{'implementation':52s} {'eval [M/s]':>11s} {'compile [s]':>12s} {'ratio ours/mitsuba':>19s}")
        for k, t in best.items():
            comp = f"{ours[k][0]:12.2f}" if k in ours else f"{'-':>12s}"
            ratio = f"{best['mitsuba'] / t:19.2f}" if mi_run is not None and k in ours else f"{'-':>19s}"
            print(f"{k:52s} {args.n / t / 1e6:11.1f} {comp} {ratio}")


if __name__ == "__main__":
    main()
