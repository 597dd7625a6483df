"""Rock-dove barbule BSDF throughput vs the plain thin-film BSDF, same run.

    python benchmarks/rock_dove_throughput.py [--n 65536] [--repeats 5]

No other program implements Huang's barbule BSDF (his Mitsuba 2 plugin is not packaged), so the
peer is our own ``iridescent`` (a microfacet BRDF with the same keratin film, d = 590 nm): the
thesis renders its feathers 2.1x slower than plain thin films [T:1760]. Timed on ``--n`` random
upper-hemisphere pairs, float32, one JAX CPU device, best of ``--repeats`` after a warm-up whose
time (trace + compile + first run) is printed: ``rock_dove.eval`` at its default rho quadrature
(12 x 2 nodes) and at 4 x 2, ``rock_dove_stochastic.eval`` (Huang's one-draw TRT, the thesis'
evaluation), ``rock_dove.reflection_geometry`` (S_R without the film, no TRT), ``rock_dove.sample_lobes`` (Huang's Algorithm 1: one estimator of
the whole BSDF, no quadrature), ``rock_dove.transmission``, and ``iridescent.eval``.
Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import first_and_best as best, upper_hemisphere_pairs  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=65536)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    import jax
    import jax.numpy as jnp

    from appearance_jax.bsdf import iridescent, rock_dove, rock_dove_stochastic
    from appearance_jax.core.vec import Vec3

    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__}, "
          f"{jax.devices()[0].device_kind}; n = {args.n:,} pairs, float32")
    wi_np, wo_np = upper_hemisphere_pairs(args.n)
    wi, wo = (Vec3(*(jnp.asarray(a) for a in w)) for w in (wi_np, wo_np))
    key = jax.random.key(0)
    p = rock_dove.Params()
    cases = [
        ("rock_dove.eval (rho 12 x 2)", lambda: rock_dove.eval(p, wi, wo).block_until_ready()),
        ("rock_dove.eval (rho 4 x 2)", lambda: rock_dove.eval(p.replace(n_phi=4), wi, wo).block_until_ready()),
        ("rock_dove_stochastic.eval (one-draw TRT)",
         lambda: rock_dove_stochastic.eval(p, wi, wo, key).block_until_ready()),
        ("rock_dove.reflection_geometry (S_R / I_R)",
         lambda: rock_dove.reflection_geometry(p, wi, wo).block_until_ready()),
        ("rock_dove.sample_lobes (Algorithm 1)", lambda: rock_dove.sample_lobes(p, wi, key)[1].block_until_ready()),
        ("rock_dove.transmission", lambda: rock_dove.transmission(p, wi).block_until_ready()),
        ("iridescent.eval (same film)", lambda: iridescent.eval(
            iridescent.Params(alpha=0.1, thickness=590.0, eta_film=1.55), wi, wo).block_until_ready()),
    ]
    rates = {}
    for name, fn in cases:
        first, t = best(fn, args.repeats)
        rates[name] = args.n / t
        print(f"{name:40s} {args.n / t / 1e6:9.4f} M/s   first call {first:6.2f} s")
    ref = rates["iridescent.eval (same film)"]
    for name, r in rates.items():
        print(f"  {name:40s} / iridescent = {r / ref:.4g}")


if __name__ == "__main__":
    main()
