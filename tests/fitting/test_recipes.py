"""The fitting recipes (fitting/*.py) run end to end on a small subset (the full runs are in fitting/)."""

import importlib.util
import os

import numpy as np
import pytest

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


# the cloth fit of notebooks/06_cloth.ipynb in its fast mode (the one the test suite runs): red-fabric's
# gonio proxy table, satin, 4 rotations, T = 4 tangent samples, the default start, cos-log, LM, 50 steps
NOTEBOOK_CLOTH_FIT = dict(rotations=4, samples=4, steps=50)


def test_cloth_merl_recipe_runs_and_reports_both_metrics(tmp_path):
    """fitting/cloth_merl.py on one proxy, one weave and few steps (the full run is in the recipe): the
    cloth fit reaches a small error, and the reports name the best model per metric.

    The cloth fit (one XLA program: compiling it is most of this test's time, and of the notebook's)
    uses exactly the settings of notebooks/06_cloth.ipynb's fast mode (NOTEBOOK_CLOTH_FIT) and the same
    default solver, so the two compile the same program, which the run's shared compilation cache
    (tests/conftest.py) builds once for both. The recipe's code (fit_cloth, result_rows,
    best_per_fabric, write_best, plot_errors, main) runs unchanged. Should the notebook's settings
    change, this test still passes; it then compiles a program of its own.
    """
    mod = _load("cloth_merl")
    assert mod.main(["--out", str(tmp_path), "--fabrics", "red-fabric", "--weaves", "satin", "--baselines",
                     "lambert", "--steps", str(NOTEBOOK_CLOTH_FIT["steps"]),
                     "--rotations", str(NOTEBOOK_CLOTH_FIT["rotations"]),
                     "--samples", str(NOTEBOOK_CLOTH_FIT["samples"])]) == 0
    for name in ("results.csv", "results.md", "best.md", "errors.png"):
        assert (tmp_path / name).exists(), name
    best = (tmp_path / "best.md").read_text()
    assert "red-fabric" in best and "cloth_weave[satin]" in best
    rows = [r for r in _rows(tmp_path / "results.csv") if r["model"] == "cloth_weave[satin]"]
    assert len(rows) == 1 and float(rows[0]["cos_log_rmse"]) < 0.05 and np.isfinite(float(rows[0]["log_rmse"]))
    assert float(rows[0]["albedo_1[R]"]) > float(rows[0]["albedo_1[B]"])  # the red fabric's threads are red


def _rows(path):
    import csv

    with open(path) as fh:
        return list(csv.DictReader(line for line in fh if not line.startswith("#")))


@pytest.mark.slow
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


def test_thin_film_recipe_snake_multistart(tmp_path):
    """The default run's share of the above: the snake case with 4 starts (one period) still needs the
    multi-start (a start lands on a wrong fringe) and recovers every parameter within 4.5 sigma."""
    mod = _load("thin_films")
    rows, res = mod.run_case("snake", n_starts=4, out=None, progress=lambda *_: None)
    assert res.converged and 0.7 < res.loss < 1.4, res.loss
    losses = np.array(res.starts["losses"])
    assert losses.max() > 5 * losses.min()
    for row in rows:
        assert abs(row["z"]) < 4.5, row
