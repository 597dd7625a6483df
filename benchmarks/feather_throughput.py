"""Padrón's feather BSDF and fibre BCSDF: throughput against chiang_hair in the same run, and the cost
and energy of K = 5 kept lobes against K = 1000 [T:1126].

    python benchmarks/feather_throughput.py [--n 2048] [--repeats 3]

No packaged program implements Padrón's model (the thesis' Mitsuba 0.6 plugin is not public), so the
reference is the hair BCSDF the thesis compares with ("only hair barbs", Fig. 5.8 [T:1073]): our
``chiang_hair`` (d'Eon/Chiang lobes, closed form). Timed on ``--n`` random pairs (wi upper hemisphere,
wo the whole sphere), float32, one JAX CPU device, best of ``--repeats`` after a warm-up whose time
(trace + compile + first run) is printed. The lobe-count part: Fig. 5.7's barb (e_b = 1.6, medulla
r = 0.6 at (-0.1, 0.1), sigma_a = (0.133, 1.967, 2.1), white medulla) at theta_i = 45 deg: the
h-averaged energy of the kept lobes over 4096 offsets for K = 5 (16 tracer events) and K = 1000 (1000
events), and feather_fiber.eval's time for both. The masking part: the analytic two-scale masking per
direction (``feather.transmission`` in the batch above) against the Monte Carlo reference
(``flatland.masking_fraction`` for both barbule rows, then ``flatland.vane``) at 2^18 rays per scale, a
binomial standard error of about 1e-3. Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import first_and_best as best, upper_hemisphere_pairs  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=2048)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    import jax
    import jax.numpy as jnp

    from appearance_jax.bcsdf import chiang
    from appearance_jax.bcsdf import feather_fiber as ff
    from appearance_jax.bsdf import feather
    from appearance_jax.core.frame import fiber_direction
    from appearance_jax.core.vec import Vec3

    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__}, "
          f"{jax.devices()[0].device_kind}; n = {args.n:,} pairs, float32")
    wi_np, wo_np = upper_hemisphere_pairs(args.n)
    wo_np[2] *= np.where(np.arange(args.n) % 2 == 0, 1.0, -1.0).astype(np.float32)  # both sides of the vane
    wi, wo = (Vec3(*(jnp.asarray(a) for a in w)) for w in (wi_np, wo_np))
    key = jax.random.key(0)
    p = feather.Params()
    barb = ff.Params(eccentricity=1.6, medulla=True, medulla_y=-0.1, medulla_z=0.1)
    hair = chiang.Params()
    block = lambda out: jax.block_until_ready(out)  # noqa: E731
    cases = [
        ("feather.eval (n_h 16)", lambda: block(feather.eval(p, wi, wo))),
        ("feather.eval (n_h 4)", lambda: block(feather.eval(p.replace(n_h=4), wi, wo))),
        ("feather.sample (one offset)", lambda: block(feather.sample(p, wi, key))),
        ("feather.sample_events", lambda: block(feather.sample_events(p, wi, key))),
        ("feather.transmission", lambda: block(feather.transmission(p, wi))),
        ("feather_fiber.eval (barb, n_h 32)", lambda: block(ff.eval(barb, wi, wo))),
        ("feather_fiber.sample (barb)", lambda: block(ff.sample(barb, wi, key))),
        ("chiang_hair.eval", lambda: block(chiang.eval(hair, wi, wo))),
        ("chiang_hair.sample", lambda: block(chiang.sample(hair, wi, key))),
    ]
    rates = {}
    for name, fn in cases:
        try:
            first, t = best(fn, args.repeats)
        except Exception as exc:  # report and go on
            print(f"{name:40s} failed: {type(exc).__name__}: {str(exc)[:120]}")
            continue
        rates[name] = args.n / t
        print(f"{name:40s} {args.n / t / 1e3:10.2f} k/s   first call {first:6.2f} s")
    ref = rates.get("chiang_hair.eval")
    if ref:
        for name, r in rates.items():
            print(f"  {name:40s} / chiang_hair.eval = {r / ref:.4g}")

    # the analytic masking vs the Monte Carlo reference at a 1e-3 standard error [T:1083-1085]
    from appearance_jax.flatland import ellipse_row, masking_fraction
    from appearance_jax.flatland.vane import vane_masking

    R = np.asarray(feather._frames(p))
    row = ellipse_row(1.0 + float(p.delta_bb), 0.5, 0.5 * float(p.e_bb))
    views = [np.array([0.3, 0.2, 0.9327379]), np.array([-0.5, 0.4, 0.7681146])]
    rays = 2**18  # binomial standard error <= 0.5 / sqrt(rays) ~ 1e-3

    def mc(w, key):
        cover = [float(masking_fraction(row, Vec3(0.0, (R[j] @ w)[1], abs((R[j] @ w)[2])), key, rays)[0])
                 for j in (1, 2)]
        r = vane_masking((w[1], w[2]), float(p.e_b), float(p.l_bb), float(p.theta_bb), cover[0], cover[1], key,
                         n_rays=rays, barb_offsets=False)
        return float(r.weights[3])

    mc(views[0], jax.random.PRNGKey(0))  # compile
    t0 = time.perf_counter()
    for i, w in enumerate(views):
        mc(w, jax.random.PRNGKey(i + 1))
    t_mc = (time.perf_counter() - t0) / len(views)
    t_an = 1.0 / rates["feather.transmission"] if "feather.transmission" in rates else float("nan")
    print(f"masking per direction: analytic {t_an * 1e6:.1f} us (exact; batch of {args.n}), Monte Carlo reference "
          f"{t_mc * 1e3:.0f} ms at {rays} rays per scale (se ~ 1e-3): {t_mc / t_an:.0f}x")

    # K = 5 vs K = 1000 lobes [T:1126]
    h = jnp.linspace(-1.0, 1.0, 4098)[1:-1].astype(jnp.float32)
    w45 = fiber_direction(jnp.float32(0.7853982), jnp.float32(0.0))
    small = jnp.asarray(wi_np[:, :256])
    wi_k, wo_k = Vec3(*small), Vec3(*jnp.asarray(wo_np[:, :256]))
    for k, events in ((5, 16), (1000, 1000)):
        q = barb.replace(n_lobes=k, max_events=events)
        t0 = time.perf_counter()
        lob = ff.lobes(q, w45, h)
        kept = np.asarray(lob.amplitude).sum(0).mean(0)
        t_l = time.perf_counter() - t0
        first, t = best(lambda: block(ff.eval(q, wi_k, wo_k)), args.repeats)
        print(f"K = {k:4d} ({events} events): kept energy (R, G, B) {np.round(kept, 5)}, discarded "
              f"{np.round(np.asarray(lob.discarded).mean(0), 6)}; lobes of 4096 offsets {t_l:.2f} s; "
              f"eval of 256 pairs {t * 1e3:.1f} ms (first call {first:.2f} s)")


if __name__ == "__main__":
    main()
