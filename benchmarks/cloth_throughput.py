"""Throughput of Sadeghi's cloth BRDF eval, and the cost of this library's energy decisions.

    python benchmarks/cloth_throughput.py [--n 100000] [--repeats 5] [--devices 2]

No peer implements the model (Mitsuba 3 and pbrt-v4 have no microcylinder cloth; the thesis'
own renderer is not public), so the same run times ``rough_conductor`` on the same pairs for
context, and the ratio printed is cloth / rough_conductor. Cloth evaluates J T tangent samples
per pair (the thread BCSDF, masking and reweighting for each), so its cost grows with
``n_samples`` T. Rows: the silk_shot preset (J = 2) at T = 16 and 64, with the defaults and with
:func:`appearance_jax.bsdf.cloth.thesis_form` (the thread energy cap D-C10, the patch gate and
the normalisation floor D-C11 switched off): their difference is what the energy decisions cost.
float32, jit, Vec3-of-arrays; best of ``--repeats`` after a warm-up. Not a test.
"""

from __future__ import annotations

import sys

from _common import best_time, sharded_vec3, throughput_args, upper_hemisphere_pairs


def main() -> int:
    args = throughput_args(__doc__, n=100_000)
    import jax

    from appearance_jax.bsdf import cloth
    from appearance_jax.bsdf import rough_conductor as rc

    wi, wo = (sharded_vec3(v, args.devices) for v in upper_hemisphere_pairs(args.n))

    def rate(kernel, params):
        f = jax.jit(kernel)
        return args.n / best_time(lambda: f(params, wi, wo).block_until_ready(), args.repeats)

    base = rate(rc.eval.kernel, rc.Params(alpha=0.3, eta=(0.18, 0.45, 1.35), k=(3.40, 2.25, 1.80)))
    rows = [("rough_conductor (context)", base)]
    for t in (16, 64):
        p = cloth.PRESETS["silk_shot"].replace(n_samples=t)
        rows.append((f"cloth silk_shot, T = {t}, defaults", rate(cloth.eval.kernel, p)))
        rows.append((f"cloth silk_shot, T = {t}, thesis_form", rate(cloth.eval.kernel, cloth.thesis_form(p))))
    print(f"{args.devices} JAX CPU device(s)")
    print("| BSDF eval | pairs/s | ratio to rough_conductor |")
    print("|---|---|---|")
    for name, r in rows:
        print(f"| {name} | {r:.2e} | {r / base:.2e} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
