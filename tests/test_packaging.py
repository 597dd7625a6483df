"""The installed package is complete: every subpackage listed, shipped data present, CLI entry point."""

import pathlib
import tomllib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_every_subpackage_is_listed_in_pyproject():
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    src = ROOT / "src"
    found = {
        ".".join(p.parent.relative_to(src).parts)
        for p in src.rglob("__init__.py")
    }
    missing = found - listed
    assert not missing, f"add these subpackages to [tool.setuptools] packages in pyproject.toml: {sorted(missing)}"
    gone = listed - found - {"appearance_jax.data"}  # data/ is mapped to appearance_jax.data
    assert not gone, f"listed in pyproject.toml but not in src/: {sorted(gone)}"


def test_shipped_data_is_installed_with_provenance():
    from appearance_jax import data

    folder = data.path("refractive_index")
    names = {p.name for p in folder.iterdir()}
    assert "SOURCES.txt" in names and "LICENSE-CC0.txt" in names
    assert len([n for n in names if n.endswith(".yml")]) >= 20
    # rough_plastic's precomputed coat tables (microfacet/coat_tables.py reads them)
    coat = {p.name for p in data.path("coat_tables").iterdir()}
    assert {"coat_tables.npz", "PROVENANCE.md"} <= coat


def test_cli_lists_models_with_parameter_tables(capsys):
    from appearance_jax.cli import main

    assert main(["models", "lambert"]) == 0
    out = capsys.readouterr().out
    assert "reflectance [bands]" in out and "[0, 1]" in out


def test_cli_reports_unknown_model(capsys):
    from appearance_jax.cli import main

    assert main(["models", "no_such_model"]) == 2
    assert "registered models" in capsys.readouterr().err
