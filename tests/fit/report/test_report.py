"""write_report: params.json, residuals.csv and the figures of a fit, in-plane and not."""

import csv
import dataclasses
import importlib.util
import json

import numpy as np
import pytest

from appearance_jax import registry
from appearance_jax.fit.report import FIT, entry_status, write_report
from appearance_jax.fit.solve import fit
from appearance_jax.fit.tables.table import Table

TRUE_RHO = np.array([0.6, 0.4, 0.2])
HAVE_PROXY = importlib.util.find_spec("appearance_jax.fit.tables.proxy") is not None


def _lambert_plus_gloss(ti, to_signed):
    """A non-Lambertian 'measurement' (f in 1/sr, RGB): Lambert + a broad lobe at the mirror direction."""
    lobe = np.exp(-((to_signed - ti) / 0.3) ** 2)[:, None] * np.array([0.2, 0.2, 0.2])
    return TRUE_RHO / np.pi + lobe


@pytest.fixture(scope="module")
def in_plane_fit():
    ti, to = np.meshgrid(np.deg2rad([0.0, 20.0, 40.0, 60.0, 88.0]), np.deg2rad(np.arange(-80.0, 81.0, 10.0)),
                         indexing="ij")
    ti, to = ti.ravel(), to.ravel()
    v = _lambert_plus_gloss(ti, to)
    v[5, 1] = np.nan  # one missing value
    t = Table.in_plane(ti, to, v, mask=np.isfinite(v), source="synthetic in-plane", masked={"missing value": 1})
    return fit("lambert", t)


@pytest.fixture(scope="module")
def report(in_plane_fit, tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    lines = []
    paths = write_report(in_plane_fit, out, progress=lines.append, extra={"command": "appearance-jax fit x"})
    return paths, lines


def _read_residuals(path):
    with open(path) as fh:
        rows = [ln for ln in fh if not ln.startswith("#")]
    return list(csv.DictReader(rows))


def _png_size(path):
    with open(path, "rb") as fh:
        head = fh.read(24)
    assert head[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def test_files_written_and_listed(report):
    paths, lines = report
    assert set(paths) == {"params", "residuals", "maps", "slices", "scatter"}
    for p in paths.values():
        assert any(p in ln for ln in lines)
    for name in ("maps", "slices", "scatter"):
        w, h = _png_size(paths[name])
        assert 400 <= w <= 4000 and 300 <= h <= 4000, (name, w, h)


def test_pngs_decode(report):
    import matplotlib.image as mpimg

    img = mpimg.imread(report[0]["maps"])
    assert img.ndim == 3 and img.shape[2] in (3, 4)
    assert img[..., :3].std() > 0.05  # not blank


def test_params_json(report, in_plane_fit):
    r = in_plane_fit
    with open(report[0]["params"]) as fh:
        d = json.load(fh, parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}"))
    assert d["model"] == "lambert" and d["metric"] == "l2"
    got = [d["parameters"][f"reflectance[{b}]"]["value"] for b in "RGB"]
    np.testing.assert_allclose(got, r.x, rtol=1e-12)
    np.testing.assert_allclose(d["params"]["reflectance"], r.x, rtol=1e-12)
    assert d["static"] == {} and d["fixed"] == {}
    assert d["table"]["source"] == "synthetic in-plane" and d["table"]["in_plane"] is True
    assert d["table"]["masked"] == {"missing value": 1}
    assert d["entries"][FIT] == r.n_valid
    assert d["entries"]["missing value"] == 1
    assert d["entries"]["grazing (theta > 85 deg)"] == 17 * 3
    assert d["command"] == {"command": "appearance-jax fit x"}
    assert "jax" in d["environment"] and d["environment"]["x64"] is True
    assert "in-plane table" in d["figures"]["maps"]


def test_residuals_csv(report, in_plane_fit):
    r = in_plane_fit
    t = r.table
    rows = _read_residuals(report[0]["residuals"])
    assert len(rows) == t.values.size
    used = [row for row in rows if row["status"] == FIT]
    assert len(used) == r.n_valid
    idx = np.array([int(row["row"]) for row in used])
    band = np.array(["RGB".index(row["band"]) for row in used])
    fitted = np.array([float(row["fitted"]) for row in used])
    measured = np.array([float(row["measured"]) for row in used])
    np.testing.assert_allclose(fitted, r.fitted[idx, band], rtol=1e-8)
    np.testing.assert_allclose(measured, t.values[idx, band], rtol=1e-8)
    np.testing.assert_allclose([float(row["residual"]) for row in used], fitted - measured, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose([float(row["theta_o_signed"]) for row in used],
                               np.rad2deg(t.signed_theta_o()[idx]), atol=1e-8)
    missing = [row for row in rows if row["status"] == "missing value"]
    assert len(missing) == 1 and missing[0]["measured"] == "" and (missing[0]["row"], missing[0]["band"]) == ("5", "G")
    assert sum(row["status"].startswith("grazing") for row in rows) == 17 * 3
    with open(report[0]["residuals"]) as fh:
        head = [ln for ln in fh if ln.startswith("#")]
    assert any("1/sr" in ln for ln in head) and any("status" in ln for ln in head)


def test_entry_status_counts_match_the_fit(in_plane_fit):
    st = entry_status(in_plane_fit)
    assert st.shape == in_plane_fit.table.values.shape
    assert (st == FIT).sum() == in_plane_fit.n_valid


def _refit(result, table, model="lambert"):
    """result moved onto another table (same params): the report's job is drawing, not fitting."""
    m = registry.get(model)
    wi, wo = table.directions()
    f = np.broadcast_to(np.asarray(m.eval(result.params, wi, wo), np.float64), table.values.shape)
    return dataclasses.replace(result, table=table, fitted=np.array(f), n_valid=int(table.mask.sum()),
                               masked=dict(table.masked))


def _gonio(dphi_deg):
    from appearance_jax.fit.tables.grids import gonio_angles

    ti, pi_, to, po = gonio_angles([0.0, 30.0, 60.0], np.arange(0.0, 81.0, 10.0), dphi_deg)
    v = np.tile(TRUE_RHO / np.pi, (ti.size, 1)) * (1 + 0.3 * np.cos(to))[:, None]
    return Table(theta_i=ti, phi_i=pi_, theta_o=to, phi_o=po, values=v, mask=np.ones_like(v, bool), source="gonio")


def test_out_of_plane_table_uses_its_in_plane_subset(in_plane_fit, tmp_path):
    t = _gonio([0.0, 90.0, 180.0])
    assert not t.is_in_plane
    rows = t.in_plane_rows() & t.above_horizon()
    assert rows.sum() == 3 * 9 * 2 + 3  # dphi 0 and 180, plus theta_o = 0 at dphi 90
    # the in-plane fit moved onto this table (_refit), as in the tests below: a fit of its own compiled
    # a solve and its covariances only to be drawn
    paths = write_report(_refit(in_plane_fit, t), tmp_path, progress=None)
    d = json.loads(open(paths["params"]).read())
    assert "in-plane subset" in d["figures"]["maps"] and "cells" in d["figures"]["maps"]
    assert len(_read_residuals(paths["residuals"])) == t.values.size
    for name in ("maps", "slices", "scatter"):
        assert _png_size(paths[name])[0] > 400


def test_table_without_in_plane_samples_renders_the_model(in_plane_fit, tmp_path):
    t = _gonio([60.0, 90.0, 120.0])
    t = t.select(t.theta_o > 0.1)  # theta_o = 0 lies in every plane
    assert t.n_samples > 0 and (t.in_plane_rows() & t.above_horizon()).sum() == 0
    paths = write_report(_refit(in_plane_fit, t), tmp_path, progress=None)
    d = json.loads(open(paths["params"]).read())
    assert "rendered densely" in d["figures"]["maps"]
    assert "model only" in d["figures"]["slices"]
    assert _png_size(paths["maps"])[0] > 400


@pytest.mark.skipif(not HAVE_PROXY, reason="appearance_jax.fit.tables.proxy not installed yet")
def test_merl_grid_in_plane_points_are_scattered(in_plane_fit, tmp_path):
    from appearance_jax.fit.tables.proxy import proxy_table

    # stride 18: 250 MERL nodes, 102 of them in the plane, still scattered (the report's time is in
    # drawing the raster, which does not shrink with the table; stride 10 only added nodes)
    t = proxy_table("white-fabric", "merl", stride=18)
    paths = write_report(_refit(in_plane_fit, t), tmp_path, progress=None, plots=True)
    d = json.loads(open(paths["params"]).read())
    assert "scattered" in d["figures"]["maps"], d["figures"]
    rows = _read_residuals(paths["residuals"])
    assert sum(row["status"] == "below horizon" for row in rows) == t.masked["below horizon"]


def test_spectral_reflectance_factor_table(in_plane_fit, tmp_path):
    ti, to = np.meshgrid(np.deg2rad([0.0, 45.0]), np.deg2rad(np.arange(-60.0, 61.0, 20.0)), indexing="ij")
    wl = np.arange(400.0, 701.0, 50.0)
    R = np.tile(np.linspace(0.2, 0.8, wl.size), (ti.size, 1))
    t = Table.in_plane(ti.ravel(), to.ravel(), R, quantity="reflectance_factor", wavelengths=wl,
                       bands=tuple(f"{w:g}" for w in wl), sigma=0.01)
    m = registry.get("lambert")
    res = _refit(dataclasses.replace(in_plane_fit, params=m.Params(reflectance=0.99 * np.linspace(0.2, 0.8, wl.size))), t)
    paths = write_report(res, tmp_path, progress=None)
    rows = _read_residuals(paths["residuals"])
    assert len(rows) == t.values.size and {row["band"] for row in rows} == {f"{w:g}" for w in wl}
    np.testing.assert_allclose([float(row["fitted"]) for row in rows],
                               [float(row["measured"]) for row in rows], rtol=1e-8)  # exact model
    assert all(row["residual_over_sigma"] != "" for row in rows)
    assert _png_size(paths["maps"])[0] > 400


def test_needs_table_and_fitted(in_plane_fit, tmp_path):
    with pytest.raises(ValueError, match="table"):
        write_report(dataclasses.replace(in_plane_fit, table=None), tmp_path)
