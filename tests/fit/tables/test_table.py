"""Table's geometry and colour helpers (what the report reads instead of recomputing it)."""

import numpy as np
import pytest

from appearance_jax.fit.tables.grids import gonio_angles
from appearance_jax.fit.tables.table import HORIZON_COS, Table


def _gonio(dphi_deg, theta_o_deg=np.arange(0.0, 91.0, 10.0)):
    ti, pi_, to, po = gonio_angles([0.0, 30.0, 60.0], theta_o_deg, dphi_deg)
    v = np.full((ti.size, 3), 0.1)
    return Table(theta_i=ti, phi_i=pi_, theta_o=to, phi_o=po, values=v, mask=np.ones_like(v, bool))


def test_in_plane_rows_of_an_out_of_plane_table():
    t = _gonio([0.0, 90.0, 180.0])
    assert not t.is_in_plane
    rows = t.in_plane_rows()
    dphi = np.rad2deg(np.mod(t.phi_o - t.phi_i, 2 * np.pi))
    expected = np.isclose(dphi, 0.0) | np.isclose(dphi, 180.0) | (t.theta_o == 0.0)
    np.testing.assert_array_equal(rows, expected)
    # signed theta_o: defined on those rows (forward side > 0), NaN elsewhere; strict refuses the table
    s = t.signed_theta_o(strict=False)
    assert np.all(np.isnan(s[~rows])) and np.all(np.isfinite(s[rows]))
    fwd = rows & np.isclose(dphi, 180.0)
    np.testing.assert_allclose(s[fwd], t.theta_o[fwd])
    with pytest.raises(ValueError, match="in-plane"):
        t.signed_theta_o()


def test_in_plane_table_every_row_and_the_horizon():
    t = Table.in_plane(np.deg2rad([0.0, 30.0, 30.0]), np.deg2rad([10.0, -40.0, 90.0]), np.ones((3, 1)), bands=("f",))
    assert t.is_in_plane and t.in_plane_rows().all()
    np.testing.assert_array_equal(t.signed_theta_o(strict=False), t.signed_theta_o())
    np.testing.assert_array_equal(t.above_horizon(), [True, True, False])  # cos 90 deg = 6e-17
    assert np.cos(np.deg2rad(90.0)) <= HORIZON_COS


def test_linear_rgb_of_rgb_grey_and_spectral_bands():
    t = _gonio([0.0])
    f = np.arange(t.n_samples * 3, dtype=float).reshape(-1, 3)
    np.testing.assert_array_equal(t.linear_rgb(f), f)
    grey = Table.in_plane([0.1, 0.2], [0.3, -0.3], [[1.0, 3.0], [np.nan, 1.0]], bands=("a", "b"))
    np.testing.assert_array_equal(grey.linear_rgb(grey.values), [[2.0, 2.0, 2.0], [np.nan] * 3])
    wl = np.arange(400.0, 701.0, 10.0)
    spec = Table.in_plane([0.1, 0.2], [0.3, -0.3], np.full((2, wl.size), 0.5), bands=tuple(map(str, wl)),
                          wavelengths=wl)
    f = spec.values.copy()
    f[1, 3] = np.nan
    rgb = spec.linear_rgb(f)
    np.testing.assert_allclose(rgb[0], 0.5, rtol=5e-3)  # a flat spectrum is grey (truncated to 400-700 nm)
    assert np.isnan(rgb[1]).all()  # a gap in the spectrum: unknown colour
    np.testing.assert_allclose(spec.to_rgb().values, spec.linear_rgb(spec.values))
