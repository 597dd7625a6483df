"""Composite BSDFs (sums of lobes): eval/pdf/sample against the components, the field naming
rule, validation messages, gradients, the property harness, and the registry's "a+b" names."""

import dataclasses
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import registry, testing
from appearance_jax.bsdf import lambert, rough_conductor, rough_plastic
from appearance_jax.bsdf.sum import DEFENSIVE_FRACTION, lobe_probabilities, sum_model
from appearance_jax.core.vec import Vec3

CL = registry.get("rough_conductor+lambert")
RC, LAM = rough_conductor.MODEL, lambert.MODEL

# non-default values for every field of rough_conductor+lambert (1-band diffuse + 3-band specular)
RC_KW = dict(alpha=0.23, alpha_v=0.41, eta=(0.3, 0.9, 1.4), k=(3.1, 2.2, 1.6), specular_reflectance=(0.7, 0.5, 0.3),
             distribution="beckmann", shadowing="separable")
LAM_KW = dict(reflectance=0.35)


def _dirs(key, n, lower_fraction=0.1):
    """Random unit directions, mostly upper hemisphere, some below the horizon."""
    v = jax.random.normal(jax.random.key(key), (3, n), dtype=jnp.float64)
    v = v / jnp.linalg.norm(v, axis=0)
    z = jnp.abs(v[2]) * jnp.where(jnp.arange(n) < int(lower_fraction * n), -1.0, 1.0)
    return Vec3(v[0], v[1], z)


WI, WO = _dirs(0, 400), _dirs(1, 400)


def _close(a, b, tol=1e-12):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape
    np.testing.assert_allclose(a, b, rtol=tol, atol=tol * max(np.abs(b).max(), 1e-300))


# ----------------------------------------------------------------------------------------
# eval / pdf are the components'


def test_eval_is_the_sum_of_the_components():
    p = CL.Params(**RC_KW, **LAM_KW)
    f = CL.eval(p, WI, WO)
    ref = rough_conductor.eval(rough_conductor.Params(**RC_KW), WI, WO) + lambert.eval(lambert.Params(**LAM_KW), WI, WO)
    assert f.shape == (400, 3)  # 1-band lambert broadcast against 3-band conductor
    assert np.all(np.asarray(f)[:40] == 0)  # wi below the horizon
    _close(f, ref)


def test_eval_rough_plastic_plus_lambert():
    m = registry.get("rough_plastic+lambert")
    kw_rp = dict(alpha=0.3, diffuse_reflectance=(0.2, 0.4, 0.6), specular_reflectance=0.8, eta=1.7)
    p = m.Params(**kw_rp, reflectance=(0.1, 0.2, 0.05))
    ref = rough_plastic.eval(rough_plastic.Params(**kw_rp), WI, WO) \
        + lambert.eval(lambert.Params(reflectance=(0.1, 0.2, 0.05)), WI, WO)
    _close(m.eval(p, WI, WO), ref)


def test_two_conductor_lobes_have_their_own_parameters():
    m = registry.get("rough_conductor+rough_conductor")
    p = m.Params(alpha=0.1, specular_reflectance=0.6, rough_conductor_1_alpha=0.7,
                 rough_conductor_1_distribution="beckmann", rough_conductor_1_eta=(1.2, 1.0, 0.8))
    a, b = p.split()
    assert float(a.alpha) == 0.1 and float(b.alpha) == 0.7 and b.distribution == "beckmann" and a.distribution == "ggx"
    np.testing.assert_array_equal(np.asarray(b.eta), [1.2, 1.0, 0.8])
    ref = rough_conductor.eval(a, WI, WO) + rough_conductor.eval(b, WI, WO)
    _close(m.eval(p, WI, WO), ref)
    # pdf: the lobe-probability mixture of the components' pdfs
    p0, p1 = lobe_probabilities([RC, RC], [a, b])
    np.testing.assert_allclose([float(p0), float(p1)],
                               [(1 - DEFENSIVE_FRACTION) * 0.6 / 1.6 + DEFENSIVE_FRACTION / 2,
                                (1 - DEFENSIVE_FRACTION) * 1.0 / 1.6 + DEFENSIVE_FRACTION / 2], rtol=1e-14)
    _close(m.pdf(p, WI, WO), p0 * rough_conductor.pdf(a, WI, WO) + p1 * rough_conductor.pdf(b, WI, WO))


def test_jacobian_apart_fields_carry_their_composite_names():
    """Each component's Model.jacobian_apart reaches the sum under the field's composite name (a
    colliding field is prefixed); a name that is not a field of the Params is refused eagerly."""
    assert registry.get("rough_conductor+rough_conductor").jacobian_apart == (
        "specular_reflectance", "rough_conductor_1_specular_reflectance")
    assert registry.get("rough_plastic+lambert").jacobian_apart == (
        "diffuse_reflectance", "specular_reflectance", "reflectance")
    with pytest.raises(ValueError, match=r"jacobian_apart names \['albedo'\].*reflectance"):
        dataclasses.replace(lambert.MODEL, jacobian_apart=("albedo",))


def test_fixing_values_reproduces_each_component():
    rc_only = CL.Params(**RC_KW, reflectance=0.0)
    lam_only = CL.Params(**{**RC_KW, "specular_reflectance": 0.0}, reflectance=0.8)
    _close(CL.eval(rc_only, WI, WO), rough_conductor.eval(rough_conductor.Params(**RC_KW), WI, WO))
    _close(CL.eval(lam_only, WI, WO), jnp.broadcast_to(lambert.eval(lambert.Params(reflectance=0.8), WI, WO),
                                                        (400, 3)))
    # the zero lobe keeps only the defensive probability: the pdf is (almost) the other lobe's
    eps2 = DEFENSIVE_FRACTION / 2
    _close(CL.pdf(lam_only, WI, WO), (1 - eps2) * lambert.pdf(lambert.Params(), WI, WO)
           + eps2 * rough_conductor.pdf(rough_conductor.Params(**RC_KW), WI, WO))
    # all lobes at zero: equal probabilities
    zero = CL.Params(specular_reflectance=0.0, reflectance=0.0)
    np.testing.assert_allclose([float(q) for q in lobe_probabilities([RC, LAM], zero.split())], [0.5, 0.5])


# ----------------------------------------------------------------------------------------
# the generated Params class


def test_field_union_and_collision_prefix_rule():
    assert list(CL.Params.__dataclass_fields__) == [
        "alpha", "alpha_v", "eta", "k", "specular_reflectance", "distribution", "shadowing", "reflectance"]
    m = sum_model(registry.get("rough_conductor"), registry.get("rough_plastic"))
    names = list(m.Params.__dataclass_fields__)
    # rough_plastic (component 1) loses alpha, specular_reflectance, eta, distribution, shadowing
    assert names == ["alpha", "alpha_v", "eta", "k", "specular_reflectance", "distribution", "shadowing",
                     "rough_plastic_1_alpha", "diffuse_reflectance", "rough_plastic_1_specular_reflectance",
                     "rough_plastic_1_eta", "rough_plastic_1_distribution", "nonlinear", "rough_plastic_1_shadowing",
                     "tables"]
    assert m.Params.components == ("rough_conductor", "rough_plastic")
    assert dict(m.Params.field_map[1])["rough_plastic_1_eta"] == "eta"
    assert m.Params._static_fields == ("distribution", "shadowing", "rough_plastic_1_distribution", "nonlinear",
                                       "rough_plastic_1_shadowing", "tables")
    # same metadata as the component's field
    from appearance_jax.core.params import param_specs
    assert param_specs(m.Params)["rough_plastic_1_eta"] == param_specs(rough_plastic.Params)["eta"]
    assert m.Params.__dataclass_fields__["rough_plastic_1_eta"].default == 1.5
    # and the component's annotation: rough_conductor's eta is per band, rough_plastic's is not
    import typing

    from appearance_jax.core.params import Bands, Real
    hints = typing.get_type_hints(m.Params)
    assert hints["eta"] == Bands and hints["rough_plastic_1_eta"] == Real and hints["tables"] is str
    # the index is the position in the sum; non-identifier characters of a nested sum's name -> "_"
    m3 = sum_model(registry.get("lambert"), CL)
    assert list(m3.Params.__dataclass_fields__)[-1] == "rough_conductor_lambert_1_reflectance"
    m4 = sum_model(registry.get("lambert"), registry.get("rough_conductor"), registry.get("lambert"))
    assert list(m4.Params.__dataclass_fields__)[-1] == "lambert_2_reflectance"
    assert m4.name == "lambert+rough_conductor+lambert"


def test_params_are_keyword_only_pytrees():
    p = CL.Params(alpha=0.3, reflectance=(0.1, 0.2, 0.3))
    with pytest.raises(TypeError):
        CL.Params(0.3)
    leaves, tree = jax.tree_util.tree_flatten(p)
    assert len(leaves) == 5  # alpha_v = None is no leaf; distribution/shadowing are static
    assert jax.tree_util.tree_unflatten(tree, leaves).distribution == "ggx"
    assert float(p.replace(alpha=0.5).alpha) == 0.5
    assert repr(p).startswith("rough_conductor+lambert.Params(alpha=")


def test_params_pickle_through_the_registry():
    import copy
    import pickle

    p = CL.Params(alpha=0.3, reflectance=(0.1, 0.2, 0.3))
    q = pickle.loads(pickle.dumps(p))
    assert type(q) is CL.Params and float(q.alpha) == 0.3 and q.distribution == "ggx"
    np.testing.assert_array_equal(np.asarray(q.reflectance), [0.1, 0.2, 0.3])
    custom = sum_model(registry.get("lambert"), registry.get("lambert"), name="custom_two_lamberts")
    assert type(copy.deepcopy(custom.Params())) is custom.Params
    with pytest.raises(pickle.PicklingError):
        pickle.dumps(custom.Params())


def test_validation_names_the_composite_and_the_field():
    msg = re.escape("rough_conductor+lambert.Params.alpha = -1 is outside the valid range [0.001, 2]")
    with pytest.raises(ValueError, match=msg):
        CL.eval(CL.Params(alpha=-1.0), WI, WO)
    with pytest.raises(ValueError, match=re.escape("rough_conductor+lambert.Params.reflectance = 1.5 is outside")):
        CL.sample(CL.Params(reflectance=(0.2, 1.5, 0.1)), WI, jax.random.key(0))
    m = registry.get("rough_conductor+rough_conductor")
    with pytest.raises(ValueError, match=re.escape(
            "rough_conductor+rough_conductor.Params.rough_conductor_1_alpha = 5 is outside the valid range")):
        m.pdf(m.Params(rough_conductor_1_alpha=5.0), WI, WO)
    with pytest.raises(ValueError, match="not one of the valid choices"):
        CL.Params(distribution="phong")
    with pytest.raises(TypeError, match=re.escape("expected parameters of type rough_conductor+lambert.Params")):
        CL.eval(rough_conductor.Params(), WI, WO)
    # a component's cross-field check runs on its sub-parameters, with the composite named
    md = registry.get("lambert+rough_dielectric")
    with pytest.raises(ValueError, match=r"lambert\+rough_dielectric\.Params, component 1 \(rough_dielectric\).*"
                                         r"too close to 1"):
        md.eval(md.Params(eta=1.0), WI, WO)


# ----------------------------------------------------------------------------------------
# jit and gradients


def test_jit_and_grad_equal_the_components():
    p = CL.Params(**RC_KW, reflectance=(0.3, 0.2, 0.6))
    c = jax.random.uniform(jax.random.key(9), (400, 3), jnp.float64)

    def loss(model, q):
        return jnp.sum(c * model.eval(q, WI, WO))

    g = jax.jit(jax.grad(lambda q: loss(CL, q)))(p)
    g_rc = jax.jit(jax.grad(lambda q: loss(RC, q)))(rough_conductor.Params(**RC_KW))
    g_l = jax.jit(jax.grad(lambda q: loss(LAM, q)))(lambert.Params(reflectance=(0.3, 0.2, 0.6)))
    for name in ("alpha", "alpha_v", "eta", "k", "specular_reflectance"):
        _close(getattr(g, name), getattr(g_rc, name))
    _close(g.reflectance, g_l.reflectance)
    assert float(jnp.abs(g.alpha)) > 0
    # pdf and sample weights are differentiable too (the lobe probabilities depend on the reflectances)
    q0 = CL.Params(alpha=0.3, specular_reflectance=0.5, reflectance=(0.3, 0.2, 0.6))
    gp = jax.jit(jax.grad(lambda q: jnp.sum(CL.pdf(q, WI, WO))))(q0)
    gs = jax.jit(jax.grad(lambda q: jnp.sum(CL.sample(q, WI, jax.random.key(3))[1])))(q0)
    for gg in (gp, gs):
        assert all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree_util.tree_leaves(gg))
    assert float(jnp.abs(gp.reflectance).sum()) > 0


# ----------------------------------------------------------------------------------------
# sampling


# albedo <= 1: half-strength gold lobe + a dim diffuse lobe
P_SAMPLING = CL.Params(alpha=0.3, specular_reflectance=0.5, reflectance=(0.4, 0.2, 0.1))


def test_property_harness_rough_conductor_plus_lambert():
    testing.assert_reciprocity(CL, P_SAMPLING, key=1, n=256)
    testing.assert_sampling(CL, P_SAMPLING, key=3, n_wi=4, n_samples=2**13)
    testing.assert_chi2(CL, P_SAMPLING, key=4, n_wi=2, n_samples=2**16)
    r = testing.assert_white_furnace(CL, P_SAMPLING, key=2, n_wi=4, n_samples=2**13, n_theta=96, n_phi=192)
    assert 0.3 < r.max_albedo <= 1.0
    # a white Lambertian + a zero conductor lobe is lossless; the zero lobe is still sampled
    # (defensive fraction), so the weights vary slightly around 1
    lossless = CL.Params(alpha=0.2, specular_reflectance=0.0, reflectance=1.0)
    testing.assert_white_furnace(CL, lossless, key=2, n_wi=4, n_samples=2**13, n_theta=96, n_phi=192,
                                 lossless=True)


def test_sample_with_uniforms_picks_the_lobe():
    """With explicit uniforms, u[0] picks the lobe (u0 < p_0: the conductor) and the rest drive
    the chosen component's sampler (the key path is covered by the harness test above)."""
    p = P_SAMPLING
    p0, _ = lobe_probabilities([RC, LAM], p.split())
    n = 64
    wi = Vec3(*(jnp.full((n,), c) for c in (0.5, 0.0, np.sqrt(0.75))))
    u1, u2 = jax.random.uniform(jax.random.key(1), (2, n), jnp.float64)
    for u0, comp, sub in ((0.5 * float(p0), RC, p.split()[0]), (0.5 + 0.5 * float(p0), LAM, p.split()[1])):
        wo, w, pdf = CL.sample(p, wi, (jnp.full((n,), u0), u1, u2))
        wo_c, _, pdf_c = comp.sample(sub, wi, (u1, u2))
        ok = np.asarray(pdf_c) > 0
        for a, b in zip(wo, wo_c):
            np.testing.assert_array_equal(np.asarray(a)[ok], np.asarray(b)[ok])
        _close(np.asarray(pdf)[ok], np.asarray(CL.pdf(p, wi, wo))[ok])
        assert np.all(np.asarray(pdf)[~ok] == 0) and np.all(np.asarray(w)[~ok] == 0)
    with pytest.raises(ValueError, match=r"rough_conductor\+lambert: the sampler takes 1 uniform array for the lobe "
                                         r"choice followed by those of the components \(2 given\)"):
        CL.sample(p, wi, (0.1, 0.2))


def test_a_component_without_sampler_gives_a_composite_without_sampler():
    no_sampler = dataclasses.replace(LAM, name="lambert_eval_only", sample=None, pdf=None)
    m = sum_model(registry.get("rough_conductor"), no_sampler)
    assert m.sample is None and m.pdf is None
    assert m.Params.__dataclass_fields__["reflectance"]
    _close(m.eval(m.Params(), WI, WO), CL.eval(CL.Params(), WI, WO))


def test_flags_summary_presets():
    assert CL.kind == "bsdf" and CL.reciprocal and not CL.transmissive and dict(CL.presets) == {}
    assert "rough_conductor" in CL.summary and "lambert" in CL.summary
    assert "Cook & Torrance 1982" in CL.source and "Lambert (1760)" in CL.source
    md = registry.get("rough_dielectric+lambert")
    assert md.transmissive and not md.reciprocal
    m = sum_model(registry.get("lambert"), registry.get("lambert"), name="two_lamberts", presets={"grey": None})
    assert m.name == "two_lamberts" and list(m.presets) == ["grey"]


# ----------------------------------------------------------------------------------------
# registry and errors


def test_registry_lists_and_caches_composites():
    assert "rough_conductor+lambert" in registry.names() and "rough_plastic+lambert" in registry.names()
    assert CL in registry.models()
    a = registry.get("lambert+rough_conductor")
    assert registry.get(" lambert + rough_conductor ") is a and a is not CL
    assert "lambert+rough_conductor" not in registry.names()  # built on demand, not listed
    assert registry.get("rough_conductor + lambert") is CL
    assert registry.get("lambert") is LAM


def test_non_bsdf_component_is_rejected():
    with pytest.raises(ValueError, match="component 'henyey_greenstein' is a phase model; only BSDFs"):
        sum_model(registry.get("rough_conductor"), registry.get("henyey_greenstein"))
    with pytest.raises(ValueError, match="component 'hg_mixture' is a phase model"):
        registry.get("lambert+hg_mixture")
    with pytest.raises(ValueError, match="is not a Model record"):
        sum_model(registry.get("lambert"), 3)
    with pytest.raises(ValueError, match="is not a Model record"):
        sum_model("lambert", registry.get("lambert"))  # names are the registry's job
    with pytest.raises(ValueError, match="at least one component"):
        sum_model()
    with pytest.raises(ValueError, match="contain no '.'"):
        sum_model(registry.get("lambert"), registry.get("lambert"), name="a.b")


def test_unknown_name_in_a_sum_lists_the_registered_models():
    with pytest.raises(KeyError, match=r"unknown model 'lamber' in 'rough_conductor\+lamber'; registered models: "
                                       r".*lambert.*rough_conductor\+lambert"):
        registry.get("rough_conductor+lamber")
    with pytest.raises(KeyError, match="unknown model ''"):
        registry.get("lambert+")
    with pytest.raises(KeyError, match="unknown model 'nope'"):
        registry.get("nope+lambert")
