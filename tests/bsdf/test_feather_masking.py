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
