"""Lorenz–Mie throughput: appearance-jax (phase/mie_series.py) vs miepython, same run.

    python benchmarks/mie_vs_miepython.py [--angles 1800] [--repeats 5] [--spheres 2000]

Workloads (float64, water m = 1.333 unless stated):

1. amplitudes S1, S2 at ``--angles`` scattering angles for one sphere, x = 10, 100, 1000,
   4000 (the rainbow drops of Sadeghi 2011 are x ~ 1000-10000): ours = coefficients +
   amplitudes in one jitted call; miepython = ``S1_S2(m, x, mu, norm="wiscombe")``;
2. efficiencies (Q_ext, Q_sca, Q_back, g) of ``--spheres`` spheres with x uniform in
   [1, 100] and m = 1.5 + 0.01i (a size distribution): ours = one vmapped call with a
   common padded series length; miepython = ``efficiencies_mx`` per sphere.

Best of ``--repeats`` after one warm-up; the first call's time (compile + run) is printed
separately, because a user waits for it. Prints spheres or angles per second and the ratio
ours / miepython. Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np
from _common import best_time as best


def first(fn):
    t0 = time.perf_counter()
    jax.block_until_ready(fn())
    return time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--angles", type=int, default=1800)
    ap.add_argument("--spheres", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import miepython

    from appearance_jax.phase import mie_series as S

    print(f"jax {jax.__version__} ({jax.default_backend()}), miepython {miepython.__version__} "
          f"(numba jit: {getattr(miepython, 'USE_JIT', '?')})")
    mu = np.cos(np.radians(np.linspace(0.0, 180.0, args.angles)))
    print(f"\n1. S1, S2 at {args.angles} angles, one sphere, m = 1.333")
    print(f"{'x':>6} {'terms':>6} {'ours first (s)':>15} {'ours (ms)':>10} {'miepython (ms)':>15} {'ratio':>7}")
    for x in (10.0, 100.0, 1000.0, 4000.0):
        terms = S.series_length(x)
        fn = jax.jit(lambda x, mu, terms=terms: S.amplitudes(*S.coefficients(1.333, x, terms), mu))
        mu_j = jnp.asarray(mu)
        t_first = first(lambda: fn(x, mu_j))
        t_ours = best(lambda: jax.block_until_ready(fn(x, mu_j)), args.repeats)
        miepython.S1_S2(1.333, x, mu, norm="wiscombe")  # numba warm-up
        t_ref = best(lambda: miepython.S1_S2(1.333, x, mu, norm="wiscombe"), args.repeats)
        print(f"{x:6.0f} {terms:6d} {t_first:15.2f} {1e3 * t_ours:10.2f} {1e3 * t_ref:15.2f} {t_ref / t_ours:7.2f}")

    print(f"\n2. efficiencies of {args.spheres} spheres, x in [1, 100], m = 1.5 + 0.01i")
    rng = np.random.default_rng(0)
    xs = rng.uniform(1.0, 100.0, args.spheres)
    terms = S.series_length(xs.max())
    m = 1.5 + 0.01j

    @jax.jit
    def eff(x):
        a, b = S.coefficients(m, x, terms)
        return S.efficiencies(a, b, x)

    xs_j = jnp.asarray(xs)
    t_first = first(lambda: eff(xs_j))
    t_ours = best(lambda: jax.block_until_ready(eff(xs_j)), args.repeats)
    m_mp = complex(m.real, -m.imag)
    n_ref = min(args.spheres, 400)
    miepython.efficiencies_mx(m_mp, xs[0])
    t_ref = best(lambda: [miepython.efficiencies_mx(m_mp, x) for x in xs[:n_ref]], args.repeats) * args.spheres / n_ref
    print(f"ours: first call {t_first:.2f} s, then {args.spheres / t_ours:,.0f} spheres/s; "
          f"miepython: {args.spheres / t_ref:,.0f} spheres/s (timed on {n_ref}); ratio {t_ref / t_ours:.2f}")


if __name__ == "__main__":
    main()
