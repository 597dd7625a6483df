"""Write the precomputed coat tables of rough_plastic (data/coat_tables/coat_tables.npz).

    python3 tools/make_coat_tables.py                 # compute and write the file (~1 min)
    python3 tools/make_coat_tables.py --check 2000    # measure the interpolation error

For each distribution (ggx, beckmann) the coat integrals of the ``"accurate"`` scheme
(``interface_integrals.tabulate``: 64 Chebyshev coefficients of T in sqrt(mu), and R_int)
are computed in float64 at the nodes of ``coat_tables.grid()`` and turned into the
coefficients of the not-a-knot tensor-product cubic B-spline through them
(``coat_tables.prefilter_matrix`` along each axis), stored as float32. Deterministic: the
same code gives the same arrays (the zip entries carry a fixed date, so the same bytes).

``--check N`` compares the shipped file's interpolant against the quadrature at N random
parameter sets (alpha log-uniform, eta half uniform on [1, 3], half 1 + 10^U(-9, -0.3))
plus the grid's corners and cell midpoints near eta = 1, at 600 cosines mu in [1e-6, 1]
(dense near 0): the max |error| of T (through the per-direction lookup of eval) against the
accurate scheme's own Chebyshev interpolant and against the direct quadrature, of R_int, and of the derivatives of R_int
and of T(mu) w.r.t. alpha and eta against the quadrature's.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import zipfile

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
OUT = ROOT / "data" / "coat_tables" / "coat_tables.npz"
CHUNK = 64  # parameter sets per quadrature call (memory)


def _jax():
    import jax

    jax.config.update("jax_enable_x64", True)
    return jax


def accurate_values(kind, alpha, eta):
    """(N, 65) float64: the accurate scheme's Chebyshev coefficients of T, then R_int."""
    jax = _jax()
    from appearance_jax.microfacet import interface_integrals as ii

    f = jax.jit(lambda a, e: ii.tabulate(kind, a, e, "accurate"))
    out = []
    for s in range(0, len(alpha), CHUNK):
        T, R = f(alpha[s:s + CHUNK], eta[s:s + CHUNK])
        out.append(np.concatenate([np.asarray(T), np.asarray(R)[:, None]], axis=1))
    return np.concatenate(out)


def compute():
    """{kind: (N_U + 2, N_W + 2, 65) float32 B-spline coefficients} and the grid record."""
    from appearance_jax.microfacet import coat_tables as ct

    alpha, eta = ct.grid()
    A, E = np.meshgrid(alpha, eta, indexing="ij")
    Pu, Pw = ct.prefilter_matrix(ct.N_U), ct.prefilter_matrix(ct.N_W)
    out = {"grid": ct._grid_record()}
    for kind in ct.KINDS:
        V = accurate_values(kind, A.ravel(), E.ravel()).reshape(ct.N_U, ct.N_W, ct.N_VALUES)
        C = np.einsum("ai,bj,ijk->abk", Pu, Pw, V)
        out[kind] = C.astype(np.float32)
        print(f"{kind}: {A.size} parameter sets", flush=True)
    return out


def write_npz(path, arrays):
    """np.savez_compressed with fixed zip dates (byte-reproducible)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for name, a in arrays.items():
            info = zipfile.ZipInfo(name + ".npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            with z.open(info, "w") as f:
                np.lib.format.write_array(f, np.ascontiguousarray(a), allow_pickle=False)


def sample(n, seed=0):
    """Random (alpha, eta) with the grid corners and near-1 cell midpoints appended."""
    from appearance_jax.microfacet import coat_tables as ct

    rng = np.random.default_rng(seed)
    lo, hi = np.log(ct.ALPHA_RANGE[0]), np.log(ct.ALPHA_RANGE[1])
    alpha = np.exp(rng.uniform(lo, hi, n))
    eta = np.where(np.arange(n) % 2 == 0, rng.uniform(1.0, 3.0, n), 1.0 + 10.0 ** rng.uniform(-9.0, -0.3, n))
    ga, ge = ct.grid()
    corners = [(a, e) for a in ct.ALPHA_RANGE for e in (1.0, 1.0 + 1e-6, 1.0 + 1e-3, 3.0)]
    mids = [(np.sqrt(ga[i] * ga[i + 1]), 0.5 * (ge[j] + ge[j + 1])) for i in (0, 5, 20, ct.N_U - 2)
            for j in range(0, ct.N_W - 1, 3)]
    extra = np.array(corners + mids)
    return np.concatenate([alpha, extra[:, 0]]), np.concatenate([eta, extra[:, 1]])


def check(n):
    jax = _jax()
    import jax.numpy as jnp

    from appearance_jax.microfacet import coat_tables as ct
    from appearance_jax.microfacet import interface_integrals as ii

    alpha, eta = sample(n)
    mu = jnp.asarray(np.concatenate([np.geomspace(1e-6, 0.05, 300), np.linspace(0.05, 1.0, 300)]))
    # T(mu) and R_int, and their derivatives w.r.t. (alpha, eta), for one parameter set
    def quantities(scheme, a, e):
        def f(a, e):
            tab = ct.tabulate(kind, a, e, scheme)
            return ct.transmittance_at(scheme, tab, mu), tab.internal_reflectance

        one, zero = jnp.ones_like(a), jnp.zeros_like(a)
        (T, R), (dT, dR) = jax.jvp(f, (a, e), (one, zero))
        _, (eT, eR) = jax.jvp(f, (a, e), (zero, one))
        return T, R, dT, dR, eT, eR

    for kind in ct.KINDS:
        # per item of the vmap one parameter set: T through the resampled lookup, as in eval
        pre = jax.jit(jax.vmap(lambda a, e: quantities("precomputed", a, e)))
        acc = jax.jit(jax.vmap(lambda a, e: quantities("accurate", a, e)))
        direct = jax.jit(jax.vmap(lambda a, e: ii.interface_transmittance(kind, a, e, mu)))
        worst = {}
        for s in range(0, len(alpha), CHUNK):
            a, e = jnp.asarray(alpha[s:s + CHUNK]), jnp.asarray(eta[s:s + CHUNK])
            P, Q, D = pre(a, e), acc(a, e), np.asarray(direct(a, e))
            names = ("T", "R_int", "dT/dalpha", "dR_int/dalpha", "dT/deta", "dR_int/deta")
            for name, p, q in zip(names, P, Q):
                err = np.abs(np.asarray(p) - np.asarray(q))
                scale = np.maximum(np.abs(np.asarray(q)), 1.0)  # derivatives: relative above 1
                rel = err / scale if name.startswith("d") else err
                i = np.unravel_index(np.argmax(rel), rel.shape)
                if rel[i] > worst.get(name, (0.0,))[0]:
                    where = f"alpha {alpha[s + i[0]]:.3g} eta {eta[s + i[0]]:.9g}" + (
                        f" mu {float(mu[i[1]]):.2e}" if len(i) > 1 else "")
                    worst[name] = (float(rel[i]), where)
            err = np.abs(np.asarray(P[0]) - D)
            i = np.unravel_index(np.argmax(err), err.shape)
            if err[i] > worst.get("T vs direct", (0.0,))[0]:
                worst["T vs direct"] = (float(err[i]), f"alpha {alpha[s + i[0]]:.3g} eta {eta[s + i[0]]:.9g} "
                                                       f"mu {float(mu[i[1]]):.2e}")
        print(f"{kind}: {len(alpha)} parameter sets x {mu.size} cosines "
              "(derivatives: |error| / max(1, |quadrature's|))")
        for name, (v, where) in worst.items():
            print(f"  {name:14s} max {v:.2e}  at {where}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", type=int, metavar="N", help="measure the shipped file's error at N random sets")
    ap.add_argument("--out", type=pathlib.Path, default=OUT)
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT / "src"))
    if args.check:
        check(args.check)
        return
    write_npz(args.out, compute())
    print(f"wrote {args.out} ({args.out.stat().st_size / 1e6:.2f} MB)")


if __name__ == "__main__":
    main()
