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


def test_thin_film_recipe_recovers_both_cases(tmp_path):
    """Snake skin and iridescent microfacets: multi-start over one period finds the true fringe.

    The tables carry their 2 % noise as sigma, so the fit is a chi-square with absolute 1-sigma
    errors: every parameter within 4.5 sigma of the truth, reduced chi-square near 1, and for the
    snake at least one start lands on a wrong fringe (the multi-start is needed, not decorative).
    """
    mod = _load("thin_films")
    rows = []
    for case in ("snake", "iridescent"):
        r, res = mod.run_case(case, n_starts=8, out=str(tmp_path), progress=lambda *_: None)
        rows += r
        assert res.converged and 0.7 < res.loss < 1.4, (case, res.loss)
        if case == "snake":
            losses = np.array(res.starts["losses"])
            assert losses.max() > 5 * losses.min()
    md = mod.write_results(rows, str(tmp_path))
    assert (tmp_path / "results.csv").exists() and "thickness" in md
    for row in rows:
        assert abs(row["z"]) < 4.5, row
        assert row["sigma"] < 0.05 * max(abs(row["truth"]), 0.01), row  # and the sigmas are informative
    assert (tmp_path / "snake" / "params.json").exists()
