"""The Monte Carlo fit path of the cosmetics recipe (``fitting/cosmetics.py --solver walk``).

The cosmetics BSDF (:mod:`appearance_jax.bsdf.cosmetics`) is a position-free random walk that
returns (estimate, standard error). This path fits it with common random numbers (CRN): one
fixed PRNG key at every iterate, so the residual is a smooth deterministic function of the
parameters and Levenberg-Marquardt sees a consistent Jacobian (forward mode through the walk;
the discrete choices carry score terms). The thesis fitted with SciPy's modified Powell over
the same kind of noisy MC objective [T:774]; this path runs both on the same objective (same
key, same sample counts, a jitted scalar loss for Powell).

The fitted model's own MC error at ``samples`` paths per cell is frozen by CRN into a fixed
random error per cell, larger than 2 % at 64-128 paths. With ``mc_weights`` (default) it is
folded into the residual weights, w = sigma^2 / (sigma^2 + se_fit^2) (se_fit estimated at the
start, with the fit's key), so the reported 1-sigma values and the reduced chi-square are
honest. Afterwards: the loss re-estimated with fresh keys (CRN bias check), the truncation
bias of ``bounces`` against the generator's count (in-plane layout), and sigma from a Jacobian
at ``cov_samples`` paths (the CRN Jacobian's own MC noise inflates J^T J). The deterministic
default path (``--solver ordinates``) and the data: fitting/cosmetics.py, fitting/cosmetics_data.py.
"""

from __future__ import annotations

import dataclasses
import os
import time

import numpy as np

from cosmetics_data import NOISE, perturbed_start, powell_fit, synthetic_table, write_records

FREE = ("c_d", "albedo_d", "albedo_p", "w_g", "g1", "g2", "alpha", "theta")
ALWAYS_FIXED = ("thickness", "base_reflectance")


def _eval_fn(model):
    import jax

    return jax.jit(lambda p, wi, wo, k: model.eval.kernel(p, wi, wo, key=k))


def run_case(name, *, free=FREE, samples=64, bounces=64, gen_samples=4096, gen_bounces=512, noise=NOISE,
             seed=0, fit_key=0, max_steps=12, rtol=1e-4, atol=1e-7, mc_weights=True, powell=True,
             powell_maxfev=2000, layout="inplane", custom_layout=None, cache_dir=None, fresh_keys=3, truncation=True,
             cov_samples=256, out=None, plots=True, progress=print):
    """Generate, fit (LM, then Powell on the same objective), check; returns (rows, summary, result)."""
    import jax
    import jax.numpy as jnp

    from appearance_jax.bsdf import cosmetics
    from appearance_jax.fit import fit
    from appearance_jax.fit.solve import build_problem
    from appearance_jax.fit.solve.transforms import ParamSpace

    model = cosmetics.MODEL
    free = tuple(free)
    fix = list(ALWAYS_FIXED) + [n for n in FREE if n not in free]
    truth = cosmetics.PRESETS[name].replace(azimuth="averaged")
    progress(f"{name}: free {', '.join(free)}; fit {samples} paths x {bounces} steps "
             f"({jnp.dtype(jnp.result_type(float)).name}), generator {gen_samples} x {gen_bounces}")
    table, info = synthetic_table(name, layout, gen_samples=gen_samples, gen_bounces=gen_bounces, noise=noise,
                                  seed=seed, cache_dir=cache_dir, custom=custom_layout, progress=progress)
    ev = _eval_fn(model)
    wi, wo = table.directions()
    valid = table.mask[:, 0]
    key = jax.random.key(fit_key)

    # truncation bias of the fit's step count (CRN: the same paths, cut at `bounces` instead of gen_bounces;
    # jax's partitionable threefry splits are prefix-stable, so the first steps are identical)
    lost = lost_max = float("nan")
    if truncation and bounces < gen_bounces and layout == "inplane":  # the generator's key: in-plane
        f_cut, _ = ev(truth.replace(n_samples=gen_samples, max_bounces=bounces), wi, wo, jax.random.key(1000 + seed))
        f_cut = np.asarray(f_cut, np.float64)
        lost = 1.0 - f_cut[valid].sum() / info["f_true"][valid].sum()
        lost_max = float(np.max(1.0 - f_cut[valid] / np.maximum(info["f_true"][valid], 1e-12)))
        progress(f"  truncation at {bounces} steps: {lost:.3%} of the in-plane signal lost (worst cell {lost_max:.2%})")

    start = perturbed_start(model, truth, free).replace(n_samples=samples, max_bounces=bounces)
    weights = None
    if mc_weights:  # the fit model's frozen MC error (CRN) as extra per-cell noise, estimated at the start
        _, se_fit = ev(start, wi, wo, key)
        se_fit = np.asarray(se_fit, np.float64)
        s2 = np.where(table.mask, table.sigma, 1.0) ** 2
        weights = s2 / (s2 + se_fit ** 2)
        info["se_fit_rel_median"] = float(np.median(se_fit[valid] / np.maximum(info["f_true"][valid], 1e-12)))
        progress(f"  fit model MC stderr (CRN, {samples} paths): median {info['se_fit_rel_median']:.1%} of f "
                 "-> folded into the weights")

    prob = build_problem(model, table, init=start, fix=fix, key=key, weights=weights)
    sp = prob.space
    # one jitted scalar loss with the key as an argument (the Problem with another key: same program)
    keyed_loss = jax.jit(lambda x, d, k: jnp.sum(dataclasses.replace(prob, key=k).residuals_x(x, d) ** 2))
    n_valid = int((np.asarray(prob.data["weight"]) > 0).sum())

    def loss_fn(x, d):
        return keyed_loss(x, d, key)

    x0 = sp.x_start()
    t0 = time.perf_counter()
    loss_start = float(loss_fn(jnp.asarray(x0), prob.data)) / n_valid
    loss_compile = time.perf_counter() - t0

    res = fit(model, table, init=start, fix=fix, key=key, weights=weights, solver="lm", rtol=rtol, atol=atol,
              max_steps=max_steps)
    progress(f"  LM: loss {loss_start:.4g} -> {res.loss:.4g} in {res.iterations} iterations, {res.wall_time:.1f} s "
             f"(+ {res.compile_time:.1f} s compile), converged {res.converged}")
    truth_x = ParamSpace(truth, table.n_bands, fix=fix, band_names=table.bands).x_from_params(truth)
    loss_truth = float(loss_fn(jnp.asarray(truth_x), prob.data)) / n_valid

    # CRN bias check: the same fitted (and true) parameters with fresh keys
    def loss_with(x, k):
        return float(keyed_loss(jnp.asarray(x, jnp.result_type(float)), prob.data, jax.random.key(k))) / n_valid

    fresh = [loss_with(res.x, 7919 + i) for i in range(fresh_keys)]
    fresh_truth = [loss_with(truth_x, 7919 + i) for i in range(fresh_keys)]
    progress(f"  CRN check: loss at the fit {res.loss:.4g} (fit key) vs {np.mean(fresh):.4g} (fresh keys, mean of "
             f"{fresh_keys}); at the truth {loss_truth:.4g} (fit key) vs {np.mean(fresh_truth):.4g} (fresh)")

    # the FitResult's sigmas come from the CRN Jacobian at `samples` paths; its own MC noise inflates J^T J
    # (weakly identified parameters look precise). Recompute them from a Jacobian at cov_samples paths,
    # scaled by the reduced chi-square (the MC weights are only an estimate of the frozen MC error).
    sigma_hi = np.full(sp.size, np.nan)
    if cov_samples and cov_samples > samples:
        from appearance_jax.fit.solve import covariance

        t0 = time.perf_counter()
        prob_hi = build_problem(model, table, init=start.replace(n_samples=cov_samples), fix=fix,
                                key=jax.random.key(fit_key + 1), weights=weights)
        cov_hi = np.asarray(jax.jit(lambda x, d: covariance(prob_hi, x, d)[0])(
            jnp.asarray(res.x, jnp.result_type(float)), prob_hi.data), np.float64)
        chi2 = max(float(res.loss) * n_valid / max(n_valid - sp.size, 1), 1.0)
        sigma_hi = np.sqrt(np.abs(np.diag(cov_hi)) * chi2)
        progress(f"  sigma from a {cov_samples}-path Jacobian x reduced chi-square {chi2:.2f}: "
                 f"{time.perf_counter() - t0:.1f} s")

    pw = None
    if powell:
        pw = powell_fit(loss_fn, prob, x0, n_valid, powell_maxfev)
        pw["compile"] = loss_compile
        progress(f"  Powell: loss {pw['loss']:.4g} in {pw['evals']} evaluations ({pw['iterations']} sweeps), "
                 f"{pw['time']:.1f} s (+ {loss_compile:.1f} s compile of the loss); {pw['message']}")

    rows = []
    for i, label in enumerate(res.labels):
        sig = float(res.sigma[i])
        flag = "at bound" if label in res.at_bound else "poorly determined" if label in res.poorly_determined else ""
        rows.append(dict(case=name, parameter=label, truth=float(truth_x[i]), start=float(x0[i]), fit=float(res.x[i]),
                         sigma=sig, z=(float(res.x[i]) - truth_x[i]) / sig if sig > 0 and np.isfinite(sig)
                         else float("nan"), sigma_hi=float(sigma_hi[i]),
                         z_hi=(float(res.x[i]) - truth_x[i]) / sigma_hi[i] if np.isfinite(sigma_hi[i]) and
                         sigma_hi[i] > 0 else float("nan"), flag=flag,
                         powell=float(pw["x"][i]) if pw else float("nan")))
    summary = dict(case=name, n_free=sp.size, n_valid=n_valid, samples=samples, bounces=bounces,
                   gen_samples=gen_samples, gen_bounces=gen_bounces, noise=noise, mc_weights=mc_weights,
                   truncation_lost=float(lost), truncation_lost_worst_cell=lost_max,
                   loss_start=loss_start, loss_lm=float(res.loss), loss_truth_fit_key=loss_truth,
                   loss_lm_fresh=float(np.mean(fresh)), loss_truth_fresh=float(np.mean(fresh_truth)),
                   lm_iterations=int(res.iterations), lm_time=float(res.wall_time),
                   lm_compile=float(res.compile_time), lm_converged=bool(res.converged),
                   powell_loss=pw["loss"] if pw else float("nan"), powell_evals=pw["evals"] if pw else 0,
                   powell_time=pw["time"] if pw else float("nan"), powell_compile=loss_compile,
                   poorly_determined=list(res.poorly_determined), at_bound=list(res.at_bound),
                   **{k: v for k, v in info.items() if not isinstance(v, np.ndarray)})
    if out:
        from appearance_jax.fit import write_report

        d = os.path.join(out, f"{name}_{layout}_walk")
        try:
            t0 = time.perf_counter()
            write_report(res, d, model=model, progress=None, plots=plots,
                         extra=dict(recipe="fitting/cosmetics.py --solver walk", summary=summary))
            progress(f"  report: {d} ({time.perf_counter() - t0:.1f} s)")
        except Exception as e:  # noqa: BLE001 - report and keep the numbers
            progress(f"  write_report failed: {type(e).__name__}: {e}")
            summary["write_report_error"] = f"{type(e).__name__}: {e}"
    return rows, summary, res


def write_results(rows, summaries, out):
    write_records(out, rows, summaries)
    lines = ["| case | parameter | truth | start | LM fit ± 1σ (CRN J) | z | σ (hi-sample J, ×χ²) | z | Powell | flag |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['case']} | {r['parameter']} | {r['truth']:.4g} | {r['start']:.4g} | {r['fit']:.4g} ± "
                     f"{r['sigma']:.2g} | {r['z']:+.2f} | {r['sigma_hi']:.2g} | {r['z_hi']:+.2f} | {r['powell']:.4g} "
                     f"| {r['flag']} |")
    lines += ["", "| case | free | loss start | LM loss | LM iter | LM time [s] | LM compile [s] | loss fresh key "
              "(fit / truth) | Powell loss | Powell evals | Powell time [s] | truncation lost |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in summaries:
        lines.append(f"| {s['case']} | {s['n_free']} | {s['loss_start']:.3g} | {s['loss_lm']:.3g} | "
                     f"{s['lm_iterations']} | {s['lm_time']:.1f} | {s['lm_compile']:.1f} | "
                     f"{s['loss_lm_fresh']:.3g} / {s['loss_truth_fresh']:.3g} | {s['powell_loss']:.3g} | "
                     f"{s['powell_evals']} | {s['powell_time']:.1f} | {s['truncation_lost']:.2%} |")
    md = "\n".join(lines) + "\n"
    with open(os.path.join(out, "results.md"), "w") as fh:
        fh.write(md)
    return md


QUICK = dict(samples=32, bounces=64, gen_samples=512, gen_bounces=256, max_steps=30, powell_maxfev=400,
             fresh_keys=1, cov_samples=0)
