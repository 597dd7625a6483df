"""Semi-Lagrangian advection of scalars on the sphere (Huang 2022 Sec. 3.4.2, App. B; spec SS-5).

References the code did not compute: analytic rotations of the fields, Williamson et al.
(1992) test case 1, the rotated problem (equivariance), trajectories integrated by RK4. The
"latlong" baseline runs on the same cases to show that each check can fail (it does, near the
poles). The vector step is checked in test_soapfilm_advect_vector.py (same helpers).

All runs use the grids COARSE = 33 x 64 and FINE = 65 x 128 (n_theta odd: a row on the
equator) and one compiled loop per (grid, order, scheme), so the file compiles few programs.

Measured (float64; see each test for the settings; machine loaded, numbers not timings):

=================================  ===============  ===========
check                               great_circle     latlong
=================================  ===============  ===========
SS-5 edge, max err > 3 cells        1.4e-4           1.0
SS-5 edge, polar-cap l1 / area      0.030            0.076
Williamson 1, l2 (33x64 / 65x128)   0.469 / 0.282    1.17
equivariance f, max (33 / 65)       0.021 / 6.3e-3   0.29
order 1 / 2, T = 1.2 in 4 steps     0.174 / 0.024    -
=================================  ===============  ===========
"""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import lax

from appearance_jax.core.vec import Vec3, cross, dot
from appearance_jax.soapfilm import advect as adv
from appearance_jax.soapfilm.grid import SphereGrid, angles, components, point

GC, LL = "great_circle", "latlong"
COARSE, FINE = SphereGrid(33, 64), SphereGrid(65, 128)


# --------------------------------------------------------------------------------------
# helpers


def _faces(g, field, dtype=np.float64):
    """(u_theta, u_phi) of the tangent field ``field: Vec3 -> Vec3`` at the staggered faces."""
    tt, pt = g.u_theta_points()
    tp, pp = g.u_phi_points()
    ut = components(field(point(tt, pt)), tt, pt)[0]
    up = components(field(point(tp, pp)), tp, pp)[1]
    return jnp.asarray(ut, dtype), jnp.asarray(up, dtype)


@functools.partial(jax.jit, static_argnames=("g", "order", "scheme"))
def _scalar_steps(g, f, ut, up, dt, n, order=2, scheme=GC):
    """n steps of advect_scalar with the velocity held fixed (n and dt traced: one compiled
    loop per grid, order, scheme and dtype)."""
    return lax.fori_loop(0, n, lambda i, f: adv.advect_scalar(g, f, ut, up, dt, order, scheme), f)


@functools.partial(jax.jit, static_argnames=("g", "order", "scheme"))
def _velocity_steps(g, ut, up, dt, n, order=2, scheme=GC):
    """n steps of advect_velocity (the velocity advects itself)."""
    return lax.fori_loop(0, n, lambda i, u: adv.advect_velocity(g, u[0], u[1], dt, order, scheme),
                         (ut, up))


def _rotate(axis, angle, p):
    """Rodrigues: p rotated by ``angle`` about the unit ``axis`` (right-handed)."""
    a = Vec3(*axis)
    c, s = math.cos(angle), math.sin(angle)
    return p * c + cross(a, p) * s + a * (dot(a, p) * (1 - c))


def _bilinear_bound(g, m_tt, m_pp):
    """Largest error of bilinear interpolation in (theta, phi) of a function whose second
    derivatives are bounded by m_tt, m_pp: (dth^2 m_tt + dph^2 m_pp) / 8."""
    return (g.dtheta ** 2 * m_tt + g.dphi ** 2 * m_pp) / 8


# a smooth, non-uniform, time-independent flow that crosses both poles: a rotation about a
# tilted axis plus the tangent part of a constant vector (divergent: sources and sinks)
_W = Vec3(0.3, 0.8, -0.5)
_D = Vec3(0.6, -0.2, 0.7)
_C = Vec3(0.0, 0.6, 0.8)


def _flow(p):
    return cross(_W, p) + (_D - p * dot(_D, p)) * 0.5


def _scalar(p):
    return jnp.exp(-2 * dot(p - _C, p - _C)) + 0.5 * p.x * p.z


# bounds on the derivatives of _scalar and _flow in (theta, phi), extended across the poles:
# |f_thth| <= 4.07 and |f_phph| <= 1.66 (measured on an 801^2 grid over theta in
# [-0.2, pi + 0.2]; an analytic bound is 2 (|f''|_3D + |f'|_3D) <= 8); |grad f| <= 4 max r
# exp(-2 r^2) + 0.5 = 2 e^-1/2 + 0.5 < 1.72. For the velocity components the bounds of
# test_soapfilm_grid.test_sample_vector_near_the_poles give the per-sample vector error
# _flow_interp(g) (|W| = 0.99, |D| / 2 = 0.47).
_F_TT, _F_PP, _F_GRAD = 4.1, 1.7, 1.72


def _flow_interp(g):
    d2t, d2p = g.dtheta ** 2, g.dphi ** 2
    rot = math.hypot(d2p / 8, (d2t + d2p) / 8) * 0.99
    grad = math.hypot(d2t / 2 + d2p / 8, (d2t + d2p) / 8) * 0.47
    return rot + grad


# --------------------------------------------------------------------------------------
# bad input


def test_bad_order_and_scheme_raise():
    g = SphereGrid(8, 16)
    f = jnp.zeros(g.shape)
    ut, up = jnp.zeros(g.theta_shape), jnp.zeros(g.shape)
    for fn, args in ((adv.advect_scalar, (g, f, ut, up, 0.1)), (adv.advect_velocity, (g, ut, up, 0.1))):
        with pytest.raises(ValueError, match="order"):
            fn(*args, order=3)
        with pytest.raises(ValueError, match="order"):
            fn(*args, order=0)
        with pytest.raises(ValueError, match="scheme"):
            fn(*args, scheme="x")
    p = point(jnp.array([0.5]), jnp.array([0.1]))
    with pytest.raises(ValueError, match="order"):
        adv.backtrace(p, Vec3(0.0, 0.0, 0.0) + p * 0, lambda q: q * 0, 0.1, order=3)


# --------------------------------------------------------------------------------------
# SS-5 / Fig. 3.8: a sharp edge carried over the north pole


def test_sharp_edge_over_the_pole_ss5():
    """f = 1 on one side of a great circle, 0 on the other, rotated about y (the flow crosses
    the pole) by beta = 8 cells in 4 steps: the edge starts beta/2 on one side of the pole and
    ends beta/2 on the other. Exact: f0(R(-beta) p).

    Bilinear interpolation is monotone: the values stay in [0, 1]. Each step smears the edge by
    at most one stencil (one cell in theta and one in phi, <= sqrt(2) dtheta on the sphere), so
    beyond 4 sqrt(2) dtheta < 6 dtheta from the exact edge the result is exact but for the
    departure-point error (great circle vs the true small circle: O(dt^3) per step, far below a
    cell); beyond 3 cells only the tails of four smearings remain (measured 1.4e-4, asserted
    1e-3); beyond 2 cells 1/50 (measured 3.6e-3)."""
    g = COARSE
    h = g.dtheta
    th, _ = g.centres()
    P = point(*g.centres())
    area = g.cell_areas()
    axis = (0.0, 1.0, 0.0)
    ut, up = _faces(g, lambda p: cross(Vec3(*axis), p))
    n, dt = 4, 2 * h
    beta = n * dt
    n0 = _rotate(axis, -beta / 2, Vec3(1.0, 0.0, 0.0))
    # (float64, not weakly typed: the signature, and so the compiled loops, of the other tests)
    f0 = lambda p: jnp.where(dot(n0, p) > 0, 1.0, 0.0).astype(jnp.float64)
    exact = np.asarray(f0(_rotate(axis, -beta, P)))
    dist = np.arcsin(np.abs(np.asarray(dot(_rotate(axis, beta, n0), P))))  # to the exact edge
    cap = th < 10 * h  # the polar cap the edge crosses
    err = {}
    for scheme, order in ((GC, 1), (GC, 2), (LL, 2)):
        out = np.asarray(_scalar_steps(g, f0(P), ut, up, dt, n, order, scheme))
        assert out.min() >= -1e-12 and out.max() <= 1 + 1e-12, scheme  # no over/undershoot
        e = np.abs(out - exact)
        err[scheme, order] = (e[dist > 2 * h].max(), e[dist > 3 * h].max(), e[dist > 6 * h].max(),
                              (e * area)[cap].sum() / area[cap].sum())
    for order in (1, 2):
        far2, far3, far6, _ = err[GC, order]
        assert far2 < 0.02 and far3 < 1e-3 and far6 < 1e-12, err[GC, order]
    # the baseline's Euler steps in (theta, phi) put whole cells on the wrong side of the edge
    assert err[LL, 2][1] > 0.5
    assert err[LL, 2][3] > 2 * err[GC, 2][3], err  # measured 0.076 vs 0.030 (2.5x)


# --------------------------------------------------------------------------------------
# Williamson et al. (1992), test case 1


def test_williamson_cosine_bell_over_the_poles():
    """A cosine bell (radius R = 1/3, h0 = 1, centred at lambda = 3 pi / 2 on the equator)
    carried once around the sphere by the solid-body rotation with alpha = pi / 2 (about the x
    axis: the bell passes over both poles). n_phi steps per revolution (Courant number ~1 at
    the equator). Normalised errors (Williamson Eqs. 82-84, area-weighted):

    ============  ======  ======  ======
    grid            l1      l2     linf
    ============  ======  ======  ======
    33 x 64       0.930   0.469   0.401
    65 x 128      0.497   0.282   0.184
    33 x 64 (LL)  2.86    1.17    0.557
    ============  ======  ======  ======

    (bilinear semi-Lagrangian is diffusive: the bell spans 3.5 cells at 33 x 64, where the
    first order of the method is not yet reached; measured l2 order 0.75.)"""
    c0 = Vec3(0.0, -1.0, 0.0)

    def bell(p):
        r = np.arccos(np.clip(np.asarray(dot(c0, p)), -1, 1))
        return np.where(r < 1 / 3, 0.5 * (1 + np.cos(3 * np.pi * r)), 0.0)

    res = {}
    for g, scheme in ((COARSE, GC), (FINE, GC), (COARSE, LL)):
        area = g.cell_areas()
        f0 = bell(point(*g.centres()))
        ut, up = _faces(g, lambda p: cross(Vec3(1.0, 0.0, 0.0), p))
        steps = g.n_phi
        out = np.asarray(_scalar_steps(g, jnp.asarray(f0), ut, up, 2 * np.pi / steps, steps, 2, scheme))
        e = out - f0
        integ = lambda v: (v * area).sum()
        res[g.n_theta, scheme] = (integ(np.abs(e)) / integ(np.abs(f0)),
                                  math.sqrt(integ(e * e) / integ(f0 * f0)),
                                  np.abs(e).max() / f0.max())
        assert out.min() >= -1e-12 and out.max() <= 1 + 1e-12
    l1, l2, linf = zip(res[33, GC], res[65, GC])
    assert l2[0] < 0.55 and l2[1] < 0.33, res
    assert l2[1] < 0.75 * l2[0] and l1[1] < 0.75 * l1[0] and linf[1] < 0.75 * linf[0], res
    assert res[33, LL][1] > 2 * l2[0], res


# --------------------------------------------------------------------------------------
# rotation equivariance


_ROT_AXIS, _ROT_ANGLE = (0.0, 1.0, 0.0), np.pi / 2  # moves the north pole to +x on the equator


def _fwd(p):
    return _rotate(_ROT_AXIS, _ROT_ANGLE, p)


def _back(p):
    return _rotate(_ROT_AXIS, -_ROT_ANGLE, p)


def _rotated_flow(p):
    """R u(R^-1 p): the flow of the rotated problem."""
    return _fwd(_flow(_back(p)))


def test_rotation_equivariance_scalar():
    """advect(f, u) == R^-1 advect(f o R^-1, R u o R^-1) (resampled), for a smooth f and the
    divergent flow _flow; the rotation moves the pole to the equator (5 steps, dt = 0.1).

    Tolerance: each side makes n interpolations of f (each <= _bilinear_bound with the bounds
    of f) and n departure points off by <= dt * (velocity interpolation error), worth
    |grad f| * dt * _flow_interp; the resampling adds one interpolation:
    tol = (2 n + 1) E_f + 2 n dt |grad f| E_u (0.083 / 0.021 at 33x64 / 65x128; measured 0.021 /
    6.3e-3, latlong 0.29)."""
    n, dt = 5, 0.1
    errs = {}
    for g, scheme in ((COARSE, GC), (FINE, GC), (COARSE, LL)):
        P = point(*g.centres())
        tol = (2 * n + 1) * _bilinear_bound(g, _F_TT, _F_PP) + 2 * n * dt * _F_GRAD * _flow_interp(g)
        a = np.asarray(_scalar_steps(g, _scalar(P), *_faces(g, _flow), dt, n, 2, scheme))
        b = _scalar_steps(g, _scalar(_back(P)), *_faces(g, _rotated_flow), dt, n, 2, scheme)
        e = np.abs(np.asarray(g.sample(b, *angles(_fwd(P)))) - a).max()
        errs[g.n_theta, scheme] = (e, tol)
        if scheme == GC:
            assert e < tol, errs
    print("equivariance scalar", errs)
    assert errs[65, GC][0] < 0.4 * errs[33, GC][0], errs  # O(h^2)
    assert errs[33, LL][0] > 5 * errs[33, GC][0], errs  # the baseline is not equivariant


# --------------------------------------------------------------------------------------
# App. B: the half step


def _flow_back(p, T, m=400):
    """Departure point of p after time T in the exact flow _flow (RK4 on the sphere)."""
    h = -T / m
    nrm = lambda q: q / jnp.sqrt(dot(q, q))

    def body(i, q):
        k1 = _flow(q)
        k2 = _flow(nrm(q + k1 * (h / 2)))
        k3 = _flow(nrm(q + k2 * (h / 2)))
        k4 = _flow(nrm(q + k3 * h))
        return nrm(q + (k1 + k2 * 2 + k3 * 2 + k4) * (h / 6))

    return jax.jit(lambda q: lax.fori_loop(0, m, body, q))(p)


def test_order2_beats_order1():
    """A smooth scalar carried by the steady flow _flow to T = 1.2 in 2 and 4 steps, against
    f0 at the exact departure points (RK4, 400 steps). The trajectory error dominates at these
    large steps: order 1 is first order in dt, the half step much more accurate.
    Measured max error (33x64): order 1 0.319 / 0.174, order 2 0.046 / 0.024 (2 / 4 steps)."""
    g = COARSE
    P = point(*g.centres())
    ut, up = _faces(g, _flow)
    T = 1.2
    exact = np.asarray(_scalar(_flow_back(P, T)))
    err = {}
    for n in (2, 4):
        for order in (1, 2):
            out = np.asarray(_scalar_steps(g, _scalar(P), ut, up, T / n, n, order))
            err[n, order] = np.abs(out - exact).max()
    print("order", err)
    for n in (2, 4):
        assert err[n, 2] < 0.25 * err[n, 1], err
    assert 0.4 < err[4, 1] / err[2, 1] < 0.65, err  # order 1: first order in dt


# --------------------------------------------------------------------------------------
# gradients and float32


@functools.partial(jax.jit, static_argnames=("g", "order"))
def _scalar_grad(g, f, ut, up, w, dt, order):
    loss = lambda f, a, b: jnp.sum(w * adv.advect_scalar(g, f, a, b, dt, order) ** 2)
    return jax.grad(loss, argnums=(0, 1, 2))(f, ut, up)


def _on_the_pole(g):
    """A rigid rotation that moves the centres of column 0 (phi_0 = dphi / 2) along their
    meridian (u_theta = 1 there, u_phi = 0 after averaging): with dt = dtheta / 2 the departure
    point of the centre (dtheta / 2, phi_0) is the north pole itself (both orders: the half step
    finds the same velocity)."""
    phi0 = 0.5 * g.dphi
    axis = Vec3(-math.sin(phi0), math.cos(phi0), 0.0)
    return _faces(g, lambda p: cross(axis, p)), 0.5 * g.dtheta


def test_gradients_are_finite():
    """jax.grad of a loss of advect_scalar (order 2, the default; one compiled reverse pass)
    w.r.t. the field and both velocity components: finite with zero velocity at some or all
    points and with a departure point exactly on the pole (acos and atan2 at their singular
    points); the velocity gradient agrees with a central difference."""
    g = COARSE
    th, ph = g.centres()
    f = jnp.asarray(np.cos(th) + 0.3 * np.sin(th) * np.cos(ph))
    w = jnp.asarray(np.random.default_rng(0).standard_normal(g.shape))
    ut, up = _faces(g, _flow)
    rows = jnp.arange(g.n_theta)[:, None] < g.n_theta // 2  # no velocity on the northern half
    (pa, pb), pdt = _on_the_pole(g)
    for order in (1, 2):
        q, _ = adv.departure_points(g, pa, pb, *(jnp.asarray(x) for x in g.centres()),
                                    *g.velocity_at_centres(pa, pb), pdt, order=order)
        assert abs(float(q.z[0, 0]) - 1.0) < 1e-15  # the case is what it claims
    cases = {
        "flow": (ut, up, 0.1),
        "half zero": (jnp.where(rows[1:], 0.0, ut), jnp.where(rows, 0.0, up), 0.1),
        "zero": (jnp.zeros_like(ut), jnp.zeros_like(up), 0.1),
        "departure on the pole": (pa, pb, pdt),
    }
    for name, (a, b, dt) in cases.items():
        grads = _scalar_grad(g, f, a, b, w, dt, 2)
        assert all(bool(jnp.all(jnp.isfinite(x))) for x in grads), name
        assert float(jnp.abs(grads[0]).max()) > 0
    # the velocity gradient is right: central difference along u itself
    _, ga, gb = _scalar_grad(g, f, ut, up, w, 0.1, 2)
    d = float(jnp.sum(ga * ut) + jnp.sum(gb * up))
    lo = lambda s: float(jnp.sum(w * _scalar_steps(g, f, ut * (1 + s), up * (1 + s), 0.1, 1) ** 2))
    fd = (lo(1e-6) - lo(-1e-6)) / 2e-6
    assert abs(d - fd) < 1e-5 * max(1.0, abs(fd)), (d, fd)


def test_float32_matches_float64():
    """float32 in, float32 out, no NaN, close to float64: the departure points carry float32
    rounding (~1e-7 rad, 1e-6 of a cell), worth |grad f| 1e-7 per step; measured 3.0e-6 after
    5 steps (the float32 rounding of f itself is 6e-8)."""
    g = COARSE
    P = point(*g.centres())
    f64 = _scalar(P)
    u64 = _faces(g, _flow)
    u32 = tuple(x.astype(jnp.float32) for x in u64)
    s64 = _scalar_steps(g, f64, *u64, 0.1, 5)
    s32 = _scalar_steps(g, f64.astype(jnp.float32), *u32, jnp.float32(0.1), 5)
    assert s32.dtype == jnp.float32 and bool(jnp.all(jnp.isfinite(s32)))
    err = float(jnp.abs(s32 - s64).max())
    print("float32", err)
    assert err < 1e-5, err
