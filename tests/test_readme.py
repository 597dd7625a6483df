"""The README's quick start runs as written and does what it says."""

import pathlib
import re

import numpy as np

README = pathlib.Path(__file__).resolve().parents[1] / "README.md"


def test_quick_start_runs():
    text = README.read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert blocks, "README has no python quick start"
    ns: dict = {}
    exec(compile(blocks[0], "README quick start", "exec"), ns)
    f, dfda = np.asarray(ns["f"]), np.asarray(ns["dfda"])
    assert f.shape == (9, 3) and np.all(np.isfinite(f)) and f.max() > 1.0  # a peak at the mirror direction
    assert np.isfinite(dfda) and dfda != 0.0
    assert np.all(np.asarray(ns["pdf"]) >= 0)


def test_readme_and_ci_run_the_same_test_command():
    ci = (README.parent / ".ci" / "run").read_text()
    cmd = [line for line in ci.splitlines() if "pytest" in line and not line.lstrip().startswith("#")]
    assert len(cmd) == 1 and cmd[0].strip() in README.read_text()


def test_fitting_example_runs(tmp_path, monkeypatch):
    """The README's fitting example (second python block) runs from the repository root."""
    import jax

    text = README.read_text()
    block = re.findall(r"```python\n(.*?)```", text, flags=re.S)[1]
    block = block.replace('"out/fit_api"', repr(str(tmp_path / "fit_api")))
    monkeypatch.chdir(README.parent)
    ns: dict = {}
    try:
        exec(compile(block, "README fitting example", "exec"), ns)
    finally:
        jax.config.update("jax_enable_x64", True)  # the test session runs in float64 anyway
    res = ns["result"]
    assert res.converged and res.metrics["cos_log_rmse"] < 0.02
    assert (tmp_path / "fit_api" / "params.json").exists() and (tmp_path / "fit_api" / "maps.png").exists()
