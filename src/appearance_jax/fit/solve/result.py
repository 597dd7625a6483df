"""The result of a fit: parameters, uncertainties, flags and the fitted values (:class:`FitResult`).

Uncertainties (:mod:`~appearance_jax.fit.solve.uncertainty`): at the optimum x* the Jacobian of
the residuals with respect to the **physical** free parameters gives the iid covariance
s^2 (J^T J)^-1, the entry sandwich (HC1), the cluster-robust sandwich over incidence directions
(CR1) and, on request (``fit(..., bootstrap=B)``), a block bootstrap over incidence directions.
``sigma`` is the default: the cluster sandwich when the table has enough incidence directions,
else HC1; the iid sigma is reported next to it (docs/fitting.md, "Uncertainties"). Parameters on a bound
get sigma = NaN (the linearisation does not hold there; the report prints "at bound"), and so do
parameters in an exactly flat direction. ``poorly_determined`` lists the parameters of
unresolved directions (noise-derived rule of :func:`~.uncertainty.degeneracies`) and those whose
sigma exceeds their magnitude or range; ``degeneracies`` names the groups and what to fix;
``warnings`` collects what a user must read (not converged, parameters at bounds, degenerate
groups, too few incidence directions, residuals larger than the stated sigma).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import jax
import numpy as np

from ...core import compile_cache
from ..tables.table import Table
from . import reuse
from . import uncertainty as unc
from .problem import Problem
from .residuals import FLOOR, error_metrics, residual, residual_scale
from .transforms import ParamSpace


FIELD = {"iid": "sigma_iid", "hc1": "sigma_hc1", "cr1": "sigma_cr1", "cr3": "sigma_sandwich",
         "bootstrap": "sigma_bootstrap"}

# ---------------------------------------------------------------------------------------
# the result


@dataclass
class FitResult:
    """Outcome of a fit. ``values``/``sigma`` map each free entry label to a number.

    ``sigma`` is the default 1-sigma (method ``sigma_method``: ``"cr3"`` or ``"hc1"``, see
    :mod:`~appearance_jax.fit.solve.uncertainty`), NaN at a bound or along an exactly flat
    direction; ``cov`` its covariance. ``sigma_iid``, ``sigma_hc1``, ``sigma_sandwich`` (the
    cluster-robust one over incidence directions, CR3), ``sigma_cr1`` and ``sigma_bootstrap``
    (None unless ``fit(..., bootstrap=B)``) are the raw estimates of each kind.
    """

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
    wall_time: float  # seconds of the solve and its covariances (compilation excluded, see compile_time)
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
    sigma_method: str = "iid"  # which kind ``sigma`` is: "cr3" or "hc1" (uncertainty.default_method)
    sigma_iid: np.ndarray | None = None
    sigma_hc1: np.ndarray | None = None
    sigma_sandwich: np.ndarray | None = None  # cluster-robust over incidence directions, jackknife form (CR3)
    sigma_cr1: np.ndarray | None = None  # cluster-robust, CR1 form
    sigma_bootstrap: np.ndarray | None = None
    bootstrap: dict | None = None  # replicates, failed, seed, interval68, interval95 (p, 2)
    cov_iid: np.ndarray | None = None
    n_clusters: int = 0
    clusters: str = ""  # what a cluster is ("one per incidence direction", "theta_i bins of 3 deg")
    degeneracies: list = field(default_factory=list)
    warnings: list = field(default_factory=list)

    @property
    def values(self) -> dict:
        return dict(zip(self.labels, self.x.tolist()))

    @property
    def uncertainties(self) -> dict:
        return dict(zip(self.labels, self.sigma.tolist()))

    def sigmas(self) -> dict:
        """{kind: (p,) array} of every sigma computed: iid, hc1, cr1, cr3 and (if run) bootstrap."""
        out = {"iid": self.sigma_iid, "hc1": self.sigma_hc1, "cr1": self.sigma_cr1, "cr3": self.sigma_sandwich,
               "bootstrap": self.sigma_bootstrap}
        return {k: v for k, v in out.items() if v is not None}

    def sigma_note(self, label: str) -> str | None:
        """Why the default sigma of ``label`` is not reported (None when it is)."""
        if label in self.at_bound:
            return "at bound: the linearised sigma does not hold"
        i = self.labels.index(label)
        if not np.isfinite(self.sigma[i]):
            return "flat direction: the data do not determine it"
        return None

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
        """Correlation matrix of the default covariance (NaN rows at bounds and flat directions)."""
        s = np.sqrt(np.abs(np.diag(self.cov)))
        with np.errstate(invalid="ignore", divide="ignore"):
            c = self.cov / np.outer(s, s)
        bad = ~np.isfinite(self.sigma)
        return np.where(bad[:, None] | bad[None, :], np.nan, c)

    def to_dict(self) -> dict:
        """JSON-ready record (params.json of the command line)."""
        def num(v):
            return None if v is None or not np.isfinite(v) else float(v)

        def param(i, lab):
            note = self.sigma_note(lab)
            rec = dict(value=float(self.x[i]), sigma=None if note else num(self.sigma[i]), unit=self.units[i],
                       at_bound=lab in self.at_bound, poorly_determined=lab in self.poorly_determined)
            if note:
                rec["sigma_note"] = note
            for kind, s in self.sigmas().items():
                rec[FIELD[kind]] = None if lab in self.at_bound else num(s[i])
            if self.bootstrap is not None:
                for k in ("interval68", "interval95"):
                    rec[f"bootstrap_{k}"] = [num(v) for v in self.bootstrap[k][i]]
            return rec

        boot = None if self.bootstrap is None else {k: self.bootstrap.get(k) for k in ("replicates", "failed",
                                                                                   "not_converged", "seed")}
        return dict(
            model=self.model, solver=self.solver, metric=self.metric, converged=bool(self.converged),
            iterations=int(self.iterations), wall_time_s=float(self.wall_time),
            compile_time_s=float(self.compile_time), loss=num(self.loss),
            errors={k: (num(v) if isinstance(v, float) else v) for k, v in self.metrics.items()},
            n_valid=self.n_valid, masked=self.masked, fixed=self.fixed,
            parameters={lab: param(i, lab) for i, lab in enumerate(self.labels)},
            uncertainty=dict(method=self.sigma_method, description=unc.DESCRIPTION.get(self.sigma_method, ""),
                             floor=None, kinds=list(self.sigmas()),
                             n_clusters=int(self.n_clusters), clusters=self.clusters,
                             min_clusters=unc.min_clusters(len(self.labels)), bootstrap=boot),
            correlation=dict(method=self.sigma_method, labels=list(self.labels),
                             matrix=[[num(v) for v in row] for row in self.correlation()]),
            degeneracies=self.degeneracies, warnings=list(self.warnings),
            starts=self.starts, source=None if self.table is None else self.table.source,
        )

    def summary(self) -> str:
        lines = [f"{self.model} fitted with {self.solver} ({self.metric} metric): "
                 f"{'converged' if self.converged else 'NOT converged'} in {self.iterations} iterations, "
                 f"{self.wall_time:.2f} s (+ {self.compile_time:.1f} s compile); loss {self.loss:.4g} over {self.n_valid} values"]
        kinds = self.sigmas()
        if kinds:
            lines.append(f"  +- is 1 sigma, {unc.DESCRIPTION.get(self.sigma_method, self.sigma_method)} "
                         f"({self.n_clusters} clusters: {self.clusters})")
        w = max(len(lab) for lab in self.labels)
        for i, (lab, v, s, u) in enumerate(zip(self.labels, self.x, self.sigma, self.units)):
            unit = "" if u in ("1", "") else f" {u}"
            if lab in self.at_bound:
                lines.append(f"  {lab.ljust(w)} = {v:.6g}{unit} (at bound)")
                continue
            flag = " (poorly determined)" if lab in self.poorly_determined else ""
            other = ", ".join(f"{k} {kinds[k][i]:.2g}" for k in kinds if k != self.sigma_method)
            lines.append(f"  {lab.ljust(w)} = {v:.6g} +- {s:.2g}{unit}{flag}" + (f"  [{other}]" if other else ""))
        if self.fixed:
            lines.append("  fixed: " + ", ".join(f"{k} = {v}" for k, v in self.fixed.items()))
        lines.append("  errors: " + ", ".join(f"{k} {v:.4g}" for k, v in self.metrics.items() if k != "n"))
        if self.masked:
            lines.append("  masked: " + ", ".join(f"{n} {why}" for why, n in self.masked.items()))
        lines += [f"  warning: {msg}" for msg in self.warnings]
        return "\n".join(lines)


def _fixed_record(space: ParamSpace) -> dict:
    out = {}
    for name in space.fixed:
        v = np.asarray(getattr(space.template, name))
        out[name] = v.tolist()
    return out


def flags(space: ParamSpace, x, sigma, covs, exact_flat):
    """(at_bound, poorly_determined) bool arrays (..., p); numpy, leading batch axes allowed.

    ``sigma`` the default sigma, ``covs`` a list of covariances (..., p, p) (the default
    method) for the unresolved-direction rule, ``exact_flat`` (..., p) from
    :func:`~.uncertainty.covariances`.
    """
    x, sigma = np.asarray(x, np.float64), np.asarray(sigma, np.float64)
    bound = space.at_bound(x)
    flat = np.asarray(exact_flat, bool).copy()
    covs = [np.asarray(c, np.float64) for c in covs]
    flat |= unc.flat_members(space, x, covs)
    specs = [f.spec for f in space.fields for _ in range(f.size)]
    width = np.array([s.hi - s.lo for s in specs], np.float64)
    flat |= ~np.isfinite(sigma) | (sigma > np.maximum(np.abs(x), 1e-12)) | (sigma > width)
    return bound, flat & ~bound


def sigma_kinds(space: ParamSpace, x, out: dict):
    """(method, raw default sigma, sigma) from the covariances of :func:`~.uncertainty.covariances` (numpy,
    batch axes allowed): the default sigma is NaN at a bound and in an exactly flat direction."""
    method = unc.default_method(np.min(np.asarray(out["g"])), space.size)
    raw = unc.default_sigma(out[method])
    bad = space.at_bound(x) | np.asarray(out["flat"], bool)
    return method, raw, np.where(bad, np.nan, raw)


def _warnings(res: FitResult, s2: float, absolute: bool) -> list:
    out = []
    if not res.converged:
        out.append(f"the solver did not converge in {res.iterations} iterations: the values are not an optimum")
    if len(res.at_bound) >= 2:
        out.append(f"{len(res.at_bound)} parameters ended at a bound ({', '.join(res.at_bound)}): the model or its "
                   "free parameters do not suit this table; fix physically known ones (e.g. a coat's eta) or "
                   "try another model")
    out += [f"degenerate: {g['text']}" for g in res.degeneracies]
    p = len(res.labels)
    if res.sigma_method == "hc1":
        out.append(f"only {res.n_clusters} incidence directions (< {unc.min_clusters(p)} for {p} parameters): "
                   "sigma is the entry sandwich (HC1), blind to residuals correlated within an incidence; "
                   "it may be too small")
    if absolute and s2 > 4.0:
        out.append(f"the residuals are {np.sqrt(s2):.3g} x the table's sigma (reduced chi-square {s2:.3g}): "
                   "the model does not fit within the stated uncertainties")
    b = res.bootstrap
    if b is not None and (b["failed"] or b.get("not_converged")):
        out.append(f"bootstrap: of {b['replicates']} refits {b.get('not_converged', 0)} ran out of steps (kept) and "
                   f"{b['failed']} gave non-finite values (left out)")
    return out


class FitDiverged(ArithmeticError):
    """The solver ended on non-finite parameters (every start diverged): there is no result to report."""


def finish(problem: Problem, table, z, loss_half, steps, ok, wall, solver, starts=None, data=None,
           bootstrap=None, covariances=None, x=None, clusters=None) -> FitResult:
    """Turn a solver's z into a :class:`FitResult` (uncertainties, flags, error metrics).

    ``bootstrap``: the summary of :func:`~.uncertainty.bootstrap_summary` (plus ``seed``) or None.
    ``covariances``: the output of :func:`~.uncertainty.covariances` at this optimum when the
    caller already has it (a batch computes every item's in its solve program), else None.
    ``x``: the physical parameters at z when the caller has them (a fit's solve program returns
    them), else computed here. ``clusters``: :func:`~.uncertainty.incidence_clusters` of ``data``
    when the caller has them.
    """
    data = problem.data if data is None else data
    sp = problem.space
    # jitted (op by op the transforms take a dozen small XLA programs: slices, sin, clip, ...),
    # and kept for later fits of the same problem (:mod:`~.reuse`)
    pkey = reuse.problem_key(problem)
    z = np.asarray(z)
    if x is None:
        x = reuse.cached("x_from_z", pkey, lambda: jax.jit(sp.x_from_z), z)(z)
    bad = [lab for lab, v in zip(sp.labels, np.asarray(x, np.float64)) if not np.isfinite(v)]
    if bad:  # a Params cannot hold them (it would raise naming a field as if the user had set it)
        raise FitDiverged(f"the solver diverged after {int(steps)} steps: non-finite {', '.join(bad)} "
                          "(the residuals became NaN or inf); try other starts (n_starts / --starts), "
                          "another metric, or fix the parameters that run away")
    cl, n_cl, what = unc.incidence_clusters(data["wi"]) if clusters is None else clusters
    out = covariances
    if out is not None and not all(np.isfinite(np.asarray(out[k])).all() for k in ("iid", "hc1", "cr1", "cr3")):
        out = None  # e.g. a column the solver's Jacobian cannot give (uncertainty.jacobian_in_x): directly
    if out is None:
        cl = np.asarray(cl)
        cov_fn = reuse.cached("covariances", None if pkey is None else (pkey, n_cl),
                               lambda: jax.jit(lambda x, d, c: unc.covariances(problem, x, d, c, n_cl)), x, data, cl)
        out = cov_fn(x, data, cl)
    out = {k: np.asarray(v) for k, v in out.items()}
    x = np.asarray(x, np.float64)
    method, raw, sigma = sigma_kinds(sp, x, out)
    cov = np.asarray(out[method], np.float64)
    exact = np.asarray(out["flat"], bool)
    cov = np.where(exact[:, None] | exact[None, :], np.nan, cov)
    bound, flat = flags(sp, x, raw, [out[method]], exact)
    params = sp.params_from_x_host(x)
    w = np.asarray(data["weight"]) > 0
    # compiled: op by op, a coated model's eval would compile dozens of small programs; kept on
    # disk too (a new process then skips tracing the model)
    evaluate = reuse.cached("evaluate", pkey,
                            lambda: compile_cache.compile_lowered(jax.jit(problem.evaluate).lower(params, data)),
                            params, data, disk=None if pkey is None else reuse.disk_key(problem))
    fitted = np.asarray(evaluate(params, data), np.float64)
    metrics = error_metrics(fitted, np.asarray(data["f"]), w, np.asarray(data["cos_i"]))
    m = int(w.sum())
    diag = lambda c: np.sqrt(np.abs(np.diag(np.asarray(c, np.float64))))  # noqa: E731
    res = FitResult(
        model=problem.model.name, params=params, labels=sp.labels, units=sp.units(), x=x, sigma=sigma, cov=cov,
        at_bound=tuple(lab for lab, b in zip(sp.labels, bound) if b),
        poorly_determined=tuple(lab for lab, b in zip(sp.labels, flat) if b), eigenvalues=out["lam"],
        loss=float(2.0 * loss_half / max(m, 1)), metrics=metrics, iterations=int(steps), wall_time=float(wall),
        converged=bool(ok), solver=solver, metric=problem.metric, n_valid=m, masked=problem.masked,
        fixed=_fixed_record(sp), starts=starts or {}, table=table, fitted=fitted, fit_mask=w,
        sigma_method=method, sigma_iid=diag(out["iid"]), sigma_hc1=diag(out["hc1"]),
        sigma_sandwich=diag(out["cr3"]), sigma_cr1=diag(out["cr1"]), cov_iid=np.asarray(out["iid"], np.float64),
        n_clusters=int(out["g"]), clusters=what, bootstrap=bootstrap,
        sigma_bootstrap=None if bootstrap is None else np.asarray(bootstrap["sigma"], np.float64))
    res.degeneracies = unc.degeneracies(sp, x, sp.labels, [out[method]], exact, bound)
    grouped = {lab for g in res.degeneracies for lab in g["parameters"]}
    res.poorly_determined = tuple(lab for lab, b in zip(sp.labels, flat) if b or lab in grouped)
    res.warnings = _warnings(res, float(out["s2"]), bool(problem.absolute_sigma))
    return res


__all__ = ["FitResult", "FitDiverged", "flags", "finish", "sigma_kinds"]
