"""Throughput of rough_dielectric eval (default height-correlated G2, and separable) vs Mitsuba 3.

    python benchmarks/dielectric_throughput.py [--n 1000000] [--repeats 10] [--devices 2] [--before]

Prints evaluations per second for appearance-jax (float32, jit, Vec3-of-arrays) with its defaults
(``shadowing="correlated"``: the height-correlated Smith G2, a Beta function for refraction pairs)
and with ``shadowing="separable"`` (Mitsuba's G), and in the same run Mitsuba 3's
``roughdielectric`` (``llvm_ad_rgb``; DRJIT_LIBLLVM_PATH is pointed at a system libLLVM >= 16 when
found), with the ratios ours / Mitsuba. Configuration on both sides: GGX, alpha = 0.3,
eta = int_ior / ext_ior = 1.5 / 1.0, 1e6 random pairs with wi and wo uniform over the whole sphere
(so about half are refraction pairs, from either side). Mitsuba is called with
``TransportMode.Importance`` and ``si.wi = wi``, where its eval is our f(wi, wo) |wo.z| (see the
rough_dielectric docstring); it is divided by |wo.z|.

The machine may be shared: the implementations are timed alternately, one call each per round, and
each line is the best of ``--repeats`` rounds after a warm-up (compilation excluded; our compile time
is printed separately). A sanity check compares our separable values with Mitsuba's on a subset.
``--before`` adds a line for the correlated G2 with its former Beta function (three ``gammaln``).
Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from _common import best_times, mitsuba_eval_fn, mitsuba_label, mitsuba_peer, sharded_vec3, throughput_args

ALPHA, INT_IOR, EXT_IOR = 0.3, 1.5, 1.0


def sphere_pairs(n, seed=0):
    """(wi, wo), each (3, n) float32, uniform on the whole sphere (numpy)."""
    rng = np.random.default_rng(seed)

    def sphere():
        v = rng.normal(size=(3, n))
        return (v / np.linalg.norm(v, axis=0)).astype(np.float32)

    return sphere(), sphere()


def _three_gammaln(a, b):
    """The transmission Beta function as G2 computed it before issue 20 (three Lanczos gammaln)."""
    import jax.numpy as jnp
    from jax.scipy.special import gammaln

    a, b = jnp.maximum(a, 0.0), jnp.maximum(b, 0.0)
    return jnp.exp(gammaln(1.0 + a) + gammaln(1.0 + b) - gammaln(2.0 + a + b))


def jax_evals(wi_np, wo_np, n_devices, before=False):
    """{label: zero-argument callable} for our G2 forms, and their compile times [s]."""
    import jax

    from appearance_jax.bsdf import rough_dielectric as rd
    from appearance_jax.microfacet import distribution as md

    wi, wo = sharded_vec3(wi_np, n_devices), sharded_vec3(wo_np, n_devices)
    calls, compile_s = {}, {}
    variants = [("correlated (default)", "correlated", md.beta1p), ("separable", "separable", md.beta1p)]
    if before:
        variants.append(("correlated, 3 gammaln (before)", "correlated", _three_gammaln))
    for name, shadowing, beta in variants:
        params = rd.Params(alpha=ALPHA, eta=INT_IOR / EXT_IOR, shadowing=shadowing)
        t0 = time.perf_counter()
        saved, md.beta1p = md.beta1p, beta  # G2 looks it up when traced
        try:
            # a fresh function object per variant: jit's trace cache is keyed on it
            f = jax.jit(lambda p, wi, wo: rd.eval.kernel(p, wi, wo)).lower(params, wi, wo).compile()
        finally:
            md.beta1p = saved
        label = f"appearance-jax {name}, {n_devices} dev"
        compile_s[label] = time.perf_counter() - t0
        calls[label] = (lambda f=f, p=params: f(p, wi, wo).block_until_ready())
    return calls, compile_s


def mitsuba_eval(wi_np, wo_np):
    """(callable, values f of the pairs as numpy, version string) or (None, None, reason)."""
    dr, mi = mitsuba_peer()
    if dr is None:
        return None, None, f"{mi}"
    bsdf = mi.load_dict({"type": "roughdielectric", "distribution": "ggx", "alpha": ALPHA,
                         "int_ior": INT_IOR, "ext_ior": EXT_IOR, "sample_visible": True})
    run = mitsuba_eval_fn(dr, mi, bsdf, wi_np, wo_np, mi.TransportMode.Importance)
    values = np.asarray(run()[0])
    return run, values, mitsuba_label(mi, "roughdielectric")


def sanity_check(wi_np, wo_np, mitsuba_values, m=4096):
    """Our separable f against Mitsuba's on the first m pairs (a print, not an assertion)."""
    from appearance_jax.bsdf import rough_dielectric as rd
    from appearance_jax.core.vec import Vec3

    wi, wo = wi_np[:, :m], wo_np[:, :m]
    p = rd.Params(alpha=ALPHA, eta=INT_IOR / EXT_IOR, shadowing="separable")
    ours = np.asarray(rd.eval(p, Vec3(*wi), Vec3(*wo)))[:, 0]
    ref = mitsuba_values[:m]
    scale = np.maximum(np.abs(ref), 1e-3)
    err = np.abs(ours - ref) / scale
    print(f"sanity (separable G, {m} pairs, {np.mean(wi[2] * wo[2] < 0):.0%} refraction): max |ours - mitsuba| / "
          f"max(|mitsuba|, 1e-3) = {err.max():.2e}, median {np.median(err):.2e}")


def main():
    before = "--before" in sys.argv  # this script's own flag (the common ones: throughput_args)
    sys.argv = [a for a in sys.argv if a != "--before"]
    args = throughput_args(__doc__)
    wi, wo = sphere_pairs(args.n)
    calls, compile_s = {}, {}
    for nd in sorted({1, args.devices}):
        c, cs = jax_evals(wi, wo, nd, before)
        calls.update(c)
        compile_s.update(cs)
    run_m, values_m, mv = mitsuba_eval(wi, wo)
    if run_m is not None:
        calls[mv] = run_m
    best = best_times(calls, args.repeats)
    print(f"{'implementation':64s} {'eval [M/s]':>11s} {'compile [s]':>12s}")
    for name, t in best.items():
        cs = f"{compile_s[name]:12.2f}" if name in compile_s else f"{'-':>12s}"
        print(f"{name:64s} {args.n / t / 1e6:11.1f} {cs}")
    if run_m is None:
        print(f"Mitsuba: {mv}")
        return
    for name, t in best.items():
        if name != mv:
            print(f"ratio ours/mitsuba [{name}]: eval {best[mv] / t:.2f}")
    sanity_check(wi, wo, values_m)


if __name__ == "__main__":
    main()
