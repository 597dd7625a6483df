"""Spectra -> XYZ -> sRGB against colour-science's own implementation."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.core import spectral as sp

colour = pytest.importorskip("colour")

# colour-science warns when it resamples a distribution to its CMF/illuminant shape
pytestmark = pytest.mark.filterwarnings("ignore:Aligning")

D65 = colour.SDS_ILLUMINANTS["D65"]


def _sd(wl, values):
    return colour.SpectralDistribution(dict(zip(np.asarray(wl, float), np.asarray(values, float))))


def _test_spectra(wl):
    # smooth, bounded reflectances: a ramp, a bump, an oscillation
    return np.stack([
        0.1 + 0.8 * (wl - 360.0) / 470.0,
        0.05 + 0.9 * np.exp(-0.5 * ((wl - 530.0) / 40.0) ** 2),
        0.5 + 0.4 * np.sin(wl / 37.0),
    ])


def test_wavelength_grid_and_rgb_wavelengths():
    g = sp.wavelength_grid()
    assert g.shape == (95,) and float(g[0]) == 360.0 and float(g[-1]) == 830.0
    assert np.allclose(np.diff(g), 5.0)
    assert sp.wavelength_grid(400, 700, 10).shape == (31,)
    assert sp.RGB_WAVELENGTHS == (650.0, 510.0, 475.0)
    with pytest.raises(ValueError):
        sp.wavelength_grid(500, 400, 5)


def test_cmfs_match_colour_table():
    cm = colour.MSDS_CMFS[sp.CMFS_NAME]
    wl = np.array([360.0, 455.0, 555.0, 700.0, 830.0])
    np.testing.assert_allclose(sp.cmfs(wl), cm[wl], rtol=1e-12)
    # between 1-nm samples: linear interpolation; outside the table: 0
    mid = sp.cmfs(555.5)
    np.testing.assert_allclose(mid, 0.5 * (cm[555.0] + cm[556.0]), rtol=1e-12)
    np.testing.assert_allclose(sp.cmfs(np.array([300.0, 900.0])), 0.0)
    assert sp.cmfs(np.zeros((4, 2))).shape == (4, 2, 3)


@pytest.mark.parametrize("step", [1.0, 5.0])
def test_reflectance_xyz_matches_colour_sd_to_xyz(step):
    wl = np.arange(360.0, 830.0 + step / 2, step)
    specs = _test_spectra(wl)
    ours = np.asarray(sp.spectrum_to_xyz(specs, wl, "D65"))
    assert ours.shape == (3, 3)
    for i, s in enumerate(specs):
        # colour's 1-nm Integration on 1-nm data; on 5-nm data its ASTM E308 method (which
        # also works on the 5-nm samples); both scale a perfect white to Y = 100
        method = "Integration" if step == 1.0 else "ASTM E308"
        ref = colour.sd_to_XYZ(_sd(wl, s), illuminant=D65, method=method) / 100.0
        np.testing.assert_allclose(ours[i], ref, rtol=1e-3)


def test_emissive_xyz_matches_colour_with_k1():
    wl = np.arange(360.0, 831.0, 1.0)
    s = _test_spectra(wl)[1] * 3.0
    ref = colour.sd_to_XYZ(_sd(wl, s), method="Integration", k=1)
    np.testing.assert_allclose(sp.spectrum_to_xyz(s, wl), ref, rtol=1e-3)
    # linear in the spectrum, no normalisation
    np.testing.assert_allclose(sp.spectrum_to_xyz(2 * s, wl), 2 * ref, rtol=1e-3)


def test_perfect_white_has_y_one_and_d65_white_is_rgb_one():
    wl = sp.wavelength_grid()
    for ill in ("D65", "A", "E"):
        xyz = sp.spectrum_to_xyz(jnp.ones_like(wl), wl, ill)
        assert float(xyz[1]) == pytest.approx(1.0, rel=1e-12)
    xyz = sp.spectrum_to_xyz(jnp.ones_like(wl), wl, "D65")
    # white point of the spectral D65 (CIE 15: x = 0.31272, y = 0.32903)
    x, y = float(xyz[0] / xyz.sum()), float(xyz[1] / xyz.sum())
    assert (x, y) == pytest.approx((0.31272, 0.32903), abs=2e-4)
    rgb = sp.xyz_to_linear_srgb(xyz)
    np.testing.assert_allclose(rgb, 1.0, atol=2e-3)
    np.testing.assert_allclose(sp.linear_to_srgb(rgb), 1.0, atol=2e-3)
    # illuminant given as an array equals the named one
    np.testing.assert_allclose(sp.spectrum_to_xyz(jnp.ones_like(wl), wl, sp.illuminant_spd("D65", wl)), xyz,
                               rtol=1e-12)


def test_xyz_to_srgb_matches_colour():
    # in-gamut colours: XYZ of random linear sRGB in [0.02, 1] (colour-science's conversion)
    rng = np.random.default_rng(3)
    rgb = rng.uniform(0.02, 1.0, (50, 3))
    xyz = colour.sRGB_to_XYZ(rgb, apply_cctf_decoding=False)
    # colour uses the 4-digit matrices printed in IEC 61966-2-1; ours are derived exactly
    # from the primaries (measured max |difference| ~1e-4)
    ours_lin = np.asarray(sp.xyz_to_linear_srgb(xyz))
    np.testing.assert_allclose(ours_lin, colour.XYZ_to_sRGB(xyz, apply_cctf_encoding=False), rtol=1e-3, atol=2e-4)
    np.testing.assert_allclose(ours_lin, rgb, rtol=1e-3, atol=2e-4)
    np.testing.assert_allclose(sp.linear_srgb_to_xyz(rgb), xyz, rtol=1e-3, atol=2e-4)
    np.testing.assert_allclose(sp.linear_to_srgb(ours_lin), colour.XYZ_to_sRGB(xyz), rtol=1e-3, atol=2e-4)


def test_transfer_function_matches_colour():
    v = np.concatenate([np.linspace(0.0, 0.01, 21), np.linspace(0.01, 1.0, 50)])
    np.testing.assert_allclose(sp.linear_to_srgb(v), colour.models.eotf_inverse_sRGB(v), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(sp.srgb_to_linear(v), colour.models.eotf_sRGB(v), rtol=1e-10, atol=1e-12)


def test_round_trips():
    rng = np.random.default_rng(5)
    rgb = rng.uniform(-0.1, 1.2, (20, 3))
    np.testing.assert_allclose(sp.xyz_to_linear_srgb(sp.linear_srgb_to_xyz(rgb)), rgb, atol=1e-12)
    v = rng.uniform(-0.1, 1.2, 200)
    np.testing.assert_allclose(sp.srgb_to_linear(sp.linear_to_srgb(v)), v, atol=1e-12)
    np.testing.assert_allclose(sp.linear_to_srgb(sp.srgb_to_linear(v)), v, atol=1e-12)
    # the transfer curve is continuous at its knee
    t = 0.0031308
    assert float(sp.linear_to_srgb(t * (1 + 1e-9))) == pytest.approx(float(sp.linear_to_srgb(t)), abs=1e-6)


def test_luminance():
    np.testing.assert_allclose(sp.luminance(jnp.ones(3)), 1.0, atol=1e-12)
    np.testing.assert_allclose(sp.LUMINANCE_WEIGHTS, [0.2126, 0.7152, 0.0722], atol=1e-4)
    rgb = np.random.default_rng(1).uniform(0, 1, (7, 3))
    np.testing.assert_allclose(sp.luminance(rgb), np.asarray(sp.linear_srgb_to_xyz(rgb))[:, 1], atol=1e-12)


def test_jit_and_gradients_finite():
    wl = sp.wavelength_grid()
    f = jax.jit(lambda s: sp.linear_to_srgb(sp.spectrum_to_linear_srgb(s, wl, "D65")))
    s = jnp.asarray(_test_spectra(np.asarray(wl)))
    assert f(s).shape == (3, 3)
    g = jax.grad(lambda s: jnp.sum(f(s)))(s)
    assert np.all(np.isfinite(np.asarray(g)))
    # the transfer curve at 0 and at its knee; wavelength derivatives of the CMF lookup
    for x in (0.0, 0.0031308, -0.5, 1.0):
        assert np.isfinite(float(jax.grad(sp.linear_to_srgb)(x)))
        assert np.isfinite(float(jax.grad(sp.srgb_to_linear)(x)))
    gw = jax.grad(lambda w: sp.cmfs(w)[1])(555.3)
    assert np.isfinite(float(gw))
    # XYZ of a linear map: the gradient of Y w.r.t. the spectrum is ybar * I * w / norm
    gy = jax.grad(lambda s: sp.spectrum_to_xyz(s, wl, "E")[1])(jnp.ones_like(wl))
    ybar = np.asarray(sp.cmfs(wl))[:, 1]
    np.testing.assert_allclose(gy, ybar / ybar.sum(), rtol=1e-10)


def test_wavelength_count_mismatch_raises():
    with pytest.raises(ValueError, match="wavelengths"):
        sp.spectrum_to_xyz(np.ones(5), np.arange(6.0) * 10 + 400)
    with pytest.raises(ValueError, match="unknown illuminant"):
        sp.spectrum_to_xyz(np.ones(3), np.array([400.0, 500.0, 600.0]), "D99")
