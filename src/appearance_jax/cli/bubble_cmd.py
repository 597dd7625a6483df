"""``appearance-jax bubble-sim``: soap-film flow on a spherical bubble (Huang 2022, Ch. 3).

Runs :func:`appearance_jax.soapfilm.flow.simulate` on a named scene
(:mod:`appearance_jax.soapfilm.scenes`) in ``--frames`` chunks, continuing the carry from chunk
to chunk, and after each chunk writes the thickness map (npz), a rendered PNG of the bubble
(:func:`appearance_jax.soapfilm.bubble.render`) and a false-colour thickness map; at the end a
contact sheet and ``summary.json``. Reference: docs/cli.md.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time

import numpy as np

from . import checks

NAME = "bubble-sim"
SCENE_FOR_AIR = {"none": "gravity", "blow": "blow", "curl": "evaporate"}
#: the scenes of :data:`appearance_jax.soapfilm.scenes.SCENES` (named here so that building the parser
#: does not import the simulator)
SCENE_HELP = {
    "gravity": "uniform film, still air: gravity bands (Huang Figs. 3.12/3.13)",
    "islands": "thin patches low on the bubble rise as islands (Huang Fig. 3.14)",
    "blow": "a rotating ball of air from 0.25 s on swirls the bands into stripes (Huang Fig. 3.15)",
    "evaporate": "noisy film, curl-noise air, evaporation: the top fades to grey (Huang Fig. 3.17)",
}
EXPOSURE_PERCENTILE = 99.5  # of the first frame's disc pixels, shown at EXPOSURE_LEVEL
EXPOSURE_LEVEL = 0.9


def add_parser(subparsers) -> None:
    SCENES = SCENE_HELP
    p = subparsers.add_parser(
        NAME, help="simulate the soap-film flow on a bubble (Huang 2022 Ch. 3); thickness maps and PNG frames",
        description="Simulate the thin-film flow on a spherical soap bubble (Huang 2022, Ch. 3: staggered "
                    "sphere grid, great-circle advection, BiMocq^2, implicit surfactant solve) from a named "
                    "scene and write, per frame, the full film thickness (npz, nm), a rendered PNG and a "
                    "false-colour thickness map, plus sheet.png and summary.json. Scenes: "
                    + "; ".join(f"{k}: {v}" for k, v in SCENES.items()) + ".")
    p.add_argument("--scene", default=None, metavar="NAME",
                   help=f"one of {', '.join(SCENES)} (default: blow for --air blow, evaporate for --air curl, "
                        "else gravity)")
    p.add_argument("--air", default=None, metavar="KIND",
                   help="none, blow (a rotating ball of air from 0.25 s on) or curl (curl noise); "
                        "overrides the scene's air")
    p.add_argument("--grid", default="128x256", metavar="NxM",
                   help="cells N_THETA x N_PHI (N_PHI even, N_THETA >= 4; default 128x256; the thesis uses 1024x2048)")
    p.add_argument("--seconds", default="2", metavar="S", help="simulated time in seconds (> 0; default 2)")
    p.add_argument("--dt-seconds", default="0.002", metavar="S",
                   help="time step in seconds (> 0; default 0.002, the thesis')")
    p.add_argument("--radius", default="0.05", metavar="M", help="bubble radius R in m (default 0.05)")
    p.add_argument("--eta0", default="5e-7", metavar="M",
                   help="mean HALF thickness in m (default 5e-7: a 1000 nm film)")
    p.add_argument("--gamma0", default="1.669e-7", metavar="MOL_M2",
                   help="mean surfactant concentration in mol/m^2 (default 1.669e-7: M = 0.83)")
    p.add_argument("--frames", type=int, default=8, metavar="K",
                   help="frames saved after the start (equally spaced in time; default 8)")
    p.add_argument("--render-size", type=int, default=256, metavar="PX",
                   help="rendered PNG size in pixels (default 256; 0 = no rendered PNGs)")
    p.add_argument("--seed", type=int, default=0, help="seed of the scene's noise (default 0)")
    p.add_argument("--float64", action="store_true",
                   help="keep the state (advection, BiMocq maps) in double precision too (the surfactant solve "
                        "always runs in double)")
    p.add_argument("--out", default="out/bubble", metavar="DIR", help="output folder (default out/bubble)")
    p.set_defaults(fn=run)


# ------------------------------------------------------------------------- option checks
def _positive(option: str, text) -> float:
    try:
        v = float(text)
    except (TypeError, ValueError):
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise checks.UsageError(f"{option} {text}: must be a finite number > 0")
    return v


def _options(args):
    """Every option checked before anything is compiled; returns a dict of the parsed values."""
    from ..soapfilm.grid import SphereGrid
    from ..soapfilm.scenes import AIR_FOR_SCENE, SCENES

    o = {}
    try:
        o["grid"] = SphereGrid.parse(args.grid)
    except (ValueError, TypeError) as e:
        raise checks.UsageError(f"--grid {args.grid}: {e}") from None
    if args.air is not None and args.air not in SCENE_FOR_AIR:
        raise checks.UsageError(f"--air {args.air}: must be one of {', '.join(SCENE_FOR_AIR)}")
    scene = args.scene if args.scene is not None else SCENE_FOR_AIR.get(args.air, "gravity")
    if scene not in SCENES:
        raise checks.UsageError(f"--scene {args.scene}: must be one of {', '.join(SCENES)}")
    o["scene"] = scene
    o["air"] = args.air if args.air is not None else AIR_FOR_SCENE[scene]
    o["seconds"] = _positive("--seconds", args.seconds)
    o["dt_seconds"] = _positive("--dt-seconds", args.dt_seconds)
    o["R"] = _positive("--radius", args.radius)
    o["eta0"] = _positive("--eta0", args.eta0)
    o["Gamma0"] = _positive("--gamma0", args.gamma0)
    o["frames"] = checks.count("--frames", args.frames)
    o["render_size"] = checks.count("--render-size", args.render_size, lo=8, zero=True)
    n_steps = int(round(o["seconds"] / o["dt_seconds"]))
    if n_steps < 1:
        raise checks.UsageError(f"--seconds {args.seconds}: shorter than one step of --dt-seconds {args.dt_seconds}")
    o["n_steps"] = n_steps
    checks.out_folder("--out", args.out)
    return o


# ------------------------------------------------------------------------- images
def environment(d):
    """The render's environment (linear RGB): dark behind the bubble, a bright sky on the camera's
    side (bluish above, warm towards the ground), so the film's reflected interference colours
    show against a dark background."""
    import jax.numpy as jnp

    front = jnp.clip(0.5 - d.y, 0.0, 1.0) ** 2  # the camera looks along +y from -y
    sky = jnp.stack([0.85 + 0.15 * d.z, 0.9 + 0.1 * d.z, 1.0 + 0.0 * d.z], axis=-1)
    ground = jnp.stack([0.55 + 0.0 * d.z, 0.45 + 0.0 * d.z, 0.35 + 0.0 * d.z], axis=-1)
    up = jnp.clip(0.5 + 2.0 * d.z, 0.0, 1.0)[..., None]
    return 0.02 + front[..., None] * (up * sky + (1.0 - up) * ground)


def _renderer(size: int):
    """A compiled ``thickness_nm map -> (image, mask)`` (the map is traced: one compilation)."""
    import jax

    from ..soapfilm.bubble import render
    from ..soapfilm.thickness import latlong_field

    @jax.jit
    def f(values_nm):
        return render(size, environment, latlong_field(values_nm))

    return f


def _srgb8(linear, exposure):
    from ..core.spectral import linear_to_srgb

    v = np.clip(np.asarray(linear, np.float64) * exposure, 0.0, 1.0)
    return (np.clip(np.asarray(linear_to_srgb(v)), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def _write_map(path, thickness_nm, vmax):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.imsave(path, np.asarray(thickness_nm, np.float64), cmap="magma", vmin=0.0, vmax=vmax)


def _write_sheet(path, frames, vmax, out):
    """One figure: renders (top row, if any) and thickness maps (bottom row) with their times."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = 2 if frames[0].get("png") else 1
    n = len(frames)
    fig, axes = plt.subplots(rows, n, figsize=(2.0 * n, 0.9 + (3.0 if rows == 2 else 1.0)), dpi=100, squeeze=False,
                             gridspec_kw={"height_ratios": [2, 1][-rows:]})
    im = None
    for k, fr in enumerate(frames):
        if rows == 2:
            axes[0, k].imshow(plt.imread(os.path.join(out, fr["png"])))
        with np.load(os.path.join(out, fr["npz"])) as z:
            im = axes[-1, k].imshow(z["thickness_nm"], cmap="magma", vmin=0.0, vmax=vmax)
        axes[0, k].set_title(f"t = {fr['time_s']:.3g} s", fontsize=8)
        for a in axes[:, k]:
            a.set_xticks([])
            a.set_yticks([])
    fig.colorbar(im, ax=axes[-1, :].tolist(), orientation="horizontal", fraction=0.08, pad=0.04,
                 label="full film thickness [nm]  (maps: theta top to bottom, phi left to right)")
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)


# ------------------------------------------------------------------------- run
def _scheme_drift(carry) -> dict:
    """``scheme_eta``/``scheme_gamma``: the relative change of the integrals made by the scheme
    itself (``Carry.drift_log``), and whether flow rescaled it away (``conserved``)."""
    from ..soapfilm import flow

    log = getattr(carry, "drift_log", None)
    if log is None:
        return {}
    e, g = (float(np.expm1(v)) for v in np.asarray(log, np.float64))
    return {"scheme_eta": e, "scheme_gamma": g, "conserved": bool(getattr(flow.Settings(), "conserve", False))}


def run(args) -> int:
    o = _options(args)
    import jax

    # x64 on in any case: the surfactant solve runs in float64 (flow.Settings.solve_dtype "auto";
    # a float32 solve is unstable in the pole rows from ~512 x 1024 on); --float64 makes the
    # state (advection, maps) double too
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    from ..soapfilm import flow, scenes

    t_start = time.perf_counter()
    grid, R, eta0 = o["grid"], o["R"], o["eta0"]
    dtype = jnp.float64 if args.float64 else jnp.float32
    scene = scenes.build(o["scene"], grid, R=R, eta0=eta0, Gamma0=o["Gamma0"], seed=args.seed, dtype=dtype)
    air, description = scene.air, scene.description
    if o["air"] != scenes.AIR_FOR_SCENE[o["scene"]]:
        air = scenes.air_field(o["air"], R=R, seed=args.seed)
        description += f" Air replaced (--air {o['air']}): {air!r}."
    nums = scenes.numbers(R, eta0, o["Gamma0"])
    dt = float(flow.seconds_to_time(o["dt_seconds"], R))
    n_steps, K = o["n_steps"], min(o["frames"], o["n_steps"])
    bounds = [round(k * n_steps / K) for k in range(K + 1)]  # chunk lengths are traced: one compilation
    os.makedirs(args.out, exist_ok=True)
    nm = 2.0 * eta0 * 1e9  # full thickness (nm) of eta = 1
    vmax = 2.0 * nm
    theta, phi = grid.theta_centres(), grid.phi_centres()
    render = _renderer(o["render_size"]) if o["render_size"] else None
    print(f"bubble-sim: {description}")
    print(f"grid {grid.n_theta}x{grid.n_phi}, {n_steps} steps of {o['dt_seconds']:g} s (dt = {dt:.4g} R/U), "
          f"air {o['air']}, {K} frames, {'float64' if args.float64 else 'float32'}", flush=True)

    frames, exposure, render_s = [], None, 0.0
    area = float(np.sum(grid.cell_areas()))

    def save(k, state, t_dimless, step):
        nonlocal exposure, render_s
        th = np.asarray(2.0 * state.eta, np.float64) * eta0 * 1e9
        rec = {"index": k, "step": int(step), "time_s": float(flow.time_to_seconds(float(t_dimless), R)),
               "npz": f"frame_{k:04d}.npz", "map_png": f"thickness_{k:04d}.png",
               "min_thickness_nm": float(th.min()), "max_thickness_nm": float(th.max())}
        np.savez_compressed(os.path.join(args.out, rec["npz"]), thickness_nm=th.astype(np.float32), theta=theta,
                            phi=phi, time_s=rec["time_s"], step=rec["step"],
                            gamma=np.asarray(state.gamma, np.float32))
        _write_map(os.path.join(args.out, rec["map_png"]), th, vmax)
        if render is not None:
            t0 = time.perf_counter()
            img, mask = render(jnp.asarray(th, dtype))
            img, mask = np.asarray(img), np.asarray(mask)
            if exposure is None:  # fixed from the first frame, so brightness compares across frames
                peak = np.percentile(img[mask], EXPOSURE_PERCENTILE) if mask.any() else 1.0
                exposure = EXPOSURE_LEVEL / max(float(peak), 1e-6)
            rec["png"] = f"frame_{k:04d}.png"
            import matplotlib.pyplot as plt

            plt.imsave(os.path.join(args.out, rec["png"]), _srgb8(img, exposure))
            render_s += time.perf_counter() - t0
        frames.append(rec)

    carry = flow.start(grid, scene.state)
    integrals0 = [float(grid.integral(scene.state.eta)), float(grid.integral(scene.state.gamma))]
    save(0, scene.state, 0.0, 0)
    step_s, step_n, sim_s = 0.0, 0, 0.0
    cg_max, res_max, res_last, stopped = 0, None, None, None  # None: no step ran
    error = None
    for k in range(1, K + 1):
        n = bounds[k] - bounds[k - 1]
        t0 = time.perf_counter()
        try:
            res = flow.simulate(grid, scene.params, scene.state, dt, n, air=air, carry=carry)
        except flow.FlowError as e:  # an unconverged solve or a non-finite state: report, keep the files
            error = str(e)
            print(f"appearance-jax {NAME}: error: {error}", file=sys.stderr, flush=True)
            break
        carry = res.carry
        jax.block_until_ready(carry.state.eta)
        took = time.perf_counter() - t0
        sim_s += took
        if k > 1:  # every chunk runs the first one's program (steps per chunk are traced)
            step_s += took
            step_n += n
        # one frame per chunk: the largest iteration count and residual over its steps
        its, resid = np.asarray(res.info.cg_iterations), np.asarray(res.info.cg_residual)
        cg_max = max(cg_max, int(its.max()))
        res_max = max(res_max or 0.0, float(resid.max()))
        res_last = float(resid[-1])
        save(k, carry.state, carry.t, int(carry.n))
        f = frames[-1]
        print(f"frame {k}/{K}: step {int(carry.n)}/{n_steps}, t = {f['time_s']:.4g} s, thickness "
              f"{f['min_thickness_nm']:.0f}-{f['max_thickness_nm']:.0f} nm, cg <= {int(its.max())} its, "
              f"{took:.1f} s", flush=True)
        if res.stopped is not None:
            stopped = res.stopped
            print(f"stopped: {stopped}", flush=True)
            break

    st = carry.state
    integrals = [float(grid.integral(st.eta)), float(grid.integral(st.gamma))]
    t_end = float(carry.t)
    maps = carry.maps
    summary = {
        "scene": o["scene"], "air": o["air"], "description": description,
        "grid": f"{grid.n_theta}x{grid.n_phi}", "n_theta": grid.n_theta, "n_phi": grid.n_phi,
        "dtype": "float64" if args.float64 else "float32", "solve_dtype": "float64",
        "device": jax.devices()[0].platform,
        "steps": int(carry.n), "steps_requested": n_steps,
        "dt_seconds": o["dt_seconds"], "dt": dt,
        "seconds_requested": o["seconds"], "simulated_seconds": float(flow.time_to_seconds(t_end, R)),
        "simulated_time": t_end,
        "wall_seconds": time.perf_counter() - t_start,
        "simulate_seconds": sim_s,
        "step_seconds": step_s if step_n else None,
        "seconds_per_step": step_s / step_n if step_n else None,
        "render_seconds": render_s,
        "relative_drift": {
            "eta": (integrals[0] - integrals0[0]) / integrals0[0],
            "gamma": (integrals[1] - integrals0[1]) / integrals0[1],
            # uniform evaporation removes rate * t from eta everywhere (the one non-conservative term)
            "eta_expected_from_evaporation": 0.0 - float(scene.params.evaporation) * t_end * area / integrals0[0],
            # the scheme's own drift, before flow's conserving rescale (Settings.conserve) removes it
            **_scheme_drift(carry),
        },
        "integrals": {"eta_start": integrals0[0], "eta_end": integrals[0], "gamma_start": integrals0[1],
                      "gamma_end": integrals[1]},
        "cg": {"max_iterations": cg_max, "final_residual": res_last, "max_residual": res_max,
               "rtol": flow.Settings().rtol(dtype)},
        "n_reinit": int(maps.n_reinit) if maps is not None else 0,
        "stopped": stopped,
        "error": error,
        "numbers": {"R_m": R, "eta0_m": eta0, "Gamma0_mol_m2": o["Gamma0"], "U_m_s": 1.0,
                    **{k: float(getattr(nums, k)) for k in ("epsilon", "M", "Re", "Cr", "g")},
                    "g_over_M": float(nums.g_over_M), "evaporation": float(scene.params.evaporation),
                    "time_unit_s": R},
        "render": {"size": o["render_size"], "exposure": exposure,
                   "environment": "dark behind, bright sky on the camera side (bubble_cmd.environment)"},
        "frames": frames,
    }
    _write_sheet(os.path.join(args.out, "sheet.png"), frames, vmax, args.out)
    with open(os.path.join(args.out, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=2)
    d = summary["relative_drift"]
    print(f"done: {summary['steps']} steps, {summary['simulated_seconds']:.4g} s simulated in "
          f"{summary['wall_seconds']:.1f} s wall; drift eta {d['eta']:.2e} (evaporation {d['eta_expected_from_evaporation']:.2e}),"
          f" gamma {d['gamma']:.2e}; cg <= {cg_max} its; {summary['n_reinit']} re-inits"
          + (f"; STOPPED early: {stopped}" if stopped else ""))
    print(f"wrote {args.out}/summary.json, sheet.png and frame_*.npz / thickness_*.png"
          + (" / frame_*.png" if render is not None else ""))
    return checks.EXIT_FAILURE if error else checks.EXIT_OK
