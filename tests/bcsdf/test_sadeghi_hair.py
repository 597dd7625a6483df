"""Sadeghi 2011 artist-friendly hair: spec seed-002 §3.3 checks H1-H7, the physical ->
artist mapping against Marschner's lobes, and the dual-scattering tables against
brute-force integrals."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import testing
from appearance_jax.bcsdf import dual_scattering as DS
from appearance_jax.bcsdf import marschner as M
from appearance_jax.bcsdf import sadeghi as S
from appearance_jax.core.frame import fiber_direction

DEG = math.pi / 180
# the model functions as compiled programs (parameters are arguments: one program per shape and
# static setting; op by op, every primitive compiles separately)
_mlobes = jax.jit(M.lobes)
_slobes = jax.jit(S.lobes)
_sazimuthal = jax.jit(S.azimuthal)
_slongitudinal = jax.jit(S.longitudinal)


def test_h1_analytic_global_azimuthal():
    ng = DS.azimuthal_global(S.Params(glint_intensity=0.0))
    np.testing.assert_allclose(float(ng[0]), 0.3729232, atol=1e-7)
    np.testing.assert_allclose(float(ng[2]), 0.3729232, atol=1e-7)  # I_g = 0: TRT = R
    for g, ref in ((5, 0.0696286), (10, 0.1392571), (20, 0.2785124), (30, 0.4166435)):
        np.testing.assert_allclose(float(DS.azimuthal_global(S.Params(gamma_tt=g * DEG))[1]), ref, atol=1e-7)
    # int_{-pi}^{pi} cos(phi/2) dphi = 4, and N^G (with glints) vs midpoint quadrature of N'
    phi = -np.pi + (np.arange(200000) + 0.5) * (2 * np.pi / 200000)
    n = np.asarray(_sazimuthal(S.Params(), jnp.asarray(phi)))
    np.testing.assert_allclose(n[0].sum() * 2 * np.pi / 200000, 4.0, atol=1e-8)
    front = phi >= np.pi / 2
    num = n[:, front].sum(1) * (2 * np.pi / 200000) * 2 / np.pi
    np.testing.assert_allclose(np.asarray(DS.azimuthal_global(S.Params(glint_angle=80 * DEG, glint_width=10 * DEG))),
                               np.asarray(_sazimuthal(S.Params(glint_angle=80 * DEG, glint_width=10 * DEG),
                                                      jnp.asarray(phi[front]))).mean(1) * 1.0, atol=1e-6)
    np.testing.assert_allclose(np.asarray(DS.azimuthal_global(S.Params())), num, atol=1e-8)


def _grid(n=9):
    th_i, th_o, ph = np.meshgrid(np.linspace(-1.2, 1.2, n), np.linspace(-1.2, 1.2, n), np.linspace(-3, 3, n),
                                 indexing="ij")
    return jnp.asarray(th_i.ravel()), jnp.asarray(th_o.ravel()), jnp.asarray(ph.ravel())


def test_h2_decoupling_invariants():
    th = jnp.linspace(-1.5, 1.5, 301)
    for b in (0.02, 0.1, 0.5):
        m = np.asarray(_slongitudinal(S.Params(beta_r=b, beta_tt=b, beta_trt=b), th))
        assert np.all(m <= 1.0)
        m0 = _slongitudinal(S.Params(beta_r=b, beta_tt=b, beta_trt=b), jnp.asarray([-5 * DEG, 2.5 * DEG, 7.5 * DEG]))
        np.testing.assert_allclose(np.diag(np.asarray(m0)), 1.0, atol=1e-15)
    ti, to, ph = _grid()
    base = np.asarray(_slobes(S.Params(), ti, to, ph))
    # beta_X leaves f'_X unchanged at theta_h = alpha_X (theta_i = theta_o = alpha_X)
    a = jnp.full(5, -5 * DEG)
    phs = jnp.linspace(0, 3, 5)
    np.testing.assert_allclose(_slobes(S.Params(beta_r=0.3), a, a, phs)[0], _slobes(S.Params(), a, a, phs)[0],
                               rtol=1e-14)
    # C_X / I_X change only their own component
    for k, kw in enumerate([dict(color_r=(0.1, 2.0, 0.3)), dict(intensity_tt=3.0), dict(color_trt=(1, 1, 1))]):
        new = np.asarray(_slobes(S.Params(**kw), ti, to, ph))
        others = [j for j in range(3) if j != k]
        np.testing.assert_array_equal(new[others], base[others])
        assert not np.allclose(new[k], base[k])
    # I_g = 0: N'_TRT = N'_R
    n = np.asarray(_sazimuthal(S.Params(glint_intensity=0.0), ph))
    np.testing.assert_array_equal(n[2], n[0])


def test_h7_peak_positions_and_shifts():
    G = 40 * DEG
    p = S.Params(glint_angle=G, glint_intensity=3.0, gamma_tt=0.3)
    phi = jnp.linspace(-np.pi, np.pi, 7201)
    n = np.asarray(_sazimuthal(p, phi))
    glint = n[2] - np.cos(np.abs(np.asarray(phi)) / 2)
    assert abs(abs(float(phi[np.argmax(glint)])) - G) < 1e-3
    np.testing.assert_allclose(glint, glint[::-1], atol=1e-12)    # two glints, +-G
    assert abs(abs(float(phi[np.argmax(n[1])])) - np.pi) < 1e-3  # TT at phi = pi
    assert abs(float(phi[np.argmax(n[0])])) < 1e-3               # R at phi = 0
    assert abs(float(phi[np.argmax(_sazimuthal(p.replace(glint_intensity=0.0), phi)[2])])) < 1e-3
    # R toward the root (theta_h peak at alpha_R < 0), TRT toward the tip
    th = jnp.linspace(-0.5, 0.5, 10001)
    m = np.asarray(_slongitudinal(S.Params(), th))
    peaks = np.asarray(th)[m.argmax(1)]
    assert peaks[0] < 0 < peaks[2] and abs(peaks[0] + 5 * DEG) < 1e-4
    # G_angle per strand in [30, 45] deg
    g = np.asarray(S.random_glint_angle(jax.random.PRNGKey(0), (1000,)))
    assert g.min() >= 30 * DEG and g.max() <= 45 * DEG


def _brute_albedo(p, theta_i, n_t=400, n_p=800):
    """Midpoint rule over theta_o in (-pi/2, pi/2), phi in (-pi, pi): front / back integrals of
    f'_s cos theta_o dw_o (independent of the Gauss-Legendre tables)."""
    to = -np.pi / 2 + (np.arange(n_t) + 0.5) * np.pi / n_t
    ph = -np.pi + (np.arange(n_p) + 0.5) * 2 * np.pi / n_p
    T, P = np.meshgrid(to, ph, indexing="ij")
    f = np.asarray(_slobes(p, jnp.full(T.shape, theta_i, jnp.float64), jnp.asarray(T), jnp.asarray(P)))
    w = (np.cos(T) ** 2 * (np.pi / n_t) * (2 * np.pi / n_p))[None, :, :, None]
    back = np.abs(P) < np.pi / 2
    fb = (f * w * back[None, :, :, None]).sum((1, 2))
    ff = (f * w * ~back[None, :, :, None]).sum((1, 2))
    return fb, ff  # per lobe, per band


N_TAB = 4  # inclinations per DS.tables call of this module (one compiled program per static setting)


def _tables(p, d, theta):
    """DS.tables at ``theta`` (1D, at most N_TAB), padded with copies of the first to N_TAB."""
    theta = jnp.asarray(theta, dtype=jnp.float64)
    n = theta.shape[0]
    tab = DS.tables(p, d, jnp.concatenate([theta, jnp.full(N_TAB - n, theta[0])]))
    return DS.Tables(*(v[:n] for v in tab))


@pytest.fixture(scope="module")
def tabs():
    th = jnp.asarray([-0.7, 0.0, 0.4, 1.1])
    return th, _tables(S.Params(), DS.DualParams(), th)


def test_h4_normalization_and_tables_vs_brute_force(tabs):
    th, tab = tabs
    np.testing.assert_allclose(np.asarray(tab.a_f + tab.a_b), 1.0, atol=1e-12)
    al = np.array([-5, 2.5, 7.5]) * DEG
    be = np.array([7.5, 3.75, 15.0]) * DEG
    for k, t in enumerate(np.asarray(th)):
        fb, ff = _brute_albedo(S.Params(), t)
        Z = (fb + ff).sum(0)
        np.testing.assert_allclose(np.asarray(tab.a_f[k]), ff.sum(0) / Z, atol=1e-3)
        np.testing.assert_allclose(np.asarray(tab.alpha_f[k]), (ff * al[:, None]).sum(0) / ff.sum(0), atol=1e-4)
        np.testing.assert_allclose(np.asarray(tab.alpha_b[k]), (fb * al[:, None]).sum(0) / fb.sum(0), atol=1e-4)
        np.testing.assert_allclose(np.sqrt(np.asarray(tab.beta_b2[k])), (fb * be[:, None]).sum(0) / fb.sum(0),
                                   atol=1e-4)
    # the artist model itself is not energy conserving (L1715): its albedo scales with I_X ...
    fb, ff = _brute_albedo(S.Params(intensity_r=4, intensity_tt=4, intensity_trt=4), 0.0, 100, 200)
    fb1, ff1 = _brute_albedo(S.Params(), 0.0, 100, 200)
    np.testing.assert_allclose((fb + ff).sum(0), 4 * (fb1 + ff1).sum(0), rtol=1e-12)
    assert np.all((fb + ff).sum(0) > 1.0)
    # ... but the normalized f_s'^norm feeding dual scattering neither vanishes nor blows up
    t4 = _tables(S.Params(intensity_r=4, intensity_tt=4, intensity_trt=4), DS.DualParams(), th[:1])
    np.testing.assert_allclose(np.asarray(t4.a_f + t4.a_b), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(t4.a_f), np.asarray(tab.a_f[:1]), atol=1e-12)


def test_backscatter_formulas(tabs):
    _, tab = tabs
    af, ab = np.asarray(tab.a_f), np.asarray(tab.a_b)
    A = ab * af ** 2 / (1 - af ** 2) + ab ** 3 * af ** 2 / (1 - af ** 2) ** 3
    np.testing.assert_allclose(np.asarray(tab.A_b), A, rtol=1e-12)
    # H6: a_b -> 0 gives A_b -> 0; finite for a_f <= 0.99 (and clamped beyond)
    A0, d0, s0 = DS.backscatter_terms(jnp.asarray([0.5, 0.99, 1.0]), 0.0, 0.1, 0.1, 0.1, 0.2, 0.7)
    np.testing.assert_array_equal(np.asarray(A0), 0.0)
    for v in DS.backscatter_terms(jnp.linspace(0, 1.0, 11), jnp.linspace(1, 0, 11), 0.05, 0.1, 0.1, 0.2, 0.7):
        assert np.all(np.isfinite(np.asarray(v)))
    sq = DS.backscatter_terms(0.5, 0.5, 0.0, 0.0, 0.1, 0.1, 0.7, "square")[0]
    np.testing.assert_allclose(float(sq), 0.5 * 0.25 / 0.75 + 0.125 * 0.25 / 0.75 ** 2, rtol=1e-12)


def _dirs():
    wi = fiber_direction(jnp.asarray([0.3, -0.5, 0.1]), jnp.asarray([0.0, 0.4, -1.0]))
    wo = fiber_direction(jnp.asarray([-0.1, 0.2, 0.6]), jnp.asarray([2.8, 0.3, 1.5]))
    return wi, wo


def test_h3_h6_dual_scattering_limits():
    p, d = S.Params(), DS.DualParams()
    wi, wo = _dirs()
    t0 = DS.dual_scattering_terms(p, d, wi, wo, 0.0, 1.0)
    np.testing.assert_allclose(np.asarray(t0.T_f), 0.7, rtol=1e-14)
    np.testing.assert_array_equal(np.asarray(t0.sigma_f2), 0.0)
    np.testing.assert_allclose(np.asarray(t0.f_back_scatter), np.asarray(t0.f_back_direct), rtol=1e-14)
    np.testing.assert_array_equal(np.asarray(t0.F_scatter), 0.0)   # clamp: (0.7 - 1) -> 0
    # fully lit, d_b = 0: exactly single scattering
    F = DS.dual_scattering(p, d.replace(d_b=0.0), wi, wo, 0.0, 1.0)
    np.testing.assert_allclose(np.asarray(F), np.asarray(S.eval(p, wi, wo)), rtol=1e-14)
    # raw option keeps the negative weight
    traw = DS.dual_scattering_terms(p, DS.DualParams(clamp="raw"), wi, wo, 0.0, 1.0)
    assert np.all(np.asarray(traw.F_scatter) < 0)
    # T_f decreases, sigma_f^2 grows linearly with n
    ns = [0.0, 1.0, 2.0, 5.0, 10.0]  # python numbers, as in the other calls: one compiled program
    Ts, s2 = [], []
    for n in ns:
        t = DS.dual_scattering_terms(p, d, wi, wo, n, 0.3)
        Ts.append(np.asarray(t.T_f))
        s2.append(np.asarray(t.sigma_f2))
    Ts, s2 = np.array(Ts), np.array(s2)
    assert np.all(np.diff(Ts, axis=0) < 0)
    np.testing.assert_allclose(s2, np.asarray(ns)[:, None, None] * s2[1][None], rtol=1e-12)
    # H3: adjusters at their defaults reproduce the unadjusted formulas
    tab = _tables(p, d, jnp.arcsin(wi.x))
    th_h = 0.5 * (jnp.arcsin(wi.x) + jnp.arcsin(wo.x))
    th_d = 0.5 * (jnp.arcsin(wo.x) - jnp.arcsin(wi.x))
    t = DS.dual_scattering_terms(p, d, wi, wo, 3.0, 0.4)
    ref = 2 * tab.A_b * DS.gaussian(th_h[:, None] - tab.delta_b, tab.sigma_b2) / (np.pi * np.cos(th_d)[:, None] ** 2)
    np.testing.assert_allclose(np.asarray(t.f_back_direct), np.asarray(ref), rtol=1e-12)
    ref_s = 2 * tab.A_b * DS.gaussian(th_h[:, None] - tab.delta_b, tab.sigma_b2 + t.sigma_f2) / (
        np.pi * np.cos(th_d)[:, None] ** 2)
    np.testing.assert_allclose(np.asarray(t.f_back_scatter), np.asarray(ref_s), rtol=1e-12)
    # adjusters act only on their own terms
    t2 = DS.dual_scattering_terms(p, d.replace(color_back=(2.0, 1.0, 0.5)), wi, wo, 3.0, 0.4)
    np.testing.assert_allclose(np.asarray(t2.f_back_direct), np.asarray(t.f_back_direct) * [2, 1, 0.5], rtol=1e-12)
    np.testing.assert_array_equal(np.asarray(t2.f_s_scatter), np.asarray(t.f_s_scatter))
    t3 = DS.dual_scattering_terms(p, d.replace(intensity_forward=2.0), wi, wo, 3.0, 0.4)
    np.testing.assert_allclose(np.asarray(t3.f_s_scatter), 2 * np.asarray(t.f_s_scatter), rtol=1e-12)
    np.testing.assert_array_equal(np.asarray(t3.f_back_scatter), np.asarray(t.f_back_scatter))


def test_forward_inclinations_and_precomputed_tables():
    p, d = S.Params(), DS.DualParams()  # the settings of the other dual-scattering tests
    wi, wo = _dirs()
    th_i = jnp.arcsin(wi.x)
    # n hairs with the shading hair's inclination == scalar n (Eqs. 4.23-4.24)
    T, s2 = DS.forward_from_inclinations(p, d, jnp.repeat(th_i[:, None], 4, axis=1))
    t = DS.dual_scattering_terms(p, d, wi, wo, 4.0, 0.2)
    np.testing.assert_allclose(np.asarray(T), np.asarray(t.T_f), rtol=1e-10)
    np.testing.assert_allclose(np.asarray(s2), np.asarray(t.sigma_f2), rtol=1e-10)
    mask = jnp.asarray([[True, True, False, False]] * 3)
    T2, _ = DS.forward_from_inclinations(p, d, jnp.repeat(th_i[:, None], 4, axis=1), mask)
    t2 = DS.dual_scattering_terms(p, d, wi, wo, 2.0, 0.2)
    np.testing.assert_allclose(np.asarray(T2), np.asarray(t2.T_f), rtol=1e-10)
    # precomputed grid + interpolation close to the direct evaluation
    grid = DS.precompute(p, d, 97)
    F1 = DS.dual_scattering(p, d, wi, wo, 4.0, 0.2, tables=grid)
    F0 = DS.dual_scattering(p, d, wi, wo, 4.0, 0.2)
    np.testing.assert_allclose(np.asarray(F1), np.asarray(F0), rtol=2e-3)


def test_mapping_reproduces_marschner_lobes():
    mp = M.Params(caustic="none", fresnel="exact")
    a = S.afc_from_marschner(mp)
    th = jnp.linspace(-1.0, 1.0, 21)   # theta_i = theta_o: theta_d = 0, theta_h = th
    # every call below with three (21,) arrays: one compiled program per lobes function
    full = lambda v: jnp.full(21, v, jnp.float64)  # noqa: E731
    phys = np.asarray(_mlobes(mp, th, th, full(0.0)))
    art = np.asarray(_slobes(a.replace(glint_intensity=0.0), th, th, full(0.0)))
    np.testing.assert_allclose(art[0], phys[0], rtol=1e-9)       # R at phi = 0
    np.testing.assert_allclose(art[2], phys[2], rtol=1e-9)       # TRT off-caustic level at phi = 0
    phys_tt = np.asarray(_mlobes(mp, th, th, full(np.pi - 1e-9)))
    art_tt = np.asarray(_slobes(a, th, th, full(np.pi)))
    np.testing.assert_allclose(art_tt[1], phys_tt[1], rtol=1e-7)  # TT at phi = pi
    # R away from phi = 0: same cos(phi/2) shape up to the dropped Fresnel factor
    phi = jnp.linspace(0.2, 3.0, 21)
    z = jnp.zeros_like(phi)
    ratio = np.asarray(_slobes(a, z, z, phi))[0, :, 0] / np.asarray(_mlobes(mp, z, z, phi))[0, :, 0]
    from appearance_jax.optics.fresnel import fresnel_dielectric
    F = np.asarray(fresnel_dielectric(jnp.cos(phi / 2), 1.55)[0])
    np.testing.assert_allclose(ratio, F[0] * 0 + fresnel_dielectric(1.0, 1.55)[0] / F, rtol=1e-9)
    # glint angle = the MJC03 caustic azimuth; TT spread a few tens of degrees
    assert abs(float(a.glint_angle) - float(M.trt_caustic(1.55, 0.0, jnp.asarray([0.0]), 0.26, 0.3, 0.5, 1)[0])) < 1e-12
    assert 10 * DEG < float(a.gamma_tt) < 60 * DEG


def test_dual_gradients_and_finite():
    wi, wo = _dirs()
    d = DS.DualParams(n_quad=24)

    def f(x):
        p = S.Params(beta_r=x[0], gamma_tt=x[1], intensity_tt=x[2])
        return jnp.sum(DS._dual_kernel(p, d, wi, wo, 3.0, 0.3))

    # values and the reverse-mode derivative from one compiled value_and_grad (grad of the jitted f
    # compiles its forward and backward passes separately, and jit(f) a third program); the
    # finite differences difference its values
    vg = jax.jit(jax.value_and_grad(f))
    testing.assert_gradients(lambda x: vg(x)[0], jnp.asarray([0.15, 0.5, 1.2]), rtol=1e-5, atol=1e-9,
                             elementwise=True, name="dual scattering", grad_fn=lambda x: vg(x)[1])
    # axis-aligned / grazing directions stay finite (with the DualParams of the other tests)
    wa = fiber_direction(jnp.asarray([np.pi / 2, -np.pi / 2, 0.0]), jnp.asarray([0.0, 0.0, 0.0]))
    wb = fiber_direction(jnp.asarray([-np.pi / 2, np.pi / 2, 0.0]), jnp.asarray([0.0, 0.0, np.pi]))
    assert np.all(np.isfinite(np.asarray(DS.dual_scattering(S.Params(), DS.DualParams(), wa, wb, 2.0, 0.5))))
    assert np.all(np.isfinite(np.asarray(S.eval(S.Params(), wa, wb))))


def test_bad_parameters_raise():
    wi, wo = _dirs()
    with pytest.raises(ValueError, match="gamma_tt"):
        S.eval(S.Params(gamma_tt=0.0), wi, wo)
    with pytest.raises(ValueError, match="d_f"):
        DS.dual_scattering(S.Params(), DS.DualParams(d_f=1.5), wi, wo)
    with pytest.raises(ValueError, match="a_b_denominator"):
        DS.DualParams(a_b_denominator="cubic")
