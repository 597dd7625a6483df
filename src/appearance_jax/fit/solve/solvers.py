"""Fit a model to a table: residuals, solvers, multi-start and the result with uncertainties.

    result = fit("rough_plastic", table, fix={"eta": 1.5}, metric="cos_log")
    print(result.summary())

Solvers (``solver=``): ``"lm"`` optimistix Levenberg-Marquardt (default), ``"gn"``
Gauss-Newton, ``"dogleg"``, ``"bfgs"`` (optimistix BFGS on the scalar loss 1/2 sum r^2) and
``"jaxopt_lm"`` (jaxopt's LevenbergMarquardt, an independent implementation). Every solver
works in the unconstrained space of :mod:`~appearance_jax.fit.transforms`; the whole solve
is one jitted XLA program, so ``n_starts`` random starts (multi-start for multimodal losses)
run batched with ``vmap`` and the best one is kept.

Stochastic models (Monte Carlo evaluators that take a PRNG ``key``) are fitted with common
random numbers: pass ``key=``; the same key is used at every iterate, so the residual is a
smooth deterministic function of the parameters and the Jacobian is consistent
(spec guidance for the cosmetics fits). A model whose ``eval`` returns ``(estimate,
standard_error)`` is accepted; the estimate is fitted.

Uncertainties (:func:`covariance`): at the optimum x* the Jacobian J of the residuals with
respect to the **physical** free parameters gives Cov = s^2 (J^T J)^-1, with s^2 = RSS /
(m - p) (m valid residuals, p parameters) unless the table carries per-value sigma, in which
case the residuals are chi-square normalised and s^2 = 1. Parameters on a bound are
reported as such (the linearisation does not hold there). Flat directions: eigenvectors of
the scaled normal matrix D^-1 J^T J D^-1 (D = column norms, so units do not matter) with an
eigenvalue below ``flat_tol`` times the largest; every parameter with a component > 0.3 in
one of them is "poorly determined", as is any with a 1-sigma larger than its value's
magnitude or its range.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

from ..core.params import validate
from .residuals import check_metric, error_metrics, residual, residual_scale
from .table import Table
from .transforms import ParamSpace

SOLVERS = ("lm", "gn", "dogleg", "bfgs", "jaxopt_lm")


# ---------------------------------------------------------------------------------------
# the problem: what a solve needs, as arrays (batchable) and static configuration


@dataclass
class Problem:
    """A model, its free parameters and a table's data, ready for a solver.

    ``data`` is a dict of arrays (a pytree, batchable with vmap): wi, wo (Vec3 (N,)),
    f (N, B) BRDF data, inv_scale (N, B) 1/sigma of the residual (1 without sigma),
    weight (N, B) = sqrt(sample weight) x mask (0 for masked entries), cos_i (N, 1).
    """

    model: Any
    space: ParamSpace
    data: dict
    metric: str
    floor: float
    key: Any = None
    model_kwargs: dict = field(default_factory=dict)
    absolute_sigma: bool = False
    masked: dict = field(default_factory=dict)

    def evaluate(self, params, data):
        """Model BRDF (N, B) at the data's directions (kernel: no validation, traceable)."""
        kw = dict(self.model_kwargs)
        if self.key is not None:
            kw["key"] = self.key
        out = self.model.eval.kernel(params, data["wi"], data["wo"], **kw)
        if isinstance(out, tuple):  # stochastic evaluators return (estimate, standard error)
            out = out[0]
        return jnp.broadcast_to(out, data["f"].shape)

    def residuals_x(self, x, data):
        """Flat residual vector (N*B,) at physical free-parameter vector x."""
        f = self.evaluate(self.space.params_from_x(x), data)
        r = residual(f, data["f"], data["cos_i"], self.metric, floor=self.floor)
        r = r * data["inv_scale"] * data["weight"]
        return jnp.where(data["weight"] > 0, r, 0.0).ravel()

    def residuals_z(self, z, data):
        return self.residuals_x(self.space.x_from_z(z), data)


def _sigma_scale(metric, f, sigma, cos_i, floor):
    s = np.asarray(residual_scale(f, sigma, cos_i, metric, floor=floor))
    return np.where(np.isfinite(s) & (s > 0), 1.0 / np.where(s > 0, s, 1.0), 0.0)


def entry_arrays(table: Table, values, sigma, mask, *, metric, weights, max_theta_deg, use_sigma, floor):
    """Per-entry data of a fit, in numpy: ``(f, inv_scale, weight, masked, absolute)``.

    ``values``, ``sigma`` (or None) and ``mask`` are in the table's quantity with its (N, B)
    shape, optionally with leading batch axes (K, N, B) on the table's angles, so that a batch
    is prepared in one vectorised pass. ``f`` is the BRDF (0 where not fitted), ``weight`` =
    sqrt(sample weight) x mask, ``masked`` maps each reason added here (grazing, bad sigma) to
    its count: an int, or a (K,) array with a batch axis.
    """
    k = table.brdf_factor()
    f = np.asarray(values, np.float64) * k
    sigma = None if sigma is None else np.asarray(sigma, np.float64) * k
    mask = np.asarray(mask, bool) & np.isfinite(f)
    masked = {}
    if max_theta_deg is not None:
        lim = np.deg2rad(max_theta_deg)
        grazing = ((table.theta_i > lim) | (table.theta_o > lim))[:, None] & mask
        if grazing.any():
            masked[f"grazing (theta > {max_theta_deg:g} deg)"] = grazing.sum(axis=(-2, -1))
            mask &= ~grazing
    cos_i = np.cos(table.theta_i)[:, None]
    w = np.ones_like(f) if weights is None else np.broadcast_to(np.asarray(weights, np.float64), f.shape)
    if np.any(~np.isfinite(w)) or np.any(w < 0):
        raise ValueError("weights must be finite and >= 0")
    if use_sigma and sigma is not None:
        bad = mask & ~(np.isfinite(sigma) & (sigma > 0))
        if bad.any():
            masked["sigma <= 0 or missing"] = bad.sum(axis=(-2, -1))
            mask &= ~bad
        inv = _sigma_scale(metric, np.where(mask, f, 0.0), np.where(mask, sigma, 1.0), cos_i, floor)
        absolute = True
    else:
        inv, absolute = np.ones_like(f), False
    weight = np.where(mask, np.sqrt(w), 0.0)
    return np.where(mask, f, 0.0), inv, weight, masked, absolute


def match_spectral_bands(params, table: Table):
    """Point a wavelength-dependent model at a spectral table's wavelengths.

    Models whose ``Params`` have the static fields ``color`` and ``wavelengths`` (thin films:
    :data:`appearance_jax.core.spectral.COLOR_MODES`) evaluate one band per wavelength in
    ``color="spectral"``; a spectral table switches them to that mode at its wavelengths.
    An RGB table keeps the model's mode ("rgb3" or "cie"), but refuses "spectral".
    """
    names = getattr(type(params), "_static_fields", ())
    if "color" not in names or "wavelengths" not in names:
        return params
    if table.wavelengths is not None:
        return params.replace(color="spectral", wavelengths=tuple(float(w) for w in table.wavelengths))
    if params.color == "spectral":
        raise ValueError(f"{table.source}: the table is RGB ({', '.join(table.bands)}) but the model's "
                         "color = 'spectral'; use color='rgb3' (650/510/475 nm) or 'cie'")
    return params


def _start_params(model, init):
    """A start (Params or preset name) of ``model``, validated."""
    if isinstance(init, str):
        if init not in model.presets:
            raise ValueError(f"preset {init!r} is not a preset of {model.name}; presets: "
                             f"{', '.join(model.presets) or 'none'}")
        init = model.presets[init]
    params = init if init is not None else model.Params()
    validate(params, model.Params)
    return params


def build_problem(model, table: Table, *, init=None, fix=None, metric="l2", weights=None,
                  max_theta_deg: float | None = 85.0, use_sigma: bool = True, floor: float = 1e-3,
                  key=None, model_kwargs=None) -> Problem:
    """Assemble a :class:`Problem` (validates everything eagerly, with clear errors)."""
    from .. import registry

    model = registry.get(model) if isinstance(model, str) else model
    if model.kind != "bsdf":
        raise ValueError(f"fit: {model.name} is a {model.kind}; tables are fitted with BSDFs")
    check_metric(metric)
    params = match_spectral_bands(_start_params(model, init), table)
    space = ParamSpace(params, table.n_bands, fix=fix, band_names=table.bands)

    f, inv, weight, extra, absolute = entry_arrays(table, table.values, table.sigma, table.mask, metric=metric,
                                                    weights=weights, max_theta_deg=max_theta_deg,
                                                    use_sigma=use_sigma, floor=floor)
    masked = dict(table.masked)
    masked.update({why: int(n) for why, n in extra.items() if n})
    n_valid = int((weight > 0).sum())
    if n_valid < space.size:
        raise ValueError(f"{table.source}: {n_valid} valid values for {space.size} free parameters "
                         f"({', '.join(space.labels)}); masked: {masked or 'none'}")
    cos_i = np.cos(table.theta_i)[:, None]
    dt = jnp.result_type(float)
    wi, wo = table.directions(dt)
    data = dict(wi=wi, wo=wo, f=jnp.asarray(f, dt), inv_scale=jnp.asarray(inv, dt),
                weight=jnp.asarray(weight, dt), cos_i=jnp.asarray(cos_i, dt))
    return Problem(model, space, data, metric, floor, key, dict(model_kwargs or {}), absolute, masked)


# ---------------------------------------------------------------------------------------
# solvers


def _progress(every: int, n_valid: int = 1) -> Callable:
    """An optimistix ``verbose`` callable printing step and loss every ``every`` steps.

    The loss printed is the one :class:`FitResult` reports: the mean squared residual over the
    ``n_valid`` fitted values. Printing is filtered on the host (a ``lax.cond`` would run both
    branches under the ``vmap`` over starts); with several starts the best current loss is shown.
    """

    def host(step, loss):
        step, loss = np.ravel(np.asarray(step)), np.ravel(np.asarray(loss, np.float64))
        if step.size and step[0] > 0 and step[0] % every == 0:
            print(f"  step {int(step[0]):4d}  loss {2.0 * np.nanmin(loss) / max(n_valid, 1):.6e}", flush=True)

    def show(**kw):
        if "num_steps" not in kw:
            return
        loss = None
        for k in ("loss_last_accepted_step", "loss", "loss_this_step"):
            if k in kw:
                loss = kw[k][1]
                break
        if loss is not None:
            jax.debug.callback(host, kw["num_steps"][1], loss)

    return show


def _make_solver(name, rtol, atol, verbose, n_valid=1):
    import optimistix as optx

    v = _progress(verbose, n_valid) if verbose else False
    if name == "lm":
        return optx.LevenbergMarquardt(rtol=rtol, atol=atol, verbose=v)
    if name == "gn":
        return optx.GaussNewton(rtol=rtol, atol=atol, verbose=v)
    if name == "dogleg":
        return optx.Dogleg(rtol=rtol, atol=atol, verbose=v)
    if name == "bfgs":
        return optx.BFGS(rtol=rtol, atol=atol, verbose=v)
    raise ValueError(f"solver = {name!r}: must be one of {', '.join(SOLVERS)}")


def solve_z(problem: Problem, z0, data, *, solver="lm", rtol=1e-8, atol=1e-10, max_steps=400, verbose=0):
    """One solve from z0 (traceable: vmap it over starts or data). Returns (z, loss, steps, ok)."""
    fn = problem.residuals_z
    if solver == "jaxopt_lm":
        import jaxopt

        lm = jaxopt.LevenbergMarquardt(residual_fun=fn, maxiter=max_steps, tol=atol, xtol=rtol, gtol=atol,
                                       stop_criterion="madsen-nielsen", solver="cholesky",
                                       materialize_jac=True, jit=True)
        z, state = lm.run(z0, data)
        r = fn(z, data)
        return z, 0.5 * jnp.sum(r * r), state.iter_num, jnp.all(jnp.isfinite(z))
    import optimistix as optx

    opt = _make_solver(solver, rtol, atol, verbose, int(np.sum(np.asarray(problem.data["weight"]) > 0)))
    if solver == "bfgs":
        sol = optx.minimise(lambda z, d: 0.5 * jnp.sum(fn(z, d) ** 2), opt, z0, data, max_steps=max_steps,
                            throw=False)
    else:
        sol = optx.least_squares(fn, opt, z0, data, max_steps=max_steps, throw=False)
    z = sol.value
    r = fn(z, data)
    ok = (sol.result == optx.RESULTS.successful) & jnp.all(jnp.isfinite(z))
    return z, 0.5 * jnp.sum(r * r), sol.stats["num_steps"], ok


def covariance(problem: Problem, x, data, *, flat_tol: float = 1e-9):
    """(cov, eigenvalues, eigenvectors) at physical x: traceable, so vmap it over a batch.

    See the module docstring. Rows/columns of ``cov`` that touch a flat direction are NaN
    (the variance along it is unbounded); eigenvalues are relative to the largest.
    """
    J = jax.jacfwd(problem.residuals_x)(x, data)
    r = problem.residuals_x(x, data)
    m = jnp.sum(data["weight"] > 0)
    p = J.shape[1]
    d = jnp.linalg.norm(J, axis=0)
    d = jnp.where(d > 0, d, 1.0)
    Js = J / d
    lam, vec = jnp.linalg.eigh(Js.T @ Js)
    big = jnp.maximum(lam[-1], jnp.finfo(lam.dtype).tiny)
    ok = lam > flat_tol * big
    inv = (vec * jnp.where(ok, 1.0 / jnp.where(ok, lam, 1.0), 0.0)) @ vec.T
    s2 = 1.0 if problem.absolute_sigma else (r @ r) / jnp.maximum(m - p, 1)
    cov = inv / jnp.outer(d, d) * s2
    flat = jnp.any((jnp.abs(vec) > 0.3) & ~ok[None, :], axis=1)
    cov = jnp.where(flat[:, None] | flat[None, :], jnp.nan, cov)
    return cov, lam / big, vec


# ---------------------------------------------------------------------------------------
# the result


@dataclass
class FitResult:
    """Outcome of a fit. ``values``/``sigma`` map each free entry label to a number."""

    model: str
    params: Any  # the fitted Params (fixed fields at their fixed values)
    labels: tuple
    units: tuple
    x: np.ndarray
    sigma: np.ndarray
    cov: np.ndarray
    at_bound: tuple
    poorly_determined: tuple
    eigenvalues: np.ndarray
    loss: float  # mean of squared residuals over valid entries, in the fit metric
    metrics: dict  # rmse, cos_log_rmse, log_rmse, rel_rmse (see residuals.error_metrics)
    iterations: int
    wall_time: float  # seconds of the solve itself (compilation excluded, see compile_time)
    converged: bool
    solver: str
    metric: str
    n_valid: int
    masked: dict
    fixed: dict
    starts: dict = field(default_factory=dict)
    table: Table | None = None
    fitted: np.ndarray | None = None  # model BRDF (N, B) at the table's directions
    compile_time: float = 0.0  # seconds spent tracing and compiling the solve
    fit_mask: np.ndarray | None = None  # (N, B) True for the entries the fit used (after every mask and weight)

    @property
    def values(self) -> dict:
        return dict(zip(self.labels, self.x.tolist()))

    @property
    def uncertainties(self) -> dict:
        return dict(zip(self.labels, self.sigma.tolist()))

    def correlation(self) -> np.ndarray:
        s = np.sqrt(np.diag(self.cov))
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.cov / np.outer(s, s)

    def to_dict(self) -> dict:
        """JSON-ready record (params.json of the command line)."""
        def num(v):
            return None if not np.isfinite(v) else float(v)

        return dict(
            model=self.model, solver=self.solver, metric=self.metric, converged=bool(self.converged),
            iterations=int(self.iterations), wall_time_s=float(self.wall_time),
            compile_time_s=float(self.compile_time), loss=num(self.loss),
            errors={k: (num(v) if isinstance(v, float) else v) for k, v in self.metrics.items()},
            n_valid=self.n_valid, masked=self.masked, fixed=self.fixed,
            parameters={lab: dict(value=float(v), sigma=num(s), unit=u, at_bound=lab in self.at_bound,
                                  poorly_determined=lab in self.poorly_determined)
                        for lab, v, s, u in zip(self.labels, self.x, self.sigma, self.units)},
            starts=self.starts, source=None if self.table is None else self.table.source,
        )

    def summary(self) -> str:
        lines = [f"{self.model} fitted with {self.solver} ({self.metric} metric): "
                 f"{'converged' if self.converged else 'NOT converged'} in {self.iterations} iterations, "
                 f"{self.wall_time:.2f} s (+ {self.compile_time:.1f} s compile); loss {self.loss:.4g} over {self.n_valid} values"]
        w = max(len(lab) for lab in self.labels)
        for lab, v, s, u in zip(self.labels, self.x, self.sigma, self.units):
            flag = " (at bound)" if lab in self.at_bound else " (poorly determined)" if lab in self.poorly_determined else ""
            unit = "" if u in ("1", "") else f" {u}"
            lines.append(f"  {lab.ljust(w)} = {v:.6g} +- {s:.2g}{unit}{flag}")
        if self.fixed:
            lines.append("  fixed: " + ", ".join(f"{k} = {v}" for k, v in self.fixed.items()))
        lines.append("  errors: " + ", ".join(f"{k} {v:.4g}" for k, v in self.metrics.items() if k != "n"))
        if self.masked:
            lines.append("  masked: " + ", ".join(f"{n} {why}" for why, n in self.masked.items()))
        return "\n".join(lines)


def _fixed_record(space: ParamSpace) -> dict:
    out = {}
    for name in space.fixed:
        v = np.asarray(getattr(space.template, name))
        out[name] = v.tolist()
    return out


def flags(space: ParamSpace, x, sigma, lam, vec, flat_tol: float = 1e-9):
    """(at_bound, poorly_determined) bool arrays (..., p); numpy, leading batch axes allowed."""
    x, sigma, lam, vec = (np.asarray(a, np.float64) for a in (x, sigma, lam, vec))
    bound = space.at_bound(x)
    small = (lam < flat_tol)[..., None, :]  # (..., 1, p): eigenvalue j is flat
    flat = np.any((np.abs(vec) > 0.3) & small, axis=-1)
    specs = [f.spec for f in space.fields for _ in range(f.size)]
    width = np.array([s.hi - s.lo if math.isfinite(s.hi - s.lo) else np.inf for s in specs])
    flat |= ~np.isfinite(sigma) | (sigma > np.maximum(np.abs(x), 1e-12)) | (sigma > width)
    return bound, flat & ~bound


def finish(problem: Problem, table, z, loss_half, steps, ok, wall, solver, starts=None, data=None) -> FitResult:
    """Turn a solver's z into a :class:`FitResult` (uncertainties, flags, error metrics)."""
    data = problem.data if data is None else data
    sp = problem.space
    x = sp.x_from_z(jnp.asarray(z))
    cov, lam, vec = (np.asarray(a, np.float64) for a in jax.jit(lambda x, d: covariance(problem, x, d))(x, data))
    x = np.asarray(x, np.float64)
    sigma = np.sqrt(np.abs(np.diag(cov)))
    bound, flat = flags(sp, x, sigma, lam, vec)
    params = sp.params_from_x(jnp.asarray(x))
    w = np.asarray(data["weight"]) > 0
    fitted = np.asarray(problem.evaluate(params, data), np.float64)
    metrics = error_metrics(fitted, np.asarray(data["f"]), w, np.asarray(data["cos_i"]))
    m = int(w.sum())
    return FitResult(
        model=problem.model.name, params=params, labels=sp.labels, units=sp.units(), x=x, sigma=sigma, cov=cov,
        at_bound=tuple(lab for lab, b in zip(sp.labels, bound) if b),
        poorly_determined=tuple(lab for lab, b in zip(sp.labels, flat) if b), eigenvalues=lam,
        loss=float(2.0 * loss_half / max(m, 1)), metrics=metrics, iterations=int(steps), wall_time=float(wall),
        converged=bool(ok), solver=solver, metric=problem.metric, n_valid=m, masked=problem.masked,
        fixed=_fixed_record(sp), starts=starts or {}, table=table, fitted=fitted, fit_mask=w)


def fit(model, table: Table, *, init=None, fix=None, metric: str = "l2", weights=None,
        max_theta_deg: float | None = 85.0, use_sigma: bool = True, solver: str = "lm", rtol: float = 1e-8,
        atol: float = 1e-10, max_steps: int = 400, n_starts: int = 1, seed: int = 0, key=None,
        model_kwargs=None, verbose: int = 0) -> FitResult:
    """Fit ``model`` (a registered name or Model) to ``table``.

    Args:
        init: start ``Params`` or a preset name (default: the model's defaults), or a list of
            them: one start each (e.g. thicknesses spread over one period of a thin film's
            optical thickness); fixed fields and static settings come from the first.
        fix: names to hold at their start value, or {name: value}.
        metric: ``"l2"`` | ``"cos_log"`` | ``"relative"`` (:mod:`~appearance_jax.fit.residuals`).
        weights: per-sample weights broadcastable to (N, B).
        max_theta_deg: mask samples with theta_i or theta_o above this (grazing; None keeps all).
        use_sigma: normalise residuals by the table's sigma when it has one (absolute covariance).
        solver: one of ``SOLVERS``; rtol/atol/max_steps: its stopping rule.
        n_starts: > 1 adds n_starts - 1 random starts (``seed``) and keeps the best.
        key: PRNG key for stochastic models (common random numbers).
        verbose: print step and loss every ``verbose`` steps (0: silent).
    """
    if solver not in SOLVERS:
        raise ValueError(f"solver = {solver!r}: must be one of {', '.join(SOLVERS)}")
    if n_starts < 1:
        raise ValueError(f"n_starts = {n_starts} must be >= 1")
    inits = list(init) if isinstance(init, (list, tuple)) else [init]
    if not inits:
        raise ValueError("init: an empty list of starts")
    init = inits[0]
    problem = build_problem(model, table, init=init, fix=fix, metric=metric, weights=weights,
                            max_theta_deg=max_theta_deg, use_sigma=use_sigma, key=key, model_kwargs=model_kwargs)
    sp = problem.space
    dt = jnp.result_type(float)
    # the given starts (the first is the problem's own), then n_starts - 1 random ones
    xs = [sp.x_start()] + [sp.x_from_params(_start_params(problem.model, p)) for p in inits[1:]]
    z0 = jnp.asarray(np.stack([sp.z_from_x(x) for x in xs]), dt)
    if n_starts > 1:
        z0 = jnp.concatenate([z0, sp.random_z(jax.random.PRNGKey(seed), n_starts - 1).astype(dt)])
    n_starts = z0.shape[0]

    def run(z0s, data):
        return jax.vmap(lambda z: solve_z(problem, z, data, solver=solver, rtol=rtol, atol=atol,
                                          max_steps=max_steps, verbose=verbose))(z0s)

    t0 = time.perf_counter()
    compiled = jax.jit(run).lower(z0, problem.data).compile()
    t1 = time.perf_counter()
    z, loss, steps, ok = jax.block_until_ready(compiled(z0, problem.data))
    wall = time.perf_counter() - t1
    loss = np.asarray(loss, np.float64)
    loss = np.where(np.isfinite(loss), loss, np.inf)
    best = int(np.argmin(loss))
    starts = {}
    if n_starts > 1:
        n = problem.space.size
        starts = dict(n_starts=n_starts, losses=(2 * loss / max(int((np.asarray(problem.data["weight"]) > 0).sum()), 1)).tolist(),
                      best=best, n_parameters=n)
    res = finish(problem, table, z[best], loss[best], np.asarray(steps)[best], np.asarray(ok)[best], wall,
                 solver, starts)
    res.compile_time = t1 - t0
    return res


__all__ = ["fit", "build_problem", "entry_arrays", "solve_z", "covariance", "finish", "FitResult", "Problem",
           "SOLVERS"]
