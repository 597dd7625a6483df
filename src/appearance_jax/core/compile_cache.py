"""A persistent compilation cache for fits and the command line (JAX's, on disk).

A fit is one XLA program; compiling it takes seconds (tens for a coated or Monte Carlo model),
far longer than the solve. JAX can keep compiled programs on disk and reuse them in a later
process when the same program (same model, free parameters, metric, table shape) is compiled
again. :func:`appearance_jax.fit.fit`, :func:`~appearance_jax.fit.fit_batch` and the
``appearance-jax`` command turn that cache on by default (:func:`ensure`); the first run of a
fit compiles and writes the cache, a re-run (another table of the same shape, another start,
the same command again) loads it. Measured figures: benchmarks/README.md ("Compilation").

Where: ``$APPEARANCE_JAX_COMPILE_CACHE`` if set to a directory, else
``$XDG_CACHE_HOME/appearance-jax/xla`` (``~/.cache/appearance-jax/xla``). At most
:data:`MAX_BYTES` on disk when the ``filelock`` package is installed (JAX then evicts the least
recently used entries); without it the directory is not size-limited (a fit writes a few MB).

Turning it off: ``APPEARANCE_JAX_COMPILE_CACHE=off`` (or ``0``, ``false``, ``no``) in the
environment, :func:`disable` in Python, or ``--no-compile-cache`` on the command line. A cache
directory the user configured for JAX itself (``jax_compilation_cache_dir``, e.g. through
``JAX_COMPILATION_CACHE_DIR``) is respected and left alone.

JAX compresses each entry with zstd when the ``zstandard`` package (a dependency) is importable,
else with zlib. The README's fit writes ~22 MB of executables (its coat tables are constants in
every program): zlib took 2.0 s to compress them and 0.17 s to read them back, zstd 0.26 s and
0.07 s; the cold run went 10.7-11.3 s -> 8.2-9.0 s (benchmarks/README.md).

Entries are keyed by JAX on the program, the compiler options and the jax/jaxlib version, so a
stale entry is never used for a different program; deleting the directory is always safe.

The fit's own programs are also kept there, loaded and keyed by what they were traced from
(:mod:`~appearance_jax.core.program_store`, subdirectory ``programs``): the same switches turn it
off.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import jax

#: the environment variable naming the cache directory, or turning the cache off
ENV_VAR = "APPEARANCE_JAX_COMPILE_CACHE"
#: values of :data:`ENV_VAR` that turn the cache off (case-insensitive)
OFF_VALUES = ("0", "off", "false", "no", "none")
#: programs that compile faster than this [s] are not written. 0: every program, the small eager
#: ones of a fit's report too (~90 of 10-30 ms each; reading one back costs ~1 ms): measured on the
#: README's fit, a warm run took 4.6-5.0 s with 0 against 6.2 s with 0.2
MIN_COMPILE_TIME_S = 0.0
#: size limit of the default cache directory [bytes]
MAX_BYTES = 2 * 1024**3

_state = {"decided": False, "dir": None, "disabled": False}


def default_dir() -> Path:
    """``$XDG_CACHE_HOME/appearance-jax/xla``, else ``~/.cache/appearance-jax/xla``."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "appearance-jax" / "xla"


def _has_filelock() -> bool:
    import importlib.util

    return importlib.util.find_spec("filelock") is not None


def _reset_jax_cache_state():
    # JAX decides once per process whether the cache is used, at its first compilation; a
    # program compiled before this call (an eager op) would otherwise have fixed "unused".
    from jax.experimental.compilation_cache import compilation_cache as cc

    cc.reset_cache()


def enable(path: str | os.PathLike | None = None) -> str:
    """Turn the persistent cache on at ``path`` (default: :func:`default_dir`); returns the
    directory. Creates it if needed; raises ``OSError`` naming it when it cannot be created."""
    path = Path(path) if path is not None else default_dir()
    path.mkdir(parents=True, exist_ok=True)
    if not os.access(path, os.W_OK):
        raise OSError(f"compilation cache directory {str(path)!r} is not writable (set {ENV_VAR}=off "
                      "or to another directory)")
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_TIME_S)
    if _has_filelock():  # JAX's size limit needs it (else every cache read fails with a warning)
        jax.config.update("jax_compilation_cache_max_size", MAX_BYTES)
    _reset_jax_cache_state()
    _state.update(decided=True, dir=str(path), disabled=False)
    return str(path)


def disable() -> None:
    """Turn off the cache that this module turned on, and keep :func:`ensure` from turning it on
    again in this process (a directory configured for JAX by the user is left as it is)."""
    if _state["dir"] is not None and jax.config.jax_compilation_cache_dir == _state["dir"]:
        jax.config.update("jax_compilation_cache_dir", None)
        _reset_jax_cache_state()
    _state.update(decided=True, dir=None, disabled=True)


def ensure() -> str | None:
    """The default: turn the cache on once per process unless it was turned off (``ENV_VAR``,
    :func:`disable`) or the user configured JAX's own cache directory. Returns the directory in
    use, or None. Cheap after the first call; a cache directory that cannot be created only
    leaves the cache off (a fit must not fail for it)."""
    if _state["decided"]:
        return None if _state["disabled"] else (_state["dir"] or jax.config.jax_compilation_cache_dir)
    _state["decided"] = True
    own = jax.config.jax_compilation_cache_dir
    if own:
        _state["dir"] = None
        return own
    env = os.environ.get(ENV_VAR)
    if env is not None and env.strip().lower() in OFF_VALUES:
        _state["disabled"] = True
        return None
    try:
        return enable(env.strip() if env and env.strip() else None)
    except OSError:
        _state["disabled"] = True
        return None


@contextlib.contextmanager
def bypassed():
    """JAX's persistent cache neither read nor written by what compiles inside (this process).

    For a program that :mod:`~appearance_jax.core.program_store` will write: an executable JAX
    loaded from its cache cannot be written out again whole (XLA:CPU keeps no object code of a
    loaded program; the copy fails with "Function ... not found" when it runs)."""
    if not jax.config.jax_enable_compilation_cache:
        yield
        return
    jax.config.update("jax_enable_compilation_cache", False)
    _reset_jax_cache_state()
    try:
        yield
    finally:
        jax.config.update("jax_enable_compilation_cache", True)
        _reset_jax_cache_state()


#: compiler options of the library's own fit programs on a CPU (:func:`compile_lowered`)
CPU_FIT_OPTIONS = {"xla_cpu_use_fusion_emitters": False}


def compile_lowered(lowered):
    """``lowered.compile()`` for the library's own fit programs (the solve, a batch, the fitted
    values, the report's model curves): on a CPU with XLA:CPU's older IR emitters
    (:data:`CPU_FIT_OPTIONS`), which compile the README fit's solve ~30 % faster (2.95-3.05 ->
    2.05-2.10 s, same run time, its loss equal to 1e-16 relative; benchmarks/README.md). Only these
    programs: nothing else the user compiles changes. An XLA that no longer knows the option
    compiles with its defaults."""
    if jax.default_backend() == "cpu":
        try:
            return lowered.compile(compiler_options=CPU_FIT_OPTIONS)
        except jax.errors.JaxRuntimeError as e:
            if "compile option" not in str(e):
                raise
    return lowered.compile()


def own_dir() -> str | None:
    """The directory this module turned the cache on at, or None (off, or JAX's own directory)."""
    return None if _state["disabled"] else _state["dir"]


def active_dir() -> str | None:
    """The directory JAX writes compiled programs to now, or None."""
    return jax.config.jax_compilation_cache_dir or None


__all__ = ["ENV_VAR", "OFF_VALUES", "MIN_COMPILE_TIME_S", "MAX_BYTES", "default_dir", "enable", "disable", "ensure",
           "own_dir", "active_dir", "bypassed",
           "CPU_FIT_OPTIONS", "compile_lowered"]
