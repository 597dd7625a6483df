"""Feather geometry textures (Padrón App. B.3, M30): Bézier fits, barbs, the rasterised angle/length/mask
channels and their 8-bit encoding, checked against straight-line geometry whose answers are closed forms."""

import numpy as np
import pytest

from appearance_jax.bsdf import feather_texture as ft

THETA = 50.0  # barb angle from the rachis [deg]
# a straight rachis along +y and straight vane contours at x = -2 (left) and x = +1.5 (right)
STRAIGHT = ft.Outline(rachis=[[0, 0], [0, 10]], left=[[-2, 0], [-2, 10]], right=[[1.5, 0], [1.5, 10]],
                      shaft_width=(0.4, 0.1))
EXTENT = (-2.5, 2.0, -0.5, 10.5)


def test_bezier_tangent_is_the_derivative():
    c = np.array([[0.0, 0.0], [1.0, 2.0], [3.0, -1.0], [4.0, 1.5]])
    t = np.linspace(0.05, 0.95, 7)
    h = 1e-6
    fd = (ft.bezier(c, t + h) - ft.bezier(c, t - h)) / (2 * h)
    np.testing.assert_allclose(ft.bezier_tangent(c, t), fd, rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(ft.bezier(c, np.array([0.0, 1.0])), c[[0, -1]], atol=1e-15)
    np.testing.assert_allclose(ft.bezier_tangent([[0, 0], [2, 1]], [0.3, 0.7]), [[2, 1], [2, 1]])


def test_fit_bezier_is_least_squares_with_chord_length_parameters():
    # evenly spaced control points on a line: uniform speed, so chord length is the curve's own parameter
    line = np.array([[0.0, 1.0], [1.0, 2.0], [2.0, 3.0], [3.0, 4.0]])
    pts = ft.bezier(line, np.linspace(0, 1, 9))
    np.testing.assert_allclose(ft.fit_bezier(pts, 3), line, atol=1e-12)
    # a noisy arc: the residual is orthogonal to every Bernstein column (the normal equations)
    rng = np.random.default_rng(0)
    phi = np.linspace(0, 2.0, 40)
    pts = np.stack([np.cos(phi), np.sin(phi)], -1) + 0.01 * rng.normal(size=(40, 2))
    c = ft.fit_bezier(pts, 3)
    seg = np.hypot(*np.diff(pts, axis=0).T)
    t = np.concatenate([[0], np.cumsum(seg)]) / seg.sum()
    A = ft.comb_row(3) * t[:, None] ** np.arange(4) * (1 - t[:, None]) ** (3 - np.arange(4))
    np.testing.assert_allclose(A.T @ (pts - ft.bezier(c, t)), 0.0, atol=1e-10)
    assert np.sqrt(np.mean(np.sum((pts - ft.bezier(c, t)) ** 2, -1))) < 0.03  # the noise, not a misfit


def test_straight_barbs_meet_the_contour_at_the_barb_angle():
    b = ft.barbs(STRAIGHT, 5, THETA, side="left", t_range=(0.1, 0.5))
    y0 = np.linspace(1.0, 5.0, 5)
    th = np.radians(THETA)
    np.testing.assert_allclose(b[:, 0], np.stack([np.zeros(5), y0], -1), atol=1e-12)
    np.testing.assert_allclose(b[:, 3], np.stack([np.full(5, -2.0), y0 + 2 / np.tan(th)], -1), atol=1e-9)
    # no bend or jitter: the inner points are the chord's thirds
    np.testing.assert_allclose(b[:, 1], b[:, 0] + (b[:, 3] - b[:, 0]) / 3, atol=1e-12)
    r = ft.barbs(STRAIGHT, 5, THETA, side="right", t_range=(0.1, 0.5))
    np.testing.assert_allclose(r[:, 3], np.stack([np.full(5, 1.5), y0 + 1.5 / np.tan(th)], -1), atol=1e-9)
    # bend > 0 moves the inner points towards the tip (+y) and off the chord by bend x chord length
    bent = ft.barbs(STRAIGHT, 5, THETA, side="left", t_range=(0.1, 0.5), bend=0.1)
    chord = np.linalg.norm(b[:, 3] - b[:, 0], axis=-1)
    off = bent[:, 1] - b[:, 1]
    np.testing.assert_allclose(np.linalg.norm(off, axis=-1), 0.1 * chord, rtol=1e-12)
    assert np.all(off[:, 1] > 0)
    np.testing.assert_allclose(np.sum(off * (b[:, 3] - b[:, 0]), -1), 0.0, atol=1e-12)  # sideways


def test_rasterised_angle_length_and_mask_are_the_closed_forms():
    th = np.radians(THETA)
    b = np.concatenate([ft.barbs(STRAIGHT, 64, THETA, side=s, t_range=(0.0, 0.8)) for s in ("left", "right")])
    tex = ft.rasterize(STRAIGHT, b, (110, 45), EXTENT, samples_per_barb=128)
    X, Y = ft.pixel_centres((110, 45), EXTENT)
    mask = tex[..., 2]
    half = 0.5 * (0.4 + (0.1 - 0.4) * np.clip(Y / 10, 0, 1))
    in_y = (Y > 0) & (Y < 10)
    # away from pixel centres that sit on a region's edge (within half a pixel), the mask is exact
    dx = (EXTENT[1] - EXTENT[0]) / 45
    clear = np.minimum.reduce([np.abs(np.abs(X) - half), np.abs(X + 2), np.abs(X - 1.5), np.abs(Y), np.abs(Y - 10),
                           np.abs(np.hypot(X, Y) - 0.2)]) > dx
    # the shaft is every point within half the local width of the rachis: round caps at its two ends
    cap = (np.hypot(X, Y) <= 0.2) | (np.hypot(X, Y - 10) <= 0.05)
    want = np.where((in_y & (np.abs(X) <= half)) | cap, ft.SHAFT,
                    np.where(in_y & (X > -2) & (X < 1.5), ft.VANE, ft.BACKGROUND))
    np.testing.assert_array_equal(mask[clear], want[clear])
    # straight barbs: the angle is the barb direction, the length |x| / sin(theta); barbs that start
    # below the rachis' base (a pixel's nearest barb is then the first one) are excluded
    v = (mask == ft.VANE) & (Y > 2.5) & (Y < 8)
    left, right = v & (X < 0), v & (X > 0)
    np.testing.assert_allclose(tex[..., 0][left], np.pi / 2 + th, atol=1e-9)
    np.testing.assert_allclose(tex[..., 0][right], np.pi / 2 - th, atol=1e-9)
    # the nearest sample is at most half a barb spacing across and half a sample step along
    spacing = 8 / 63 * np.sin(th)
    step = 2 / np.sin(th) / 127
    err = np.abs(tex[..., 1][v] - np.abs(X[v]) / np.sin(th))
    assert err.max() < spacing / np.tan(th) + step, err.max()
    assert np.all(tex[..., :2][mask != ft.VANE] == 0.0)


def test_rgb8_round_trip_within_one_step():
    b = np.concatenate([ft.barbs(STRAIGHT, 30, 35.0, side=s, bend=0.1, jitter=0.05, t_range=(0.0, 0.7)) for s in ("left", "right")])
    tex = ft.rasterize(STRAIGHT, b, (40, 20), EXTENT, samples_per_barb=32)
    rgb = ft.encode_rgb8(tex, max_length=4.0)
    a, length, mask = ft.decode_rgb8(rgb, max_length=4.0)
    np.testing.assert_array_equal(mask, tex[..., 2].astype(int))
    da = np.angle(np.exp(1j * (a - tex[..., 0])))
    assert np.abs(da).max() <= np.pi / 256 + 1e-12
    assert np.abs(length - np.minimum(tex[..., 1], 4.0)).max() <= 4.0 / 510 + 1e-12


def test_bad_input_names_the_parameter():
    with pytest.raises(ValueError, match="n_barbs"):
        ft.barbs(STRAIGHT, 0, THETA)
    with pytest.raises(ValueError, match="barb_angle_deg"):
        ft.barbs(STRAIGHT, 3, 180.0)
    with pytest.raises(ValueError, match="t_range"):
        ft.barbs(STRAIGHT, 3, THETA, t_range=(0.5, 0.4))
    with pytest.raises(ValueError, match="side"):
        ft.barbs(STRAIGHT, 3, THETA, side="up")
    with pytest.raises(ValueError, match="jitter"):
        ft.barbs(STRAIGHT, 3, THETA, jitter=-1.0)
    with pytest.raises(ValueError, match="never meet the vane contour"):  # the contour ends at y = 10
        ft.barbs(STRAIGHT, 3, 5.0, t_range=(0.8, 1.0))
    with pytest.raises(ValueError, match="shaft_width"):
        ft.Outline(rachis=[[0, 0], [0, 1]], left=[[-1, 0], [-1, 1]], right=[[1, 0], [1, 1]], shaft_width=(-1, 0))
    with pytest.raises(ValueError, match="rachis"):
        ft.Outline(rachis=[[0, 0]], left=[[-1, 0], [-1, 1]], right=[[1, 0], [1, 1]])
    with pytest.raises(ValueError, match="points"):
        ft.fit_bezier([[0, 0], [1, 1]], 3)
    with pytest.raises(ValueError, match="degree"):
        ft.fit_bezier([[0, 0], [1, 1]], 0)
    with pytest.raises(ValueError, match="barb_curves"):
        ft.rasterize(STRAIGHT, np.zeros((3, 3, 2)), (4, 4), EXTENT)
    with pytest.raises(ValueError, match="extent"):
        ft.rasterize(STRAIGHT, np.zeros((1, 4, 2)), (4, 4), (1, 0, 0, 1))
    with pytest.raises(ValueError, match="max_length"):
        ft.encode_rgb8(np.zeros((2, 2, 3)), 0.0)
    with pytest.raises(ValueError, match="uint8"):
        ft.decode_rgb8(np.zeros((2, 2, 3)), 1.0)
