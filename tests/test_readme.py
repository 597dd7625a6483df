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
