"""read_table: one text spec -> Table (CSV, MERL .binary, Neural-BRDF proxy), with clear errors."""

import importlib.util

import numpy as np
import pytest

from appearance_jax.fit.tables import io
from appearance_jax.fit.tables.csv_table import TableError
from appearance_jax.fit.tables.grids import MERL_SHAPE
from appearance_jax.fit.tables.io import DEFAULT_MERL_STRIDE, read_table, write_table
from appearance_jax.fit.tables.table import Table

HAVE_PROXY = importlib.util.find_spec("appearance_jax.fit.tables.proxy") is not None
needs_proxy = pytest.mark.skipif(not HAVE_PROXY, reason="appearance_jax.fit.tables.proxy (Neural-BRDF proxies) not installed yet")


def _table():
    ti, to = np.meshgrid(np.deg2rad([0.0, 30.0]), np.deg2rad([-40.0, 0.0, 40.0]), indexing="ij")
    v = np.arange(18, dtype=float).reshape(6, 3) / 100 + 0.01
    v[2, 1] = np.nan
    return Table.in_plane(ti.ravel(), to.ravel(), v, mask=np.isfinite(v), source="t", masked={"missing value": 1})


def test_csv_round_trip_and_case_insensitive_extension(tmp_path):
    t = _table()
    for name in ("a.csv", "b.CSV"):
        p = tmp_path / name
        write_table(t, p)
        r = read_table(str(p))
        assert r.source == str(p)
        assert r.is_in_plane and r.quantity == "brdf"
        np.testing.assert_array_equal(r.mask, t.mask)
        np.testing.assert_allclose(r.values[r.mask], t.values[t.mask], rtol=1e-8)
        np.testing.assert_allclose(r.signed_theta_o(), t.signed_theta_o(), atol=1e-12)
    assert read_table(tmp_path / "a.csv").n_samples == 6  # path-like accepted


def test_csv_errors_come_from_the_reader(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("# quantity: brdf\ntheta_i,theta_o,R,G,B\n30,10,0.1,x,0.3\n")
    with pytest.raises(TableError, match=r"bad\.csv:3:"):
        read_table(str(p))


def test_missing_file_names_the_path(tmp_path):
    for name in ("nope.csv", "nope.binary"):
        p = str(tmp_path / name)
        with pytest.raises(FileNotFoundError, match="nope"):
            read_table(p)
        try:
            read_table(p)
        except FileNotFoundError as e:
            assert p in str(e)


def test_directory_is_not_a_table(tmp_path):
    d = tmp_path / "x.csv"
    d.mkdir()
    with pytest.raises(ValueError, match="directory"):
        read_table(str(d))


@pytest.mark.parametrize("spec", ["table.txt", "table", "merl:white-fabric", "", "proxy"])
def test_unknown_form_lists_the_accepted_forms(spec):
    with pytest.raises(ValueError) as e:
        read_table(spec)
    msg = str(e.value)
    assert ".csv" in msg and ".binary" in msg and "proxy:NAME" in msg


def test_stride_checks(tmp_path):
    p = tmp_path / "a.csv"
    write_table(_table(), p)
    with pytest.raises(ValueError, match="stride"):
        read_table(str(p), stride=3)
    for bad in (0, -1, 2.5, True):
        with pytest.raises(ValueError, match="stride"):
            read_table(str(tmp_path / "x.binary"), stride=bad)


def test_binary_dispatch_uses_default_stride(tmp_path, monkeypatch):
    from appearance_jax.fit.tables import merl

    p = tmp_path / "m.binary"
    p.write_bytes(b"")
    calls = []
    monkeypatch.setattr(merl, "read_merl_table", lambda path, stride: calls.append((path, stride)) or "T")
    assert read_table(str(p)) == "T"
    assert read_table(str(p), stride=5) == "T"
    assert calls == [(str(p), DEFAULT_MERL_STRIDE), (str(p), 5)]
    assert DEFAULT_MERL_STRIDE == 3 and all(n % DEFAULT_MERL_STRIDE == 0 for n in MERL_SHAPE)


def test_binary_file_is_read(tmp_path):
    from appearance_jax.fit.tables.merl import BELOW_HORIZON, write_merl

    brdf = np.empty(MERL_SHAPE + (3,))
    brdf[:] = (0.3, 0.2, 0.1)
    p = tmp_path / "const.binary"
    write_merl(p, brdf)
    t = read_table(str(p), stride=45)  # 2 x 2 x 4 nodes
    assert t.n_samples == 16 and t.bands == ("R", "G", "B") and t.quantity == "brdf"
    np.testing.assert_allclose(t.values[t.mask.all(axis=1)], np.tile([0.3, 0.2, 0.1], (int(t.mask.all(axis=1).sum()), 1)))
    assert set(t.masked) <= {BELOW_HORIZON}


def test_corrupt_binary_is_a_table_error(tmp_path):
    p = tmp_path / "short.binary"
    p.write_bytes(b"\x00\x01")
    with pytest.raises(TableError, match="short.binary"):
        read_table(str(p))


@needs_proxy
def test_proxy_grids():
    g = read_table("proxy:white-fabric")
    assert g.source.startswith("proxy:white-fabric") and "gonio" in g.source and not g.is_in_plane
    ip = read_table("proxy:white-fabric:in_plane")
    assert ip.is_in_plane
    # 5 x 5 x 10 nodes: the table of test_report's MERL-grid test, so the proxy's evaluation on it is one
    # compiled program for both (the gonio and in-plane grids are test_proxy's)
    m = read_table("proxy:white-fabric:merl", stride=18)
    assert m.n_samples == 250 and "stride 18" in m.source


@needs_proxy
def test_proxy_errors():
    with pytest.raises(ValueError, match="white-fabric"):  # unknown name: close matches, as a ValueError
        read_table("proxy:white-fabrik")
    with pytest.raises(ValueError, match="gonio, in_plane, merl"):
        read_table("proxy:white-fabric:polar")
    with pytest.raises(ValueError, match="merl grid only"):
        read_table("proxy:white-fabric:in_plane", stride=5)
    with pytest.raises(ValueError, match="proxy:NAME"):
        read_table("proxy:")
    with pytest.raises(ValueError, match="proxy:NAME"):
        read_table("proxy:a:b:c")


def test_module_documents_forms():
    assert "proxy:NAME" in io.__doc__ and "DEFAULT_MERL_STRIDE" in io.__doc__
