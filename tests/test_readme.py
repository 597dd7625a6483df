"""The README's quick start runs as written and does what it says."""

import pathlib
import re

import numpy as np
import pytest

README = pathlib.Path(__file__).resolve().parents[1] / "README.md"


def _block(marker: str) -> str:
    """The README python block containing ``marker`` (exactly one)."""
    blocks = [b for b in re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S) if marker in b]
    assert len(blocks) == 1, f"{len(blocks)} README python blocks contain {marker!r}"
    return blocks[0]


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
    """The README's fitting example runs from the repository root."""
    import jax

    block = _block("read_table(")
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


def test_thin_film_example_runs():
    ns: dict = {}
    exec(compile(_block("thinfilm.airy("), "README thin-film example", "exec"), ns)
    np.testing.assert_allclose(np.asarray(ns["r"].R), [0.1308, 0.1743, 0.0156], atol=1e-4)
    chart = np.asarray(ns["chart"])
    assert chart.shape == (101, 18, 3) and np.all((chart >= 0) & (chart <= 1))


@pytest.fixture(scope="module")
def bubble_ns():
    """The namespace after the README's soap-bubble example, run once for the two tests below (the
    flow example continues it)."""
    ns: dict = {}
    exec(compile(_block("soapfilm.render("), "README soap-bubble example", "exec"), ns)
    return ns


def test_soap_bubble_example_runs(bubble_ns):
    ns = dict(bubble_ns)
    image, mask = np.asarray(ns["image"]), np.asarray(ns["mask"])
    assert image.shape == (64, 64, 3) and mask.shape == (64, 64) and np.all(np.isfinite(image))
    assert 0.7 < mask.mean() < 0.8  # the disc: pi / 4 of the square
    assert np.ptp(image[mask], axis=0).max() > 0.05  # not a flat colour: interference bands


def test_cosmetics_example_runs():
    ns: dict = {}
    exec(compile(_block("cosmetics.eval_stack("), "README cosmetics example", "exec"), ns)
    f, se, f2 = (np.asarray(ns[k]) for k in ("f", "se", "f2"))
    assert f.shape == (5, 3) and se.shape == (5, 3) and np.all(se > 0) and np.all(np.isfinite(f2))
    assert np.argmax(f.mean(-1)) == 3  # the dewy highlight at the mirror direction (30 deg)
    f_ad = np.asarray(ns["f_ad"])
    assert f_ad.shape == (5,) and np.all(f_ad > 0)


def test_flatland_example_runs():
    ns: dict = {}
    exec(compile(_block("flatland.trace_fiber("), "README flatland example", "exec"), ns)
    w = np.asarray(ns["rec"].weight[:, 0, 0])
    from appearance_jax.optics.fresnel import fresnel_dielectric
    f = float(fresnel_dielectric(np.cos(0.3) * np.sqrt(0.75), 1.55)[0])   # spec M18: f = F(cos th cos g_i)
    np.testing.assert_allclose(w[0], f, rtol=1e-5)
    assert abs(w[1] - (1 - f) ** 2) < 1e-5 and w.sum() < 1
    S, v = ns["S"], np.asarray(ns["v"])
    assert S.S.shape == (4, 45, 90, 3) and np.all(np.isfinite(np.asarray(S.S)))
    assert v.shape == (4, 3) and np.all(v >= 0) and v[1].max() > 0
    bow = ns["bow"]
    ang = np.degrees(np.asarray(bow.scattering_angle)[np.asarray(bow.valid)])
    np.testing.assert_allclose(ang, 137.630, atol=2e-3)


def test_hair_example_runs():
    ns: dict = {}
    exec(compile(_block("chiang.sample("), "README hair example", "exec"), ns)
    for k in ("S", "S_m", "S_h"):
        v = np.asarray(ns[k])
        assert v.shape == (3,) and np.all(np.isfinite(v)) and np.all(v >= 0) and v.max() > 0, k
    assert np.all(np.asarray(ns["se"]) >= 0)


def test_cloth_example_runs():
    ns: dict = {}
    exec(compile(_block("cloth.eval("), "README cloth example", "exec"), ns)
    f, f90, ft = (np.asarray(ns[k]) for k in ("f", "f_90", "f_t"))
    for v, bands in ((f, 3), (f90, 3), (ft, 1)):  # the twill's albedo is one grey band
        assert v.shape == (57, bands) and np.all(np.isfinite(v)) and np.all(v >= 0)
    assert not np.allclose(f, f90)  # the weave is anisotropic


def test_soap_film_flow_example_runs(bubble_ns):
    """The bubble example, then the flow example that continues it (a copy of the bubble's namespace:
    the bubble test's names stay as the bubble example left them).

    The only default run of ``every`` (frames kept along the run; tests/soapfilm run the last frame
    only), so it compiles a program of its own; 250 steps (0.5 s) form the bands as well as 500 do
    (top 0.30, bottom 2.55 measured; 0.25 and 2.60 after 1 s)."""
    ns = dict(bubble_ns)
    exec(compile(_block("soapfilm.simulate("), "README flow example", "exec"), ns)
    frames = np.asarray(ns["sim"].frames)
    assert frames.shape == (5, 32, 64) and ns["sim"].stopped is None
    np.testing.assert_array_equal(frames[-1], np.asarray(ns["sim"].carry.state.eta))  # the frame is the end state
    top, bottom = frames[-1][0].mean(), frames[-1][-1].mean()
    assert top < 0.7 < 1.3 < bottom  # bands: thin on top, thick below (Huang Eq. 3.36)
    assert callable(ns["bands"])
