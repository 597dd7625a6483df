"""The appearance-jax table v1 CSV schema: round trips, missing samples and every error message."""

import re

import numpy as np
import pytest

from appearance_jax.fit.tables.csv_table import TableError, read_csv, write_csv
from appearance_jax.fit.tables.table import Table

HEAD = "# appearance-jax table v1\n# quantity: brdf\n"
RF = "# quantity: reflectance_factor\n"
SIG = "theta_i,theta_o,R,G,B,sigma_R,sigma_G,sigma_B\n"
FULL = "theta_i,phi_i,theta_o,phi_o,R,G,B\n"


def _write(tmp_path, text, name="x.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _assert_same(a: Table, b: Table):
    np.testing.assert_allclose(b.theta_i, a.theta_i, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.theta_o, a.theta_o, rtol=0, atol=1e-9)
    # azimuths compared on the circle
    for x, y in ((a.phi_i, b.phi_i), (a.phi_o, b.phi_o)):
        d = np.mod(x - y + np.pi, 2 * np.pi) - np.pi
        assert np.all(np.abs(d) < 1e-9)
    np.testing.assert_array_equal(b.mask, a.mask)
    np.testing.assert_allclose(b.values, a.values, rtol=1e-8, atol=0, equal_nan=True)
    if a.sigma is None:
        assert b.sigma is None
    else:
        np.testing.assert_allclose(np.where(a.mask, b.sigma, 0), np.where(a.mask, a.sigma, 0), rtol=1e-8, atol=0)
        assert np.all(np.isnan(b.sigma[~a.mask]))
    assert b.quantity == a.quantity
    assert b.white_reference == a.white_reference
    assert b.bands == a.bands
    if a.wavelengths is None:
        assert b.wavelengths is None
    else:
        np.testing.assert_array_equal(b.wavelengths, a.wavelengths)


def _rng_table(rng, n, **kw):
    ti = np.deg2rad(rng.uniform(0, 89, n))
    to = np.deg2rad(rng.uniform(0, 89, n))
    pi_ = rng.uniform(0, 2 * np.pi, n)
    po = rng.uniform(0, 2 * np.pi, n)
    b = len(kw.get("bands", ("R", "G", "B")))
    return Table(theta_i=ti, phi_i=pi_, theta_o=to, phi_o=po, values=rng.uniform(0, 3, (n, b)),
                 mask=np.ones((n, b), bool), **kw)


# ------------------------------------------------------------------------ round trips
def test_round_trip_rgb_full_geometry(tmp_path):
    t = _rng_table(np.random.default_rng(0), 50, quantity="reflectance_factor", white_reference=0.97,
                   source="gonio run 7")
    p = tmp_path / "rgb.csv"
    write_csv(t, p)
    text = p.read_text()
    assert text.startswith("# appearance-jax table v1\n# quantity: reflectance_factor\n# white_reference: 0.97\n")
    assert "# source: gonio run 7" in text
    assert "theta_i,phi_i,theta_o,phi_o,R,G,B\n" in text
    back = read_csv(p)
    _assert_same(t, back)
    assert back.source == str(p) and back.masked == {} and not back.is_in_plane


def test_round_trip_in_plane_signed(tmp_path):
    ti = np.deg2rad(np.repeat([0.0, 15.0, 30.0, 60.0], 7))
    to = np.deg2rad(np.tile([-80.0, -30.0, -5.5, 0.0, 12.25, 30.0, 85.0], 4))
    vals = np.random.default_rng(1).uniform(0.01, 1, (ti.size, 3))
    t = Table.in_plane(ti, to, vals, quantity="cosine_weighted_brdf")
    p = tmp_path / "plane.csv"
    write_csv(t, p)
    lines = p.read_text().splitlines()
    assert "theta_i,theta_o,R,G,B" in lines
    assert any(ln.startswith("15,-80,") for ln in lines)
    back = read_csv(p)
    _assert_same(t, back)
    assert back.is_in_plane
    np.testing.assert_allclose(back.signed_theta_o(), to, atol=1e-12)
    # the signed convention: theta_o > 0 forward (phi_o = 180 deg), < 0 retro side (phi_o = 0)
    np.testing.assert_allclose(back.phi_o, np.where(to >= 0, np.pi, 0.0))
    # and forcing the full geometry on the same table round trips too
    write_csv(t, p, in_plane=False)
    assert "theta_i,phi_i,theta_o,phi_o,R,G,B" in p.read_text()
    _assert_same(t, read_csv(p))


def test_in_plane_auto_keeps_full_geometry_when_plane_is_rotated(tmp_path):
    # in the plane of incidence, but at phi_i = 90 deg: the in-plane file would lose that azimuth
    t = Table(theta_i=np.deg2rad([30.0, 30.0]), phi_i=np.deg2rad([90.0, 90.0]), theta_o=np.deg2rad([20.0, 40.0]),
              phi_o=np.deg2rad([270.0, 90.0]), values=np.ones((2, 3)), mask=np.ones((2, 3), bool))
    assert t.is_in_plane
    p = tmp_path / "rot.csv"
    write_csv(t, p)
    _assert_same(t, read_csv(p))
    write_csv(t, p, in_plane=True)  # explicit: isotropic rotation to phi_i = 0
    back = read_csv(p)
    np.testing.assert_allclose(back.signed_theta_o(), np.deg2rad([20.0, -40.0]))


def test_round_trip_spectral_with_sigma_and_missing(tmp_path):
    rng = np.random.default_rng(2)
    wl = np.array([400.0, 452.5, 500.0, 550.0, 700.0])
    t = _rng_table(rng, 30, bands=("400", "452.5", "500", "550", "700"), wavelengths=wl)
    mask = rng.uniform(size=t.values.shape) > 0.2
    t = t.replace(mask=mask, sigma=rng.uniform(0, 0.01, t.values.shape),
                  masked={"missing value": int((~mask).sum())})
    p = tmp_path / "spec.csv"
    write_csv(t, p)
    header = [ln for ln in p.read_text().splitlines() if ln.startswith("theta_i")][0]
    assert header == ("theta_i,phi_i,theta_o,phi_o,400,452.5,500,550,700,"
                      "sigma_400,sigma_452.5,sigma_500,sigma_550,sigma_700")
    back = read_csv(p)
    _assert_same(t, back)
    assert back.spectral and back.masked == {"missing value": int((~mask).sum())}
    assert np.all(np.isnan(back.values[~mask]))  # missing stays missing, never zero


def test_round_trip_keeps_values_and_sigma_to_9_digits(tmp_path):
    t = Table.in_plane(np.deg2rad([10.0, 20.0]), np.deg2rad([-10.0, 20.0]),
                       np.array([[1.0 / 3, 2e-7, 12345.678901], [np.pi, 0.0, 1e-300]]),
                       sigma=np.full((2, 3), 1.0 / 7))
    p = tmp_path / "digits.csv"
    write_csv(t, p)
    back = read_csv(p)
    np.testing.assert_allclose(back.values, t.values, rtol=5e-9)
    np.testing.assert_allclose(back.sigma, t.sigma, rtol=5e-9)


def test_missing_values_masked_and_counted(tmp_path):
    p = _write(tmp_path, HEAD + "theta_i,phi_i,theta_o,phi_o,R,G,B,sigma_R,sigma_G,sigma_B\n"
               "30,0,30,180,0.1,0.2,0.3,0.01,0.01,0.01\n"
               "30,0,40,180,,nan,NaN,,,\n"
               "# a comment between rows\n"
               "\n"
               "30,0,50,180, NA ,0.2,0.3,0.5,0.01,0.01\n")
    t = read_csv(p)
    assert t.n_samples == 3
    np.testing.assert_array_equal(t.mask, [[1, 1, 1], [0, 0, 0], [0, 1, 1]])
    assert t.masked == {"missing value": 1, "missing value (whole row)": 3}
    assert np.all(np.isnan(t.values[~t.mask])) and np.all(np.isnan(t.sigma[~t.mask]))
    assert "1 missing value, 3 missing value (whole row)" in t.summary()


def test_reflectance_factor_to_brdf(tmp_path):
    p = _write(tmp_path, "# quantity: reflectance_factor\n# instrument: test\n" + FULL + "30,0,30,180,0.5,1,2\n")
    t = read_csv(p)
    assert t.white_reference == 0.99
    f, _ = t.brdf()
    np.testing.assert_allclose(f, [[0.99 * 0.5 / np.pi, 0.99 / np.pi, 0.99 * 2 / np.pi]], rtol=1e-15)
    # an explicit white reference is used instead
    p = _write(tmp_path, "# quantity: reflectance_factor\n# white_reference: 0.95\n" + FULL + "30,0,30,180,1,1,1\n")
    np.testing.assert_allclose(read_csv(p).brdf()[0], 0.95 / np.pi)


def test_phi_360_is_0_and_stored_in_radians(tmp_path):
    p = _write(tmp_path, HEAD + FULL + "45,360,60,180,1,1,1\n90,90,0,270,1,1,1\n")
    t = read_csv(p)
    np.testing.assert_allclose(t.phi_i, [0.0, np.pi / 2], atol=1e-15)
    np.testing.assert_allclose(t.theta_i, [np.pi / 4, np.pi / 2])
    np.testing.assert_allclose(t.phi_o, [np.pi, 1.5 * np.pi])


def test_columns_in_any_order_and_crlf(tmp_path):
    p = tmp_path / "x.csv"
    p.write_bytes(b"# quantity: brdf\r\nB,theta_o,G,theta_i,R\r\n0.3,-20,0.2,10,0.1\r\n")
    t = read_csv(p)
    assert t.bands == ("R", "G", "B")
    np.testing.assert_allclose(t.values, [[0.1, 0.2, 0.3]])
    np.testing.assert_allclose(t.signed_theta_o(), [np.deg2rad(-20)])


# ------------------------------------------------------------------------ errors
BAD = [
    # (file text, line, regex of the problem)
    ("", 1, "empty file"),
    ("\n  \n", 1, "empty file"),
    (FULL + "30,0,30,180,1,1,1\n", 1, re.escape("missing header line '# quantity: ...' (one of brdf, "
                                              "cosine_weighted_brdf, reflectance_factor)")),
    ("# appearance-jax table v1\n# quantity: radiance\n" + FULL, 2, "unknown quantity 'radiance'"),
    ("# appearance-jax table v2\n# quantity: brdf\n" + FULL, 1, "unsupported schema version 'v2'"),
    (HEAD + "# quantity: brdf\n" + FULL, 3, "second '# quantity:' line"),
    (HEAD + FULL + "# quantity: brdf\n", 4, "must come before the column header"),
    (RF + "# white_reference: 99\n" + FULL, 2, r"white_reference = 99 is outside \(0, 1\]"),
    (RF + "# white_reference: 0\n" + FULL, 2, r"white_reference = 0 is outside \(0, 1\]"),
    (RF + "# white_reference: high\n" + FULL, 2, "white_reference = 'high' is not a number"),
    ("# quantity: brdf\n# white_reference: 0.99\n" + FULL, 2, "only meaningful for quantity reflectance_factor"),
    (HEAD + "# only comments\n", 3, "no column header line"),
    (HEAD + FULL, 3, "no data rows after the column header"),
    (HEAD + "\n" + FULL + "\n# nothing\n", 4, "no data rows"),
    (HEAD + "theta_i,phi_i,theta_o,phi_o,R,G,B,foo\n", 3,
     re.escape("unknown column 'foo' (expected theta_i, phi_i, theta_o, phi_o, value columns R,G,B or "
               "wavelengths in nm, optional sigma_<band>)")),
    (HEAD + "theta_i,phi_i,phi_o,R,G,B\n", 3, "missing column theta_o"),
    (HEAD + "theta_i,R,G,B\n", 3, "missing column theta_o"),
    (HEAD + "R,G,B\n", 3, "missing columns theta_i, theta_o"),
    (HEAD + "theta_i,theta_o\n", 3, "no value columns"),
    (HEAD + "theta_i,theta_o,R,G\n", 3, "without column B"),
    (HEAD + "theta_i,theta_o,R,G,B,R\n", 3, "column 'R' appears twice"),
    (HEAD + "theta_i,theta_o,R,G,B,550\n", 3, r"mixes RGB columns \(R, G, B\) and spectral columns \(550\)"),
    (HEAD + "theta_i,theta_o,500,450\n", 3, "strictly increasing: '450' after '500'"),
    (HEAD + "theta_i,theta_o,500,500.0\n", 3, "strictly increasing"),
    (HEAD + "theta_i,theta_o,-5,450\n", 3, "not a positive number of nm"),
    (HEAD + "theta_i,theta_o,R,G,B,sigma_R,sigma_G,sigma_X\n", 3,
     "sigma column 'sigma_X' without its value column 'X'"),
    (HEAD + "theta_i,theta_o,450,500,sigma_450,sigma_600\n", 3, "sigma column 'sigma_600' without its value column"),
    (HEAD + "theta_i,theta_o,R,G,B,sigma_R\n", 3, "missing sigma columns sigma_G, sigma_B"),
    (HEAD + "theta_i;theta_o;R;G;B\n", 3, "separated by commas"),
    (HEAD + "30,0,30,180,1,1,1\n", 3, "looks like data"),
    (HEAD + FULL + "30,0,30,180,1,1,1\n30,0,40,180,1,1\n", 5, "row has 6 cells, expected 7"),
    (HEAD + FULL + "30,0,30,180,1,1,1,\n", 4, "row has 8 cells, expected 7"),
    (HEAD + FULL + "abc,0,30,180,1,1,1\n", 4, "theta_i = 'abc' is not a number"),
    (HEAD + FULL + "30,0,30,180,1,x1,1\n", 4, "G = 'x1' is not a number"),
    (HEAD + FULL + "30,0,30,180,1,1,1\n\n# c\n30,0,95,180,1,1,1\n", 7, r"theta_o = 95 is outside \[0, 90\] degrees"),
    (HEAD + FULL + "-1,0,30,180,1,1,1\n", 4, r"theta_i = -1 is outside \[0, 90\] degrees"),
    (HEAD + FULL + "30,361,30,180,1,1,1\n", 4, r"phi_i = 361 is outside \[0, 360\] degrees"),
    (HEAD + FULL + "30,0,30,-10,1,1,1\n", 4, r"phi_o = -10 is outside \[0, 360\] degrees"),
    (HEAD + "theta_i,theta_o,R,G,B\n30,-91,1,1,1\n", 4, r"theta_o = -91 is outside \[-90, 90\] degrees"),
    (HEAD + "theta_i,theta_o,R,G,B\n-30,30,1,1,1\n", 4, r"theta_i = -30 is outside \[0, 90\] degrees"),
    (HEAD + FULL + "30,,30,180,1,1,1\n", 4, "phi_i is empty"),
    (HEAD + FULL + "30,0,nan,180,1,1,1\n", 4, "theta_o is 'nan'"),
    (HEAD + FULL + "30,0,inf,180,1,1,1\n", 4, "theta_o = inf is not finite"),
    (HEAD + FULL + "30,0,30,180,1,-inf,1\n", 4, "G = -inf is not finite"),
    (HEAD + SIG + "30,30,1,1,1,0.1,,0.1\n", 4, "sigma_G is empty"),
    (HEAD + SIG + "30,30,1,1,1,0.1,NaN,0.1\n", 4, "sigma_G is 'NaN'"),
    (HEAD + SIG + "30,30,1,1,1,0.1,inf,0.1\n", 4, "sigma_G = inf is not finite"),
    (HEAD + SIG + "30,30,1,1,1,0.1,-0.1,0.1\n", 4, "sigma_G = -0.1 is negative"),
    (HEAD + FULL + "30,0,30,180,1,1,1\n10,0,10,0,1,1,1\n# again\n30,360,30,180.0000000000001,2,2,2\n", 7,
     re.escape("duplicate of line 4 (same theta_i, phi_i, theta_o, phi_o)")),
    (HEAD + "theta_i,theta_o,R,G,B\n30,-20,1,1,1\n30,20,1,1,1\n30,-20.0,1,1,1\n", 6,
     re.escape("duplicate of line 4 (same theta_i, theta_o)")),
]


@pytest.mark.parametrize("text,line,problem", BAD, ids=[f"{i}-{b[2][:30]}" for i, b in enumerate(BAD)])
def test_malformed_raises_with_file_and_line(tmp_path, text, line, problem):
    p = _write(tmp_path, text, name="bad_table.csv")
    with pytest.raises(TableError, match="^" + re.escape(f"{p}:{line}: ") + ".*" + problem):
        read_csv(p)


def test_non_utf8_file(tmp_path):
    p = tmp_path / "latin1.csv"
    p.write_bytes(HEAD.encode() + b"# sample: \xe9chantillon\n" + FULL.encode())
    with pytest.raises(TableError, match="^" + re.escape(f"{p}:3: not UTF-8 text (byte 0xe9)")):
        read_csv(p)


def test_table_error_is_a_value_error():
    assert issubclass(TableError, ValueError)


def test_error_message_uses_path_as_given(tmp_path, monkeypatch):
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "x.csv").write_text(HEAD + FULL + "30,0,30,180,1,1,1\n30,0,95,180,1,1,1\n")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(TableError, match=r"^data/x\.csv:5: theta_o = 95 is outside \[0, 90\] degrees$"):
        read_csv("data/x.csv")


def test_write_rejects_unwritable_tables(tmp_path):
    t = Table.in_plane([0.1], [0.2], np.ones((1, 1)), bands=("Y",))
    with pytest.raises(ValueError, match="neither R, G, B nor wavelengths"):
        write_csv(t, tmp_path / "y.csv")
    t = _rng_table(np.random.default_rng(3), 4)
    with pytest.raises(ValueError, match="in-plane"):
        write_csv(t, tmp_path / "y.csv", in_plane=True)
    t = Table.in_plane([0.1], [0.2], np.ones((1, 3)), sigma=np.array([[0.1, np.nan, 0.1]]))
    with pytest.raises(ValueError, match="finite sigma"):
        write_csv(t, tmp_path / "y.csv")
    below = Table.in_plane([0.1, 0.2], [0.2, 1.8], np.ones((2, 3)))  # wo below the horizon
    with pytest.raises(ValueError, match="1 rows have angles outside"):
        write_csv(below, tmp_path / "y.csv")
    write_csv(below.select([0]), tmp_path / "y.csv")
    assert read_csv(tmp_path / "y.csv").n_samples == 1
    with pytest.raises(ValueError, match="no samples"):
        write_csv(below.select(np.zeros(2, bool)), tmp_path / "y.csv")


def _docstring_examples():
    import appearance_jax.fit.tables.csv_table as mod

    blocks = re.findall(r"::\n\n((?:    .*\n)+)", mod.__doc__)
    return ["".join(ln[4:] + "\n" for ln in b.splitlines()) for b in blocks]


def test_docstring_examples_are_valid_tables(tmp_path):
    full, plane = _docstring_examples()
    t = read_csv(_write(tmp_path, full, name="example.csv"))
    assert t.quantity == "reflectance_factor" and t.white_reference == 0.99
    assert t.n_samples == 4 and t.masked == {"missing value": 1} and not t.mask[2, 0]
    assert t.sigma is not None and not t.is_in_plane  # the last row is out of the plane
    t = read_csv(_write(tmp_path, plane, name="plane.csv"))
    assert t.is_in_plane and t.spectral and t.bands == ("450", "550", "650")
    np.testing.assert_allclose(np.rad2deg(t.signed_theta_o()), [-30, 0, 30])
