"""write_csv of in-plane tables whose band count is not 3 (spectral, one band)."""

import numpy as np
import pytest

from appearance_jax.fit.tables import read_csv, write_csv
from appearance_jax.fit.tables.table import Table


@pytest.mark.parametrize("wavelengths", [(450.0, 550.0, 650.0, 750.0), (550.0,)])
def test_in_plane_spectral_round_trip(tmp_path, wavelengths):
    ti = np.deg2rad([0.0, 30.0, 30.0, 60.0])
    to = np.deg2rad([10.0, -20.0, 40.0, 0.0])
    b = len(wavelengths)
    values = 0.1 + 0.01 * np.arange(4 * b, dtype=float).reshape(4, b)
    t = Table.in_plane(ti, to, values, bands=tuple(f"{w:g}" for w in wavelengths),
                       wavelengths=np.asarray(wavelengths))
    path = tmp_path / "t.csv"
    write_csv(t, path)  # in_plane=None: decided from the geometry, for any band count
    back = read_csv(path)
    assert back.is_in_plane
    np.testing.assert_allclose(back.values, values, rtol=1e-9)
    np.testing.assert_allclose(back.signed_theta_o(), to, atol=1e-9)
    np.testing.assert_allclose(back.wavelengths, wavelengths)
