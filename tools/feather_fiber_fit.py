"""Issue 21's second fitting stand-in: recover a barb's cortex absorption sigma_a (RGB) and medulla albedo d_m
(RGB) from lat-long tables of the fibre BCSDF, and report what the tables cannot tell apart.

    python3 tools/feather_fiber_fit.py [--n-h-data 1024] [--n-h 256] [--free-medulla-size] [--quick]

Padrón hand-tuned his parameters and fitted nothing [T:1132]. The stand-in: ``feather_fiber.eval`` of
Fig. 5.7's barb (e = 1.6, medulla r = 0.6 at (-0.1, 0.1), eta = 1.53, beta = 0.13 / 0.12) with a blue
medulla d_m = (0.3, 0.5, 0.9) and sigma_a = (0.133, 1.967, 2.1), on lat-long grids of the light direction
(theta_o x phi_o) at theta_i = 15, 45 and 75 deg (phi_i = 0), estimated with ``--n-h-data`` offsets and
other keys than the fit's (independent Monte Carlo noise; its standard error is the table's sigma).
The fit evaluates the model with ``--n-h`` offsets and one fixed key at every iterate (common random
numbers) and minimises the residuals, whitened by the table's and the model's standard errors, with the library's Levenberg-Marquardt
(:func:`appearance_jax.fit.solve.lm.levenberg_marquardt`) from a start off in every parameter;
sigma_a is fitted in log space, d_m through a logistic. ``--free-medulla-size`` also frees the medulla's
radius (a_m = b_m) to show the flat direction sigma_a / d_m / size. The 1-sigma errors and correlations
come from the Gauss-Newton covariance (J^T J)^-1 at the optimum (whitened residuals: chi^2 / dof ~ 1
when the model's own noise is small against the table's); the flattest direction is its eigenvector of
largest scaled variance.

Prints the truth, the start, the fit with 1-sigma, chi^2 / dof, the correlations above 0.8 and the
flattest direction, and the times. Not a test (tests/bcsdf/test_feather_fiber_fit.py runs --quick).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

TRUTH = dict(sigma_a=(0.133, 1.967, 2.1), medulla_albedo=(0.3, 0.5, 0.9), medulla_r=0.6)
START = dict(sigma_a=(0.3, 1.2, 3.0), medulla_albedo=(0.6, 0.3, 0.6), medulla_r=0.45)
THETA_I = (15.0, 45.0, 75.0)


def base_params(n_h):
    from appearance_jax.bcsdf import feather_fiber as ff

    return ff.Params(eccentricity=1.6, medulla=True, medulla_y=-0.1, medulla_z=0.1, n_h=n_h,
                     sigma_a=TRUTH["sigma_a"], medulla_albedo=TRUTH["medulla_albedo"])


def grid(quick=False):
    """(wi, wo) of the lat-long tables, (3, 1) and (1, K): theta_o x phi_o cell centres for each theta_i
    (phi_i = 0)."""
    import jax.numpy as jnp

    from appearance_jax.core.frame import fiber_direction

    nt, nph = (8, 16) if quick else (12, 24)
    th = (np.arange(nt) + 0.5) / nt * math.pi - 0.5 * math.pi
    ph = (np.arange(nph) + 0.5) / nph * 2 * math.pi - math.pi
    T, P = (a.ravel() for a in np.meshgrid(th, ph, indexing="ij"))
    # incidences (3, 1) against cells (1, K): the fibre traces each incidence once
    wi = fiber_direction(jnp.asarray(np.radians(THETA_I))[:, None], jnp.zeros((3, 1)))
    wo = fiber_direction(jnp.asarray(T)[None, :], jnp.asarray(P)[None, :])
    return wi, wo


def table(n_h_data=256, quick=False, seed=7):
    """The data: eval with n_h_data offsets and key ``seed`` (not the fit's), and its standard error."""
    from appearance_jax.bcsdf import feather_fiber as ff

    wi, wo = grid(quick)
    S, se = ff.eval(base_params(n_h_data), wi, wo, key=seed)
    S, se = np.asarray(S), np.asarray(se)
    # a floor (0.1 % of the largest value) keeps cells that no offset's lobe reached (se = 0) finite
    return wi, wo, S, np.maximum(se, 1e-3 * S.max())  # (3, K, bands)


def run(n_h_data=1024, n_h=256, free_size=False, quick=False, verbose=True):
    import jax
    import jax.numpy as jnp

    from appearance_jax.bcsdf import feather_fiber as ff
    from appearance_jax.core.params import replace_unchecked
    from appearance_jax.fit.solve.lm import levenberg_marquardt

    t0 = time.perf_counter()
    wi, wo, S, sigma = table(n_h_data, quick)
    t_data = time.perf_counter() - t0
    base = base_params(n_h)
    labels = [f"sigma_a[{c}]" for c in "RGB"] + [f"d_m[{c}]" for c in "RGB"] + (["medulla_r"] if free_size else [])

    def params_of(z):
        q = replace_unchecked(base, sigma_a=jnp.exp(z[:3]), medulla_albedo=jax.nn.sigmoid(z[3:6]))
        if free_size:
            r = 0.05 + 0.6 * jax.nn.sigmoid(z[6])  # (0.05, 0.65): inside the cortex at (-0.1, 0.1), e = 1.6
            q = replace_unchecked(q, medulla_a=r, medulla_b=r)
        return q

    def x_of(z):
        x = np.concatenate([np.exp(z[:3]), 1 / (1 + np.exp(-z[3:6]))])
        return np.append(x, 0.05 + 0.6 / (1 + np.exp(-z[6]))) if free_size else x

    def residual(z, data):
        model = ff.eval.kernel(params_of(z), wi, wo, key=3)[0]
        return ((model - data["S"]) / data["sigma"]).ravel()

    logit = lambda v: np.log(np.asarray(v) / (1 - np.asarray(v)))  # noqa: E731
    z0 = np.concatenate([np.log(START["sigma_a"]), logit(START["medulla_albedo"])])
    if free_size:
        z0 = np.append(z0, logit((START["medulla_r"] - 0.05) / 0.6))
    # the fit's model is a Monte Carlo estimate too (n_h offsets, one key): its standard error at the
    # start joins the table's in the whitening (held fixed during the fit), or the covariance below
    # would be that of a noiseless model and too small
    se_model = np.asarray(ff.eval(params_of(jnp.asarray(z0)), wi, wo, key=3)[1])
    sigma = np.sqrt(sigma**2 + se_model**2)
    data = dict(S=jnp.asarray(S), sigma=jnp.asarray(sigma))
    t1 = time.perf_counter()
    solve = jax.jit(lambda z, d: levenberg_marquardt(residual, z, d, max_steps=60))
    z, loss, steps, ok = jax.block_until_ready(solve(jnp.asarray(z0), data))
    t_fit = time.perf_counter() - t1
    z = np.asarray(z)
    J = np.asarray(jax.jit(jax.jacfwd(residual))(jnp.asarray(z), data))
    x = x_of(z)
    # the covariance in x: dx/dz is diagonal (the transforms act per parameter)
    dxdz = np.concatenate([np.exp(z[:3]), np.exp(-z[3:6]) / (1 + np.exp(-z[3:6])) ** 2])
    if free_size:
        dxdz = np.append(dxdz, 0.6 * np.exp(-z[6]) / (1 + np.exp(-z[6])) ** 2)
    cov_z = np.linalg.pinv(J.T @ J)
    cov = cov_z * np.outer(dxdz, dxdz)
    err = np.sqrt(np.diag(cov))
    corr = cov / np.outer(err, err)
    dof = J.shape[0] - J.shape[1]
    chi2 = 2 * float(loss) / dof
    # the flattest direction: the largest-variance eigenvector of the covariance in relative units
    rel = cov / np.outer(x, x)
    w, v = np.linalg.eigh(rel)
    flat = v[:, -1] * np.sign(v[np.argmax(np.abs(v[:, -1])), -1])
    truth = np.concatenate([TRUTH["sigma_a"], TRUTH["medulla_albedo"]] + ([[TRUTH["medulla_r"]]] if free_size else []))
    out = dict(labels=labels, x=x, sigma=err, truth=truth, corr=corr, chi2_dof=chi2, steps=int(steps),
               converged=bool(ok), flat=flat, flat_rel_sigma=float(np.sqrt(w[-1])), t_data=t_data, t_fit=t_fit)
    if verbose:
        print(f"tables: {S.shape[0] * S.shape[1]} cells x 3 bands at theta_i = {THETA_I} deg, n_h = {n_h_data} (key 7); "
              f"fit n_h = {n_h} (key 3); {t_data:.1f} s for the tables, {t_fit:.1f} s for the fit "
              f"({int(steps)} LM steps, converged {bool(ok)}), chi2/dof = {chi2:.3f}")
        for k, name in enumerate(labels):
            print(f"  {name:12s} truth {truth[k]:.4f}  fit {x[k]:.4f} +- {err[k]:.4f}  "
                  f"(z = {(x[k] - truth[k]) / err[k]:+.2f})")
        for i in range(len(labels)):
            for j in range(i):
                if abs(corr[i, j]) > 0.8:
                    print(f"  correlated: {labels[i]} ~ {labels[j]}: {corr[i, j]:+.3f}")
        print("  flattest direction (relative units, 1-sigma {:.3f}): ".format(out["flat_rel_sigma"])
              + ", ".join(f"{n} {c:+.2f}" for n, c in zip(labels, flat) if abs(c) > 0.1))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n-h-data", type=int, default=1024)
    ap.add_argument("--n-h", type=int, default=256)
    ap.add_argument("--free-medulla-size", action="store_true")
    ap.add_argument("--quick", action="store_true", help="8 x 16 cells per theta_i")
    args = ap.parse_args()
    import jax

    jax.config.update("jax_enable_x64", True)
    run(args.n_h_data, args.n_h, args.free_medulla_size, args.quick)


if __name__ == "__main__":
    main()
