"""Issue 21's first fitting stand-in: recover the barbule geometry (delta_bb, e_bb, l_bb, theta_bb) of a
feather vane from backlit transmission curves made by the Monte Carlo reference, not by the analytic code.

    python3 tools/feather_masking_fit.py [--rays 65536] [--seed 0]

The setting of Fig. 5.12 [T:1100-1108]: a vane lit from behind, photographed while it turns, loses its
transparency. The data: w_t, the fraction of the light passing straight through, at 8 tilts (0-70 deg)
about three axes (the barb axis, across it, and halfway), made by the two-scale Monte Carlo reference
(each barbule row's coverage by :func:`appearance_jax.flatland.masking_fraction`, then the vane by
:func:`appearance_jax.flatland.vane.vane_masking`, ``--rays`` rays each), with their binomial standard
errors. The fit: :func:`appearance_jax.bsdf.feather.transmission` (the analytic two-scale masking) with
e_b known (1.6, the barb's cross-section is measurable) and delta_bb, e_bb - 1, l_bb in log space and
theta_bb through a logistic onto (0, pi/2), the library's Levenberg-Marquardt on the whitened residuals
from a start off in every parameter. 1-sigma errors and correlations from (J^T J)^-1 at the optimum.

Prints the truth, the start, the fit with 1-sigma and z, chi^2 / dof and the correlations above 0.8, and the
times. Not a test (tests/flatland/test_vane.py runs it with fewer rays).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

TRUTH = dict(delta_bb=0.6, e_bb=1.4, l_bb=0.8, theta_bb=0.35)
START = dict(delta_bb=1.2, e_bb=1.1, l_bb=1.5, theta_bb=0.15)
FREE = tuple(TRUTH)
E_B = 1.6
TILTS = np.radians(np.arange(0.0, 71.0, 10.0))
AXES = np.radians([90.0, 0.0, 45.0])  # azimuth of the tilt: about the barb axis, across it, halfway


def views():
    """(theta, phi) of the viewer (= the light's straight path) for every tilt and axis."""
    th, ph = np.meshgrid(TILTS, AXES, indexing="ij")
    return th.ravel(), ph.ravel()


def mc_transmission(rays=2**16, seed=0):
    """w_t and its standard error at :func:`views` by the two-scale Monte Carlo reference."""
    import jax

    from appearance_jax.bsdf import feather
    from appearance_jax.core.frame import spherical_direction
    from appearance_jax.core.vec import Vec3
    from appearance_jax.flatland import ellipse_row, masking_fraction
    from appearance_jax.flatland.vane import vane_masking

    p = feather.Params(e_b=E_B, **TRUTH)
    R = np.asarray(feather._frames(p))
    row = ellipse_row(1.0 + TRUTH["delta_bb"], 0.5, 0.5 * TRUTH["e_bb"])
    key = jax.random.PRNGKey(seed)
    wt, se = [], []
    for i, (th, ph) in enumerate(zip(*views())):
        w = np.array([float(c) for c in spherical_direction(th, ph)])
        cover = []
        for j in (1, 2):
            loc = R[j] @ w
            f, _, trunc = masking_fraction(row, Vec3(0.0, loc[1], abs(loc[2])), jax.random.fold_in(key, 3 * i + j),
                                           rays)
            if float(trunc) > 0:
                raise RuntimeError(f"view {np.degrees([th, ph])} deg: the barbule row is seen too close to its plane")
            cover.append(float(f))
        r = vane_masking((w[1], w[2]), E_B, TRUTH["l_bb"], TRUTH["theta_bb"], cover[0], cover[1],
                         jax.random.fold_in(key, 3 * i), n_rays=rays, barb_offsets=False)
        wt.append(float(r.weights[3]))
        se.append(float(r.stderr[3]))
    return np.asarray(wt), np.asarray(se)


def run(rays=2**16, seed=0, verbose=True):
    import jax
    import jax.numpy as jnp

    from appearance_jax.bsdf import feather
    from appearance_jax.core.frame import spherical_direction
    from appearance_jax.core.params import replace_unchecked
    from appearance_jax.fit.solve.lm import levenberg_marquardt

    t0 = time.perf_counter()
    wt, se = mc_transmission(rays, seed)
    t_data = time.perf_counter() - t0
    th, ph = views()
    wi = spherical_direction(jnp.asarray(th), jnp.asarray(ph))
    base = feather.Params(e_b=E_B)
    sigma = np.maximum(se, 0.5 / rays)  # a closed vane (w_t = 0) has se = 0

    def x_of(z):
        return (jnp.exp(z[0]), 1.0 + jnp.exp(z[1]), jnp.exp(z[2]), 0.5 * math.pi * jax.nn.sigmoid(z[3]))

    def residual(z, data):
        q = replace_unchecked(base, **dict(zip(FREE, x_of(z))))
        return (feather.transmission.kernel(q, wi) - data["wt"]) / data["sigma"]

    s = START
    z0 = jnp.asarray([math.log(s["delta_bb"]), math.log(s["e_bb"] - 1.0), math.log(s["l_bb"]),
                      math.log(s["theta_bb"] / (0.5 * math.pi - s["theta_bb"]))])
    data = dict(wt=jnp.asarray(wt), sigma=jnp.asarray(sigma))
    t1 = time.perf_counter()
    z, loss, steps, ok = jax.block_until_ready(jax.jit(lambda z, d: levenberg_marquardt(residual, z, d, max_steps=200))(
        z0, data))
    t_fit = time.perf_counter() - t1
    J = np.asarray(jax.jit(jax.jacfwd(residual))(z, data))
    x = np.asarray([float(v) for v in x_of(z)])
    dxdz = np.asarray(jax.jacfwd(lambda v: jnp.stack(x_of(v)))(z))
    cov = dxdz @ np.linalg.pinv(J.T @ J) @ dxdz.T
    err = np.sqrt(np.diag(cov))
    corr = cov / np.outer(err, err)
    dof = J.shape[0] - J.shape[1]
    truth = np.asarray([TRUTH[k] for k in FREE])
    out = dict(labels=FREE, x=x, sigma=err, truth=truth, corr=corr, chi2_dof=2 * float(loss) / dof,
               steps=int(steps), converged=bool(ok), t_data=t_data, t_fit=t_fit)
    if verbose:
        print(f"{th.size} backlit views (8 tilts x 3 axes), {rays} rays each: {t_data:.1f} s for the Monte Carlo "
              f"data, {t_fit:.1f} s for the fit ({int(steps)} LM steps, converged {bool(ok)}), "
              f"chi2/dof = {out['chi2_dof']:.3f}")
        for k, name in enumerate(FREE):
            print(f"  {name:9s} truth {truth[k]:.4f}  start {START[name]:.4f}  fit {x[k]:.4f} +- {err[k]:.4f}  "
                  f"(z = {(x[k] - truth[k]) / err[k]:+.2f})")
        for i in range(len(FREE)):
            for j in range(i):
                if abs(corr[i, j]) > 0.8:
                    print(f"  correlated: {FREE[i]} ~ {FREE[j]}: {corr[i, j]:+.3f}")
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rays", type=int, default=2**16)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    import jax

    jax.config.update("jax_enable_x64", True)
    run(args.rays, args.seed)


if __name__ == "__main__":
    main()
