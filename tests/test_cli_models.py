"""`appearance-jax models` and `models NAME` for every registered model."""

import pytest

from appearance_jax import registry
from appearance_jax.cli import main


def test_models_lists_every_registered_model(capsys):
    assert main(["models"]) == 0
    out = capsys.readouterr().out
    for name in registry.names():
        assert name in out


@pytest.mark.parametrize("name", registry.names())
def test_models_name_prints_the_parameter_table(name, capsys):
    assert main(["models", name]) == 0
    out = capsys.readouterr().out
    for field in registry.get(name).Params.__dataclass_fields__:
        assert field in out, f"{name}: field {field} missing from its table"


def test_nested_tuple_defaults_are_printed(capsys):
    assert main(["models", "cloth"]) == 0
    out = capsys.readouterr().out
    line = next(L for L in out.splitlines() if L.strip().startswith("offsets"))
    assert "((" in line  # per-family tuples of tangent offsets


def test_models_name_shows_the_parameters_fit_holds_fixed(capsys):
    assert main(["models", "rough_plastic"]) == 0
    out = capsys.readouterr().out
    value, why = registry.get("rough_plastic").fit_fixed["eta"]
    assert f"held fixed by `fit` unless --free NAME: eta = {value:g} ({why})" in out
    assert main(["models", "lambert"]) == 0
    assert "held fixed" not in capsys.readouterr().out
