"""The persistent compilation cache (core.compile_cache): on by default for fits and the CLI,
off by environment, function or flag, and JAX's own setting respected."""

import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import pytest

from appearance_jax.core import compile_cache as cc


@pytest.fixture
def fresh(monkeypatch):
    """Undecided module state and no JAX cache directory; both restored afterwards."""
    saved = dict(cc._state)
    saved_dir = jax.config.jax_compilation_cache_dir
    saved_min = jax.config.jax_persistent_cache_min_compile_time_secs
    jax.config.update("jax_compilation_cache_dir", None)
    cc._state.update(decided=False, dir=None, disabled=False)
    monkeypatch.delenv(cc.ENV_VAR, raising=False)
    yield
    cc._state.clear()
    cc._state.update(saved)
    jax.config.update("jax_compilation_cache_dir", saved_dir)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", saved_min)
    cc._reset_jax_cache_state()


def test_default_directory_follows_xdg(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert cc.default_dir() == tmp_path / "appearance-jax" / "xla"


def test_ensure_turns_on_the_env_directory_and_writes_entries(fresh, monkeypatch, tmp_path):
    monkeypatch.setenv(cc.ENV_VAR, str(tmp_path / "xla"))
    assert cc.ensure() == str(tmp_path / "xla")
    assert cc.active_dir() == str(tmp_path / "xla")
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.jit(lambda x: jnp.cos(x) * 3.25 + 0.125)(jnp.arange(7.0)).block_until_ready()
    entries = [f for f in (tmp_path / "xla").iterdir() if f.name.endswith("-cache")]
    assert entries, "no compiled program was written"
    # compressed with zstd (the zstandard dependency), not zlib: ~8x faster on the README fit's executables
    assert all(f.read_bytes()[:4] == b"\x28\xb5\x2f\xfd" for f in entries), [f.read_bytes()[:4] for f in entries]
    assert cc.ensure() == str(tmp_path / "xla")  # idempotent


@pytest.mark.parametrize("value", ["off", "0", "FALSE", "no"])
def test_environment_turns_it_off(fresh, monkeypatch, value):
    monkeypatch.setenv(cc.ENV_VAR, value)
    assert cc.ensure() is None
    assert cc.active_dir() is None


def test_disable_wins_over_ensure(fresh, monkeypatch, tmp_path):
    monkeypatch.setenv(cc.ENV_VAR, str(tmp_path))
    cc.enable(tmp_path)
    cc.disable()
    assert cc.active_dir() is None
    assert cc.ensure() is None


def test_users_own_jax_directory_is_left_alone(fresh, monkeypatch, tmp_path):
    jax.config.update("jax_compilation_cache_dir", str(tmp_path / "mine"))
    monkeypatch.setenv(cc.ENV_VAR, str(tmp_path / "ours"))
    assert cc.ensure() == str(tmp_path / "mine")
    cc.disable()  # only undoes what this module set
    assert cc.active_dir() == str(tmp_path / "mine")


def test_unwritable_directory_is_a_clear_error_but_not_fatal_for_ensure(fresh, monkeypatch, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    with pytest.raises(OSError):
        cc.enable(blocker / "xla")
    monkeypatch.setenv(cc.ENV_VAR, str(blocker / "xla"))
    assert cc.ensure() is None  # a fit must not fail because the cache cannot be created


def test_cli_flag_turns_it_off(tmp_path):
    # a fresh process: the flag must win over the environment's directory
    code = ("import sys; from appearance_jax.cli import main; from appearance_jax.core import compile_cache as cc; "
            "rc = main(['models', 'lambert', '--no-compile-cache']); print('DIR', cc.active_dir()); sys.exit(rc)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={**os.environ, cc.ENV_VAR: str(tmp_path / "xla")})
    assert out.returncode == 0, out.stderr
    assert "DIR None" in out.stdout
    code = code.replace(", '--no-compile-cache'", "")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={**os.environ, cc.ENV_VAR: str(tmp_path / "xla")})
    assert out.returncode == 0, out.stderr
    assert f"DIR {tmp_path / 'xla'}" in out.stdout


def test_fit_programs_compile_with_the_cpu_options_and_fall_back():
    f = jax.jit(lambda x: jnp.sin(x) * 2.5)
    x = jnp.arange(4.0)
    assert bool(jnp.all(cc.compile_lowered(f.lower(x))(x) == f(x)))

    class Lowered:  # records what compile_lowered asks for; the first XLA does not know the option
        def __init__(self, known):
            self.known, self.calls = known, []

        def compile(self, compiler_options=None):
            self.calls.append(compiler_options)
            if compiler_options and not self.known:
                raise jax.errors.JaxRuntimeError("INVALID_ARGUMENT: No such compile option: 'x'")
            return "compiled"

    on_cpu = jax.default_backend() == "cpu"
    known = Lowered(known=True)
    assert cc.compile_lowered(known) == "compiled"
    assert known.calls == ([cc.CPU_FIT_OPTIONS] if on_cpu else [None])
    unknown = Lowered(known=False)
    assert cc.compile_lowered(unknown) == "compiled"  # the defaults, not an error
    assert unknown.calls == ([cc.CPU_FIT_OPTIONS, None] if on_cpu else [None])
