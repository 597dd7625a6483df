"""core.special.atan2 (the vectorisable atan2 behind safe_asin / safe_acos / safe_atan2) against numpy's libm."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.core.special import atan2, safe_acos, safe_asin, safe_atan2


@pytest.mark.parametrize("dtype, ulp", [(np.float64, 4), (np.float32, 6)])
def test_atan2_matches_libm_to_a_few_ulp(dtype, ulp):
    rng = np.random.default_rng(0)
    n = 100_000
    y = (rng.normal(size=n) * np.exp(rng.uniform(-20, 20, n))).astype(dtype)
    x = (rng.normal(size=n) * np.exp(rng.uniform(-20, 20, n))).astype(dtype)
    got = np.asarray(atan2(jnp.asarray(y), jnp.asarray(x)))
    assert got.dtype == dtype
    ref = np.arctan2(y.astype(np.float64), x.astype(np.float64))
    assert np.max(np.abs(got - ref) / np.spacing(np.abs(ref).astype(dtype)).astype(np.float64)) <= ulp
    s = np.concatenate([rng.uniform(-1, 1, n), [1.0, -1.0, 0.0, 1 - 1e-16, -1 + 1e-16]]).astype(dtype)
    for fn, ref_fn in ((safe_asin, np.arcsin), (safe_acos, np.arccos)):
        got = np.asarray(fn(jnp.asarray(s))).astype(np.float64)
        ref = ref_fn(s.astype(np.float64))
        assert np.max(np.abs(got - ref) / np.spacing(np.maximum(np.abs(ref), 1e-30).astype(dtype))) <= ulp


def test_atan2_quadrants_signed_zeros_and_origin():
    cases = [(0.0, 1.0), (-0.0, -1.0), (0.0, -1.0), (1.0, 0.0), (-1.0, 0.0), (1.0, -0.0), (-1.0, -1.0),
             (1.0, 1.0), (1.0, -1.0), (-0.0, 0.0), (3.0, -1e-300), (1e-300, -3.0)]
    for y, x in cases:
        assert float(atan2(y, x)) == pytest.approx(np.arctan2(y, x), rel=1e-15, abs=0), (y, x)
    assert float(safe_atan2(0.0, 0.0)) == 0.0
    assert float(safe_asin(1.5)) == pytest.approx(np.pi / 2) and float(safe_acos(-2.0)) == pytest.approx(np.pi)


def test_atan2_gradients():
    g = jax.grad(lambda y, x: atan2(y, x), argnums=(0, 1))(0.3, -0.7)
    assert np.allclose(g, (-0.7 / 0.58, -0.3 / 0.58), rtol=1e-14)
    assert np.allclose(jax.grad(lambda y, x: safe_atan2(y, x), argnums=(0, 1))(0.0, 0.0), 0.0)  # finite at the origin
    assert float(jax.grad(safe_asin)(0.3)) == pytest.approx(1 / np.sqrt(1 - 0.09), rel=1e-14)
    assert np.isfinite(float(jax.grad(safe_asin)(1.0))) and np.isfinite(float(jax.grad(safe_acos)(-1.0)))
