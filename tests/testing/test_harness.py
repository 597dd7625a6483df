"""The property harness must catch broken models and pass correct ones.

Each broken model below is lambert with one deliberate defect; every check is run on it
and on the correct models, so a check that cannot fail (or fails everything) shows up here.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import testing
from appearance_jax.bsdf import lambert
from appearance_jax.core import warp
from appearance_jax.core.model import Model, as_bands, boundary, with_bands
from appearance_jax.core.params import param, params_class, static
from appearance_jax.core.rng import uniforms
from appearance_jax.phase import henyey_greenstein as hg

LAMBERT = lambert.MODEL
WHITE = lambert.Params(reflectance=1.0)
RGB = lambert.Params(reflectance=(0.2, 0.6, 0.9))


def _up(wi, wo):
    return (wi.z > 0) & (wo.z > 0)


def _model(name, eval_, sample_, pdf_, **kw):
    P = lambert.Params
    return Model(name=name, kind="bsdf", Params=P, eval=boundary(eval_, P), sample=boundary(sample_, P),
                 pdf=boundary(pdf_, P), summary="broken on purpose", source="test", **kw)


def _cos_sample(p, wi, u, weight_scale=1.0):
    u1, u2 = uniforms(u, jnp.shape(wi.z), 2)
    wo = warp.square_to_cosine_hemisphere(u1, u2)
    ok = _up(wi, wo)
    pdf = jnp.where(ok, wo.z / jnp.pi, 0.0)
    return wo, jnp.where(with_bands(ok), weight_scale * as_bands(p.reflectance), 0.0), pdf


# --- f(wi, wo) depends on wi.z only: energy conserving and consistently sampled, not reciprocal
def _nr_eval(p, wi, wo):
    return jnp.where(with_bands(_up(wi, wo)), as_bands(p.reflectance) * with_bands(0.5 + 0.5 * wi.z) / jnp.pi, 0.0)


def _nr_sample(p, wi, u):
    wo, w, pdf = _cos_sample(p, wi, u)
    return wo, w * with_bands(0.5 + 0.5 * wi.z), pdf


NON_RECIPROCAL = _model("non_reciprocal", _nr_eval, _nr_sample, lambert._pdf)


# --- cosine-distributed directions, but sample() and pdf() both claim the uniform density
def _unif_pdf(p, wi, wo):
    return jnp.where(_up(wi, wo), 0.5 / jnp.pi, 0.0)


def _ws_sample(p, wi, u):
    wo, _, _ = _cos_sample(p, wi, u)
    pdf = _unif_pdf(p, wi, wo)
    f = lambert._eval(p, wi, wo)
    return wo, f * with_bands(wo.z / jnp.where(pdf > 0, pdf, 1.0)), pdf


WRONG_SAMPLER = _model("wrong_sampler", lambert._eval, _ws_sample, _unif_pdf)

# --- correct sampler, but pdf() disagrees with the pdf that sample() returns
PDF_MISMATCH = _model("pdf_mismatch", lambert._eval, lambert._sample, _unif_pdf)

# --- weight is not f cos / pdf
WEIGHT_MISMATCH = _model("weight_mismatch", lambert._eval, lambda p, wi, u: _cos_sample(p, wi, u, 1.1),
                         lambert._pdf)

# --- creates energy: f = 1.5 rho / pi, consistently sampled (albedo 1.5 rho)
ENERGY = _model("energy_creating", lambda p, wi, wo: 1.5 * lambert._eval(p, wi, wo),
                lambda p, wi, u: _cos_sample(p, wi, u, 1.5), lambert._pdf)


# --- fails 20% of its samples (pdf 0, weight 0) but pdf() still claims the full density
def _fail_sample(p, wi, u):
    u1, u2, u3 = uniforms(u, jnp.shape(wi.z), 3)
    wo, w, pdf = _cos_sample(p, wi, (u1, u2))
    keep = u3 >= 0.2
    return wo, jnp.where(with_bands(keep), w, 0.0), jnp.where(keep, pdf, 0.0)


LOSES_SAMPLES = _model("loses_samples", lambert._eval, _fail_sample, lambert._pdf)


# ----------------------------------------------------------------------------------
# reciprocity


@pytest.mark.parametrize("model,params", [(LAMBERT, RGB), (hg.MODEL, hg.Params(g=0.8))])
def test_reciprocity_passes_correct_models(model, params):
    r = testing.check_reciprocity(model, params, key=1)
    assert r.passed, r.message
    assert r.max_abs_error <= r.atol + r.rtol * r.max_value
    assert r.max_value > 0  # the pairs were not all outside the support


def test_reciprocity_catches_non_reciprocal_model():
    r = testing.check_reciprocity(NON_RECIPROCAL, RGB, key=1)
    assert not r.passed
    assert "FAILED" in r.message and "non_reciprocal" in r.message
    # f differs by 0.5 |wi.z - wo.z| rho / pi: far above rounding
    assert r.max_rel_error > 0.1
    with pytest.raises(AssertionError, match="reciprocity FAILED"):
        testing.assert_reciprocity(NON_RECIPROCAL, RGB, key=1)


def test_non_reciprocal_model_passes_the_other_checks():
    """Specificity: its sampler and energy are fine, so only reciprocity may fail."""
    assert testing.check_white_furnace(NON_RECIPROCAL, WHITE, key=2, n_theta=32, n_phi=64).passed
    assert testing.check_sampling(NON_RECIPROCAL, WHITE, key=2, n_samples=4096).passed


# ----------------------------------------------------------------------------------
# white furnace


def test_furnace_lossless_lambert():
    r = testing.assert_white_furnace(LAMBERT, WHITE, key=3, lossless=True, n_theta=32, n_phi=64)
    np.testing.assert_allclose(r.albedo_quad, 1.0, atol=1e-12)
    np.testing.assert_allclose(r.albedo_mc, 1.0, atol=1e-12)


def test_furnace_albedo_equals_reflectance():
    r = testing.assert_white_furnace(LAMBERT, RGB, key=3, n_theta=32, n_phi=64)
    np.testing.assert_allclose(r.albedo_quad, np.broadcast_to([0.2, 0.6, 0.9], r.albedo_quad.shape), atol=1e-12)


def test_furnace_catches_energy_creation():
    r = testing.check_white_furnace(ENERGY, WHITE, key=3, n_theta=32, n_phi=64)
    assert not r.passed
    assert "A_mc > 1" in r.message and "A_quad > 1" in r.message
    np.testing.assert_allclose(r.max_albedo, 1.5, rtol=1e-9)


def test_furnace_catches_a_lossy_model_claimed_lossless():
    r = testing.check_white_furnace(LAMBERT, lambert.Params(reflectance=0.99), key=3, lossless=True,
                                    n_theta=32, n_phi=64)
    assert not r.passed and "lossless" in r.message


def test_furnace_catches_biased_weights():
    # E[weight] = int (f cos / (1/2pi)) cos/pi dw = 4/3 rho: MC and quadrature disagree
    r = testing.check_white_furnace(WRONG_SAMPLER, RGB, key=3, n_theta=32, n_phi=64)
    assert not r.passed and "|A_mc - A_quad|" in r.message
    np.testing.assert_allclose(r.albedo_mc[:, 0], 4 / 3 * 0.2, rtol=0.05)


def test_furnace_flags_an_unconverged_quadrature():
    r = testing.check_white_furnace(hg.MODEL, hg.Params(g=0.95), key=3, lossless=True, n_theta=16, n_phi=16)
    assert not r.passed and "not converged" in r.message


def test_furnace_monte_carlo_error_is_honest():
    """HG with band-valued g: weights vary, the MC albedo is 1 within its standard error."""
    r = testing.assert_white_furnace(hg.MODEL, hg.Params(g=(-0.4, 0.2, 0.6)), key=4, lossless=True,
                                     n_samples=4096, n_theta=64, n_phi=64)
    z = np.abs(r.albedo_mc - 1.0) / r.se_mc
    assert np.all(r.se_mc > 0) and np.max(z) < r.k
    np.testing.assert_allclose(r.albedo_quad, 1.0, atol=1e-6)


# ----------------------------------------------------------------------------------
# sample / pdf consistency


def test_sampling_passes_lambert():
    r = testing.assert_sampling(LAMBERT, RGB, key=5, n_samples=4096)
    assert r.max_weight_rel_error < 1e-12 and r.max_pdf_rel_error < 1e-12 and r.failed_fraction == 0


@pytest.mark.parametrize("model,needle", [
    (PDF_MISMATCH, "sample pdf != pdf(wi, wo)"),
    (WEIGHT_MISMATCH, "weight != f cos / pdf"),
    (WRONG_SAMPLER, "importance-sampled and uniform estimates differ"),
])
def test_sampling_catches_inconsistent_samplers(model, needle):
    r = testing.check_sampling(model, RGB, key=5, n_samples=4096)
    assert not r.passed
    assert needle in r.message, r.message
    with pytest.raises(AssertionError):
        testing.assert_sampling(model, RGB, key=5, n_samples=4096)


def test_sampling_catches_samples_lost_without_compensation():
    """Failing 20% of samples while pdf() claims the full density biases the estimate by -20%."""
    r = testing.check_sampling(LOSES_SAMPLES, RGB, key=5, n_samples=4096)
    assert not r.passed and "importance-sampled and uniform estimates differ" in r.message
    # the failed samples themselves are well-formed (pdf 0, weight 0): no other complaint
    assert "failed samples" not in r.message and r.max_weight_rel_error < 1e-12
    assert abs(r.failed_fraction - 0.2) < 5 * math.sqrt(0.2 * 0.8 / r.n_samples / 8)
    np.testing.assert_allclose(r.estimate_is / r.estimate_uniform, 0.8, atol=5 * r.se_is.max() / 0.2 + 0.02)


# ----------------------------------------------------------------------------------
# chi-square


@pytest.mark.parametrize("model,params", [(LAMBERT, RGB), (hg.MODEL, hg.Params(g=0.9)),
                                          (hg.MODEL, hg.Params(g=-0.5))])
def test_chi2_passes_correct_samplers(model, params):
    r = testing.assert_chi2(model, params, key=6, n_samples=2**17, n_wi=2)
    np.testing.assert_allclose(r.pdf_integral, 1.0, atol=1e-4)
    assert np.all(r.observed.sum(axis=(1, 2)) == r.n_samples)


@pytest.mark.parametrize("model,needle", [
    (WRONG_SAMPLER, "chi2 ="),
    (PDF_MISMATCH, "chi2 ="),
    (LOSES_SAMPLES, "sampled fraction"),
])
def test_chi2_catches_wrong_samplers(model, needle):
    r = testing.check_chi2(model, RGB, key=6, n_samples=2**16, n_wi=2)
    assert not r.passed and needle in r.message, r.message


def test_chi2_catches_a_subtly_wrong_hg():
    """A sampler of HG(0.85 g) checked against the pdf of HG(g): 15% error in g."""

    def bad_sample(p, wi, u):
        return hg._sample(hg.Params(g=0.85 * p.g), wi, u)

    bad = Model(name="hg_bad", kind="phase", Params=hg.Params, eval=hg.eval, sample=boundary(bad_sample, hg.Params),
                pdf=hg.pdf, summary="", source="", transmissive=True)
    assert not testing.check_chi2(bad, hg.Params(g=0.5), key=6, n_samples=2**16, n_wi=2).passed


def test_chi2_statistics_helpers():
    # chi-square with 2 dof: P(X > x) = exp(-x / 2)
    np.testing.assert_allclose(testing.chi2_pvalue(3.0, 2), math.exp(-1.5), rtol=1e-10)
    # pooling: cells expecting < 5 are merged into one bin (kept if it reaches 5, else
    # merged into the smallest cell); the totals are kept
    obs, exp = np.array([10, 1, 0, 2, 30]), np.array([12.0, 1.5, 1.0, 2.0, 28.0])
    o, e = testing.pool_cells(obs, exp, 5.0)
    np.testing.assert_allclose(e, [16.5, 28.0]) and np.testing.assert_array_equal(o, [13, 30])
    obs, exp = np.array([10, 4, 3, 30]), np.array([12.0, 3.0, 3.0, 28.0])
    o, e = testing.pool_cells(obs, exp, 5.0)
    np.testing.assert_allclose(e, [12.0, 28.0, 6.0]) and np.testing.assert_array_equal(o, [10, 30, 7])
    # Sidak: 1 - (1 - a)^(1/n); and its normal quantile
    np.testing.assert_allclose(testing.sidak(0.05, 10), 1 - 0.95**0.1, rtol=1e-12)
    np.testing.assert_allclose(testing.z_threshold(0.05, 1), 1.959964, rtol=1e-6)


# ----------------------------------------------------------------------------------
# gradients


@jax.custom_jvp
def _bad_scale(r):
    return r / jnp.pi


@_bad_scale.defjvp
def _bad_scale_jvp(primals, tangents):
    (r,), (dr,) = primals, tangents
    return r / jnp.pi, 2.0 * dr / jnp.pi  # wrong by a factor of 2


@params_class
class _OptParams:
    a: object = param(0.5, lo=0.0, hi=1.0, bands=True)
    b: object = param(None, lo=0.0, hi=1.0)
    c: object = param((0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6, 1.7, 1.8))
    mode: str = static("x", choices=("x", "y"))


def _pairs():
    wi = testing.random_directions(7, 16, "upper")
    wo = testing.random_directions(8, 16, "upper")
    return wi, wo


def test_gradients_pass_lambert():
    wi, wo = _pairs()
    w = jnp.linspace(0.5, 2.0, 16)[:, None]
    r = testing.assert_gradients(lambda p: jnp.sum(w * lambert.eval(p, wi, wo) ** 2), RGB, name="lambert")
    assert r.leaves == (".reflectance",) and max(r.rel_error) < 1e-7


def test_gradients_catch_a_wrong_derivative():
    wi, wo = _pairs()
    r = testing.check_gradients(lambda p: jnp.sum(_bad_scale(as_bands(p.reflectance)) * wi.z[:, None]), RGB)
    assert not r.passed and ".reflectance" in r.message
    np.testing.assert_allclose(r.rel_error[0], 0.5, rtol=1e-6)  # AD = 2 FD


def test_gradients_skip_none_and_static_fields_and_probe_large_leaves():
    p = _OptParams()
    r = testing.assert_gradients(lambda q: jnp.sum(jnp.sin(q.c) * q.a) + jnp.sum(q.c**3), p, max_elements=8)
    assert r.leaves == (".a", ".c")  # b is None, mode is static
    assert len(r.ad[1]) == 4  # 18 elements > max_elements: 4 random directions


def test_gradients_of_arrays_fields_steps_and_supplied_derivatives():
    """Array-valued fn (Jacobian, forward and reverse), a subset of fields, per-field steps, the
    elementwise tolerance, derivatives supplied by grad_fn; unknown names raise."""
    x = {"a": 0.3, "b": jnp.array([1.0, 2.0, 3.0])}
    fn = lambda d: jnp.sin(d["a"] * d["b"]) + d["b"] ** 2  # noqa: E731
    for mode in ("fwd", "rev"):
        r = testing.assert_gradients(fn, x, mode=mode, elementwise=True, rtol=1e-8)
        assert r.leaves == ("['a']", "['b']") and r.ad[1].shape == (3, 3)
    r = testing.assert_gradients(fn, x, fields="b", step={"b": 1e-6}, rtol=1e-8)
    assert r.leaves == ("['b']",)
    g = jax.grad(lambda d: jnp.sum(fn(d)))(x)
    assert testing.check_gradients(lambda d: jnp.sum(fn(d)), x, grad_fn=lambda d: g).passed
    wrong = {"a": 2.0 * g["a"], "b": g["b"]}
    r = testing.check_gradients(lambda d: jnp.sum(fn(d)), x, grad_fn=lambda d: wrong)
    assert not r.passed and "['a']" in r.message and "['b']" not in r.message.split("Problems")[1]
    for kw in (dict(fields=("c",)), dict(step={"c": 1e-6})):
        with pytest.raises(ValueError, match="not leaves"):
            testing.check_gradients(fn, x, **kw)


def test_gradients_of_sampled_directions_hg():
    """Sampled HG directions are reparameterised: d wo / d g checked by FD with fixed uniforms."""
    wi = testing.random_directions(9, 64, "sphere")
    u = tuple(jax.random.uniform(k, (64,), jnp.float64) for k in jax.random.split(jax.random.key(9)))
    tgt = testing.random_directions(10, 64, "sphere")

    def fn(p):
        wo, _, _ = hg.sample(p, wi, u)
        return jnp.sum(wo.x * tgt.x + wo.y * tgt.y + wo.z * tgt.z)

    for g in (-0.6, 0.0, 1e-7, 0.7):
        testing.assert_gradients(fn, hg.Params(g=g))


def test_random_directions_domains():
    for dom, sign in (("upper", 1), ("lower", -1)):
        w = testing.random_directions(11, 1000, dom, min_cos=0.2)
        assert np.all(sign * np.asarray(w.z) >= 0.2)
        np.testing.assert_allclose(np.asarray(w.x**2 + w.y**2 + w.z**2), 1.0, atol=1e-12)
    w = testing.random_directions(11, 20000, "sphere")
    # uniform on the sphere: <z> = 0, <z^2> = 1/3, standard errors 1/sqrt(3n), sqrt(4/45/n)
    assert abs(float(jnp.mean(w.z))) < 5 / math.sqrt(3 * 20000)
    assert abs(float(jnp.mean(w.z**2)) - 1 / 3) < 5 * math.sqrt(4 / 45 / 20000)


def test_harness_accepts_any_model_like_object():
    """The public API needs only the Model fields, not the Model class."""

    class MyModel:
        name, kind, transmissive = "mine", "bsdf", False
        eval, sample, pdf = staticmethod(lambert.eval), staticmethod(lambert.sample), staticmethod(lambert.pdf)

    assert testing.check_reciprocity(MyModel, RGB, n=64).passed
    assert testing.check_sampling(MyModel, RGB, n_samples=1024, n_wi=2).passed
