"""Soap-bubble shading (Huang 2022, Sec. 3.5): path weights Eq. 3.29, directions Eq. 3.30, Eq. 3.32.

Checks SB-1..SB-3 of seed-001-spec.md §3.2 and the limit cases of the brief: a film of zero
thickness is invisible, a white environment gives (almost exactly) white.
"""


import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import testing
from appearance_jax.core import spectral
from appearance_jax.core.vec import Vec3, cross, dot
from appearance_jax.soapfilm import bubble as sb
from appearance_jax.soapfilm import thickness as th

WL = np.array([400.0, 475.0, 510.0, 560.0, 650.0, 700.0])


def _airy_np(cos_theta, wl, d, n=1.33):
    """Eqs. 3.27 / 3.28 (Huang 2022) in numpy, per polarisation: an independent reference.

    Air | film (n, full thickness d) | air; Fresnel amplitudes r_as, t_as and the Stokes
    relations r_sa = -r_as, t_as t_sa = 1 - r_as^2; Delta psi = 2 pi 2 d n cos(theta_s) / lambda.
    Returns (R_s, R_p, T_s, T_p).
    """
    ci = np.asarray(cos_theta, dtype=float)
    ct = np.sqrt(1.0 - (1.0 - ci ** 2) / n ** 2)
    r = {"s": (ci - n * ct) / (ci + n * ct), "p": (n * ci - ct) / (n * ci + ct)}
    e = np.exp(2j * np.pi * 2.0 * np.asarray(d) * n * ct / np.asarray(wl))
    out = []
    for pol in ("s", "p"):
        ras = r[pol]
        rsa, tt = -ras, 1.0 - ras ** 2
        den = 1.0 - rsa ** 2 * e
        out.append(np.abs(ras + tt * rsa * e / den) ** 2)
        out.append(np.abs(tt / den) ** 2)
    R_s, T_s, R_p, T_p = out
    return R_s, R_p, T_s, T_p


def _unit(a):
    a = np.asarray(a, dtype=float)
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def _v(a):
    return Vec3.from_array(jnp.asarray(a))


def _env(w):
    """A smooth, coloured, non-symmetric environment (linear RGB)."""
    return jnp.stack([1.0 + 0.5 * w.x, 0.8 + 0.3 * w.y * w.z, 0.6 - 0.4 * w.z], axis=-1)


def _white(w):
    return jnp.ones(jnp.shape(w.x) + (3,))


# --------------------------------------------------------------------------------------
# SB-1: uniform lossless film


def test_uniform_film_path_sums_sb1():
    cos_theta = np.array([1.0, 0.55, 0.12])[:, None, None]  # (3, 1, 1) angles
    d = np.array([0.0, 120.0, 800.0, 1500.0])[None, :, None]  # (1, 4, 1) thicknesses
    N = 40
    pw = sb.path_weights(cos_theta[..., 0], np.broadcast_to(d, (3, 4, N)), WL, per_polarization=True)
    assert pw.mean.shape == (3, 4, N, WL.size)
    R_s, R_p, T_s, T_p = _airy_np(cos_theta, WL, d)  # computed independently, (3, 4, n_wl)
    np.testing.assert_allclose(R_s + T_s, 1.0, atol=1e-14)  # lossless
    for w, R, T in ((pw.s, R_s, T_s), (pw.p, R_p, T_p)):
        R, T = np.asarray(R), np.asarray(T)
        w = np.asarray(w)
        # individual paths: R, T^2 R^(k-1)
        np.testing.assert_allclose(w[..., 0, :], R, rtol=1e-12, atol=1e-15)
        for k in range(1, 8):
            np.testing.assert_allclose(w[..., k, :], T * T * R ** (k - 1), rtol=1e-12, atol=1e-15)
        # truncated sum after path K: 1 - T R^K
        cums = np.cumsum(w, axis=-2)
        for K in range(N):
            np.testing.assert_allclose(cums[..., K, :], 1.0 - T * R ** K, rtol=0, atol=1e-12)
        # -> 1 as K grows (monotone); with 40 paths only grazing light still leaks
        assert np.all(np.diff(cums, axis=-2) >= -1e-15)
        np.testing.assert_allclose(cums[:2, :, -1], 1.0, atol=1e-12)
    np.testing.assert_allclose(pw.mean, 0.5 * (pw.s + pw.p), rtol=1e-15)


def test_per_polarisation_average_differs_from_unpolarised_product():
    c = 0.3  # oblique: R_s and R_p differ a lot
    d = np.array([310.0, 505.0, 720.0, 980.0])
    w = sb.path_weights(c, d, WL)
    Rs, Rp, Ts, Tp = _airy_np(c, WL, d[:, None])  # (4, n_wl) each, interaction i = row i
    by_hand = [
        0.5 * (Rs[0] + Rp[0]),
        0.5 * (Ts[0] * Ts[1] + Tp[0] * Tp[1]),
        0.5 * (Ts[0] * Rs[1] * Ts[2] + Tp[0] * Rp[1] * Tp[2]),
        0.5 * (Ts[0] * Rs[1] * Rs[2] * Ts[3] + Tp[0] * Rp[1] * Rp[2] * Tp[3]),
    ]
    np.testing.assert_allclose(w, np.stack(by_hand), rtol=1e-12, atol=1e-16)
    R, T = 0.5 * (Rs + Rp), 0.5 * (Ts + Tp)
    unpolarised = [R[0], T[0] * T[1], T[0] * R[1] * T[2], T[0] * R[1] * R[2] * T[3]]
    rel = np.abs(np.asarray(w[3]) - np.asarray(unpolarised[3])) / np.asarray(w[3])
    assert rel.max() > 0.05  # the orders of the products and the average do not commute


def test_zero_thickness_only_the_straight_path():
    for c in (1.0, 0.6, 0.2):
        w = sb.path_weights(c, jnp.zeros(4), WL)
        expect = np.zeros((4, WL.size))
        expect[1] = 1.0
        np.testing.assert_allclose(w, expect, atol=1e-15)
    # a hole only at the entry point: no first-surface reflection, the rest unchanged
    w2 = sb.path_weights(0.7, jnp.array([0.0, 600.0, 600.0, 600.0]), WL, per_polarization=True)
    R_s, R_p, T_s, T_p = _airy_np(0.7, WL, 600.0)
    np.testing.assert_allclose(w2.mean[0], 0.0, atol=1e-15)
    np.testing.assert_allclose(w2.s[2], R_s * T_s, rtol=1e-12)
    np.testing.assert_allclose(w2.p[3], R_p ** 2 * T_p, rtol=1e-12)


def test_path_weights_broadcast_and_single_path():
    c = jnp.array([[1.0], [0.5]])  # (2, 1)
    d = jnp.full((1, 3, 4), 400.0)  # (1, 3, N=4)
    shape = jax.eval_shape(lambda c, d: sb.path_weights(c, d, WL), c, d).shape
    assert shape == (2, 3, 4, WL.size)
    one = sb.path_weights(0.8, jnp.array([400.0]), WL)
    R_s, R_p, _, _ = _airy_np(0.8, WL, 400.0)
    np.testing.assert_allclose(one[0], 0.5 * (R_s + R_p), rtol=1e-12)


# --------------------------------------------------------------------------------------
# SB-2 / SB-3: directions


def _random_configs(n=64, seed=0):
    rng = np.random.default_rng(seed)
    nrm = _unit(rng.normal(size=(n, 3)))
    view = _unit(rng.normal(size=(n, 3)))
    view = np.where(np.sum(nrm * view, -1, keepdims=True) < 0, -view, view)  # front-facing
    view[0] = nrm[0]  # normal incidence
    view[1] = _unit(nrm[1] + 1e-3 * _unit(np.cross(nrm[1], [0.3, 0.1, 0.9])))  # near normal
    return nrm, view


def test_direction_invariants_sb2():
    nrm, view = _random_configs()
    N = 8
    p = sb.path_directions(_v(nrm), _v(view), N)
    n, i, o = (x.to_array() for x in (p.normal, p.incident, p.outgoing))  # (64, N, 3)
    c = np.sum(nrm * view, -1)
    np.testing.assert_allclose(p.cos_theta, c, rtol=1e-14)
    for a in (n, i, o):
        np.testing.assert_allclose(np.linalg.norm(a, axis=-1), 1.0, atol=1e-13)
    # all angles equal (Fig. 3.11): at both ends of every chord, and for the light
    np.testing.assert_allclose(np.sum(n * o, -1), c[:, None] * np.ones(N), atol=1e-13)
    np.testing.assert_allclose(np.sum(n[:, 1:] * o[:, :-1], -1), -c[:, None] * np.ones(N - 1), atol=1e-13)
    np.testing.assert_allclose(np.sum(n * i, -1), c[:, None] * np.ones(N), atol=1e-13)
    # consecutive normals are the ends of a chord along o^(i): p_i - p_{i+1} = 2 cos(theta) o^(i)
    np.testing.assert_allclose(n[:, :-1] - n[:, 1:], 2 * c[:, None, None] * o[:, :-1], atol=1e-13)
    # the chord's far end found by intersecting the backward ray p_i - t o^(i) with the sphere
    p0, d0 = n[:, 0], -o[:, 0]
    b = np.sum(p0 * d0, -1)
    t = -b + np.sqrt(b * b - (np.sum(p0 * p0, -1) - 1.0))  # the far root of |p + t d| = 1
    np.testing.assert_allclose(p0 + t[:, None] * d0, n[:, 1], atol=1e-12)
    # each chord subtends the central angle pi - 2 theta, always turning the same way
    np.testing.assert_allclose(np.sum(n[:, :-1] * n[:, 1:], -1), -(2 * c[:, None] ** 2 - 1) * np.ones(N - 1),
                               atol=1e-12)
    # the conventions: o^(0) = view, i^(0) = mirror of the view, i^(k) = -o^(k-1), o = reflect(i, n)
    np.testing.assert_allclose(o[:, 0], view, atol=1e-15)
    np.testing.assert_allclose(i[:, 0], 2 * c[:, None] * nrm - view, atol=1e-14)
    np.testing.assert_allclose(i[:, 1:], -o[:, :-1], atol=1e-15)
    np.testing.assert_allclose(o, 2 * np.sum(i * n, -1, keepdims=True) * n - i, atol=1e-13)
    # path 1 sees straight through the bubble
    np.testing.assert_allclose(i[:, 1], -view, atol=1e-15)


def test_paths_are_coplanar_sb3():
    nrm, view = _random_configs(seed=1)
    p = sb.path_directions(_v(nrm), _v(view), 8)
    plane = cross(_v(nrm), _v(view))
    plane = plane / jnp.sqrt(dot(plane, plane))
    pl = Vec3(plane.x[:, None], plane.y[:, None], plane.z[:, None])
    ok = slice(2, None)  # the plane is undefined at (near-)normal incidence: configs 0 and 1
    for vecs in (p.normal, p.incident, p.outgoing):
        np.testing.assert_allclose(np.asarray(dot(vecs, pl))[ok], 0.0, atol=1e-12)
    # the s direction (perpendicular to the plane of incidence) is the same at every interaction
    s_dirs = cross(p.normal, p.outgoing)
    s_dirs = s_dirs / jnp.sqrt(dot(s_dirs, s_dirs))
    np.testing.assert_allclose(np.abs(np.asarray(dot(s_dirs, pl)))[ok], 1.0, atol=1e-12)


# --------------------------------------------------------------------------------------
# shading (Eq. 3.32)


def _points(seed=2, n=16):
    nrm, view = _random_configs(n, seed)
    return _v(nrm), _v(view)


def test_white_environment_uniform_film_gives_white_minus_leak():
    nrm, view = _points()
    N, d = 8, 900.0
    rgb = sb.shade(view, nrm, _white, th.uniform_field(d), n_paths=N)
    c = np.asarray(dot(nrm, view))
    wl = spectral.band_wavelengths("cie")
    R_s, R_p, T_s, T_p = _airy_np(c[:, None], np.asarray(wl), d)
    leak = 0.5 * (T_s * R_s ** (N - 1) + T_p * R_p ** (N - 1))  # light lost after path N-1
    white = spectral.spectrum_to_linear_srgb(np.ones(wl.shape), wl, "D65")  # (1, 1, 1) to 3e-4
    expect = spectral.spectrum_to_linear_srgb(1.0 - leak, wl, "D65") / white  # int s_j = 1 per channel
    np.testing.assert_allclose(rgb, expect, rtol=0, atol=1e-12)
    front = c > 0.5
    np.testing.assert_allclose(np.asarray(rgb)[front], 1.0, atol=1e-3)


def test_zero_thickness_bubble_is_invisible():
    nrm, view = _points(seed=3)
    rgb = sb.shade(view, nrm, _env, th.uniform_field(0.0))
    np.testing.assert_allclose(rgb, _env(-view), atol=1e-13)
    white = sb.shade(view, nrm, _white, th.uniform_field(0.0))
    np.testing.assert_allclose(white, 1.0, atol=1e-14)


def test_shade_is_the_sum_over_paths_and_jits():
    nrm, view = _points(seed=4)
    field = th.equilibrium_field(1.2, eta0_nm=300.0)
    eager = sb.shade(view, nrm, _env, field)
    assert eager.shape == (16, 3)
    # by hand: path colours (the CIE integral of each path's weight) times environment lookups
    p = sb.path_directions(nrm, view, 8)
    wl = spectral.band_wavelengths("cie")
    w = sb.path_weights(p.cos_theta, field(p.normal), wl)
    F = spectral.spectrum_to_linear_srgb(w, wl, "D65") / spectral.spectrum_to_linear_srgb(np.ones(wl.shape), wl, "D65")
    np.testing.assert_allclose(eager, jnp.sum(_env(p.incident) * F, axis=-2), rtol=1e-12)
    jitted = jax.jit(lambda v, n: sb.shade(v, n, _env, field))(view, nrm)
    np.testing.assert_allclose(jitted, eager, rtol=1e-12)


def test_gradient_wrt_film_thickness_matches_finite_differences():
    nrm, view = _points(seed=5)

    def f(d):
        field = lambda m: d * (1.0 + 0.3 * m.z)  # noqa: E731
        return sb.shade(view, nrm, _env, field)

    # step 1e-3 nm (h = step * |d|)
    r = testing.assert_gradients(f, 430.0, step=1e-3 / 430.0, rtol=1e-6, atol=1e-10, elementwise=True, mode="fwd",
                                 name="shade")
    assert np.max(np.abs(r.ad[0])) > 1e-5


# --------------------------------------------------------------------------------------
# rendering


def _z_env(w):  # mirror-symmetric in x, coloured with height
    return jnp.stack([0.7 + 0.3 * w.z, 0.5 + 0.2 * w.y, 0.6 - 0.3 * w.z * w.z], axis=-1)


def test_render_shape_mask_and_horizontal_bands():
    H, W = 14, 18
    field = th.equilibrium_field(1.182, eta0_nm=250.0)
    img, mask = sb.render((H, W), _z_env, field, background="environment")
    assert img.shape == (H, W, 3) and mask.shape == (H, W)
    x, y = sb.image_plane((H, W))
    np.testing.assert_array_equal(mask, np.asarray(x) ** 2 + np.asarray(y) ** 2 < 1.0)
    assert np.all(np.isfinite(img)) and mask.sum() > 100
    # outside the disc: the environment straight through the (orthographic) view
    np.testing.assert_allclose(np.asarray(img)[~np.asarray(mask)], np.broadcast_to(_z_env(Vec3(0.0, 1.0, 0.0)),
                               ((~np.asarray(mask)).sum(), 3)), atol=1e-14)
    # side view with +z up and an x-symmetric world: mirrored pixels match (bands are horizontal)
    np.testing.assert_allclose(img, img[:, ::-1], atol=1e-12)
    # the film is thinner at the top than at the bottom: the colours differ between them
    assert np.max(np.abs(np.asarray(img[2, W // 2]) - np.asarray(img[H - 3, W // 2]))) > 1e-3
    # shading in chunks (lax.map over 7 chunks) gives the same image
    chunked, _ = sb.render((H, W), _z_env, field, background="environment", chunk_size=37)
    np.testing.assert_allclose(chunked, img, atol=1e-14)
    # pixels equal shade() at their sphere points n = (x, -sqrt(1 - x^2 - y^2), y)
    rows, cols = np.nonzero(np.asarray(mask))
    pick = np.linspace(0, rows.size - 1, 16).astype(int)  # 16 pixels: the shapes of the tests above
    xs, ys = np.asarray(x)[rows[pick], cols[pick]], np.asarray(y)[rows[pick], cols[pick]]
    n = Vec3(jnp.asarray(xs), -jnp.sqrt(1 - xs ** 2 - ys ** 2), jnp.asarray(ys))
    view = Vec3(jnp.zeros(16), -jnp.ones(16), jnp.zeros(16))
    np.testing.assert_allclose(np.asarray(img)[rows[pick], cols[pick]], sb.shade(view, n, _z_env, field),
                               rtol=1e-11)


# --------------------------------------------------------------------------------------
# bad input


def test_bad_input_names_the_argument():
    nrm, view = _points()  # the 16 points of the shading tests: their compiled path directions
    field = th.uniform_field(500.0)
    with pytest.raises(ValueError, match="n_paths"):
        sb.path_directions(nrm, view, 0)
    with pytest.raises(ValueError, match="n_paths"):
        sb.shade(view, nrm, _env, field, n_paths=0)
    with pytest.raises(ValueError, match="thicknesses_nm"):
        sb.path_weights(1.0, jnp.array([100.0, -1.0]), WL)
    with pytest.raises(ValueError, match="thickness"):
        sb.shade(view, nrm, _env, lambda m: -5.0 + 0.0 * m.x)
    with pytest.raises(ValueError, match="eta_film"):
        sb.path_weights(1.0, jnp.array([100.0]), WL, eta_film=0.0)
    with pytest.raises(ValueError, match="eta_film"):
        sb.render(4, _env, field, eta_film=-1.33)
    with pytest.raises(ValueError, match="color"):
        sb.shade(view, nrm, _env, field, color="xyz")
    with pytest.raises(ValueError, match="up"):
        sb.render(4, _env, field, view=(0.0, 0.0, 1.0), up=(0.0, 0.0, 2.0))
    with pytest.raises(ValueError, match="resolution"):
        sb.render(0, _env, field)
