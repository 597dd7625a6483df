"""Compile time of every registered model's eval, each in a fresh (cold) process.

    python benchmarks/compile_times.py [--models a,b] [--n 4096] [--x64] [--warm]

For each model of ``appearance_jax.registry.names()`` a new Python process builds the
model's default parameters and ``n`` random direction pairs (upper hemisphere for reflection
models, the whole sphere for the others), then times, separately,

- trace: ``jax.jit(model.eval.kernel).trace(...)`` (Python tracing to a jaxpr);
- lower + compile: ``.lower().compile()`` (StableHLO -> XLA:CPU machine code);
- first call: running the compiled program once (to show it is not the cost).

The persistent compilation cache is off (``APPEARANCE_JAX_COMPILE_CACHE=off`` and no JAX
cache directory) so every figure is a cold compile; ``--warm`` instead points both processes
of a model at one fresh cache directory and reports the second (warm) process too. Not a
test: nothing asserts a time. Stochastic models are compiled with their PRNG key argument.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

CHILD = r"""
import json, sys, time
t_import = time.perf_counter()
import numpy as np
import jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", {x64})
from appearance_jax import registry
from appearance_jax.core.vec import Vec3
t_import = time.perf_counter() - t_import
m = registry.get({name!r})
p = m.Params()
rng = np.random.default_rng(0)
def dirs(upper):
    v = rng.normal(size=({n}, 3)); v /= np.linalg.norm(v, axis=1, keepdims=True)
    if upper: v[:, 2] = np.abs(v[:, 2])
    return Vec3(*(jnp.asarray(v[:, k]) for k in range(3)))
upper = m.kind == "bsdf" and not m.transmissive
wi, wo = dirs(upper), dirs(upper)
kw = dict(key=jax.random.PRNGKey(0)) if m.stochastic else {{}}
f = jax.jit(m.eval.kernel)
t0 = time.perf_counter(); tr = f.trace(p, wi, wo, **kw); t1 = time.perf_counter()
c = tr.lower().compile(); t2 = time.perf_counter()
jax.block_until_ready(c(p, wi, wo, **kw)); t3 = time.perf_counter()
print("RESULT " + json.dumps(dict(model={name!r}, import_s=t_import, trace_s=t1 - t0, compile_s=t2 - t1, run_s=t3 - t2)))
"""


def run_child(name, n, x64, cache_dir):
    env = dict(os.environ)
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    if cache_dir is None:
        env["APPEARANCE_JAX_COMPILE_CACHE"] = "off"
        code = CHILD.format(name=name, n=n, x64=x64)
    else:
        env["APPEARANCE_JAX_COMPILE_CACHE"] = cache_dir
        code = CHILD.format(name=name, n=n, x64=x64).replace(
            "t_import = time.perf_counter() - t_import",
            "from appearance_jax.core import compile_cache; compile_cache.ensure()\n"
            "jax.config.update('jax_persistent_cache_min_compile_time_secs', 0.0)\n"
            "t_import = time.perf_counter() - t_import")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=900)
    for line in out.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    raise RuntimeError(f"{name}: {out.stderr[-2000:]}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default=None, help="comma-separated names (default: all registered)")
    ap.add_argument("--n", type=int, default=4096, help="direction pairs (default 4096)")
    ap.add_argument("--x64", action="store_true", help="float64 (default float32)")
    ap.add_argument("--warm", action="store_true", help="also a second process reading a fresh persistent cache")
    a = ap.parse_args()
    if a.models:
        names = a.models.split(",")
    else:
        from appearance_jax import registry

        names = registry.names()
    import jax

    print(f"jax {jax.__version__}, {'float64' if a.x64 else 'float32'}, {a.n} pairs, cold process per model")
    head = "| model | trace [s] | compile [s] | trace + compile [s] | first call [s] |"
    if a.warm:
        head += " warm trace + compile [s] |"
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    for name in names:
        try:
            if a.warm:
                with tempfile.TemporaryDirectory() as d:
                    r = run_child(name, a.n, a.x64, d)
                    w = run_child(name, a.n, a.x64, d)
            else:
                r, w = run_child(name, a.n, a.x64, None), None
        except RuntimeError as e:  # one model that does not compile must not hide the others' rows
            last = [ln for ln in str(e).splitlines() if ln.strip()][-3:]
            print(f"| {name} | failed: {' / '.join(last)[:300]} |", flush=True)
            continue
        row = (f"| {name} | {r['trace_s']:.2f} | {r['compile_s']:.2f} | {r['trace_s'] + r['compile_s']:.2f} "
               f"| {r['run_s']:.3f} |")
        if w is not None:
            row += f" {w['trace_s'] + w['compile_s']:.2f} |"
        print(row, flush=True)


if __name__ == "__main__":
    main()
