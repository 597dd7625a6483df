"""chiang_hair's fast eval: the float32 special functions of bcsdf.fast32 against float64
references, the stepped near-field eval (_eval_near: batches above one step, per-pair
parameters, gradients) against the per-lobe terms, and float32 eval against float64."""

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.special as sps

from appearance_jax.bcsdf import chiang, fast32
from appearance_jax.core.special import atan2, safe_asin
from appearance_jax.core.vec import Vec3
from appearance_jax.optics.fresnel import fresnel_dielectric

# unstepped eval and lobes in batches of 1200 pairs with an h per pair: the programs of
# test_chiang_hair.py and the Mitsuba tests (hair_batches)
sys.path.insert(0, str(Path(__file__).parent))
from hair_batches import batched  # noqa: E402

EPS32 = float(np.finfo(np.float32).eps)

# the special functions as compiled programs, as the eval kernel uses them (op by op, each of
# their dozens of primitives compiled separately for every shape and dtype)
_atan2, _asin, _exp_i0e = (jax.jit(f) for f in (fast32.atan2, fast32.asin, fast32.exp_i0e))
_fresnel_outside = jax.jit(fast32.fresnel_outside)
_exact_atan2, _exact_asin = jax.jit(atan2), jax.jit(safe_asin)
_fresnel = jax.jit(lambda c, eta: fresnel_dielectric(c, eta)[0])
_exp_i0e_exact = jax.jit(lambda a, x: jnp.exp(a) * jax.scipy.special.i0e(x))


def _f32(x):
    return jnp.asarray(np.asarray(x, dtype=np.float32))


def test_atan2_asin_float32():
    rng = np.random.default_rng(0)
    y, x = rng.normal(size=(2, 200_000)).astype(np.float32)
    y[:8] = [0.0, -0.0, 0.0, -0.0, 1.0, -1.0, 3.0, 0.0]
    x[:8] = [1.0, 1.0, -1.0, -1.0, 0.0, 0.0, 3.0, 0.0]
    got = np.asarray(_atan2(_f32(y), _f32(x)), np.float64)
    ref = np.arctan2(y.astype(np.float64), x.astype(np.float64))
    assert np.all(np.abs(got - ref) <= 2 * EPS32 * np.abs(ref) + EPS32 * np.pi), np.max(np.abs(got - ref))
    assert np.array_equal(np.signbit(got[:4]), [False, True, False, True]) and got[7] == 0.0
    s = np.concatenate([rng.uniform(-1, 1, 100_000), [-1.0, 1.0, 0.0, 1 - 2 ** -24]]).astype(np.float32)
    got = np.asarray(_asin(_f32(s)), np.float64)
    ref = np.arcsin(s.astype(np.float64))
    assert np.all(np.abs(got - ref) <= 3 * EPS32 * np.abs(ref) + EPS32 * np.pi / 2)
    assert np.all(np.abs(np.asarray(_asin(_f32([-1.5, 1.5]))) - [-np.pi / 2, np.pi / 2]) < 1e-6)


def test_float64_is_exact_path():
    """float64 arguments take the exact functions (bit for bit; each side compiled on its own)."""
    with jax.enable_x64(True):
        rng = np.random.default_rng(1)
        y, x = (np.asarray(v) for v in rng.normal(size=(2, 1000)))
        assert np.array_equal(_atan2(y, x), _exact_atan2(y, x))
        assert np.array_equal(_asin(np.tanh(y)), _exact_asin(np.tanh(y)))
        c = np.abs(np.tanh(x))
        assert np.array_equal(_fresnel_outside(c, 1.55), _fresnel(c, 1.55))
        a = -np.abs(y)
        assert np.array_equal(_exp_i0e(a, np.abs(x) * 9), _exp_i0e_exact(a, np.abs(x) * 9))


def test_exp_i0e_float32():
    x = np.concatenate([np.linspace(0, 10, 20_001), np.geomspace(10, 1e5, 2_000), [3.75, 3.7500002]])
    a = -np.linspace(0, 30, x.size)
    got = np.asarray(_exp_i0e(_f32(a), _f32(x)), np.float64)
    xf, af = x.astype(np.float32).astype(np.float64), a.astype(np.float32).astype(np.float64)
    ref = np.exp(af) * sps.i0e(xf)
    # A&S 9.8.1-2 (< 1.9e-7) + rounding of the exponential, whose argument is up to 30 + x
    assert np.all(np.abs(got - ref) <= (4e-7 + 2 * EPS32 * (np.abs(af) + 1)) * ref)


def test_fresnel_outside_float32():
    """Within 8 ulp of float64 (at the float32 index) where the reflectance is well conditioned;
    for eta -> 1 (cancellation in c - eta cos_t) no worse than fresnel_dielectric in float32."""
    c = np.concatenate([np.linspace(0, 1, 10_001), [1e-7, 1 - 1e-7]]).astype(np.float32)
    for eta in (1.0001, 1.01, 1.33, 1.55, 4.0):
        e32 = np.float32(eta)
        with jax.enable_x64(True):
            ref = np.asarray(_fresnel(jnp.asarray(c, jnp.float64), float(e32)))
        got = np.asarray(_fresnel_outside(_f32(c), e32), np.float64)
        generic = np.asarray(_fresnel(_f32(c), e32), np.float64)
        rel, rel_generic = np.abs(got - ref) / ref, np.abs(generic - ref) / ref
        assert rel.max() <= max(8 * EPS32, 1.5 * rel_generic.max()), (eta, rel.max(), rel_generic.max())
        if eta > 1.3:
            assert rel.max() <= 8 * EPS32


def test_fast32_gradients_finite():
    # each derivative one compiled program (op by op, every primitive of the forward and
    # backward passes compiled separately)
    d_atan2 = jax.jit(jax.grad(lambda y, x: fast32.atan2(y, x), argnums=(0, 1)))
    g = d_atan2(jnp.float32(0.0), jnp.float32(0.0))
    assert all(float(v) == 0.0 for v in g)
    g = d_atan2(jnp.float32(0.3), jnp.float32(-0.4))
    assert np.allclose([float(v) for v in g], [-0.4 / 0.25, -0.3 / 0.25], rtol=1e-6)
    d_asin = jax.jit(jax.grad(fast32.asin))
    for s in (-1.0, 1.0, 0.5):
        d = float(d_asin(jnp.float32(s)))
        assert np.isfinite(d)
    assert abs(float(d_asin(jnp.float32(0.5))) - 1 / np.sqrt(0.75)) < 1e-5
    x = jnp.asarray([0.0, 2.0, 3.75, 20.0], jnp.float32)
    d = jax.jit(jax.vmap(jax.grad(lambda x: fast32.exp_i0e(jnp.float32(-1.0), x))))(x)
    ref = np.exp(-1.0) * (sps.i1e([0.0, 2.0, 3.75, 20.0]) - sps.i0e([0.0, 2.0, 3.75, 20.0]))
    assert np.all(np.isfinite(d)) and np.allclose(d, ref, rtol=2e-3, atol=1e-6)


# ------------------------------------------------------------------------------------------
# the stepped near-field eval


def _pairs(n, seed, dtype=np.float64):
    rng = np.random.default_rng(seed)
    w = rng.normal(size=(2, 3, n))
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    w[0, 2] = np.abs(w[0, 2])
    return (Vec3(*(jnp.asarray(c, dtype) for c in w[0])), Vec3(*(jnp.asarray(c, dtype) for c in w[1])))


def _reference(p, wi, wo, h):
    """S = sum_p A_p M_p N_p / cos(theta_o) from the per-lobe terms (the pdf path's kernel; lobes
    in the shared batches of hair_batches, the rest in numpy)."""
    A, M, N = batched(chiang.lobes, p, wi, wo, h=h, axis=1)
    cos_o = np.sqrt(np.asarray(wo.y) ** 2 + np.asarray(wo.z) ** 2)
    return np.sum(A * (M * N)[..., None], axis=0) / cos_o[:, None]


N_BIG = 2 * chiang._CHUNK + 37  # odd: one group, three steps, the last one overlapping
C_GROUP = chiang._CHUNK // chiang._GROUPS
N_GROUPED = chiang._GROUPS * (2 * C_GROUP + 5)  # _GROUPS groups of three steps, the last overlapping


@pytest.mark.parametrize("n", [N_BIG, N_GROUPED])
def test_stepped_eval_matches_lobes(n):
    with jax.enable_x64(True):
        p = chiang.Params.from_melanin(0.8, 0.2, beta_m=0.2, beta_n=0.35, alpha=0.06)
        wi, wo = _pairs(n, 2)
        h = chiang.offset_from_normal(wi)
        S = np.asarray(chiang.eval(p, wi, wo, h=h))
        ref = _reference(p, wi, wo, h)
        assert S.shape == (n, 3)
        assert np.allclose(S, ref, rtol=1e-12, atol=1e-300)
        # the same pairs far below one step at a time (the unstepped path): 1200-pair batches, the
        # last one padded with copies of the first pair (pairs are independent)
        part = batched(chiang.eval, p, wi, wo, h=h)
        assert np.allclose(part, S, rtol=1e-13, atol=1e-300)
        # a 2D batch and a scalar h
        k = n - n % 2
        S2 = np.asarray(chiang.eval(p, Vec3(*(c[:k].reshape(2, -1) for c in wi)),
                                    Vec3(*(c[:k].reshape(2, -1) for c in wo)), h=0.3))
        ref2 = _reference(p, Vec3(*(c[:k] for c in wi)), Vec3(*(c[:k] for c in wo)), 0.3)
        assert np.allclose(S2.reshape(-1, 3), ref2, rtol=1e-12, atol=1e-300)


@pytest.mark.parametrize("n", [N_BIG, N_GROUPED])
def test_stepped_eval_per_pair_parameters(n):
    with jax.enable_x64(True):
        wi, wo = _pairs(n, 3)
        rng = np.random.default_rng(4)
        sig = rng.uniform(0, 3, (n, 3))
        bm = rng.uniform(0.05, 0.8, n)
        p = chiang.Params(sigma_a=sig, beta_m=bm, beta_n=0.4, alpha=0.03)
        h = chiang.offset_from_normal(wi)
        S = np.asarray(jax.jit(chiang.eval.kernel)(p, wi, wo, h))  # one program (op by op: dozens)
        m, c = (n, chiang._CHUNK) if n % 2 else (n // chiang._GROUPS, C_GROUP)
        # step and group edges (the last step of a group overlaps the one before)
        idx = sorted({i for i in (0, 1, c - 1, c, 2 * c, m - c, m - 1, m, m + c, n - 1) if i < n})
        for i in idx:
            q = chiang.Params(sigma_a=sig[i], beta_m=bm[i], beta_n=0.4, alpha=0.03)
            # the pair alone, with its own parameters (repeated to one batch of hair_batches)
            one = batched(chiang.eval, q, Vec3(*(c[i] for c in wi)), Vec3(*(c[i] for c in wo)), h=float(h[i]))
            assert np.allclose(S[i], one, rtol=1e-12, atol=1e-300), i


def test_stepped_eval_gradient():
    """d/d(params) of a sum over a stepped batch equals the sum of the unstepped pieces'."""
    n = N_GROUPED
    with jax.enable_x64(True):
        wi, wo = _pairs(n, 5)
        h = chiang.offset_from_normal(wi)
        p = chiang.Params.from_melanin(1.0, 0.1, beta_m=0.25, beta_n=0.3)

        def loss(q, a, b, hh):
            return jnp.sum(jnp.log1p(chiang.eval.kernel(q, a, b, hh)))

        # jitted (op by op the stepped loop's gradient took a minute); equal parts below one step:
        # one compiled program for all of them. One gradient with respect to everything (parameters,
        # directions, h): two compilations (stepped batch, part) instead of four
        m = n // chiang._GROUPS
        assert m * chiang._GROUPS == n and m < chiang._CHUNK
        grad_all = jax.jit(jax.grad(loss, argnums=(0, 1, 2, 3)))
        g, *gd = grad_all(p, wi, wo, h)
        both = [grad_all(p, Vec3(*(c[k:k + m] for c in wi)), Vec3(*(c[k:k + m] for c in wo)), h[k:k + m])
                for k in range(0, n, m)]
        parts = [q[0] for q in both]
        for name in ("eta", "sigma_a", "beta_m", "beta_n", "alpha"):
            ref = sum(np.asarray(getattr(q, name)) for q in parts)
            assert np.allclose(np.asarray(getattr(g, name)), ref, rtol=1e-10), name
        # and with respect to the directions and h (per pair)
        parts = [q[1:] for q in both]
        for a, b in zip(jax.tree.leaves(gd), (np.concatenate(x) for x in zip(*(jax.tree.leaves(q) for q in parts)))):
            # 1e-7: a few pairs whose derivative cancels differ at ~1e-9 between the two programs
            assert np.allclose(np.asarray(a), b, rtol=1e-7, atol=1e-300)


@pytest.mark.parametrize("preset", ["brown", "blond", "black", "white"])
def test_float32_eval_close_to_float64(preset):
    """float32 (fast special functions, stepped) against float64 at the same float32 inputs."""
    # sigma_a in three bands (white's is a scalar 0): one float32 and one float64 program for all
    # presets, the float64 one that of test_stepped_eval_matches_lobes[N_BIG]
    p = chiang.PRESETS[preset]
    p = p.replace(sigma_a=np.broadcast_to(np.asarray(p.sigma_a), (3,)))
    p = jax.tree.map(lambda v: jnp.asarray(v, jnp.float32), p)
    wi32, wo32 = _pairs(N_BIG, 6, np.float32)
    S32 = chiang.eval(p, wi32, wo32, h=chiang.offset_from_normal(wi32))
    assert S32.dtype == jnp.float32
    S32 = np.asarray(S32, np.float64)
    with jax.enable_x64(True):
        p64 = jax.tree.map(lambda v: jnp.asarray(v, jnp.float64), p)
        wi, wo = (Vec3(*(jnp.asarray(c, jnp.float64) for c in w)) for w in (wi32, wo32))
        S64 = np.asarray(chiang.eval(p64, wi, wo, h=chiang.offset_from_normal(wi)))
    assert np.all(np.isfinite(S32))
    rel = np.abs(S32 - S64) / np.maximum(np.abs(S64), 1e-3 * S64.max())
    # measured (2e5 pairs): max 3e-3-5e-3, 99.9th percentile 1e-5-1e-4, both as with the former
    # float64-grade special functions (the conditioning of h and 1/cos(theta_o) in float32)
    assert rel.max() < 1e-2 and np.percentile(rel, 99.9) < 3e-4, (rel.max(), np.percentile(rel, 99.9))
