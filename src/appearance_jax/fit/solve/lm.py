"""A compact Levenberg-Marquardt solver for the fitters: small to trace, small to compile.

The default solver of :func:`appearance_jax.fit.fit` (``solver="lm"``). It minimises
1/2 |r(z)|^2 for a residual vector r of a handful of unconstrained parameters z, as one
``lax.while_loop`` (jittable, vmappable over starts or tables):

- Jacobian J = dr/dz by forward mode (``jax.jacfwd``: one JVP per parameter), computed at the
  top of an iteration that follows an accepted step (one trace of it in the program); r(z0)
  comes from a first pass of the loop (a trial at a zero step, not counted as a step) and the
  accepted trial's r is carried, so the forward pass is traced once too;
- step: (JᵀJ + λ d I) δ = -Jᵀr, solved by Cholesky, with d the mean of diag(JᵀJ) (isotropic
  damping, as Levenberg's; Marquardt's per-parameter scaling, Moré 1978, crawled for hundreds of
  steps when a parameter sat at a bound of its transform, where its Jacobian column vanishes);
- gain ratio ρ = actual / predicted decrease of the loss; the step is accepted when ρ > 1e-4
  and the new loss is finite. The damping follows Nielsen (1999, "Damping parameter in
  Marquardt's method", IMM-REP-1999-05): on acceptance λ <- λ max(1/3, 1 - (2ρ - 1)^3) and ν
  <- 2, on rejection λ <- λ ν and ν <- 2ν (a NaN or inf trial point is a rejection, so a model
  that blows up far from the data only shortens the step);
- convergence (the Cauchy criterion of optimistix' least-squares solvers): a step with
  max_i |δ_i| / (atol + rtol |z_i|) <= 1 and |Δloss| <= atol + rtol loss (accepted or, at an
  optimum, rejected by rounding), or a residual
  orthogonal to every Jacobian column to rounding (cosine <= 100 eps, MINPACK's gtol test),
  or (``loss_tol``, off by default) a Gauss-Newton decrement below a loss tolerance.
  ``max_steps`` counts iterations (accepted or not); a damping above 1e16 (no step decreases
  the loss) stops the loop unconverged.

Why our own: optimistix' LevenbergMarquardt (still available as ``solver="optx_lm"``) reaches
the same optima, but its trust-region machinery takes 3-4x longer to trace (compilation takes
about as long); a warm fit's wall time is mostly tracing (benchmarks/README.md,
``fit_lm_vs_powell.py`` and ``solver_compile.py``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

#: smallest gain ratio of an accepted step
RHO_MIN = 1e-4
#: initial damping, relative to the mean diagonal of JᵀJ
LAMBDA0 = 1e-3
#: the orthogonality test, in units of machine epsilon
GTOL_EPS = 100.0
#: damping beyond which no step can make progress (the loss is flat to rounding): stop
LAMBDA_MAX = 1e16


def levenberg_marquardt(fn, z0, data, *, rtol: float = 1e-8, atol: float = 1e-10, max_steps: int = 400,
                        loss_tol: float | None = None, progress=None, with_jacobian: bool = False,
                        n_residuals: int | None = None, jacobian=None):
    """Minimise 1/2 |fn(z, data)|^2 from ``z0`` (p,). Returns ``(z, loss, steps, converged)``
    (loss = 1/2 |r|^2 at z; steps = iterations taken; converged a bool array). ``loss_tol``:
    also converged when the Gauss-Newton decrement 1/2 gᵀ(JᵀJ)⁻¹g at the current point (the
    loss the undamped step would remove) is at most this (None: off). ``progress``: a
    host function ``(step, loss)`` called after every iteration (a host callback: such a
    program is not kept in JAX's persistent compilation cache). ``with_jacobian``: also return
    r and J = dr/dz at the returned z, ``(z, loss, steps, converged, r, J)``: when the last step
    was accepted the loop runs one more pass that only takes the Jacobian there (the same traced
    Jacobian, so the program holds one copy of it; the uncertainties at the optimum need no
    program of their own). ``n_residuals``: the length of r when the caller knows it (else it
    is found by tracing ``fn`` once more). ``jacobian``: a function ``(z, data) -> dr/dz`` to use
    instead of ``jax.jacfwd(fn)`` (a fit's :meth:`~.problem.Problem.jacobian_z`)."""
    z0 = jnp.asarray(z0)
    dt = z0.dtype
    jac = jax.jacfwd(fn) if jacobian is None else jacobian

    # r(z0) is not evaluated here but by a first pass of the loop (``start``), as a trial point
    # with a zero step: the model's forward pass is then traced and compiled once, in the loop
    # (a copy before the loop cost a fifth of the solve program's compile time)
    m = jax.eval_shape(fn, z0, data).shape[0] if n_residuals is None else int(n_residuals)
    lam0 = jnp.asarray(LAMBDA0, dt)
    eye = jnp.eye(z0.shape[0], dtype=dt)

    def cond(s):
        more = (~s["done"]) & (s["step"] < max_steps)
        return s["start"] | ((more | s["fresh"]) if with_jacobian else more)

    def body(s):
        z, loss, lam, nu, start = s["z"], s["loss"], s["lam"], s["nu"], s["start"]
        # with_jacobian: a pass after the last step only refreshes J (the state is kept below)
        final = s["done"] | (s["step"] >= max_steps)
        # the Jacobian at the current point, computed only after a move: one trace of the model's
        # forward-mode derivative in the program (compile time), none after the last step. r is the
        # plain evaluation that accepted z (the trial's r_new), not the JVP's primal output
        # (jacfwd(has_aux)): a Monte Carlo model's estimator may differ under differentiation (the
        # cosmetics walk's CRN fit then stopped converging), and r must match the loss; carrying it
        # (and taking r(z0) from the start pass) keeps one copy of the forward pass in the program
        r = s["r"]
        J = jax.lax.cond(s["fresh"], lambda: jac(z, data), lambda: s["J"])
        g = J.T @ r
        H = J.T @ J
        # isotropic damping lam * mean(diag H) * I: a parameter pinned at a bound (its Jacobian column
        # vanishes there) stays damped, while the others converge (Marquardt's diagonal scaling
        # crawled for hundreds of steps on such fits)
        d = jnp.mean(jnp.diag(H))
        A = H + (lam * d) * eye
        c = jax.scipy.linalg.cho_factor(A, lower=True)
        dz = -jax.scipy.linalg.cho_solve(c, g)
        dz = jnp.where(jnp.all(jnp.isfinite(dz)) & ~start, dz, 0.0)
        z_new = z + dz
        r_new = fn(z_new, data)
        loss_new = 0.5 * jnp.sum(r_new * r_new)
        pred = 0.5 * jnp.dot(dz, (lam * d) * dz - g)  # loss decrease of the linear model, >= 0
        rho = (loss - loss_new) / jnp.where(pred > 0, pred, 1.0)
        ok = jnp.isfinite(loss_new) & (pred > 0) & (rho > RHO_MIN)
        # first-order optimality to rounding: the residual is orthogonal to every Jacobian column
        # (the cosine, as MINPACK's gtol test); catches an optimum where rounding rejects every step
        rnorm = jnp.sqrt(2.0 * loss)
        colnorm = jnp.sqrt(jnp.maximum(jnp.diag(H), jnp.finfo(dt).tiny))
        flat = jnp.max(jnp.abs(g) / colnorm) <= GTOL_EPS * jnp.finfo(dt).eps * rnorm
        small_step = jnp.all(jnp.abs(dz) <= atol + rtol * jnp.abs(z))
        small_change = jnp.abs(loss - loss_new) <= atol + rtol * loss
        # a step below the tolerances whose loss matches to the tolerance ends the fit, accepted or
        # not: at an optimum rounding rejects such steps (away from one a short enough step always
        # decreases the loss, and a NaN trial point fails small_change)
        converged = (jnp.isfinite(loss_new) & small_step & small_change) | flat
        if loss_tol is not None:
            # JᵀJ regularised at the dtype's rounding: an exactly flat direction (zero column) has g = 0.
            # Conservative near a bound of a parameter's transform: there its column vanishes but the
            # residual's projection on it does not, so the decrement stays up and the fit goes on. A
            # test on a step's gain instead (MINPACK's ftol) would end such crawls sooner, but it also
            # stops Rosenbrock's curved valley (b = 1000) at a loss of 2: not used
            Hr = H + (10.0 * jnp.finfo(dt).eps * d) * eye
            dec = 0.5 * jnp.dot(g, jax.scipy.linalg.cho_solve(jax.scipy.linalg.cho_factor(Hr, lower=True), g))
            converged = converged | (jnp.isfinite(dec) & (dec <= loss_tol))
        z2 = jnp.where(ok, z_new, z)
        lam2 = jnp.where(ok, lam * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), lam * nu)
        nu2 = jnp.where(ok, 2.0, 2.0 * nu)
        stuck = lam2 > LAMBDA_MAX
        if progress is not None:
            # step 0 for the start and the final pass: _progress_host prints nothing for them
            jax.debug.callback(progress, jnp.where(final | start, 0, s["step"] + 1), jnp.where(ok, loss_new, loss))
        new = dict(z=z2, r=jnp.where(ok, r_new, r), J=J, fresh=ok, loss=jnp.where(ok, loss_new, loss), lam=lam2,
                   nu=nu2, step=s["step"] + 1, done=converged | stuck, converged=converged, start=start)
        # the start pass: r and the loss at z0 (the trial at dz = 0) and J there; no step counted
        first = dict(s, r=r_new, J=J, fresh=jnp.asarray(False), loss=loss_new, done=~jnp.isfinite(loss_new),
                     start=jnp.asarray(False))
        if with_jacobian:
            new = jax.tree_util.tree_map(lambda a, b: jnp.where(final, a, b), dict(s, J=J, fresh=jnp.asarray(False)),
                                         new)
        return jax.tree_util.tree_map(lambda a, b: jnp.where(start, a, b), first, new)

    s0 = dict(z=z0, r=jnp.zeros(m, dt), J=jnp.zeros((m, z0.shape[0]), dt), fresh=jnp.asarray(True),
              loss=jnp.asarray(jnp.inf, dt), lam=lam0, nu=jnp.asarray(2.0, dt), step=jnp.asarray(0),
              done=jnp.asarray(False), converged=jnp.asarray(False), start=jnp.asarray(True))
    s = jax.lax.while_loop(cond, body, s0)
    if with_jacobian:
        return s["z"], s["loss"], s["step"], s["converged"], s["r"], s["J"]
    return s["z"], s["loss"], s["step"], s["converged"]


__all__ = ["levenberg_marquardt"]
