"""Uncertainties of a fit that stay honest under misfit and correlated residuals, and degeneracies.

Four estimates of the covariance of the fitted (physical) parameters x*, all from the Jacobian
J of the weighted residual vector r at the optimum (m valid residuals, p parameters,
"bread" B = (J^T J)^-1):

``iid``
    Cov = s^2 B with s^2 = r^T r / (m - p) (or 1 when the table carries sigma). Exact when
    every residual is an independent measurement error of the stated size and the model is
    right; far too small otherwise (a MERL table has ~116k strongly correlated values).
``hc1``
    Huber-White sandwich over single entries: Cov = m / (m - p) B (sum_e s_e s_e^T) B with
    the per-entry score s_e = J_e^T r_e (White 1980, MacKinnon & White 1985 "HC1"). Honest
    under misfit and heteroscedastic residuals, still blind to correlation between entries.
``cr1``
    Cluster-robust sandwich (Liang & Zeger 1986; Cameron & Miller 2015 "CR1"):
    Cov = c B (sum_g S_g S_g^T) B, S_g = sum over the entries of cluster g of s_e,
    c = G / (G - 1) (m - 1) / (m - p). Clusters are the table's **incidence directions**
    (rows with the same wi; :func:`incidence_clusters`): residuals of one incidence share
    the lamp, the sample's placement and the model's misfit along theta_o, and are strongly
    correlated; different incidences are treated as independent. The estimate has about
    G - 1 degrees of freedom, so it needs many incidences (:func:`min_clusters`).
``cr3``
    Its jackknife form (Bell & McCaffrey 2002; MacKinnon, Nielsen & Webb 2023 "CR3"): the
    linearised delete-one-cluster jackknife, Cov = (G - 1) / G sum_g d_g d_g^T with
    d_g = (A - A_g)^-1 S_g = (I - B A_g)^-1 B S_g (A = J^T J, A_g = J_g^T J_g). CR1 is biased
    low when a few incidences carry most of the fit's weight (grazing highlights in the l2
    metric); CR3 undoes most of that bias (benchmarks/README.md, "Uncertainty coverage": 1-sigma
    coverage 0.66 against CR1's 0.55 on the same tables).

A fifth, ``bootstrap``, refits the table B times with incidence blocks resampled with
replacement (:func:`bootstrap_weights`: multiplicity weights, so every replicate has the
table's shapes and all of them run as one compiled, vmapped solve from the optimum) and
reports the standard deviation and percentile intervals of the replicates
(:func:`bootstrap_summary`).

The default sigma of a :class:`~appearance_jax.fit.solve.FitResult` (:func:`default_method`)
is CR3 when the table has at least :func:`min_clusters` incidence directions, else the entry
sandwich HC1 (with a warning): sigma = sqrt(diag Cov_method), with no floor at the iid sigma
(:func:`default_sigma` says why; the iid sigma is reported next to it).

Degeneracies (:func:`degeneracies`): each parameter is scaled by its magnitude, clipped to
[1 %, 100 %] of its declared range (u = x / scale; a bounded range such as eta in [0, 20] is far
wider than what "resolved" means for eta = 1.5). A unit direction v in u is **unresolved** when
the data cannot tell a move of ``FLAT_FRACTION`` (half) of the parameters' scale along v from
noise: the loss rises by delta^2 lambda_v for a step delta and by one noise unit s^2 at the
1-sigma contour, so v is flat when its sigma, sqrt(v^T Cov_u v), exceeds FLAT_FRACTION (with the
iid covariance this is the eigenvalue rule lambda_v FLAT_FRACTION^2 < s^2 of the scaled J^T J;
with the sandwich it uses the honest noise level instead of s^2). The unresolved directions are
the eigenvectors of the scaled covariance of the default method with an eigenvalue above
FLAT_FRACTION^2; every parameter with a component above 0.3 in one belongs to its group.
A group also takes in every parameter correlated with a member by more than ``CORR`` (0.95).
Directions with an eigenvalue of the column-normalised J^T J below a fraction of the largest
(:func:`numerical_tol`: 1e3 machine epsilons) are exactly flat (the data do not depend on them
at all); their parameters get sigma = NaN. Parameters on a bound are held there (not part of
any group).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

FLAT_FRACTION = 0.5  # a direction whose 1-sigma exceeds this fraction of the parameters' scale is unresolved
MEMBER = 0.3  # a parameter belongs to a flat direction when its component exceeds this
CORR = 0.95  # ... or when it is correlated with a member by more than this
THETA_BIN_DEG = 3.0  # scattered incidences (e.g. the MERL grid) are clustered by theta_i in bins this wide
KNOWN = ("eta", "k")  # fields usually known from the material (a coat's or a metal's index)
METHODS = ("iid", "hc1", "cr1", "cr3", "bootstrap")
DESCRIPTION = {
    "iid": "s^2 (J^T J)^-1: every value an independent measurement",
    "hc1": "Huber-White sandwich over single entries (HC1)",
    "cr1": "cluster-robust sandwich (CR1) over incidence directions",
    "cr3": "cluster-robust sandwich over incidence directions, jackknife form (CR3)",
    "bootstrap": "block bootstrap over incidence directions (std of refits)",
}


def numerical_tol(dtype) -> float:
    """Eigenvalue ratio of the column-normalised J^T J below which a direction is exactly flat."""
    return float(1e3 * jnp.finfo(dtype).eps)


def min_clusters(p: int) -> int:
    """Incidence directions needed for the cluster sandwich with p parameters: max(10, 2 p + 1).

    Its meat has rank <= G - 1 (the scores sum to 0 at the optimum) and roughly G - p degrees of
    freedom; below this the relative error of its sigma exceeds ~1 / sqrt(2 (p + 1)).
    """
    return max(10, 2 * p + 1)


def incidence_clusters(wi) -> tuple[np.ndarray, int, str]:
    """(cluster index per row (N,), number of clusters G, what a cluster is).

    ``wi`` is the incident direction of each row (a Vec3 or anything with x, y, z). Rows whose
    wi agree to 1e-6 share a cluster. When most incidences are unique (scattered angle lists,
    the MERL half/difference grid: a cluster would be a single row), rows are clustered by
    theta_i in bins of ``THETA_BIN_DEG`` degrees instead.
    """
    xyz = np.stack([np.asarray(getattr(wi, c), np.float64) for c in "xyz"], axis=-1)
    # the three rounded components (|.| <= 1e6 < 2^20) packed into one int64 in their order, so that a
    # 1-D unique (several times faster than unique rows) gives the same lexicographic cluster order
    q = np.round(xyz / 1e-6).astype(np.int64) + (1 << 20)
    _, idx = np.unique((q[:, 0] << 42) | (q[:, 1] << 21) | q[:, 2], return_inverse=True)
    idx = idx.ravel()
    n = xyz.shape[0]
    g = int(idx.max()) + 1 if n else 0
    if n and g > n / 2:
        theta = np.degrees(np.arccos(np.clip(xyz[:, 2], -1.0, 1.0)))
        _, idx = np.unique(np.floor(theta / THETA_BIN_DEG).astype(np.int64), return_inverse=True)
        return idx.ravel(), int(idx.max()) + 1, f"theta_i bins of {THETA_BIN_DEG:g} deg"
    return idx, g, "one per incidence direction"


def off_bound(space, x, rel: float = 1e-3, xp=jnp):
    """(p,) bool: the entry is not within ``rel`` of a finite bound (as
    :meth:`~appearance_jax.fit.solve.transforms.ParamSpace.at_bound`). Traceable with ``xp=jnp``
    (the default), numpy with ``xp=np``."""
    specs = [f.spec for f in space.fields for _ in range(f.size)]
    lo = xp.asarray([s.lo for s in specs], x.dtype)
    hi = xp.asarray([s.hi for s in specs], x.dtype)
    box = xp.isfinite(lo) & xp.isfinite(hi)
    scale = xp.where(box, hi - lo, xp.maximum(xp.abs(x), 1e-12))
    near = (xp.isfinite(lo) & (x - lo <= rel * scale)) | (xp.isfinite(hi) & (hi - x <= rel * scale))
    return ~near


def covariances(problem, x, data, cluster, n_clusters: int, *, J=None, r=None) -> dict:
    """The iid, HC1, CR1 and CR3 covariances at physical x, and the numerically flat directions.

    Traceable (vmap it over a batch). ``cluster`` (N,) int: each row's cluster, ``n_clusters``
    static. A parameter on a bound is held there (an active constraint): its Jacobian column is
    dropped, so the others' covariances are conditional on it and its own rows are 0. Returns a dict of arrays: ``iid``, ``hc1``, ``cr1``, ``cr3`` (p, p) (pseudo-inverse
    bread: exactly flat directions projected out, see ``flat``), ``lam`` eigenvalues of the
    column-normalised J^T J relative to the largest, ``flat`` (p,) bool: the parameter has a
    component > ``MEMBER`` in an exactly flat direction, ``s2`` the iid residual variance,
    ``m`` valid residuals and ``g`` clusters with a valid residual. ``J`` (m_all, p) and ``r``
    (m_all,): the residuals' Jacobian in x and the residuals at x when the caller has them
    (:func:`jacobian_in_x`), else computed here. :func:`covariances_host` is the same in numpy.
    """
    if J is None:
        J = jax.jacfwd(problem.residuals_x)(x, data)
    if r is None:
        r = problem.residuals_x(x, data)
    return _estimates(jnp, J, r, data["weight"], cluster, n_clusters, off_bound(problem.space, x),
                      problem.absolute_sigma)


def covariances_host(problem, x, r, J, weight, cluster, n_clusters: int) -> dict:
    """:func:`covariances` in numpy, from the residuals ``r`` (m_all,) and their Jacobian ``J``
    (m_all, p) in x at physical ``x`` (as :func:`jacobian_in_x` gives them), in their dtype.

    Why on the host: a fit's compiled solve then only returns r and J, and XLA does not compile
    the estimates (their eigendecompositions, cluster sums and per-cluster solves took a quarter
    of a small fit's compile time; docs/fitting.md). A few milliseconds for a MERL-sized table.
    """
    J = np.asarray(J)
    x = np.asarray(x, J.dtype)
    try:
        # NaN in, NaN out, silently (as XLA computes the traced estimates): finish() checks the result
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            return _estimates(np, J, np.asarray(r, J.dtype), np.asarray(weight), np.asarray(cluster), n_clusters,
                              off_bound(problem.space, x, xp=np), problem.absolute_sigma)
    except np.linalg.LinAlgError:  # e.g. an infinite Jacobian entry: NaN estimates, as the traced ones give
        p = J.shape[-1]
        nan = np.full((p, p), np.nan, J.dtype)
        return dict(iid=nan, hc1=nan, cr1=nan, cr3=nan, lam=np.full(p, np.nan, J.dtype), flat=np.zeros(p, bool),
                    s2=np.asarray(np.nan, J.dtype), m=int(np.sum(np.asarray(weight) > 0)), g=0)


def _segment_summer(xp, ids, n: int):
    """Two functions of an array with rows per entry (m, ...), ``ids`` (m,) its segments in
    [0, n): the sums of the rows per segment (n, ...), and of J (m, p) the per-segment
    Gram matrices sum_e J_e J_e^T (n, p, p). The numpy ones sort the ids once for both."""
    if xp is jnp:
        summed = lambda v: jax.ops.segment_sum(v, ids, num_segments=n)  # noqa: E731
        return summed, lambda J: summed(J[:, :, None] * J[:, None, :])
    order = np.argsort(ids, kind="stable")
    bounds = np.searchsorted(ids[order], np.arange(n + 1))  # segment k: sorted rows bounds[k]:bounds[k+1]
    present = bounds[1:] > bounds[:-1]

    def summed(v):
        out = np.zeros((n,) + v.shape[1:], v.dtype)
        if present.any():
            out[present] = np.add.reduceat(v[order], bounds[:-1][present], axis=0)
        return out

    def gram(J):
        # one matrix product per segment: the (m, p, p) outer products would be 64 MB on a MERL table
        Js = J[order]
        out = np.zeros((n, J.shape[1], J.shape[1]), J.dtype)
        for k in np.flatnonzero(present):
            block = Js[bounds[k]:bounds[k + 1]]
            out[k] = block.T @ block
        return out

    return summed, gram


def _solve_each(xp, A, b):
    """Solutions of A_g x_g = b_g (G, p, p), (G, p); NaN for a singular A_g (as XLA's LU gives)."""
    if xp is jnp:
        return jnp.linalg.solve(A, b[..., None])[..., 0]
    try:
        return np.linalg.solve(A, b[..., None])[..., 0]
    except np.linalg.LinAlgError:  # numpy raises for any singular member: one at a time
        out = np.full(b.shape, np.nan, b.dtype)
        for k in range(A.shape[0]):
            try:
                out[k] = np.linalg.solve(A[k], b[k])
            except np.linalg.LinAlgError:
                pass
        return out


def _estimates(xp, J, r, weight, cluster, n_clusters: int, keep, absolute_sigma: bool) -> dict:
    """The estimates of :func:`covariances` from J (m_all, p) and r (m_all,) in x, with ``xp`` one
    of jnp (traceable) and np."""
    J = J * keep[None, :]
    valid = (weight > 0).ravel()
    m = xp.sum(valid)
    p = J.shape[1]
    d = xp.linalg.norm(J, axis=0)
    d = xp.where(d > 0, d, 1.0)
    Jn = J / d
    lam, vec = xp.linalg.eigh(Jn.T @ Jn)
    big = xp.maximum(lam[-1], xp.finfo(lam.dtype).tiny)
    ok = lam > numerical_tol(lam.dtype) * big
    bread = ((vec * xp.where(ok, 1.0 / xp.where(ok, lam, 1.0), 0.0)) @ vec.T) / xp.outer(d, d)
    dof = xp.maximum(m - p, 1)
    s2 = xp.asarray(1.0, r.dtype) if absolute_sigma else (r @ r) / dof
    scores = J * r[:, None]  # (m_all, p); masked entries have r = 0 and J = 0
    meat_e = scores.T @ scores * (m / dof)
    n_bands = weight.shape[-1]
    per_cluster, gram_per_cluster = _segment_summer(xp, xp.repeat(xp.asarray(cluster), n_bands), n_clusters)
    S = per_cluster(scores)
    g = xp.sum(per_cluster(valid.astype(r.dtype)) > 0)
    c = g / xp.maximum(g - 1, 1) * (m - 1) / dof
    meat_c = S.T @ S * c
    # CR3: the linearised delete-one-cluster jackknife, x_(-g) - x = (A - A_g)^-1 S_g
    # = (I - B A_g)^-1 B S_g (A = J^T J, A_g its part from cluster g); where deleting g leaves
    # the system singular, the CR1 term B S_g stands in.
    A_g = gram_per_cluster(J)
    BS = S @ bread.T
    delta = _solve_each(xp, xp.eye(p, dtype=J.dtype) - bread @ A_g, BS)
    delta = xp.where(xp.all(xp.isfinite(delta), axis=-1, keepdims=True), delta, BS)
    cov_jk = delta.T @ delta * ((g - 1) / xp.maximum(g, 1))
    flat = xp.any((xp.abs(vec) > MEMBER) & ~ok[None, :], axis=1) & keep
    return dict(iid=bread * s2, hc1=bread @ meat_e @ bread, cr1=bread @ meat_c @ bread, cr3=cov_jk,
                lam=lam / big, flat=flat, s2=s2, m=m, g=g)


def jacobian_in_x(problem, z, Jz):
    """(x, dr/dx) at x = x(z) from a solver's Jacobian ``Jz`` = dr/dz (traceable). The transforms
    act entry by entry (:mod:`~.transforms`), so dr/dx = Jz / (dx/dz) column by column; forward
    mode scales a column's tangent by dx/dz before propagating it, so the quotient is dr/dx to
    rounding. A column with dx/dz = 0 (x clipped to a bound) becomes NaN unless :func:`off_bound`
    drops it anyway: the caller then computes the covariances directly."""
    x, d = jax.jvp(problem.space.x_from_z, (z,), (jnp.ones_like(z),))
    keep = off_bound(problem.space, x)
    return x, jnp.where(d != 0, Jz / jnp.where(d != 0, d, 1.0), jnp.where(keep, jnp.nan, 0.0))


def covariance(problem, x, data):
    """(iid covariance, eigenvalues, exactly-flat mask) at physical x: traceable.

    The iid estimate of :func:`covariances` alone (no clusters), with NaN in the rows and
    columns of parameters in an exactly flat direction, for callers that rescale it themselves.
    """
    n = data["weight"].shape[0]
    out = covariances(problem, x, data, jnp.zeros(n, jnp.int32), 1)
    cov = jnp.where(out["flat"][:, None] | out["flat"][None, :], jnp.nan, out["iid"])
    return cov, out["lam"], out["flat"]


def default_method(n_clusters, p: int) -> str:
    """``"cr3"`` with at least :func:`min_clusters` (p) incidence clusters, else ``"hc1"``."""
    return "cr3" if int(n_clusters) >= min_clusters(p) else "hc1"


def default_sigma(cov_method) -> np.ndarray:
    """sqrt(diag Cov_method) (numpy; leading batch axes allowed).

    No floor at the iid sigma: the iid sigma pools s^2 over every entry, so when the errors are
    heteroscedastic (a glossy peak's residuals are orders of magnitude larger than the diffuse
    part's) it inflates the sigma of parameters that only the quiet entries determine (a coat's
    diffuse albedo) and would flag them as undetermined although the data pin them down.
    """
    b = np.diagonal(np.asarray(cov_method, np.float64), axis1=-2, axis2=-1)
    return np.sqrt(np.abs(b))


def scales(space, x) -> np.ndarray:
    """Scale of each free entry for the degeneracy rule: |x| clipped to [1 %, 100 %] of the range
    (max(|x|, 1e-12) for an unbounded field). Numpy; leading batch axes allowed."""
    x = np.asarray(x, np.float64)
    specs = [f.spec for f in space.fields for _ in range(f.size)]
    width = np.array([s.hi - s.lo for s in specs], np.float64)
    a = np.maximum(np.abs(x), 1e-12)
    return np.where(np.isfinite(width), np.clip(a, 0.01 * width, width), a)


def _scaled_eigh(space, x, cov):
    """Eigenvalues (..., p), eigenvectors (..., p, p) of the covariance in scaled parameters
    (:func:`scales`; numpy, leading batch axes allowed) and whether it is finite (...); a
    non-finite one is decomposed as 0."""
    R = scales(space, x)
    cu = np.asarray(cov, np.float64) / (R[..., :, None] * R[..., None, :])
    finite = np.all(np.isfinite(cu), axis=(-2, -1))
    cu = np.where(finite[..., None, None], cu, 0.0)
    w, v = np.linalg.eigh(0.5 * (cu + np.swapaxes(cu, -1, -2)))
    return w, v, finite


def unresolved(space, x, covs) -> tuple[np.ndarray, np.ndarray]:
    """(sigma along each unresolved eigen-direction, their eigenvectors) in scaled parameters.

    ``covs``: covariances (p, p) of one fit (the default method's). Returns a (k,) array
    of sigmas in units of the parameters' :func:`scales` (largest first) and (p, k) unit
    eigenvectors, for the directions whose sigma exceeds ``FLAT_FRACTION``.
    """
    sig, vecs = [], []
    for cov in covs:
        w, v, finite = _scaled_eigh(space, x, cov)
        if not finite:
            continue
        for j in np.argsort(w)[::-1]:
            if w[j] <= FLAT_FRACTION ** 2:
                break
            sig.append(math.sqrt(w[j]))
            vecs.append(v[:, j])
    return np.array(sig), (np.stack(vecs, axis=1) if vecs else np.zeros((np.shape(x)[-1], 0)))


def flat_members(space, x, covs) -> np.ndarray:
    """(..., p) bool: the parameter belongs to an unresolved direction (:func:`unresolved`).

    Leading batch axes allowed (``x`` (..., p), each cov (..., p, p)): one batched
    eigendecomposition for a whole :func:`~appearance_jax.fit.solve.fit_batch`. A fit whose
    scaled covariance is not finite contributes no direction, as in :func:`unresolved`.
    """
    x = np.asarray(x, np.float64)
    out = np.zeros(x.shape, bool)
    for cov in covs:
        w, v, finite = _scaled_eigh(space, x, cov)
        big = (w > FLAT_FRACTION ** 2) & finite[..., None]  # (..., k): direction k is unresolved
        out |= np.any((np.abs(v) > MEMBER) & big[..., None, :], axis=-1)
    return out


def _suggest(labels, members, comps) -> str:
    """What to fix in a degenerate group: a usually-known field (eta, k) if one is in it, else the
    member most aligned with the flat direction."""
    fields = [lab.partition("[")[0] for lab in members]
    known = [f for f in KNOWN if f in fields]
    if known:
        return (f"fix {' and '.join(known)} (a coat's or metal's refractive index is usually known), "
                "e.g. fix={" + ", ".join(f"{k!r}: ..." for k in known) + "}")
    lead = members[int(np.argmax(np.abs(comps)))]
    return f"fix {lead.partition('[')[0]} or constrain the group with other measurements"


def degeneracies(space, x, labels, covs, exact_flat, bound) -> list[dict]:
    """Groups of parameters that move together without changing the fit, with a suggestion.

    ``covs`` (the default method's covariance), ``exact_flat`` (p,) bool (numerically flat,
    :func:`covariances`), ``bound`` (p,) bool. Each group: ``parameters`` (labels),
    ``direction`` (components in scaled units), ``sigma_scaled`` (its 1-sigma in units of the
    parameters' :func:`scales`, None when exactly flat), ``correlated`` (the largest |correlation| among
    the members, None if unknown), ``suggestion`` and ``text`` (one line for the report).
    """
    labels = list(labels)
    ok = ~np.asarray(bound, bool)
    groups, seen = [], []
    sig, vecs = unresolved(space, x, covs)
    cands = [(s, vecs[:, j]) for j, s in enumerate(sig)]
    if np.any(exact_flat):
        cands.insert(0, (None, np.asarray(exact_flat, np.float64)))
    cov = np.asarray(covs[-1], np.float64)
    sd = np.sqrt(np.abs(np.diag(cov)))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr_all = np.abs(cov / np.outer(sd, sd))
    for s, v in cands:
        idx = [i for i in range(len(labels)) if abs(v[i]) > MEMBER and ok[i]] if s is not None else \
            [i for i in range(len(labels)) if v[i] > 0 and ok[i]]
        if s is not None and idx:
            near = np.nan_to_num(corr_all[idx]).max(axis=0) > CORR
            idx = sorted(set(idx) | {i for i in range(len(labels)) if near[i] and ok[i]})
        if not idx or any(set(idx) <= g for g in seen):
            continue  # an unresolved direction of the iid and of the default covariance: one group
        keep = [k for k, g in enumerate(seen) if not g <= set(idx)]
        groups, seen = [groups[k] for k in keep], [seen[k] for k in keep]
        seen.append(set(idx))
        members = [labels[i] for i in idx]
        corr = None
        if len(idx) > 1 and s is not None:
            with np.errstate(invalid="ignore", divide="ignore"):
                c = cov[np.ix_(idx, idx)] / np.outer(sd[idx], sd[idx])
            off = np.abs(c[~np.eye(len(idx), dtype=bool)])
            corr = float(np.nanmax(off)) if np.isfinite(off).any() else None
        how = ("the data do not depend on them" if s is None else
               f"their combined direction is unresolved: 1 sigma = {s:.2g} x their magnitudes")
        together = "move together" if len(idx) > 1 else "is undetermined"
        corr_txt = f", |corr| up to {corr:.2f}" if corr is not None else ""
        sugg = _suggest(labels, members, np.abs(v[idx]) * (np.abs(v[idx]) > MEMBER))
        groups.append(dict(parameters=members, direction=[float(v[i]) for i in idx],
                           sigma_scaled=None if s is None else float(s), correlated=corr, suggestion=sugg,
                           text=f"{', '.join(members)} {together} ({how}{corr_txt}); {sugg}"))
    return groups


def bootstrap_weights(cluster, valid_rows, n_boot: int, seed: int = 0) -> np.ndarray:
    """(n_boot, N) multiplicities of the rows: incidence clusters resampled with replacement.

    Each replicate draws G clusters (those with a valid row) uniformly with replacement
    (``numpy.random.default_rng(seed)``); a row's multiplicity is its cluster's count. The sum
    of squared residuals of a replicate weights each entry by it (so the fit's weight, a
    square root, is multiplied by sqrt(count)).
    """
    if not isinstance(n_boot, (int, np.integer)) or isinstance(n_boot, bool) or n_boot < 2:
        raise ValueError(f"bootstrap = {n_boot!r}: the number of replicates must be an int >= 2")
    cluster = np.asarray(cluster)
    live = np.unique(cluster[np.asarray(valid_rows, bool)])
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, live.size, size=(n_boot, live.size))
    counts = np.zeros((n_boot, int(cluster.max()) + 1))
    np.add.at(counts, (np.arange(n_boot)[:, None], live[draws]), 1.0)  # counts[b, c] += 1 per draw
    return counts[:, cluster]


def bootstrap_summary(xs, ok) -> dict:
    """Standard deviation and percentile intervals (68.3 %, 95 %) of the replicates x (B, p).

    Every replicate with finite values counts, converged or not (``ok``): a refit that runs out
    of steps in a flat valley has wandered along it, and leaving it out would hide the valley.
    ``failed`` counts the non-finite replicates (left out), ``not_converged`` the others.
    """
    xs = np.asarray(xs, np.float64)
    good = np.all(np.isfinite(xs), axis=1)
    xg = xs[good]
    out = dict(replicates=int(xs.shape[0]), failed=int((~good).sum()),
               not_converged=int((good & ~np.asarray(ok, bool)).sum()))
    if xg.shape[0] < 2:
        nan = np.full(xs.shape[1], np.nan)
        return dict(out, sigma=nan, interval68=np.stack([nan, nan], 1), interval95=np.stack([nan, nan], 1))
    q = np.percentile(xg, [15.865, 84.135, 2.5, 97.5], axis=0)
    return dict(out, sigma=xg.std(axis=0, ddof=1), interval68=q[:2].T, interval95=q[2:].T)


__all__ = ["covariances", "covariances_host", "jacobian_in_x", "covariance", "incidence_clusters", "default_method", "default_sigma", "min_clusters",
           "degeneracies", "flat_members", "unresolved", "scales", "bootstrap_weights", "bootstrap_summary",
           "METHODS", "DESCRIPTION", "FLAT_FRACTION"]
