"""Fit a model to a table: the solvers and multi-start (:func:`fit`, :func:`solve_z`).

    result = fit("rough_plastic", table, fix={"eta": 1.5}, metric="cos_log")
    print(result.summary())

Solvers (``solver=``): ``"lm"`` Levenberg-Marquardt (default; :mod:`~.lm`, a compact
implementation that traces 3-4x faster than optimistix'), ``"optx_lm"``
optimistix' LevenbergMarquardt, ``"gn"`` Gauss-Newton, ``"dogleg"``, ``"bfgs"`` (optimistix BFGS
on the scalar loss 1/2 sum r^2) and ``"jaxopt_lm"`` (jaxopt's LevenbergMarquardt). Every solver
works in the unconstrained space of :mod:`~appearance_jax.fit.solve.transforms`; the whole solve
is one jitted XLA program, in which ``n_starts`` random starts (multi-start for multimodal
losses) run one after another and the best one is kept.

Compiled solves are kept in JAX's persistent compilation cache on disk, turned on by default
(:mod:`appearance_jax.core.compile_cache`: where, and how to turn it off), so a re-run of the
same fit in a new process loads the program instead of compiling it.

Stochastic models (Monte Carlo evaluators that take a PRNG ``key``) are fitted with common
random numbers: pass ``key=``; the same key is used at every iterate, so the residual is a
smooth deterministic function of the parameters and the Jacobian is consistent
(spec guidance for the cosmetics fits). A model whose ``eval`` returns ``(estimate,
standard_error)`` is accepted; the estimate is fitted.

The problem (residuals, masks) is built by :mod:`~appearance_jax.fit.solve.problem`; the result with
its uncertainties by :mod:`~appearance_jax.fit.solve.result`.
"""

from __future__ import annotations

import time
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from ...core import compile_cache
from ..tables.table import Table
from .problem import Problem, build_problem, start_params
from . import uncertainty as unc
from . import reuse
from .lm import levenberg_marquardt
from .result import FitResult, finish

SOLVERS = ("lm", "optx_lm", "gn", "dogleg", "bfgs", "jaxopt_lm")


# ---------------------------------------------------------------------------------------
# solvers


def _progress_host(every: int, n_valid: int = 1) -> Callable:
    """A host function ``(step, loss)`` printing step and loss every ``every`` steps.

    The loss printed is the one :class:`FitResult` reports: the mean squared residual over the
    ``n_valid`` fitted values (``loss`` is 1/2 the sum of squares). Printing is filtered on the
    host (a ``lax.cond`` would run both branches under a ``vmap``, as in a batch); with several
    starts each start prints its own.
    """

    def host(step, loss):
        step, loss = np.ravel(np.asarray(step)), np.ravel(np.asarray(loss, np.float64))
        if step.size and step[0] > 0 and step[0] % every == 0:
            print(f"  step {int(step[0]):4d}  loss {2.0 * np.nanmin(loss) / max(n_valid, 1):.6e}", flush=True)

    return host


def _progress(every: int, n_valid: int = 1) -> Callable:
    """An optimistix ``verbose`` callable printing step and loss every ``every`` steps
    (:func:`_progress_host`)."""
    host = _progress_host(every, n_valid)

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
    if name == "optx_lm":
        return optx.LevenbergMarquardt(rtol=rtol, atol=atol, verbose=v)
    if name == "gn":
        return optx.GaussNewton(rtol=rtol, atol=atol, verbose=v)
    if name == "dogleg":
        return optx.Dogleg(rtol=rtol, atol=atol, verbose=v)
    if name == "bfgs":
        return optx.BFGS(rtol=rtol, atol=atol, verbose=v)
    raise ValueError(f"solver = {name!r}: must be one of {', '.join(SOLVERS)}")


def solve_z(problem: Problem, z0, data, *, solver="lm", rtol=1e-8, atol=1e-10, max_steps=400, verbose=0,
            loss_tol=None):
    """One solve from z0 (traceable: vmap it over starts or data). Returns (z, loss, steps, ok)."""
    return _solve(problem, z0, data, solver=solver, rtol=rtol, atol=atol, max_steps=max_steps, verbose=verbose,
                  loss_tol=loss_tol)[0]


def solve_with_jacobian(problem: Problem, z0, data, **solve_kw):
    """:func:`solve_z`, then x(z) and the residuals and their Jacobian in x there (traceable), for
    :func:`~.uncertainty.covariances_host`. Returns ((z, loss, steps, ok), (x, r, J)). With
    ``solver="lm"`` r and J are the solver's own at its last point (:func:`~.uncertainty.jacobian_in_x`:
    the program traces the model's Jacobian once); other solvers' programs take them anew."""
    (z, loss, steps, ok), rJ = _solve(problem, z0, data, jacobian=True, **solve_kw)
    if rJ is not None:
        x, J = unc.jacobian_in_x(problem, z, rJ[1])
        return (z, loss, steps, ok), (x, rJ[0], J)
    x = problem.space.x_from_z(z)
    return (z, loss, steps, ok), (x, problem.residuals_x(x, data), jax.jacfwd(problem.residuals_x)(x, data))


def solve_with_covariances(problem: Problem, z0, data, cluster, n_clusters: int, **solve_kw):
    """:func:`solve_with_jacobian`, then the covariances from its r and J (:func:`~.uncertainty.covariances`;
    traceable, for a batch's program). Returns ((z, loss, steps, ok), covariances)."""
    out, (x, r, J) = solve_with_jacobian(problem, z0, data, **solve_kw)
    return out, unc.covariances(problem, x, data, cluster, n_clusters, J=J, r=r)


def _solve(problem: Problem, z0, data, *, solver="lm", rtol=1e-8, atol=1e-10, max_steps=400, verbose=0,
           loss_tol=None, jacobian=False):
    """((z, loss, steps, ok), (r, J) at z or None): (r, J) only from ``solver="lm"`` with ``jacobian``."""
    fn = problem.residuals_z
    if solver == "lm":
        n_valid = int(np.sum(np.asarray(problem.data["weight"]) > 0))
        out = levenberg_marquardt(fn, z0, data, rtol=rtol, atol=atol, max_steps=max_steps, loss_tol=loss_tol,
                                  progress=_progress_host(verbose, n_valid) if verbose else None,
                                  with_jacobian=jacobian, n_residuals=int(data["weight"].size),
                                  jacobian=problem.jacobian_z)
        z, loss, steps, ok = out[:4]
        return (z, loss, steps, ok & jnp.all(jnp.isfinite(z))), (out[4:] if jacobian else None)
    if solver == "jaxopt_lm":
        import jaxopt

        lm = jaxopt.LevenbergMarquardt(residual_fun=fn, maxiter=max_steps, tol=atol, xtol=rtol, gtol=atol,
                                       stop_criterion="madsen-nielsen", solver="cholesky",
                                       materialize_jac=True, jit=True)
        z, state = lm.run(z0, data)
        r = fn(z, data)
        return (z, 0.5 * jnp.sum(r * r), state.iter_num, jnp.all(jnp.isfinite(z))), None
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
    return (z, 0.5 * jnp.sum(r * r), sol.stats["num_steps"], ok), None


_OWN = {"_solve": _solve, "solve_with_covariances": solve_with_covariances}


def stock_solve(entry) -> bool:
    """Whether ``entry`` (a solve function of this module, as a caller holds it) and the ``_solve``
    it calls are the ones this module defines: only programs traced from those are stored on disk
    (:mod:`~appearance_jax.core.program_store`; a test may replace either)."""
    return _solve is _OWN["_solve"] and _OWN.get(getattr(entry, "__name__", None)) is entry


def fit(model, table: Table, *, init=None, fix=None, metric: str = "l2", weights=None,
        max_theta_deg: float | None = 85.0, use_sigma: bool = True, solver: str = "lm", rtol: float = 1e-8,
        atol: float = 1e-10, max_steps: int = 400, n_starts: int = 1, seed: int = 0, key=None,
        model_kwargs=None, verbose: int = 0, bootstrap: int = 0, bootstrap_seed: int = 0,
        loss_tol: float | None = None) -> FitResult:
    """Fit ``model`` (a registered name or Model) to ``table``.

    Args:
        init: start ``Params`` or a preset name (default: the model's defaults), or a list of
            them: one start each (e.g. thicknesses spread over one period of a thin film's
            optical thickness); fixed fields and static settings come from the first.
        fix: names to hold at their start value, or {name: value}.
        metric: ``"l2"`` | ``"cos_log"`` | ``"relative"`` (:mod:`~appearance_jax.fit.solve.residuals`).
        weights: per-sample weights broadcastable to (N, B).
        max_theta_deg: mask samples with theta_i or theta_o above this (grazing; None keeps all).
        use_sigma: normalise residuals by the table's sigma when it has one (absolute covariance).
        solver: one of ``SOLVERS``; rtol/atol/max_steps: its stopping rule.
        loss_tol: ``solver="lm"`` only: also stop when the Gauss-Newton step from the current
            point would lower the loss 1/2 sum r^2 by less than this (the fit is as close to the
            data as it gets). With absolute sigmas (whitened residuals) that is a chi^2 within
            2 loss_tol of its minimum: 0.005 puts every parameter within ~0.1 sigma of the
            optimum, and ends fits whose poorly constrained directions would keep the step
            criterion (rtol, atol on the parameters) from ever holding. None: off.
        n_starts: > 1 adds n_starts - 1 random starts (``seed``) and keeps the best.
        key: PRNG key for stochastic models (common random numbers).
        verbose: print step and loss every ``verbose`` steps (0: silent).
        bootstrap: number of block-bootstrap replicates (0: none; >= 2): incidence directions
            resampled with replacement (``bootstrap_seed``) and refitted from the optimum in one
            vmapped solve; sets ``sigma_bootstrap`` and ``bootstrap`` (percentile intervals) of
            the result (:mod:`~appearance_jax.fit.solve.uncertainty`). 64 is a good start.

    Raises:
        FitDiverged: every start ended on non-finite parameters (:mod:`~.result`); a fit that
            merely stops at ``max_steps`` returns a result with ``converged = False``.
    """
    if solver not in SOLVERS:
        raise ValueError(f"solver = {solver!r}: must be one of {', '.join(SOLVERS)}")
    compile_cache.ensure()
    if n_starts < 1:
        raise ValueError(f"n_starts = {n_starts} must be >= 1")
    if loss_tol is not None:
        if solver != "lm":
            raise ValueError(f"loss_tol = {loss_tol!r}: only solver='lm' has this stopping rule (solver = {solver!r})")
        if not (isinstance(loss_tol, (int, float, np.floating)) and np.isfinite(loss_tol) and loss_tol >= 0):
            raise ValueError(f"loss_tol = {loss_tol!r} must be a finite number >= 0 (or None)")
    if bootstrap != 0:
        unc.bootstrap_weights(np.zeros(1, int), np.ones(1, bool), bootstrap)  # checks the count eagerly
    if not isinstance(bootstrap_seed, (int, np.integer)) or isinstance(bootstrap_seed, bool):
        raise ValueError(f"bootstrap_seed = {bootstrap_seed!r} must be an int")
    inits = list(init) if isinstance(init, (list, tuple)) else [init]
    if not inits:
        raise ValueError("init: an empty list of starts")
    init = inits[0]
    problem = build_problem(model, table, init=init, fix=fix, metric=metric, weights=weights,
                            max_theta_deg=max_theta_deg, use_sigma=use_sigma, key=key, model_kwargs=model_kwargs)
    sp = problem.space
    dt = np.dtype(jnp.result_type(float))
    # the given starts (the first is the problem's own), then n_starts - 1 random ones; numpy, like
    # the problem's data (build_problem): the compiled solve moves its arguments in one call
    xs = [sp.x_start()] + [sp.x_from_params(start_params(problem.model, p)) for p in inits[1:]]
    z0 = np.stack([sp.z_from_x(x) for x in xs]).astype(dt)
    if n_starts > 1:
        z0 = np.concatenate([z0, np.asarray(sp.random_z(jax.random.PRNGKey(seed), n_starts - 1), dt)])
    n_starts = z0.shape[0]

    def run(z0s, data):
        # starts one after another (lax.map), not vmapped: a vmapped while loop compiles to a
        # program 2-3x slower to compile (every branch becomes a select over the batch), and
        # on a CPU batching the starts saves little. Each start's residuals and Jacobian come with
        # it (LM's own final ones, so no program of their own traces and compiles the model again);
        # the covariances are computed from them on the host (uncertainty.covariances_host)
        return jax.lax.map(lambda z: solve_with_jacobian(problem, z, data, solver=solver, rtol=rtol, atol=atol,
                                                         max_steps=max_steps, verbose=verbose, loss_tol=loss_tol),
                           z0s)

    # the compiled solve is kept for later fits of the same problem and shapes (:mod:`~.reuse`)
    pkey = reuse.problem_key(problem)
    n_valid = int((np.asarray(problem.data["weight"]) > 0).sum()) if verbose else None  # printed loss scale
    # _solve itself too: a replaced solver function (a test's monkeypatch) must not get the old program
    skey = None if pkey is None else (pkey, _solve, solver, rtol, atol, max_steps, verbose, n_valid, loss_tol)
    # and on disk for later processes (:mod:`~appearance_jax.core.program_store`), when it is this
    # module's own solve of a registered model and prints nothing (a printer is a host callback)
    dkey = reuse.disk_key(problem) if skey is not None and stock_solve(_solve) and not verbose else None
    disk = None if dkey is None else (dkey, solver, rtol, atol, max_steps, loss_tol)
    t0 = time.perf_counter()
    compiled = reuse.cached("solve", skey,
                            lambda: compile_cache.compile_lowered(jax.jit(run).lower(z0, problem.data)),
                            z0, problem.data, disk=disk)
    t1 = time.perf_counter()
    (z, loss, steps, ok), (xs, rs, Js) = jax.block_until_ready(compiled(z0, problem.data))
    z = np.asarray(z)  # on the host: indexing a device array is a program of its own
    loss = np.asarray(loss, np.float64)
    loss = np.where(np.isfinite(loss), loss, np.inf)
    best = int(np.argmin(loss))
    clusters = unc.incidence_clusters(problem.data["wi"])
    cl, n_cl, _ = clusters
    x_best = np.asarray(xs)[best]
    cov = unc.covariances_host(problem, x_best, np.asarray(rs)[best], np.asarray(Js)[best], problem.data["weight"],
                               cl, n_cl)
    wall = time.perf_counter() - t1  # the solve and its covariances
    starts = {}
    if n_starts > 1:
        n = problem.space.size
        starts = dict(n_starts=n_starts, losses=(2 * loss / max(int((np.asarray(problem.data["weight"]) > 0).sum()), 1)).tolist(),
                      best=best, n_parameters=n)
    boot = None
    if bootstrap:
        boot = _bootstrap(problem, z[best], bootstrap, bootstrap_seed, solver=solver, rtol=rtol, atol=atol,
                          max_steps=max_steps)
    res = finish(problem, table, z[best], loss[best], np.asarray(steps)[best], np.asarray(ok)[best], wall,
                 solver, starts, bootstrap=boot, covariances=cov, x=x_best,
                 clusters=clusters)
    res.compile_time = t1 - t0
    return res


def _bootstrap(problem: Problem, z, n_boot: int, seed: int, **solve_kw) -> dict:
    """Block bootstrap of one fit: ``n_boot`` refits from its optimum ``z`` (:func:`bootstrap_refits`)."""
    xs, ok = bootstrap_refits(problem, np.asarray(z)[None], n_boot, seed, **solve_kw)
    out = unc.bootstrap_summary(xs[0], ok[0])
    out["seed"] = int(seed)
    return out


def bootstrap_refits(problem: Problem, zs, n_boot: int, seed: int = 0, *, f=None, weight=None,
                     batch_size: int = 8, **solve_kw):
    """Block-bootstrap refits over incidence directions, all in one vmapped solve.

    ``zs`` (K, p): the optima of K fits of ``problem`` (K = 1 for :func:`fit`); ``f`` and
    ``weight`` (K, N, B): their data (default: the problem's own, broadcast). Every replicate
    multiplies the weights by sqrt(multiplicity) of the resampled incidence clusters
    (:func:`~.uncertainty.bootstrap_weights`, the same ``n_boot`` draws for every fit), so
    shapes stay fixed, and starts from the fit's optimum. The replicates run ``batch_size`` at a
    time (vmapped) in one compiled loop. Returns physical x (K, n_boot, p) and converged
    (K, n_boot), numpy.
    """
    data = problem.data
    zs = np.atleast_2d(np.asarray(zs))
    K = zs.shape[0]
    dt = jnp.result_type(float)
    fs = np.broadcast_to(np.asarray(data["f"] if f is None else f), (K,) + tuple(data["f"].shape))
    ws = np.broadcast_to(np.asarray(data["weight"] if weight is None else weight), fs.shape)
    cl, _, _ = unc.incidence_clusters(data["wi"])
    counts = unc.bootstrap_weights(cl, (ws > 0).any(axis=(0, 2)), n_boot, seed)  # (n_boot, N)
    mult = jnp.asarray(np.sqrt(counts)[:, :, None], dt)

    def run(zs, fs, ws, mult, data):
        def one(z, f, w):
            d = dict(data, f=f, weight=w)
            z, _, _, ok = solve_z(problem, z, d, **solve_kw)
            return problem.space.x_from_z(z), ok

        # replicates in chunks of batch_size (lax.map): the memory of a vmapped solve grows with
        # the batch (a coated model's Jacobian over 64 replicates needs tens of GB)
        return jax.vmap(lambda z, f, w: jax.lax.map(lambda m: one(z, f, w * m), mult,
                                                    batch_size=min(batch_size, n_boot)))(zs, fs, ws)

    args = (jnp.asarray(zs, dt), jnp.asarray(fs, dt), jnp.asarray(ws, dt), mult, data)
    pkey = reuse.problem_key(problem)
    bkey = None if pkey is None else (pkey, solve_z, n_boot, batch_size, tuple(sorted(solve_kw.items())))
    run_jit = reuse.cached("bootstrap", bkey, lambda: jax.jit(run), *args)
    xs, ok = run_jit(*args)
    return np.asarray(xs, np.float64), np.asarray(ok)


__all__ = ["fit", "solve_z", "solve_with_jacobian", "solve_with_covariances", "bootstrap_refits", "SOLVERS"]
