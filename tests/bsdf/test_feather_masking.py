"""bsdf.feather_masking (Padrón App. B.2.1; spec seed-000 M23): the barbule row's covered fraction
against flatland's ray-cast masking_fraction (its own intersection code; binomial standard error), the
visible offset range against rays cast at the row one by one, the thesis' Fig. 5.9 closed form, and
finite values at the edge directions."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.bsdf import feather_masking as fm
from appearance_jax.core.vec import Vec3
from appearance_jax.flatland import ellipse_row, masking_fraction
from appearance_jax.flatland import geometry as G


def test_fig_5_9_closed_form():
    """e_bb = delta_bb = 1: w' = 1 / (2 cos psi), full cover from 60 deg on, the diameter fully visible
    until then (spec M23's example)."""
    psi = np.radians([0.0, 20.0, 45.0, 59.0, 61.0, 80.0, -45.0])
    w, lo, hi = (np.asarray(v) for v in fm.barbule_masking(np.sin(psi), np.cos(psi), 1.0, 1.0))
    np.testing.assert_allclose(w, np.minimum(1.0, 1.0 / (2.0 * np.cos(psi))), rtol=1e-14)
    full = np.abs(psi) < np.radians(60.0)
    assert np.all(lo[full] == -1.0) and np.all(hi[full] == 1.0)
    # beyond 60 deg the visible length is 2 P cos(psi) / W = 4 cos(psi)
    np.testing.assert_allclose((hi - lo)[~full], 4.0 * np.cos(psi[~full]), rtol=1e-14)


@pytest.mark.parametrize("e_bb, delta_bb", [(1.0, 1.0), (0.4, 0.3), (2.0, 0.1)])
def test_covered_fraction_is_flatlands_ray_cast(e_bb, delta_bb):
    period = 1.0 + delta_bb
    row = ellipse_row(period, 0.5, 0.5 * e_bb)  # flatland: the row along y, z = the vane normal
    for i, psi in enumerate(np.radians([10.0, 35.0, 55.0, 70.0])):
        frac, se, trunc = masking_fraction(row, Vec3(0.0, math.sin(psi), math.cos(psi)), jax.random.PRNGKey(i),
                                           2 ** 15)
        w = float(fm.barbule_masking(math.sin(psi), math.cos(psi), e_bb, delta_bb)[0])
        assert float(trunc) == 0.0
        # stratified offsets: the error of a covered fraction is at most ~2 / n per edge, below se
        assert abs(float(frac) - w) <= 4.5 * float(se) + 4.0 / 2 ** 15, (psi, frac, w)


def _visible_h(e_bb, delta_bb, wx, wy, n=20000):
    """Rays cast along -w' over three periods at a row of 41 ellipses; the offsets h (flatland's
    tangent-point convention) of the rays whose first hit is the centre ellipse."""
    ax, ay, P = 0.5, 0.5 * e_bb, 1.0 + delta_bb
    r = math.hypot(wx, wy)
    dx, dy = wx / r, wy / r
    left = np.array([dy, -dx])  # to the left of the direction of travel -w'
    half = float(G.half_width(-dx, -dy, ax, ay, 0.0))
    s = np.linspace(-1.5 * P, 1.5 * P, n)
    ox, oy = s * left[0] + 30 * dx, s * left[1] + 30 * dy  # far along +w', moving towards -w'
    cx = jnp.arange(-20, 21)[None, :] * P
    t, hit = G.intersect(jnp.asarray(ox)[:, None], jnp.asarray(oy)[:, None], -dx, -dy, cx, 0.0, ax, ay, 0.0,
                         0.0, 2 * math.pi, jnp.zeros(cx.shape, bool))
    t = np.where(np.asarray(hit), np.asarray(t), np.inf)
    first = np.argmin(t, axis=1)
    mine = np.isfinite(t.min(axis=1)) & (first == 20)
    return s[mine] / half


@pytest.mark.parametrize("psi_deg", [70.0, -70.0, 30.0, 180.0 - 75.0])
def test_visible_range_is_what_rays_reach(psi_deg):
    """Beyond full cover the neighbour nearer the viewer hides one end of the diameter: the offsets of
    the rays that reach the barbule first span [h-, h+] (to the rays' spacing), on the side the
    geometry says; seen from below (psi > 90 deg) as well."""
    e_bb, delta_bb = 1.0, 1.0
    psi = math.radians(psi_deg)
    wx, wy = math.sin(psi), math.cos(psi)
    h = _visible_h(e_bb, delta_bb, wx, wy)
    _, lo, hi = (float(v) for v in fm.barbule_masking(wx, wy, e_bb, delta_bb))
    step = 3 * (1 + delta_bb) / 20000 / float(G.half_width(-wx, -wy, 0.5, 0.5 * e_bb, 0.0))
    assert h.min() == pytest.approx(lo, abs=2 * step) and h.max() == pytest.approx(hi, abs=2 * step)
    if abs(psi_deg) < 60:
        assert lo == -1.0 and hi == 1.0


def test_edges_are_finite():
    w, lo, hi = (np.asarray(v) for v in fm.barbule_masking(jnp.asarray([0.0, 1.0, -1.0, 0.0]),
                                                           jnp.asarray([0.0, 0.0, 0.0, 1.0]), 1.0, 1.0))
    assert np.all(np.isfinite(w)) and np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))
    assert w[0] == pytest.approx(0.5) and w[3] == pytest.approx(0.5)  # along the axis: the normal view
    assert np.all(w[1:3] == 1.0) and np.all(hi[1:3] == lo[1:3])  # grazing: covered, nothing visible
    g = jax.grad(lambda e: jnp.sum(fm.barbule_masking(jnp.asarray([0.0, 1.0, 0.3]), jnp.asarray([0.0, 0.0, 0.2]), e,
                                                      1.0)[0]))(1.0)
    assert np.isfinite(float(g))


@pytest.mark.parametrize("kw, match", [(dict(e_bb=0.0, delta_bb=1.0), "e_bb = 0.0"),
                                       (dict(e_bb=1.0, delta_bb=-0.1), "delta_bb = -0.1"),
                                       (dict(e_bb=float("nan"), delta_bb=1.0), "e_bb")])
def test_bad_parameters_are_named(kw, match):
    with pytest.raises(ValueError, match=match):
        fm.barbule_masking(0.3, 0.9, **kw)


# ------------------------------------------------------------------------------ barb masking (M24)

def _brute_barb(wx, wy, e_b, l_bb, theta, w_bp, w_bd, corner=1, n=40000, copies=12):
    """Dense rays over one period, each intersected with 2 copies + 1 barbs and barbule segments
    (numpy: circle-like quadratic and segment crossings written here) and composited front to back."""
    r = math.hypot(wx, wy)
    dx, dy = wx / r, wy / r
    X = 1 + 2 * l_bb * math.cos(theta)
    cy = corner * l_bb * math.sin(theta)
    s = ((np.arange(n) + 0.5) / n - 0.5) * X * abs(dy)  # one projected period, centred
    ox, oy = s * dy + 50 * dx, -s * dx + 50 * dy         # far towards the viewer
    hits = []                                             # (travel distance, coverage, kind)
    for k in range(-copies, copies + 1):
        cx = k * X
        # barb: (x - cx)^2 / a^2 + y^2 / b^2 = 1 along o - t d
        a, b = 0.5, 0.5 * e_b
        px, py = ox - cx, oy
        A = dx * dx / a ** 2 + dy * dy / b ** 2
        B = -2 * (px * dx / a ** 2 + py * dy / b ** 2)
        C = px * px / a ** 2 + py * py / b ** 2 - 1
        disc = B * B - 4 * A * C
        t = np.where(disc > 0, (-B - np.sqrt(np.maximum(disc, 0))) / (2 * A), np.inf)
        hits.append((t, np.ones(n), 0))
        for (x0, y0), (x1, y1), cov, kind in (((cx + 0.5, 0.0), (cx + X / 2, cy), w_bp, 1),
                                              ((cx + X / 2, cy), (cx + X - 0.5, 0.0), w_bd, 2)):
            ex, ey = x1 - x0, y1 - y0
            den = dx * ey - dy * ex  # solve t d + u e = o - p0 (Cramer)
            rx, ry = x0 - ox, y0 - oy
            tt = (-rx * ey + ry * ex) / den
            u = (-dx * ry + dy * rx) / den
            hits.append((np.where((u > 0) & (u < 1) & (tt > 0), tt, np.inf), np.full(n, cov), kind))
    T = np.stack([h[0] for h in hits])
    cov = np.stack([h[1] for h in hits])
    kind = np.array([h[2] for h in hits])
    order = np.argsort(T, axis=0)
    T, cov, kind = np.take_along_axis(T, order, 0), np.take_along_axis(cov, order, 0), kind[order]
    cov = np.where(np.isfinite(T), cov, 0.0)
    trans = np.cumprod(1 - cov, axis=0)
    before = np.vstack([np.ones((1, n)), trans[:-1]])
    seen = before * cov
    return [float(np.mean(np.sum(np.where(kind == j, seen, 0), 0))) for j in range(3)] + [float(np.mean(trans[-1]))]


@pytest.mark.parametrize("psi_deg, e_b, l_bb, theta_deg, w_bp, w_bd, corner", [
    (0.0, 1.0, 1.0, 30.0, 0.6, 0.6, 1), (35.0, 1.0, 1.0, 30.0, 0.6, 0.3, 1), (-50.0, 2.0, 0.7, 45.0, 0.9, 0.5, 1),
    (65.0, 1.0, 1.5, 20.0, 0.4, 0.8, -1), (110.0, 1.0, 1.0, 30.0, 0.6, 0.6, 1)])
def test_barb_weights_are_the_dense_ray_composite(psi_deg, e_b, l_bb, theta_deg, w_bp, w_bd, corner):
    psi, theta = math.radians(psi_deg), math.radians(theta_deg)
    out = [float(v) for v in fm.barb_masking(math.sin(psi), math.cos(psi), e_b, l_bb, theta, w_bp, w_bd,
                                             corner=corner)]
    ref = _brute_barb(math.sin(psi), math.cos(psi), e_b, l_bb, theta, w_bp, w_bd, corner)
    assert sum(out[:4]) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(out[:4], ref, atol=2e-4)  # the dense rays resolve 1/40000 per edge


def test_barb_masking_closed_forms_and_trends():
    th = math.radians(30.0)
    X = 1 + 2 * math.cos(th)
    # transparent barbules: the barb row alone, w_b = min(1, W / (X cos psi))
    for psi in np.radians([0.0, 30.0, 60.0]):
        w_b, w_bp, w_bd, w_t, _, _ = (float(v) for v in fm.barb_masking(math.sin(psi), math.cos(psi), 1.5, 1.0, th,
                                                                         0.0, 0.0))
        W = 2 * math.sqrt(0.25 * math.cos(psi) ** 2 + 0.5625 * math.sin(psi) ** 2)
        assert w_b == pytest.approx(min(1.0, W / (X * math.cos(psi))), rel=1e-12) and w_bp == w_bd == 0.0
    # opaque barbules at the normal view close every gap; 1/X of the period is barb
    w_b, w_bp, w_bd, w_t, _, _ = (float(v) for v in fm.barb_masking(0.0, 1.0, 1.0, 1.0, th, 1.0, 1.0))
    assert w_t == pytest.approx(0.0, abs=1e-14) and w_b == pytest.approx(1 / X, rel=1e-12)
    assert w_bp == pytest.approx(w_bd, rel=1e-12)
    # the symmetric V seen from -psi swaps proximal and distal (spec Q-F8's mirror)
    a = [float(v) for v in fm.barb_masking(math.sin(0.4), math.cos(0.4), 1.0, 1.0, th, 0.7, 0.3)]
    b = [float(v) for v in fm.barb_masking(-math.sin(0.4), math.cos(0.4), 1.0, 1.0, th, 0.3, 0.7)]
    np.testing.assert_allclose([a[0], a[1], a[2], a[3]], [b[0], b[2], b[1], b[3]], rtol=1e-12)
    # Q-F9: wider barbule gaps (smaller w'_bb in the barbules' frame) let more light through the vane
    w_wide = float(fm.barbule_masking(0.3, 0.95, 1.0, 2.0)[0])
    w_narrow = float(fm.barbule_masking(0.3, 0.95, 1.0, 0.5)[0])
    t = [float(fm.barb_masking(0.3, 0.95, 1.0, 1.0, th, w, w)[3]) for w in (w_narrow, w_wide)]
    assert w_wide < w_narrow and t[1] > t[0]


def test_barb_masking_edges_and_bad_input():
    out = [np.asarray(v) for v in fm.barb_masking(jnp.asarray([0.0, 1.0, 0.0]), jnp.asarray([0.0, 0.0, -1.0]), 1.0,
                                                  1.0, 0.5, 0.6, 0.6)]
    assert all(np.all(np.isfinite(v)) for v in out)
    np.testing.assert_allclose(sum(out[:4]), 1.0, rtol=1e-12)
    assert out[0][1] == 1.0  # in the vane plane the barbs cover everything
    for kw, match in ((dict(e_b=0.0), "e_b = 0.0"), (dict(l_bb=-1.0), "l_bb = -1.0"), (dict(w_bp=1.5), "w_bp = 1.5"),
                      (dict(theta_bb=1.6), "theta_bb = 1.6"), (dict(corner=0), "corner = 0")):
        args = dict(e_b=1.0, l_bb=1.0, theta_bb=0.5, w_bp=0.5, w_bd=0.5)
        args.update(kw)
        corner = args.pop("corner", 1)
        with pytest.raises(ValueError, match=match):
            fm.barb_masking(0.3, 0.9, args["e_b"], args["l_bb"], args["theta_bb"], args["w_bp"], args["w_bd"],
                            corner=corner)


def test_padrons_single_occlusion_differs_only_in_the_corner_case():
    """[T:1371]: Padrón approximates a ray's repeated barbule occlusions by one. With occlusions=1 the
    weights (B.18-normalised) equal the exact ones wherever no ray crosses two barbule layers in front of
    something: every view of the thesis' vane, whose barbs stand above the barbules. A steep inverted V
    seen from below at ~65 deg has rays through two barbule rows, and there they differ (by 0.032)."""
    ang = np.radians(np.linspace(-89.0, 89.0, 179))
    for side in (1.0, -1.0):
        wx, wy = np.sin(ang), side * np.cos(ang)
        exact = np.array([np.asarray(v) for v in fm.barb_masking(wx, wy, 1.6, 1.0, 0.2618, 0.58, 0.58)[:4]])
        one = np.array([np.asarray(v) for v in fm.barb_masking(wx, wy, 1.6, 1.0, 0.2618, 0.58, 0.58, occlusions=1)[:4]])
        np.testing.assert_allclose(one, exact, atol=1e-12)
    a = np.radians(114.5)
    exact = np.array([float(v) for v in fm.barb_masking(np.sin(a), np.cos(a), 1.0, 0.5, 0.8, 0.9, 0.3, corner=-1)[:4]])
    one = np.array([float(v) for v in fm.barb_masking(np.sin(a), np.cos(a), 1.0, 0.5, 0.8, 0.9, 0.3, corner=-1,
                                                      occlusions=1)[:4]])
    assert np.abs(one - exact).max() > 0.02
    assert abs(one.sum() - 1.0) < 1e-12 and np.all(one >= 0)
    with pytest.raises(ValueError, match="occlusions"):
        fm.barb_masking(0.3, 0.9, 1.6, 1.0, 0.26, 0.5, 0.5, occlusions=0)
