"""Data of the cosmetics recipe (fitting/cosmetics.py): measurement layouts, synthetic tables made
by the position-free random walk (cached on disk), the perturbed start.

Layouts (angles in degrees here, radians in the tables):

- ``inplane``: the layout of Fig. 4.4 of Padron 2025: theta_i in {0, 10, ..., 70}, signed
  theta_o in {-80, ..., 80} (negative: retro side), 136 cells; missing: the retro-reflection
  cell of every row (|theta_o + theta_i| < 10: the detector arm would block the beam) and the
  grazing cells |theta_o| = 80 at theta_i >= 60.
- ``gonio``: an out-of-plane gonioreflectometer set: theta_i in {20, 40, 60} x theta_o in
  {10, 30, 50, 70} x phi_o - phi_i in {0, 45, 90, 135, 180}, plus theta_i = 0 x the four
  theta_o (at normal incidence the azimuth is irrelevant for an unoriented sample, and with
  ``azimuth="averaged"`` f depends on (theta_i, theta_o, delta phi) only: the other phi_o
  would be replicas), 64 cells. Why this set: theta_o on the odd multiples of 10 deg
  interleaves with the in-plane grid (the combined layout samples the plane of incidence and
  the specular neighbourhood every 10 deg in theta_o on both grids), the 45 deg azimuth
  steps sample how the diffusers' forward lobe and the platelet highlight fall off out of
  the plane (what separates a forward-peaked phase function from a broad one at the same
  in-plane profile), and theta_i <= 60 / theta_o <= 70 avoid grazing cells. No cell lies
  within 10 deg of retro-reflection, so none is missing.
- ``combined``: the two tables concatenated (200 cells; the same noise realisations).

Tables: f and the generator's standard error se from the walk (``cosmetics``,
``azimuth="averaged"``) at ``gen_samples`` paths x ``gen_bounces`` steps per cell (key
1000 + seed for in-plane, 2000 + seed for gonio: independent errors), cached as .npz files
keyed by preset, layout, counts and key (a rerun loads them); then 2 % multiplicative Gaussian
noise (numpy seed per layout) and sigma = sqrt((noise f)^2 + se^2) stated in the table.
"""

from __future__ import annotations

import csv
import json
import os
import time

import numpy as np

NOISE = 0.02
PERTURB = 0.15
THETA_I = np.arange(0, 71, 10)
THETA_O = np.arange(-80, 81, 10)
LAYOUTS = ("inplane", "gonio", "combined")
PIECES = {"inplane": ("inplane",), "gonio": ("gonio",), "combined": ("inplane", "gonio")}
KEY_OFFSET = {"inplane": 1000, "gonio": 2000}


def in_plane_layout(theta_i=THETA_I, theta_o=THETA_O):
    """(theta_i, signed theta_o) in radians, row-major, and the validity mask (missing cells False)."""
    ti, to = (a.ravel() for a in np.meshgrid(theta_i, theta_o, indexing="ij"))
    retro = np.abs(to + ti) < 10 - 1e-9  # detector blocks the beam (theta_o = -theta_i on a 10 deg grid)
    grazing = (np.abs(to) >= 80) & (ti >= 60)  # low signal at grazing
    return np.deg2rad(ti.astype(float)), np.deg2rad(to.astype(float)), ~(retro | grazing), \
        dict(retro=int(retro.sum()), grazing=int((grazing & ~retro).sum()))


def quick_layout():
    """A coarse in-plane layout for smoke runs: theta_i {0, 20, 40, 60}, theta_o every 20 deg."""
    return in_plane_layout(np.arange(0, 61, 20), np.arange(-80, 81, 20))


def gonio_angles(theta_i=(20, 40, 60), theta_o=(10, 30, 50, 70), phi_o=(0, 45, 90, 135, 180), normal=True):
    """(theta_i, phi_i, theta_o, phi_o) in radians of the out-of-plane layout (module docstring)."""
    g = [a.ravel() for a in np.meshgrid(theta_i, theta_o, phi_o, indexing="ij")]
    ti, to, po = (np.asarray(a, float) for a in g)
    if normal:
        n = np.asarray(theta_o, float)
        ti, to, po = np.concatenate([np.zeros_like(n), ti]), np.concatenate([n, to]), np.concatenate([0 * n, po])
    return tuple(np.deg2rad(a) for a in (ti, np.zeros_like(ti), to, po))


def _empty_table(piece, layout=None):
    """The piece's Table with zero values, its validity mask (N,) and masked-reason counts."""
    from appearance_jax.fit.tables.table import Table

    if piece == "inplane":
        ti, to, valid, counts = layout or in_plane_layout()
        t = Table.in_plane(ti, to, np.zeros((ti.size, 3)), source="synthetic cosmetics")
        masked = {"retro-reflection (detector blocks the beam)": 3 * counts["retro"],
                  "grazing (|theta_o| = 80, theta_i >= 60)": 3 * counts["grazing"]}
        return t, valid, masked
    if piece == "gonio":
        ti, pi, to, po = gonio_angles()
        t = Table(theta_i=ti, phi_i=pi, theta_o=to, phi_o=po, values=np.zeros((ti.size, 3)),
                  mask=np.ones((ti.size, 3), bool), source="synthetic cosmetics")
        return t, np.ones(ti.size, bool), {}
    raise ValueError(f"unknown layout piece {piece!r}")


def walk_values(preset, piece, *, gen_samples, gen_bounces, seed=0, cache_dir=None, layout=None, progress=print):
    """(f, se, gen_time) of the walk on a layout piece, from the .npz cache when there is one."""
    path = None
    if cache_dir and layout is None:
        path = os.path.join(cache_dir, f"walk_{preset}_{piece}_{gen_samples}x{gen_bounces}_key{KEY_OFFSET[piece] + seed}.npz")
        if os.path.exists(path):
            z = np.load(path)
            return z["f"], z["se"], float(z["gen_time"])
    import jax

    from appearance_jax.bsdf import cosmetics

    t, _, _ = _empty_table(piece, layout)
    wi, wo = t.directions()
    p = cosmetics.PRESETS[preset].replace(azimuth="averaged", n_samples=gen_samples, max_bounces=gen_bounces)
    ev = jax.jit(lambda q, a, b, k: cosmetics.MODEL.eval.kernel(q, a, b, key=k))
    t0 = time.perf_counter()
    f, se = (np.asarray(a, np.float64) for a in jax.block_until_ready(ev(p, wi, wo, jax.random.key(KEY_OFFSET[piece] + seed))))
    gen_time = time.perf_counter() - t0
    progress(f"  walk {preset}/{piece}: {t.n_samples} cells x {gen_samples} paths x {gen_bounces} steps, {gen_time:.1f} s")
    if path:
        os.makedirs(cache_dir, exist_ok=True)
        np.savez(path, f=f, se=se, gen_time=gen_time)
    return f, se, gen_time


def synthetic_table(preset, layout="inplane", *, gen_samples=16384, gen_bounces=256, noise=NOISE, seed=0,
                    cache_dir=None, custom=None, progress=print):
    """The preset's RGB table on ``layout`` (walk values + noise, sigma stated) and an info dict
    (f_true, se_gen: the walk's own value and standard error; generation time). ``custom``: an
    in-plane layout tuple (:func:`in_plane_layout`) instead of the named one (not cached)."""
    from appearance_jax.fit.tables.table import Table

    parts = []
    for k, piece in enumerate(PIECES[layout]):
        t, valid, masked = _empty_table(piece, custom)
        f, se, gt = walk_values(preset, piece, gen_samples=gen_samples, gen_bounces=gen_bounces, seed=seed,
                                cache_dir=cache_dir, layout=custom, progress=progress)
        rng = np.random.default_rng([seed, KEY_OFFSET[piece]])
        values = f * (1.0 + noise * rng.standard_normal(f.shape))
        parts.append((t, valid, masked, f, se, values, gt))
    cat = lambda i: np.concatenate([p[i] for p in parts])  # noqa: E731
    t0 = parts[0][0]
    f, se, values, valid = cat(3), cat(4), cat(5), cat(1)
    masked = {}
    for p in parts:
        masked.update(p[2])
    mask = np.repeat(valid[:, None], 3, axis=1)
    table = Table(theta_i=np.concatenate([p[0].theta_i for p in parts]),
                  phi_i=np.concatenate([p[0].phi_i for p in parts]),
                  theta_o=np.concatenate([p[0].theta_o for p in parts]),
                  phi_o=np.concatenate([p[0].phi_o for p in parts]),
                  values=np.where(mask, values, np.nan), sigma=np.sqrt((noise * f) ** 2 + se ** 2), mask=mask,
                  masked=masked, bands=t0.bands,
                  source=f"synthetic cosmetics {preset}/{layout} (walk {gen_samples} paths x {gen_bounces} steps, "
                         f"{noise:.0%} noise)")
    rel = se[valid] / np.maximum(f[valid], 1e-12)
    gen_time = sum(p[6] for p in parts)
    progress(f"  table: {table.summary()}; walk MC stderr median {np.median(rel):.2%}, max {rel.max():.2%} of f")
    return table, dict(f_true=f, se_gen=se, gen_time=gen_time, se_gen_rel_median=float(np.median(rel)),
                       se_gen_rel_max=float(rel.max()))


def perturbed_start(model, truth, free, perturb=PERTURB):
    """The truth with every free value moved by +-perturb (alternating signs, inwards at a bound)."""
    from appearance_jax.core.params import param_specs

    specs = param_specs(model.Params)
    kw, sign = {}, 1.0
    for name in free:
        s = specs[name]
        v = np.atleast_1d(np.asarray(getattr(truth, name), np.float64)).copy()
        for j in range(v.size):
            lo = s.lo + 1e-3 * (s.hi - s.lo)
            hi = s.hi - 1e-3 * (s.hi - s.lo)
            step = perturb * max(abs(v[j]), 0.05)  # tilt 0 or g near 0 still move
            nv = v[j] + sign * step
            if not lo <= nv <= hi:
                nv = v[j] - sign * step
            v[j] = float(np.clip(nv, lo, hi))
            sign = -sign
        kw[name] = tuple(v) if v.size > 1 else float(v[0])
    return truth.replace(**kw)


def powell_fit(loss, prob, x0, n_valid, maxfev, *, warm=False):
    """SciPy's Powell on ``loss(x, data) / n_valid`` (x physical), each parameter bounded 1e-4 of
    its range inside the range. ``warm``: one timed call first (the loss's compile, counted as an
    evaluation). Returns dict(time, compile, evals, iterations, loss, x, message)."""
    import jax
    import jax.numpy as jnp
    from scipy.optimize import minimize

    from appearance_jax.core.params import param_specs

    specs = param_specs(prob.model.Params)
    bounds = []
    for f in prob.space.fields:
        s = specs[f.name]
        eps = 1e-4 * (s.hi - s.lo)
        bounds += [(s.lo + eps, s.hi - eps)] * f.size
    count = [0]
    data = jax.device_put(prob.data)  # on the device once (build_problem's are numpy): calls move only x

    def objective(x):
        count[0] += 1
        return float(loss(jnp.asarray(x, jnp.result_type(float)), data)) / n_valid

    t_c = 0.0
    if warm:
        t0 = time.perf_counter()
        objective(x0)
        t_c = time.perf_counter() - t0
    t0 = time.perf_counter()
    opt = minimize(objective, x0, method="Powell", bounds=bounds, options=dict(xtol=1e-3, ftol=1e-5, maxfev=maxfev))
    return dict(time=time.perf_counter() - t0, compile=t_c, evals=count[0], iterations=int(opt.nit),
                loss=float(opt.fun), x=np.asarray(opt.x), message=str(opt.message))


def write_records(out, rows, summaries, **extra):
    """results.csv (one row per parameter), summary.json and one <name>.json per ``extra`` item."""
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "results.csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    for name, obj in (("summary", summaries),) + tuple(extra.items()):
        with open(os.path.join(out, f"{name}.json"), "w") as fh:
            json.dump(obj, fh, indent=1)


def generate(argv=None):
    """Fill the cache: ``python3 fitting/cosmetics_data.py --out out/cosmetics [--cases ...]``."""
    import argparse

    ap = argparse.ArgumentParser(description=generate.__doc__)
    ap.add_argument("--out", default="out/cosmetics")
    ap.add_argument("--cases", default="dewy1,dewy2,matte1,matte2")
    ap.add_argument("--pieces", default="inplane,gonio")
    ap.add_argument("--gen-samples", type=int, default=16384)
    ap.add_argument("--gen-bounces", type=int, default=256)
    a = ap.parse_args(argv)
    for c in a.cases.split(","):
        for piece in a.pieces.split(","):
            walk_values(c, piece, gen_samples=a.gen_samples, gen_bounces=a.gen_bounces,
                        cache_dir=os.path.join(a.out, "tables"))


if __name__ == "__main__":
    generate()
