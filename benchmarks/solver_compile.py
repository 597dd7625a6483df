"""Trace and compile time of one fit's solve, per solver, each in a fresh process.

    python benchmarks/solver_compile.py [--models rough_conductor rough_plastic] [--solvers lm optx_lm jaxopt_lm gn]

The problems of ``fit_lm_vs_powell.py`` (noisy synthetic in-plane tables, same starts). For each
(model, solver) a new Python process builds the problem and times, separately, tracing
(``jax.jit(solve).trace``), lowering and XLA compilation of one solve (``solve_z``, unbatched),
then runs it once (steps, final loss, converged). The persistent compilation cache is off, so
every figure is cold. Not a test: nothing asserts a time.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

CHILD = r"""
import json, sys, time
sys.path.insert(0, {bench!r})
import jax
jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp, numpy as np
from fit_lm_vs_powell import CASES, make_table
from appearance_jax import registry
from appearance_jax.fit.solve import build_problem
from appearance_jax.fit.solve.solvers import solve_z
model = registry.get({name!r}); truth, start, fix = CASES[{name!r}]
table = make_table(model, model.Params(**truth))
problem = build_problem(model, table, init=model.Params(**start), fix=fix, metric="l2")
z0 = jnp.asarray(problem.space.z_from_x(problem.space.x_start()))
jnp.zeros(1).block_until_ready()
f = jax.jit(lambda z, d: solve_z(problem, z, d, solver={solver!r}))
t0 = time.perf_counter(); tr = f.trace(z0, problem.data); t1 = time.perf_counter()
lo = tr.lower(); t2 = time.perf_counter(); c = lo.compile(); t3 = time.perf_counter()
z, loss, steps, ok = jax.block_until_ready(c(z0, problem.data)); t4 = time.perf_counter()
print("RESULT " + json.dumps(dict(trace=t1 - t0, lower=t2 - t1, compile=t3 - t2, run=t4 - t3, steps=int(steps),
                                  loss=float(loss), ok=bool(ok))))
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", nargs="*", default=["rough_conductor", "rough_conductor+lambert", "rough_plastic"])
    ap.add_argument("--solvers", nargs="*", default=["lm", "optx_lm", "jaxopt_lm", "gn"])
    a = ap.parse_args()
    bench = os.path.dirname(os.path.abspath(__file__))
    env = dict(os.environ, APPEARANCE_JAX_COMPILE_CACHE="off")
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    print("| model | solver | trace [s] | lower [s] | compile [s] | total [s] | solve [s] | steps | final loss | converged |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in a.models:
        for solver in a.solvers:
            code = CHILD.format(bench=bench, name=name, solver=solver)
            out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=1800)
            line = [x for x in out.stdout.splitlines() if x.startswith("RESULT ")]
            if not line:
                print(f"| {name} | {solver} | failed: {out.stderr.strip().splitlines()[-1] if out.stderr else '?'} |")
                continue
            r = json.loads(line[0][7:])
            print(f"| {name} | {solver} | {r['trace']:.2f} | {r['lower']:.2f} | {r['compile']:.2f} "
                  f"| {r['trace'] + r['lower'] + r['compile']:.2f} | {r['run']:.3f} | {r['steps']} | {r['loss']:.8g} "
                  f"| {r['ok']} |", flush=True)


if __name__ == "__main__":
    main()
