"""The staggered sphere grid of the soap-film flow (Huang 2022 Sec. 3.4.1, Eqs. 3.13-3.16, App. C).

Every check compares with something the grid did not compute: closed-form spherical harmonics,
hand-derived values of the stencils, exact bilinear-interpolation error bounds.

Measured (n_theta x 2 n_theta, float64; h = dtheta = dphi):

=====================  ===========  ===========  ===========  ======
quantity                 16 x 32      32 x 64     64 x 128    order
=====================  ===========  ===========  ===========  ======
integral cos^2 error    1.36e-2      3.37e-3      8.42e-4      2.0
grad x, max error       1.61e-3      4.02e-4      1.00e-4      2.0
lap cos(theta), max     1.59e-2      4.01e-3      1.00e-3      2.0
lap x, area-l2 (rel)    1.32e-2      3.52e-3      9.34e-4      1.9
lap x, max, pole row    4.72e-2      2.43e-2      1.22e-2      1.0
lap xz, max, pole row   2.29e-1      1.21e-1      6.11e-2      1.0
=====================  ===========  ===========  ===========  ======

The pole rows of the 5-point stencil (Huang Eq. 3.16) have an O(h) pointwise error for the
m = 1 harmonics (the value there is itself O(h)): derived by hand in
``test_laplacian_pole_row_closed_form`` (L_h x = -(5/4) h cos(phi) + O(h^3) against the exact
-h cos(phi)). The area-weighted error is still second order.
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.core.vec import Vec3, cross, dot
from appearance_jax.soapfilm.grid import SphereGrid, angles, basis, components, point, tangent


def _order(errors):
    """log2 of the ratio of successive errors (h halves each time)."""
    e = np.asarray(errors)
    return np.log2(e[:-1] / e[1:])


def _faces(g, field):
    """(u_theta, u_phi) of the tangent field ``field: Vec3 -> Vec3`` at the staggered faces."""
    tt, pt = g.u_theta_points()
    tp, pp = g.u_phi_points()
    ut = components(field(point(tt, pt)), tt, pt)[0]
    up = components(field(point(tp, pp)), tp, pp)[1]
    return ut, up


# --------------------------------------------------------------------------------------
# construction


@pytest.mark.parametrize("args, exc, name", [
    ((16, 31), ValueError, "n_phi"),
    ((3, 8), ValueError, "n_theta"),
    ((16, 2), ValueError, "n_phi"),
    ((16.0, 32), TypeError, "n_theta"),
    ((16, "32"), TypeError, "n_phi"),
    ((True, 32), TypeError, "n_theta"),
])
def test_bad_input_names_the_parameter(args, exc, name):
    with pytest.raises(exc, match=name):
        SphereGrid(*args)


def test_minimal_and_numpy_ints_accepted():
    g = SphereGrid(np.int64(4), np.int32(4))
    assert g.shape == (4, 4) and g.theta_shape == (3, 4) and type(g.n_theta) is int
    assert SphereGrid.parse("8x16") == SphereGrid(8, 16)
    with pytest.raises(ValueError, match="grid"):
        SphereGrid.parse("8by16")


def test_layout_coordinates():
    g = SphereGrid(6, 8)
    th, ph = g.centres()
    tt, pt = g.u_theta_points()
    tp, pp = g.u_phi_points()
    assert th.shape == tp.shape == (6, 8) and tt.shape == (5, 8)
    np.testing.assert_allclose(th[:, 0], (np.arange(6) + 0.5) * np.pi / 6)
    np.testing.assert_allclose(tt[:, 0], np.arange(1, 6) * np.pi / 6)  # no pole samples
    np.testing.assert_allclose(pp[0], np.arange(8) * 2 * np.pi / 8)
    np.testing.assert_allclose(pt[0], ph[0])


# --------------------------------------------------------------------------------------
# areas and integrals


@pytest.mark.parametrize("shape", [(4, 4), (16, 32), (33, 64), (48, 96)])
def test_cell_areas_sum_to_4pi(shape):
    g = SphereGrid(*shape)
    a = g.cell_areas()
    assert a.shape == g.shape and np.all(a > 0)
    assert abs(a.sum() - 4 * np.pi) < 1e-12
    # the band between theta_i -+ dtheta/2, exactly: 2 sin(theta_i) sin(dtheta/2) dphi
    th, _ = g.centres()
    np.testing.assert_allclose(a, 2 * np.sin(th) * np.sin(g.dtheta / 2) * g.dphi, rtol=1e-12)


def test_integral_cos2_second_order():
    errs = []
    for n in (16, 32, 64):
        g = SphereGrid(n, 2 * n)
        th, _ = g.centres()
        errs.append(abs(float(g.integral(jnp.asarray(np.cos(th) ** 2))) - 4 * np.pi / 3))
    # midpoint rule in cos(theta) bands: error ~ C h^2 with C ~ 0.35 (measured)
    assert errs[0] < 0.5 * (np.pi / 16) ** 2
    assert np.all(np.abs(_order(errs) - 2) < 0.1), errs


# --------------------------------------------------------------------------------------
# difference operators


def test_gradient_second_order_everywhere():
    """grad x = (cos th cos ph, -sin ph) and grad(xz) = (cos 2th cos ph, -cos th sin ph),
    compared at every face, pole rows included."""
    cases = {
        "x": (lambda t, p: np.sin(t) * np.cos(p),
              lambda t, p: np.cos(t) * np.cos(p), lambda t, p: -np.sin(p)),
        "xz": (lambda t, p: np.sin(t) * np.cos(t) * np.cos(p),
               lambda t, p: np.cos(2 * t) * np.cos(p), lambda t, p: -np.cos(t) * np.sin(p)),
    }
    for name, (f, gt, gp) in cases.items():
        errs = []
        for n in (16, 32, 64):
            g = SphereGrid(n, 2 * n)
            tt, pt = g.u_theta_points()
            tp, pp = g.u_phi_points()
            a, b = g.gradient(jnp.asarray(f(*g.centres())))
            errs.append(max(np.abs(a - gt(tt, pt)).max(), np.abs(b - gp(tp, pp)).max()))
        # central differences: error <= (h^2 / 24) max|f'''| (f''' <= 8 for xz)
        h = np.pi / 16
        assert errs[0] < 8 * h * h / 24, (name, errs)
        assert np.all(_order(errs) > 1.9), (name, errs)


def _laplacian_errors(f, l, n):
    g = SphereGrid(n, 2 * n)
    th, ph = g.centres()
    v = f(th, ph)
    e = np.abs(np.asarray(g.laplacian(jnp.asarray(v))) + l * (l + 1) * v)
    area = g.cell_areas()
    l2 = math.sqrt((e ** 2 * area).sum() / (v ** 2 * area).sum())
    band = np.abs(np.cos(th)) < 0.5
    return e.max(), l2, e[band].max(), e[0].max()


def test_laplacian_spherical_harmonics():
    """Laplace-Beltrami Y_l = -l(l+1) Y_l for cos(theta) (l=1, m=0), x (l=1, m=1),
    xz (l=2, m=1), (x^2 - y^2) (l=2, m=2)."""
    y10 = lambda t, p: np.cos(t)
    y11 = lambda t, p: np.sin(t) * np.cos(p)
    y21 = lambda t, p: np.sin(t) * np.cos(t) * np.cos(p)
    y22 = lambda t, p: np.sin(t) ** 2 * np.cos(2 * p)
    ns = (16, 32, 64)
    # m = 0: second order in the max norm, pole rows included
    mx = [_laplacian_errors(y10, 1, n)[0] for n in ns]
    assert np.all(_order(mx) > 1.9), mx
    for f, l in ((y11, 1), (y21, 2), (y22, 2)):
        errs = np.array([_laplacian_errors(f, l, n) for n in ns])
        assert np.all(_order(errs[:, 1]) > 1.8), errs  # area-weighted l2, all rows
        assert np.all(_order(errs[:, 2]) > 1.8), errs  # max, |cos theta| < 1/2
        assert np.all(_order(errs[:, 0]) > 0.9), errs  # max over all rows: >= first order
    # the constant is in the kernel
    g = SphereGrid(16, 32)
    assert float(jnp.abs(g.laplacian(jnp.full(g.shape, 3.0))).max()) < 1e-12


def test_laplacian_pole_row_closed_form():
    """Eq. 3.16 on row 0 (theta0 = h/2, no flux through the pole) for f = x = sin th cos ph,
    dtheta = dphi = h, by hand:
      theta part: sin(h) (f(3h/2) - f(h/2)) / h^2 / sin(h/2) = 2 sin(h) cos(h) cos(ph) / h^2
      phi part:   sin(h/2) cos(ph) (2 cos h - 2) / (sin^2(h/2) h^2) = -4 sin(h/2) cos(ph) / h^2
    (= (-(5/4) h + (17/64) h^3 + O(h^5)) cos(ph), the exact value being -2 sin(h/2) cos(ph))."""
    for n in (16, 48):
        g = SphereGrid(n, 2 * n)
        h = g.dtheta
        th, ph = g.centres()
        lap = np.asarray(g.laplacian(jnp.asarray(np.sin(th) * np.cos(ph))))
        want = (2 * np.sin(h) * np.cos(h) - 4 * np.sin(h / 2)) / h ** 2 * np.cos(ph[0])
        np.testing.assert_allclose(lap[0], want, atol=1e-12)
        np.testing.assert_allclose(lap[-1], want, atol=1e-12)  # south pole: same by symmetry
        np.testing.assert_allclose(lap[0], -1.25 * h * np.cos(ph[0]), atol=0.27 * h ** 3)  # 17/64 = 0.266


def test_divergence_of_analytic_fields():
    """div(c - (c.p) p) = -2 c.p (the tangent part of a constant vector, u_theta depends on
    theta and phi and crosses the poles); second order in the area-weighted norm."""
    c = Vec3(0.3, -0.7, 0.6)
    field = lambda p: c - p * dot(c, p)
    l2, band = [], []
    for n in (16, 32, 64):
        g = SphereGrid(n, 2 * n)
        th, ph = g.centres()
        want = np.asarray(-2 * dot(c, point(th, ph)))
        e = np.abs(np.asarray(g.divergence(*_faces(g, field))) - want)
        area = g.cell_areas()
        l2.append(math.sqrt((e ** 2 * area).sum() / (want ** 2 * area).sum()))
        band.append(e[np.abs(np.cos(th)) < 0.5].max())
    assert np.all(_order(l2) > 1.8), l2
    assert np.all(_order(band) > 1.9), band


@pytest.mark.parametrize("axis", [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (0.3, -0.5, 0.8)])
def test_divergence_of_rigid_rotation(axis):
    """u = a x p. With a = (ax, ay, az): u_theta = ay cos ph - ax sin ph,
    u_phi = az sin th - cos th (ax cos ph + ay sin ph). Eq. 3.13 then gives exactly
    cot(th) (ay cos ph - ax sin ph) (sinc(dtheta/2) - sinc(dphi/2)), sinc(x) = sin x / x:
    zero (round-off) for square cells, O(h^2 cot th) otherwise."""
    a = Vec3(*axis)
    rot = lambda p: cross(a, p)
    for shape in ((16, 32), (24, 48)):  # dtheta == dphi
        g = SphereGrid(*shape)
        div = np.asarray(g.divergence(*_faces(g, rot)))
        assert np.abs(div).max() < 1e-12 / g.dtheta, (shape, np.abs(div).max())
    sinc = lambda x: np.sin(x) / x
    for shape in ((16, 48), (33, 64)):  # dphi = 2/3 dtheta, dphi = 33/32 dtheta
        g = SphereGrid(*shape)
        th, ph = g.centres()
        want = (np.cos(th) / np.sin(th) * (axis[1] * np.cos(ph) - axis[0] * np.sin(ph))
                * (sinc(g.dtheta / 2) - sinc(g.dphi / 2)))
        np.testing.assert_allclose(np.asarray(g.divergence(*_faces(g, rot))), want, atol=1e-12)


def test_sin_scaled_laplacian_is_symmetric():
    """App. C: -sin(theta) L is a symmetric (positive semi-definite) matrix."""
    rng = np.random.default_rng(1)
    for shape in ((8, 16), (33, 64)):
        g = SphereGrid(*shape)
        s = np.sin(g.centres()[0])
        A = lambda v: -s * np.asarray(g.laplacian(jnp.asarray(v)))
        x, y = rng.standard_normal((2,) + g.shape)
        lhs, rhs = np.sum(y * A(x)), np.sum(x * A(y))
        assert abs(lhs - rhs) <= 1e-12 * np.sqrt(np.sum(x * x) * np.sum(y * y)) * np.abs(A(x)).max()
        assert np.sum(x * A(x)) > 0
    # on the small grid, the whole matrix
    g = SphereGrid(6, 8)
    s = np.sin(g.centres()[0]).ravel()
    eye = np.eye(48).reshape(48, 6, 8)
    M = -s[:, None] * np.stack([np.asarray(g.laplacian(jnp.asarray(e))).ravel() for e in eye], axis=1)
    np.testing.assert_allclose(M, M.T, atol=1e-12)
    w = np.linalg.eigvalsh(M)
    assert abs(w[0]) < 1e-12 and w[1] > 1e-3  # only the constants in the kernel


# --------------------------------------------------------------------------------------
# sampling


def _sample_points(g, m=3000, seed=0):
    """Uniform points on the sphere plus points within half a cell of either pole."""
    rng = np.random.default_rng(seed)
    k = m // 4
    th = np.concatenate([np.arccos(rng.uniform(-1, 1, m)), rng.uniform(0, g.dtheta / 2, k),
                         np.pi - rng.uniform(0, g.dtheta / 2, k), [0.0, np.pi]])
    return th, rng.uniform(0, 2 * np.pi, th.size)


def test_sample_scalar_bilinear_bound():
    """Bilinear interpolation in (theta, phi) of a function smooth across the pole (f(-th, ph)
    = f(th, ph + pi) for x, y, z) errs by at most (dth^2 max|f_thth| + dph^2 max|f_phph|) / 8
    <= (dth^2 + dph^2) / 8 for the coordinates x, y, z."""
    for shape in ((16, 32), (32, 64), (24, 96)):
        g = SphereGrid(*shape)
        th, ph = _sample_points(g)
        exact = tuple(point(th, ph))
        centres = tuple(point(*g.centres()))
        bound = (g.dtheta ** 2 + g.dphi ** 2) / 8
        for k in range(3):
            e = np.abs(np.asarray(g.sample(jnp.asarray(centres[k]), th, ph)) - np.asarray(exact[k]))
            assert e.max() <= bound * (1 + 1e-9), (shape, "xyz"[k], e.max() / bound)
            assert e.max() >= 0.3 * bound  # the bound is not vacuous (measured 0.5-0.99)
    # and it is O(h^2): same points on grids 16x32 -> 64x128
    errs = []
    for n in (16, 32, 64):
        g = SphereGrid(n, 2 * n)
        th, ph = _sample_points(SphereGrid(64, 128))
        ex = np.asarray(point(th, ph).x)
        errs.append(np.abs(np.asarray(g.sample(jnp.asarray(point(*g.centres()).x), th, ph)) - ex).max())
    assert np.all(np.abs(_order(errs) - 2) < 0.2), errs


@pytest.mark.parametrize("kind", ["rot_y", "rot_x", "rot_tilted", "gradient"])
def test_sample_vector_near_the_poles(kind):
    """Tangent fields that cross the poles, sampled at random points (a quarter of them within
    half a cell of a pole).

    Component errors (the components are interpolated in the local basis, each bilinearly on
    its own grid): for u = a x p, u_theta = ay cos ph - ax sin ph does not depend on theta and
    the pole row of ``pad_u_theta`` is exact, so |e_theta| <= dph^2 |a| / 8 and
    |e_phi| <= (dth^2 + dph^2) |a| / 8. For u = c - (c.p) p (u_theta = c.e_theta), the pole row
    is the mean of u_theta at -+dtheta, off by <= dth^2 |c| / 2, so
    |e_theta| <= (dth^2 / 2 + dph^2 / 8) |c|. The vector error is at most the hypotenuse."""
    vec = {"rot_y": (0.0, 1.0, 0.0), "rot_x": (1.0, 0.0, 0.0), "rot_tilted": (0.48, -0.6, 0.64),
           "gradient": (0.48, -0.6, 0.64)}[kind]
    a = Vec3(*vec)
    field = (lambda p: p * 0.0 + a - p * dot(a, p)) if kind == "gradient" else (lambda p: cross(a, p))
    for shape in ((16, 32), (32, 64)):
        g = SphereGrid(*shape)
        th, ph = _sample_points(g)
        p = point(th, ph)
        got = g.sample_vector(*_faces(g, field), p)
        exact = field(p)
        err = np.sqrt(np.asarray(dot(got - exact, got - exact)))
        d2t, d2p = g.dtheta ** 2, g.dphi ** 2
        e_theta = (d2t / 2 + d2p / 8) if kind == "gradient" else d2p / 8
        bound = math.hypot(e_theta, (d2t + d2p) / 8)
        assert err.max() <= bound * (1 + 1e-9), (shape, err.max() / bound)
        near = slice(-(len(th) - 3000), None)  # the near-pole points (and the poles)
        assert err[near].max() <= bound * (1 + 1e-9)
        # tangent: no normal component is created. Up to the conditioning of angles() near a pole:
        # theta = acos(z) is off by ~eps / theta (4e-13 at theta = 1e-5, 4e-11 at 1e-7)
        assert np.abs(np.asarray(dot(got, p))).max() < 1e-9


# --------------------------------------------------------------------------------------
# coordinate helpers


def test_coordinate_helpers_round_trip():
    rng = np.random.default_rng(3)
    th = np.arccos(rng.uniform(-1, 1, 200))
    ph = rng.uniform(0, 2 * np.pi, 200)
    p = point(th, ph)
    t2, p2 = angles(p)
    np.testing.assert_allclose(t2, th, atol=1e-12)
    np.testing.assert_allclose(np.mod(p2 - ph + np.pi, 2 * np.pi) - np.pi, 0, atol=1e-12)
    et, ep = basis(th, ph)
    # e_theta = dp/dtheta, e_phi = dp/(sin theta dphi), by finite differences
    d = 1e-6
    pt = (point(th + d, ph) - point(th - d, ph)) * (0.5 / d)
    pp = (point(th, ph + d) - point(th, ph - d)) * (0.5 / d / np.sin(th))
    for a, b in ((et, pt), (ep, pp)):
        np.testing.assert_allclose(np.asarray(a.to_array()), np.asarray(b.to_array()), atol=1e-8)
    # right-handed: e_theta x e_phi = p (outward)
    np.testing.assert_allclose(np.asarray(cross(et, ep).to_array()), np.asarray(p.to_array()), atol=1e-12)
    v = tangent(0.3, -1.2, th, ph)
    a, b = components(v, th, ph)
    np.testing.assert_allclose(a, 0.3, atol=1e-12)
    np.testing.assert_allclose(b, -1.2, atol=1e-12)
