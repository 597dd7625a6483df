"""Marschner et al. 2003 hair BCSDF against independent references: brute-force root search,
the flatland smooth-cylinder tracer (per-lobe azimuthal distributions, caustics), symmetry,
reciprocity, normalisation, gradients and degenerate directions."""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import flatland, testing
from appearance_jax.bcsdf import dual_scattering as DS
from appearance_jax.bcsdf import marschner as M
from appearance_jax.bcsdf.fiber import bravais_eta
from appearance_jax.core.frame import fiber_direction
from appearance_jax.core.quadrature import gauss_legendre
from appearance_jax.core.vec import Vec3

_azimuthal_jit = jax.jit(M.azimuthal)
_N_AZ = 36 * 400  # azimuths per call: the flatland comparison's grid (36 bins x 400 midpoints)


def _azimuthal(params, phi, theta_d):
    """M.azimuthal at the azimuths ``phi`` (any shape, at most _N_AZ of them) and a scalar
    theta_d, padded to _N_AZ azimuths so that every call of the module runs one compiled
    program per static configuration of ``params``; shape (3,) + phi.shape + bands."""
    phi = np.asarray(phi, dtype=float)
    flat = np.zeros(_N_AZ)
    flat[:phi.size] = phi.ravel()
    out = np.asarray(_azimuthal_jit(params, jnp.asarray(flat), jnp.asarray(theta_d, dtype=jnp.float64)))
    return out[:, :phi.size].reshape((3,) + phi.shape + out.shape[-1:])


def _brute_roots(hh, ph, phi):
    g = (ph - phi + np.pi) % (2 * np.pi) - np.pi
    idx = np.where((np.sign(g[:-1]) != np.sign(g[1:])) & (np.abs(g[:-1]) < 0.5))[0]
    # linear interpolation inside the bracket
    return np.sort(hh[idx] - g[idx] * (hh[idx + 1] - hh[idx]) / (g[idx + 1] - g[idx]))


@functools.partial(jax.jit, static_argnums=0)
def _roots_and_phases(p, phis, eta_p, hh):
    """M.roots at phis, Phi(p, .) at those roots and on the brute-force grid hh: one compiled
    program per lobe p (eta_p is traced, so the three indices share it; op by op, the bisection
    and every array shape of the checks below compiled separately)."""
    r = M.roots(p, phis, eta_p)
    return r.h, r.valid, M.exit_phi(p, r.h, eta_p), M.exit_phi(p, hh, eta_p)


@pytest.mark.parametrize("eta_p", [1.55, 1.8, 2.3])
@pytest.mark.parametrize("p", [0, 1, 2])
def test_roots_match_brute_force(p, eta_p):
    # avoid phi = 0 exactly (a double grid root); dense near 0 for the three-root region
    phis = np.concatenate([np.linspace(-3.1, 3.1, 32) + 0.0123, np.linspace(-0.3, 0.3, 13) + 0.0017])
    hh = np.linspace(-1.0, 1.0, 200001)
    h, v, ph_roots, ph = (np.asarray(a) for a in _roots_and_phases(p, jnp.asarray(phis), eta_p, jnp.asarray(hh)))
    n_multi = 0
    for k, f in enumerate(phis):
        bf = _brute_roots(hh, ph, f)
        order = np.argsort(h[v[:, k], k])
        mine = h[v[:, k], k][order]
        assert len(mine) == len(bf), (p, eta_p, f, bf, mine)
        np.testing.assert_allclose(mine, bf, atol=1e-6)
        # each root really solves Phi = phi (mod 2 pi)
        res = (ph_roots[v[:, k], k][order] - f + np.pi) % (2 * np.pi) - np.pi
        np.testing.assert_allclose(res, 0.0, atol=1e-10)
        n_multi += len(mine) == 3
    if p == 2 and eta_p < 2:
        assert n_multi > 0  # the three-root region near phi = 0 was exercised


def test_root_gradient_is_implicit_derivative():
    # |AD - FD| <= 5e-7 (1 + |FD|) <= 1e-6 max(1, |FD|). Values and derivative from one compiled
    # value_and_grad (the finite differences difference its values)
    vg = jax.jit(jax.value_and_grad(lambda e: M.roots(1, 0.9, e).h[0]))
    testing.assert_gradients(lambda e: vg(e)[0], 1.6, rtol=5e-7, atol=5e-7, name="roots", grad_fn=lambda e: vg(e)[1])


def _flatland_bins(eta, sigma_a, theta_i, edges):
    sec = flatland.fiber(eta, sigma_a)
    wi = fiber_direction(jnp.asarray(theta_i), jnp.asarray(0.0))
    sl = flatland.smooth_lobes(sec, wi, 4096)
    phi = (np.asarray(sl.phi) + np.pi) % (2 * np.pi) - np.pi
    w = np.asarray(sl.power)[..., 0] * np.asarray(sl.weight)[None, :]
    lobe = np.asarray(sl.lobe)
    out = []
    for p in range(3):
        m = lobe == p
        out.append(np.histogram(phi[m], edges, weights=w[m])[0])
    return np.array(out), np.asarray(sl.albedo)[:3, 0]


def _model_bins(params, theta_d, edges, per_bin=400):
    x = (np.arange(per_bin) + 0.5) / per_bin
    lo, hi = edges[:-1], edges[1:]
    phis = lo[:, None] + (hi - lo)[:, None] * x[None, :]
    N = _azimuthal(params, phis, theta_d)[..., 0]
    return N.mean(-1) * (hi - lo)[None, :]


@pytest.mark.parametrize("theta_i", [0.0, pytest.param(0.5, marks=pytest.mark.slow)])
def test_azimuthal_distribution_matches_flatland(theta_i):
    eta, sa = 1.55, 0.4
    edges = np.linspace(-np.pi, np.pi, 37)
    ref, alb = _flatland_bins(eta, sa, theta_i, edges)
    # on the specular cone theta_o = -theta_i, so theta_d = -theta_i. The model's bands 1, 2 are
    # not compared: its sigma_a (and static settings) are those of
    # test_smooth_peaks_and_r_lobe_closed_form, which shares the compiled program
    pr = M.Params(eta=eta, sigma_a=(sa, 0.3, 0.5), fresnel="exact", caustic="none")
    mine = _model_bins(pr, -theta_i, edges)
    # R and TT: smooth densities, per-bin agreement to 1e-4 absolute (albedos 0.05 .. 0.5)
    np.testing.assert_allclose(mine[0], ref[0], atol=1e-4)
    np.testing.assert_allclose(mine[1], ref[1], atol=2e-4)
    # TRT: the caustic singularity limits the midpoint rule; totals to 1 %, bins to 5e-4
    np.testing.assert_allclose(mine[2], ref[2], atol=5e-4)
    np.testing.assert_allclose(mine.sum(1)[:2], alb[:2], rtol=1e-3)
    np.testing.assert_allclose(mine.sum(1)[2], alb[2], rtol=3e-2)
    # exact per-lobe albedo (1/2) int A(p, h) dh (Gauss-Legendre in h = sin u) vs flatland
    u, wu = gauss_legendre(256, -math.pi / 2, math.pi / 2)
    h, wh = jnp.asarray(np.sin(u)), jnp.asarray(0.5 * wu * np.cos(u))
    np.testing.assert_allclose(np.asarray(_lobe_albedos(h, wh, eta, -theta_i, jnp.asarray([sa]))), alb[:3], rtol=1e-6)


@jax.jit
def _lobe_albedos(h, wh, eta, theta_d, sigma_a):
    """(1/2) int A(p, h) dh of the R, TT, TRT attenuations (exact Fresnel), band 0, one program."""
    return jnp.stack([M.attenuation(p, h, eta, theta_d, sigma_a, "exact")[:, 0] @ wh for p in range(3)])


@jax.jit
def _caustic(eta, theta):
    """(h_c, phi_c) of the model: M.caustic_offset at Bravais' eta' and M.trt_caustic's azimuth."""
    return M.caustic_offset(bravais_eta(eta, theta)), M.trt_caustic(eta, theta, jnp.asarray([0.0]), 0.2, 0.3, 0.5,
                                                                    1.0)[0]


def test_trt_caustic_position_matches_flatland():
    eta = 1.55
    for theta in (0.0, 0.4, 0.8):
        wi = fiber_direction(jnp.asarray(theta), jnp.asarray(0.0))
        c = flatland.caustics(flatland.fiber(eta, 0.0), wi, 2)
        ref_h = np.sort(np.abs(np.asarray(c.h)[np.asarray(c.valid)]))
        ref_phi = np.sort(np.abs(np.asarray(c.phi)[np.asarray(c.valid)]))
        hc, phi_c = (float(v) for v in _caustic(eta, theta))
        np.testing.assert_allclose(ref_h, [hc, hc], atol=1e-7)
        np.testing.assert_allclose(ref_phi, [phi_c] * 2, atol=1e-6)
    # eta' >= 2: no caustic, phi_c = 0
    assert float(_caustic(2.2, 0.0)[1]) == 0.0


def _dirs(key, n):
    k1, k2 = jax.random.split(key)
    th = jax.random.uniform(k1, (2, n), minval=-1.4, maxval=1.4)
    ph = jax.random.uniform(k2, (2, n), minval=-np.pi, maxval=np.pi)
    return fiber_direction(th[0], ph[0]), fiber_direction(th[1], ph[1]), th, ph


def test_symmetry_and_reciprocity():
    wi, wo, th, ph = _dirs(jax.random.PRNGKey(1), 256)
    for pr in (M.Params(), M.Params(axis_ratio=0.85, fresnel="exact", chord="mjc03")):
        f = M.eval(pr, wi, wo)
        np.testing.assert_allclose(M.eval(pr, wo, wi), f, rtol=1e-9, atol=1e-12)
        assert np.all(np.isfinite(f)) and np.all(f >= 0)
    # S(phi) = S(-phi) for the circular fiber (mirror both azimuths)
    pr = M.Params()
    wi2, wo2 = fiber_direction(th[0], -ph[0]), fiber_direction(th[1], -ph[1])
    np.testing.assert_allclose(M.eval(pr, wi2, wo2), M.eval(pr, wi, wo), rtol=1e-9, atol=1e-12)


def test_longitudinal_normalisation():
    x, w = gauss_legendre(200, -math.pi / 2, math.pi / 2)
    Mx = np.asarray(M.longitudinal(M.Params(), jnp.asarray(x)))
    np.testing.assert_allclose(Mx @ w, 1.0, atol=1e-9)
    # halved variant: unit integral over theta_o at fixed theta_i
    th_i = 0.2
    to, wt = gauss_legendre(400, -math.pi / 2, math.pi / 2)
    Mh = np.asarray(M.longitudinal(M.Params(longitudinal="half"), 0.5 * (th_i + jnp.asarray(to))))
    np.testing.assert_allclose(Mh @ wt, 1.0, atol=5e-3)   # tails beyond +-pi/2 of the TRT lobe


def test_smooth_peaks_and_r_lobe_closed_form():
    sig = np.array([0.4, 0.3, 0.5])
    pr = M.Params(sigma_a=tuple(sig), fresnel="exact", caustic="none")
    # N_R(phi) = F(gamma_i) cos(phi/2) / 4 with gamma_i = -phi/2; the last azimuth is TT's peak
    phi = np.append(np.linspace(-3.0, 3.0, 25), np.pi - 1e-9)
    n = _azimuthal(pr, phi, 0.0)
    n_r = n[0, :25, 0]
    from appearance_jax.optics.fresnel import fresnel_dielectric
    F = np.asarray(fresnel_dielectric(jnp.cos(jnp.asarray(phi[:25]) / 2), 1.55)[0])
    np.testing.assert_allclose(n_r, F * np.cos(phi[:25] / 2) / 4, rtol=1e-9)
    # TT at phi = pi: (1 - F0)^2 T / (4 (1 - 1/eta'))
    n_tt = n[1, 25]
    F0 = ((1.55 - 1) / 2.55) ** 2
    np.testing.assert_allclose(n_tt, (1 - F0) ** 2 * np.exp(-2 * sig) / (4 * (1 - 1 / 1.55)), rtol=1e-7)


def test_energy_physical_tables():
    """H5: sigma_a = 0, Fresnel on: a_f + a_b <= 1 up to the cos^2 theta_d approximation for
    the halved longitudinal; the literal MJC03 M integrates to ~2 over theta_o."""
    th = jnp.asarray([0.0, 0.6])
    half = DS.tables(M.Params(sigma_a=0.0, longitudinal="half", caustic="none"), DS.DualParams(n_quad=48), th)
    tot = np.asarray(half.a_f + half.a_b)[:, 0]
    assert np.all(tot <= 1.05) and np.all(tot > 0.85), tot
    lit = DS.tables(M.Params(sigma_a=0.0, caustic="none"), DS.DualParams(n_quad=48), th)
    np.testing.assert_allclose(np.asarray(lit.a_f + lit.a_b)[:, 0], 2 * tot, rtol=1e-9)


def test_gradients_match_finite_differences():
    wi = fiber_direction(jnp.asarray([0.3, -0.2]), jnp.asarray([0.0, 0.4]))
    wo = fiber_direction(jnp.asarray([-0.1, 0.5]), jnp.asarray([2.0, -0.6]))

    def f(x):
        pr = M.Params(eta=x[0], sigma_a=x[1], alpha=x[2], beta=x[3], glint_scale=x[4])
        return jnp.sum(M.eval.kernel(pr, wi, wo))

    # values and the reverse-mode derivative from one compiled value_and_grad (grad of the jitted f
    # compiles its forward and backward passes separately, and jit(f) a third program); the
    # finite differences difference its values
    vg = jax.jit(jax.value_and_grad(f))
    testing.assert_gradients(lambda x: vg(x)[0], jnp.asarray([1.55, 0.3, -0.08, 0.12, 0.7]), step=1e-6 / 1.55,
                             rtol=1e-5, atol=1e-8, elementwise=True, name="marschner", grad_fn=lambda x: vg(x)[1])


def test_degenerate_directions_finite():
    """eval is finite at degenerate pairs (along the axis, grazing, phi = pi, near the caustic) and
    0 when both directions lie along the axis (cos theta_d = 0). The pairs fill the first 14 of
    the 256 pairs of test_symmetry_and_reciprocity (the rest stay random): the default model's
    eval is the program compiled there."""
    th = jnp.asarray([np.pi / 2, -np.pi / 2, 0.0, 0.0, 1.5, 1.3, 0.0])
    ph = jnp.asarray([0.0, 0.0, 0.0, np.pi, 0.0, 0.3, 0.3249061599])
    wi, wo = fiber_direction(th, ph * 0), fiber_direction(-th[::-1], ph)
    # both directions along the axis: 7 copies
    ai = fiber_direction(jnp.full(7, -np.pi / 2), jnp.zeros(7))
    ao = fiber_direction(jnp.full(7, np.pi / 2), jnp.zeros(7))
    ri, ro, _, _ = _dirs(jax.random.PRNGKey(1), 256)
    wi, wo = (Vec3(*(jnp.concatenate([a, b, c[14:]]) for a, b, c in zip(d, e, r))) for d, e, r in ((wi, ai, ri),
                                                                                                       (wo, ao, ro)))
    for k, pr in enumerate((M.Params(), M.Params(eta=3.5, axis_ratio=0.5, fade="literal"))):
        f = np.asarray(M.eval(pr, wi, wo))
        assert np.all(np.isfinite(f))
        if k == 0:
            assert np.all(f[7:14] == 0.0)


@pytest.mark.slow
def test_degenerate_directions_have_finite_gradients():
    th = jnp.asarray([np.pi / 2, -np.pi / 2, 0.0, 0.0, 1.5, 1.3, 0.0])
    ph = jnp.asarray([0.0, 0.0, 0.0, np.pi, 0.0, 0.3, 0.3249061599])
    wi = fiber_direction(th, ph * 0)
    wo = fiber_direction(-th[::-1], ph)
    gfun = jax.jit(jax.grad(lambda pr: jnp.sum(M.eval.kernel(pr, wi, wo))))
    for pr in (M.Params(), M.Params(eta=3.5, axis_ratio=0.5, fade="literal")):
        g = gfun(pr)
        assert all(np.all(np.isfinite(np.asarray(v))) for v in jax.tree_util.tree_leaves(g))


def test_bad_parameters_raise():
    wi = fiber_direction(jnp.asarray(0.1), 0.0)
    with pytest.raises(ValueError, match="eta"):
        M.eval(M.Params(eta=0.9), wi, wi)
    with pytest.raises(ValueError, match="sigma_a"):
        M.eval(M.Params(sigma_a=(-1.0, 0.0, 0.0)), wi, wi)
    with pytest.raises(ValueError, match="fresnel"):
        M.Params(fresnel="schlick")
