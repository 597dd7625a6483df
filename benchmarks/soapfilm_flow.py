"""Soap-film flow (issue 24): seconds per step, compile time, the advection/solve split, CG
iterations and peak memory, per grid.

There is no peer program to run: the reference is the thesis' 1.1 s per step at 1024 x 2048 on a
GTX 1080 (CUDA + AmgX, 16-17 CG iterations, 75 % forces/divergence, 25 % advection; Huang
Sec. 3.4.4, [T:730-734]). The scene is the CLI's "blow" set-up (Table 3.2 numbers, a rotating
ball of air), dt = 0.002 s on a 5 cm bubble (0.04 dimensionless); by default the CLI's precision:
float32 state (advection, maps) and a float64 solve.

    python3 benchmarks/soapfilm_flow.py [--grids 128x256,256x512] [--steps 40] [--state float64] [--solve float32]
"""

from __future__ import annotations

import argparse
import resource
import time

import jax
import jax.numpy as jnp
import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--grids", default="128x256,256x512")
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--state", choices=("float32", "float64"), default="float32")
    ap.add_argument("--solve", choices=("float32", "float64"), default="float64")
    args = ap.parse_args()
    if "float64" in (args.state, args.solve):
        jax.config.update("jax_enable_x64", True)
    if args.solve == "float32" and args.state == "float64":
        ap.error("--solve float32 needs --state float32")
    from appearance_jax.soapfilm import air, concentration as C, flow
    from appearance_jax.soapfilm.grid import SphereGrid
    from appearance_jax.soapfilm.transport import advect_step

    dtype = jnp.dtype(args.state)
    wd = jnp.dtype(args.solve)
    print(f"device: {jax.devices()[0].device_kind} ({jax.default_backend()}), state {dtype.name}, solve {wd.name}")
    print(f"{'grid':>10} {'compile s':>9} {'s/step':>8} {'steps/s':>8} {'advect s':>9} {'solve s':>8} "
          f"{'cg it (max)':>11} {'reinit':>6} {'maxrss MB':>9}")
    for text in args.grids.split(","):
        grid = SphereGrid.parse(text)
        params = flow.FlowParams()
        a = air.Rotating()
        state = flow.rest_state(grid, dtype=dtype)
        t0 = time.perf_counter()
        r = flow.simulate(grid, params, state, 0.04, 4, air=a)  # compile + 4 steps (spin-up)
        jax.block_until_ready(r.frames)
        t_first = time.perf_counter() - t0
        t0 = time.perf_counter()
        r4 = flow.simulate(grid, params, None, 0.04, 4, air=a, carry=r.carry)
        jax.block_until_ready(r4.frames)
        t4 = time.perf_counter() - t0
        compile_s = t_first - t4
        t0 = time.perf_counter()
        r = flow.simulate(grid, params, None, 0.04, args.steps, air=a, carry=r4.carry)
        jax.block_until_ready(r.frames)
        per_step = (time.perf_counter() - t0) / args.steps
        # the split: the advection pass and the solve alone, on the state reached
        s, m = r.carry.state, r.carry.maps
        adv = jax.jit(lambda s, m: advect_step(grid, s.u_theta, s.u_phi, None, m, 0.04, 2))
        out = adv(s, m)
        jax.block_until_ready(out)

        def solve(s):
            s = type(s)(*(a.astype(wd) for a in s))
            z_t, z_p = jnp.zeros_like(s.u_theta), jnp.zeros_like(s.u_phi)
            faces = C.face_terms(grid, s.eta, s.u_theta, s.u_phi, z_t, z_p, 0.83, 2.1, 0.49, 0.04)
            P = C.row_mean_preconditioner(grid, faces, s.gamma, 0.04)
            x, info = C.cg(lambda v: C.apply(grid, faces, s.gamma, 0.04, v), C.rhs(grid, faces, 0.04), s.gamma, P,
                           1e-6 if dtype == jnp.float32 else 1e-10, 2000)
            return x, info

        sol = jax.jit(solve)
        jax.block_until_ready(sol(s))
        ta = _best(lambda: jax.block_until_ready(adv(s, m)))
        ts = _best(lambda: jax.block_until_ready(sol(s)))
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"{text:>10} {compile_s:9.2f} {per_step:8.4f} {1 / per_step:8.2f} {ta:9.4f} {ts:8.4f} "
              f"{int(np.max(r.info.cg_iterations)):>11d} {int(m.n_reinit):>6d} {rss:9.0f}")


def _best(fn, n=5):
    best = float("inf")
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


if __name__ == "__main__":
    main()
