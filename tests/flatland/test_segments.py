"""Flatland's segment shape and semi-transparent interfaces (issue 21): the segment intersection against a
brute-force solve, masking tallies of segment rows against their closed forms (coverage, the coin per
crossing, the first-hit offsets), a diffuse segment row's energy split, and the first-hit offset convention
of the tracer (the h of flatland.launch)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import flatland as fl
from appearance_jax.core.frame import fiber_direction
from appearance_jax.core.vec import Vec3
from appearance_jax.flatland import geometry as G

N = 2**15


def _row(L, P, psi=0.0, coverage=1.0, interface=None):
    half = 0.5 * L
    p, q = (-half * math.cos(psi), -half * math.sin(psi)), (half * math.cos(psi), half * math.sin(psi))
    itf = interface if interface is not None else fl.Interface("absorber", coverage=coverage)
    return fl.Section((fl.segment(p, q, itf),), (fl.Medium(),), jnp.asarray(P, float), 8).validate()


def _view(alpha):
    """A viewer at angle alpha (rad) from the row's normal +z, in the section plane."""
    return Vec3(0.0, math.sin(alpha), math.cos(alpha))


def test_segment_intersection_is_the_brute_force_solve():
    rng = np.random.default_rng(3)
    n = 4000
    py, pz = rng.uniform(-2, 2, (2, n))
    ang = rng.uniform(0, 2 * np.pi, n)
    dy, dz = np.cos(ang), np.sin(ang)
    cy, cz, a, psi = 0.3, -0.2, 0.8, 0.7
    t, hit = G.intersect_segment(py, pz, dy, dz, cy, cz, a, psi, np.zeros(n, bool))
    t, hit = np.asarray(t), np.asarray(hit)
    e = np.array([np.cos(psi), np.sin(psi)])
    for k in range(n):  # solve p + t d = c + s e
        A = np.array([[dy[k], -e[0]], [dz[k], -e[1]]])
        ts, ss = np.linalg.solve(A, np.array([cy - py[k], cz - pz[k]]))
        expect = ts > 0 and abs(ss) <= a
        assert hit[k] == expect
        if expect:
            assert abs(t[k] - ts) < 1e-12
    assert 0.1 * n < hit.sum() < 0.9 * n
    # a ray leaving the segment cannot meet it again; a ray along its line does not meet it
    t2, hit2 = G.intersect_segment(cy, cz, 0.0, 1.0, cy, cz, a, psi, True)
    assert not bool(hit2) and math.isinf(float(t2))
    t3, hit3 = G.intersect_segment(cy - 2 * e[0], cz - 2 * e[1], e[0], e[1], cy, cz, a, psi, False)
    assert not bool(hit3)


@pytest.mark.parametrize("psi", [0.0, 0.6, -1.1])
def test_segment_row_coverage_is_the_projected_length(psi):
    """A row of solid absorbing segments (length L, period P, tilt psi) seen along u covers
    min(1, L |cross(u, e)| / (P |u_z|)) of its projected period; rays meet a segment first over its whole
    projected width when copies do not overlap (h in [-1, 1])."""
    L, P = 1.2, 2.0
    row = _row(L, P, psi)
    for i, alpha in enumerate((0.0, 0.5, -0.9, 2.5)):
        wo = _view(alpha)
        u = (-math.sin(alpha), -math.cos(alpha))
        W = L * abs(u[0] * math.sin(psi) - u[1] * math.cos(psi))
        Pp = P * abs(u[1])
        ref = min(1.0, W / Pp)
        r = fl.first_hits(row, wo, jax.random.PRNGKey(i), N)
        got = float(r.fraction[0])
        assert abs(got - ref) <= 4.5 * float(r.stderr[0]) + 2.0 / N, (alpha, got, ref)
        assert abs(float(r.fraction.sum()) - 1.0) < 1e-12
        assert float(r.truncated) == 0.0
        if W < Pp:
            np.testing.assert_allclose(np.asarray(r.h_range[0]), [-1.0, 1.0], atol=4.0 * Pp / (W * N) * 2)


@pytest.mark.parametrize("c", [0.3, 0.75])
def test_semi_transparent_row_draws_a_coin_per_crossing(c):
    """Coverage c: where the projected copies overlap n or n + 1 deep, a ray passes with probability
    (1 - c)^n or (1 - c)^(n + 1), so the covered fraction is 1 - [(1 - f)(1 - c)^n + f (1 - c)^(n + 1)],
    W / Pp = n + f (W, Pp: projected segment width and period). One coin per row would give c instead."""
    L, P, psi = 1.6, 1.0, 0.9
    row = _row(L, P, psi, coverage=c)
    for i, alpha in enumerate((0.0, 0.7, 1.2)):
        u = (-math.sin(alpha), -math.cos(alpha))
        ratio = L * abs(u[0] * math.sin(psi) - u[1] * math.cos(psi)) / (P * abs(u[1]))
        n, f = math.floor(ratio), ratio - math.floor(ratio)
        ref = ratio * c if ratio <= 1 else 1.0 - ((1 - f) * (1 - c) ** n + f * (1 - c) ** (n + 1))
        r = fl.first_hits(row, _view(alpha), jax.random.PRNGKey(10 + i), N)
        got = float(r.fraction[0])
        assert abs(got - ref) <= 4.5 * float(r.stderr[0]) + 2.0 / N, (alpha, ratio, got, ref)
    # coverage 0: the shape is never there; coverage 1 draws no coin and is solid
    assert float(fl.first_hits(_row(L, P, psi, 0.0), _view(0.3), jax.random.PRNGKey(0), 1024).fraction[0]) == 0.0
    assert not fl.Interface("absorber").semi_transparent and fl.Interface("absorber", coverage=0.5).semi_transparent


def test_diffuse_segment_row_splits_the_energy_by_coverage():
    """Horizontal white diffuse segments (length L, period P, coverage c): a ray from above is reflected up
    (and escapes, the row being flat) with probability c L / P and passes down otherwise, from either side;
    nothing is absorbed, the reflected rays leave on the side they came from."""
    L, P, c = 0.6, 1.0, 0.7
    row = _row(L, P, 0.0, interface=fl.Interface("diffuse", albedo=1.0, coverage=c))
    h = jnp.linspace(-1.0, 1.0, N, endpoint=False) + 1.0 / N
    for i, alpha in enumerate((0.3, 2.6)):
        wi = _view(alpha)
        rec = fl.trace(row, wi, h, jax.random.PRNGKey(20 + i), max_events=3, mode="random")
        w = np.asarray(rec.weight[..., 0])
        dz = np.asarray(rec.direction.z)
        side = np.sign(float(wi.z))
        back = (w * (dz * side > 0)).sum() / N
        through = (w * (dz * side < 0)).sum() / N
        p = c * L / P
        se = math.sqrt(p * (1 - p) / N)
        assert abs(back - p) < 4.5 * se + 2.0 / N, (alpha, back, p)
        assert abs(back + through - 1.0) < 1e-9
        assert float(np.abs(np.asarray(rec.absorbed)).max()) == 0.0 and float(np.asarray(rec.residual).max()) == 0.0


def test_first_hit_offset_is_the_launch_offset():
    """A bounded section's rays meet its outer shape first at the offset h they were launched with."""
    sec = fl.fiber(1.55, eccentricity=0.6, rotation=0.4)
    h = jnp.linspace(-0.99, 0.99, 23)
    rec = fl.trace(sec, fiber_direction(0.3, 0.7), h, max_events=2)
    np.testing.assert_allclose(np.asarray(rec.first_h), np.asarray(h), atol=1e-12)
    assert np.all(np.asarray(rec.first_shape) == 0)


def test_segment_and_coverage_bad_input_is_named():
    with pytest.raises(ValueError, match="coverage"):
        _row(1.0, 2.0, coverage=1.5)
    with pytest.raises(ValueError, match="half length"):
        fl.segment((0.0, 0.0), (0.0, 0.0))
    s = fl.segment((0.0, 0.0), (1.0, 0.0))
    from dataclasses import replace
    with pytest.raises(ValueError, match="segment is open"):
        fl.Section((replace(s, inside=1),), (fl.Medium(), fl.Medium()), 2.0).validate()
    with pytest.raises(ValueError, match="geometry"):
        fl.Section((replace(s, geometry="square"),), (fl.Medium(),), 2.0).validate()
    with pytest.raises(ValueError, match="wo.z"):
        fl.first_hits(_row(1.0, 2.0), Vec3(0.0, 1.0, 0.0), jax.random.PRNGKey(0))
    with pytest.raises(ValueError, match="periodic"):
        fl.first_hits(fl.fiber(1.5), _view(0.2), jax.random.PRNGKey(0))
