"""The fit and eval commands of the command line: reports, plumbing, errors, the eval -> fit round trip."""

import json

import jax
import numpy as np
import pytest

from appearance_jax import registry
from appearance_jax.cli import EXIT_NOT_CONVERGED, main
from appearance_jax.cli.checks import parse_fix
from appearance_jax.fit.tables.csv_table import read_csv, write_csv
from appearance_jax.fit.tables.table import Table

RHO = (0.6, 0.4, 0.2)


@pytest.fixture
def lambert_csv(tmp_path):
    """An in-plane reflectance-factor table of a Lambertian (R = rho / 0.99), one value missing."""
    ti, to = np.meshgrid(np.deg2rad([0.0, 30.0, 60.0]), np.deg2rad(np.arange(-80.0, 81.0, 20.0)), indexing="ij")
    R = np.tile(np.array(RHO) / 0.99, (ti.size, 1))
    R[4, 0] = np.nan
    t = Table.in_plane(ti.ravel(), to.ravel(), R, quantity="reflectance_factor", mask=np.isfinite(R))
    p = tmp_path / "lambert.csv"
    write_csv(t, p)
    return str(p)


def test_fit_writes_report_and_recovers_reflectance(lambert_csv, tmp_path, capsys):
    out = tmp_path / "fit"
    assert main(["fit", lambert_csv, "--model", "lambert", "--out", str(out), "--progress-every", "1"]) == 0
    for name in ("params.json", "residuals.csv", "maps.png", "slices.png", "scatter.png"):
        assert (out / name).is_file(), name
    d = json.loads((out / "params.json").read_text())
    got = [d["parameters"][f"reflectance[{b}]"]["value"] for b in "RGB"]
    np.testing.assert_allclose(got, RHO, rtol=1e-7)
    assert d["converged"] and d["table"]["quantity"] == "reflectance_factor"
    assert d["command"]["argv"][:2] == ["fit", lambert_csv] and d["command"]["command"].startswith("appearance-jax fit")
    assert d["command"]["options"]["model"] == "lambert"
    text = capsys.readouterr().out
    assert "1 missing value" in text  # the table summary, with what was masked
    assert "compiling" in text and "step" in text and "loss" in text  # progress
    assert "reflectance[R]" in text and "converged" in text  # result.summary()
    assert str(out / "maps.png") in text  # the files written
    assert text.strip().splitlines()[-1] == f"status: converged in {d['iterations']} steps (exit 0)"
    assert d["warnings"] and all(text.count(w) == 1 for w in d["warnings"])  # each warning once, not twice
    assert d["exit"] == {"code": 0, "status": "converged"} and d["fixed_by"] == {}
    assert jax.config.jax_enable_x64  # left as the tests set it


def test_parse_fix():
    assert parse_fix(["eta=1.5", "k", "specular_reflectance=0.9,0.8,0.7"]) == {
        "eta": 1.5, "k": None, "specular_reflectance": (0.9, 0.8, 0.7)}
    assert parse_fix(None) == {}
    with pytest.raises(ValueError, match="--fix"):
        parse_fix(["=3"])


def test_fit_options_reach_the_fitter(lambert_csv, tmp_path, monkeypatch):
    """Argument plumbing without a solve: the fitter is replaced by a spy."""
    from appearance_jax.fit import solve

    seen = {}

    def spy(model, table, **kw):
        seen.update(kw, model=model, table=table, x64=jax.config.jax_enable_x64)
        raise ValueError("spy stops here")

    monkeypatch.setattr(solve, "fit", spy)
    argv = ["fit", lambert_csv, "--model", "rough_conductor", "--preset", "gold", "--param", "alpha=0.3",
            "--param", "distribution=beckmann", "--fix", "eta", "--fix", "k=3,2,1", "--loss", "cos_log",
            "--solver", "dogleg", "--starts", "4", "--seed", "7", "--max-theta", "none", "--max-steps", "50",
            "--float32", "--quiet", "--out", str(tmp_path)]
    assert main(argv) == 2
    assert seen["model"].name == "rough_conductor"
    assert seen["fix"] == {"eta": None, "k": (3.0, 2.0, 1.0)}
    gold = registry.get("rough_conductor").presets["gold"]
    np.testing.assert_allclose(np.asarray(seen["init"].eta), np.asarray(gold.eta), rtol=1e-6)
    assert float(seen["init"].alpha) == pytest.approx(0.3) and seen["init"].distribution == "beckmann"
    assert (seen["metric"], seen["solver"], seen["n_starts"], seen["seed"]) == ("cos_log", "dogleg", 4, 7)
    assert seen["max_theta_deg"] is None and seen["max_steps"] == 50 and seen["verbose"] == 0
    assert seen["x64"] is False  # --float32 ...
    assert jax.config.jax_enable_x64  # ... and restored afterwards


def _err(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


@pytest.mark.parametrize("extra, needle", [
    (["--model", "no_such_model"], "unknown model 'no_such_model'"),
    (["--model", "henyey_greenstein"], "is a phase"),
    (["--model", "lambert", "--fix", "alpha=0.1"], "--fix alpha: lambert has no parameter 'alpha'"),
    (["--model", "rough_conductor", "--fix", "distribution"], "--param distribution=VALUE"),
    (["--model", "lambert", "--fix", "reflectance=0.5"], "nothing to fit"),
    (["--model", "lambert", "--param", "albedo=0.5"], "unknown parameter(s) albedo"),
    (["--model", "lambert", "--param", "reflectance"], "expected name=value"),
    (["--model", "lambert", "--param", "reflectance=7"], "reflectance"),
    (["--model", "lambert", "--preset", "gold"], "no preset 'gold'"),
    (["--model", "lambert", "--stride", "3"], "stride applies"),
])
def test_fit_bad_options_exit_2(lambert_csv, capsys, extra, needle):
    assert main(["fit", lambert_csv, *extra]) == 2
    msg = _err(capsys)
    assert msg.startswith("appearance-jax fit: error:") and needle in msg, msg


@pytest.mark.parametrize("make, needle", [
    (lambda d: str(d / "missing.csv"), "table file not found"),
    (lambda d: str(d / "table.txt"), "accepted forms"),
    (lambda d: (d / "bad.csv").write_text("# quantity: brdf\ntheta_i,theta_o,R,G,B\n30,100,1,1,1\n") and str(d / "bad.csv"),
     "bad.csv:3:"),
    (lambda d: "proxy:white-fabrik", "white-fabri"),
])
def test_fit_bad_tables_exit_2(tmp_path, capsys, make, needle):
    spec = make(tmp_path)
    assert main(["fit", spec, "--model", "lambert", "--out", str(tmp_path / "o")]) == 2
    msg = _err(capsys)
    assert needle in msg, msg
    assert not (tmp_path / "o").exists()


def test_eval_on_table_writes_model_values(tmp_path, capsys):
    from appearance_jax.fit.tables.grids import gonio_angles

    ti, pi_, to, po = gonio_angles([0.0, 45.0], [0.0, 30.0, 60.0], [0.0, 90.0])
    R = np.full((ti.size, 3), 0.5)
    R[1, 2] = np.nan
    t = Table(theta_i=ti, phi_i=pi_, theta_o=to, phi_o=po, values=R, mask=np.isfinite(R),
              quantity="reflectance_factor", white_reference=0.98)
    src = tmp_path / "gonio.csv"
    write_csv(t, src)
    out = tmp_path / "ev"
    assert main(["eval", "--model", "lambert", "--param", "reflectance=0.3,0.2,0.1", "--table", str(src),
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    back = read_csv(out / "lambert.csv")
    assert back.quantity == "reflectance_factor" and back.white_reference == pytest.approx(0.98)
    assert back.n_samples == t.n_samples and back.n_valid == back.values.size
    m = registry.get("lambert")
    wi, wo = back.directions()
    f = np.broadcast_to(np.asarray(m.eval(m.Params(reflectance=(0.3, 0.2, 0.1)), wi, wo)), back.values.shape)
    np.testing.assert_allclose(back.brdf()[0], f, rtol=1e-8)
    np.testing.assert_allclose(back.values, np.tile(np.array([0.3, 0.2, 0.1]) / 0.98, (t.n_samples, 1)), rtol=1e-8)
    assert "rmse" in text and f"over {t.n_valid} values" in text


def test_eval_on_table_errors(tmp_path, capsys):
    assert main(["eval", "--model", "lambert", "--table", str(tmp_path / "none.csv")]) == 2
    assert "table file not found" in _err(capsys)
    assert main(["eval", "--model", "lambert", "--table", "x.csv", "--theta-i", "10"]) == 2
    assert "--theta-i" in _err(capsys)


def test_eval_grid_mode_unchanged(tmp_path, capsys):
    assert main(["eval", "--model", "lambert", "--theta-i", "0,45", "--theta-o=-80:80:40", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "lambert.csv").is_file() and (tmp_path / "lambert.png").is_file()
    assert "(10 rows" in capsys.readouterr().out
    assert main(["eval", "--model", "lambert", "--theta-i", "100", "--out", str(tmp_path)]) == 2
    assert "--theta-i 100: angles must lie in [0, 90]" in _err(capsys)


def test_eval_csv_round_trips_through_fit(tmp_path, capsys):
    """eval writes the table format fit reads: fitting its CSV recovers the parameters."""
    rho = (0.3, 0.2, 0.1)
    assert main(["eval", "--model", "lambert", "--param", "reflectance=" + ",".join(map(str, rho)),
                 "--theta-i", "0,30,60", "--theta-o=-80:80:20", "--out", str(tmp_path)]) == 0
    csv = tmp_path / "lambert.csv"
    back = read_csv(csv)
    assert back.quantity == "brdf" and back.bands == ("R", "G", "B") and back.is_in_plane
    assert main(["fit", str(csv), "--model", "lambert", "--no-plots", "--quiet", "--out", str(tmp_path / "fit")]) == 0
    d = json.loads((tmp_path / "fit" / "params.json").read_text())
    np.testing.assert_allclose([d["parameters"][f"reflectance[{b}]"]["value"] for b in "RGB"], rho, rtol=1e-8)


def test_eval_grid_of_a_one_band_model_is_written_as_grey_rgb(tmp_path):
    assert main(["eval", "--model", "lambert", "--theta-i", "30", "--theta-o", "0,40", "--out", str(tmp_path)]) == 0
    t = read_csv(tmp_path / "lambert.csv")
    np.testing.assert_allclose(t.values, 0.5 / np.pi, rtol=1e-8)  # default reflectance 0.5 in every band
    assert t.values.shape == (2, 3)


def test_eval_grid_of_a_spectral_model_has_wavelength_columns(tmp_path):
    wl = (420.0, 550.0, 680.0, 700.0)
    assert main(["eval", "--model", "iridescent", "--param", "color=spectral",
                 "--param", "wavelengths=" + ",".join(map(str, wl)), "--theta-i", "30", "--theta-o", "30",
                 "--out", str(tmp_path)]) == 0
    t = read_csv(tmp_path / "iridescent.csv")
    np.testing.assert_array_equal(t.wavelengths, wl)
    assert t.values.shape == (1, 4) and np.all(t.values > 0)


def test_fit_that_does_not_converge_exits_3_and_says_so_last(lambert_csv, tmp_path, capsys):
    out = tmp_path / "fit"
    code = main(["fit", lambert_csv, "--model", "lambert", "--max-steps", "1", "--no-plots", "--out", str(out)])
    assert code == EXIT_NOT_CONVERGED == 3
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("status: NOT converged") and "--max-steps 1" in last and last.endswith("(exit 3)")
    d = json.loads((out / "params.json").read_text())
    assert d["converged"] is False and d["exit"] == {"code": 3, "status": "not converged"}


def test_fit_that_diverges_exits_3_with_a_named_error(lambert_csv, tmp_path, capsys, monkeypatch):
    """A solve ending on non-finite parameters is reported as such (FitDiverged), not as a bad
    user value of a Params field, and exits 3 with the status as its last line."""
    import jax.numpy as jnp

    from appearance_jax.fit.solve import FitDiverged, solvers

    def diverging(problem, z0, data, **kw):  # solvers._solve: ((z, loss, steps, ok), (r, J) or None)
        return (jnp.full_like(z0, jnp.nan), jnp.asarray(jnp.nan), jnp.asarray(7), jnp.asarray(False)), None

    monkeypatch.setattr(solvers, "_solve", diverging)
    code = main(["fit", lambert_csv, "--model", "lambert", "--no-plots", "--out", str(tmp_path / "fit")])
    assert code == EXIT_NOT_CONVERGED
    cap = capsys.readouterr()
    assert "diverged after 7 steps" in cap.err and "reflectance" in cap.err
    assert cap.out.strip().splitlines()[-1] == "status: NOT converged: the solver diverged (exit 3)"
    assert issubclass(FitDiverged, ArithmeticError) and not issubclass(FitDiverged, ValueError)
