"""The compact Levenberg-Marquardt of fit/solve/lm.py against closed forms and numpy."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.fit.solve.lm import levenberg_marquardt


def rosenbrock(z, data):
    a, b = data
    return jnp.stack([b * (z[1] - z[0] ** 2), a - z[0]])


def test_rosenbrock_reaches_the_minimum():
    z, loss, steps, ok = jax.jit(lambda z0: levenberg_marquardt(rosenbrock, z0, (1.0, 10.0)))(jnp.array([-1.2, 1.0]))
    assert bool(ok) and 0 < int(steps) < 100
    np.testing.assert_allclose(np.asarray(z), [1.0, 1.0], atol=1e-7)
    assert float(loss) < 1e-14


def test_linear_least_squares_matches_lstsq():
    rng = np.random.default_rng(0)
    A = rng.standard_normal((40, 5)) * np.array([1.0, 10.0, 1e-2, 3.0, 1e3])  # badly scaled columns
    y = rng.standard_normal(40)
    z, loss, steps, ok = levenberg_marquardt(lambda z, d: d[0] @ z - d[1], jnp.zeros(5), (jnp.asarray(A), jnp.asarray(y)))
    x, res, *_ = np.linalg.lstsq(A, y, rcond=None)
    assert bool(ok)
    np.testing.assert_allclose(np.asarray(z), x, rtol=1e-7, atol=1e-10)
    assert float(loss) == pytest.approx(0.5 * res[0], rel=1e-10)


def test_nan_region_only_shortens_steps():
    """Residuals that are NaN beyond z = 1.5 (a model outside its domain): the trial points there
    are rejected, the solve still converges to the minimum at z = 1.4 inside."""

    def fn(z, d):
        r = jnp.stack([z[0] - 1.4, 0.1 * (z[0] - 1.4) ** 3])
        return jnp.where(z[0] > 1.5, jnp.nan, r)

    z, loss, steps, ok = levenberg_marquardt(fn, jnp.array([-30.0]), None)
    assert bool(ok)
    assert float(z[0]) == pytest.approx(1.4, abs=1e-8)


def test_step_limit_and_start_at_the_optimum():
    z, _, steps, ok = levenberg_marquardt(rosenbrock, jnp.array([-1.2, 1.0]), (1.0, 100.0), max_steps=3)
    assert int(steps) == 3 and not bool(ok)
    # started on the optimum (as bootstrap refits are): converged, not stuck rejecting rounding
    z, loss, steps, ok = levenberg_marquardt(rosenbrock, jnp.array([1.0, 1.0]), (1.0, 100.0))
    assert bool(ok) and int(steps) <= 2 and float(loss) == 0.0


def test_vmapped_starts_agree_with_single_solves():
    starts = jnp.array([[-1.2, 1.0], [2.0, -1.0], [0.5, 0.5]])
    batched = jax.vmap(lambda z0: levenberg_marquardt(rosenbrock, z0, (1.0, 10.0)))(starts)
    for k in range(3):
        single = levenberg_marquardt(rosenbrock, starts[k], (1.0, 10.0))
        np.testing.assert_allclose(np.asarray(batched[0][k]), np.asarray(single[0]), atol=1e-12)
        assert bool(batched[3][k]) and int(batched[2][k]) == int(single[2])


def _exponential(z, d):
    t, y = d
    return z[0] * jnp.exp(-z[1] * t) - y


def test_loss_tol_stops_within_the_tolerance_of_the_optimum():
    """loss_tol: the fit stops once the Gauss-Newton decrement (the loss an undamped step would still
    remove) is below the tolerance; the loss is then within about that of the tight optimum, in
    fewer iterations. Off (None), the step criterion alone decides, as before."""
    t = jnp.linspace(0.0, 4.0, 30)
    rng = np.random.default_rng(3)
    y = 2.0 * jnp.exp(-0.7 * t) + 0.01 * jnp.asarray(rng.standard_normal(30))
    d = (t, y / 0.01)  # whitened: residuals in units of the noise
    fn = lambda z, d: _exponential(z, (d[0], d[1] * 0.01)) / 0.01  # noqa: E731
    z0 = jnp.array([0.5, 3.0])
    zt, lt, st, okt = levenberg_marquardt(fn, z0, d, rtol=1e-12, atol=1e-14)
    for tol in (0.5, 0.005):
        z, loss, steps, ok = levenberg_marquardt(fn, z0, d, rtol=1e-12, atol=1e-14, loss_tol=tol)
        assert bool(ok) and int(steps) < int(st)
        # the decrement bounds the remaining loss of the quadratic model; allow its curvature a factor 2
        assert 0.0 <= float(loss) - float(lt) <= 2.0 * tol
    # a tolerance no step can beat: stops at the first iteration, converged
    _, _, steps, ok = levenberg_marquardt(fn, z0, d, loss_tol=1e12)
    assert bool(ok) and int(steps) == 1


def test_fit_checks_loss_tol():
    from appearance_jax.fit import fit
    from appearance_jax.fit.tables import Table

    tab = Table(theta_i=np.zeros(1), phi_i=np.zeros(1), theta_o=np.zeros(1), phi_o=np.zeros(1),
                values=np.ones((1, 3)), mask=np.ones((1, 3), bool))
    with pytest.raises(ValueError, match="loss_tol = -1"):
        fit("lambert", tab, loss_tol=-1)
    with pytest.raises(ValueError, match="only solver='lm'"):
        fit("lambert", tab, loss_tol=0.1, solver="gn")



def test_loss_tol_is_safe_in_a_curved_valley():
    """The decrement test does not stop a crawl along a curved valley early (Rosenbrock, b = 1000:
    damped steps there each gain little, which a test on the step's gain would take for
    convergence): with zero residual at the optimum the decrement is the whole loss."""
    with jax.enable_x64(True):
        z, loss, steps, ok = levenberg_marquardt(rosenbrock, jnp.array([-1.2, 1.0]), (1.0, 1000.0), loss_tol=0.025,
                                                 max_steps=400)
        assert bool(ok) and float(loss) <= 0.025 + 1e-12


@pytest.mark.parametrize("max_steps", [0, 1, 3, 400])
def test_with_jacobian_returns_r_and_j_at_the_returned_point(max_steps):
    """with_jacobian: the same solve (z, loss, steps, converged bitwise), and r, J at the returned
    z exactly (jacfwd there), also when the loop stops on an accepted step (converged, or at the
    step limit), and under vmap (starts ending at different steps)."""
    data = (1.0, 10.0)
    z0s = jnp.array([[-1.2, 1.0], [0.9, 0.8], [1.0, 1.0]])
    plain = jax.jit(jax.vmap(lambda z: levenberg_marquardt(rosenbrock, z, data, max_steps=max_steps)))(z0s)
    full = jax.jit(jax.vmap(lambda z: levenberg_marquardt(rosenbrock, z, data, max_steps=max_steps,
                                                          with_jacobian=True)))(z0s)
    for a, b in zip(plain, full[:4]):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    z = np.asarray(full[0])
    for k in range(z0s.shape[0]):
        np.testing.assert_allclose(np.asarray(full[4][k]), np.asarray(rosenbrock(jnp.asarray(z[k]), data)),
                                   rtol=1e-12, atol=1e-18)  # r ~ 1e-14 at the optimum: rounding in z1 - z0^2
        np.testing.assert_allclose(np.asarray(full[5][k]), np.asarray(jax.jacfwd(rosenbrock)(jnp.asarray(z[k]), data)),
                                   rtol=1e-14, atol=1e-14)
    if max_steps == 400:
        assert np.all(np.asarray(full[3]))
