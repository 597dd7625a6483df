"""``appearance-jax bubble-sim`` end to end on a tiny grid, its option checks, and the named scenes
(:mod:`appearance_jax.soapfilm.scenes`)."""

from __future__ import annotations

import json
import math
import os

import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.cli import main
from appearance_jax.cli.bubble_cmd import SCENE_FOR_AIR, SCENE_HELP
from appearance_jax.soapfilm import air as sair
from appearance_jax.soapfilm import flow, scenes
from appearance_jax.soapfilm.grid import SphereGrid, point

GRID = SphereGrid(16, 32)


# --------------------------------------------------------------------------------------
# scenes


@pytest.mark.parametrize("name", list(scenes.SCENES))
def test_scene_builds_a_valid_state(name):
    sc = scenes.build(name, GRID, seed=3)
    st = sc.state
    assert st.eta.shape == GRID.shape and st.gamma.shape == GRID.shape
    assert st.u_theta.shape == GRID.theta_shape and st.u_phi.shape == GRID.shape
    assert float(jnp.min(st.eta)) > 0 and float(jnp.min(st.gamma)) > 0
    assert np.all(np.isfinite(np.asarray(st.eta)))
    flow.check_state(GRID, st)
    # Huang Table 3.2 at the defaults
    assert sc.params.M == pytest.approx(0.83, abs=0.01)
    assert sc.params.Cr == pytest.approx(2.1, abs=0.05)
    assert sc.params.g == pytest.approx(0.49, abs=0.01)
    assert (sc.params.evaporation > 0) == (name == "evaporate")
    assert name in sc.description and "thesis gives none" in sc.description
    hash(sc.air)  # a static argument of simulate


def test_scene_details():
    # islands: thin patches low on the bubble in the equilibrium film; Gamma keeps the equilibrium
    # profile (buoyant patches), so Gamma / eta = 1 outside the patches and > 1 inside
    isl = scenes.build("islands", GRID, seed=1).state
    ratio = np.asarray(isl.gamma) / np.asarray(isl.eta)
    assert ratio.min() == pytest.approx(1.0, abs=1e-6) and ratio.max() > 1.5
    assert np.median(ratio) == pytest.approx(1.0, abs=1e-3)
    gam = np.asarray(isl.gamma)
    np.testing.assert_allclose(gam, gam[:, :1] * np.ones((1, GRID.n_phi)), rtol=1e-6)  # depends on theta only
    assert gam[0, 0] < gam[-1, 0]  # thin on top
    eq = scenes.build("islands", GRID, seed=1)  # same seed, same state
    np.testing.assert_array_equal(np.asarray(eq.state.eta), np.asarray(isl.eta))
    theta = GRID.theta_centres()
    rows = np.asarray(isl.eta).min(axis=1)
    assert theta[np.argmin(rows)] > 0.6 * np.pi
    # blow: the straw blows from BLOW_START (converted with R), swirling about a horizontal axis
    air = scenes.build("blow", GRID, R=0.05).air
    assert isinstance(air, sair.Rotating)
    assert air.start == pytest.approx(flow.seconds_to_time(scenes.BLOW_START, 0.05)) and air.stop == math.inf
    stop = scenes.build("blow", GRID, R=0.1, blow_start=0.0, blow_stop=1.0).air
    assert stop.start == 0.0 and stop.stop == pytest.approx(10.0)
    assert air.axis[2] == 0.0 and air.width == scenes.BLOW_WIDTH
    # evaporate: curl-noise air, a noisy film, the overridable rate
    ev = scenes.build("evaporate", GRID, evaporation=0.05)
    assert isinstance(ev.air, sair.CurlNoise) and ev.params.evaporation == 0.05
    assert float(jnp.std(ev.state.eta)) > 0.02
    # R, eta0 and Gamma0 reach the dimensionless numbers
    big = scenes.build("gravity", GRID, R=0.1)
    assert big.params.g == pytest.approx(2 * 0.49, rel=0.02)


def test_swirl_is_a_tangent_divergence_free_localised_rotation():
    from appearance_jax.core.vec import dot

    sw = scenes.Swirl(axis=(0.0, -1.0, 0.0), omega=4.0, width=0.15)
    g = SphereGrid(32, 64)
    theta, phi = g.centres()
    p = point(jnp.asarray(theta), jnp.asarray(phi))
    u = sw(p, 1.0)
    assert float(jnp.max(jnp.abs(dot(u, p)))) < 1e-12  # tangent
    speed = float(jnp.max(jnp.sqrt(dot(u, u))))
    assert speed == pytest.approx(0.92, abs=0.02)  # the fastest air, 0.38 rad from the axis
    # divergence-free: the discrete divergence is truncation error only, falling at second order
    # (measured 3.0e-2 / 7.5e-3 at 16x32 / 32x64)
    divs = []
    for gg in (GRID, g):
        ut, up = sair.on_faces(gg, sw, 1.0, jnp.float64)
        divs.append(float(np.max(np.abs(np.asarray(gg.divergence(ut, up))))))
    assert divs[1] < 0.01 and divs[1] < divs[0] / 3.5
    # far from the axis the air is still; with an infinite width it is the rigid Rotating
    back = point(jnp.asarray(np.pi / 2), jnp.asarray(np.pi / 2))  # +y, opposite the axis
    assert float(jnp.linalg.norm(jnp.stack(list(sw(back, 1.0))))) < 1e-5
    rigid = scenes.Swirl(axis=(1.0, 0.0, 0.0), omega=2.0, width=float("inf"))
    np.testing.assert_allclose(np.stack(list(rigid(p, 1.0))), np.stack(list(sair.Rotating(omega=2.0)(p, 1.0))),
                               atol=1e-14)


def test_scene_bad_input():
    with pytest.raises(ValueError, match="scene"):
        scenes.build("foam", GRID)
    for kw in (dict(R=0.0), dict(eta0=-1e-7), dict(Gamma0=float("nan"))):
        with pytest.raises(ValueError, match=list(kw)[0]):
            scenes.build("gravity", GRID, **kw)
    with pytest.raises(ValueError, match="air"):
        scenes.air_field("wind")
    with pytest.raises(ValueError, match="width"):
        scenes.Swirl(width=0.0)
    with pytest.raises(ValueError, match="blow_start"):
        scenes.air_field("blow", blow_start=1.0, blow_stop=0.5)


def test_cli_scene_names_match_the_module():
    assert list(SCENE_HELP) == list(scenes.SCENES)
    assert set(SCENE_FOR_AIR.values()) <= set(scenes.SCENES)


# --------------------------------------------------------------------------------------
# the command line


def test_bubble_sim_end_to_end(tmp_path, capsys):
    """The gravity scene on 32 x 64 in float32 (the CLI's default state): the program of
    tests/soapfilm/test_soapfilm_flow.py's float32 runs (same grid, still air, default settings,
    one frame per call), so the run compiles that one flow program once, not a second for the CLI.
    (The blow scene's air: test_scene_builds_a_valid_state, test_scene_details.)"""
    out = tmp_path / "frames"
    rc = main(["bubble-sim", "--grid", "32x64", "--seconds", "0.02", "--frames", "2", "--render-size", "16",
               "--scene", "gravity", "--out", str(out), "--no-compile-cache"])
    printed = capsys.readouterr().out
    assert rc == 0
    assert "frame 2/2" in printed
    for k in range(3):  # the start and two frames
        for name in (f"frame_{k:04d}.npz", f"frame_{k:04d}.png", f"thickness_{k:04d}.png"):
            assert (out / name).is_file(), name
    assert (out / "sheet.png").is_file()
    s = json.loads((out / "summary.json").read_text())
    assert s["scene"] == "gravity" and s["air"] == "none"
    assert s["grid"] == "32x64" and s["steps"] == 10 and s["steps_requested"] == 10
    assert s["dt_seconds"] == 0.002 and s["dt"] == pytest.approx(0.04)
    assert s["simulated_seconds"] == pytest.approx(0.02, rel=1e-5)
    assert s["wall_seconds"] > 0 and s["simulate_seconds"] > 0
    for q in ("eta", "gamma", "scheme_eta", "scheme_gamma"):
        assert math.isfinite(s["relative_drift"][q]) and abs(s["relative_drift"][q]) < 1e-3, q
    assert s["cg"]["max_iterations"] > 0
    assert 0 <= s["cg"]["final_residual"] <= s["cg"]["max_residual"] <= s["cg"]["rtol"]
    assert isinstance(s["n_reinit"], int) and s["n_reinit"] >= 0
    assert s["stopped"] is None and s["error"] is None
    assert s["numbers"]["M"] == pytest.approx(0.83, abs=0.01)
    assert [f["step"] for f in s["frames"]] == [0, 5, 10]
    with np.load(out / "frame_0002.npz") as z:
        th = z["thickness_nm"]
        assert th.shape == (32, 64) and np.all(th > 0) and np.all(np.isfinite(th))
        assert 500 < th.mean() < 1500  # eta0 = 500 nm half thickness: a film about 1000 nm thick
        assert z["theta"].shape == (32,) and z["phi"].shape == (64,)
        np.testing.assert_allclose(z["theta"], SphereGrid(32, 64).theta_centres())
        assert float(z["time_s"]) == pytest.approx(0.02, rel=1e-5)


def test_bubble_sim_reports_evaporation_stop(tmp_path, capsys, monkeypatch):
    """A run that stops early (evaporation: Result.stopped set) is reported -- printed, in
    summary.json, last frame written, exit 0 -- not a crash. The simulation is faked (no
    compilation): the second chunk stops after 2 of its steps."""
    calls = []

    def stopping(grid, params, state, dt, n_steps, *, air, carry=None, **kw):
        calls.append(params)
        done = n_steps if len(calls) == 1 else 2
        c = carry._replace(n=carry.n + done, t=carry.t + done * dt,
                           state=carry.state._replace(eta=carry.state.eta * 0.5))
        fill = {"cg_iterations": np.full(1, 3), "cg_residual": np.full(1, 1e-8)}
        info = flow.StepInfo(**{k: fill.get(k, np.zeros(1)) for k in flow.StepInfo._fields})
        why = None if len(calls) == 1 else f"the film evaporated (eta <= 0 somewhere) at step {int(c.n)}"
        return flow.Result(c, None, None, info, why)

    monkeypatch.setattr(flow, "simulate", stopping)
    out = tmp_path / "ev"
    rc = main(["bubble-sim", "--scene", "evaporate", "--grid", "8x16", "--seconds", "0.04", "--frames", "4",
               "--render-size", "0", "--out", str(out)])
    printed = capsys.readouterr().out
    assert rc == 0
    assert calls[0].evaporation == scenes.EVAPORATION
    assert len(calls) == 2  # no chunk after the stop
    s = json.loads((out / "summary.json").read_text())
    assert s["stopped"].startswith("the film evaporated") and s["error"] is None
    assert "stopped: the film evaporated" in printed and "STOPPED early" in printed
    assert s["steps"] == 7 and s["steps_requested"] == 20
    assert s["relative_drift"]["eta"] == pytest.approx(-0.75, rel=1e-5)
    # evaporation alone removes rate * t from eta over the 4 pi of the sphere
    assert s["relative_drift"]["eta_expected_from_evaporation"] == pytest.approx(
        -scenes.EVAPORATION * 7 * 0.04 * 4 * np.pi / s["integrals"]["eta_start"], rel=1e-5)
    assert [f["step"] for f in s["frames"]] == [0, 5, 7]
    assert (out / "frame_0002.npz").is_file() and not (out / "frame_0003.npz").exists()
    assert not any(name.startswith("frame_") and name.endswith(".png") for name in os.listdir(out))


@pytest.mark.parametrize("args, option", [
    (["--grid", "3x8"], "--grid"),
    (["--grid", "16x31"], "--grid"),
    (["--grid", "big"], "--grid"),
    (["--seconds", "0"], "--seconds"),
    (["--seconds", "-1"], "--seconds"),
    (["--seconds", "nan"], "--seconds"),
    (["--dt-seconds", "0"], "--dt-seconds"),
    (["--dt-seconds", "inf"], "--dt-seconds"),
    (["--seconds", "0.001", "--dt-seconds", "0.01"], "--seconds"),
    (["--scene", "foam"], "--scene"),
    (["--air", "wind"], "--air"),
    (["--radius", "0"], "--radius"),
    (["--eta0=-5e-7"], "--eta0"),
    (["--gamma0", "x"], "--gamma0"),
    (["--frames", "0"], "--frames"),
    (["--render-size", "-1"], "--render-size"),
])
def test_bubble_sim_bad_input_exits_2(tmp_path, capsys, args, option):
    rc = main(["bubble-sim", "--out", str(tmp_path / "x")] + args)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1 and err[0].startswith("appearance-jax bubble-sim: error: " + option), err
    assert not (tmp_path / "x").exists()  # nothing written


def test_bubble_sim_air_override_and_solver_failure(tmp_path, capsys, monkeypatch):
    """--air replaces the scene's air; a FlowError ends the run with exit 1, the error in
    summary.json and the frames written so far kept (the simulation is faked: nothing compiles)."""
    seen = {}

    def failing(grid, params, state, dt, n_steps, *, air, carry=None, **kw):
        seen["air"] = air
        raise flow.FlowError("solve did not converge at step 3 (t = 0.12): cg residual 1e-3")

    monkeypatch.setattr(flow, "simulate", failing)
    out = tmp_path / "fail"
    rc = main(["bubble-sim", "--scene", "gravity", "--air", "curl", "--grid", "8x16", "--seconds", "0.01",
               "--render-size", "0", "--out", str(out)])
    io = capsys.readouterr()
    assert rc == 1
    assert isinstance(seen["air"], sair.CurlNoise)
    assert "error: solve did not converge" in io.err
    s = json.loads((out / "summary.json").read_text())
    assert s["scene"] == "gravity" and s["air"] == "curl" and "Air replaced" in s["description"]
    assert s["error"].startswith("solve did not converge") and s["steps"] == 0
    assert s["cg"]["final_residual"] is None  # no step ran (and no NaN in the JSON)
    assert (out / "frame_0000.npz").is_file() and (out / "sheet.png").is_file()
