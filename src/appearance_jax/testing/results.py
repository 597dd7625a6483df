"""Result records of the property checks and the statistics they share.

Every check returns a small frozen dataclass with the numbers it measured, a ``passed``
flag and a readable ``message``; ``result.raise_if_failed()`` (what the ``assert_*``
twins call) raises ``AssertionError(message)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist

import jax
import jax.numpy as jnp


@dataclass(frozen=True)
class CheckResult:
    """Base of all results: which check, whether it passed, and why (one readable message)."""

    check: str
    passed: bool
    message: str

    def raise_if_failed(self) -> "CheckResult":
        if not self.passed:
            raise AssertionError(self.message)
        return self

    def __str__(self) -> str:
        return self.message


def sidak(significance: float, n_tests: int) -> float:
    """Per-test significance so that ``n_tests`` independent tests have family-wise ``significance``.

    ``1 - (1 - a)^(1/m)``, computed with log1p/expm1 so tiny values keep their digits.
    """
    n_tests = max(int(n_tests), 1)
    return -math.expm1(math.log1p(-significance) / n_tests)


def z_threshold(significance: float, n_comparisons: int = 1) -> float:
    """Two-sided normal quantile k with P(|Z| > k) = the Sidak-corrected per-comparison level.

    A difference ``|a - b| <= k * standard_error`` then fails by chance with probability
    at most ``significance`` over all ``n_comparisons`` (Gaussian approximation of the
    estimator, CLT).
    """
    a = sidak(significance, n_comparisons)
    return NormalDist().inv_cdf(1.0 - 0.5 * a)


def float_dtype():
    """The default float dtype (float64 when jax_enable_x64 is on)."""
    return jnp.result_type(float)


def is_x64() -> bool:
    return bool(jax.config.jax_enable_x64)


def default_rtol() -> float:
    """Relative tolerance for identities that hold exactly up to rounding."""
    return 1e-6 if is_x64() else 1e-3


def default_atol() -> float:
    """Absolute floor (values near 0) for identities that hold exactly up to rounding."""
    return 1e-10 if is_x64() else 1e-5


def fmt(x) -> str:
    return f"{float(x):.6g}"
