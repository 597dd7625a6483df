"""Every notebook in notebooks/ runs top to bottom (fast mode), and the committed ones carry no outputs.

Each ``notebooks/*.ipynb`` is executed with nbclient in a fresh ``python3`` kernel of the interpreter
running pytest, with ``APPEARANCE_JAX_FAST=1`` (small sample counts and iteration budgets) and the
notebooks folder as working directory; a cell that raises fails the test. New notebooks are picked up
automatically. The notebooks load shipped data through ``appearance_jax.data.path`` so they also run
against a non-editable install.
"""

import json
import pathlib
import sys

import pytest

NOTEBOOK_DIR = pathlib.Path(__file__).resolve().parents[1] / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
KERNEL = "python3"
TIMEOUT_S = 600  # per cell


def test_there_are_notebooks():
    assert NOTEBOOKS, f"no notebooks found in {NOTEBOOK_DIR}"


@pytest.fixture(scope="module")
def kernel_dir(tmp_path_factory):
    """A ``python3`` kernelspec that runs this interpreter, first on JUPYTER_PATH.

    ipykernel ships a ``python3`` kernelspec, but a user-level one (another environment's Python)
    would take precedence; this one makes the kernel the interpreter that runs the tests.
    """
    root = tmp_path_factory.mktemp("jupyter")
    spec = root / "kernels" / KERNEL
    spec.mkdir(parents=True)
    argv = [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"]
    (spec / "kernel.json").write_text(json.dumps({"argv": argv, "display_name": "Python 3", "language": "python"}))
    return root


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_runs(path, kernel_dir, monkeypatch):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    monkeypatch.setenv("APPEARANCE_JAX_FAST", "1")
    monkeypatch.setenv("JUPYTER_PATH", str(kernel_dir))
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(nb, kernel_name=KERNEL, timeout=TIMEOUT_S,
                                     resources={"metadata": {"path": str(NOTEBOOK_DIR)}})
    client.execute()  # raises CellExecutionError (with the cell and its traceback) if a cell fails


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_is_committed_without_outputs(path):
    nb = json.loads(path.read_text(encoding="utf-8"))
    dirty = [i for i, cell in enumerate(nb["cells"]) if cell["cell_type"] == "code"
             and (cell.get("outputs") or cell.get("execution_count") is not None)]
    assert not dirty, (f"{path.name}: code cells {dirty} have outputs or execution counts; strip them "
                       f"(e.g. jupyter nbconvert --clear-output --inplace {path.name})")
