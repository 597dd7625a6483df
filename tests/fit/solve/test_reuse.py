"""fit.solve.reuse: compiled fit programs reused within a process.

A reused program must give exactly what a fresh one gives (every result below is compared with a
fit after ``reuse.clear()``), and anything the traced code depends on besides its array
arguments must select another program: fixed values, metric, absolute vs relative sigma,
solver settings, the model.
"""

import numpy as np

from appearance_jax import registry
from appearance_jax.fit.solve import fit, reuse
from appearance_jax.fit.solve.problem import build_problem
from appearance_jax.fit.tables.grids import in_plane_angles
from appearance_jax.fit.tables.table import Table

MODEL = registry.get("rough_conductor")


def table(alpha, seed, sigma=True):
    ti, to = in_plane_angles([0, 30, 60], np.arange(-80, 81, 10))
    t = Table.in_plane(ti, to, np.ones((ti.size, 3)), source=f"synthetic alpha {alpha}")
    wi, wo = t.directions()
    f = np.asarray(MODEL.eval(MODEL.Params(alpha=alpha, specular_reflectance=(0.9, 0.8, 0.7)), wi, wo), np.float64)
    f = f * (1 + 0.02 * np.random.default_rng(seed).standard_normal(f.shape))
    return t.replace(values=f, sigma=0.02 * f if sigma else None, mask=np.ones(f.shape, bool))


FIX = {"eta": None, "k": None}


def run(t, **kw):
    kw = {"fix": FIX, **kw}
    return fit(MODEL, t, **kw)


def fresh(t, **kw):
    reuse.clear()
    return run(t, **kw)


def same(a, b):
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.sigma, b.sigma)
    np.testing.assert_array_equal(a.fitted, b.fitted)
    assert a.loss == b.loss and a.iterations == b.iterations


def test_refit_and_another_table_of_the_same_shape_reuse_the_solve_and_equal_fresh_fits():
    # one test (was two): the refit of a and the fit of b both reuse a's programs, built once here
    a, b = table(0.2, 0), table(0.35, 1)
    first = fresh(a)
    kept = len(reuse._CACHE)
    again = run(a)
    assert kept > 0 and len(reuse._CACHE) == kept  # every program taken from the cache, none built
    same(again, first)
    reused = run(b)
    assert len(reuse._CACHE) == kept  # b's fit built no program
    same(reused, fresh(b))
    assert abs(reused.x[0] - 0.35) < 0.05  # and it is b's fit, not a's


CHANGES = {"fixed value": dict(fix={"eta": 1.3, "k": None}), "metric": dict(metric="cos_log"),
           "max_steps": dict(max_steps=3), "sigma kind": dict(use_sigma=False)}


def test_what_the_trace_depends_on_selects_another_program():
    """Every change is fitted while the base fit's programs (and those of the changes before it)
    are kept, then compared with a fit of its own after ``reuse.clear()``. One test (was one per
    change): the base fit is built once instead of once per change."""
    t = table(0.2, 0)
    base = fresh(t)
    changed = {name: run(t, **change) for name, change in CHANGES.items()}
    for name, change in CHANGES.items():
        same(changed[name], fresh(t, **change))
        assert not (changed[name].loss == base.loss and np.array_equal(changed[name].sigma, base.sigma)), name


def test_problem_key_covers_fixed_values_and_sigma_kind():
    t = table(0.2, 0)
    k = lambda **kw: reuse.problem_key(build_problem(MODEL, t, **kw))  # noqa: E731
    assert k(fix=FIX) == k(fix=FIX)
    assert k(fix=FIX) != k(fix={"eta": 1.3, "k": None})
    assert k(fix=FIX) != k(fix=FIX, use_sigma=False)
    assert k(fix=FIX) != k(fix=FIX, metric="relative")
    assert reuse.problem_key(build_problem(MODEL, t, fix=FIX, model_kwargs={"x": [1]})) is None  # unhashable


def test_fit_batch_reuses_its_program_and_equals_a_fresh_batch():
    from appearance_jax.fit.solve import fit_batch

    t = table(0.2, 0)
    values = np.stack([table(0.2, 0).values, table(0.3, 1).values])
    other = np.stack([table(0.25, 2).values, table(0.15, 3).values])
    reuse.clear()
    fit_batch(MODEL, t, values, fix=FIX)
    kept = len(reuse._CACHE)
    again = fit_batch(MODEL, t, other, fix=FIX)
    assert kept > 0 and len(reuse._CACHE) == kept  # the second batch built no program
    reuse.clear()
    ref = fit_batch(MODEL, t, other, fix=FIX)
    for name in ("x", "sigma", "loss", "iterations"):
        np.testing.assert_array_equal(getattr(again, name), getattr(ref, name))
    assert abs(again.x[0, 0] - 0.25) < 0.05 and abs(again.x[1, 0] - 0.15) < 0.05  # the new tables' fits
