"""The precomputed coat tables (microfacet/coat_tables.py): against the accurate quadrature,
gradients, clamping at the grid edges, the per-direction lookup, and the file loader.

The wide sweep of the interpolation error is ``tools/make_coat_tables.py --check N``
(docs/microfacet.md); here a fixed sample with the corners of the domain."""

from __future__ import annotations

import zipfile

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import testing
from appearance_jax.microfacet import coat_tables as ct
from appearance_jax.microfacet import interface_integrals as ii

TOL = 1e-4  # the stated accuracy of T(mu) and R_int against tabulate(..., "accurate")
# cosines: dense near grazing (mu -> 0), normal incidence included
MU = np.concatenate([[0.0, 1e-6, 1e-4, 1e-3], np.geomspace(3e-3, 0.05, 8), np.linspace(0.07, 1.0, 12)])


def _sample(kind):
    """Corners (alpha 1e-3 and 2, eta 1, 1 + 1e-6 and 3: the index-matched kink), a point
    near the Beckmann/GGX tail, and random sets (fixed seed) away from the nodes."""
    rng = np.random.default_rng(7 if kind == "ggx" else 8)
    corners = [(1e-3, 1.0), (1e-3, 1.0 + 1e-6), (1e-3, 3.0), (2.0, 1.0), (2.0, 3.0), (1.84, 2.2), (0.02, 1.0003)]
    rand = list(zip(np.exp(rng.uniform(np.log(1e-3), np.log(2.0), 5)), rng.uniform(1.0, 3.0, 5)))
    a, e = np.array(corners + rand).T
    return jnp.asarray(a), jnp.asarray(e)


@jax.jit
def _pre(alpha, eta):
    """(T (sets, mu) through the per-direction lookup of one set, as eval; the same through the
    Chebyshev series of the batched tables; R_int) for both distributions."""
    out = {}
    for kind in ct.KINDS:
        tab = ct.tabulate(kind, alpha, eta, "precomputed")
        look = jax.vmap(lambda c, r: ct.transmittance_at("precomputed", ii.CoatTables(c, r), jnp.asarray(MU)))
        series = ct.transmittance_at("precomputed", tab, jnp.asarray(MU)[:, None]).T
        out[kind] = (look(tab.transmittance, tab.internal_reflectance), series, tab.internal_reflectance)
    return out


@pytest.mark.parametrize("kind", ["ggx", "beckmann"])
def test_precomputed_matches_accurate_quadrature(kind):
    """T(mu) and R_int within 1e-4 of the accurate scheme at the corners and random sets; the
    resampled lookup and the Chebyshev series agree. A wrong axis, a transposed table or the
    two distributions swapped would be off by 1e-2 or more."""
    alpha, eta = _sample(kind)
    T_look, T_series, R = (np.asarray(x) for x in _pre(alpha, eta)[kind])
    acc = ii.tabulate(kind, alpha, eta, "accurate")
    T_acc = np.asarray(ii.transmittance_at("accurate", acc, jnp.asarray(MU)[:, None])).T
    R_acc = np.asarray(acc.internal_reflectance)
    assert np.max(np.abs(T_look - T_acc)) <= TOL
    assert np.max(np.abs(T_series - T_acc)) <= TOL
    assert np.max(np.abs(R - R_acc)) <= TOL
    # the lookup's resampling alone (same coefficients): <= 5.4e-5 (docs/microfacet.md)
    assert np.max(np.abs(T_look - T_series)) <= 6e-5
    # the other distribution's tables differ from these by far more than the tolerance
    other = "beckmann" if kind == "ggx" else "ggx"
    assert np.max(np.abs(np.asarray(_pre(alpha, eta)[other][2]) - R_acc)) > 100 * TOL


def _quantities(p, kind="ggx", mu=(0.05, 0.4, 0.9)):
    """T at a few cosines and R_int, as one vector, from a dict {alpha, eta}."""
    tab = ct.tabulate(kind, p["alpha"], p["eta"], "precomputed")
    T = ct.transmittance_at("precomputed", tab, jnp.asarray(mu))
    return jnp.concatenate([T, tab.internal_reflectance[None]])


def test_gradients_match_finite_differences():
    """d(T, R_int)/d(alpha, eta) of the spline (C2 in alpha and eta) = its central differences."""
    p = {"alpha": jnp.float64(0.23), "eta": jnp.float64(1.45)}
    testing.assert_gradients(jax.jit(_quantities), p, rtol=1e-6, elementwise=True, name="coat tables")


@pytest.mark.slow  # differentiating the quadrature compiles for ~20 s
def test_gradients_match_the_quadrature():
    """... and are within the measured interpolation error of the quadrature's own derivatives
    (<= 6e-3 absolute for eta >= 1.01, the derivatives being of order 1-10 here)."""
    p = {"alpha": jnp.float64(0.23), "eta": jnp.float64(1.45)}
    jac = jax.jacfwd(_quantities)(p)

    def quad(p):
        tab = ii.tabulate("ggx", p["alpha"], p["eta"], "accurate")
        T = ii.transmittance_at("accurate", tab, jnp.asarray((0.05, 0.4, 0.9)))
        return jnp.concatenate([T, tab.internal_reflectance[None]])

    ref = jax.jit(jax.jacfwd(quad))(p)
    for k in p:
        assert np.max(np.abs(np.asarray(jac[k]) - np.asarray(ref[k]))) <= 6e-3, k
        assert np.max(np.abs(np.asarray(ref[k]))) > 0.05  # the comparison is not between zeros


def test_clamped_outside_the_grid():
    """alpha, eta beyond the grid (Params refuses them; inside a user's jit they can occur)
    give the edge values, finite, with zero gradient outside and finite gradient at the edges."""
    a = jnp.asarray([1e-4, 1e-3, 2.0, 5.0, 0.3, 0.3, 0.3, 0.3])
    e = jnp.asarray([1.5, 1.5, 1.5, 1.5, 0.8, 1.0, 3.0, 4.0])
    tab = ct.interpolate("ggx", a, e)
    T, R = np.asarray(tab.transmittance), np.asarray(tab.internal_reflectance)
    assert np.all(np.isfinite(T)) and np.all(np.isfinite(R))
    for i, j in ((0, 1), (3, 2), (4, 5), (7, 6)):
        np.testing.assert_array_equal(T[i], T[j])
        assert R[i] == R[j]
    g = jax.vmap(jax.grad(lambda a, e: ct.interpolate("ggx", a, e).internal_reflectance, argnums=(0, 1)))(a, e)
    ga, ge = (np.asarray(x) for x in g)
    assert np.all(np.isfinite(ga)) and np.all(np.isfinite(ge))
    assert ga[0] == 0 and ga[3] == 0 and ge[4] == 0 and ge[7] == 0
    assert ga[1] != 0 and ga[2] != 0 and ge[6] != 0


def test_float32_and_vmap():
    """float32 in, float32 out, within 1e-5 of float64; vmap = the batched call."""
    a, e = jnp.asarray([0.01, 0.3, 1.2]), jnp.asarray([1.1, 1.5, 2.7])
    t64 = ct.interpolate("beckmann", a, e)
    t32 = ct.interpolate("beckmann", a.astype(jnp.float32), e.astype(jnp.float32))
    assert t32.transmittance.dtype == jnp.float32 and t32.internal_reflectance.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(t32.internal_reflectance), np.asarray(t64.internal_reflectance), atol=1e-5)
    mu = jnp.linspace(0.0, 1.0, 11)
    T32 = jax.vmap(lambda c, r: ct.transmittance_at("precomputed", ii.CoatTables(c, r), mu.astype(jnp.float32)))(
        t32.transmittance, t32.internal_reflectance)
    T64 = jax.vmap(lambda c, r: ct.transmittance_at("precomputed", ii.CoatTables(c, r), mu))(
        t64.transmittance, t64.internal_reflectance)
    assert T32.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(T32), np.asarray(T64), atol=1e-5)
    tv = jax.vmap(lambda a, e: ct.interpolate("beckmann", a, e))(a, e)
    np.testing.assert_allclose(np.asarray(tv.transmittance), np.asarray(t64.transmittance), rtol=1e-12, atol=1e-15)


def test_unknown_scheme_and_distribution():
    with pytest.raises(ValueError, match="scheme 'exact'"):
        ct.tabulate("ggx", 0.1, 1.5, "exact")
    with pytest.raises(ValueError, match="distribution 'phong'"):
        ct.interpolate("phong", 0.1, 1.5)


# ----------------------------------------------------------------------------------------
# the file


def test_shipped_file_loads():
    tables = ct.load()
    assert set(tables) == set(ct.KINDS)
    assert all(t.shape == (ct.N_U + 2, ct.N_W + 2, ct.N_VALUES) for t in tables.values())
    assert ct.table_path().is_file()


def _write(path, arrays):
    np.savez(path, **arrays)
    return path


def test_loader_refuses_bad_files(tmp_path):
    good = dict(np.load(ct.table_path(), allow_pickle=False))
    raw = ct.table_path().read_bytes()
    (tmp_path / "truncated.npz").write_bytes(raw[: len(raw) // 2])
    cases = {
        "truncated.npz": "cannot read",
        "missing.npz": "cannot read",
    }
    for name, match in cases.items():
        with pytest.raises(ct.CoatTableFileError, match=match):
            ct.load(tmp_path / name)
    bad = {
        "no_beckmann": ({k: v for k, v in good.items() if k != "beckmann"}, "holds arrays"),
        "other_grid": ({**good, "grid": good["grid"] * 1.01}, "computed for grid"),
        "transposed": ({**good, "ggx": np.ascontiguousarray(np.swapaxes(good["ggx"], 0, 1))}, "shape"),
        "float64": ({**good, "ggx": good["ggx"].astype(np.float64)}, "dtype"),
        "nan": ({**good, "beckmann": np.where(np.arange(good["beckmann"].size).reshape(good["beckmann"].shape) == 5,
                                               np.float32(np.nan), good["beckmann"])}, "non-finite"),
    }
    for name, (arrays, match) in bad.items():
        with pytest.raises(ct.CoatTableFileError, match=match):
            ct.load(_write(tmp_path / f"{name}.npz", arrays))
    # a pickled object array is refused (allow_pickle=False), not executed
    np.savez(tmp_path / "pickled.npz", grid=good["grid"], ggx=np.array([{"a": 1}], dtype=object),
             beckmann=good["beckmann"])
    with pytest.raises(ct.CoatTableFileError, match="cannot read"):
        ct.load(tmp_path / "pickled.npz")
    assert zipfile.is_zipfile(ct.table_path())
