"""Test-wide settings: float64 everywhere (DESIGN.md: tests that need it run in x64), a bound
on the memory mappings that compiled XLA executables hold, one persistent compilation cache
shared by the workers of a run, and XLA:CPU's faster-compiling legacy fusion emitters."""

import gc
import os
import shutil
import subprocess
import sys
import tempfile

# XLA:CPU's legacy fusion emitters compile the suite's programs ~25 % faster, and its Monte Carlo
# tests run no slower (docs/testing.md, "Legacy fusion emitters"); values agree with the default
# emitters to a few ulps. Set before JAX starts its backend, by the controller (the workers inherit
# it), and only where this XLA knows the flag (an unknown one aborts every process). The
# special-directions check compiles with the default emitters, the ones users get.
# APPEARANCE_JAX_TEST_XLA_DEFAULT=1 runs the whole suite with XLA's defaults.
LEGACY_EMITTERS = "--xla_cpu_use_fusion_emitters=false"


def _xla_knows(flag):
    env = dict(os.environ, XLA_FLAGS=f"{os.environ.get('XLA_FLAGS', '')} {flag}".strip(), JAX_PLATFORMS="cpu")
    try:
        return subprocess.run([sys.executable, "-c", "import jax.numpy as j; j.zeros(1).block_until_ready()"],
                              env=env, capture_output=True, timeout=120).returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False


if os.environ.get("APPEARANCE_JAX_TEST_XLA_DEFAULT") != "1" and LEGACY_EMITTERS not in os.environ.get("XLA_FLAGS", ""):
    if _xla_knows(LEGACY_EMITTERS):
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {LEGACY_EMITTERS}".strip()
    else:  # the workers inherit the decision instead of probing again
        os.environ["APPEARANCE_JAX_TEST_XLA_DEFAULT"] = "1"

import jax  # noqa: E402
import pytest  # noqa: E402


@pytest.fixture(scope="session")
def user_compiler_options():
    """``compiler_options`` for a ``jax.jit`` that must compile as users' programs do: the default
    fusion emitters when this run uses the legacy ones, else None."""
    return {"xla_cpu_use_fusion_emitters": True} if LEGACY_EMITTERS in os.environ.get("XLA_FLAGS", "") else None

jax.config.update("jax_enable_x64", True)

# One on-disk compilation cache per test run (appearance_jax.core.compile_cache), shared by the
# pytest-xdist workers: a program compiled by one worker (a module fixture's fit, a model's
# eval, the README's fit run in a subprocess) is loaded by the other instead of compiled again.
# The controller creates it before the workers start (they inherit the environment) and removes
# it at the end, so no run reads another run's programs. A directory given in the environment
# (or APPEARANCE_JAX_COMPILE_CACHE=off) is used as it is and kept.
_RUN_CACHE = None
if "APPEARANCE_JAX_COMPILE_CACHE" not in os.environ:
    _RUN_CACHE = tempfile.mkdtemp(prefix="appearance-jax-test-xla-")
    os.environ["APPEARANCE_JAX_COMPILE_CACHE"] = _RUN_CACHE

from appearance_jax.core import compile_cache  # noqa: E402
from appearance_jax.fit.solve import reuse  # noqa: E402

compile_cache.ensure()
# only programs that take a while: the suite compiles thousands of small ones, rarely twice
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)


def pytest_unconfigure(config):
    if _RUN_CACHE is not None and not hasattr(config, "workerinput"):  # the controller (or a plain run)
        shutil.rmtree(_RUN_CACHE, ignore_errors=True)

# Every XLA:CPU executable JIT-compiled by LLVM keeps ~3 memory mappings alive while JAX
# caches it. A long-lived pytest-xdist worker compiles tens of thousands of them (tests/bsdf
# alone leaves ~28,000 mappings), and once a process reaches the kernel's vm.max_map_count
# (65,530 by default) the next mmap inside LLVM fails and the worker dies with a segfault in
# backend_compile (seen in CI). Clearing JAX's caches when the count gets high releases them.
MAX_MAPPINGS = 30_000


def _mapping_count():
    try:
        with open("/proc/self/maps", "rb") as f:
            return f.read().count(b"\n")
    except OSError:  # not Linux: no such limit to guard against
        return 0


@pytest.fixture(autouse=True)
def _bound_compiled_executables():
    yield
    if _mapping_count() > MAX_MAPPINGS:
        jax.clear_caches()
        reuse.clear()  # the fitters' kept programs (fit.solve.reuse) hold executables too
        gc.collect()
