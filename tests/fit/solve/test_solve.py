"""Fitting: parameter recovery from noisy synthetic tables, solvers, uncertainties, errors.

Recovery tolerances come from the fit itself: the data carry their 1-sigma noise (2 %
multiplicative, as stated in the table's sigma), so the Jacobian covariance is absolute and
the recovered parameters must lie within 4.5 of their own sigma of the truth (a 4.5-sigma
miss has probability ~7e-6 per parameter). The sigmas themselves must be small (the test
would pass trivially otherwise) and the reduced chi-square must be 1 within 5 of its standard
error sqrt(2 / dof).
"""

import numpy as np
import pytest

import jax
import jax.numpy as jnp

from appearance_jax import registry
from appearance_jax.core.model import Model, boundary
from appearance_jax.core.vec import Vec3
from appearance_jax.fit.tables.grids import gonio_angles, in_plane_angles
from appearance_jax.fit.solve import SOLVERS, fit
from appearance_jax.fit.tables.table import Table


def gonio_table():
    """A realistic out-of-plane gonioreflectometer: 5 x 9 x 7 = 315 directions."""
    ti, pi, to, po = gonio_angles([0, 20, 40, 60, 75], np.arange(0, 81, 10), np.arange(0, 181, 30))
    return Table(ti, pi, to, po, np.ones((ti.size, 3)), np.ones((ti.size, 3), bool), source="gonio")


def in_plane_table():
    """In-plane only, signed theta_o (Padrón 2025 Fig. 4.4 layout): 6 x 35 = 210 directions."""
    ti, to = in_plane_angles([0, 15, 30, 45, 60, 75], np.arange(-85, 86, 5))
    return Table.in_plane(ti, to, np.ones((ti.size, 3)), source="in-plane")


def synth(model, params, table, noise=0.02, seed=0):
    wi, wo = table.directions()
    f = np.asarray(model.eval(params, wi, wo), np.float64)
    f = np.broadcast_to(f, table.values.shape)
    rng = np.random.default_rng(seed)
    return table.replace(values=f * (1 + noise * rng.standard_normal(f.shape)), sigma=noise * f,
                         mask=np.ones(f.shape, bool))


def truth_vector(result, truth):
    out = []
    for lab in result.labels:
        name, _, band = lab.partition("[")
        v = np.asarray(getattr(truth, name), np.float64)
        out.append(float(np.broadcast_to(v, (3,))["RGB".index(band[0])] if band else v))
    return np.array(out)


CASES = {
    "lambert-gonio": ("lambert", dict(reflectance=(0.7, 0.4, 0.2)), dict(reflectance=(0.5, 0.5, 0.5)), None,
                      gonio_table),
    "rough_conductor-gonio": ("rough_conductor", dict(alpha=0.25, specular_reflectance=(0.9, 0.8, 0.7)),
                              dict(alpha=0.35, specular_reflectance=(0.7, 0.7, 0.7)), ["eta", "k"], gonio_table),
    "rough_conductor-in_plane": ("rough_conductor", dict(alpha=0.12, specular_reflectance=(0.9, 0.8, 0.7)),
                                 dict(alpha=0.08, specular_reflectance=(1.0, 1.0, 1.0)), ["eta", "k"],
                                 in_plane_table),
    "rough_dielectric-in_plane": ("rough_dielectric", dict(alpha=0.2, eta=1.6), dict(alpha=0.3, eta=1.4), None,
                                  in_plane_table),
    "rough_conductor+lambert-gonio": ("rough_conductor+lambert",
                                      dict(alpha=0.3, specular_reflectance=(0.5, 0.4, 0.3), reflectance=(0.3, 0.2, 0.6)),
                                      dict(alpha=0.2, specular_reflectance=(0.3, 0.3, 0.3), reflectance=(0.4, 0.4, 0.4)),
                                      ["eta", "k"], gonio_table),
    "rough_plastic-in_plane": ("rough_plastic", dict(alpha=0.15, diffuse_reflectance=(0.5, 0.3, 0.2)),
                               dict(alpha=0.2, diffuse_reflectance=(0.3, 0.3, 0.3)),
                               ["eta", "specular_reflectance"], in_plane_table),
}


# rough_plastic: its coat integrals are recomputed at every iterate (~1 min). rough_conductor-in_plane: a
# second case of a model and a table layout the default cases cover (rough_conductor-gonio for the model,
# rough_dielectric-in_plane for the in-plane table with signed theta_o), each case compiles its own fit
SLOW = {"rough_plastic-in_plane", "rough_conductor-in_plane"}


@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c in SLOW else c for c in CASES])
def test_recovery_from_noisy_tables(case):
    name, truth_kw, start_kw, fix, make_table = CASES[case]
    model = registry.get(name)
    truth = model.Params(**truth_kw)
    table = synth(model, truth, make_table())
    res = fit(model, table, init=model.Params(**start_kw), fix=fix)
    assert res.converged, res.summary()
    t = truth_vector(res, truth)
    assert np.all(np.isfinite(res.sigma)), res.summary()
    assert np.all(res.sigma < 0.03 * np.abs(t)), res.summary()  # the data do determine the parameters
    assert np.all(np.abs(res.x - t) < 4.5 * res.sigma), (res.summary(), t)
    # the same through the by-label accessors
    assert all(abs(res.values[lab] - v) < 4.5 * res.uncertainties[lab] for lab, v in zip(res.labels, t))
    dof = res.n_valid - len(res.x)
    assert abs(res.loss * res.n_valid / dof - 1.0) < 5 * np.sqrt(2.0 / dof), res.summary()
    assert not res.at_bound and not res.poorly_determined


def test_noise_free_data_are_fitted_exactly_in_every_metric():
    """cos_log and relative here; l2 in test_explicit_start_list_runs_one_start_each (same table and
    assertions, one program fewer: each metric compiles its own solve)."""
    model = registry.get("rough_conductor")
    truth = model.Params(alpha=0.3, specular_reflectance=(0.8, 0.6, 0.9))
    table = synth(model, truth, gonio_table(), noise=0.0).replace(sigma=None)
    for metric in ("cos_log", "relative"):
        res = fit(model, table, init=model.Params(alpha=0.1), fix=["eta", "k"], metric=metric)
        np.testing.assert_allclose(res.x, truth_vector(res, truth), rtol=1e-7, err_msg=metric)
        assert res.loss < 1e-16


@pytest.mark.slow  # 20 s; LM is the default of every other fit test, BFGS/Powell are exercised by the recipes
def test_all_solvers_reach_the_same_optimum():
    model = registry.get("rough_conductor")
    truth = model.Params(alpha=0.2, specular_reflectance=(0.9, 0.8, 0.7))
    table = synth(model, truth, gonio_table(), seed=4)
    results = {s: fit(model, table, init=model.Params(alpha=0.3, specular_reflectance=0.8), fix=["eta", "k"],
                      solver=s, max_steps=2000) for s in SOLVERS}
    ref = results["lm"].x
    for s, r in results.items():
        assert r.converged, (s, r.summary())
        np.testing.assert_allclose(r.x, ref, rtol=2e-5, err_msg=s)
        assert r.iterations > 0


def test_uncertainties_match_the_spread_over_noise_realisations():
    """Jacobian 1-sigma vs the standard deviation of 48 refits with fresh noise (fit_batch).

    The sample standard deviation of n = 48 estimates has a relative standard error of
    1/sqrt(2 (n - 1)) = 0.103; the ratio must be 1 within 3.5 of that.
    """
    from appearance_jax.fit.solve.batch import fit_batch

    model = registry.get("rough_conductor")
    truth = model.Params(alpha=0.2, specular_reflectance=(0.9, 0.8, 0.7))
    table = gonio_table()
    wi, wo = table.directions()
    f = np.asarray(model.eval(truth, wi, wo), np.float64)
    rng = np.random.default_rng(11)
    n = 48
    values = f * (1 + 0.02 * rng.standard_normal((n,) + f.shape))
    res = fit_batch(model, table, values, sigma=0.02 * f, init=model.Params(alpha=0.3), fix=["eta", "k"])
    assert res.converged.all()
    spread = res.x.std(axis=0, ddof=1)
    predicted = res.sigma.mean(axis=0)
    ratio = spread / predicted
    assert np.all(np.abs(ratio - 1) < 3.5 / np.sqrt(2 * (n - 1))), ratio
    # the batch result of one item equals a single fit of that table
    single = fit(model, table.replace(values=values[5], sigma=0.02 * f), init=model.Params(alpha=0.3),
                 fix=["eta", "k"])
    np.testing.assert_allclose(res.x[5], single.x, rtol=1e-7)
    np.testing.assert_allclose(res.sigma[5], single.sigma, rtol=1e-6)


def test_masked_and_grazing_samples_are_counted_not_used():
    model = registry.get("lambert")
    ti, to = in_plane_angles([0, 30, 60, 88], np.arange(-80, 81, 20))
    f = np.full((ti.size, 3), 0.5 / np.pi)
    f[3, 1] = np.nan  # a missing sample
    f[5] = 1e3  # an outlier row, masked by the user below
    t = Table.in_plane(ti, to, f, mask=np.isfinite(f), masked={"missing value": 1})
    w = np.ones_like(f)
    w[5] = 0.0
    res = fit(model, t, weights=w)
    assert res.masked["missing value"] == 1
    assert res.masked["grazing (theta > 85 deg)"] == 9 * 3  # theta_i = 88: 9 directions x 3 bands
    assert res.n_valid == ti.size * 3 - 1 - 27 - 3
    np.testing.assert_allclose(res.x, 0.5, rtol=1e-8)


def test_problem_data_are_host_arrays_of_the_tables_directions():
    """build_problem keeps the data in numpy (the compiled solve moves them itself) in JAX's default
    float dtype, with the directions of Table.directions to rounding."""
    from appearance_jax.fit.solve import build_problem

    t = gonio_table()
    prob = build_problem("lambert", t)
    leaves = jax.tree_util.tree_leaves(prob.data)
    assert len(leaves) == 10 and all(type(v) is np.ndarray and v.dtype == jnp.result_type(float) for v in leaves)
    for host, dev in zip(prob.data["wi"] + prob.data["wo"], t.directions()[0] + t.directions()[1]):
        np.testing.assert_allclose(host, np.asarray(dev), rtol=0, atol=4 * np.finfo(host.dtype).eps)


@pytest.mark.parametrize("model, fix", [("rough_plastic", ["eta"]), ("rough_conductor+lambert", ["eta", "k"]),
                                        ("rough_plastic", ["eta", "alpha"]),
                                        ("rough_conductor", ["specular_reflectance"])])
def test_jacobian_with_fields_apart_is_the_whole_jacobian(model, fix):
    """Problem.jacobian_z (the fields of Model.jacobian_apart in a forward pass of their own, the
    others in another; the band fields of a band-separable model one tangent each) gives
    jax.jacfwd's Jacobian, columns in z's order: two passes with collapsed band fields, one pass
    with them (eta, k of rough_conductor), and only apart fields free. At a point off the start,
    where no column vanishes."""
    from appearance_jax.fit.solve import build_problem

    m = registry.get(model)
    prob = build_problem(m, in_plane_table(), fix=fix)
    z = jnp.asarray(prob.space.z_from_x(prob.space.x_start())) + jnp.linspace(0.1, 0.3, prob.space.size)
    ref = jax.jit(jax.jacfwd(prob.residuals_z))(z, prob.data)
    J = jax.jit(prob.jacobian_z)(z, prob.data)
    assert J.shape == ref.shape and np.all(np.abs(np.asarray(ref)).max(axis=0) > 0)
    np.testing.assert_allclose(np.asarray(J), np.asarray(ref), rtol=1e-12, atol=1e-12 * float(jnp.max(jnp.abs(ref))))


def _separable_models():
    names = [n for n in registry.names() if registry.get(n).kind == "bsdf" and registry.get(n).band_separable]
    return names


# settings that keep the costlier evals cheap (compile time) and touch no band structure: a coarse
# ordinates grid without the tilt correction (a thin layer, so that the base shows), one weave
# orientation, the harness' snake case
_CHEAP = {"cosmetics_ordinates": dict(thickness=1.0, n_nodes=8, n_modes=6, tilt_correction=False),
          "cloth_weave": dict(weave="twill", alpha=20.0, n_rotations=2, n_samples=4),
          "snake": dict(eta1=2.0, eta2=1.3)}


def _band_mixing(m, p):
    """What breaks Model.band_separable for ``m`` at ``p``: changing entry b of a band field must change
    output band b and leave the other bands bit for bit unchanged. A list of messages (empty: none)."""
    from appearance_jax.core.params import ParamSpec, param_specs
    from appearance_jax.testing.directions import call_chunked

    rng = np.random.default_rng(1)
    v = rng.normal(size=(2, 64, 3))
    v[..., 2] = np.abs(v[..., 2]) + 0.05
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    wi, wo = (Vec3(*(jnp.asarray(v[k, :, c]) for c in range(3))) for k in range(2))

    def f(q):
        return call_chunked(m.eval, q, wi, wo)

    specs = param_specs(type(p))
    fields = [k for k, s in specs.items() if isinstance(s, ParamSpec) and s.bands]
    assert fields
    out = []
    for k in fields:
        lo, hi = specs[k].lo, specs[k].hi
        val = np.broadcast_to(np.asarray(getattr(p, k), np.float64), (3,)) * np.array([0.9, 0.8, 0.7]) + 0.05
        val = np.clip(val, lo if np.isfinite(lo) else -np.inf, hi if np.isfinite(hi) else np.inf)
        f0 = f(p.replace(**{k: tuple(val)}))
        for b in range(3):
            moved = val.copy()
            moved[b] = 0.8 * moved[b] + 0.01
            f1 = f(p.replace(**{k: tuple(moved)}))
            other = [c for c in range(3) if c != b]
            if not np.array_equal(f1[..., other], f0[..., other]):
                out.append(f"{m.name}.{k}[{b}] moves bands {other}")
            if np.array_equal(f1[..., b], f0[..., b]):
                out.append(f"{m.name}.{k}[{b}] does not act on band {b}")
    return out


@pytest.mark.parametrize("name", _separable_models())
def test_band_separable_models_never_mix_bands(name):
    """Every model that declares Model.band_separable (what lets a fit collapse a band field's tangents)
    passes the check of _band_mixing."""
    m = registry.get(name)
    assert _band_mixing(m, m.Params(**_CHEAP.get(name, {}))) == []


def test_band_mixing_check_finds_a_model_that_mixes_bands():
    """The check itself: a Lambertian whose albedo is the band mean in every band fails it."""
    from appearance_jax.bsdf import lambert

    def mixed(p, wi, wo):
        rho = jnp.broadcast_to(jnp.asarray(p.reflectance), (3,))
        return lambert.eval.kernel(p.replace(reflectance=0.5 * rho + 0.5 * jnp.mean(rho)), wi, wo)

    m = Model(name="mixed_lambert", kind="bsdf", Params=lambert.Params, eval=boundary(mixed, lambert.Params),
              sample=None, pdf=None, summary="", source="", band_separable=True)
    problems = _band_mixing(m, lambert.Params())
    assert len(problems) == 3 and all("moves bands" in t for t in problems)


def test_bad_requests_raise_clear_errors():
    model = registry.get("lambert")
    t = in_plane_table().replace(values=np.full((210, 3), 0.1))
    with pytest.raises(ValueError, match="solver = 'newton'"):
        fit(model, t, solver="newton")
    with pytest.raises(ValueError, match="metric = 'l1'"):
        fit(model, t, metric="l1")
    with pytest.raises(ValueError, match="preset 'gold' is not a preset of lambert"):
        fit(model, t, init="gold")
    with pytest.raises(ValueError, match="henyey_greenstein is a phase"):
        fit("henyey_greenstein", t)
    with pytest.raises(ValueError, match="0 valid values for 3 free parameters"):
        fit(model, t.replace(mask=np.zeros((210, 3), bool)))
    with pytest.raises(ValueError, match=r"lambert.Params.reflectance = 1.5 is outside"):
        fit(model, t, init=model.Params(reflectance=1.5))


def _toy_stochastic_model():
    """Lambert estimated by Monte Carlo: mean over 64 samples of rho/pi (1 + 0.2 u_k), u ~ U(-1, 1).

    Its expectation is rho/pi; each key gives a different (but smooth in rho) function.
    """
    lam = registry.get("lambert")

    def kernel(params, wi, wo, key):
        u = jax.random.uniform(key, (64,), minval=-1.0, maxval=1.0)
        scale = jnp.mean(1 + 0.2 * u)
        f = lam.eval.kernel(params, wi, wo) * scale
        return f, jnp.abs(f) * 0.2 / jnp.sqrt(3 * 64)

    return Model("toy_mc_lambert", "bsdf", lam.Params, boundary(kernel, lam.Params), None, None, "toy", "test")


def test_stochastic_model_is_fitted_with_common_random_numbers():
    model = _toy_stochastic_model()
    lam = registry.get("lambert")
    t = synth(lam, lam.Params(reflectance=(0.6, 0.5, 0.4)), in_plane_table(), noise=0.0).replace(sigma=None)
    key = jax.random.PRNGKey(7)
    a = fit(model, t, key=key)
    b = fit(model, t, key=key)
    assert a.converged and a.loss < 1e-20  # with a fixed key the residual is deterministic: exact fit
    np.testing.assert_array_equal(a.x, b.x)  # same key, same numbers
    scale = float(jnp.mean(1 + 0.2 * jax.random.uniform(key, (64,), minval=-1.0, maxval=1.0)))
    np.testing.assert_allclose(a.x, np.array([0.6, 0.5, 0.4]) / scale, rtol=1e-8)
    c = fit(model, t, key=jax.random.PRNGKey(8))
    assert np.max(np.abs(c.x - a.x)) > 1e-4  # another key is another (consistent) estimator


def test_degenerate_parameters_are_reported_as_poorly_determined():
    """lambert + lambert: only the sum of the two albedos is determined (a flat direction)."""
    model = registry.get("lambert+lambert")
    lam = registry.get("lambert")
    table = synth(lam, lam.Params(reflectance=0.6), gonio_table(), seed=3)
    res = fit(model, table, init=model.Params(reflectance=0.2, lambert_1_reflectance=0.3))
    assert set(res.poorly_determined) == set(res.labels), res.summary()
    assert np.all(np.isnan(res.sigma))
    np.testing.assert_allclose(res.x[:3] + res.x[3:], 0.6, atol=4.5 * 0.02 * 0.6 / np.sqrt(315))
    # a well-posed fit of the same table flags nothing
    assert not fit(lam, table).poorly_determined


def test_spectral_table_fits_band_parameters_per_wavelength():
    """A 5-wavelength table: band fields are fitted per wavelength; fixed 3-band fields are refused."""
    wl = np.array([450.0, 500.0, 550.0, 600.0, 650.0])
    ti, to = in_plane_angles([0, 30, 60], np.arange(-60, 61, 15))
    rho = np.array([0.1, 0.2, 0.4, 0.6, 0.7])
    t = Table.in_plane(ti, to, np.broadcast_to(rho / np.pi, (ti.size, 5)), bands=tuple(f"{w:g}" for w in wl),
                       wavelengths=wl)
    res = fit("lambert", t)
    assert res.labels[0] == "reflectance[450]" and len(res.labels) == 5
    np.testing.assert_allclose(res.x, rho, rtol=1e-8)
    with pytest.raises(ValueError, match="eta \\(fixed\\) has 3 bands but the table has 5"):
        fit("rough_conductor", t, fix=["eta", "k"])


def test_explicit_start_list_runs_one_start_each():
    """init=[...]: one start per entry (plus n_starts - 1 random ones), the best one is kept.

    Also the l2 case of test_noise_free_data_are_fitted_exactly_in_every_metric (noise-free data
    fitted exactly) and what test_preset_start_and_multi_start_keeps_the_best checked (a preset
    name as a start, random starts added, the best start's loss reported): both fitted the same
    model, fixed values and table, so they now share this test's compiled solve.
    """
    model = registry.get("rough_conductor")
    truth = model.Params(alpha=0.2, specular_reflectance=(0.8, 0.6, 0.9))
    table = synth(model, truth, gonio_table(), noise=0.0).replace(sigma=None)
    starts = [model.Params(alpha=a) for a in (1.5, 0.05, 0.7)]
    res = fit(model, table, init=starts, fix=["eta", "k"])
    assert res.starts["n_starts"] == 3 and len(res.starts["losses"]) == 3
    np.testing.assert_allclose(res.x, truth_vector(res, truth), rtol=1e-7)
    assert res.loss < 1e-16
    # a given start, a preset ("gold": the default eta and k, so the fixed values stay those of the first
    # start) and n_starts - 1 = 1 random one: 3 starts again, so this fit reuses the compiled solve of
    # the first (same problem, same number of starts) instead of compiling another
    res = fit(model, table, init=[starts[0], "gold"], fix=["eta", "k"], n_starts=2, seed=1)
    assert res.starts["n_starts"] == 3 and len(res.starts["losses"]) == 3
    assert res.loss == pytest.approx(min(res.starts["losses"]), rel=1e-12)
    assert res.starts["losses"][res.starts["best"]] == pytest.approx(res.loss, rel=1e-12)
    np.testing.assert_allclose(res.x, truth_vector(res, truth), rtol=1e-7)
    with pytest.raises(ValueError, match="empty"):
        fit(model, table, init=[])
    with pytest.raises(ValueError, match="preset 'nope'"):
        fit(model, table, init=[starts[0], "nope"])


def _toy_spectral_model():
    """f = w(lambda) / pi with w = lambda / 1000: a model with static color/wavelengths fields."""
    from appearance_jax.core import spectral
    from appearance_jax.core.params import param, params_class, static

    @params_class
    class P:
        scale: object = param(1.0, lo=0.0, hi=10.0)
        color: str = static("rgb3", choices=spectral.COLOR_MODES)
        wavelengths: tuple = static(spectral.RGB_WAVELENGTHS, convert=spectral.wavelengths_tuple)

    def kernel(p, wi, wo):
        wl = spectral.band_wavelengths(p.color, p.wavelengths)
        v = p.scale * wl / 1000.0 / jnp.pi * jnp.ones(jnp.shape(wi.z) + (1,))
        return spectral.to_bands(v, p.color, p.wavelengths)

    return Model("toy_spectral", "bsdf", P, boundary(kernel, P), None, None, "toy", "test")


def test_spectral_table_sets_the_model_wavelengths():
    model = _toy_spectral_model()
    wl = np.array([420.0, 500.0, 610.0, 700.0])
    ti, to = in_plane_angles([0, 30], np.arange(-60, 61, 30))
    t = Table.in_plane(ti, to, np.broadcast_to(0.7 * wl / 1000 / np.pi, (ti.size, 4)),
                       bands=tuple(f"{w:g}" for w in wl), wavelengths=wl)
    res = fit(model, t)
    assert res.params.color == "spectral" and res.params.wavelengths == tuple(wl)
    np.testing.assert_allclose(res.params.scale, 0.7, rtol=1e-8)
    # an RGB table keeps rgb3 (650/510/475 nm) and refuses "spectral"
    rgb = Table.in_plane(ti, to, np.broadcast_to(0.5 * np.array([650.0, 510, 475]) / 1000 / np.pi, (ti.size, 3)))
    np.testing.assert_allclose(fit(model, rgb).params.scale, 0.5, rtol=1e-8)
    with pytest.raises(ValueError, match="color = 'spectral'"):
        fit(model, rgb, init=model.Params(color="spectral"))
    with pytest.raises(ValueError, match="wavelengths"):
        model.Params(wavelengths=(500.0, -1.0))
