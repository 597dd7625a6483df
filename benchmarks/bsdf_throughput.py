"""Throughput of rough_conductor eval and eval+grad (w.r.t. roughness) vs Mitsuba 3.

    python benchmarks/bsdf_throughput.py [--n 1000000] [--repeats 10] [--devices 2] [--native]

Prints evaluations per second for appearance-jax (float32, jit, Vec3-of-arrays) and, in
the same run, for Mitsuba 3 ``llvm_ad_rgb`` when it is importable (it needs a system
libLLVM >= 16, e.g. Debian's libllvm19; this script points DRJIT_LIBLLVM_PATH at it when
found), and the ratio ours / Mitsuba. Same configuration on both sides: GGX, alpha = 0.3,
RGB gold-like eta/k, separable Smith G (Mitsuba's), 1e6 random pairs with wi, wo in the
upper hemisphere. Timings are the best of ``--repeats`` after a warm-up (compilation
excluded on both sides). Not a test: nothing here asserts a time.

XLA:CPU runs one fused elementwise loop on one thread, while Mitsuba's LLVM backend uses
every core. ``--devices N`` (default: the number of cores) splits the host into N JAX CPU
devices and shards the direction batch over them with ``jax.sharding`` -- JAX's own
parallelism, the same mechanism a batched fit uses -- and the single-device figure is
printed as well.

Reverse mode is timed twice: as shipped (``rough_conductor.eval`` carries
``core.autodiff.forward_jacobian_rule``: one perturbed scalar costs one forward-mode column)
and with ``--native`` also JAX's plain reverse mode of the unwrapped kernel, alternately in
the same run. The temporary memory of each compiled gradient (XLA's ``memory_analysis``) is
printed with it.
"""

from __future__ import annotations

import os
import sys

from _common import best_time, best_times, mitsuba_label, mitsuba_peer, sharded_vec3, throughput_args, upper_hemisphere_pairs

ETA = (0.18, 0.45, 1.35)
K = (3.40, 2.25, 1.80)
ALPHA = 0.3


def _temp_mb(f, *args):
    """Temporary buffer size of the compiled ``f(*args)`` in MB (None where XLA does not say)."""
    m = f.lower(*args).compile().memory_analysis()
    return None if m is None else m.temp_size_in_bytes / 1e6


def bench_jax(wi_np, wo_np, repeats, n_devices=1, native=False):
    """Best times [s] of eval, reverse-mode eval+grad, forward-mode eval+grad and (``native``)
    plain reverse mode of the unwrapped kernel, their temporary memory [MB], jax's version."""
    import jax
    import jax.numpy as jnp

    from appearance_jax.bsdf import rough_conductor as rc

    wi, wo = sharded_vec3(wi_np, n_devices), sharded_vec3(wo_np, n_devices)
    params = rc.Params(alpha=ALPHA, eta=ETA, k=K, shadowing="separable")
    kernel = rc.eval.kernel  # the jitted public function minus the eager validation

    f_eval = jax.jit(kernel)
    loss = lambda a, wi, wo: jnp.sum(kernel(params.replace(alpha=a), wi, wo))  # noqa: E731
    f_grad = jax.jit(jax.value_and_grad(loss))
    # JAX's own reverse mode: the kernel without its forward-Jacobian rule (stores the graph)
    loss_native = lambda a, wi, wo: jnp.sum(kernel.unwrapped(params.replace(alpha=a), wi, wo))  # noqa: E731
    f_native = jax.jit(jax.value_and_grad(loss_native))
    # forward mode: one scalar parameter -> one JVP pass (what a Jacobian column costs in a fit)
    f_fwd = jax.jit(lambda a, wi, wo: jax.jvp(lambda a: loss(a, wi, wo), (a,), (jnp.ones_like(a),)))
    a = jnp.float32(ALPHA)
    runs = {"eval": lambda: f_eval(params, wi, wo).block_until_ready(),
            "grad": lambda: f_grad(a, wi, wo)[1].block_until_ready(),
            "fwd": lambda: f_fwd(a, wi, wo)[1].block_until_ready()}
    mem = {"grad": _temp_mb(f_grad, a, wi, wo), "fwd": _temp_mb(f_fwd, a, wi, wo)}
    if native:
        runs["native"] = lambda: f_native(a, wi, wo)[1].block_until_ready()
        mem["native"] = _temp_mb(f_native, a, wi, wo)
    return best_times(runs, repeats), mem, jax.__version__


def bench_mitsuba(wi_np, wo_np, repeats):
    dr, mi = mitsuba_peer()
    if dr is None:
        return None, None, f"{mi}"
    n = wi_np.shape[1]
    bsdf = mi.load_dict({"type": "roughconductor", "distribution": "ggx", "alpha": ALPHA,
                         "eta": {"type": "rgb", "value": list(ETA)}, "k": {"type": "rgb", "value": list(K)},
                         "sample_visible": True})
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(wi_np)
    wo = mi.Vector3f(wo_np)
    ctx = mi.BSDFContext()
    cos_o = mi.Float(wo_np[2])

    def run_eval():
        # Mitsuba returns f * cos(theta_o); divide to return the same quantity as ours.
        v = bsdf.eval(ctx, si, wo) / cos_o
        dr.eval(v)
        dr.sync_thread()

    params = mi.traverse(bsdf)
    key = [k for k in params.keys() if k.startswith("alpha")][0]

    def run_grad():
        params[key] = mi.Float(ALPHA)
        dr.enable_grad(params[key])
        params.update()
        v = bsdf.eval(ctx, si, wo) / cos_o
        loss = dr.sum(v[0] + v[1] + v[2])
        dr.backward(loss)
        g = dr.grad(params[key])
        dr.eval(loss, g)
        dr.sync_thread()

    t_eval = best_time(run_eval, repeats)
    t_grad = best_time(run_grad, repeats)
    return t_eval, t_grad, mitsuba_label(mi, "")


def main():
    native = "--native" in sys.argv  # this script's own flag (the common ones: throughput_args)
    sys.argv = [a for a in sys.argv if a != "--native"]
    args = throughput_args(__doc__)
    wi, wo = upper_hemisphere_pairs(args.n)
    rows = []
    for nd in sorted({1, args.devices}):
        t, mem, jv = bench_jax(wi, wo, args.repeats, nd, native)
        labels = {"grad": f"reverse-mode grad (jax {jv})", "fwd": "forward-mode grad (jvp)",
                  "native": "reverse-mode grad, native (no rule)"}
        for key in [k for k in labels if k in t]:
            rows.append((f"appearance-jax {nd} device(s), {labels[key]}", t["eval"], t[key]))
            print(f"{rows[-1][0].split(' (jax')[0]}: temporary memory {mem[key]} MB")
        if "native" in t:
            print(f"ratio reverse-mode with rule / native, {nd} device(s): {t['native'] / t['grad']:.2f}")
    tm_e, tm_g, mv = bench_mitsuba(wi, wo, args.repeats)
    rows.append((mv, tm_e, tm_g))
    print(f"{'implementation':64s} {'eval [M/s]':>11s} {'eval+grad [M/s]':>16s}")
    for name, te, tg in rows:
        if te is None:
            print(f"{name:64s} {'-':>11s} {'-':>16s}")
        else:
            print(f"{name:64s} {args.n / te / 1e6:11.1f} {args.n / tg / 1e6:16.1f}")
    if tm_e is not None:
        for name, te, tg in rows[:-1]:
            print(f"ratio ours/mitsuba [{name.split(' (')[0]}]: eval {tm_e / te:.2f}, eval+grad {tm_g / tg:.2f}")


if __name__ == "__main__":
    main()
