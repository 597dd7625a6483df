"""bsdf/cosmetics_ordinates.py: the deterministic cosmetic foundation against the random walk
(the `cosmetics` model, an independent Monte Carlo code path), in both precisions, with named
errors. Solver-level checks (HG adding-doubling, closed forms, energy, reciprocity) are in
tests/layered/test_ordinates.py; the property harness runs it through tests/test_properties.py."""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.bsdf import cosmetics
from appearance_jax.bsdf import cosmetics_ordinates as co
from appearance_jax.core.vec import Vec3

# in-plane (phi_o = 0: back towards the light; pi: the mirror side) and out-of-plane pairs
TI = np.deg2rad([0, 30, 30, 30, 60, 60, 45, 75.0])
TO = np.deg2rad([20, 30, 0, 60, 60, 20, 45, 30.0])
PO = np.array([0, 0, 0, np.pi, np.pi, np.pi / 2, 2.0, 0.5])
WI = Vec3(jnp.asarray(np.sin(TI)), jnp.asarray(0 * TI), jnp.asarray(np.cos(TI)))
WO = Vec3(jnp.asarray(np.sin(TO) * np.cos(PO)), jnp.asarray(np.sin(TO) * np.sin(PO)), jnp.asarray(np.cos(TO)))
# the presets' black base as RGB: every solver evaluation below then has the parameter shapes of
# test_thickness_zero_is_the_base (a base per band) and they share one compiled program per
# precision (compilation is most of this file's cost)
BLACK = (0.0, 0.0, 0.0)


def _walk(name, n_samples, max_bounces, key):
    p = cosmetics.PRESETS[name].replace(n_samples=n_samples, max_bounces=max_bounces, azimuth="averaged")
    f, se = cosmetics.eval(p, WI, WO, key=jax.random.key(key))
    return np.asarray(f), np.asarray(se)


def test_matte1_agrees_with_the_random_walk():
    """Matte 1 (Table A.1), azimuth averaged, 8 pairs in and out of the plane: within 3.5
    standard errors of the walk (8192 paths, 128 steps: the truncation loses < 0.05 % of
    Matte 1's signal, fitting/README.md). Measured at 16k paths: |z| <= 1.6."""
    f = np.asarray(co.eval(co.PRESETS["matte1"].replace(base_reflectance=BLACK), WI, WO))
    fw, se = _walk("matte1", 8192, 128, 3)
    z = (f - fw) / se
    assert np.all(np.abs(z) < 3.5), z


@pytest.mark.slow
@pytest.mark.parametrize("name", ["dewy1", "dewy2", "matte1", "matte2"])
def test_presets_agree_with_the_random_walk(name):
    """Dewy 1, Dewy 2 (alpha_p = 0.002: the resolvable-roughness blur of the multiply scattered
    kernels), Matte 1, Matte 2 (theta_p = 52 deg: the tilt correction; without it +3..+5 %, z up to
    7): within 3.5 standard errors of a 16k-path, 512-step walk."""
    f = np.asarray(co.eval(co.PRESETS[name], WI, WO))
    fw, se = _walk(name, 16384, 512, 3)
    z = (f - fw) / se
    assert np.all(np.abs(z) < 3.5), z


@pytest.mark.slow
def test_matte2_oriented_sample_agrees_with_the_random_walk():
    """Matte 2 with azimuth 'fixed' (the oriented sample): the tilt correction's full-azimuth
    form; within 3.5 standard errors (measured |z| <= 2.3 at 32k paths; without the correction
    up to 10)."""
    p = co.PRESETS["matte2"].replace(azimuth="fixed")
    f = np.asarray(co.eval(p, WI, WO))
    pw = cosmetics.PRESETS["matte2"].replace(n_samples=16384, max_bounces=512, azimuth="fixed")
    fw, se = cosmetics.eval(pw, WI, WO, key=jax.random.key(4))
    z = (f - np.asarray(fw)) / np.asarray(se)
    assert np.all(np.abs(z) < 3.5), z


def test_float32_matches_float64():
    """The same table in float32 (the fitting recipe's precision) and float64: 1e-4 relative
    (measured 2e-6 for Dewy 1)."""
    p = co.PRESETS["dewy1"].replace(base_reflectance=BLACK)
    f64 = np.asarray(co.eval(p, WI, WO))
    old = jax.config.jax_enable_x64
    jax.config.update("jax_enable_x64", False)
    try:
        f32 = np.asarray(co.eval(p, WI, WO))
    finally:
        jax.config.update("jax_enable_x64", old)
    assert f32.dtype == np.float32
    np.testing.assert_allclose(f32, f64, rtol=1e-4)


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="eta"):
        co.Params(eta=0.9)
    with pytest.raises(ValueError, match="thickness"):
        co.Params(thickness=-1.0)
    with pytest.raises(ValueError, match="c_d"):
        co.Params(c_d=float("nan"))
    with pytest.raises(ValueError, match="n_nodes"):
        co.Params(n_nodes=2)
    with pytest.raises(ValueError, match="azimuth"):
        co.Params(azimuth="rotated")
    with pytest.raises(ValueError, match="albedo_d"):
        co.Params(albedo_d=(0.5, 0.5))
    # a lobe the default quadrature does not resolve: a warning with the measured energy error
    with pytest.warns(UserWarning, match=r"relative energy error of 0\.06"):
        co.Params(g1=0.95)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        co.Params(g1=0.95, n_nodes=48, n_modes=64)  # resolved: no warning


def test_thickness_zero_is_the_base():
    """t = 0: exactly the Lambertian base, band by band, also with tilted platelets (Matte 1's:
    the tilt correction vanishes with the layer)."""
    p = co.PRESETS["matte1"].replace(thickness=0.0, base_reflectance=(0.2, 0.4, 0.6))
    np.testing.assert_allclose(np.asarray(co.eval(p, WI, WO)),
                               np.broadcast_to(np.array([0.2, 0.4, 0.6]) / np.pi, (TI.size, 3)), rtol=1e-12)


@pytest.mark.slow
def test_gradients_agree_with_the_walks_score_function_estimates():
    """d/dc_d and d/dalpha of sum f over the pairs (Matte 1): the solver's exact derivative vs
    the walk's unbiased autodiff estimate (score terms; 8 keys x 4096 paths, 64 steps), within 3.5
    standard errors of the walk's mean derivative."""
    p = co.PRESETS["matte1"]
    names = ("c_d", "alpha")

    def solver(v):
        return co.MODEL.eval.kernel(p.replace(**dict(zip(names, v))), WI, WO).sum()

    g = np.asarray(jax.grad(solver)(jnp.array([p.c_d, p.alpha])))
    pw = cosmetics.PRESETS["matte1"].replace(n_samples=4096, max_bounces=64, azimuth="averaged")

    @jax.jit
    def walk_grad(key):
        def fn(v):
            return cosmetics.MODEL.eval.kernel(pw.replace(**dict(zip(names, v))), WI, WO, key)[0].sum()
        return jax.grad(fn)(jnp.array([pw.c_d, pw.alpha]))

    gw = np.array([np.asarray(walk_grad(jax.random.key(100 + k))) for k in range(8)])
    mean, se = gw.mean(0), gw.std(0, ddof=1) / np.sqrt(len(gw))
    assert np.all(np.abs(g - mean) < 3.5 * se), (g, mean, se)
