"""Every option of fit and eval is checked before a table is read or anything compiled, and the
physically known parameters are held fixed unless --free (no solve runs in this file)."""

import pathlib

import pytest

from appearance_jax import registry
from appearance_jax.cli import EXIT_USAGE, main

TABLE = str(pathlib.Path(__file__).resolve().parents[1] / "data" / "tables" / "merl-proxy-red-fabric-in-plane.csv")


@pytest.fixture
def no_work(monkeypatch):
    """Reading a table or solving fails the test: the checks must come first."""
    from appearance_jax.fit import solve
    from appearance_jax.fit.tables import io

    def forbidden(*a, **k):
        raise AssertionError("an option check came after reading the table or starting the fit")

    monkeypatch.setattr(io, "read_table", forbidden)
    monkeypatch.setattr(solve, "fit", forbidden)


def _err(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err  # one line, no traceback
    return err[0]


@pytest.mark.parametrize("extra, needle", [
    (["--fix", "alpha=-1"], "--fix alpha = -1 is outside the valid range [0.001, 2]"),
    (["--fix", "nosuch=1"], "--fix nosuch: rough_plastic has no parameter 'nosuch'; parameters are alpha"),
    (["--fix", "eta=glass"], "--fix eta=glass: expected a number"),
    (["--param", "alpha"], "--param 'alpha': expected name=value"),
    (["--param", "alpha=5"], "alpha = 5 is outside the valid range [0.001, 2]"),
    (["--starts", "0"], "--starts 0: must be an integer >= 1"),
    (["--max-steps", "0"], "--max-steps 0: must be an integer >= 1"),
    (["--stride", "0"], "--stride 0: must be a positive integer dividing 90 and 180"),
    (["--stride", "3"], "--stride 3: the stride applies to MERL .binary files"),
    (["--seed", "-1"], "--seed -1: must be an integer >= 0"),
    (["--max-theta", "100"], "--max-theta 100: must lie in (0, 90] degrees"),
    (["--progress-every", "-1"], "--progress-every -1: must be an integer >= 0"),
    (["--free", "alpha"], "--free alpha: not a parameter that fit holds fixed by default (rough_plastic's are eta"),
    (["--free", "eta", "--fix", "eta"], "--free eta and --fix eta"),
    (["--preset", "gold"], "--preset gold: rough_plastic: no preset 'gold'"),
])
def test_fit_option_errors_name_the_option(no_work, capsys, extra, needle):
    assert main(["fit", TABLE, "--model", "rough_plastic", *extra]) == EXIT_USAGE
    msg = _err(capsys)
    assert msg.startswith("appearance-jax fit: error: ") and needle in msg, msg


def test_out_must_not_be_a_file(no_work, tmp_path, capsys):
    f = tmp_path / "taken"
    f.write_text("x")
    assert main(["fit", TABLE, "--model", "lambert", "--out", str(f)]) == EXIT_USAGE
    assert f"--out {f}: is an existing file" in _err(capsys)
    assert main(["eval", "--model", "lambert", "--out", str(f)]) == EXIT_USAGE
    assert f"--out {f}: is an existing file" in _err(capsys)


def test_unknown_model_suggests_close_names(no_work, capsys):
    assert main(["fit", TABLE, "--model", "rough_plastik"]) == EXIT_USAGE
    msg = _err(capsys)
    assert "--model rough_plastik: unknown model 'rough_plastik'" in msg and "did you mean rough_plastic" in msg
    assert main(["fit", TABLE, "--model", "rough_conductor+lamberd"]) == EXIT_USAGE
    assert "did you mean lambert?" in _err(capsys)
    assert main(["models", "lamber"]) == EXIT_USAGE
    assert "did you mean lambert" in _err(capsys)


def test_missing_table_and_unknown_form(no_work, tmp_path, capsys):
    assert main(["fit", str(tmp_path / "none.csv"), "--model", "lambert"]) == EXIT_USAGE
    assert f"table file not found: {tmp_path / 'none.csv'}" in _err(capsys)
    assert main(["fit", str(tmp_path), "--model", "lambert"]) == EXIT_USAGE
    assert "accepted forms" in _err(capsys)


@pytest.mark.parametrize("argv, needle", [
    (["--theta-o", "a:b"], "--theta-o a:b: expected degrees"),
    (["--theta-o=-95,0"], "--theta-o -95,0: angles must lie in [-90, 90]"),
    (["--theta-i=-10"], "--theta-i -10: angles must lie in [0, 90]"),
    (["--theta-o", "0:10:0"], "step > 0"),
    (["--stride", "3"], "--stride 3: applies to --table"),
    (["--param", "reflectance=2"], "reflectance = 2 is outside the valid range [0, 1]"),
])
def test_eval_option_errors(tmp_path, capsys, argv, needle):
    assert main(["eval", "--model", "lambert", *argv, "--out", str(tmp_path / "o")]) == EXIT_USAGE
    msg = _err(capsys)
    assert needle in msg, msg
    assert not (tmp_path / "o").exists()


def test_argparse_errors_exit_2(capsys):
    with pytest.raises(SystemExit) as e:
        main(["fit", TABLE, "--model", "lambert", "--starts", "two"])
    assert e.value.code == EXIT_USAGE
    assert "--starts" in capsys.readouterr().err


# --------------------------------------------------------------- physically known parameters
@pytest.fixture
def spy(monkeypatch):
    """Capture the fitter's keywords and stop there."""
    from appearance_jax.fit import solve

    seen = {}

    def fake(model, table, **kw):
        seen.update(kw, model=model)
        raise ValueError("spy stops here")

    monkeypatch.setattr(solve, "fit", fake)
    return seen


@pytest.mark.parametrize("extra, fix", [
    ([], {"eta": 1.5}),  # the record's default
    (["--free", "eta"], {}),
    (["--free", "all"], {}),
    (["--fix", "eta=1.6"], {"eta": 1.6}),  # the user's value wins
    (["--param", "eta=1.4"], {"eta": None}),  # held at the user's start value
    (["--fix", "alpha=0.3"], {"alpha": 0.3, "eta": 1.5}),
])
def test_known_parameters_are_held_unless_freed(spy, capsys, extra, fix):
    assert main(["fit", TABLE, "--model", "rough_plastic", "--out", "unused", *extra]) == EXIT_USAGE
    assert spy["fix"] == fix
    assert "spy stops here" in capsys.readouterr().err


def test_held_parameters_are_announced_with_their_reason(spy, capsys):
    main(["fit", TABLE, "--model", "rough_plastic", "--out", "unused"])
    out = capsys.readouterr().out
    reason = registry.get("rough_plastic").fit_fixed["eta"][1]
    assert f"fixed: eta = 1.5 (default: {reason}; --free eta fits it)" in out


def test_a_sum_holds_its_components_known_parameters(spy):
    main(["fit", TABLE, "--model", "rough_plastic+lambert", "--out", "unused"])
    assert spy["fix"] == {"eta": 1.5}
    main(["fit", TABLE, "--model", "lambert+rough_plastic", "--out", "unused"])
    assert spy["fix"] == {"eta": 1.5}
    main(["fit", TABLE, "--model", "rough_plastic+rough_plastic", "--out", "unused"])
    assert spy["fix"] == {"eta": 1.5, "rough_plastic_1_eta": 1.5}  # the renamed field of the second lobe


def test_bootstrap_option(spy, capsys):
    from appearance_jax.cli.fit_cmd import _fit_accepts

    if not _fit_accepts("bootstrap"):
        pytest.skip("fit() has no bootstrap keyword: the CLI leaves --bootstrap out")
    assert main(["fit", TABLE, "--model", "lambert", "--bootstrap", "1"]) == EXIT_USAGE
    assert "--bootstrap 1: must be 0 or an integer >= 2" in _err(capsys)
    main(["fit", TABLE, "--model", "lambert", "--out", "unused", "--bootstrap", "8", "--seed", "3"])
    assert spy["bootstrap"] == 8 and spy.get("bootstrap_seed", 3) == 3


def test_warnings_come_from_the_result_or_from_parameters_at_bounds():
    from types import SimpleNamespace

    from appearance_jax.cli.fit_cmd import _warnings

    assert _warnings(SimpleNamespace(warnings=["a", "b"], at_bound=())) == ["a", "b"]
    old = SimpleNamespace(at_bound=("eta", "diffuse_reflectance[G]"))  # a result without .warnings
    (w,) = _warnings(old)
    assert w.startswith("2 parameters ended at a bound (eta, diffuse_reflectance[G])")
    assert _warnings(SimpleNamespace(at_bound=("eta",))) == []
