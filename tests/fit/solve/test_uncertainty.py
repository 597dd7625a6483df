"""Honest uncertainties: coverage under correlated residuals, the bootstrap, degeneracies, bounds.

The synthetic "measurements" carry an error field that is smooth along theta_o within each
incidence direction and independent between incidences: per incidence i and band b,
g = a0 + a1 P1(u) + a2 P2(u) (u = theta_o / 80 deg, P Legendre polynomials, a ~ N(0, 1)),
data = f_true (1 + EPS g) (1 + NOISE n), n ~ N(0, 1) iid. The field has zero mean over
realisations, so the truth is the parameter that generated f_true (to O(EPS^2) for a
non-linear model, far below sigma). Within an incidence the ~33 residuals of a band are
strongly correlated, which is what makes the iid sigma far too small; the cluster-robust
sandwich, clustered by incidence direction, is built for exactly this (its jackknife form CR3
is the default; CR1 under-covers here, 0.55 in benchmarks/sigma_coverage.py, because the
grazing highlights carry most of the l2 fit's weight).
"""

import json

import numpy as np
import pytest

from appearance_jax import registry
from appearance_jax.fit.report.records import write_params_json
from appearance_jax.fit.solve import fit
from appearance_jax.fit.solve.batch import fit_batch
from appearance_jax.fit.solve.uncertainty import bootstrap_weights, incidence_clusters
from appearance_jax.fit.tables.grids import gonio_angles, in_plane_angles
from appearance_jax.fit.tables.table import Table

EPS, NOISE = 0.04, 0.004
TRUTH = dict(alpha=0.2, specular_reflectance=(0.9, 0.8, 0.7))
FIX = ["eta", "k"]
COVER = 0.6827  # P(|z| < 1)


def _table():
    """26 incidences (0..75 deg step 3) x 33 signed theta_o: many clusters, ~2600 entries."""
    ti, to = in_plane_angles(np.arange(0, 76, 3), np.arange(-80, 81, 5))
    return Table.in_plane(ti, to, np.ones((ti.size, 3)), source="correlated in-plane")


def _realisations(table, f, k, seed):
    rng = np.random.default_rng(seed)
    inc = np.unique(table.theta_i, return_inverse=True)[1].ravel()
    u = table.signed_theta_o() / np.deg2rad(80.0)
    basis = np.stack([np.ones_like(u), u, 1.5 * u ** 2 - 0.5], axis=-1)  # (N, 3) Legendre P0..P2
    a = rng.standard_normal((k, inc.max() + 1, 3, f.shape[1]))  # (K, incidences, order, bands)
    g = np.einsum("nl,knlb->knb", basis, a[:, inc])
    return f * (1 + EPS * g) * (1 + NOISE * rng.standard_normal((k,) + f.shape))


def _model_values(model, params, table):
    wi, wo = table.directions()
    return np.broadcast_to(np.asarray(model.eval(params, wi, wo), np.float64), table.values.shape)


def test_clusters_are_incidence_directions():
    t = _table()
    cl, g, what = incidence_clusters(t.directions()[0])
    assert g == 26 and what == "one per incidence direction"
    assert all(np.unique(t.theta_i[cl == c]).size == 1 for c in range(g))
    # scattered incidences (every row its own wi) fall back to theta_i bins
    rng = np.random.default_rng(0)
    s = Table(rng.uniform(0, 1.4, 200), rng.uniform(0, 6, 200), rng.uniform(0, 1.4, 200), rng.uniform(0, 6, 200),
              np.ones((200, 1)), np.ones((200, 1), bool), bands=("Y",))
    cl, g, what = incidence_clusters(s.directions()[0])
    assert what.startswith("theta_i bins") and g <= 28 and g < 200


def test_clusters_order_rows_like_unique_rows():
    """The packed one-key clustering numbers clusters as np.unique over rounded (x, y, z) rows does
    (lexicographic), including negative components, the poles and directions 1e-7 apart (one cluster)."""
    from appearance_jax.core.vec import Vec3

    rng = np.random.default_rng(3)
    v = rng.normal(size=(40, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v[:6] = [(0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0), (0, -1, 0), (0, 1, 0)]
    rows = v[rng.integers(0, 40, 300)]
    rows[::7] += 1e-7  # rounds to the same 1e-6 grid point as its twin, or to a neighbour: either way as unique rows
    cl, g, what = incidence_clusters(Vec3(*rows.T))
    _, ref = np.unique(np.round(rows / 1e-6).astype(np.int64), axis=0, return_inverse=True)
    assert what == "one per incidence direction" and g == ref.max() + 1
    np.testing.assert_array_equal(cl, ref.ravel())


def test_honest_sigma_covers_the_truth_and_iid_does_not():
    """K = 64 realisations in one fit_batch: pooled 1-sigma coverage of the 4 parameters.

    The pooled coverage averages 4 correlated indicators per realisation, so its variance is at
    most that of one indicator: |coverage - 0.683| <= 3 sqrt(0.683 x 0.317 / K) (= 0.17) is a
    3-sigma band. The iid sigma must under-cover clearly (< 0.4; with ~33 correlated values
    per incidence it is too small by a factor ~4, coverage ~0.2).
    """
    model = registry.get("rough_conductor")
    truth = model.Params(**TRUTH)
    table = _table()
    f = _model_values(model, truth, table)
    K = 64
    values = _realisations(table, f, K, seed=19)
    res = fit_batch(model, table, values, init=model.Params(alpha=0.3), fix=FIX)
    assert res.converged.all() and res.sigma_method == "cr3" and res.n_clusters == 26
    t = np.array([0.2, 0.9, 0.8, 0.7])
    err = np.abs(res.x - t)
    cover = np.mean(err < res.sigma)
    cover_iid = np.mean(err < res.sigma_iid)
    tol = 3 * np.sqrt(COVER * (1 - COVER) / K)
    assert abs(cover - COVER) <= tol, (cover, cover_iid)
    assert cover_iid < 0.4, (cover, cover_iid)
    assert np.all(res.sigma >= res.sigma_iid * (1 - 1e-12))  # the default never drops below iid
    # the batch item is a single fit of that table: its covariances (computed in the batch's
    # vmapped program) equal those of fit() on table 3 alone, started at the batch's optimum
    one = res.item(3)
    single = fit(model, table.replace(values=values[3]), fix=FIX,
                 init=model.Params(alpha=float(one.x[0]), specular_reflectance=tuple(one.x[1:])))
    np.testing.assert_allclose(single.x, one.x, rtol=1e-7)
    for kind in ("sigma", "sigma_sandwich", "sigma_iid", "sigma_cr1"):
        np.testing.assert_allclose(getattr(one, kind), getattr(single, kind), rtol=1e-5, err_msg=kind)
    np.testing.assert_allclose(one.sigma, res.sigma[3], rtol=1e-12)
    assert np.median(res.sigma_sandwich / res.sigma_cr1) > 1  # the jackknife form undoes CR1's low bias


def test_bootstrap_agrees_with_the_sandwich_and_is_reproducible():
    """B = 48 block-bootstrap refits vs the cluster sandwich (CR1 form) on one correlated table.

    Both estimate the same spread from the same 26 incidence blocks; the bootstrap sigma has a
    resampling error of 1 / sqrt(2 (B - 1)) = 0.10 relative, and the two differ by the CR1
    factor and bootstrap bias of O(p / G) ~ 0.15: the ratio must be 1 within 3.5 x 0.10 + 0.15.
    """
    model = registry.get("rough_conductor")
    table = _table()
    f = _model_values(model, model.Params(**TRUTH), table)
    values = _realisations(table, f, 1, seed=5)[0]
    B = 48
    res = fit(model, table.replace(values=values), init=model.Params(alpha=0.3), fix=FIX, bootstrap=B,
              bootstrap_seed=3)
    assert res.bootstrap["replicates"] == B and res.bootstrap["failed"] == res.bootstrap["not_converged"] == 0
    ratio = res.sigma_bootstrap / res.sigma_cr1
    assert np.all(np.abs(ratio - 1) < 3.5 / np.sqrt(2 * (B - 1)) + 0.15), ratio
    lo, hi = res.bootstrap["interval68"].T
    assert np.all(lo < res.x) and np.all(res.x < hi)
    d = res.to_dict()["parameters"]["alpha"]
    assert d["sigma_bootstrap"] == pytest.approx(res.sigma_bootstrap[0]) and len(d["bootstrap_interval95"]) == 2
    # the same seed gives the same replicates
    w1, w2 = (bootstrap_weights(np.arange(5).repeat(3), np.ones(15, bool), 4, seed=3) for _ in range(2))
    np.testing.assert_array_equal(w1, w2)
    assert np.all(w1.reshape(4, 5, 3).sum(axis=1)[:, 0] == 5)  # G draws per replicate
    with pytest.raises(ValueError, match="bootstrap = 1"):
        fit(model, table.replace(values=values), fix=FIX, bootstrap=1)


def test_flat_valley_is_named_with_a_suggestion():
    """A conductor seen over a narrow range of angles: eta, k and the scale trade off (the
    Fresnel factor barely changes between 0 and 30 deg), so the fit cannot resolve them."""
    model = registry.get("rough_conductor")
    truth = model.Params(alpha=0.3, eta=1.5, k=3.0, specular_reflectance=0.7)
    ti, to = in_plane_angles(np.arange(0, 31, 2), np.arange(-30, 31, 3))
    table = Table.in_plane(ti, to, np.ones((ti.size, 1)), bands=("Y",))
    f = _model_values(model, truth, table)
    noisy = f * (1 + 0.02 * np.random.default_rng(2).standard_normal(f.shape))
    res = fit(model, table.replace(values=noisy), init=truth)
    assert res.degeneracies, res.summary()
    group = res.degeneracies[0]
    assert {"eta[Y]", "k[Y]"} <= set(group["parameters"]), group
    # the scale is in the valley too, unless the solver walked along it to the scale's bound (the
    # plain LM does: a lower loss at specular_reflectance = 1), where it has no sigma
    assert "specular_reflectance[Y]" in group["parameters"] or "specular_reflectance[Y]" in res.at_bound, group
    assert "alpha" not in group["parameters"] and group["correlated"] > 0.95
    assert "fix eta and k" in group["suggestion"]
    assert any(w.startswith("degenerate:") for w in res.warnings)
    assert set(group["parameters"]) <= set(res.poorly_determined)
    # a well-posed fit of the same table (index known) flags nothing
    ok = fit(model, table.replace(values=noisy), init=truth, fix=["eta", "k"])
    assert not ok.degeneracies and not ok.poorly_determined, ok.summary()


def test_parameters_at_bounds_get_no_sigma_and_a_warning(tmp_path):
    """Lambert with two bands of zero reflectance: two parameters end on the bound 0. A gonio
    table with 5 incidences has too few clusters for the cluster sandwich (HC1 + a warning)."""
    ti, pi_, to, po = gonio_angles([0, 20, 40, 60, 75], np.arange(0, 81, 10), np.arange(0, 181, 30))
    rho = np.array([0.5, 0.0, 0.0])
    v = np.broadcast_to(rho / np.pi, (ti.size, 3)) * (1 + 0.01 * np.random.default_rng(1).standard_normal((ti.size, 3)))
    t = Table(ti, pi_, to, po, np.abs(v), np.ones((ti.size, 3), bool), source="two dark bands")
    res = fit("lambert", t)
    assert set(res.at_bound) == {"reflectance[G]", "reflectance[B]"}
    assert np.isnan(res.sigma[1:]).all() and np.isfinite(res.sigma[0])
    assert res.sigma_method == "hc1" and res.n_clusters == 5
    assert any("2 parameters ended at a bound" in w for w in res.warnings)
    assert any("only 5 incidence directions" in w for w in res.warnings)
    text = res.summary()
    assert "reflectance[G] = " in text and "(at bound)" in text and "warning:" in text
    assert "+-" not in text.split("reflectance[G]")[1].splitlines()[0]
    d = write_params_json(res, tmp_path / "params.json")
    back = json.loads((tmp_path / "params.json").read_text())
    g = back["parameters"]["reflectance[G]"]
    assert g["sigma"] is None and g["sigma_iid"] is None and g["sigma_note"].startswith("at bound")
    assert back["uncertainty"]["method"] == "hc1" and back["warnings"] == res.warnings
    assert back["correlation"]["labels"] == list(res.labels) and len(back["correlation"]["matrix"]) == 3
    assert back["correlation"]["matrix"][0][0] == pytest.approx(1.0) and d["degeneracies"] == []


def _direct_covariances(model, table, x, **build):
    """unc.covariances at x with the model's own Jacobian in x (the reference for the solver's)."""
    import jax

    from appearance_jax.fit.solve.problem import build_problem
    from appearance_jax.fit.solve.uncertainty import covariances

    problem = build_problem(model, table, **build)
    cl, n_cl, _ = incidence_clusters(problem.data["wi"])
    out = jax.jit(lambda x, d, c: covariances(problem, x, d, c, n_cl))(np.asarray(x), problem.data, np.asarray(cl))
    return {k: np.asarray(v, np.float64) for k, v in out.items()}


@pytest.mark.parametrize("case", ["interior", "bounds"])
def test_covariances_from_the_solvers_jacobian_are_the_models(case):
    """fit() and fit_batch() take the covariances from LM's final Jacobian in z, divided by dx/dz
    (uncertainty.jacobian_in_x); they must equal the covariances from the model's Jacobian in x to
    rounding: in the interior (2 starts, the best one's), and with parameters on a bound (their
    columns dropped, the others' intact)."""
    if case == "interior":
        table = _table()
        model = registry.get("rough_conductor")
        f = _model_values(model, model.Params(alpha=0.2, specular_reflectance=(0.9, 0.8, 0.7)), table)
        table = table.replace(values=_realisations(table, f, 1, seed=3)[0])
        build, kw = dict(fix=FIX), dict(n_starts=2, seed=1)
    else:
        ti, pi_, to, po = gonio_angles([0, 20, 40, 60, 75], np.arange(0, 81, 10), np.arange(0, 181, 30))
        v = np.broadcast_to(np.array([0.5, 0.0, 0.0]) / np.pi, (ti.size, 3))
        v = np.abs(v * (1 + 0.01 * np.random.default_rng(1).standard_normal((ti.size, 3))))
        table = Table(ti, pi_, to, po, v, np.ones((ti.size, 3), bool), source="two dark bands")
        model, build, kw = registry.get("lambert"), {}, {}
    res = fit(model, table, **build, **kw)
    if case == "bounds":
        assert set(res.at_bound) == {"reflectance[G]", "reflectance[B]"}
    ref = _direct_covariances(model, table, res.x, **build)
    for got, want in ((res.cov_iid, ref["iid"]), (res.sigma_hc1, np.sqrt(np.diag(ref["hc1"]))),
                      (res.sigma_cr1, np.sqrt(np.diag(ref["cr1"]))), (res.sigma_sandwich, np.sqrt(np.diag(ref["cr3"]))),
                      (res.eigenvalues, ref["lam"])):
        np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-12 * np.max(np.abs(want)))
    batch = fit_batch(model, table, table.values[None], **build)
    np.testing.assert_allclose(batch.sigma_hc1[0], np.sqrt(np.diag(_direct_covariances(
        model, table, batch.x[0], **build)["hc1"])), rtol=1e-7, atol=1e-14)


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_host_covariances_are_the_traced_ones(dtype):
    """fit() takes its covariances in numpy on the host (uncertainty.covariances_host) from the
    solve's r and J; batches take them inside their program (uncertainty.covariances). Both are one
    formula (_estimates with np or jnp): on the same r and J (masked entries, a parameter on its
    bound, a cluster with no valid value, a flat direction) every estimate must agree to rounding."""
    import jax
    import jax.numpy as jnp

    from appearance_jax.fit.solve.problem import build_problem
    from appearance_jax.fit.solve.uncertainty import covariances, covariances_host

    table = _table()
    model = registry.get("rough_conductor")
    problem = build_problem(model, table, fix=FIX)
    n, b = problem.data["weight"].shape
    p = problem.space.size
    rng = np.random.default_rng(5)
    cl, n_cl, _ = incidence_clusters(problem.data["wi"])
    weight = np.asarray(problem.data["weight"]).copy()
    weight[cl == 2] = 0.0  # a cluster without a valid value
    weight[rng.random(weight.shape) < 0.1] = 0.0
    ok = (weight > 0).ravel()
    J = rng.standard_normal((n * b, p)) * ok[:, None]
    J[:, 2] = 0.5 * J[:, 1]  # specular_reflectance[R] and [G]: one exactly flat direction
    r = rng.standard_normal(n * b) * ok
    x = np.array([problem.space.fields[0].spec.lo, 0.5, 0.6, 0.7])  # alpha on its bound: its column is dropped
    J, r, x = (a.astype(dtype) for a in (J, r, x))
    data = dict(problem.data, weight=jnp.asarray(weight, dtype))
    want = jax.jit(lambda x, d, c, J, r: covariances(problem, x, d, c, n_cl, J=J, r=r))(x, data, cl, J, r)
    got = covariances_host(problem, x, r, J, weight.astype(dtype), cl, n_cl)
    assert set(got) == set(want)
    tol = dict(float64=1e-10, float32=2e-4)[dtype]
    for k in want:
        w, g = np.asarray(want[k]), np.asarray(got[k])
        if w.dtype == bool or k in ("m", "g"):
            np.testing.assert_array_equal(g, w, err_msg=k)
        else:
            np.testing.assert_allclose(g, w, rtol=tol, atol=tol * np.max(np.abs(w)), err_msg=k)
    assert np.all(np.asarray(got["iid"])[0] == 0) and got["flat"][1] and got["flat"][2] and not got["flat"][0]
    assert int(got["g"]) == n_cl - 1


def test_host_cluster_solves_give_nan_for_a_singular_cluster():
    """The jackknife's per-cluster systems: numpy raises for a singular one, where XLA's LU returns
    non-finite values (and the CR1 term stands in); the host version must give NaN for that
    cluster only."""
    from appearance_jax.fit.solve.uncertainty import _solve_each

    A = np.array([[[2.0, 0.0], [0.0, 4.0]], [[1.0, 0.0], [0.0, 0.0]], [[1.0, 1.0], [0.0, 1.0]]])
    b = np.array([[2.0, 4.0], [1.0, 1.0], [3.0, 1.0]])
    got = _solve_each(np, A, b)
    np.testing.assert_allclose(got[0], [1.0, 1.0])
    assert np.all(np.isnan(got[1]))
    np.testing.assert_allclose(got[2], [2.0, 1.0])


def test_host_covariances_of_a_non_finite_jacobian_are_nan():
    """A NaN or infinite Jacobian entry (a model that blows up at the optimum) gives NaN estimates,
    not an exception: the result then falls back to the covariances from the model's own Jacobian
    (result.finish) or reports NaN sigmas, as with the traced estimates."""
    from appearance_jax.fit.solve.problem import build_problem
    from appearance_jax.fit.solve.uncertainty import covariances_host

    problem = build_problem(registry.get("rough_conductor"), _table(), fix=FIX)
    n, b = problem.data["weight"].shape
    cl, n_cl, _ = incidence_clusters(problem.data["wi"])
    rng = np.random.default_rng(2)
    x = np.array([0.2, 0.5, 0.6, 0.7])
    for bad in (np.nan, np.inf):
        J = rng.standard_normal((n * b, 4))
        J[3, 1] = bad
        out = covariances_host(problem, x, rng.standard_normal(n * b), J, problem.data["weight"], cl, n_cl)
        for k in ("iid", "hc1", "cr1", "cr3"):
            assert not np.all(np.isfinite(out[k])), k
