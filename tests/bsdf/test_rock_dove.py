"""rock_dove (Huang 2022 Ch. 5): the barbule row's visibility against a brute-force ray cast with
flatland's own intersection code, the NDF's closed forms and normalisation, the thesis' thin-film
and melanin numbers, S_R's reciprocity, energy, the sampler's density, trends of App. H, edge
cases and bad input. The property harness runs the model too (tests/test_properties.py)."""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad

from appearance_jax.bsdf import barbule_row as row
from appearance_jax.bsdf import rock_dove as rd
from appearance_jax.core.params import replace_unchecked
from appearance_jax.core.vec import Vec3
from appearance_jax.flatland import feather
from appearance_jax.flatland import geometry as G
from appearance_jax.optics import melanin
from appearance_jax.optics.refractive_index import Cauchy
from appearance_jax.optics.thinfilm import airy, airy_trt
from appearance_jax.testing.directions import call_chunked, sample_chunked

P = rd.Params()
# rho with fewer nodes: every check below holds at any quadrature. These are the static fields of
# the property harness' case (tests/test_properties.py), and the helpers below call the kernels on
# the harness' chunks (testing.directions.CHUNK pairs): the tests and the harness run the same
# compiled eval, pdf and sample programs (compilation is most of their cost).
COARSE = dict(n_phi=2, n_theta=1)
Q = rd.Params(**COARSE)


def ev(p, wi, wo):
    return call_chunked(rd.eval, p, wi, wo)


def pdf(p, wi, wo):
    return call_chunked(rd.pdf, p, wi, wo)


def trans(p, wi):
    return call_chunked(lambda q, a, _: rd.transmission(q, a), p, wi, wi)


def _dirs(seed, n, lo=0.05, hi=1.5):
    rng = np.random.default_rng(seed)
    th, ph = rng.uniform(lo, hi, n), rng.uniform(-math.pi, math.pi, n)
    return th, ph, Vec3(*(jnp.asarray(v) for v in (np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th))))


def _front_first_hits(p, w, n=4000, copies=24):
    """Brute force: rays over one period of the row from the local direction w (3-tuple), each
    tested against 2 copies + 1 arcs with flatland.geometry.intersect (flatland's section frame:
    the row along y = local x, z = the barb-plane normal; the ellipse's first axis at psi = -mu).
    Returns the fraction whose first hit is on the outer (front) side of an arc."""
    b, H, mu = float(p.b), float(p.H), float(p.mu)
    # the arc's normal azimuths [phi0, phi1] as flatland's parametric angles (decreasing in phi)
    g_lo, span = feather.arc_range(b, float(p.phi0), float(p.phi1))
    r = math.hypot(w[0], w[2])
    return float(_front_fraction(b, H, mu, g_lo, span, w[0] / r, w[2] / r, n=n, copies=copies))


# one compiled program for every row and direction (op by op, this cast compiled ~260 small programs)
@functools.partial(jax.jit, static_argnames=("n", "copies"))
def _front_fraction(b, H, mu, g_lo, span, dy, dz, n, copies):
    h = ((jnp.arange(n) + 0.5) / n - 0.5) * H * jnp.abs(dz)  # one period, measured across the rays
    py, pz = (-h * dz + 60 * dy)[:, None], (h * dy + 60 * dz)[:, None]
    # every copy at once (the launch line is 60 units up: cover its footprint), the nearest hit wins
    cy = jnp.arange(-copies - 48, copies + 49)[None, :] * H
    t, hit = G.intersect(py, pz, -dy, -dz, cy, 0.0, 1.0, b, -mu, g_lo, span, jnp.zeros(cy.shape, bool))
    t = jnp.where(hit, t, jnp.inf)
    k = jnp.argmin(t, axis=1)[:, None]
    tk, ck = jnp.take_along_axis(t, k, 1)[:, 0], jnp.take_along_axis(jnp.broadcast_to(cy, t.shape), k, 1)[:, 0]
    ny, nz = G.normal_at(py[:, 0] - tk * dy, pz[:, 0] - tk * dz, ck, 0.0, 1.0, b, -mu)
    front = jnp.isfinite(tk) & (ny * dy + nz * dz > 0)
    return jnp.mean(front)


_valid_fraction_jit = jax.jit(rd.valid_fraction)


def _valid_fraction(p, w):
    """rd.valid_fraction (a plain function: op by op it compiles ~150 small programs) as one compiled
    program, on directions padded to 8 so that every test here runs the same one."""
    n = int(np.size(w.z))
    m = -(-n // 8) * 8
    flat = lambda c: jnp.ravel(jnp.asarray(c, jnp.float64))  # noqa: E731  (not weak-typed: one signature)
    pad = lambda c: jnp.concatenate([flat(c), jnp.repeat(flat(c)[:1], m - n)])  # noqa: E731
    return _valid_fraction_jit(p, w.map(pad))[:n].reshape(np.shape(w.z))


# ------------------------------------------------------------------------------ geometry


@pytest.mark.parametrize("preset", ["thesis_fit", "ablation_spacing_2.5",
                                    pytest.param("ablation_circular", marks=pytest.mark.slow),
                                    pytest.param("ablation_mu_-0.8", marks=pytest.mark.slow)])
def test_valid_fraction_is_the_brute_force_front_hit_fraction(preset):
    """Delta h'/Delta h (closed-form pieces, one ray test each) against 4000 stratified rays per
    direction: the stratified estimate of a piecewise-constant fraction errs by <= 1/n per edge."""
    p = rd.PRESETS[preset]
    th, ph, w = _dirs(7, 6, 0.2, 1.45)
    v = np.asarray(_valid_fraction(p, w))
    ref = [_front_first_hits(p, (float(w.x[i]), float(w.y[i]), float(w.z[i]))) for i in range(6)]
    np.testing.assert_allclose(v, ref, atol=2e-3)
    assert np.ptp(ref) > 0.05 or preset in ("thesis_fit", "ablation_circular")  # the directions see gaps


def test_valid_fraction_on_random_rows_with_gaps_and_back_hits():
    """Random arcs, spacings and tilts (open arcs: rays can pass under a neighbour into the next one,
    or hit an arc's inside): the pieces still classify every ray as the brute force does."""
    rng = np.random.default_rng(3)
    out, ref = [], []
    for _ in range(8):
        p0 = rng.uniform(-1.5, 0.0)
        p = rd.Params(b=rng.uniform(0.1, 1.0), phi0=p0, phi1=p0 + rng.uniform(1.0, math.pi), H=rng.uniform(0.8, 3.0),
                      mu=rng.uniform(-1.2, 1.2))
        _, _, w = _dirs(int(rng.integers(1 << 30)), 1, 0.3, 1.4)
        out.append(float(_valid_fraction(p, w)[0]))
        ref.append(_front_first_hits(p, (float(w.x[0]), float(w.y[0]), float(w.z[0]))))
    np.testing.assert_allclose(out, ref, atol=2e-3)
    assert min(ref) < 0.9  # some rays pass or hit an inside


@pytest.mark.slow  # a convergence check of the default (the brute-force tests cover the values)
def test_more_neighbours_change_nothing_at_the_presets():
    _, _, w = _dirs(11, 64)
    for name in ("thesis_fit", "ablation_mu_-0.8", "ablation_circular"):
        p = rd.PRESETS[name]
        np.testing.assert_allclose(np.asarray(rd.valid_fraction(p, w)),
                                   np.asarray(rd.valid_fraction(p.replace(neighbours=4), w)), rtol=1e-12)


def test_curvature_closed_forms():
    """F-2: 1/kappa(0) = 1/b, 1/kappa(pi/2) = b^2; the arc point of normal azimuth phi has that normal."""
    b = 0.25
    assert float(row.radius_of_curvature(0.0, b)) == pytest.approx(1 / b, rel=1e-12)
    assert float(row.radius_of_curvature(math.pi / 2, b)) == pytest.approx(b * b, rel=1e-12)
    phi = jnp.linspace(-3.0, 3.0, 13)
    x, z = row.arc_point(phi, b)
    np.testing.assert_allclose(np.asarray(x ** 2 + z ** 2 / b ** 2), 1.0, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(row.normal_azimuth(x, z, b)), np.asarray(phi), atol=1e-12)


def test_ndf_normalisation_with_and_without_visibility():
    """F-1 and [T:1632]: the longitudinal factor integrates to 1; the transversal one to the
    projected arc length / H = 1.3810 at the thesis fit (the barbules overlap), and to exactly 1
    over the part visible from n (every ray from n lands on a front-facing arc)."""
    p = P
    b, H, mu, p0, p1 = 0.25, 1.25, -0.35, -0.37, 2.64
    d_phi = lambda f: b * b / H * (math.sin(f) ** 2 + b * b * math.cos(f) ** 2) ** -1.5  # noqa: E731  Eq. 5.5
    no_v = quad(lambda f: d_phi(f) * math.cos(f + mu), p0, p1, limit=200)[0]
    assert no_v == pytest.approx(1.3810483377, abs=1e-8)
    # D over a fine (theta, phi) grid, with and without the visibility from n
    t = np.polynomial.legendre.leggauss(16)
    theta = float(p.theta_d) * t[0]
    wt = float(p.theta_d) * t[1]
    phi = np.linspace(p0, p1, 60001)
    wphi = np.full(phi.size, phi[1] - phi[0])
    wphi[[0, -1]] *= 0.5
    T, F = np.meshgrid(theta, phi, indexing="ij")
    d, sees = (np.asarray(v) for v in _ndf_and_sees(p, jnp.asarray(T), jnp.asarray(F), -math.sin(mu), math.cos(mu)))
    cos_n = np.cos(T) * np.cos(F + mu)  # <w_m, n>
    dw = np.cos(T) * wt[:, None] * wphi[None, :]
    assert np.sum(d * np.maximum(cos_n, 0) * dw) == pytest.approx(quad(lambda f: d_phi(f) * max(math.cos(f + mu), 0),
                                                                        p0, p1, limit=200)[0], rel=1e-5)
    assert np.sum((d * cos_n * dw)[:, sees]) == pytest.approx(1.0, abs=2e-4)
    assert float(_valid_fraction(p, Vec3(jnp.asarray(0.0), jnp.asarray(0.0), jnp.asarray(1.0)))) == pytest.approx(1.0)


@jax.jit  # one program (op by op: ~60 small ones)
def _ndf_and_sees(p, T, F, dx, dz):
    """D on the (theta, phi) grid and which azimuths of F's first row see the 2D direction (dx, dz)."""
    return rd.ndf(p, T, F), rd._sees(p, F[0], dx, dz)


def test_visible_normals_integrate_to_the_valid_fraction():
    """For random w_i: int D V_i <w_i, w_m>+ dw_m = <w_i, n> Delta h'/Delta h (the issue's identity)."""
    p = rd.PRESETS["ablation_spacing_2.5"]
    th, ph, w = _dirs(5, 5, 0.2, 1.3)
    t, wt = np.polynomial.legendre.leggauss(12)
    lhs = np.asarray(_visible_normal_integral(p, w, jnp.asarray(t * float(p.theta_d))[:, None, None],
                                              jnp.asarray(wt * float(p.theta_d))[:, None, None]))
    np.testing.assert_allclose(lhs, np.asarray(w.z * _valid_fraction(p, w)), rtol=2e-3)


@jax.jit  # one program (op by op: ~200 small ones)
def _visible_normal_integral(p, w, theta, wt):
    """int D V_i <w_i, w_m>+ dw_m per direction of w: Gauss nodes theta (weights wt) x 20001 in phi."""
    b = rd.to_barbule(p, w)
    phi = jnp.linspace(p.phi0, p.phi1, 20001)[None, :, None]
    dphi = phi[0, 1, 0] - phi[0, 0, 0]
    dx, dz, c, s = rd._transverse(b)
    cos_i = c * jnp.cos(theta) * (dx * jnp.sin(phi) + dz * jnp.cos(phi)) + s * jnp.sin(theta)
    v = rd._sees(p, phi, dx, dz)
    integrand = rd.ndf(p, theta, phi) * jnp.where(v, jnp.maximum(cos_i, 0), 0) * jnp.cos(theta) * wt * dphi
    return jnp.sum(integrand, axis=(0, 1))


# ------------------------------------------------------------------------------ optics


def test_film_numbers_of_the_thesis():
    """TF-4/TF-6: d = 590 nm, eta = 1.55, normal incidence: maxima 406.4/522.6/731.6 nm with
    R = 0.16991, zeros (total destructive interference, [T:1562]) at 457.2/609.7 nm."""
    p = rd.Params(color="spectral", wavelengths=(406.4, 457.2, 522.6, 609.7, 731.6), eta_keratin=1.55)
    film_r = jax.jit(rd.film_r)  # one program (op by op: ~30 small ones)
    r = np.asarray(film_r(p, jnp.asarray(1.0)))
    np.testing.assert_allclose(r[[0, 2, 4]], 0.16991, atol=2e-5)
    np.testing.assert_allclose(r[[1, 3]], 0.0, atol=2e-6)
    # R -> 1 at grazing
    assert float(film_r(p, jnp.asarray(1e-6))[0]) > 0.999


def test_melanin_numbers_of_app_g():
    assert float(melanin.absorption_coefficient(0.0632, 589.0)) == pytest.approx(1.348e-3, rel=1e-3)
    assert float(melanin.transmittance(0.0632, 589.0, 2000.0)) == pytest.approx(0.0674, abs=2e-4)
    assert float(melanin.normal_reflectance(1.648, 0.0632)) == pytest.approx(0.0604, abs=1e-4)
    assert float(P.melanin_reflectance) == pytest.approx(float(melanin.normal_reflectance(1.648, 0.0632)), abs=1e-4)


def test_trt_is_symmetric_and_bounded_by_the_film_transmittance():
    """F-5: I_TRT(i, o) = I_TRT(o, i); with a white melanin and one angle it is T_s^2/2 + T_p^2/2."""
    c = jnp.linspace(0.0, 1.0, 11)
    v, ts, tp = (np.asarray(a) for a in _trt_and_film(c))
    np.testing.assert_allclose(v, v.T, rtol=1e-12)
    np.testing.assert_allclose(np.diag(v), 0.5 * (ts ** 2 + tp ** 2), rtol=1e-12)
    assert np.all(v <= 1.0 + 1e-12) and np.all(v >= 0)


@jax.jit  # one program (op by op: ~100 small ones)
def _trt_and_film(c):
    f = airy(c, 550.0, 590.0, 1.0, 1.55, 1.0)
    return airy_trt(c[:, None], c[None, :], 550.0, 590.0, 1.55, 1.0), f.T_s, f.T_p


def test_cauchy_keratin_is_the_refractive_index_module_law():
    p = rd.Params(keratin="cauchy", color="spectral", wavelengths=(450.0, 589.0, 700.0))
    wl = jnp.asarray([450.0, 589.0, 700.0])
    np.testing.assert_allclose(np.asarray(rd.keratin_index(p, wl)), np.asarray(Cauchy(A=1.532, B=5.89e-3)(wl)[0]),
                               rtol=1e-12)


# ------------------------------------------------------------------------------ the BSDF


def test_mirror_lobe_is_reciprocal_and_the_trt_lobe_is_not():
    """S_R(i, o) = S_R(o, i) (melanin off: S = S_R); with the melanin on, rho averages over the area
    lit from w_i (Huang Eq. 5.17), so swapping the directions changes it."""
    _, _, wi = _dirs(21, 400)
    _, _, wo = _dirs(22, 400)
    p = Q.replace(melanin_reflectance=0.0)
    a, b = ev(p, wi, wo), ev(p, wo, wi)
    assert np.count_nonzero(a.sum(-1)) > 20  # the pairs do hit the mirror lobe
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-14)
    a, b = ev(Q, wi, wo), ev(Q, wo, wi)
    assert np.max(np.abs(a - b) / np.maximum(a, b).max()) > 1e-3


def test_reflection_plus_transmission_conserve_energy():
    """int (S_R + S_TRT) <w_o, n> dw_o + S_T <= 1 (I_R + I_TRT <= 1 at every facet), and with the
    film's and melanin's reflectances both 1 the R lobe alone carries (Delta h'/Delta h)."""
    from appearance_jax.core.quadrature import sphere_rule

    wo, wq = sphere_rule(96, 192, hemisphere=True)
    th, ph = np.array([0.3, 1.1, 1.3]), np.array([0.4, -2.0, 0.2])
    wi = Vec3(np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th))
    for name in ("thesis_fit", "ablation_spacing_2.5"):
        p = rd.PRESETS[name].replace(**COARSE)
        # the three incident directions in one call (fewer padded chunks): (3, nodes, bands)
        f = ev(p, wi.map(lambda c: c[:, None]), wo.map(lambda c: np.asarray(c)[None, :]))
        a_all = np.sum(f * np.asarray(wo.z * wq)[None, :, None], axis=1)
        t_all = trans(p, wi)
        for theta_i, a, t in zip(th, a_all, t_all):
            assert np.all(a + t <= 1.0 + 2e-3), (name, theta_i, a, t)
            assert np.all(a > 0.02)


def test_sampler_density_integrates_and_matches_its_histogram():
    """pdf integrates to (P_R x the part of the mirror directions above the plane) + (1 - P_R) <= 1;
    the sample/eval/pdf consistency and chi-square are the harness' (tests/test_properties.py)."""
    from appearance_jax.core.quadrature import sphere_rule

    wo, wq = sphere_rule(128, 256, hemisphere=True)
    wi = Vec3(*(jnp.full(wo.x.shape, v) for v in (0.4, 0.2, math.sqrt(1 - 0.2))))
    total = float(np.sum(pdf(Q, wi, wo) * np.asarray(wq)))
    assert 0.9 < total <= 1.0 + 5e-3
    wi_s = Vec3(*(jnp.full(4000, v) for v in (0.4, 0.2, math.sqrt(1 - 0.2))))
    # a typed key, as the harness' checks pass: the same compiled sample program as theirs
    w_s, weight, p_s = sample_chunked(rd.MODEL, Q, wi_s, jax.random.key(3))
    ok = p_s > 0
    assert ok.mean() > 0.8
    np.testing.assert_allclose(p_s[ok], pdf(Q, wi_s, w_s)[ok], rtol=1e-6)
    f = ev(Q, wi_s, w_s)
    np.testing.assert_allclose(weight[ok], (f * w_s.z[:, None])[ok] / p_s[ok, None], rtol=1e-6)


def test_app_h_trends():
    """[T:2297]: a wider spacing or a steeper barbule lets more light through (T up, R down);
    a wider longitudinal arc spreads the mirror lobe along the barbule."""
    _, _, w = _dirs(31, 300, 0.1, 1.4)
    base = float(np.mean(trans(Q, w)))
    assert float(np.mean(trans(rd.PRESETS["ablation_spacing_2.5"].replace(**COARSE), w))) > base + 0.05
    assert float(np.mean(trans(rd.PRESETS["ablation_mu_-0.8"].replace(**COARSE), w))) > base + 0.02
    # longitudinal spread: the mirror lobe's extent in w_o.y about the specular direction
    wi = Vec3(jnp.asarray(0.3), jnp.asarray(0.0), jnp.asarray(math.sqrt(1 - 0.09)))
    y = jnp.linspace(-0.4, 0.4, 161)
    wo = Vec3(jnp.full(161, -0.3), y, jnp.sqrt(1 - 0.09 - y * y))
    narrow = ev(Q.replace(melanin_reflectance=0.0), wi, wo).sum(-1) > 0
    wide = ev(rd.PRESETS["ablation_theta_d_0.1571"].replace(melanin_reflectance=0.0, **COARSE), wi, wo).sum(-1) > 0
    assert wide.sum() > 1.6 * narrow.sum() > 0


def test_edge_directions_are_finite_with_finite_gradients():
    """Grazing <w, n> = 0, w along the barbule axis, directions on opposite sides (only the T delta
    connects them) and a pair below the plane (0; the barb's underside is rd.underside)."""
    cases = [((0.6, 0.0, 0.8), (1.0, 0.0, 0.0)), ((0.0, 1.0, 0.0), (0.0, 0.6, 0.8)), ((0.6, 0.0, 0.8), (0.0, 0.6, -0.8)),
             ((0.0, 0.0, 1.0), (0.0, 0.0, 1.0)), ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0))]
    wi, wo = (Vec3(*(jnp.asarray([c[j][k] for c in cases]) for k in range(3))) for j in (0, 1))
    f = ev(Q, wi, wo)
    assert np.all(np.isfinite(f)) and np.all(f[[0, 1, 2, 4]] == 0) and np.all(f[3] > 0)
    assert np.all(np.isfinite(pdf(Q, wi, wo)))
    # d eval, d pdf at these directions: tests/testing/test_special_directions.py (horizon_y is the
    # barbule axis); the transmission is checked here
    g = jax.jit(jax.grad(lambda q: jnp.sum(rd.transmission(q, wi))))(Q)  # one program (not forward + backward)
    assert all(np.all(np.isfinite(np.asarray(v))) for v in jax.tree_util.tree_leaves(g))
    assert np.all(np.isfinite(trans(Q, wi)))
    wi_b = Vec3(jnp.asarray(-0.3), jnp.asarray(0.1), jnp.asarray(-math.sqrt(0.9)))
    wo_b = Vec3(jnp.asarray(0.5), jnp.asarray(0.05), jnp.asarray(-math.sqrt(0.7475)))
    assert np.all(ev(Q, wi_b, wo_b) == 0)  # a reflection BSDF: 0 below the plane
    below = ev(Q, rd.underside(wi_b), rd.underside(wo_b))  # the barb's underside, seen from above
    above = ev(Q, Vec3(jnp.asarray(0.3), jnp.asarray(0.1), jnp.asarray(math.sqrt(0.9))),
               Vec3(jnp.asarray(-0.5), jnp.asarray(0.05), jnp.asarray(math.sqrt(0.7475))))
    np.testing.assert_allclose(below, above, rtol=1e-12)


def test_gradients_match_finite_differences():
    """AD of a sum of values vs central differences: the film (thickness), the ellipse (b)
    and the arc half-angle on the TRT lobe (smooth in them); spacing, tilt and the arc's ends
    move the lit intervals' ends continuously, so rho is differentiable there too."""
    _, _, wi = _dirs(41, 64, 0.2, 1.2)
    _, _, wo = _dirs(42, 64, 0.2, 1.2)
    base = Q.replace(melanin_reflectance=0.5)

    def total(q):
        return jnp.sum(rd.eval(q, wi, wo) * jnp.asarray([1.0, 0.7, 0.4]))

    g = jax.jacfwd(total)(base)  # forward mode, as a fit's Jacobian (reverse mode: the special directions test)
    band = np.asarray([1.0, 0.7, 0.4])

    def total_np(q):  # the differences on the shared compiled eval
        return float(np.sum(ev(q, wi, wo) * band))

    for name, h in (("thickness", 1e-3), ("b", 1e-6), ("theta_d", 1e-6), ("H", 1e-6), ("mu", 1e-6),
                    ("phi0", 1e-6), ("phi1", 1e-6)):
        v = float(getattr(base, name))
        fd = (total_np(base.replace(**{name: v + h})) - total_np(base.replace(**{name: v - h}))) / (2 * h)
        ad = float(getattr(g, name))
        # S_R's support (D's ends, the binary G) is not differentiable: the pairs keep off its edges
        # at these steps, so the two agree to the differences' rounding
        assert ad == pytest.approx(fd, rel=2e-4, abs=1e-7), (name, ad, fd)


@pytest.mark.parametrize("kw, match", [
    (dict(b=0.0), r"b = 0"), (dict(b=1.5), r"b = 1.5"), (dict(H=0.0), r"H = 0"), (dict(thickness=-1.0), "thickness"),
    (dict(theta_d=0.0), "theta_d"), (dict(theta_d=2.0), "theta_d"), (dict(mu=1.6), "mu"), (dict(mu=-1.6), "mu"),
    (dict(phi0=1.0, phi1=0.5), r"phi0 = 1.0, phi1 = 0.5"), (dict(phi0=-1.0, phi1=2.5), "phi0 = -1.0, phi1 = 2.5"),
    (dict(melanin_reflectance=1.2), "melanin_reflectance"), (dict(eta_keratin=0.5), "eta_keratin"),
    (dict(neighbours=0), "neighbours"), (dict(n_phi=0), "n_phi"), (dict(color="xyz"), "color"),
])
def test_bad_parameters_are_named(kw, match):
    with pytest.raises(ValueError, match=match):
        rd.Params(**kw)


def test_bad_wavelengths_are_named():
    with pytest.raises(ValueError, match="wavelength"):
        rd.Params(color="spectral", wavelengths=(500.0, -3.0))


def test_algorithm_1_estimates_the_whole_bsdf_with_the_delta():
    """Huang's Algorithm 1 (sample_lobes): E[weight g(w_o)] = int S <w_o, n> g dw_o + S_T g(-w_i) for
    g = 1, w_o.x, w_o.y (quadrature of eval; sampled means within 4.5 standard errors + the
    quadrature's error), the T lobe's mass is S_T, and a grey film's sample value
    (I_R + I_TRT - 1) f + 1 is <= 1 (F-6; the band means of an RGB film's weights)."""
    from appearance_jax.core.quadrature import sphere_rule

    p = rd.Params(theta_d=0.3, H=1.8, mu=-0.6, melanin_reflectance=0.3, n_phi=4)  # rho at 4 x 2 nodes: inside the tolerance (2 x 1: off by ~1 %)
    wq_dirs, wq = sphere_rule(128, 256, hemisphere=True)
    n = 40000
    ts = []
    for wi3 in ((0.5, 0.2, math.sqrt(0.71)), (-0.8, 0.3, math.sqrt(0.27))):
        wi = Vec3(*(jnp.full(n, v) for v in wi3))
        wo, weight, lobe = rd.sample_lobes(p, wi, jax.random.key(11))
        weight, lobe = np.asarray(weight), np.asarray(lobe)
        wiq = Vec3(*(jnp.full(wq_dirs.x.shape, v) for v in wi3))
        fq = ev(p, wiq, wq_dirs) * np.asarray(wq_dirs.z * wq)[:, None]
        t = float(trans(p.replace(**COARSE), wiq)[0])  # S_T does not depend on rho's nodes: the shared program
        for g_s, g_q, g_t in ((1.0, 1.0, 1.0), (np.asarray(wo.x), np.asarray(wq_dirs.x), -wi3[0]),
                              (np.asarray(wo.y), np.asarray(wq_dirs.y), -wi3[1])):
            est = weight * np.broadcast_to(np.asarray(g_s), (n,))[:, None]
            mean, se = est.mean(0), est.std(0) / math.sqrt(n)
            ref = (fq * np.broadcast_to(np.asarray(g_q), fq.shape[:1])[:, None]).sum(0) + t * g_t
            assert np.all(np.abs(mean - ref) <= 4.5 * se + 2e-3), (wi3, mean, ref, se)
        assert np.mean(np.where(lobe == 2, weight[:, 0], 0.0)) == pytest.approx(t, abs=4.5 * 0.5 / math.sqrt(n) + 1e-9)
        ts.append(t)
    assert max(ts) > 0.2 and min(ts) == 0  # one direction sees gaps between the barbules, the other none
    # F-6 at the thesis fit: an unrejected sample's weights (value / P(lobe), P from the band means)
    # average over the bands to exactly the thesis' value (I_R + I_TRT - 1) f + 1 of the grey film whose
    # I_R, I_TRT are those band means: checked on the program above (same static fields and shape;
    # n_phi is rho's, which the sampler does not use) instead of compiling a one-band film's
    thesis = rd.Params(n_phi=4)
    wi = Vec3(*(jnp.full(n, v) for v in (0.6, 0.1, math.sqrt(0.63))))
    _, weight, lobe = rd.sample_lobes(thesis, wi, jax.random.key(2))
    assert float(jnp.max(jnp.mean(weight, axis=-1))) <= 1.0 + 1e-12


def test_an_arc_wider_than_pi_inside_a_fit_is_held_at_pi():
    """Params() rejects phi1 > phi0 + pi; a fit's traced Params skip that check, and the kernels
    then hold phi1 at phi0 + pi (flat beyond it) rather than run the one-piece geometry on a
    wider arc."""
    _, _, wi = _dirs(51, 16)
    _, _, wo = _dirs(52, 16)
    edge = Q.replace(phi1=float(Q.phi0) + math.pi)
    # the kernels under jit, as a fit calls them (the Params traced, unchecked); jax.jit of the same
    # kernel function on the harness' chunks runs the compiled programs of ev and trans
    wide = replace_unchecked(Q, phi1=jnp.asarray(float(Q.phi0) + math.pi + 0.3, jnp.float64))
    np.testing.assert_allclose(call_chunked(jax.jit(rd.eval.kernel), wide, wi, wo), ev(edge, wi, wo), rtol=1e-12)
    t = call_chunked(lambda q, a, _: jax.jit(rd.transmission.kernel)(q, a), wide, wi, wi)
    np.testing.assert_allclose(t, trans(edge, wi), rtol=1e-12, atol=1e-14)
