"""Test-wide settings: float64 everywhere (DESIGN.md: tests that need it run in x64), and a
bound on the memory mappings that compiled XLA executables hold."""

import gc

import jax
import pytest

jax.config.update("jax_enable_x64", True)

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
        gc.collect()
