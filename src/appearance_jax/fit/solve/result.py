"""The result of a fit: parameters, uncertainties, flags and the fitted values (:class:`FitResult`).

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
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..tables.table import Table
from .problem import Problem
from .residuals import FLOOR, error_metrics, residual, residual_scale
from .transforms import ParamSpace


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

    def entry_residuals(self) -> tuple[np.ndarray, np.ndarray | None]:
        """(residual, residual / its sigma) of every (direction, band) entry of the table, (N, B) float64.

        In the fit metric, unweighted, with the floor the fit used (:data:`~.residuals.FLOOR`);
        NaN where the table has no measurement. The second array is None for a table without
        sigma, NaN where the propagated sigma is not positive.
        """
        t = self.table
        f_data, sigma = t.brdf()
        f_data = np.where(t.mask, f_data, np.nan)
        cos_i = np.cos(t.theta_i)[:, None]
        with jax.enable_x64(True):
            r = np.asarray(residual(self.fitted, f_data, cos_i, self.metric, floor=FLOOR), np.float64)
            z = None
            if sigma is not None:
                s = np.asarray(residual_scale(f_data, sigma, cos_i, self.metric, floor=FLOOR), np.float64)
                with np.errstate(divide="ignore", invalid="ignore"):
                    z = np.where(np.isfinite(s) & (s > 0), r / s, np.nan)
        return r, z

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


__all__ = ["FitResult", "covariance", "flags", "finish"]
