"""MERL .binary files: layout, scale factors, missing samples, horizon masking and bin lookup.

The reference file is written here byte by byte (not with write_merl) from an analytic
pattern whose value encodes its own (channel, theta_h, theta_d, phi_d) indices, so channel
order, C order, the scale factors and the sqrt theta_h mapping are checked exactly.
"""

import re

import numpy as np
import pytest

from appearance_jax.fit.tables.csv_table import TableError
from appearance_jax.fit.tables.grids import MERL_SHAPE, merl_angles
from appearance_jax.fit.tables.merl import (
    MERL_FILE_BYTES,
    lookup,
    merl_indices,
    merl_table,
    read_merl,
    read_merl_table,
    write_merl,
)

SCALE = (1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0)  # R, G, B as published with the database
# missing samples (channel, theta_h, theta_d, phi_d): one below the horizon, the others above
MISSING = [(0, 0, 0, 0), (1, 10, 20, 30), (2, 89, 89, 179), (0, 45, 5, 90), (2, 45, 5, 90)]


def _pattern():
    """Stored values 1 + c 1e7 + i 1e5 + j 1e3 + k: exact in float64, decodable."""
    c, i, j, k = np.meshgrid(np.arange(3), np.arange(90), np.arange(90), np.arange(180), indexing="ij")
    raw = 1.0 + c * 1e7 + i * 1e5 + j * 1e3 + k
    for idx in MISSING:
        raw[idx] = -1.0
    return raw


@pytest.fixture(scope="module")
def merl_file(tmp_path_factory):
    raw = _pattern()
    path = tmp_path_factory.mktemp("merl") / "pattern.binary"
    with open(path, "wb") as f:
        f.write(np.array([90, 90, 180], dtype="<i4").tobytes())
        f.write(raw.astype("<f8").tobytes(order="C"))  # R block, then G, then B; C order inside
    assert path.stat().st_size == 12 + 3 * 90 * 90 * 180 * 8 == MERL_FILE_BYTES
    return path, raw


@pytest.fixture(scope="module")
def brdf(merl_file):
    return read_merl(merl_file[0])


def _decode(brdf_value, channel):
    """(i, j, k) of a pattern value read back in 1/sr."""
    n = int(round(brdf_value / SCALE[channel])) - 1 - channel * 10**7
    return n // 10**5, (n // 10**3) % 100, n % 1000


def _node_angles(i, j, k):
    return (np.asarray(i) / 90.0) ** 2 * (np.pi / 2), np.asarray(j) * np.pi / 180, np.asarray(k) * np.pi / 180


# ------------------------------------------------------------------------ file layout
def test_read_layout_channel_order_and_scale(merl_file, brdf):
    _, raw = merl_file
    assert brdf.shape == (90, 90, 180, 3) and brdf.dtype == np.float64
    for c in range(3):
        expected = np.where(raw[c] < 0, np.nan, raw[c] * SCALE[c])
        np.testing.assert_array_equal(brdf[..., c], expected)  # exact, NaN where missing
    # spot checks written out by hand: value of (channel, i, j, k)
    assert brdf[0, 1, 0, 0] == 1001.0 * (1.0 / 1500.0)  # theta_d = 1
    assert brdf[0, 0, 1, 0] == 2.0 * (1.0 / 1500.0)  # phi_d = 1
    assert brdf[3, 2, 1, 1] == (1.0 + 1e7 + 3e5 + 2e3 + 1) * (1.15 / 1500.0)
    assert brdf[89, 88, 178, 2] == (1.0 + 2e7 + 89e5 + 88e3 + 178) * (1.66 / 1500.0)
    assert _decode(brdf[12, 34, 56, 1], 1) == (12, 34, 56)


def test_missing_samples_become_nan(brdf):
    nan = np.argwhere(np.isnan(brdf))
    expected = sorted((i, j, k, c) for c, i, j, k in MISSING)
    assert sorted(map(tuple, nan.tolist())) == expected


def test_round_trip_write_read_exact(tmp_path, merl_file, brdf):
    path = tmp_path / "copy.binary"
    write_merl(path, brdf)
    assert path.stat().st_size == MERL_FILE_BYTES
    again = read_merl(path)
    np.testing.assert_array_equal(again, brdf)  # bit-exact, NaN included
    data = np.frombuffer(path.read_bytes(), dtype="<f8", offset=12).reshape((3,) + MERL_SHAPE)
    assert np.array_equal(np.frombuffer(path.read_bytes()[:12], "<i4"), [90, 90, 180])
    raw = merl_file[1]
    assert np.all(data[raw < 0] == -1.0)  # NaN written as the MERL missing marker
    np.testing.assert_allclose(data[raw >= 0], raw[raw >= 0], rtol=1e-15, atol=0)


def test_round_trip_arbitrary_values_within_an_ulp(tmp_path):
    f = np.random.default_rng(4).lognormal(-2, 2, MERL_SHAPE + (3,))
    f[1, 2, 3, 1] = np.nan
    f[5, 5, 5, :] = 0.0
    path = tmp_path / "random.binary"
    write_merl(path, f)
    back = read_merl(path)
    assert np.isnan(back[1, 2, 3, 1]) and np.isnan(back).sum() == 1
    np.testing.assert_allclose(back, f, rtol=3e-16, atol=0, equal_nan=True)
    assert np.all(back[5, 5, 5] == 0.0)


def test_write_merl_validates(tmp_path):
    good = np.ones(MERL_SHAPE + (3,))
    with pytest.raises(ValueError, match=re.escape("expected (90, 90, 180, 3)")):
        write_merl(tmp_path / "x.binary", np.ones((90, 90, 90, 3)))
    bad = good.copy()
    bad[0, 0, 0, 0] = -0.5
    with pytest.raises(ValueError, match="negative"):
        write_merl(tmp_path / "x.binary", bad)
    bad[0, 0, 0, 0] = np.inf
    with pytest.raises(ValueError, match="inf"):
        write_merl(tmp_path / "x.binary", bad)


# ------------------------------------------------------------------------ malformed files
def test_too_short(tmp_path):
    p = tmp_path / "short.binary"
    p.write_bytes(b"\x5a\x00\x00")
    with pytest.raises(TableError, match="^" + re.escape(f"{p}: 3 bytes, too short for the MERL header")):
        read_merl(p)


def test_wrong_header(tmp_path):
    p = tmp_path / "hdr.binary"
    p.write_bytes(np.array([180, 90, 90], "<i4").tobytes() + bytes(8 * 3 * 90 * 90 * 180))
    with pytest.raises(TableError, match="^" + re.escape(f"{p}: MERL header gives bin counts (180, 90, 90), "
                                                        "expected (90, 90, 180)")):
        read_merl(p)
    p.write_bytes(np.array([90, 90, 180], ">i4").tobytes())  # big-endian: not a MERL file
    with pytest.raises(TableError, match=re.escape("expected (90, 90, 180)")):
        read_merl(p)


def test_wrong_size(tmp_path, merl_file):
    data = merl_file[0].read_bytes()
    p = tmp_path / "cut.binary"
    p.write_bytes(data[:-8])
    with pytest.raises(TableError, match="^" + re.escape(f"{p}: file has {MERL_FILE_BYTES - 8} bytes, "
                                                        f"expected {MERL_FILE_BYTES}")):
        read_merl(p)
    p.write_bytes(data + b"\0")
    with pytest.raises(TableError, match=re.escape(f"file has {MERL_FILE_BYTES + 1} bytes")):
        read_merl(p)


def test_nan_or_inf_values(tmp_path, merl_file):
    raw = np.frombuffer(merl_file[0].read_bytes(), dtype=np.uint8).copy()
    vals = raw[12:].view("<f8")
    flat = np.ravel_multi_index((1, 2, 3, 4), (3,) + MERL_SHAPE)
    vals[flat] = np.nan
    vals[flat + 1] = np.inf
    p = tmp_path / "nan.binary"
    p.write_bytes(raw.tobytes())
    with pytest.raises(TableError, match="^" + re.escape(f"{p}: 2 NaN/inf values (first in channel G at bin "
                                                        "theta_h=2, theta_d=3, phi_d=4)")):
        read_merl(p)


# ------------------------------------------------------------------------ tables
def _above_horizon_numpy(stride):
    """wi.z, wo.z > 0 at the grid nodes, from the Rusinkiewicz construction written out."""
    th, td, pd = merl_angles(stride)
    wi_z = np.cos(th) * np.cos(td) - np.sin(th) * np.sin(td) * np.cos(pd)  # wi = R_y(theta_h) d
    wo_z = 2 * np.cos(td) * np.cos(th) - wi_z  # mirror of wi about h: wi.h = cos theta_d
    return ((wi_z > 1e-12) & (wo_z > 1e-12)).ravel()


def test_merl_table_full_resolution_masks_and_counts(merl_file, brdf):
    t = merl_table(brdf, stride=1, source="pattern")
    assert t.n_samples == 90 * 90 * 180 and t.quantity == "brdf" and t.bands == ("R", "G", "B")
    above = _above_horizon_numpy(1)
    n_below = int((~above).sum())
    assert 0 < n_below < above.size
    # every node is a row; the missing sample at (0, 0, 0) is above the horizon, the one at
    # (89, 89, 179) below it (counted there only)
    flat_missing = [np.ravel_multi_index((i, j, k), MERL_SHAPE) for _, i, j, k in MISSING]
    n_missing_above = sum(bool(above[f]) for f in flat_missing)
    assert not above[np.ravel_multi_index((89, 89, 179), MERL_SHAPE)] and n_missing_above == 4
    assert t.masked == {"below horizon": 3 * n_below, "missing (negative in MERL file)": n_missing_above}
    np.testing.assert_array_equal(t.mask, above[:, None] & np.isfinite(brdf.reshape(-1, 3)))
    assert t.n_valid == t.values.size - 3 * n_below - n_missing_above
    np.testing.assert_array_equal(t.mask[~above], False)
    valid = t.mask
    np.testing.assert_array_equal(t.values[valid], brdf.reshape(-1, 3)[valid])
    assert np.all(np.isnan(t.values[~valid]))
    assert np.all((t.theta_i >= 0) & (t.theta_o >= 0) & (t.phi_i >= 0) & (t.phi_i < 2 * np.pi))
    assert "below horizon" in t.summary()


@pytest.mark.parametrize("stride", [5, 9])
def test_merl_table_matches_lookup_at_nodes(brdf, stride):
    t = merl_table(brdf, stride=stride)
    n = (90 // stride, 90 // stride, 180 // stride)
    assert t.n_samples == np.prod(n)
    th, td, pd = merl_angles(stride)
    looked = lookup(brdf, th.ravel(), td.ravel(), pd.ravel())
    np.testing.assert_array_equal(t.values[t.mask], looked[t.mask])
    above = _above_horizon_numpy(stride)
    assert t.masked["below horizon"] == 3 * int((~above).sum())
    # the nodes really are every stride-th bin
    i, j, k = np.meshgrid(*(np.arange(0, m * stride, stride) for m in n), indexing="ij")
    for c in range(3):
        ok = t.mask[:, c]
        dec = np.array([_decode(v, c) for v in t.values[ok, c][:50]])
        np.testing.assert_array_equal(dec, np.stack([i.ravel(), j.ravel(), k.ravel()], 1)[ok][:50])


def test_merl_table_directions_round_trip_to_the_same_bins(brdf):
    """wi, wo of the table -> Rusinkiewicz angles -> lookup gives the table value back."""
    from appearance_jax.core.frame import to_half_diff

    t = merl_table(brdf, stride=5)
    th, td, pd = (a.ravel() for a in merl_angles(5))
    wi, wo = t.directions()
    h_th, _, h_td, h_pd = (np.asarray(a) for a in to_half_diff(wi, wo))
    # phi_d is undefined where theta_d = 0 and phi_h where theta_h = 0
    ok = t.mask[:, 0] & (th > 0) & (td > 0)
    np.testing.assert_array_equal(lookup(brdf, h_th, h_td, h_pd)[ok], t.values[ok])


def test_read_merl_table(merl_file):
    t = read_merl_table(merl_file[0], stride=10)
    assert t.source == str(merl_file[0]) and t.n_samples == 9 * 9 * 18


def test_merl_table_rejects_bad_input(brdf):
    with pytest.raises(ValueError, match="stride"):
        merl_table(brdf, stride=7)
    with pytest.raises(ValueError, match="shape"):
        merl_table(brdf[:, :, :90], stride=1)


# ------------------------------------------------------------------------ lookup
def test_lookup_random_nodes_return_their_bin(brdf):
    rng = np.random.default_rng(5)
    i, j, k = rng.integers(0, 90, 2000), rng.integers(0, 90, 2000), rng.integers(0, 180, 2000)
    th, td, pd = _node_angles(i, j, k)
    ii, jj, kk = merl_indices(th, td, pd)
    np.testing.assert_array_equal(ii, i)
    np.testing.assert_array_equal(jj, j)
    np.testing.assert_array_equal(kk, k)
    np.testing.assert_array_equal(lookup(brdf, th, td, pd), brdf[i, j, k])
    # every node of every axis, including those where a bare floor would fall one bin short
    n = np.arange(90)
    np.testing.assert_array_equal(merl_indices(*_node_angles(n, n, n))[0], n)
    np.testing.assert_array_equal(merl_indices(0.0, 0.0, np.arange(180) * np.pi / 180)[2], np.arange(180))


def test_lookup_inside_bins_sqrt_theta_h_mapping(brdf):
    rng = np.random.default_rng(6)
    i, j, k = rng.integers(0, 90, 500), rng.integers(0, 90, 500), rng.integers(0, 180, 500)
    u = rng.uniform(0.01, 0.99, (3, 500))  # position inside the bin
    th = ((i + u[0]) / 90.0) ** 2 * (np.pi / 2)
    td = (j + u[1]) * np.pi / 180
    pd = (k + u[2]) * np.pi / 180
    np.testing.assert_array_equal(lookup(brdf, th, td, pd), brdf[i, j, k])
    # 20 degrees of theta_h is bin floor(sqrt(20/90) * 90) = 42, not 20 (the grid is not linear)
    assert merl_indices(np.deg2rad(20.0), 0.0, 0.0)[0] == 42
    assert _decode(lookup(brdf, np.deg2rad(20.0), 0.1, 0.1)[0], 0)[0] == 42


def test_lookup_folding_and_clipping(brdf):
    th, td, pd = _node_angles(30, 40, 50)
    pd = pd + 0.25 * np.pi / 180
    base = lookup(brdf, th, td, pd)
    np.testing.assert_array_equal(lookup(brdf, th, td, pd + np.pi), base)  # reciprocity
    np.testing.assert_array_equal(lookup(brdf, th, td, pd - np.pi), base)
    np.testing.assert_array_equal(lookup(brdf, th, td, pd - 3 * np.pi), base)
    assert merl_indices(-0.1, -0.1, 0.0)[:2] == (0, 0)
    assert merl_indices(np.pi / 2, np.pi / 2, 0.0)[:2] == (89, 89)
    assert merl_indices(2.0, 2.0, 0.0)[:2] == (89, 89)
    assert merl_indices(0.0, 0.0, np.pi - 1e-12)[2] == 0  # folds onto phi_d = 0
    assert merl_indices(0.0, 0.0, np.pi - 0.5 * np.pi / 180)[2] == 179
    out = lookup(brdf, np.zeros((2, 4)), np.zeros((2, 4)), np.zeros(4))
    assert out.shape == (2, 4, 3)


def test_merl_table_to_csv_and_back(tmp_path, brdf):
    """A MERL table written in the CSV schema: valid rows only (below-horizon directions have no
    place in it) and theta_d > 0 (at theta_d = 0 every phi_d bin is the same direction pair)."""
    from appearance_jax.fit.tables.csv_table import read_csv, write_csv

    t = merl_table(brdf, stride=10)
    td = merl_angles(10)[1].ravel()
    keep = t.mask.any(axis=1) & (td > 0)
    with pytest.raises(ValueError, match="outside the schema"):
        write_csv(t, tmp_path / "all.csv")
    sub = t.select(keep)
    write_csv(sub, tmp_path / "merl.csv")
    back = read_csv(tmp_path / "merl.csv")
    np.testing.assert_allclose(back.values, sub.values, rtol=1e-8, equal_nan=True)
    np.testing.assert_array_equal(back.mask, sub.mask)
    np.testing.assert_allclose(back.theta_o, sub.theta_o, atol=1e-9)
