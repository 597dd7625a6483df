"""The registry: every model module's MODEL is listed under its own name, the listing order is the
models' order, and a model's module is imported only when that model is asked for (a CLI fit of one
model does not import the other 22)."""

from __future__ import annotations

import importlib
import pathlib
import re
import subprocess
import sys

import pytest

from appearance_jax import registry
from appearance_jax.core.model import Model

SRC = pathlib.Path(registry.__file__).parent


def test_every_listed_name_is_its_model_and_in_order():
    names = registry.names()
    assert len(set(names)) == len(names)
    models = registry.models()
    assert [m.name for m in models] == names
    for name, m in zip(names, models):
        assert isinstance(m, Model)
        assert registry.get(name) is m                     # one object per name
    assert registry.get("rough_conductor + lambert") is registry.get("rough_conductor+lambert")


def test_every_model_module_is_registered():
    """A module under bsdf/, bcsdf/ or phase/ that ends in ``MODEL = Model(...)`` is listed, and the
    registry serves that very record."""
    found = []
    for path in sorted(SRC.glob("[bp]*/**/*.py")):
        if re.search(r"^MODEL = Model\(", path.read_text(), re.M):
            mod = ".".join(("appearance_jax",) + path.relative_to(SRC).with_suffix("").parts)
            found.append(importlib.import_module(mod).MODEL)
    assert len(found) >= 20
    for m in found:
        assert m.name in registry.names(), f"{m.name} is not in registry._ENTRIES"
        assert registry.get(m.name) is m


def test_a_model_module_is_imported_on_first_use_only():
    code = ("import sys\n"
            "from appearance_jax import registry\n"
            "before = set(sys.modules)\n"
            "registry.names()\n"
            "assert set(sys.modules) == before, 'names() imported modules'\n"
            "registry.get('rough_plastic')\n"
            "print(' '.join(sorted(m for m in sys.modules if m.startswith('appearance_jax.'))))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    loaded = set(out.stdout.split())
    assert "appearance_jax.bsdf.rough_plastic" in loaded
    for heavy in ("bsdf.feather", "bsdf.rock_dove", "bsdf.cosmetics_ordinates", "bcsdf.huang", "phase.mie",
                  "bsdf.cloth"):
        assert f"appearance_jax.{heavy}" not in loaded, heavy


def test_unknown_names_list_the_valid_ones():
    with pytest.raises(KeyError, match=r"unknown model 'nope'.*rough_plastic"):
        registry.get("nope")
    with pytest.raises(KeyError, match=r"unknown model 'nope' in 'lambert\+nope'"):
        registry.get("lambert+nope")
