"""Test-wide settings: float64 everywhere (DESIGN.md: tests that need it run in x64)."""

import jax

jax.config.update("jax_enable_x64", True)
