"""Strict inputs (issue 19): parameter values checked at construction, checkify under jit,
fitter start values, and direction arguments at the public boundary."""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.experimental import checkify

from appearance_jax import registry
from appearance_jax.bsdf import rough_conductor as rc
from appearance_jax.core.params import (ParamSpec, check_traced, checked, param_specs, replace_unchecked,
                                        validate)
from appearance_jax.core.vec import UNIT_TOLERANCE, Vec3, as_direction, vec3

W = vec3(0.0, 0.0, 1.0)
W2 = vec3(0.6, 0.0, 0.8)


# ----------------------------------------------------------------------------------------
# construction


@pytest.mark.parametrize("kw, match", [
    (dict(alpha=float("nan")), r"rough_conductor\.Params\.alpha = nan is not finite; valid range \[0\.001, 2\]"),
    (dict(alpha=-1.0), r"rough_conductor\.Params\.alpha = -1 is outside the valid range \[0\.001, 2\]"),
    (dict(k=(1.0, np.inf, 2.0)), r"rough_conductor\.Params\.k = inf is not finite"),
    (dict(alpha="x"), r"rough_conductor\.Params\.alpha = 'x' is not numeric \(str\): expected a real number"),
    (dict(alpha={}), r"rough_conductor\.Params\.alpha = \{\} is not numeric \(dict\)"),
    (dict(eta=[1.0, "a", 2.0]), r"rough_conductor\.Params\.eta = \[1\.0, 'a', 2\.0\] is not numeric"),
    (dict(alpha=jnp.array(0.1 + 1j)), r"rough_conductor\.Params\.alpha has dtype complex\d+: expected a real"),
])
def test_construction_rejects_bad_values_naming_class_field_value_and_range(kw, match):
    with pytest.raises(ValueError, match=match):
        rc.Params(**kw)


def test_band_fields_must_agree_on_their_length_and_scalars_broadcast():
    with pytest.raises(ValueError, match=re.escape(
            "rough_conductor.Params.k has 3 bands (trailing axis) but rough_conductor.Params.eta has 2")):
        rc.Params(eta=(1.0, 2.0))
    with pytest.raises(ValueError, match=r"specular_reflectance has 4 bands .*\.eta has 3"):
        rc.Params(specular_reflectance=np.full((5, 4), 0.5))
    # a scalar, a length-1 axis and leading (spatial) axes broadcast
    rc.Params(eta=1.5, k=(2.0,), specular_reflectance=np.full((5, 3), 0.5))
    # replace() checks too
    with pytest.raises(ValueError, match="eta has 2"):
        rc.Params().replace(eta=(1.0, 2.0))


def test_model_band_count_is_checked_at_construction():
    snake = registry.get("snake")
    with pytest.raises(ValueError, match=r"snake\.Params\.kd has 2 values .* computes on 3 wavelengths"):
        snake.Params(kd=(0.1, 0.2), sigma_a=(0.1, 0.2))


def _first_float_field(Params):
    p = Params()
    for name, spec in param_specs(Params).items():
        if isinstance(spec, ParamSpec) and getattr(p, name) is not None:
            return name, getattr(p, name)
    raise AssertionError(f"{Params} has no numeric field")


@pytest.mark.parametrize("name", registry.names())
def test_every_registered_model_rejects_nan_at_construction(name):
    m = registry.get(name)
    field, default = _first_float_field(m.Params)
    bad = np.array(default, dtype=float)
    bad.flat[0] = np.nan
    with pytest.raises(ValueError, match=rf"\.{field} = nan is not finite"):
        m.Params(**{field: bad})


@pytest.mark.parametrize("name", registry.names())
def test_every_registered_model_constructs_under_jit_vmap_and_from_pytree_rebuilds(name):
    m = registry.get(name)
    p = m.Params()
    data = {n: getattr(p, n) for n in m.Params._data_fields if getattr(p, n) is not None}
    statics = {n: getattr(p, n) for n in m.Params._static_fields}
    built = jax.jit(lambda d: m.Params(**d, **statics))(data)  # traced construction
    assert jax.tree_util.tree_structure(built) == jax.tree_util.tree_structure(p)
    # vmap axis specs (ints and None), abstract values and sentinels rebuild without checks
    spec = jax.tree.map(lambda _: 0, p)
    batched = jax.tree.map(lambda x: jnp.stack([x, x]), p)
    out = jax.vmap(lambda q: q, in_axes=(spec,))(batched)
    assert jax.tree_util.tree_all(jax.tree.map(lambda a, b: bool(jnp.all(a == b)), out, p))
    jax.tree.map(lambda _: None, p)
    jax.tree.map(lambda _: object(), p)
    jax.eval_shape(lambda q: q, p)


def test_presets_are_checked_and_a_per_field_vmap_axis_spec_works():
    for name in registry.names():
        for preset in registry.get(name).presets.values():
            validate(preset)
    p = rc.Params()
    axes = jax.tree_util.tree_map_with_path(lambda k, _: 0 if k[0].name == "alpha" else None, p)
    f = jax.vmap(lambda q: rc.eval(q, W2, W2), in_axes=(axes,))(p.replace(alpha=jnp.array([0.1, 0.2, 0.4])))
    np.testing.assert_allclose(np.asarray(f[1]), np.asarray(rc.eval(rc.Params(alpha=0.2), W2, W2)), rtol=1e-6)


def test_traced_construction_under_grad_and_vmap_over_a_batched_field():
    g = jax.grad(lambda a: rc.eval(rc.Params(alpha=a), W2, W2).sum())(0.3)
    assert np.isfinite(float(g)) and float(g) != 0.0
    f = jax.vmap(lambda a: rc.eval(rc.Params(alpha=a), W2, W2))(jnp.array([0.1, 0.2, 0.4]))
    assert f.shape == (3, 3)
    # a Jacobian w.r.t. the parameters is a Params of blocks of any shape: rebuilt, not checked
    jac = jax.jacfwd(lambda q: rc.eval(q, W2, W2))(rc.Params())
    assert jac.eta.shape == (3, 3) and np.isnan(np.asarray(jac.alpha)).sum() == 0


def test_rebuilt_pytrees_are_still_checked_at_the_boundary():
    bad = jax.tree.map(lambda x: -x, rc.Params())  # unflattened: no construction checks
    with pytest.raises(ValueError, match=r"rough_conductor\.Params\.alpha = -0\.1 is outside"):
        rc.eval(bad, W, W)
    with pytest.raises(ValueError, match=r"\.alpha = -0\.1 is outside"):
        validate(bad)
    validate(rc.Params())
    with pytest.raises(ValueError, match=r"rough_conductor\.Params\.k has 3 bands .*\.eta has 2"):
        rc.pdf(replace_unchecked(rc.Params(), eta=(1.0, 2.0)), W, W)
    with pytest.raises(TypeError, match="has no field"):
        replace_unchecked(rc.Params(), alhpa=0.1)


# ----------------------------------------------------------------------------------------
# checkify under jit


def test_check_traced_reports_the_named_field_under_checkify_jit():
    def f(a, wi, wo):
        p = rc.Params(alpha=a)
        check_traced(p)
        return rc.eval(p, wi, wo)

    run = checkify.checkify(jax.jit(f))
    err, out = run(jnp.float32(jnp.nan), W, W)
    assert re.search(r"rough_conductor\.Params\.alpha = nan is not finite or outside the valid range \[0\.001, 2\]",
                     err.get())
    err, out = run(jnp.float32(0.3), W, W)
    assert err.get() is None and np.all(np.asarray(out) > 0)
    err, _ = checkify.checkify(jax.jit(jax.vmap(lambda a: f(a, W, W))))(jnp.array([0.2, 3.0]))
    assert re.search(r"alpha = 3(\.0)? is not finite or outside", err.get())


def test_checked_raises_named_value_errors_and_passes_valid_parameters():
    g = checked(lambda p, wi, wo: rc.eval(p, wi, wo))
    negative_bands = jax.tree.map(lambda x: -x if x.ndim else x, rc.Params())  # rebuilt: not checked yet
    with pytest.raises(ValueError, match=r"rough_conductor\.Params\.eta = -0\.155\d* is not finite or outside"):
        g(negative_bands, W, W)
    ok = g(rc.Params(), W2, W2)
    assert np.array_equal(np.asarray(ok), np.asarray(rc.eval(rc.Params(), W2, W2)))


def test_check_traced_rejects_band_mismatch_while_tracing():
    with pytest.raises(ValueError, match="k has 3 bands"):
        jax.jit(lambda e: check_traced(jax.tree.map(lambda x: x, rc.Params()).replace(eta=e)))(jnp.ones(2))


# ----------------------------------------------------------------------------------------
# fitters: start values, fixed values and presets are checked before anything is compiled


def _table():
    from appearance_jax.fit.tables.table import Table
    ti, to = np.meshgrid(np.deg2rad([10.0, 40.0]), np.deg2rad([-30.0, 0.0, 20.0, 50.0]))
    return Table.in_plane(ti.ravel(), to.ravel(), np.full((ti.size, 3), 0.1), source="tiny")


def test_fit_rejects_out_of_range_fixed_and_start_values_eagerly():
    from appearance_jax.fit.solve import fit
    with pytest.raises(ValueError, match=r"rough_conductor\.Params\.alpha = -1 is outside the valid range"):
        fit("rough_conductor", _table(), fix={"alpha": -1})
    with pytest.raises(ValueError, match=r"alpha = nan is not finite"):
        fit("rough_conductor", _table(), init=rc.Params(alpha=float("nan")))
    rebuilt = jax.tree.map(lambda x: x * np.nan, rc.Params())  # escapes construction checks
    with pytest.raises(ValueError, match=r"rough_conductor\.Params\.alpha = nan is not finite"):
        fit("rough_conductor", _table(), init=rebuilt)


def test_fitted_parameters_stay_inside_their_declared_ranges():
    from appearance_jax.fit.solve.transforms import ParamSpace, _forward
    sp = ParamSpace(rc.Params(), 3, fix=["eta", "k"])
    for zi in jnp.linspace(-50.0, 50.0, sp.size * 7).reshape(7, sp.size):
        sp.params_from_z(zi)  # built eagerly: construction checks every value
    # an open bound is never reached, not even where sin z = -1 or exp(z) underflows to 0
    for spec, z in ((ParamSpec(0.0, 90.0, lo_open=True), -np.pi / 2), (ParamSpec(1.0, lo_open=True), -500.0),
                    (ParamSpec(hi=1.0, hi_open=True), 500.0), (ParamSpec(-1.0, 1.0, True, True), np.pi / 2)):
        x = _forward(spec, jnp.asarray(z, jnp.float32))
        assert spec.lo < float(x) < spec.hi


def test_values_are_compared_in_their_own_precision():
    cosmetics = registry.get("cosmetics")  # theta in [0, pi/2]: float32(pi/2) > pi/2 in float64
    cosmetics.Params(theta=np.float32(np.pi / 2))
    with pytest.raises(ValueError, match=r"alpha = 2\.00000024 is outside the valid range \[0\.001, 2\]"):
        rc.Params(alpha=np.nextafter(np.float32(2.0), np.float32(3.0)))


def test_replace_copy_and_pickle_keep_the_checks():
    import copy
    import pickle
    p = rc.Params(alpha=0.3)
    assert np.array_equal(np.asarray(copy.deepcopy(p).eta), np.asarray(p.eta))
    q = pickle.loads(pickle.dumps(p))
    assert float(q.alpha) == pytest.approx(0.3)
    rebuilt = jax.tree.map(lambda x: -x, p)  # unchecked: replace() checks every field again
    with pytest.raises(ValueError, match=r"\.eta = -0\.155\d* is outside"):
        rebuilt.replace(alpha=0.2)
    assert float(p.replace(alpha=0.5).alpha) == pytest.approx(0.5)


# ----------------------------------------------------------------------------------------
# directions


def test_vec3_directions_give_bit_identical_results():
    p = rc.Params(alpha=0.2)
    wi = vec3(np.array([0.0, 0.6]), 0.0, np.array([1.0, 0.8]))
    wo = vec3(np.array([0.0, -0.28]), np.array([0.0, 0.96]), np.array([1.0, 0.0]))
    ref = jax.jit(rc.eval.kernel)(p, wi, wo)
    assert np.array_equal(np.asarray(rc.eval(p, wi, wo)), np.asarray(ref))
    assert as_direction("wi", wi) is wi


def test_arrays_and_tuples_of_three_numbers_are_converted():
    p = rc.Params()
    ref = np.asarray(rc.eval(p, W2, W))
    np.testing.assert_array_equal(np.asarray(rc.eval(p, (0.6, 0.0, 0.8), (0, 0, 1))), ref)
    both = np.asarray(rc.eval(p, np.array([[0.6, 0.0, 0.8], [0.0, 0.0, 1.0]]), W))
    np.testing.assert_array_equal(both[0], ref)
    np.testing.assert_array_equal(np.asarray(rc.eval(p, jnp.array([0.6, 0.0, 0.8]), wo=W)), ref)
    assert rc.pdf(p, [0.6, 0.0, 0.8], W).shape == ()


@pytest.mark.parametrize("wo, match", [
    ("z", r"wo: expected a Vec3, an array of shape \(\.\.\., 3\) or a tuple of 3 numbers, got str"),
    ((0.0, 1.0), r"wo: expected .* got a tuple of length 2"),
    (np.zeros((3, 2)), r"wo: expected .* got an array of shape \(3, 2\)"),
    ((np.zeros(2), np.zeros(2), np.ones(2)), r"wo: .* entries are not all numbers .* Vec3\(x, y, z\)"),
])
def test_unsupported_direction_types_raise_type_errors(wo, match):
    with pytest.raises(TypeError, match=match):
        rc.eval(rc.Params(), W, wo)


@pytest.mark.parametrize("w, match", [
    (vec3(0.0, 0.0, 0.0), r"wi = \(0, 0, 0\) has zero length"),
    (vec3(np.nan, 0.0, 1.0), r"wi = \(nan, 0, 1\) is not finite"),
    (vec3(jnp.array([0.0, 0.0]), 0.0, jnp.array([1.0, 1.1])), r"wi = \(0, 0, 1\.1\) at index \(1,\) is not a unit "
                                                              r"vector: its norm is 1\.1 "),
    ((0.0, 0.0, 1.0 + 3 * UNIT_TOLERANCE), r"wi = .* is not a unit vector: its norm is 1\.003"),
])
def test_bad_directions_raise_value_errors_naming_the_argument(w, match):
    with pytest.raises(ValueError, match=match):
        rc.eval(rc.Params(), w, W)
    with pytest.raises(ValueError, match=match):
        rc.sample(rc.Params(), w, jax.random.key(0))


def test_nearly_unit_grazing_and_below_horizon_directions_are_valid():
    p = rc.Params()
    eps = 0.5 * UNIT_TOLERANCE
    assert np.all(np.isfinite(np.asarray(rc.eval(p, vec3(0.0, 0.0, 1.0 + eps), W))))
    for w in (vec3(1.0, 0.0, 0.0), vec3(0.0, 0.0, -1.0), vec3(0.6, 0.0, -0.8)):
        assert np.all(np.asarray(rc.eval(p, w, W)) == 0.0)
        assert np.all(np.asarray(rc.eval(p, W, w)) == 0.0)


def test_large_direction_arrays_are_checked_on_the_device_and_the_bad_entry_is_named():
    n = 20_000
    z = np.ones(n)
    z[12_345] = 1.01
    good = rc.eval(rc.Params(), vec3(jnp.zeros(n), jnp.zeros(n), jnp.ones(n)), W)
    assert good.shape == (n, 3)
    with pytest.raises(ValueError, match=r"wo = \(0, 0, 1\.01\) at index \(12345,\) is not a unit vector"):
        rc.eval(rc.Params(), W, vec3(jnp.zeros(n), jnp.zeros(n), jnp.asarray(z)))


def test_traced_directions_are_not_checked():
    out = jax.jit(lambda a: rc.eval(rc.Params(), Vec3.from_array(a), W))(jnp.array([0.0, 0.0, 2.0]))
    assert out.shape == (3,)
