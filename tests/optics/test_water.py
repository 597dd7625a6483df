"""Water index for rainbows (Sadeghi 2011 Table 3.2; seed-002 spec §1.1.5, decisions D-R1, D-R2)."""

import jax
import numpy as np
import pytest

from appearance_jax.optics import water
from appearance_jax.optics.refractive_index import Cauchy, Tabulated
from appearance_jax.optics.refractiveindex_yaml import load_material


def test_wavelengths_are_the_33_rainbow_samples():
    wl = water.WAVELENGTHS_NM
    assert wl.shape == (33,) and wl[0] == 380.0 and wl[-1] == 700.0  # L1296's "720" is a typo
    np.testing.assert_array_equal(np.diff(wl), 10.0)
    assert water.TABLE_3_2_ETA.shape == (33,)


def test_table_spot_values_and_text_values():
    eta = dict(zip(water.WAVELENGTHS_NM, water.TABLE_3_2_ETA))
    assert eta[380.0] == 1.3406 and eta[400.0] == 1.339 and eta[550.0] == 1.333
    assert eta[630.0] == 1.3318 and eta[650.0] == 1.331 and eta[700.0] == 1.331
    # the thesis text (L1057-1062) differs from its own table
    assert water.ETA_TEXT_700NM == 1.3314 and water.ETA_TEXT_400NM == 1.3445


def test_table_is_hale_querry_linearly_interpolated():
    # "derived from [HQ73]": exactly the linear interpolation of Hale & Querry's 25 nm,
    # three-decimal table (hence its plateaus), not an independent rounding.
    hq = load_material("water_H2O_Hale")
    np.testing.assert_allclose(hq(water.WAVELENGTHS_NM)[0], water.TABLE_3_2_ETA, atol=1e-12)


def test_water_ior_table_interpolates_linearly():
    assert isinstance(water.water_model(), Tabulated)
    np.testing.assert_allclose(water.water_ior(water.WAVELENGTHS_NM), water.TABLE_3_2_ETA, rtol=0, atol=1e-15)
    assert float(water.water_ior(385.0)) == pytest.approx(0.5 * (1.3406 + 1.3398), abs=1e-15)
    assert float(water.water_ior(652.5, model="table")) == pytest.approx(1.331, abs=1e-15)
    assert water.water_ior(np.full((2, 3), 500.0)).shape == (2, 3)


@pytest.mark.parametrize("model, coeffs, max_res", [
    ("cauchy3", water.CAUCHY3_COEFFICIENTS, 4.3e-4),
    ("cauchy2", water.CAUCHY2_COEFFICIENTS, 4.2e-4),
])
def test_cauchy_fits(model, coeffs, max_res):
    m = water.water_model(model)
    assert isinstance(m, Cauchy)
    wl = water.WAVELENGTHS_NM
    eta = np.asarray(water.water_ior(wl, model=model))
    # the spec's coefficients are in lambda [um] (the library's Cauchy unit): check by hand
    lam = wl * 1e-3
    by_hand = coeffs[0] + coeffs[1] / lam**2 + (coeffs[2] / lam**4 if len(coeffs) > 2 else 0.0)
    np.testing.assert_allclose(eta, by_hand, rtol=0, atol=1e-14)
    res = np.abs(eta - water.TABLE_3_2_ETA)
    assert res.max() <= max_res
    # they are the least-squares fits to Table 3.2
    a = np.stack([lam ** (-2 * j) for j in range(len(coeffs))], axis=1)
    lsq = np.linalg.lstsq(a, water.TABLE_3_2_ETA, rcond=None)[0]
    np.testing.assert_allclose(lsq, coeffs, rtol=2e-5)
    # normal dispersion: strictly decreasing in wavelength, smooth derivative
    fine = np.linspace(380.0, 700.0, 321)
    assert np.all(np.diff(np.asarray(water.water_ior(fine, model=model))) < 0)
    d = jax.vmap(jax.grad(lambda w: water.water_ior(w, model=model)))(fine)
    assert np.all(np.asarray(d) < 0)


def test_out_of_range_and_unknown_model():
    for model in water.MODELS:
        with pytest.raises(ValueError, match=r"water.*720 nm.*\[380, 700\] nm"):
            water.water_ior(720.0, model=model)
    with pytest.raises(ValueError, match=r"'sellmeier'.*'table', 'cauchy3', 'cauchy2'"):
        water.water_ior(500.0, model="sellmeier")


def test_jit_clamps():
    f = jax.jit(lambda w: water.water_ior(w))
    assert float(f(720.0)) == pytest.approx(1.331)
    assert float(f(550.0)) == pytest.approx(1.333)
