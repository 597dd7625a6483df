"""core.special.beta1p / log_beta1p: B(1 + a, 1 + b), the correlated Smith G2 of refraction pairs.

References: scipy.special.beta where it is exact to ~1e-14 (arguments up to ~30), mpmath (when
installed) over the whole range G2 uses, a, b in [0, 1e8]; derivatives against the digamma form
d/da log B(1 + a, 1 + b) = psi(1 + a) - psi(2 + a + b).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import special as sp

from appearance_jax.core import special
from appearance_jax.microfacet.distribution import _LAMBDA_MAX

EPS32 = float(np.finfo(np.float32).eps)
# jitted: op-by-op dispatch of the ~100 elementwise operations is most of an eager call's time
beta1p, log_beta1p = jax.jit(special.beta1p), jax.jit(special.log_beta1p)


def _pairs(n, hi, seed):
    """(a, b) float64: a uniform block on [0, 4], a log-uniform block on [1e-6, hi], exact 0s."""
    rng = np.random.default_rng(seed)
    k = n // 2
    a = np.concatenate([rng.uniform(0, 4, k), 10 ** rng.uniform(-6, np.log10(hi), n - k), [0.0, 0.0, hi, hi]])
    b = np.concatenate([rng.uniform(0, 4, k), 10 ** rng.uniform(-6, np.log10(hi), n - k), [0.0, hi, 0.0, hi]])
    return a, b


def _mp_beta(a, b):
    mpmath = pytest.importorskip("mpmath")
    with mpmath.workdps(30):
        vals = [mpmath.beta(1 + mpmath.mpf(x), 1 + mpmath.mpf(y)) for x, y in zip(a, b)]
        return np.array([float(v) for v in vals]), np.array([float(mpmath.log(v)) for v in vals])


def test_matches_scipy_float64():
    a, b = _pairs(4000, 30.0, 0)
    ref = sp.beta(1 + a, 1 + b)
    got = np.asarray(beta1p(a, b))
    assert got.dtype == np.float64
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=0)
    np.testing.assert_allclose(np.asarray(log_beta1p(a, b)), np.log(ref), rtol=1e-13, atol=1e-13)


def test_wide_range_float64_against_mpmath():
    """[0, LAMBDA_MAX]: relative error <= 1e-12 where B is a normal float64, and log B to
    1e-13 of its size where B underflows (scipy's own beta is off by ~1e-7 there)."""
    a, b = _pairs(300, _LAMBDA_MAX, 1)
    ref, log_ref = _mp_beta(a, b)
    got, log_got = np.asarray(beta1p(a, b)), np.asarray(log_beta1p(a, b))
    normal = ref > 1e-300
    assert normal.sum() > 150 and (~normal).sum() > 10
    np.testing.assert_allclose(got[normal], ref[normal], rtol=1e-12, atol=0)
    assert np.all(got[~normal] < 1e-300)
    assert np.max(np.abs(log_got - log_ref) / (1 + np.abs(log_ref))) < 1e-13


def test_float32_few_ulp():
    """float32 inputs (exact) against the float64 reference of the same inputs: a few ulp of B,
    times the condition of exp, 1 + |log B|. The three-gammaln form it replaces loses ~|lgamma(a + b)|
    ulp in float32 (log-Gammas cancelling: no correct digit by a + b ~ 1e6)."""
    a, b = _pairs(4000, _LAMBDA_MAX, 2)
    a32, b32 = a.astype(np.float32), b.astype(np.float32)
    small = (a32 < 30) & (b32 < 30)
    ref = sp.beta(1 + a32[small].astype(float), 1 + b32[small].astype(float))
    got = np.asarray(beta1p(jnp.asarray(a32[small]), jnp.asarray(b32[small])))
    assert got.dtype == np.float32
    rel = np.abs(got - ref) / ref
    assert np.max(rel / (1 + np.abs(np.log(ref)))) < 16 * EPS32
    assert np.max(rel[ref > 0.01]) < 16 * EPS32  # ~2e-6
    # the whole range, finite and in [0, 1]
    big = np.asarray(beta1p(jnp.asarray(a32), jnp.asarray(b32)))
    assert np.all(np.isfinite(big)) and np.all((big >= 0) & (big <= 1))


def test_gradients_match_digamma():
    a, b = _pairs(2000, _LAMBDA_MAX, 3)
    da, db = jax.jit(jax.vmap(jax.grad(special.log_beta1p, argnums=(0, 1))))(a, b)
    psi_s = sp.digamma(2 + a + b)
    for got, psi in ((da, sp.digamma(1 + a)), (db, sp.digamma(1 + b))):
        # scale: the two digammas, whose difference cancels for large arguments
        scale = 1 + np.abs(psi) + np.abs(psi_s)
        assert np.max(np.abs(np.asarray(got) - (psi - psi_s)) / scale) < 1e-12
    # the Beta itself, float32: finite gradients over the whole range, also at a = b and a = 0
    g = jax.jit(jax.vmap(jax.grad(special.beta1p, argnums=(0, 1))))(jnp.asarray(a, jnp.float32), jnp.asarray(b, jnp.float32))
    assert all(np.all(np.isfinite(np.asarray(x))) for x in g)


def test_closed_forms_and_edges():
    """B(1, 1 + b) = 1/(1 + b); B(2, 2) = 1/6; symmetric; the derivative at a = 0 and at a tie
    a = b is the full one-sided derivative (a clamp by minimum/maximum would halve it); negative
    arguments count as 0."""
    b = np.array([0.0, 0.5, 3.0, 1e3, 1e8])
    np.testing.assert_allclose(np.asarray(beta1p(0.0 * b, b)), 1 / (1 + b), rtol=1e-14)
    assert float(beta1p(1.0, 1.0)) == pytest.approx(1 / 6, rel=1e-15)
    np.testing.assert_array_equal(np.asarray(beta1p(b, 0.5)), np.asarray(beta1p(0.5, b)))
    a0, b0 = np.array([0.0, 0.7, 0.0]), np.array([2.0, 0.7, 0.0])
    ga = jax.jit(jax.vmap(jax.grad(special.log_beta1p)))(a0, b0)
    np.testing.assert_allclose(np.asarray(ga), sp.digamma(1 + a0) - sp.digamma(2 + a0 + b0), rtol=1e-12)
    np.testing.assert_array_equal(np.asarray(beta1p(np.array([-0.5, 2.0]), np.array([2.0, -1e-9]))),
                                  np.asarray(beta1p(np.array([0.0, 2.0]), np.array([2.0, 0.0]))))
