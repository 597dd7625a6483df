"""Fit many tables (or texels) that share their angles, in one batched XLA program.

    result = fit_batch("lambert", table, values)      # values: (K, N, B), K tables on table's angles
    result.x, result.sigma                             # (K, p)

The single-table solve of :mod:`~appearance_jax.fit.solve` is ``vmap``-ed over the batch
axis (data, masks, sigma, start values); the directions are shared. With more than one
device the batch axis is **sharded** with ``jax.sharding`` (a 1-D ``Mesh`` named
``"batch"``; shared arrays replicated), so the same code runs on one CPU, several
accelerators, or — after ``jax.distributed.initialize()`` — several hosts: XLA partitions
the program, there is no home-made scheduler. K is padded to a multiple of the device count
by repeating the last item; the padding is dropped from the result.

A batched while-loop runs until every item has converged, so ``iterations`` is per item
but the wall time is that of the slowest.

Test on CPU with ``XLA_FLAGS=--xla_force_host_platform_device_count=2``.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ...core import compile_cache
from ..tables.table import Table
from .problem import build_problem, entry_arrays
from . import reuse
from . import uncertainty as unc
from .result import FitResult, finish, flags, sigma_kinds
from .solvers import SOLVERS, bootstrap_refits, solve_with_covariances, stock_solve


@dataclass
class BatchFitResult:
    """Results of :func:`fit_batch`; arrays have a leading batch axis K."""

    model: str
    labels: tuple
    units: tuple
    x: np.ndarray  # (K, p)
    sigma: np.ndarray  # (K, p) default 1-sigma (method sigma_method; NaN at a bound or flat), as FitResult.sigma
    loss: np.ndarray  # (K,) mean squared residual in the fit metric
    iterations: np.ndarray  # (K,)
    converged: np.ndarray  # (K,)
    at_bound: np.ndarray  # (K, p) bool
    poorly_determined: np.ndarray  # (K, p) bool
    wall_time: float
    compile_time: float
    n_devices: int
    solver: str
    metric: str
    sigma_method: str = "cr3"
    sigma_iid: np.ndarray | None = None  # (K, p) each kind as FitResult's
    sigma_hc1: np.ndarray | None = None
    sigma_sandwich: np.ndarray | None = None  # cluster-robust over incidence directions (CR3)
    sigma_cr1: np.ndarray | None = None  # its CR1 form
    n_clusters: int = 0
    _problem: object = None
    _z: np.ndarray | None = None
    _data: dict | None = None
    _masked: list | None = None  # per item: reason -> count
    _cov: dict | None = None  # uncertainty.covariances of every item, (K, ...) arrays
    _solve_kw: dict = dataclasses.field(default_factory=dict)  # rtol, atol, max_steps of the solve

    def __len__(self) -> int:
        return self.x.shape[0]

    def item(self, k: int) -> FitResult:
        """The full :class:`FitResult` of item k: its covariances from the batch's solve, its fitted
        values and error metrics computed here."""
        data = {n: (v if n in ("wi", "wo", "cos_i") else v[k]) for n, v in self._data.items()}
        problem = dataclasses.replace(self._problem, masked=self._masked[k])
        cov = None if self._cov is None else {n: v[k] for n, v in self._cov.items()}
        r = finish(problem, None, self._z[k], 0.5 * self.loss[k] * max(int((np.asarray(data["weight"]) > 0).sum()), 1),
                   self.iterations[k], self.converged[k], self.wall_time, self.solver, data=data, covariances=cov)
        return r

    def bootstrap(self, n_boot: int = 64, seed: int = 0, items=None) -> dict:
        """Block bootstrap over incidence directions for every item (or ``items``: indices), in one
        vmapped solve.

        Returns {"sigma": (k, p), "interval68", "interval95": (k, p, 2), "replicates": n_boot,
        "failed", "not_converged": (k,) counts of refits} (:func:`~.uncertainty.bootstrap_summary`).
        """
        idx = np.arange(len(self)) if items is None else np.asarray(items, int)
        kw = dict(solver=self.solver, **self._solve_kw)
        xs, ok = bootstrap_refits(self._problem, self._z[idx], n_boot, seed, f=self._data["f"][idx],
                                  weight=self._data["weight"][idx], **kw)
        items = [unc.bootstrap_summary(x, o) for x, o in zip(xs, ok)]
        return dict(sigma=np.stack([d["sigma"] for d in items]),
                    interval68=np.stack([d["interval68"] for d in items]),
                    interval95=np.stack([d["interval95"] for d in items]), replicates=int(n_boot),
                    failed=np.array([d["failed"] for d in items]),
                    not_converged=np.array([d["not_converged"] for d in items]), seed=int(seed))


def fit_batch(model, table: Table, values, *, sigma=None, mask=None, init=None, fix=None, metric: str = "l2",
              weights=None, max_theta_deg: float | None = 85.0, solver: str = "lm", rtol: float = 1e-8,
              atol: float = 1e-10, max_steps: int = 400, devices=None, key=None, model_kwargs=None) -> BatchFitResult:
    """Fit ``model`` to K tables on the angles of ``table``.

    Args:
        table: gives the directions, quantity, bands and the base mask (its values are ignored).
        values: (K, N, B) in ``table.quantity`` (NaN = missing).
        sigma, mask: optional (K, N, B) uncertainties and extra masks.
        devices: devices to shard the batch over (default: all of ``jax.devices()``).
        Other arguments as :func:`~appearance_jax.fit.solve.fit`.
    """
    if solver not in SOLVERS:
        raise ValueError(f"solver = {solver!r}: must be one of {', '.join(SOLVERS)}")
    compile_cache.ensure()
    values = np.asarray(values, np.float64)
    if values.ndim != 3 or values.shape[1:] != table.values.shape:
        raise ValueError(f"fit_batch: values must have shape (K, {table.n_samples}, {table.n_bands}), got {values.shape}")
    K = values.shape[0]
    base = np.broadcast_to(table.mask, values.shape) & np.isfinite(values)
    if mask is not None:
        base = base & np.broadcast_to(np.asarray(mask, bool), values.shape)
    if sigma is not None:
        sigma = np.broadcast_to(np.asarray(sigma, np.float64), values.shape)

    # The model, the free parameters, the directions and cos theta_i are shared: one problem (on
    # item 0) carries them; the per-entry arrays of all K items are prepared in one numpy pass.
    problem = build_problem(model, table.replace(values=values[0], mask=base[0],
                                                 sigma=None if sigma is None else sigma[0]),
                            init=init, fix=fix, metric=metric, weights=weights, max_theta_deg=max_theta_deg,
                            key=key, model_kwargs=model_kwargs)
    sp = problem.space
    f, inv, weight, extra, _ = entry_arrays(table, values, sigma, base, metric=metric, weights=weights,
                                            max_theta_deg=max_theta_deg, use_sigma=True, floor=problem.floor)
    n_valid = (weight > 0).sum(axis=(1, 2))
    if np.any(n_valid < sp.size):
        k = int(np.argmin(n_valid))
        raise ValueError(f"{table.source}[{k}]: {int(n_valid[k])} valid values for {sp.size} free parameters "
                         f"({', '.join(sp.labels)})")
    masked = [dict(table.masked) for _ in range(K)]
    missing = (~np.isfinite(values) & table.mask).sum(axis=(1, 2))
    for k in range(K):
        if missing[k]:
            masked[k]["missing value"] = masked[k].get("missing value", 0) + int(missing[k])
        masked[k].update({why: int(n[k]) for why, n in extra.items() if n[k]})
    devs = list(devices) if devices is not None else jax.devices()
    n_dev = len(devs)
    pad = (-K) % n_dev
    idx = np.array(list(range(K)) + [K - 1] * pad)
    per_item = ("f", "inv_scale", "weight")
    dt = jnp.result_type(float)
    stacked = dict(f=f, inv_scale=inv, weight=weight)
    data = {n: (problem.data[n] if n not in per_item else jnp.asarray(stacked[n][idx], dt)) for n in problem.data}
    z0 = jnp.asarray(sp.z_from_x(sp.x_start()), jnp.result_type(float))
    z0 = jnp.broadcast_to(z0, (len(idx), z0.shape[0]))

    in_axes = ({n: (0 if n in per_item else None) for n in data},)
    cl, n_cl, _ = unc.incidence_clusters(problem.data["wi"])
    cl = jnp.asarray(cl)

    def run(z0s, data):
        def one(z, d):
            (z, loss, steps, ok), cov = solve_with_covariances(problem, z, d, cl, n_cl, solver=solver, rtol=rtol,
                                                               atol=atol, max_steps=max_steps)
            return z, sp.x_from_z(z), cov, loss, steps, ok

        return jax.vmap(one, in_axes=(0,) + in_axes)(z0s, data)

    if n_dev > 1:
        from jax.sharding import Mesh, NamedSharding, PartitionSpec as P

        mesh = Mesh(np.array(devs), ("batch",))
        batched, shared = NamedSharding(mesh, P("batch")), NamedSharding(mesh, P())
        z0 = jax.device_put(z0, batched)
        data = {n: jax.device_put(v, batched if n in per_item else shared) for n, v in data.items()}
    # kept for later batches of the same problem, shapes and devices (:mod:`~.reuse`); ``run`` also
    # captures the incidence clusters (from the directions) and the solver settings
    pkey = reuse.problem_key(problem)
    bkey = None if pkey is None else (pkey, solve_with_covariances, solver, rtol, atol, max_steps, int(n_cl),
                                      np.asarray(cl).tobytes(), tuple(d.id for d in devs))
    t0 = time.perf_counter()
    # on disk too for one device (a stored program's devices are ids of this process' client)
    dkey = reuse.disk_key(problem) if bkey is not None and n_dev == 1 and stock_solve(solve_with_covariances) else None
    disk = None if dkey is None else (dkey, solver, rtol, atol, max_steps, int(n_cl), np.asarray(cl))
    compiled = reuse.cached("batch", bkey, lambda: compile_cache.compile_lowered(jax.jit(run).lower(z0, data)),
                            z0, data, disk=disk)
    t1 = time.perf_counter()
    z, x, out, loss, steps, ok = jax.block_until_ready(compiled(z0, data))
    wall = time.perf_counter() - t1
    z, x, loss, steps, ok = (np.asarray(a)[:K] for a in (z, x, loss, steps, ok))
    out = {k: np.asarray(v)[:K] for k, v in out.items()}
    method, raw, sig = sigma_kinds(sp, x, out)
    bound, flat = flags(sp, x, raw, [out[method]], out["flat"])
    diag = lambda c: np.sqrt(np.abs(np.diagonal(c, axis1=-2, axis2=-1)))  # noqa: E731
    data_k = {n: (v if n not in per_item else np.asarray(v)[:K]) for n, v in data.items()}
    return BatchFitResult(model=problem.model.name, labels=sp.labels, units=sp.units(), x=x, sigma=sig,
                          loss=2.0 * loss / np.maximum(n_valid, 1), iterations=steps, converged=ok, at_bound=bound,
                          poorly_determined=flat, wall_time=wall, compile_time=t1 - t0, n_devices=n_dev,
                          solver=solver, metric=metric, sigma_method=method, sigma_iid=diag(out["iid"]),
                          sigma_hc1=diag(out["hc1"]), sigma_sandwich=diag(out["cr3"]),
                          sigma_cr1=diag(out["cr1"]),
                          n_clusters=int(np.min(out["g"])), _problem=problem, _z=z, _data=data_k, _masked=masked, _cov=out,
                          _solve_kw=dict(rtol=rtol, atol=atol, max_steps=max_steps))
