"""Helpers shared by the benchmark scripts (run as ``python3 benchmarks/<script>.py``, so this
directory is on ``sys.path``): timing, sharded inputs, and loading Mitsuba's LLVM backend."""

from __future__ import annotations

import argparse
import glob
import os
import platform
import time

import numpy as np


def throughput_args(doc, n=1_000_000):
    """The benchmarks' common command line (--n, default ``n``; --repeats, --devices); sets the
    number of JAX CPU devices (before the backend starts) and prints the machine line."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=n)
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--devices", type=int, default=os.cpu_count() or 1,
                    help="JAX CPU devices to shard the batch over (default: cores)")
    args = ap.parse_args()
    import jax

    jax.config.update("jax_num_cpu_devices", args.devices)
    dev = jax.devices()[0]
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; JAX {jax.__version__} on "
          f"{dev.platform} ({dev.device_kind}); n = {args.n:,} direction pairs")
    return args


def upper_hemisphere_pairs(n, seed=0):
    """(wi, wo), each (3, n) float32, uniform on the upper hemisphere (numpy)."""
    rng = np.random.default_rng(seed)

    def hemi():
        v = rng.normal(size=(3, n))
        v /= np.linalg.norm(v, axis=0)
        v[2] = np.abs(v[2])
        return v.astype(np.float32)

    return hemi(), hemi()


def best_time(fn, repeats):
    """Best wall time of ``repeats`` calls of ``fn`` after one warm-up (compilation) call."""
    fn()
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return min(ts)


def first_and_best(fn, repeats):
    """(wall time of the first call (trace + compile + run), best of ``repeats`` further calls)."""
    t0 = time.perf_counter()
    fn()
    first = time.perf_counter() - t0
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return first, min(ts)


def best_times(runs, repeats):
    """Best wall time of each of ``runs`` (name -> callable) after a warm-up call each, the
    calls alternating so that a change in machine load affects them alike."""
    for fn in runs.values():
        fn()
    best = {k: float("inf") for k in runs}
    for _ in range(repeats):
        for k, fn in runs.items():
            t0 = time.perf_counter()
            fn()
            best[k] = min(best[k], time.perf_counter() - t0)
    return best


def mitsuba_eval_fn(dr, mi, bsdf, wi_np, wo_np, mode=None):
    """``run()`` evaluating Mitsuba's ``bsdf`` at the pairs (wi, wo: (3, n) numpy, local frame)
    and returning f, i.e. Mitsuba's eval divided by |cos theta_o| (it returns f |cos theta_o|).
    ``mode``: a ``mi.TransportMode`` for the context (default: Mitsuba's, Radiance)."""
    si = dr.zeros(mi.SurfaceInteraction3f, wi_np.shape[1])
    si.wi = mi.Vector3f(wi_np)
    wo = mi.Vector3f(wo_np)
    ctx = mi.BSDFContext() if mode is None else mi.BSDFContext(mode)
    cos_o = mi.Float(np.abs(wo_np[2]))

    def run():
        v = bsdf.eval(ctx, si, wo) / cos_o
        dr.eval(v)
        dr.sync_thread()
        return v

    return run


def sharded_vec3(rows, n_devices=1):
    """A Vec3 of the three rows of ``rows`` (3, n), split over the first ``n_devices`` JAX
    devices along the batch axis (jax.sharding)."""
    import jax
    import jax.numpy as jnp
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    from appearance_jax.core.vec import Vec3

    devices = jax.devices()[:n_devices]
    sharding = NamedSharding(Mesh(np.array(devices), ("batch",)), PartitionSpec("batch"))
    return Vec3(*(jax.device_put(jnp.asarray(c), sharding) for c in rows))


def _find_libllvm():
    for pat in ("/usr/lib/x86_64-linux-gnu/libLLVM-1[6-9]*.so*", "/usr/lib/x86_64-linux-gnu/libLLVM.so.1[6-9]*",
                "/usr/lib/llvm-1[6-9]/lib/libLLVM*.so*", "/usr/lib/x86_64-linux-gnu/libLLVM-2*.so*"):
        hits = sorted(glob.glob(pat))
        if hits:
            return hits[-1]
    return None


def mitsuba_variant():
    """The Mitsuba variant the benchmarks compare against: ``$APPEARANCE_JAX_BENCH_MITSUBA``,
    default ``llvm_ad_rgb`` (the CPU peer); ``cuda_ad_rgb`` on a GPU machine."""
    return os.environ.get("APPEARANCE_JAX_BENCH_MITSUBA", "llvm_ad_rgb")


def mitsuba_peer():
    """``(drjit, mitsuba)`` with the peer variant set (:func:`mitsuba_variant`, ``llvm_ad_rgb``
    unless the environment names another), or ``(None, reason)`` when the peer is unavailable
    (Mitsuba's LLVM backend needs a system libLLVM >= 16, its CUDA backend a GPU driver)."""
    variant = mitsuba_variant()
    if variant.startswith("llvm") and "DRJIT_LIBLLVM_PATH" not in os.environ:
        lib = _find_libllvm()
        if not lib:  # Dr.Jit would load an older libLLVM it cannot generate code with, and abort
            return None, "unavailable (no system libLLVM >= 16 found; set DRJIT_LIBLLVM_PATH)"
        os.environ["DRJIT_LIBLLVM_PATH"] = lib
    try:
        import drjit as dr
        import mitsuba as mi

        mi.set_variant(variant)
    except Exception as e:  # noqa: BLE001 - any failure means "peer unavailable"
        return None, f"unavailable ({type(e).__name__}: {e})"
    return dr, mi


def mitsuba_label(mi, what=""):
    """``mitsuba <version> <variant> [what]`` (and the libLLVM used, for the LLVM backend)."""
    v = mi.variant()
    lib = f" ({os.environ.get('DRJIT_LIBLLVM_PATH')})" if v.startswith("llvm") else ""
    return f"mitsuba {mi.__version__} {v}{(' ' + what) if what else ''}{lib}"
