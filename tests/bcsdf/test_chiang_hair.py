"""chiang_hair (d'Eon 2011 / Chiang 2016 BCSDF): lobe functions, energy conservation,
reciprocity (what holds), sampling, gradients, limits. The pointwise comparison with
Mitsuba 3's ``hair`` is in tests/validation/test_mitsuba_hair.py."""

import functools
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.special as sps

from appearance_jax import flatland, testing
from appearance_jax.bcsdf import chiang, fiber
from appearance_jax.core.frame import fiber_direction
from appearance_jax.core.quadrature import gauss_legendre
from appearance_jax.core.vec import Vec3

# near-field eval, pdf, sample and lobes in batches of BATCH pairs with an h per pair (hair_batches:
# one compiled program per function for this module, test_chiang_fast32 and the Mitsuba tests)
sys.path.insert(0, str(Path(__file__).parent))
from hair_batches import N as BATCH, batched  # noqa: E402

MODEL = chiang.MODEL


def _dirs(theta, phi):
    return fiber_direction(jnp.asarray(theta, dtype=jnp.float64), jnp.asarray(phi, dtype=jnp.float64))


_mlobe = jax.jit(chiang.longitudinal_lobe)
_nlobe = jax.jit(chiang.azimuthal_lobe)
_smooth_attenuation = jax.jit(fiber.smooth_attenuation, static_argnames="p_max")


# ------------------------------------------------------------------------------------------
# lobe functions


@functools.lru_cache(maxsize=None)
def _gauss_legendre_400():
    """The 400-point rule on [0, 1] (an eigenvalue problem: computed once for the six cases)."""
    return gauss_legendre(400, 0.0, 1.0)


@pytest.mark.parametrize("v", [1e-4, 0.05, 110.0])
@pytest.mark.parametrize("theta_i", [0.7, -1.4])
def test_mp_normalised(v, theta_i):
    """int M_p cos(theta_o) dtheta_o = 1, small v (log-I0 regime) to large v; the quadrature
    is split at the peak theta_o = -theta_i so that narrow lobes are resolved."""
    pk = -theta_i
    total = 0.0
    for a, b in ((-np.pi / 2, pk), (pk, np.pi / 2)):
        # graded nodes: dense near the peak
        t, w = _gauss_legendre_400()
        if b == pk:
            x = b - (b - a) * t ** 3
            dx = (b - a) * 3 * t ** 2 * w
        else:
            x = a + (b - a) * t ** 3
            dx = (b - a) * 3 * t ** 2 * w
        m = np.asarray(_mlobe(theta_i, jnp.asarray(x), v))
        total += np.sum(m * np.cos(x) * dx)
    assert abs(total - 1.0) < 1e-8, total


def test_mp_closed_form_and_symmetry():
    """The log form equals d'Eon's closed form csch(1/v)/(2v) e^{-si so/v} I0(ci co/v) where that
    is representable, stays finite for tiny v, and M(ti, to) = M(to, ti)."""
    rng = np.random.default_rng(0)
    ti, to = rng.uniform(-1.5, 1.5, (2, 200))
    for v in (0.02, 0.1, 0.5, 3.0):
        ref = (1 / np.sinh(1 / v)) / (2 * v) * np.exp(-np.sin(ti) * np.sin(to) / v) * sps.i0(np.cos(ti) * np.cos(to) / v)
        m = np.asarray(_mlobe(jnp.asarray(ti), jnp.asarray(to), v))
        assert np.allclose(m, ref, rtol=1e-10, atol=1e-300)
        assert np.allclose(m, np.asarray(_mlobe(jnp.asarray(to), jnp.asarray(ti), v)), rtol=1e-12)
    m = np.asarray(_mlobe(jnp.asarray(ti), jnp.asarray(to), 1e-6))
    assert np.all(np.isfinite(m)) and np.all(m >= 0)
    # the peak of a narrow lobe: M(ti, -ti) ~ 1 / sqrt(2 pi v) / cos(ti) (Gaussian limit)
    v = 1e-6
    assert np.isclose(float(_mlobe(0.3, -0.3, v)), 1 / np.sqrt(2 * np.pi * v) / np.cos(0.3), rtol=1e-3)


def test_np_normalised_and_roughness_maps():
    x, w = gauss_legendre(1000, 0.0, np.pi)  # the lobe is even, with a kink at 0
    for bn in (0.05, 0.3, 0.9):
        s = chiang.azimuthal_scale(bn)
        assert abs(2 * np.sum(np.asarray(_nlobe(jnp.asarray(x), s)) * w) - 1) < 1e-9
        # periodic: a shifted argument wraps
        assert np.allclose(_nlobe(jnp.asarray(x) + 2 * np.pi, s), _nlobe(jnp.asarray(x), s))
    assert np.isclose(float(chiang.azimuthal_scale(0.3)), np.sqrt(np.pi / 8) * (0.265 * .3 + 1.194 * .09 + 5.372 * .3 ** 22))
    v = chiang.longitudinal_variances(0.3)
    v0 = (0.726 * .3 + 0.812 * .09 + 3.7 * .3 ** 20) ** 2
    assert np.allclose([float(a) for a in v], [v0, v0 / 4, 4 * v0, 4 * v0])


# M18 reference table (eta = 1.55, sigma_a = 0): h, theta_i (deg), Phi_0..2 (deg, wrapped), A_0..A_2
M18 = [
    (0.0, 0.0, (0.0, 180.0, 0.0), (0.04652, 0.90912, 0.04229)),
    (0.5, 0.0, (-60.00, 157.64, 15.28), (0.04814, 0.90604, 0.04362)),
    (0.5, 30.0, (-60.00, 154.33, 8.66), (0.05367, 0.89553, 0.04807)),
    (0.9, 0.0, (-128.32, 122.68, 13.67), (0.12268, 0.76969, 0.09443)),
]


@pytest.mark.parametrize("row", M18, ids=[f"h{r[0]}_t{r[1]}" for r in M18])
def test_smooth_limit_lobes_match_m18(row):
    """Narrow lobes (beta_m, beta_n -> small, alpha = 0): A_p equal fiber.smooth_attenuation and the
    M18 table; the R/TT/TRT lobes peak at phi_o - phi_i = Phi(p, h) and theta_o = -theta_i."""
    h, ti_deg, phis, amps = row
    # sigma_a = 0 in three bands (bands are compared below as band 0): the module's lobes program
    p = chiang.Params(sigma_a=(0.0, 0.0, 0.0), beta_m=0.02, beta_n=0.02, alpha=0.0)
    ti = np.radians(ti_deg)
    phi = np.linspace(-np.pi, np.pi, 20001)
    wi = _dirs(np.full_like(phi, ti), np.zeros_like(phi))
    wo = _dirs(np.full_like(phi, -ti), phi)
    A, M, N = batched(chiang.lobes, p, wi, wo, h=h, axis=1)
    ref = np.asarray(_smooth_attenuation(h, ti, 1.55, 0.0, p_max=3))
    assert np.allclose(A[:, 0, 0], ref[:, 0], rtol=1e-12)
    assert np.allclose(A[:3, 0, 0], amps, atol=6e-6)
    assert abs(A[:, 0, 0].sum() - 1) < 1e-12  # energy conserving lobe split
    for k in range(3):
        peak = np.degrees(phi[np.argmax(N[k])])
        assert abs((peak - phis[k] + 180) % 360 - 180) < 0.05, (k, peak, phis[k])
    # the longitudinal peak of every lobe sits on the specular cone theta_o = -theta_i
    to = np.linspace(-1.5, 1.5, 30001)
    Mt = batched(chiang.lobes, p, _dirs(np.full_like(to, ti), 0 * to), _dirs(to, 0 * to + 1.0), h=h, axis=1)[1]
    assert np.all(np.abs(to[np.argmax(Mt, axis=1)] + ti) < 1e-3)  # up to ~v tan(theta)/2 off the cone


def test_tilt_shifts_lobes():
    """Chiang's tilt: the R peak moves to theta_o = 2 alpha - theta_i, TT to -alpha - theta_i,
    TRT to -4 alpha - theta_i (pbrt/Mitsuba signs)."""
    a, ti = 0.05, 0.3
    p = chiang.Params(beta_m=0.02, alpha=a)
    to = np.linspace(-1.5, 1.5, 60001)
    M = batched(chiang.lobes, p, _dirs(np.full_like(to, ti), 0 * to), _dirs(to, 0 * to), axis=1)[1]
    peaks = to[np.argmax(M, axis=1)]
    assert np.allclose(peaks, [2 * a - ti, -a - ti, -4 * a - ti, -ti], atol=1e-3)


def test_direction_kernel_equals_angle_formulas():
    """The eval kernel works from direction components (angle addition for the tilt, a squared
    chord for sin^2((ti + to)/2), one atan2): its M_p and N_p equal the angle-form lobe functions
    at random directions, including tilts that fold theta_i + a past +-pi/2 and narrow lobes."""
    rng = np.random.default_rng(3)
    n = 4000
    ti, to = rng.uniform(-1.55, 1.55, n), rng.uniform(-1.55, 1.55, n)
    ti[:20] = np.linspace(1.45, 1.5707, 20)  # R/TRT tilt folds back past pi/2
    pi_, po = rng.uniform(-np.pi, np.pi, n), rng.uniform(-np.pi, np.pi, n)
    h = rng.uniform(-1, 1, n)
    for beta_m, alpha in ((0.3, 0.2), (0.03, -0.3), (0.9, 0.0)):
        p = chiang.Params(beta_m=beta_m, beta_n=0.25, alpha=alpha)
        A, M, N = batched(chiang.lobes, p, _dirs(ti, pi_), _dirs(to, po), h=h, axis=1)
        M_ref, N_ref, A_ref = (np.asarray(a) for a in _angle_form(p, *(jnp.asarray(a) for a in (ti, to, pi_, po, h))))
        assert np.allclose(M, M_ref, rtol=1e-9, atol=1e-12 * M_ref.max())
        assert np.allclose(N[:3], N_ref, rtol=1e-9, atol=1e-12)
        assert np.allclose(A, A_ref, rtol=1e-12)


@jax.jit
def _angle_form(p, ti, to, pi_, po, h):
    """M_p (tilted), N_p (R, TT, TRT) and A_p from the angle-form lobe functions (one compiled
    program for the three parameter sets)."""
    v = jnp.stack(chiang.longitudinal_variances(p.beta_m))[:, None]
    M_ref = chiang.longitudinal_lobe(chiang.tilted_angles(ti, p.alpha), to[None], v)
    eta_p = fiber.bravais_eta(p.eta, ti)
    s = chiang.azimuthal_scale(p.beta_n)
    N_ref = jnp.stack([chiang.azimuthal_lobe(po - pi_ - fiber.exit_azimuth(k, h, eta_p), s) for k in range(3)])
    return M_ref, N_ref, fiber.smooth_attenuation(h, ti, p.eta, chiang.as_bands(p.sigma_a), 3)


# ------------------------------------------------------------------------------------------
# absorption, checked without an oracle program


@pytest.mark.parametrize("theta_i", [0.0, 0.6, -1.1])
def test_absorbing_attenuations_match_flatland_and_closed_form(theta_i):
    """sigma_a > 0 (the M18 table has none): the attenuations that eval uses (chiang.lobes' A_p of
    R, TT, TRT and the residual) equal the flatland tracer's per-lobe powers of a smooth absorbing
    cylinder at the same offsets h (Fresnel at every event, Beer-Lambert along each traced 3D
    chord), and the closed form written out here (Chiang 2016 Eqs. 3-6): A_0 = f, A_1 = (1 - f)^2 T,
    A_2 = (1 - f)^2 T^2 f, T = exp(-sigma_a 2 cos(gamma_t) / cos(theta_t)), gamma_t = asin(h / eta'),
    with f the tracer's first reflection. A wrong power of T or a missing f in one lobe fails here,
    without the Mitsuba comparison (tests/validation/test_mitsuba_hair.py, skipped without mitsuba)."""
    eta, sig = 1.55, np.array([0.2, 0.5, 1.5])
    sl = flatland.smooth_lobes(flatland.fiber(eta, tuple(sig)), fiber_direction(theta_i, 0.0), n_h=32,
                               max_events=64)  # enough events that the tracer's tail of the residual lobe is negligible
    h, lobe, power = np.asarray(sl.h), np.clip(np.asarray(sl.lobe), 0, 3), np.asarray(sl.power)
    ref = np.stack([np.sum(np.where((lobe == p)[..., None], power, 0.0), axis=0) for p in range(4)])
    n = h.size
    wi = _dirs(np.full(n, theta_i), np.zeros(n))
    wo = _dirs(np.full(n, -theta_i), np.full(n, 1.0))  # A_p depends on wi and h only
    A = batched(chiang.lobes, chiang.Params(eta=eta, sigma_a=tuple(sig), alpha=0.0), wi, wo, h=h, axis=1)[0]
    np.testing.assert_allclose(A, ref, rtol=1e-9, atol=1e-14)
    s, c = np.sin(theta_i), np.cos(theta_i)
    cos_gt = np.sqrt(1.0 - (h * c / np.sqrt(eta ** 2 - s ** 2)) ** 2)[:, None]
    T = np.exp(-sig * 2.0 * cos_gt / np.sqrt(1.0 - (s / eta) ** 2))
    f = ref[0]
    assert np.all(T < 0.95) and np.all(f > 0.03)  # both factors matter at every node
    np.testing.assert_allclose(A[:3], [f, (1 - f) ** 2 * T, (1 - f) ** 2 * T ** 2 * f], rtol=1e-9, atol=1e-14)


# ------------------------------------------------------------------------------------------
# energy


def _sphere_quadrature(n_t=200, n_p=400):
    t, wt = gauss_legendre(n_t, -np.pi / 2, np.pi / 2)
    ph = (np.arange(n_p) + 0.5) * 2 * np.pi / n_p
    T, P = np.meshgrid(t, ph, indexing="ij")
    return T, P, wt[:, None] * np.cos(T) * (2 * np.pi / n_p)


@pytest.mark.parametrize("far", [False, pytest.param(True, marks=pytest.mark.slow)])
def test_albedo_is_sum_of_attenuations(far):
    """Quadrature: int S cos(theta_o) dwo = sum_p A_p (= 1 with sigma_a = 0) and int pdf dwo = 1,
    near field at several (theta_i, h), far field = the h-average of sum_p A_p."""
    T, P, W = _sphere_quadrature(96, 192)
    # n_h only for the far field (a static setting: near-field programs are the module's)
    base = dict(beta_m=0.4, beta_n=0.5, far_field=far, **(dict(n_h=16) if far else {}))
    for ti, h in ((0.3, 0.2), (-1.2, -0.8), (0.0, 0.95)):
        wi = _dirs(np.full(T.shape, ti), np.full(T.shape, 0.4))
        wo = _dirs(T, P)
        cos_o = np.cos(T)[..., None]
        # sigma_a = 0 in each of three bands
        S0 = batched(chiang.eval, chiang.Params(sigma_a=(0.0, 0.0, 0.0), **base), wi, wo, h=h)
        a0 = np.sum(S0 * cos_o * W[..., None], axis=(0, 1))
        assert np.allclose(a0, 1.0, atol=1e-5), a0
        pr = chiang.Params(sigma_a=(0.2, 0.5, 1.5), **base)
        S = batched(chiang.eval, pr, wi, wo, h=h)
        pdf = batched(chiang.pdf, pr, wi, wo, h=h)
        if far:
            x, w = gauss_legendre(16)
            ref = np.sum(np.asarray(_smooth_attenuation(jnp.asarray(x), ti, 1.55, jnp.asarray((0.2, 0.5, 1.5)),
                                                        p_max=3)).sum(0) * w[:, None] / 2, axis=0)
        else:
            ref = np.asarray(_smooth_attenuation(h, ti, 1.55, jnp.asarray((0.2, 0.5, 1.5)), p_max=3)).sum(0)
        assert np.allclose(np.sum(S * cos_o * W[..., None], axis=(0, 1)), ref, atol=1e-5)
        assert abs(np.sum(pdf * W) - 1) < 1e-5


@pytest.mark.parametrize("far", [False, True])
def test_white_sample_weights_are_exactly_one(far):
    """sigma_a = 0: A_p are the same in every band and the lobe probabilities equal A_p, and
    M_p, N_p are sampled exactly, so every weight S cos / pdf is 1 (to rounding)."""
    n = BATCH  # one batch of the module's sampler programs
    key = jax.random.key(11)
    wi = testing.random_directions(key, n, "sphere")
    # sigma_a = 0 in each of three bands; n_h as in the module's other far-field calls
    p = chiang.Params(sigma_a=(0.0, 0.0, 0.0), beta_m=0.2, beta_n=0.3, far_field=far, n_h=16)
    h = jax.random.uniform(jax.random.key(12), (n,), minval=-1, maxval=1)
    wo, w, pdf = batched(chiang.sample, p, wi, jax.random.key(13), h=h)
    assert np.all(pdf > 0)
    assert np.max(np.abs(w - 1.0)) < 1e-9
    # unit directions
    assert np.allclose(np.asarray(wo.x) ** 2 + np.asarray(wo.y) ** 2 + np.asarray(wo.z) ** 2, 1.0)


@pytest.mark.slow
def test_white_furnace_harness():
    testing.assert_white_furnace(MODEL, chiang.Params(sigma_a=0.0), key=2, n_wi=4, n_samples=2**12,
                                 n_theta=96, n_phi=192, lossless=True)
    testing.assert_white_furnace(MODEL, chiang.Params(), key=3, n_wi=4, n_samples=2**12, n_theta=96, n_phi=192)


# ------------------------------------------------------------------------------------------
# reciprocity


def test_reciprocity_where_it_holds():
    """Chiang's model is not reciprocal in general: A_p and the tilt depend on theta_i only, and
    N_p on the offset of the given ray. What holds exactly, with alpha = 0, on the specular cone
    theta_o = -theta_i (where A_p(theta_i) = A_p(theta_o)): S(wi, wo; h) = S(wo, wi; -h) near
    field, and S(wi, wo) = S(wo, wi) in the far field. Off the cone it fails (checked)."""
    rng = np.random.default_rng(3)
    n = BATCH
    ti = rng.uniform(-1.4, 1.4, n)
    pi_, po = rng.uniform(-np.pi, np.pi, (2, n))
    h = rng.uniform(-1, 1, n)
    wi, wo = _dirs(ti, pi_), _dirs(-ti, po)
    p = chiang.Params(alpha=0.0, beta_m=0.25, beta_n=0.35)
    a = batched(chiang.eval, p, wi, wo, h=h)
    b = batched(chiang.eval, p, wo, wi, h=-h)
    assert np.allclose(a, b, rtol=1e-10, atol=0)
    pf = p.replace(far_field=True, n_h=16)
    assert np.allclose(batched(chiang.eval, pf, wi, wo), batched(chiang.eval, pf, wo, wi), rtol=1e-10)
    # with the tilt, or off the specular cone, it does not hold
    # alpha = 0, h = 0, general pairs: as testing.reciprocity_pairs draws them (half uniform, half
    # with wo from the sampler), with the module's sampler program
    k1, k2, k3 = jax.random.split(jax.random.key(1), 3)
    wi_g, wo_g = (testing.random_directions(k, BATCH, "sphere") for k in (k1, k2))
    ws, _, pdf = batched(chiang.sample, p, wi_g, k3)
    use = (np.arange(BATCH) % 2 == 1) & (pdf > 0)
    wo_g = Vec3(*(np.where(use, a, np.asarray(b)) for a, b in zip(ws, wo_g)))
    res = testing.check_reciprocity(MODEL, p, wi=wi_g, wo=wo_g)
    assert not res.passed and res.max_rel_error > 1e-2
    pt = p.replace(alpha=0.05)
    assert not np.allclose(batched(chiang.eval, pt, wi, wo, h=h), batched(chiang.eval, pt, wo, wi, h=-h), rtol=1e-3)


# ------------------------------------------------------------------------------------------
# sampling


CASES = {
    "blond_tilt": chiang.Params.from_melanin(0.3, 0.1, beta_m=0.15, beta_n=0.25, alpha=0.05),
    "default": chiang.Params(),
    "far_black": chiang.Params.from_melanin(8.0, 0.0, beta_m=0.6, beta_n=0.8, far_field=True, n_h=8),
}


# the default run checks sampling, chi-square and gradients of the blond and white cases through
# the property harness (tests/test_properties.py); these are the wider versions
@pytest.mark.slow
@pytest.mark.parametrize("name", ["blond_tilt", "default", "far_black"])
def test_sampling_consistency_and_chi2(name):
    p = CASES[name]
    testing.assert_sampling(MODEL, p, key=3, n_wi=2, n_samples=2**12)
    testing.assert_chi2(MODEL, p, key=4, n_wi=2, n_samples=2**15, n_tests=len(CASES))


def test_sampler_accepts_uniform_tuples_and_keys():
    # two directions, repeated to one batch of BATCH pairs (the program of test_mitsuba_hair's sampling test)
    wi = _dirs(np.resize([0.2, -0.5], BATCH), np.resize([0.0, 1.0], BATCH))
    p = chiang.Params()
    u = tuple(jnp.asarray(np.resize([0.1, 0.9], BATCH)) for _ in range(5))
    wo1, w1, p1 = batched(chiang.sample, p, wi, u)
    wo2, w2, p2 = batched(chiang.sample, p, wi, u)
    assert np.allclose(w1, w2) and np.all(p1 > 0)
    # pdf returned by sample == pdf(wi, wo)
    assert np.allclose(p1, batched(chiang.pdf, p, wi, wo1))
    with pytest.raises(ValueError):
        chiang.sample(p, wi, u[:3])


# ------------------------------------------------------------------------------------------
# gradients, edge cases, validation


@pytest.mark.slow
def test_gradients_vs_finite_differences():
    wi, wo = testing.reciprocity_pairs(MODEL, CASES["blond_tilt"], key=5, n=16)
    wi, wo = (w.map(jnp.asarray) for w in (wi, wo))
    h = jnp.linspace(-0.9, 0.9, 16)
    c = jax.random.uniform(jax.random.key(6), (16, 3), jnp.float64)

    def fn(p):
        f, pdf = chiang.eval_pdf.kernel(p, wi, wo, h)
        return jnp.sum(c * f) + jnp.sum(c[:, 0] * pdf) / 10

    testing.assert_gradients(jax.jit(fn), CASES["blond_tilt"], name="chiang_hair")
    # melanin concentration through the converter
    def g(eu):
        p = CASES["blond_tilt"].replace(sigma_a=fiber.melanin_sigma_a_rgb(eu, 0.1))
        return jnp.sum(c * chiang.eval.kernel(p, wi, wo, h))

    testing.assert_gradients(g, 0.3, rtol=5e-7, atol=5e-9, name="melanin")  # within np.isclose(rtol=1e-6, atol=1e-8)


def test_grazing_and_degenerate_inputs_are_finite():
    """eval, pdf and sample (near and far field) stay finite along the fiber axis, at grazing
    incidence and at |h| = 1 (the five pairs are repeated to one batch of BATCH pairs)."""
    p = chiang.Params()
    ax = jnp.array([1.0, -1.0, 0.0, 0.0, 1.0])
    wi = Vec3(ax, jnp.array([0.0, 0.0, 1.0, 0.0, 0.0]), jnp.array([0.0, 0.0, 0.0, 1.0, 0.0]))
    wo = Vec3(jnp.array([-1.0, 1.0, 1.0, 0.0, 0.6]), jnp.array([0.0, 0.0, 0.0, -1.0, 0.8]), jnp.zeros(5))
    for hh in (jnp.array([0.0, 1.0, -1.0, 1.0, 0.5]),):
        for pp in (p, p.replace(far_field=True, n_h=16)):
            f = batched(chiang.eval, pp, wi, wo, h=hh)
            assert np.all(np.isfinite(f)) and np.all(f >= 0)
            assert np.all(np.isfinite(batched(chiang.pdf, pp, wi, wo, h=hh)))
            _, w, pdf = batched(chiang.sample, pp, wi, jax.random.key(0), h=hh)
            assert np.all(np.isfinite(w)) and np.all(np.isfinite(pdf))
    # theta_o = +-pi/2 exactly: S (which carries 1/cos theta_o) is set to 0 there (at h = 0, the
    # default; in the fixed-size chunks of testing.call_chunked, as check_reciprocity calls eval)
    assert np.all(testing.call_chunked(chiang.eval, p, wi, wo)[:2] == 0)
    g = jax.jit(jax.jacfwd(lambda b: jnp.sum(chiang.eval.kernel(p.replace(beta_m=b), wi, wo, hh))))(0.3)
    assert np.isfinite(float(g))


def test_bad_parameters_raise_naming_the_field():
    with pytest.raises(ValueError, match="beta_m"):
        chiang.eval(chiang.Params(beta_m=0.0), _dirs(0.1, 0.0), _dirs(0.2, 1.0))
    with pytest.raises(ValueError, match="beta_n"):
        chiang.eval(chiang.Params(beta_n=1.5), _dirs(0.1, 0.0), _dirs(0.2, 1.0))
    with pytest.raises(ValueError, match="sigma_a"):
        chiang.eval(chiang.Params(sigma_a=(-1.0, 0.0, 0.0)), _dirs(0.1, 0.0), _dirs(0.2, 1.0))
    with pytest.raises(ValueError, match="eta"):
        chiang.pdf(chiang.Params(eta=1.0), _dirs(0.1, 0.0), _dirs(0.2, 1.0))
    with pytest.raises(ValueError, match="h"):
        chiang.eval(chiang.Params(), _dirs(0.1, 0.0), _dirs(0.2, 1.0), h=1.5)
    with pytest.raises(ValueError, match="n_h"):
        chiang.Params(far_field=True, n_h=1)


def test_from_melanin_and_color():
    p = chiang.Params.from_melanin(1.3, 0.0)
    assert np.allclose(np.asarray(p.sigma_a), 1.3 * np.asarray(fiber.EUMELANIN_RGB))
    q = chiang.Params.from_color((0.5, 0.3, 0.1), beta_n=0.4)
    assert np.allclose(np.asarray(q.sigma_a), np.asarray(fiber.sigma_a_from_color((0.5, 0.3, 0.1), 0.4)))
    s = chiang.Params.from_melanin(1.0, 0.5, wavelength_nm=(450.0, 550.0, 650.0, 700.0))
    f = chiang.eval(s, _dirs(0.1, 0.0), _dirs(-0.2, 2.0))
    assert f.shape == (4,)
    assert set(MODEL.presets) >= {"brown", "blond", "black"}
