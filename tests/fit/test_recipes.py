"""The fitting recipes run end to end on a small subset (the full runs are in fitting/)."""

import importlib.util
import os

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _load(name):
    spec = importlib.util.spec_from_file_location(name, os.path.join(ROOT, "fitting", f"{name}.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_merl_fabrics_recipe_on_two_fabrics(tmp_path):
    mod = _load("merl_fabrics")
    rows = mod.fit_fabrics(["white-fabric", "red-fabric"], ["lambert"], progress=lambda *_: None)
    md = mod.write_results(rows, str(tmp_path))
    assert (tmp_path / "results.csv").exists() and "white-fabric" in md
    white, red = rows
    assert white["converged"] and red["converged"]
    # the proxies' colours come out: white is bright and warm-neutral, red is red
    assert white["reflectance[R]"] > 0.2 and white["reflectance[B]"] > 0.1
    assert red["reflectance[R]"] > 4 * red["reflectance[G]"]
    assert 0 < white["cos_log_rmse"] < 0.05 and np.isfinite(white["log_rmse"])
