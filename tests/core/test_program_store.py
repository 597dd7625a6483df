"""core.program_store: fit programs kept on disk for later processes.

A stored program must give bit for bit what a freshly compiled one gives, in a new process,
including after JAX's own cache held the program (an executable JAX loaded cannot be written out
whole); anything a trace depends on must change the entry's name; and the loader reads only
private files of bounded size, drops a broken entry, and never stores a program that calls back
into the process that traced it.
"""

import copy
import json
import os
import shutil
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import registry
from appearance_jax.core import compile_cache, program_store
from appearance_jax.fit.solve import reuse, solvers
from appearance_jax.fit.solve.problem import build_problem
from appearance_jax.fit.tables.grids import in_plane_angles
from appearance_jax.fit.tables.table import Table

MODEL = registry.get("rough_conductor")

# a fit in a fresh process: the table is synthetic, the model's Fresnel fixed
SCRIPT = r"""
import json, sys
import numpy as np
from appearance_jax import registry
from appearance_jax.core import program_store
from appearance_jax.fit.solve import fit
from appearance_jax.fit.tables.grids import in_plane_angles
from appearance_jax.fit.tables.table import Table
m = registry.get("rough_conductor")
ti, to = in_plane_angles([0, 30, 60], np.arange(-80, 81, 10))
t = Table.in_plane(ti, to, np.ones((ti.size, 3)), source="synthetic")
wi, wo = t.directions()
f = np.asarray(m.eval(m.Params(alpha=0.3, specular_reflectance=(0.9, 0.8, 0.7)), wi, wo), np.float64)
f = f * (1 + 0.02 * np.random.default_rng(1).standard_normal(f.shape))
r = fit(m, t.replace(values=f, sigma=0.02 * f, mask=np.ones(f.shape, bool)), fix={"eta": None, "k": None})
print(json.dumps(dict(x=r.x.tolist(), sigma=r.sigma.tolist(), fitted=r.fitted.ravel().tolist(), loss=r.loss,
                      steps=r.iterations, stats=program_store.stats())))
"""


def _fit_in_process(cache):
    env = dict(os.environ, APPEARANCE_JAX_COMPILE_CACHE=str(cache))
    out = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_stored_solve_runs_in_a_new_process_and_equals_the_compiled_one(tmp_path):
    cache = tmp_path / "xla"
    # two programs: the solve (with the covariances) and the fitted values
    a = _fit_in_process(cache)  # compiles, writes JAX's cache and the store
    assert a["stats"]["saved"] == 2 and a["stats"]["loaded"] == 0, a["stats"]
    b = _fit_in_process(cache)  # loads the stored programs: no trace, no compile
    assert b["stats"]["loaded"] == 2 and b["stats"]["saved"] == 0, b["stats"]
    # without the store, JAX's cache holds the program: the store must not copy JAX's loaded
    # executable (its object code is gone: "Function ... not found" when it runs) but compile it
    shutil.rmtree(cache / "programs")
    c = _fit_in_process(cache)
    assert c["stats"]["saved"] == 2, c["stats"]
    d = _fit_in_process(cache)
    assert d["stats"]["loaded"] == 2, d["stats"]
    for other in (b, c, d):
        for k in ("x", "sigma", "fitted", "loss", "steps"):
            assert other[k] == a[k], k


def _table(n_out=17):
    ti, to = in_plane_angles([0, 30, 60], np.linspace(-80, 80, n_out))
    t = Table.in_plane(ti, to, np.full((ti.size, 3), 0.3), source="synthetic")
    return t.replace(sigma=np.full((ti.size, 3), 0.01), mask=np.ones((ti.size, 3), bool))


def _name(problem, *settings, args=(np.zeros(2),)):
    return program_store.entry_name("solve", (reuse.disk_key(problem),) + settings, args)


def test_the_entry_name_follows_everything_the_trace_depends_on():
    t = _table()
    base = build_problem(MODEL, t, fix={"eta": None, "k": None})
    name = _name(base, "lm", 1e-8)
    assert name == _name(build_problem(MODEL, t, fix={"eta": None, "k": None}), "lm", 1e-8)  # by content
    others = [
        _name(build_problem(MODEL, t, fix={"eta": 1.2, "k": None}), "lm", 1e-8),  # a fixed value
        _name(build_problem(MODEL, t, fix={"eta": None, "k": None, "alpha": None}), "lm", 1e-8),  # free fields
        _name(build_problem(MODEL, t, fix={"eta": None, "k": None}, metric="cos_log"), "lm", 1e-8),  # metric
        _name(build_problem(MODEL, t, fix={"eta": None, "k": None}, use_sigma=False), "lm", 1e-8),  # sigma scale
        _name(base, "lm", 1e-7),  # a solver setting
        _name(base, "lm", 1e-8, args=(np.zeros(3),)),  # a shape
        _name(base, "lm", 1e-8, args=(np.zeros(2, np.float32),)),  # a dtype
    ]
    assert name is not None and len({name, *others}) == len(others) + 1
    # the environment: jax settings (x64 here) are part of it
    with jax.enable_x64(False):
        assert _name(base, "lm", 1e-8) != name


def test_what_has_no_faithful_key_is_not_stored():
    t = _table()
    mine = copy.copy(MODEL)  # not the registry's instance: in memory only
    assert reuse.disk_key(build_problem(mine, t, fix={"eta": None, "k": None})) is None
    assert program_store.entry_name("x", (lambda: 0,), (np.zeros(1),)) is None  # a function
    assert program_store.entry_name("x", (object(),), (np.zeros(1),)) is None


@pytest.fixture
def store(tmp_path, monkeypatch):
    """The store in a directory of its own."""
    monkeypatch.setattr(compile_cache, "own_dir", lambda: str(tmp_path))
    return tmp_path / "programs"


def _tiny():
    x = jnp.arange(5.0)
    return jax.jit(lambda a: jnp.linalg.cholesky(jnp.eye(5) * 2.0 + a[:, None] * a[None, :]).sum()).lower(x).compile(), x


def test_save_load_and_the_loaders_refusals(store, monkeypatch):
    compiled, x = _tiny()
    name = program_store.entry_name("t", ("tiny",), (x,))
    assert program_store.save(name, compiled)
    path = store / name
    loaded = program_store.load(name, (x,))
    assert loaded is not None and float(loaded(x)) == float(compiled(x))
    os.chmod(path, 0o666)  # writable by others: not read, not deleted
    assert program_store.load(name, (x,)) is None and path.exists()
    os.chmod(path, 0o644)
    monkeypatch.setattr(program_store, "MAX_ENTRY_BYTES", 16)  # too large: not read
    assert program_store.load(name, (x,)) is None and path.exists()
    assert not program_store.save(name + "2", compiled)  # and not written
    monkeypatch.undo()
    monkeypatch.setattr(compile_cache, "own_dir", lambda: str(store.parent))
    path.write_bytes(b"not a stored program")  # broken: dropped, and the caller compiles
    rejected = program_store.stats()["rejected"]
    assert program_store.load(name, (x,)) is None and not path.exists()
    assert program_store.stats()["rejected"] == rejected + 1


def test_a_program_with_a_host_callback_is_not_stored(store):
    x = jnp.arange(3.0)
    compiled = jax.jit(lambda a: (jax.debug.callback(lambda v: None, a), a * 2)[1]).lower(x).compile()
    assert not program_store.save("cb.jaxprog", compiled)
    assert not store.exists() or not list(store.iterdir())


def test_the_least_recently_used_entries_go_beyond_the_size_limit(store, monkeypatch):
    compiled, x = _tiny()
    assert program_store.save("a.jaxprog", compiled)
    size = (store / "a.jaxprog").stat().st_size
    monkeypatch.setattr(program_store, "MAX_BYTES", 2 * size + 1)
    os.utime(store / "a.jaxprog", (1, 1))
    assert program_store.save("b.jaxprog", compiled)
    os.utime(store / "b.jaxprog", (2, 2))
    assert program_store.save("c.jaxprog", compiled)
    assert sorted(p.name for p in store.glob("*.jaxprog")) == ["b.jaxprog", "c.jaxprog"]


def test_a_replaced_solve_or_a_progress_printer_is_not_stored(store, monkeypatch):
    t = _table(9)
    wi, wo = t.directions()
    f = np.asarray(MODEL.eval(MODEL.Params(alpha=0.3), wi, wo), np.float64)
    t = t.replace(values=f, sigma=0.01 + 0.02 * f)
    saved = program_store.stats()["saved"]
    own = solvers._solve
    monkeypatch.setattr(solvers, "_solve", lambda *a, **k: own(*a, **k))
    solvers.fit(MODEL, t, fix={"eta": None, "k": None})
    monkeypatch.setattr(solvers, "_solve", own)
    solvers.fit(MODEL, t, fix={"eta": None, "k": None}, verbose=100)
    assert program_store.stats()["saved"] == saved + 1  # only the fitted values' program
    reuse.clear()
    solvers.fit(MODEL, t, fix={"eta": None, "k": None})  # the stock solve is stored
    assert program_store.stats()["saved"] == saved + 2


def test_off_with_the_compilation_cache(monkeypatch):
    monkeypatch.setattr(compile_cache, "own_dir", lambda: None)  # --no-compile-cache, =off, a JAX-configured dir
    assert program_store.directory() is None
    compiled, x = _tiny()
    assert not program_store.save("off.jaxprog", compiled)
    assert program_store.load("off.jaxprog", (x,)) is None


def test_the_reports_model_curves_equal_the_models_eval():
    from appearance_jax.core.frame import in_plane_directions
    from appearance_jax.fit.report.geometry import eval_in_plane

    p = MODEL.Params(alpha=0.27, specular_reflectance=(0.9, 0.8, 0.7))
    ti, to = np.deg2rad(np.full(41, 30.0)), np.deg2rad(np.linspace(-89, 89, 41))
    stored = eval_in_plane(MODEL, p, ti, to)  # a compiled kernel kept by reuse (and on disk with the cache on)
    mine = eval_in_plane(copy.copy(MODEL), p, ti, to)  # not the registry's: the model's own eval
    wi, wo = jax.jit(in_plane_directions)(ti, to)
    np.testing.assert_array_equal(stored, np.asarray(MODEL.eval(p, wi, wo)))
    np.testing.assert_array_equal(stored, mine)


def test_a_stored_batch_equals_the_compiled_one(store):
    from appearance_jax.fit.solve import fit_batch

    t = _table(9)
    wi, wo = t.directions()
    values = np.stack([np.asarray(MODEL.eval(MODEL.Params(alpha=a), wi, wo), np.float64) for a in (0.2, 0.35)])
    kw = dict(fix={"eta": None, "k": None}, devices=jax.devices()[:1])
    reuse.clear()
    saved, loaded = program_store.stats()["saved"], program_store.stats()["loaded"]
    a = fit_batch(MODEL, t, values, **kw)  # compiled and written
    assert program_store.stats()["saved"] == saved + 1
    reuse.clear()
    b = fit_batch(MODEL, t, values, **kw)  # loaded from the store
    assert program_store.stats()["loaded"] == loaded + 1
    for k in ("x", "sigma", "loss", "iterations"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))
    np.testing.assert_allclose(a.x[:, 0], [0.2, 0.35], rtol=1e-6)
