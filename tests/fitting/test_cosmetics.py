"""fitting/cosmetics.py: the deterministic default (solver ``cosmetics_ordinates`` fitted to tables
made by the random walk) on a coarse table; the Monte Carlo path (``--solver walk``) in the slow
tests (the full runs are in fitting/README.md)."""

import importlib.util
import os

import jax
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _load(name="cosmetics"):
    spec = importlib.util.spec_from_file_location(f"{name}_recipe", os.path.join(ROOT, "fitting", f"{name}.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


# the coarse solver of these tests; Matte 1 and Dewy 1 have tilts of 2.0 and 1.5 deg, where the tilt
# correction changes f by < 0.1 % (docs/cosmetics.md): off, it saves ~2 min of compiling
QUICK = dict(n_nodes=8, n_modes=8, tilt_correction=False)


@pytest.fixture
def float32():
    """The recipe's precision (float32, about 2x faster than the test suite's float64), restored after."""
    old = jax.config.jax_enable_x64
    jax.config.update("jax_enable_x64", False)
    yield
    jax.config.update("jax_enable_x64", old)


def test_cosmetics_ordinates_recipe_recovers_cd_and_albedo_quick(float32, tmp_path):
    """Matte 1 on the coarse in-plane table (theta_i 0..60 step 20, theta_o every 20 deg, missing cells
    emulated: 90 values) made by the WALK (1024 paths x 128 steps: MC error ~4 % per cell, folded into
    sigma with the 2 % noise; the steps beyond 128 change f by < 2e-5 relative, 1e-3 of its standard
    error, on this layout), fitted with the deterministic solver at 8 cosines x 8 modes (f within
    0.4 % of 24 x 24 on this layout: far below the per-cell sigma); c_d and albedo_d (RGB) free.

    Asserts: the four values are identified at the truth (1-sigma < 5 % of their range); LM lowers the
    chi-square by > 10x from the 15 %-off start to chi2/N < 1 + 5 sqrt(2/N) (the noise-only spread of
    chi2/N is sqrt(2/N) = 0.15) and no higher than at the truth (to one unit of chi2: LM reaches the
    optimum); each value within 3 sigma of the truth; the results and the identifiability table are written."""
    mod = _load()
    rows, s, idn, res = mod.run_case("matte1", "inplane", free=("c_d", "albedo_d"), gen_samples=1024, gen_bounces=128,
                                     custom_layout=mod.quick_layout(), settings=QUICK, max_steps=30, progress=print)
    assert set(idn["identified"]) == {"c_d", "albedo_d[R]", "albedo_d[G]", "albedo_d[B]"}, idn
    n = s["n_valid"]
    assert n == 90 and res.converged, s
    assert s["loss_lm"] < s["loss_start"] / 10, s
    assert s["loss_lm"] < 1 + 5 * np.sqrt(2 / n), s
    assert s["loss_lm"] <= s["loss_truth"] + 1.0 / n, s  # within one unit of the total chi-square
    for r in rows:
        assert abs(r["z"]) < 3.0, r
    md = mod.write_results(rows, [s], [idn], str(tmp_path))
    assert (tmp_path / "results.csv").exists() and (tmp_path / "identifiability.json").exists()
    assert "c_d" in md and "singular values" in md


@pytest.mark.slow  # 80 s; notebooks/04_cosmetics.ipynb runs a gradient vs derivative-free fit by default
def test_cosmetics_recipe_recovers_cd_and_alpha_quick(tmp_path, float32):
    """The Monte Carlo path (``--solver walk``): Matte 1 on the coarse in-plane table, 2 % noise stated
    as sigma, c_d and alpha free (the rest at the truth), LM with common random numbers (64 paths x 64
    steps; the frozen MC error folded into the weights; at 32 paths the CRN fit of c_d is biased by
    ~9 % (z ~ -6): the loss then favours parameters of lower MC variance).

    Asserts: LM lowers the chi-square by > 3x from the 15 %-off start to a reduced
    chi-square < 3; c_d and alpha come back within 4 sigma and 10 % of the truth with informative
    sigmas; Powell on the same CRN objective reaches a loss within 30 % of LM's; the table and the
    result files are written.
    """
    _load()  # puts fitting/ on the path
    walk = _load("cosmetics_walk")
    data = _load("cosmetics_data")
    rows, s, res = walk.run_case("matte1", free=("c_d", "alpha"), samples=64, bounces=64, gen_samples=512,
                                 gen_bounces=64, max_steps=40, powell_maxfev=80, custom_layout=data.quick_layout(),
                                 fresh_keys=1, truncation=False, cov_samples=0, out=None, progress=print)
    md = walk.write_results(rows, [s], str(tmp_path))
    assert (tmp_path / "results.csv").exists() and "c_d" in md and "Powell" in md
    assert s["lm_iterations"] >= 2, s
    assert s["loss_lm"] < s["loss_start"] / 3 and s["loss_lm"] < 3.0, s
    for r in rows:
        assert abs(r["z"]) < 4.0, r
        assert abs(r["fit"] - r["truth"]) < 0.10 * r["truth"], r
        assert r["sigma"] < 0.1 * r["truth"], r
    assert abs(np.log(s["powell_loss"] / s["loss_lm"])) < np.log(1.3), s
    # the fresh-key loss is a finite, comparable chi-square (CRN bias check ran)
    assert np.isfinite(s["loss_lm_fresh"]) and s["loss_lm_fresh"] < 10 * max(s["loss_lm"], 1.0)


@pytest.mark.slow
def test_cosmetics_recipe_cli_quick_all_free(tmp_path, float32):
    """The command line in --quick mode with all 12 parameters free writes results and a report,
    for the Monte Carlo path (``--solver walk``). A smoke run: 32 paths per cell and 30 LM steps
    lower the loss (14.5 -> 2.0 on 2026-11-28) but need not converge on 12 parameters of a noisy
    objective (w_g and theta are flagged poorly determined), so convergence is reported, not asserted."""
    mod = _load()
    rows, sums = mod.main(["--solver", "walk", "--quick", "--cases", "matte1", "--out", str(tmp_path)])
    assert len(rows) == 12 and isinstance(sums[0]["lm_converged"], bool)
    assert sums[0]["loss_lm"] < sums[0]["loss_start"] / 3
    assert (tmp_path / "results.md").exists() and (tmp_path / "matte1_inplane_walk" / "params.json").exists()


def test_cosmetics_identifiability_dewy1_g2_exactly_flat(float32):
    """Dewy 1 has w_g = 1 (Padron Table A.1): the second HG lobe carries no weight, so its asymmetry g2
    drops out of f exactly. The recipe's identifiability analysis (whitened Jacobian at the truth, SVD
    in range units) must find exactly one exactly flat direction, along g2, and nothing else flat: on
    the coarse in-plane layout with sigma = 2 % of the solver's own f (8 cosines x 8 modes, no walk),
    the smallest singular value is below 1e-6 of the largest with |v_g2| > 0.99, the next one above 1
    (chi^2 changes by more than 1 over a whole range along every other direction), and g2 is the one
    parameter reported with an infinite sigma."""
    mod = _load()
    data = _load("cosmetics_data")
    from appearance_jax.bsdf import cosmetics_ordinates as co

    table, _, _ = data._empty_table("inplane", data.quick_layout())
    wi, wo = table.directions()
    f = np.asarray(co.eval(mod._truth("dewy1", QUICK), wi, wo), np.float64)
    table = table.replace(values=f, sigma=0.02 * f, mask=np.ones_like(f, bool))
    idn, _, _ = mod.identifiability("dewy1", table, settings=QUICK)
    s = np.asarray(idn["s"])
    v = np.asarray(idn["Vt"])[-1]
    g2 = idn["labels"].index("g2")
    assert s[-1] < 1e-6 * s[0] and abs(v[g2]) > 0.99, (s, v)
    assert s[-2] > 1.0, s
    assert [lab for lab, r in zip(idn["labels"], idn["sigma_rel"]) if not np.isfinite(r)] == ["g2"], idn
    assert idn["chi2_truth"] < 1e-6, idn  # the table is the solver's own f
