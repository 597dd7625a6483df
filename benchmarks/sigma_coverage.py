"""Coverage of the fit's 1-sigma under residuals correlated within each incidence direction.

    python3 benchmarks/sigma_coverage.py [--realisations 100] [--bootstrap-realisations 40] [--replicates 32]
    python3 benchmarks/sigma_coverage.py --cases [--replicates 64]   # the three example tables instead

A rough_conductor (alpha = 0.2, specular_reflectance = 0.9/0.8/0.7, eta and k fixed) is
sampled on an in-plane grid of 26 incidences (theta_i = 0..75 deg step 3) x 33 signed theta_o
(-80..80 deg step 5), RGB. Every realisation multiplies it by (1 + EPS g) with an error field g
that is a random quadratic in theta_o per incidence and band (Legendre coefficients ~ N(0, 1),
independent between incidences: a per-incidence calibration / placement error that is smooth
along theta_o), then adds NOISE iid relative noise. The field has zero mean, so the generating
parameters are the truth. All realisations are fitted in one ``fit_batch``; the bootstrap
refits of the first realisations run in one more vmapped solve (``BatchFitResult.bootstrap``).

Prints, per sigma kind, the fraction of (realisation, parameter) pairs with |x - truth| < sigma
and its binomial standard error (the 4 parameters of one realisation are correlated, so the
error is computed from the number of realisations: an upper bound). 0.683 is honest.
"""

from __future__ import annotations

import argparse

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from appearance_jax import registry  # noqa: E402
from appearance_jax.fit.solve import fit_batch  # noqa: E402
from appearance_jax.fit.tables.grids import in_plane_angles  # noqa: E402
from appearance_jax.fit.tables.table import Table  # noqa: E402

EPS, NOISE = 0.04, 0.004
TRUE_X = np.array([0.2, 0.9, 0.8, 0.7])  # alpha, specular_reflectance R, G, B


def error_fields(table: Table, n: int, n_bands: int, rng) -> np.ndarray:
    """(n, N, n_bands) fields: per incidence and band a0 + a1 P1(u) + a2 P2(u), u = theta_o / 80 deg."""
    u = table.signed_theta_o() / np.deg2rad(80.0)
    legendre = np.polynomial.legendre.legvander(u, 2)  # (N, 3): P0, P1, P2
    incidences, which = np.unique(table.theta_i, return_inverse=True)
    coef = rng.standard_normal((n, incidences.size, n_bands, 3))
    return np.sum(coef[:, which.ravel()] * legendre[None, :, None, :], axis=-1)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--realisations", type=int, default=100)
    ap.add_argument("--bootstrap-realisations", type=int, default=40)
    ap.add_argument("--replicates", type=int, default=32)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--cases", action="store_true", help="fit the metal, plastic and fabric example tables")
    ap.add_argument("--only", nargs="*", default=None, help="with --cases: these titles (metal, plastic, fabric)")
    a = ap.parse_args(argv)
    if a.cases:
        return cases(a.replicates, a.only)
    model = registry.get("rough_conductor")
    ti, to = in_plane_angles(np.arange(0, 76, 3), np.arange(-80, 81, 5))
    table = Table.in_plane(ti, to, np.ones((ti.size, 3)), source="correlated in-plane")
    wi, wo = table.directions()
    truth = model.Params(alpha=TRUE_X[0], specular_reflectance=tuple(TRUE_X[1:]))
    f = np.broadcast_to(np.asarray(model.eval(truth, wi, wo), np.float64), table.values.shape)
    rng = np.random.default_rng(a.seed)
    K = a.realisations
    values = f * (1 + EPS * error_fields(table, K, 3, rng)) * (1 + NOISE * rng.standard_normal((K,) + f.shape))
    res = fit_batch(model, table, values, init=model.Params(alpha=0.3), fix=["eta", "k"])
    good = res.converged
    err = np.abs(res.x - TRUE_X)[good]
    rows = [("iid", res.sigma_iid[good]), ("hc1 (entry sandwich)", res.sigma_hc1[good]),
            ("cr1 (cluster sandwich)", res.sigma_cr1[good]), ("cr3 (cluster sandwich, jackknife)", res.sigma_sandwich[good]), (f"default ({res.sigma_method})", res.sigma[good])]
    kb = min(a.bootstrap_realisations, K)
    boot = None
    if kb > 0:
        boot = res.bootstrap(a.replicates, seed=a.seed, items=range(kb))
    print(f"rough_conductor, {table.n_samples} directions x 3 bands, {res.n_clusters} incidence clusters, "
          f"EPS = {EPS}, NOISE = {NOISE}; {int(good.sum())} of {K} fits converged")
    print("| sigma | realisations | 1-sigma coverage | binomial s.e. | median sigma(alpha) |")
    print("|---|---|---|---|---|")
    for name, s in rows:
        n = s.shape[0]
        print(f"| {name} | {n} | {np.mean(err < s):.3f} | {np.sqrt(0.683 * 0.317 / n):.3f} | {np.median(s[:, 0]):.3g} |")
    if boot is not None:
        ok = good[:kb]
        s = boot["sigma"][ok]
        e = np.abs(res.x[:kb] - TRUE_X)[ok]
        lo, hi = boot["interval68"][ok][..., 0], boot["interval68"][ok][..., 1]
        n = s.shape[0]
        se = np.sqrt(0.683 * 0.317 / n)
        print(f"| bootstrap std, B = {a.replicates} | {n} | {np.mean(e < s):.3f} | {se:.3f} | {np.median(s[:, 0]):.3g} |")
        inside = np.mean((lo <= TRUE_X) & (TRUE_X <= hi))
        print(f"| bootstrap 68 % percentile interval | {n} | {inside:.3f} | {se:.3f} | |")
        print(f"bootstrap refits out of steps: {int(boot['not_converged'].sum())}, non-finite: "
              f"{int(boot['failed'].sum())}, of {kb * a.replicates}")


CASES = (  # (title, model, table, fix): proxies on an in-plane grid with 26 incidences (theta_i step 3 deg)
    ("metal", "rough_conductor", "proxy:ss440", None),
    ("plastic", "rough_plastic", "proxy:specular-blue-phenolic", {"eta": 1.5}),
    ("fabric", "rough_plastic", "data/tables/merl-proxy-red-fabric-in-plane.csv", {"eta": 1.5}),
)


def cases(replicates: int, only=None):
    """The iid, sandwich and bootstrap sigma and the flagged degeneracies of three example fits
    (``replicates`` = 0: no bootstrap)."""
    from appearance_jax.fit import fit, read_table
    from appearance_jax.fit.tables.proxy import proxy_table

    for title, model, source, fix in CASES:
        if only and title not in only:
            continue
        if source.startswith("proxy:"):
            table = proxy_table(source[6:], "in_plane", theta_i_deg=np.arange(0, 76, 3))
        else:
            table = read_table(source)
        res = fit(model, table, fix=fix, bootstrap=replicates)
        print(f"\n## {title}: {model} on {table.source}, fix {fix}")
        print(res.summary())
        print("| parameter | value | iid | hc1 | cr1 | cr3 | bootstrap | default |")
        print("|---|---|---|---|---|---|---|---|")
        for i, lab in enumerate(res.labels):
            cells = ["-" if s is None else f"{s[i]:.2g}" for s in (res.sigma_iid, res.sigma_hc1, res.sigma_cr1,
                                                                   res.sigma_sandwich, res.sigma_bootstrap)]
            d = "at bound" if lab in res.at_bound else f"{res.sigma[i]:.2g}"
            print(f"| {lab} | {res.x[i]:.4g} | " + " | ".join(cells) + f" | {d} |")


if __name__ == "__main__":
    main()
