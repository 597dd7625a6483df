"""The layer rules of docs/architecture.md, checked from the imports (tools/architecture.py)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _tool():
    spec = importlib.util.spec_from_file_location("architecture_tool", ROOT / "tools" / "architecture.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


arch = _tool()


@pytest.fixture(scope="module")
def graph():
    return arch.imports(arch.module_files())


def test_no_upward_import(graph):
    assert arch.upward_imports(graph) == []


def test_no_import_circle(graph):
    assert arch.circles(graph) == []


def test_every_package_has_a_layer():
    assert arch.unlisted(arch.module_files()) == []


def test_the_page_is_generated_from_the_current_imports():
    page = arch.PAGE.read_text(encoding="utf-8")
    assert arch.page_with(page, arch.generated()) == page, "run: python tools/architecture.py --write"


def _fake_tree(tmp_path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        f = tmp_path / "appearance_jax" / rel
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(text)
    return tmp_path


def test_the_checker_sees_lazy_upward_imports_and_circles(tmp_path):
    src = _fake_tree(tmp_path, {
        "__init__.py": "",
        "core/__init__.py": "",
        "core/vec.py": "def f():\n    from ..fit import solve  # lazy, upward\n",
        "core/a.py": "from . import b\n",
        "core/b.py": "from .a import x\n",
        "fit/__init__.py": "from .solve import fit\n",
        "fit/solve.py": "from ..core.vec import f\nimport appearance_jax.registry\n",
        "registry.py": "from .core import a\n",
        "extra/__init__.py": "",
    })
    modules = arch.module_files(src)
    graph = arch.imports(modules)
    assert graph["appearance_jax.core.vec"] == {"appearance_jax.fit.solve"}
    assert arch.upward_imports(graph) == [("appearance_jax.core.vec", "appearance_jax.fit.solve")]
    circles = arch.circles(graph)
    assert ["appearance_jax.core.a", "appearance_jax.core.b"] in circles
    assert ["appearance_jax.core.vec", "appearance_jax.fit.solve"] in circles
    # a package re-exporting its own module is no circle
    assert not any("appearance_jax.fit" in c for c in circles)
    assert arch.unlisted(modules) == ["extra"]
