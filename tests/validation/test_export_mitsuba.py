"""appearance_jax.export.mitsuba: the exported BSDF, loaded in Mitsuba 3 (scalar_rgb), against ours.

For every exportable model (and the two listed sums) with non-default, fitted-like parameters,
the dict of :func:`to_mitsuba` is loaded with ``mitsuba.load_dict`` and its ``eval`` (which
returns f |cos theta_o|) is compared with ours at 1200 direction pairs (fixed seeds; the pair
generators, the Mitsuba call loop and the corrections for Mitsuba's own approximations, its
rational Beckmann G1 and its hair I0 series, are those of the test_mitsuba_* files, shared in
mitsuba_common.py). Error metric and tolerances are theirs: max relative error over the entries
>= 1e-3 x the batch maximum, the others to 1e-6 x the maximum absolutely; 1e-4 (conductor,
dielectric, lambert, hair), 6e-4 for rough_plastic with ``tables="mitsuba"`` (the gap of Mitsuba's
own coat-table quadrature, test_mitsuba_rough_plastic.py). A sum gets its loosest component's.

Also: the refusals (unexportable model, a setting Mitsuba lacks, a sum blendbsdf cannot hold),
``approximate=True`` (Mitsuba then equals our separable-G2 model; the size of the difference is
measured), and a round trip ``appearance-jax fit`` -> ``params.json`` -> ``appearance-jax export``
(XML and JSON) -> a file that Mitsuba loads and that evaluates as the fitted model.
"""

import argparse
import json
import os
import zlib

import numpy as np
import pytest

from appearance_jax import registry
from appearance_jax.bcsdf import chiang
from appearance_jax.export import cli as export_cli
from appearance_jax.export import mitsuba as mx

try:
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
except ImportError:  # the refusals and option checks still run
    mi = None

from mitsuba_common import (  # noqa: E402
    as_vec3, dielectric_pairs, hair_ours, hair_pairs, hair_to_mitsuba, max_rel_error, mi_eval_pdf,
    mitsuba_beckmann_g1_ratio, reflection_pairs)

needs_mitsuba = pytest.mark.skipif(mi is None, reason="mitsuba is not installed")

N_PAIRS = 1200
TINY = 1e-3
TOL = 1e-4  # test_mitsuba_rough_conductor / _rough_dielectric / _hair
PLASTIC_TOL = 6e-4  # test_mitsuba_rough_plastic OWN_F_TOL["ggx"]: Mitsuba's coat tables vs ours

COPPERISH = dict(eta=(0.27, 1.12, 1.25), k=(3.4, 2.6, 2.4))
SEP = dict(shadowing="separable")
CASES = [
    # id, model, Params keywords, tolerance
    ("lambert", "lambert", dict(reflectance=(0.62, 0.41, 0.18)), TOL),
    ("conductor-ggx-aniso", "rough_conductor",
     dict(alpha=0.27, alpha_v=0.12, specular_reflectance=(0.9, 0.75, 0.6), **COPPERISH, **SEP), TOL),
    ("conductor-beckmann", "rough_conductor",
     dict(alpha=0.35, specular_reflectance=0.8, distribution="beckmann", **SEP), TOL),
    ("dielectric", "rough_dielectric", dict(alpha=0.18, eta=1.42, **SEP), TOL),
    ("dielectric-inverted", "rough_dielectric", dict(alpha=0.3, alpha_v=0.15, eta=0.75, **SEP), TOL),
    ("plastic-nonlinear", "rough_plastic",
     dict(alpha=0.22, eta=1.6, diffuse_reflectance=(0.45, 0.3, 0.12), specular_reflectance=0.85,
          nonlinear=True, tables="mitsuba", **SEP), PLASTIC_TOL),
    ("conductor+lambert", "rough_conductor+lambert",
     dict(alpha=0.15, specular_reflectance=(0.7, 0.6, 0.5), reflectance=(0.15, 0.1, 0.05), **SEP), TOL),
    ("plastic+lambert", "rough_plastic+lambert",
     dict(alpha=0.3, eta=1.45, diffuse_reflectance=(0.3, 0.2, 0.1), reflectance=(0.2, 0.25, 0.3),
          tables="mitsuba", **SEP), PLASTIC_TOL),
    ("dielectric+lambert", "rough_dielectric+lambert", dict(alpha=0.2, eta=1.5, reflectance=(0.3, 0.2, 0.1), **SEP),
     TOL),
]


def _ours_f_cos(model, p, wi, wo, transmissive=False):
    """Our f |cos theta_o| at float32-rounded pairs, in float64, (N, bands)."""
    f = np.asarray(model.eval(p, as_vec3(wi), as_vec3(wo)), np.float64)
    return f * np.abs(wo[:, 2:3].astype(np.float64))


def _leaves(params):
    """(component name, Params) of a (possibly composite) parameter object."""
    names = getattr(type(params), "components", None)
    return [(None, params)] if names is None else list(zip(names, params.split()))


@needs_mitsuba
@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_exported_bsdf_matches_ours(case):
    name, model_name, kw, tol = case
    model = registry.get(model_name)
    p = model.Params(**kw)
    bsdf = mi.load_dict(mx.to_mitsuba(model_name, p))
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    au = float(kw.get("alpha", 0.3))
    av = float(kw.get("alpha_v") or au)
    ctx = None
    if model_name.startswith("rough_dielectric"):
        wi, wo = dielectric_pairs(rng, N_PAIRS, au, av, kw["eta"])
        ctx = mi.BSDFContext(mi.TransportMode.Importance)  # si.wi = our wi: Mitsuba gives f |wo.z|
    else:
        wi, wo = reflection_pairs(rng, N_PAIRS, au, av)
    f_mi = mi_eval_pdf(bsdf, wi, wo, ctx=ctx)[0]
    f = _ours_f_cos(model, p, wi, wo)
    if kw.get("distribution") == "beckmann":  # Mitsuba's rational G1, once per factor
        f = f * (mitsuba_beckmann_g1_ratio(wi, au, av) * mitsuba_beckmann_g1_ratio(wo, au, av))[:, None]
    rel, tiny_abs, count = max_rel_error(np.broadcast_to(f, f_mi.shape), f_mi, TINY)
    print(f"\n{name}: {mx.to_mitsuba(model_name, p)['type']}, max rel err {rel:.2e} ({count} entries)")
    assert count > 300  # the lobes were sampled
    assert rel < tol and tiny_abs < 1e-6


@needs_mitsuba
def test_exported_hair_matches_ours():
    """chiang_hair -> hair: sigma_a as RGB, eta -> int_ior, the tilt in degrees (Mitsuba's frame
    and offset h, and its I0 series, as in test_mitsuba_hair.py)."""
    params = chiang.Params(sigma_a=(0.42, 0.8, 1.6), eta=1.6, beta_m=0.25, beta_n=0.35, alpha=np.radians(3.0))
    d = mx.to_mitsuba("chiang_hair", params)
    assert d["scale_tilt"] == pytest.approx(3.0) and d["int_ior"] == pytest.approx(1.6)
    bsdf = mi.load_dict(d)
    wi, wo = hair_pairs(np.random.default_rng(19), params, N_PAIRS)
    f_mi = mi_eval_pdf(bsdf, wi, wo, to_mitsuba=hair_to_mitsuba)[0]
    _, _, f_corr, _, _ = hair_ours(params, wi, wo)
    rel, tiny_abs, count = max_rel_error(f_corr, f_mi, TINY)
    print(f"\nhair: max rel err {rel:.2e} ({count} entries)")
    assert count > 300 and rel < TOL and tiny_abs < 1e-6


def test_refusals_name_the_problem():
    with pytest.raises(mx.ExportError, match=r"'iridescent' has no Mitsuba 3 equivalent; exportable: lambert"):
        mx.to_mitsuba("iridescent", registry.get("iridescent").Params())
    with pytest.raises(mx.ExportError, match=r"component 'iridescent'"):
        mx.to_mitsuba("rough_conductor+iridescent", registry.get("rough_conductor+iridescent").Params())
    rc = registry.get("rough_conductor")
    with pytest.raises(mx.ExportError, match=r"rough_conductor.shadowing = 'correlated'.*approximate=True"):
        mx.to_mitsuba(rc, rc.Params())  # the default G2 has no Mitsuba equivalent
    rp = registry.get("rough_plastic")
    assert len(mx.differences(rp, rp.Params())) == 2  # correlated G2 and the accurate tables
    assert mx.differences(rp, rp.Params(shadowing="separable", tables="mitsuba")) == []
    # a sum whose coloured reflectance maxima reach 1: no convex blend with RGB values <= 1
    s = registry.get("rough_conductor+lambert")
    with pytest.raises(mx.ExportError, match=r"sum to 1.1 >= 1"):
        mx.to_mitsuba(s, s.Params(specular_reflectance=(0.9, 0.8, 0.7), reflectance=(0.2, 0.1, 0.1), **SEP))
    sp = registry.get("rough_plastic+lambert")
    with pytest.raises(mx.ExportError, match=r"nonlinear = True in a sum"):
        mx.to_mitsuba(sp, sp.Params(nonlinear=True, tables="mitsuba", diffuse_reflectance=(0.3, 0.2, 0.1),
                                    reflectance=0.2, **SEP))
    with pytest.raises(mx.ExportError, match=r"lambert.reflectance has 5 bands"):
        mx.to_mitsuba("lambert", registry.get("lambert").Params(reflectance=(0.1, 0.2, 0.3, 0.4, 0.5)))
    with pytest.raises(mx.ExportError, match=r"rough_conductor.alpha has shape \(2,\)"):
        mx.to_mitsuba(rc, rc.Params(alpha=np.array([0.1, 0.2]), **SEP))
    with pytest.raises(TypeError, match=r"expected lambert.Params"):
        mx.to_mitsuba("lambert", rc.Params())


def test_sum_weights_keep_coloured_values_in_range():
    """c_k = m_k + (1 - sum m) M_k / sum M: coloured values <= 1, grey ones may exceed 1, zero lobes dropped."""
    sp = registry.get("rough_plastic+lambert")
    p = sp.Params(diffuse_reflectance=(0.3, 0.2, 0.1), specular_reflectance=1.0, reflectance=(0.2, 0.25, 0.3),
                  tables="mitsuba", **SEP)
    d = mx.to_mitsuba(sp, p)
    c0, c1 = 1.0 - d["weight"], d["weight"]
    # m = (0.3, 0.3), M = (1, 0.3): c = (0.3 + 0.4/1.3, 0.3 + 0.4 * 0.3/1.3)
    assert c0 == pytest.approx(0.3 + 0.4 / 1.3) and c1 == pytest.approx(0.3 + 0.12 / 1.3)
    np.testing.assert_allclose(d["bsdf_0"]["diffuse_reflectance"]["value"], np.array([0.3, 0.2, 0.1]) / c0)
    assert d["bsdf_0"]["specular_reflectance"] == pytest.approx(1.0 / c0)  # grey: a float above 1
    assert max(d["bsdf_1"]["reflectance"]["value"]) <= 1.0
    rcl = registry.get("rough_conductor+lambert")
    only = mx.to_mitsuba(rcl, rcl.Params(reflectance=0.0, specular_reflectance=(0.5, 0.4, 0.3), **SEP))
    assert only["type"] == "roughconductor"  # a zero lobe is left out, the other is exact unscaled
    assert only["specular_reflectance"]["value"] == [0.5, 0.4, 0.3]


@needs_mitsuba
def test_approximate_export_is_the_separable_model():
    """approximate=True writes the nearest Mitsuba BSDF: our model with the separable G2."""
    rc = registry.get("rough_conductor")
    p = rc.Params(alpha=0.4, specular_reflectance=(0.9, 0.8, 0.7))  # correlated G2 (default)
    bsdf = mi.load_dict(mx.to_mitsuba(rc, p, approximate=True))
    wi, wo = reflection_pairs(np.random.default_rng(7), 600, 0.4, 0.4)
    f_mi = mi_eval_pdf(bsdf, wi, wo)[0]
    sep = max_rel_error(_ours_f_cos(rc, p.replace(shadowing="separable"), wi, wo), f_mi, TINY)[0]
    corr = max_rel_error(_ours_f_cos(rc, p, wi, wo), f_mi, TINY)[0]
    print(f"\napproximate export: vs separable {sep:.1e}, vs the correlated model {corr:.1e}")
    assert sep < TOL
    assert corr > 10 * TOL  # a real difference, which is why it needs approximate=True


# ---------------------------------------------------------------------------- command line

def _export(argv) -> int:
    """``appearance-jax export ARGV`` through the command module's own parser."""
    parser = argparse.ArgumentParser(prog="appearance-jax")
    export_cli.add_parser(parser.add_subparsers(dest="cmd"))
    args = parser.parse_args(["export", *argv])
    return args.fn(args)


def _conductor_table(path):
    """An in-plane BRDF table of a separable-G2 rough conductor (3 incidences x 17 exits)."""
    from appearance_jax.fit.tables.csv_table import write_csv
    from appearance_jax.fit.tables.table import Table

    ti, to = np.meshgrid(np.deg2rad([0.0, 30.0, 60.0]), np.deg2rad(np.arange(-80.0, 81.0, 10.0)), indexing="ij")
    ti, to = ti.ravel(), to.ravel()
    wi = np.stack([np.sin(ti), 0 * ti, np.cos(ti)], 1)
    wo = np.stack([-np.sin(to), 0 * to, np.cos(to)], 1)  # signed theta_o > 0: the mirror side
    rc = registry.get("rough_conductor")
    f = np.asarray(rc.eval(rc.Params(alpha=0.25, specular_reflectance=(0.8, 0.7, 0.6), **SEP),
                           as_vec3(wi), as_vec3(wo)))
    write_csv(Table.in_plane(ti, to, f, quantity="brdf"), path)


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """params.json of a real (tiny) fit: rough_conductor, separable G2, alpha and the reflectance free."""
    from appearance_jax.cli import main

    d = tmp_path_factory.mktemp("export")
    _conductor_table(d / "table.csv")
    out = d / "fit"
    rc = main(["fit", str(d / "table.csv"), "--model", "rough_conductor", "--param", "shadowing=separable",
               "--param", "alpha=0.4", "--fix", "eta", "--fix", "k", "--no-plots", "--quiet", "--out", str(out)])
    assert rc == 0
    return out / "params.json"


def test_from_params_json_rebuilds_the_fit(fitted):
    model, p = mx.from_params_json(fitted)
    rec = json.loads(fitted.read_text())
    assert model.name == "rough_conductor" and p.shadowing == "separable"
    assert float(p.alpha) == pytest.approx(0.25, rel=1e-4)
    np.testing.assert_allclose(np.asarray(p.specular_reflectance), (0.8, 0.7, 0.6), rtol=1e-4)
    # the same Params from the labelled values, fixed and static records alone (no "params" field)
    del rec["params"]
    alt = fitted.parent / "labels_only.json"
    alt.write_text(json.dumps(rec))
    _, q = mx.from_params_json(alt)
    for field in ("alpha", "eta", "k", "specular_reflectance"):
        np.testing.assert_allclose(np.asarray(getattr(q, field)), np.asarray(getattr(p, field)), rtol=1e-12)
    assert q.shadowing == "separable"


@needs_mitsuba
@pytest.mark.parametrize("kind", ["xml", "json"])
def test_fit_then_export_loads_in_mitsuba(fitted, tmp_path, kind, capsys):
    out = tmp_path / f"material.{kind}"
    assert _export([str(fitted), "--format", "mitsuba", "--out", str(out)]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    if kind == "xml":
        bsdf = mi.load_file(str(out))
        assert "rough_conductor fitted in" in out.read_text()
    else:
        bsdf = mi.load_dict(json.loads(out.read_text()))
    model, p = mx.from_params_json(fitted)
    wi, wo = reflection_pairs(np.random.default_rng(3), 400, 0.25, 0.25)
    rel, tiny_abs, count = max_rel_error(_ours_f_cos(model, p, wi, wo), mi_eval_pdf(bsdf, wi, wo)[0], TINY)
    assert count > 100 and rel < TOL and tiny_abs < 1e-6


def test_export_options_are_checked_first(fitted, tmp_path, capsys):
    with pytest.raises(mx.ExportError, match=r"PARAMS_JSON .*no such file"):
        _export([str(tmp_path / "none.json"), "--out", str(tmp_path / "m.xml")])
    with pytest.raises(mx.ExportError, match=r"PARAMS_JSON .* is a directory"):
        _export([str(tmp_path), "--out", str(tmp_path / "m.xml")])
    with pytest.raises(mx.ExportError, match=r"--out .* is a directory"):
        _export([str(fitted), "--out", str(tmp_path)])
    with pytest.raises(mx.ExportError, match=r"--out .*does not exist"):
        _export([str(fitted), "--out", str(tmp_path / "no" / "m.xml")])
    with pytest.raises(mx.ExportError, match=r"--id '1x'"):
        _export([str(fitted), "--id", "1x"])
    with pytest.raises(SystemExit):  # argparse names the option
        _export([str(fitted), "--format", "pbrt"])
    assert "--format: invalid choice: 'pbrt'" in capsys.readouterr().err
    if hasattr(os, "mkfifo"):  # answered at once, not blocking
        os.mkfifo(tmp_path / "pipe")
        with pytest.raises(mx.ExportError, match=r"params.json .*pipe.* is a FIFO"):
            _export([str(tmp_path / "pipe")])
        with pytest.raises(mx.ExportError, match=r"--out .*pipe.* is a FIFO"):
            _export([str(fitted), "--out", str(tmp_path / "pipe")])
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(mx.ExportError, match=r"is not JSON"):
        _export([str(bad)])
    bad.write_text(json.dumps({"model": "cloth", "params": {}}))
    with pytest.raises(mx.ExportError, match=r"'cloth' has no Mitsuba 3 equivalent"):
        _export([str(bad)])
    rec = json.loads(fitted.read_text())
    spectral = tmp_path / "spectral.json"
    spectral.write_text(json.dumps({**rec, "table": {**rec["table"], "wavelengths_nm": [450.0, 550.0, 650.0]}}))
    with pytest.raises(mx.ExportError, match=r"bands are wavelengths \(450, 550, 650 nm\)"):
        _export([str(spectral)])
    stalled = tmp_path / "stalled.json"
    stalled.write_text(json.dumps({**rec, "converged": False}))
    assert _export([str(stalled), "--out", str(tmp_path / "s.xml")]) == 0
    assert "did not converge" in capsys.readouterr().err
    # a correlated-G2 record: refused, then written with --approximate (and the difference listed)
    rec["params"]["shadowing"] = "correlated"
    corr = tmp_path / "corr.json"
    corr.write_text(json.dumps(rec))
    with pytest.raises(mx.ExportError, match=r"--approximate"):
        _export([str(corr), "--dict"])
    assert _export([str(corr), "--dict", "--approximate"]) == 0
    io = capsys.readouterr()
    assert json.loads(io.out)["type"] == "roughconductor" and "approximated: rough_conductor.shadowing" in io.err


def test_registered_in_the_command_line(fitted, tmp_path, capsys):
    from appearance_jax.cli import main

    assert main(["export", str(fitted), "--out", str(tmp_path / "m.xml")]) == 0
    assert (tmp_path / "m.xml").read_text().startswith("<?xml")
    assert main(["export", str(fitted), "--out", str(tmp_path)]) == 2  # bad input: exit status 2, one line
    assert "appearance-jax export: error: --out" in capsys.readouterr().err
