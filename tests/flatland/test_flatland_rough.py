"""The flatland tracer with rough (cuticle) interfaces, medullas and periodic rows.

- the camera-side next-event estimator's R lobe equals an independent quadrature of
  Eq. 4.12 / 4.28 (Huang 2022; meso NDF, macro cosines, separable Smith) on the circle and
  on an ellipse (arc-length element and D_o);
- forward histograms agree with next-event estimates for R, TT and TRT (4 sigma);
- reciprocity D_o S(i, o) = D_i S(o, i) for a tilted rough ellipse (H-6);
- white furnace: lobes + lost + residual = 1, the microsurface loss vanishes as the
  roughness -> 0; medullas in random mode conserve energy in expectation;
- gradients of common-random-number estimates w.r.t. roughness, tilt and absorption vs
  central differences of the same estimates;
- periodic rows: the covered fraction equals the closed form of spec M23;
- bad input raises errors that name the parameter.

Statistical tolerances: 4 combined standard errors (fixed keys).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import flatland as fl, testing
from appearance_jax.core.frame import Frame, fiber_direction
from appearance_jax.core.vec import Vec3, dot, normalize
from appearance_jax.microfacet import distribution as mf
from appearance_jax.optics.fresnel import fresnel_dielectric

KEY = jax.random.PRNGKey(7)
# Compilation dominates: nee_bcsdf compiles one program per (paths, lobes, events) and section
# layout. The next-event estimates below therefore all run NEE_PATHS paths, NEE_LOBES lobes and
# NEE_EVENTS events on a one-shape rough fiber (one program): a test that needs fewer lobes or
# events reads the first ones (R, TT and TRT end within 3 events; the first hit's connection,
# the R estimate, does not depend on later events).
NEE_PATHS, NEE_LOBES, NEE_EVENTS = 2 ** 14, 4, 8


def _dir(theta, phi):
    """fiber_direction of float64 angles: from Python floats the direction is weakly typed, a
    different signature for the tracer, which then compiles its program once more."""
    return fiber_direction(np.float64(theta), np.float64(phi))


@jax.jit
def _r_integrand(ny, nz, wi, wo, eta, alpha):
    """F D G1(i) G1(o) / 4 at the ellipse points of normal (0, ny, nz), 0 where either direction
    is below the surface (one compiled program: eagerly its ~35 operations compile one by one)."""
    n = ny.shape[0]
    N = Vec3(jnp.zeros(n), ny, nz)
    fr = Frame.from_normal_tangent(N, Vec3(jnp.ones(n), jnp.zeros(n), jnp.zeros(n)))
    il = fr.to_local(Vec3(*[jnp.broadcast_to(c, (n,)) for c in wi]))
    ol = fr.to_local(Vec3(*[jnp.broadcast_to(c, (n,)) for c in wo]))
    h = normalize(il + ol)
    F, _, _, _ = fresnel_dielectric(jnp.abs(dot(il, h)), eta)
    val = F * mf.D("ggx", h, alpha, alpha) * mf.G1("ggx", il, h, alpha) * mf.G1("ggx", ol, h, alpha) / 4
    return jnp.where((il.z > 0) & (ol.z > 0), val, 0.0)


def r_lobe_quadrature(wi, wo, eta, alpha, b=1.0, n=20001):
    """S_R cos(theta_i) = 1 / (2 D_o cos(theta_o)) int F D G1(i) G1(o) / 4 dl over the
    points of the ellipse y^2/b^2 + z^2 = 1 that see both directions (Eqs. 4.12, 4.28)."""
    g = np.linspace(-np.pi, np.pi, n)
    ny, nz = np.cos(g) / b, np.sin(g)
    nn = np.hypot(ny, nz)
    ny, nz = ny / nn, nz / nn
    dl = np.hypot(b * np.sin(g), np.cos(g))          # |dp/dgamma|
    val = np.asarray(_r_integrand(jnp.asarray(ny), jnp.asarray(nz), wi, wo, eta, alpha))
    u = np.array([float(wo.y), float(wo.z)])
    u /= np.linalg.norm(u)
    D_o = np.sqrt(b * b * u[1] ** 2 + u[0] ** 2)
    cos_o = np.sqrt(float(wo.y) ** 2 + float(wo.z) ** 2)
    return np.trapezoid(val * dl, g) / (2 * D_o * cos_o)


@pytest.mark.parametrize("ecc", [0.0, 0.8])
def test_nee_r_lobe_equals_quadrature_of_eq_4_12(ecc):
    eta, alpha = 1.55, 0.25
    sec = fl.fiber(eta, roughness=alpha, eccentricity=ecc)
    wi = _dir(0.3, 0.4)
    b = np.sqrt(1 - ecc ** 2)
    for th, ph in [(-0.4, 0.5), (-0.2, 2.0), (-0.5, -1.2), (-0.3, 3.0)]:
        wo = _dir(th, ph)
        v, se = fl.nee_bcsdf(sec, wi, wo, KEY, NEE_PATHS, n_lobes=NEE_LOBES, max_events=NEE_EVENTS)
        ref = r_lobe_quadrature(wi, wo, eta, alpha, b)
        assert abs(float(v[0, 0]) - ref) < 4 * float(se[0, 0]) + 1e-9 * ref, (th, ph, float(v[0, 0]), ref)


def test_histogram_agrees_with_next_event_estimates_per_lobe():
    sec = fl.fiber(1.55, 0.2, roughness=0.3)
    wi = _dir(0.3, 0.0)
    hist = fl.trace_fiber(sec, wi, KEY, 2 ** 18, n_theta=60, n_phi=120, chunk=2 ** 15, max_events=8)
    b = fl.bcsdf_from_histogram(hist)
    S, se = np.asarray(b.S[..., 0]) * np.cos(0.3), np.asarray(b.S_se[..., 0]) * np.cos(0.3)
    checked = 0
    for p in range(3):
        # the three best-resolved bins of each lobe (relative standard error < 10 %)
        ratio = np.where(se[p] > 0, S[p] / np.where(se[p] > 0, se[p], 1.0), 0.0)
        best = np.argsort(ratio, axis=None)[::-1][:3]
        assert ratio.reshape(-1)[best[-1]] > 10, p
        for it, ip in zip(*np.unravel_index(best, ratio.shape)):
            wo = fiber_direction(b.theta[it], b.phi[ip])
            v, sv = fl.nee_bcsdf(sec, wi, wo, jax.random.PRNGKey(3), NEE_PATHS, n_lobes=NEE_LOBES,
                                 max_events=NEE_EVENTS)
            # a 3 x 3 degree bin average vs the value at its centre: allow 2 % curvature bias
            tol = 4 * np.hypot(se[p, it, ip], float(sv[p, 0])) + 0.02 * S[p, it, ip]
            assert abs(S[p, it, ip] - float(v[p, 0])) < tol, (p, it, ip, S[p, it, ip], float(v[p, 0]))
            checked += 1
    assert checked == 9


def test_reciprocity_of_a_tilted_rough_ellipse():
    ecc = 0.7
    sec = fl.fiber(1.55, roughness=0.2, tilt=np.radians(3.0), eccentricity=ecc)
    for (ti, pi_), (to, po) in [((0.3, 0.2), (-0.1, 1.9)), ((-0.2, 1.0), (0.4, -0.8))]:
        wi, wo = _dir(ti, pi_), _dir(to, po)
        a, sa = fl.nee_bcsdf(sec, wi, wo, KEY, NEE_PATHS, n_lobes=NEE_LOBES, max_events=NEE_EVENTS)  # S(i, o) cos_i
        b, sb = fl.nee_bcsdf(sec, wo, wi, KEY, NEE_PATHS, n_lobes=NEE_LOBES, max_events=NEE_EVENTS)  # S(o, i) cos_o
        D = lambda phi: np.sqrt(1 - ecc ** 2 * np.sin(phi) ** 2)
        lhs, lhs_se = D(po) * a / np.cos(ti), D(po) * sa / np.cos(ti)
        rhs, rhs_se = D(pi_) * b / np.cos(to), D(pi_) * sb / np.cos(to)
        for p in range(3):
            assert abs(float(lhs[p, 0] - rhs[p, 0])) < 4 * float(np.hypot(lhs_se[p, 0], rhs_se[p, 0])) + 1e-12


def test_white_furnace_and_microsurface_loss():
    wi = fiber_direction(0.4, 0.0)
    losses = []
    for alpha in (0.3, 0.1, 0.01):
        hist = fl.trace_fiber(fl.fiber(1.55, roughness=alpha), wi, KEY, 2 ** 14, n_theta=2, n_phi=2,
                              max_events=24)
        total = float(hist.albedo.sum() + hist.lost[0] + hist.residual[0] + hist.absorbed[0])
        assert abs(total - 1.0) < 1e-9          # split mode: exact per path
        losses.append(float(hist.lost[0]))
    assert losses[0] > losses[1] > losses[2]
    assert losses[2] < 2e-3                     # -> 0 as the roughness -> 0


@pytest.mark.slow  # a second histogram program (a smooth fiber's): the tallies' bookkeeping is
# checked by default above, a smooth fiber's zero loss and exact split-mode sum by
# test_flatland_smooth.py::test_energy_bookkeeping_is_exact_in_split_mode
def test_white_furnace_of_a_smooth_fiber():
    wi = fiber_direction(0.4, 0.0)
    smooth = fl.trace_fiber(fl.fiber(1.55), wi, KEY, 2 ** 12, n_theta=2, n_phi=2, max_events=24)
    assert float(smooth.lost[0]) == 0.0
    assert abs(float(smooth.albedo.sum() + smooth.residual[0]) - 1.0) < 1e-12


def test_diffuse_medulla_conserves_energy_in_expectation_and_leaves_the_cone():
    sec = fl.fiber(1.55, medulla=(0.1, -0.1, 0.6, 0.6), medulla_albedo=1.0)
    wi = fiber_direction(0.5, 0.0)
    n = 2 ** 14
    h = (jnp.arange(n) + 0.5) / n * 2 - 1
    rec = fl.trace(sec, wi, h, KEY, max_events=40, mode="split")
    per_path = np.asarray(rec.weight.sum(0)[:, 0] + rec.residual[:, 0] + rec.lost[:, 0] + rec.absorbed[:, 0])
    assert abs(per_path.mean() - 1.0) < 4 * per_path.std() / np.sqrt(n) + 1e-12
    th = np.arcsin(np.asarray(rec.direction.x))
    w = np.asarray(rec.weight[..., 0])
    off_cone = w[np.abs(th + 0.5) > 1e-6].sum() / w.sum()
    assert off_cone > 0.05                      # medulla-scattered light leaves the specular cone
    # an absorbing medulla (d_m = 0) is a pure absorber region
    black = fl.fiber(1.55, medulla=(0.0, 0.0, 0.6, 0.6), medulla_kind="absorber")
    rb = fl.trace(black, wi, h, KEY, max_events=40)
    assert float(rb.absorbed.mean()) > 0.3
    np.testing.assert_allclose(np.asarray(rb.weight.sum(0) + rb.absorbed + rb.lost + rb.residual), 1.0,
                               atol=1e-12)


def test_a_shape_switched_off_as_data_is_not_there():
    """Shape.present: with the medulla switched off (a traced False) a fiber traces as the same fiber
    without it, values and d/d(sigma_a), with the same key, in the one program that traces it switched on
    (which equals the plain medulla fiber). bsdf.feather runs its barbules this way."""
    from dataclasses import replace
    wi = fiber_direction(0.4, 0.3)
    n = 256
    h = (jnp.arange(n) + 0.5) / n * 2 - 1
    sig = jnp.asarray([0.2, 0.5, 1.0])

    def sec(sigma_a, medulla=True):
        return fl.fiber(1.55, sigma_a, medulla=(0.1, -0.1, 0.5, 0.5) if medulla else None, medulla_albedo=0.7)

    def total(sigma_a, present):
        s = sec(sigma_a)
        s = replace(s, shapes=(s.shapes[0], replace(s.shapes[1], present=present)))
        r = fl.trace(s, wi, h, KEY, max_events=12)
        return jnp.sum(r.weight[..., 0] * r.direction.y), r

    f = jax.jit(jax.value_and_grad(total, has_aux=True))
    (v_on, r_on), g_on = f(sig, jnp.asarray(True))
    (v_off, r_off), g_off = f(sig, jnp.asarray(False))
    assert f._cache_size() == 1

    def plain(sigma_a, medulla):
        r = fl.trace(sec(sigma_a, medulla), wi, h, KEY, max_events=12)
        return jnp.sum(r.weight[..., 0] * r.direction.y), r

    for (v, r), g, medulla in (((v_on, r_on), g_on, True), ((v_off, r_off), g_off, False)):
        (v_ref, r_ref), g_ref = jax.value_and_grad(plain, has_aux=True)(sig, medulla)
        np.testing.assert_allclose(np.asarray(r.weight), np.asarray(r_ref.weight), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(np.asarray(r.absorbed), np.asarray(r_ref.absorbed), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(float(v), float(v_ref), rtol=1e-12)
        np.testing.assert_allclose(np.asarray(g), np.asarray(g_ref), rtol=1e-10, atol=1e-14)
        assert np.all(np.isfinite(np.asarray(g)))
    # the medulla matters here (else the test could not tell the two apart)
    assert abs(float(v_on) - float(v_off)) > 1e-3 * abs(float(v_off))
    with pytest.raises(ValueError, match=r"shapes\[1\]\.present = 2"):
        s = sec(sig)
        fl.trace(replace(s, shapes=(s.shapes[0], replace(s.shapes[1], present=2))), wi, h, KEY)


def test_gradients_of_crn_estimates_match_finite_differences():
    """Forward-mode autodiff of the next-event estimate (common random numbers) w.r.t.
    (roughness, tilt, sigma_a). R has no random choice: autodiff == central differences of
    the same estimate. TT: absorption enters smoothly (compared per key), but the
    reflect/transmit choice makes the estimate piecewise smooth in the roughness, so the
    mean derivative over keys is compared with the mean difference quotient (4 SE)."""
    wi, wo = fiber_direction(0.3, 0.0), fiber_direction(-0.35, 2.2)

    def lobes_(x, key):
        sec = fl.fiber(1.55, x[2], roughness=x[0], tilt=x[1])
        v, _ = fl.nee_bcsdf(sec, wi, wo, key, 2 ** 11, n_lobes=3, max_events=4)
        return v[:, 0]

    # one compiled program, a jvp along a given direction, gives a Jacobian column and the values:
    # the difference quotients reuse it instead of compiling the estimate on its own (and it
    # compiles faster than jacfwd's vmapped program with the values as aux)
    jvp = jax.jit(lambda x, key, v: jax.jvp(lambda y: lobes_(y, key), (x,), (v,)))
    e = np.eye(3)
    jac = lambda x, key: np.stack([np.asarray(jvp(x, key, e[k])[1]) for k in range(3)], -1)
    lobes = lambda x, key: jvp(x, key, e[0])[0]
    x = np.array([0.2, 0.04, 0.5])

    def fd(key, k, h):
        return (lobes(x + h * e[k], key) - lobes(x - h * e[k], key)) / (2 * h)

    J = np.asarray(jac(x, KEY))
    names = ("roughness", "tilt", "sigma_a")
    for lobe, fields in ((0, ("roughness", "tilt")), (1, ("sigma_a",))):  # R: roughness, tilt; TT: absorption
        r = testing.assert_gradients(lambda d: lobes(jnp.stack([d[n] for n in names]), KEY)[lobe],
                                     dict(zip(names, np.asarray(x))), fields=fields, step=1e-6, rtol=1e-5, atol=0.0,
                                     elementwise=True, grad_fn=lambda d: dict(zip(names, J[lobe])),
                                     name=f"lobe {lobe}")
        assert all(abs(q[0]) > 1e-3 for q in r.fd), r.message
    assert r.fd[0][0] < 0  # TT darkens with absorption
    ad, fdq = [], []
    for i in range(8):                                 # TT + TRT: roughness, over keys
        key = jax.random.PRNGKey(100 + i)
        ad.append(float(jvp(x, key, e[0])[1][1:].sum()))   # the roughness column
        fdq.append(float(fd(key, 0, 2e-3)[1:].sum()))
    diff = np.array(ad) - np.array(fdq)
    assert abs(diff.mean()) < 4 * diff.std(ddof=1) / np.sqrt(len(diff)) + 1e-3 * abs(np.mean(ad))
    assert abs(np.mean(ad)) > 4 * np.std(ad, ddof=1) / np.sqrt(len(ad))   # resolved


@pytest.mark.parametrize("ax, ay, P", [(0.5, 0.5, 2.0), (0.5, 0.25, 1.3)])
def test_periodic_row_covered_fraction_equals_closed_form(ax, ay, P):
    """w'_bb(psi) = min(1, W(psi) / (P cos psi)), W = 2 sqrt(a_x^2 cos^2 + a_y^2 sin^2) (M23)."""
    # 4 neighbours per event (default 8; the tracer unrolls them, so fewer compile faster): the
    # rays here reach at most 3.5 periods, and trunc = 0 below checks that none needed more, so
    # the fraction is the one the default gives
    sec = fl.ellipse_row(P, ax, ay, copies=4)
    for psi in (0.0, 0.5, 1.0, 1.3):
        wo = Vec3(jnp.asarray(0.0), jnp.asarray(np.sin(psi)), jnp.asarray(np.cos(psi)))
        m, se, trunc = fl.masking_fraction(sec, wo, KEY, 2 ** 14)
        W = 2 * np.sqrt(ax ** 2 * np.cos(psi) ** 2 + ay ** 2 * np.sin(psi) ** 2)
        ref = min(1.0, W / (P * np.cos(psi)))
        # stratified launch: the error is far below the binomial standard error
        assert abs(float(m) - ref) < max(4 * float(se), 1e-3)
        assert float(trunc) == 0.0


def test_open_half_circles_cover_their_projected_width():
    """Upper / lower half circles of radius r seen at psi project onto r (1 + cos psi)
    (the full circle: 2r), so the covered fraction is r (1 + cos psi) / (P cos psi)."""
    r, P = 0.5, 2.0
    for arc in ((0.0, np.pi), (np.pi, np.pi)):
        sec = fl.ellipse_row(P, r, r, arc=arc, copies=1)  # (these rays reach 0.84 periods; trunc = 0 checked)
        for psi in (0.3, 0.6):
            wo = Vec3(jnp.asarray(0.0), jnp.asarray(np.sin(psi)), jnp.asarray(np.cos(psi)))
            m, se, trunc = fl.masking_fraction(sec, wo, KEY, 2 ** 14)
            assert abs(float(m) - r * (1 + np.cos(psi)) / (P * np.cos(psi))) < max(4 * float(se), 1e-3)
            assert float(trunc) == 0.0


def test_bad_input_names_the_parameter():
    with pytest.raises(ValueError, match="roughness"):
        fl.fiber(1.55, roughness=1.5)
    with pytest.raises(ValueError, match="eccentricity"):
        fl.fiber(1.55, eccentricity=1.0)
    with pytest.raises(ValueError, match=r"media\[1\].sigma_a"):
        fl.fiber(1.55, -0.1)
    with pytest.raises(ValueError, match=r"media\[1\].eta"):
        fl.fiber(-1.0)
    with pytest.raises(ValueError, match="h must lie"):
        fl.trace(fl.fiber(1.5), fiber_direction(0.1, 0.0), jnp.array([1.5]))
    with pytest.raises(ValueError, match="mode"):
        fl.trace(fl.fiber(1.5), fiber_direction(0.1, 0.0), jnp.array([0.0]), mode="both")
    with pytest.raises(ValueError, match="periodic"):
        fl.trace(fl.ellipse_row(2.0, 0.5, 0.5), fiber_direction(0.1, 1.0), jnp.array([0.0]))
    with pytest.raises(ValueError, match="wo.z"):
        fl.masking_fraction(fl.ellipse_row(2.0, 0.5, 0.5), Vec3(0.0, 1.0, 0.0), KEY)
    with pytest.raises(ValueError, match="diffuse"):
        fl.trace(fl.fiber(1.5, medulla=(0, 0, 0.5, 0.5)), fiber_direction(0.1, 0.0), jnp.array([0.0]),
                 polarized=True)
    with pytest.raises(ValueError, match="n_paths"):
        fl.trace_fiber(fl.fiber(1.5), fiber_direction(0.1, 0.0), KEY, 0)
    with pytest.raises(ValueError, match="wi"):
        fl.trace(fl.fiber(1.5), Vec3(1.0, 1.0, 0.0), jnp.array([0.0]))
    with pytest.raises(ValueError, match="mode"):
        fl.trace_fiber(fl.fiber(1.5), fiber_direction(0.1, 0.0), KEY, 16, mode="both")
    with pytest.raises(ValueError, match="rough interface"):
        fl.nee_bcsdf(fl.fiber(1.5), fiber_direction(0.1, 0.0), fiber_direction(0.1, 1.0), KEY)
