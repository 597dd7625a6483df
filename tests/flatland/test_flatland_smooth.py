"""The flatland tracer on smooth sections, against closed forms it did not write.

- a smooth circle reproduces the pbrt/d'Eon lobe table of spec M18 (directions Phi(p, h),
  attenuations A_p) and the corrected chord length 2 cos(gamma_t)/cos(theta_t) (H-17);
- energy bookkeeping: lobes + absorbed + lost + residual = 1 per ray (split mode);
- rotating an ellipse together with omega_i changes nothing; e = 0 is the circle;
- the deterministic smooth mode integrates A_p(h) exactly and bins Phi_p(h) like the closed
  form; the tilt law of a smooth tilted cylinder (H-9);
- wave data: optical path lengths and amplitudes equal the closed forms of spec seed-002
  §1.2.5, the meridional foci equal a brute-force neighbour-crossing count;
- water cylinder rainbows at Descartes' angles (shipped refractive index of water);
- a thin film at the hit gives the Airy reflectance; grazing directions give zeros.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import flatland as fl, testing
from appearance_jax.core.frame import fiber_angles, fiber_direction
from appearance_jax.core.vec import Vec3
from appearance_jax.optics.refractiveindex_yaml import load_material
from appearance_jax.optics.thinfilm import airy

KEY = jax.random.PRNGKey(0)


def fresnel(cos_i, eta):
    sin_t = np.sqrt(1 - cos_i ** 2) / eta
    cos_t = np.sqrt(1 - sin_t ** 2)
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 0.5 * (rs ** 2 + rp ** 2)


def closed_form_lobes(h, theta_i, eta, sigma_a, p_max=4):
    """pbrt / d'Eon 2011 smooth-cylinder lobes (spec M18): Phi(p, h) and A_p(h)."""
    eta_p = np.sqrt(eta ** 2 - np.sin(theta_i) ** 2) / np.cos(theta_i)
    g_i = np.arcsin(h)
    g_t = np.arcsin(h / eta_p)
    f = fresnel(np.cos(theta_i) * np.cos(g_i), eta)
    cos_theta_t = np.sqrt(1 - (np.sin(theta_i) / eta) ** 2)
    T = np.exp(-sigma_a * 2 * np.cos(g_t) / cos_theta_t)
    A = [f, (1 - f) ** 2 * T]
    for _ in range(2, p_max):
        A.append(A[-1] * T * f)
    Phi = [2 * p * g_t - 2 * g_i + p * np.pi for p in range(p_max)]
    return np.array(A), np.array(Phi)


def wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


# spec seed-000 M18 reference table (eta = 1.55, sigma_a = 0)
M18 = [
    (0.0, 0.0, 0.04652, (0, 180, 0, 180), (0.04652, 0.90912, 0.04229, 0.00197)),
    (0.5, 0.0, 0.04814, (-60.00, 157.64, 15.28, -127.09), (0.04814, 0.90604, 0.04362, 0.00210)),
    (0.5, 30.0, 0.05367, (-60.00, 154.33, 8.66, -137.00), (0.05367, 0.89553, 0.04807, 0.00258)),
    (0.9, 0.0, 0.12268, (-128.32, 122.68, 13.67, -95.34), (0.12268, 0.76969, 0.09443, 0.01158)),
]


# Compilation dominates: fl.trace compiles one program per (number of offsets, max_events,
# mode, flags, number of bands, interface kinds). The split-mode traces of smooth one-band
# fibers below therefore all use N_SPLIT offsets and E_SPLIT events, the nodes and events of the
# smooth-mode tests' smooth_lobes (whose trace is the same program): a test that needs fewer
# offsets repeats its own to fill the array and reads its first ones; events beyond a lobe do
# not change the records of that lobe (events are a scan: more cost run time, not compilation).
N_SPLIT, E_SPLIT = 512, 12


def _fill(h):
    """h repeated to N_SPLIT offsets (the first len(h) are h)."""
    return jnp.asarray(np.resize(np.asarray(h, float), N_SPLIT))


def _dir(theta, phi):
    """fiber_direction of float64 angles: from Python floats the direction is weakly typed, a
    different signature for fl.trace, which then compiles its program once more."""
    return fiber_direction(np.float64(theta), np.float64(phi))


@pytest.mark.parametrize("h, theta_deg, f, phis, amps", M18)
def test_smooth_circle_matches_spec_m18_table(h, theta_deg, f, phis, amps):
    wi = fiber_direction(np.radians(theta_deg), 0.0)
    rec = fl.trace(fl.fiber(1.55), wi, _fill([h]), max_events=E_SPLIT)
    w = np.asarray(rec.weight[:4, 0, 0])
    th, ph = fiber_angles(rec.direction)
    # printed to 5 decimals / 0.01 deg
    np.testing.assert_allclose(w, amps, atol=6e-6)
    d = wrap(np.asarray(ph[:4, 0]) - np.radians(np.array(phis, float)))
    assert np.max(np.abs(np.degrees(d))) < 0.006
    np.testing.assert_allclose(np.asarray(th[:4, 0]), -np.radians(theta_deg), atol=1e-12)  # specular cone
    np.testing.assert_allclose(np.asarray(rec.lobe[:4, 0]), [0, 1, 2, 3])


def test_smooth_circle_equals_closed_form_with_absorption_per_band():
    sigma = jnp.array([0.1, 0.8, 2.5])
    theta_i = 0.7
    # 64 offsets and 12 events: the shape of test_energy_bookkeeping_is_exact_in_split_mode
    # (one compiled program); the closed form covers the first 4 lobes
    h = np.linspace(-0.97, 0.97, 64)
    rec = fl.trace(fl.fiber(1.55, sigma), _dir(theta_i, 0.3), jnp.asarray(h), max_events=12)
    for b, s in enumerate(np.asarray(sigma)):
        A, Phi = closed_form_lobes(h, theta_i, 1.55, s)
        np.testing.assert_allclose(np.asarray(rec.weight[:4, :, b]), A, rtol=1e-10, atol=1e-14)
    _, ph = fiber_angles(rec.direction)
    np.testing.assert_allclose(wrap(np.asarray(ph[:4]) - 0.3 - Phi), 0.0, atol=1e-9)


def test_energy_bookkeeping_is_exact_in_split_mode():
    # (three bands: the shape of the absorption test above, one compiled program)
    sec = fl.fiber(1.6, jnp.array([0.0, 0.4, 1.3]), eccentricity=0.7, rotation=0.4)
    h = jax.random.uniform(KEY, (64,), minval=-1, maxval=1)
    rec = fl.trace(sec, _dir(-0.6, 1.1), h, max_events=12)
    total = rec.weight.sum(0) + rec.absorbed + rec.lost + rec.residual
    np.testing.assert_allclose(np.asarray(total), 1.0, atol=1e-12)
    assert float(jnp.max(rec.lost)) == 0.0          # smooth: nothing is killed
    assert float(jnp.min(rec.absorbed[:, 1])) > 0.0  # the absorbing band absorbs
    np.testing.assert_allclose(np.asarray(rec.absorbed[:, 0]), 0.0, atol=0)


def test_rotating_ellipse_with_incidence_changes_nothing():
    h = jnp.linspace(-0.95, 0.95, N_SPLIT)
    base = fl.trace(fl.fiber(1.55, 0.3, eccentricity=0.8), _dir(0.4, 0.2), h, max_events=E_SPLIT)
    for psi in (0.3, 1.2, -2.0):
        rot = fl.trace(fl.fiber(1.55, 0.3, eccentricity=0.8, rotation=psi), _dir(0.4, 0.2 + psi), h,
                       max_events=E_SPLIT)
        np.testing.assert_allclose(np.asarray(rot.weight), np.asarray(base.weight), atol=1e-12)
        _, p0 = fiber_angles(base.direction)
        _, p1 = fiber_angles(rot.direction)
        emitted = np.asarray(base.weight[..., 0]) > 0      # (directions of empty slots are arbitrary)
        np.testing.assert_allclose(wrap(np.asarray(p1) - np.asarray(p0) - psi)[emitted], 0.0, atol=1e-9)


def test_ellipse_with_zero_eccentricity_is_the_circle():
    h = jnp.linspace(-0.99, 0.99, N_SPLIT)
    wi = _dir(0.5, 0.9)
    a = fl.trace(fl.fiber(1.55, 0.5), wi, h, max_events=E_SPLIT)
    b = fl.trace(fl.fiber(1.55, 0.5, eccentricity=0.0, rotation=1.234), wi, h, max_events=E_SPLIT)
    np.testing.assert_allclose(np.asarray(b.weight), np.asarray(a.weight), atol=1e-13)
    np.testing.assert_allclose(np.asarray(b.direction.to_array()), np.asarray(a.direction.to_array()), atol=1e-12)


def test_ellipse_projected_width_and_chord_lengths():
    """Launch width D(phi) = sqrt(1 - e^2 sin^2 phi) (Eq. 4.27, Huang 2022) and the TT
    absorption path = explicit 2D chord / cos(theta_t) (Eq. 4.17 / [T:1186])."""
    e = 0.8
    sec = fl.fiber(1.5, 1.0, eccentricity=e)
    for phi in (0.0, 0.7, 1.5708):
        _, _, D = fl.launch(sec, fiber_direction(0.3, phi), jnp.zeros(1))
        np.testing.assert_allclose(float(D), np.sqrt(1 - e ** 2 * np.sin(phi) ** 2), rtol=1e-12)
    # TT with sigma = 1: A_TT / ((1 - F1)(1 - F2)) = exp(-chord_3D); R and TT without absorption
    wi = _dir(0.3, 0.7)
    h = _fill([0.2])
    with_abs = fl.trace(sec, wi, h, max_events=E_SPLIT)
    no_abs = fl.trace(sec.with_media(sigma_a=jnp.zeros(())), wi, h, max_events=E_SPLIT)  # (zeros: not weakly typed)
    ratio = float(with_abs.weight[1, 0, 0] / no_abs.weight[1, 0, 0])
    # explicit chord: entry point from the launch geometry, exit point = second emission's
    # origin; here recomputed in numpy from the ellipse (semi-axes b along y, 1 along z)
    b = np.sqrt(1 - e * e)
    d = -np.asarray(wi.to_array(), float)
    u = d[1:] / np.linalg.norm(d[1:])
    left = np.array([-u[1], u[0]])
    # tangent points of the ellipse y^2/b^2 + z^2 = 1 for direction u: support along +-left
    s = np.sqrt(b * b * left[0] ** 2 + left[1] ** 2)
    p_left = np.array([b * b * left[0], left[1]]) / s
    o = p_left * 0.2 - 10 * u           # h = 0.2 between the tangent points (B.8, fixed)
    def hit(o, v, far):
        A = v[0] ** 2 / b ** 2 + v[1] ** 2
        B = 2 * (o[0] * v[0] / b ** 2 + o[1] * v[1])
        C = o[0] ** 2 / b ** 2 + o[1] ** 2 - 1
        r = np.roots([A, B, C])
        return np.max(r) if far else np.min(r)
    x1 = o + hit(o, u, False) * u
    n1 = np.array([x1[0] / b ** 2, x1[1]])
    n1 /= np.linalg.norm(n1)
    d3 = d.copy()
    nn = np.array([0.0, *n1])
    ci = -d3 @ nn
    eta = 1 / 1.5
    ct = np.sqrt(1 - eta ** 2 * (1 - ci ** 2))
    dt = eta * d3 + (eta * ci - ct) * nn
    v = dt[1:] / np.linalg.norm(dt[1:])
    x2 = x1 + hit(x1, v, True) * v
    chord3d = np.linalg.norm(x2 - x1) / np.linalg.norm(dt[1:])
    np.testing.assert_allclose(ratio, np.exp(-chord3d), rtol=1e-9)


def test_smooth_mode_albedo_and_azimuthal_distribution_equal_closed_form():
    theta_i, eta, sigma = 0.4, 1.55, 0.3
    wi = _dir(theta_i, 0.0)
    lob = fl.smooth_lobes(fl.fiber(eta, sigma), wi, n_h=512, n_lobes=4, max_events=12)
    # albedo (1/2) int A_p dh of the closed form, Gauss-Legendre in numpy over h = sin(v) (smooth
    # in v): 400 nodes agree with 3000 to 1.3e-13 relative and cost 0.1 s instead of 10 s
    u, w = np.polynomial.legendre.leggauss(400)
    x, w = np.sin(u * np.pi / 2), w * np.pi / 2 * np.cos(u * np.pi / 2)   # h = sin(v)
    A, Phi = closed_form_lobes(x, theta_i, eta, sigma, p_max=12)
    ref = [0.5 * np.sum(w * A[p]) for p in range(3)] + [0.5 * np.sum(w * A[3:].sum(0))]
    np.testing.assert_allclose(np.asarray(lob.albedo[:, 0]), ref, rtol=1e-9)
    # binned azimuthal distribution N_p(phi) of TT and TRT: tracer nodes vs closed-form nodes
    bins = np.linspace(-np.pi, np.pi, 37)
    for p in (1, 2):
        m = np.asarray(lob.lobe) == p
        hist_t, _ = np.histogram(np.asarray(lob.phi)[m], bins, weights=(np.asarray(lob.power[..., 0])
                                                                        * np.asarray(lob.weight)[None, :])[m])
        xs = np.asarray(lob.h)
        Ac, Pc = closed_form_lobes(xs, theta_i, eta, sigma)
        hist_c, _ = np.histogram(wrap(Pc[p]), bins, weights=Ac[p] * np.asarray(lob.weight))
        np.testing.assert_allclose(hist_t, hist_c, atol=1e-12)


@pytest.mark.parametrize("alpha_deg", [2.0, -4.0])
def test_tilt_law_of_a_smooth_tilted_cylinder(alpha_deg):
    """H-9: sin(theta_o) = 2 sin(alpha)(cos(theta_i) cos(alpha) sqrt(1 - h^2) + sin(theta_i)
    sin(alpha)) - sin(theta_i); at h = 0: theta_o = 2 alpha - theta_i exactly."""
    a = np.radians(alpha_deg)
    theta_i = 0.35
    h = np.array([0.0, 0.3, 0.6, 0.9])
    rec = fl.trace(fl.fiber(1.55, tilt=a), _dir(theta_i, 0.0), _fill(h), max_events=E_SPLIT)
    th, _ = fiber_angles(rec.direction)
    th = th[:, :h.size]
    ref = np.arcsin(2 * np.sin(a) * (np.cos(theta_i) * np.cos(a) * np.sqrt(1 - h ** 2)
                                     + np.sin(theta_i) * np.sin(a)) - np.sin(theta_i))
    np.testing.assert_allclose(np.asarray(th[0]), ref, atol=1e-12)
    np.testing.assert_allclose(float(th[0, 0]), 2 * a - theta_i, atol=1e-12)


def test_grazing_and_edge_offsets_return_finite_values():
    sec = fl.fiber(1.55, 0.5, roughness=0.2)
    # omega_i along the fiber axis: no projected width, nothing is hit (split mode, the rough
    # fiber's program below; random mode: test_axis_direction_in_random_mode, slow)
    axis = Vec3(*(jnp.asarray(np.float64(v)) for v in (1.0, 0.0, 0.0)))   # (float64, not weakly typed)
    rec = fl.trace(sec, axis, _fill([-1.0, 0.0, 1.0]), KEY, max_events=E_SPLIT)
    for leaf in jax.tree_util.tree_leaves(rec):
        assert np.all(np.isfinite(np.asarray(leaf)))
    # h = +-1 (grazing entry) on smooth and rough fibers
    for s in (fl.fiber(1.55, 0.5), sec):               # (the smooth one: the shared N_SPLIT program)
        rec = fl.trace(s, _dir(0.3, 0.0), _fill([-1.0, 1.0]), KEY, max_events=E_SPLIT)
        for leaf in jax.tree_util.tree_leaves(rec):
            assert np.all(np.isfinite(np.asarray(leaf)))
        total = rec.weight.sum(0) + rec.absorbed + rec.lost + rec.residual
        np.testing.assert_allclose(np.asarray(total), 1.0, atol=1e-9)


@pytest.mark.slow  # a program of its own; the degenerate launch (no projected width) is the same
# code in both modes, checked by default in split mode by test_grazing_and_edge_offsets_return_finite_values
def test_axis_direction_in_random_mode():
    sec = fl.fiber(1.55, 0.5, roughness=0.2)
    rec = fl.trace(sec, Vec3(jnp.asarray(1.0), jnp.asarray(0.0), jnp.asarray(0.0)), jnp.array([-1.0, 0.0, 1.0]),
                   KEY, max_events=4, mode="random")
    for leaf in jax.tree_util.tree_leaves(rec):
        assert np.all(np.isfinite(np.asarray(leaf)))


# ----------------------------------------------------------------------------- wave data


# The wave-data tests share traces of a water cylinder at normal incidence (module fixture):
# the offsets of both tests in one array, max_events = 5 (later events do not change the
# records of earlier lobes), both polarisations from one program (that of test_drop.py's
# test_circle_equals_flatland_tracer). The unpolarised wave trace, a program of its own, is
# checked under slow (test_unpolarised_wave_trace_weights).
H_PATH = np.linspace(-0.99, 0.99, 15)
H_FOCI = np.array([-0.95, -0.6, -0.2, 0.1, 0.5, 0.8, 0.9, 0.97])
H_WAVE = np.unique(np.concatenate([H_PATH, H_FOCI]))
assert H_WAVE.size == H_PATH.size + H_FOCI.size


def _at(records, h):
    """The records of the offsets h (a subset of H_WAVE), rays along axis 1."""
    j = np.searchsorted(H_WAVE, h)
    assert np.array_equal(H_WAVE[j], h)
    ev = lambda a: jax.tree_util.tree_map(lambda x: x[:, j], a)      # (events, N, ...) fields
    ray = lambda a: jax.tree_util.tree_map(lambda x: x[j], a)           # (N, ...) fields
    return records._replace(**{k: ev(getattr(records, k)) for k in
                               ("direction", "weight", "lobe", "opl", "foci", "field")},
                            **{k: ray(getattr(records, k)) for k in
                               ("h", "absorbed", "lost", "residual", "first_shape", "truncated")})


@pytest.fixture(scope="module")
def water_cylinder():
    wi = fiber_direction(0.0, 0.0)
    sec, h = fl.cylinder(1.331), jnp.asarray(H_WAVE)
    rec = fl.trace(sec, wi, h, max_events=5, wave=True, polarized=True)
    # (wave=True as above: the same static configuration, the same compiled program)
    par = fl.trace(sec, wi, h, max_events=5, wave=True, polarized=True,
                   field=Vec3(0.0, 0.0, 1.0 + 0j))  # in the section plane (TE)
    return rec, par


def test_optical_path_and_amplitudes_equal_closed_forms(water_cylinder):
    """Spec seed-002 §1.2.5: L = -2 cos i + 2 p n cos r; A_perp = rho (p = 0),
    (1 - rho^2)(-rho)^(p-1); |A_par| likewise with rho_par."""
    n = 1.331
    h = H_PATH
    rec, par = (_at(r, h) for r in water_cylinder)
    i = np.arcsin(np.abs(h))
    r = np.arcsin(np.sin(i) / n)
    rho_s = (np.cos(i) - n * np.cos(r)) / (np.cos(i) + n * np.cos(r))
    rho_p = (n * np.cos(i) - np.cos(r)) / (n * np.cos(i) + np.cos(r))
    for p in range(5):
        np.testing.assert_allclose(np.asarray(rec.opl[p]), -2 * np.cos(i) + 2 * p * n * np.cos(r), atol=1e-12)
        a_s = rho_s if p == 0 else (1 - rho_s ** 2) * (-rho_s) ** (p - 1)
        a_p = rho_p if p == 0 else (1 - rho_p ** 2) * (-rho_p) ** (p - 1)
        np.testing.assert_allclose(np.asarray(rec.field.x[p]), a_s, atol=1e-12)
        E_par = np.abs(np.stack([np.asarray(c[p]) for c in par.field]))
        np.testing.assert_allclose(np.sqrt(np.sum(E_par ** 2, 0)), np.abs(a_p), atol=1e-12)
        np.testing.assert_allclose(np.abs(np.asarray(par.field.x[p])), 0.0, atol=1e-12)  # stays TE


@pytest.mark.slow  # a program of its own (wave data, unpolarised): the same weights are checked by
# default in split mode (test_smooth_circle_matches_spec_m18_table), the wave data on the
# polarised traces (test_optical_path_and_amplitudes_equal_closed_forms)
def test_unpolarised_wave_trace_weights():
    n, h = 1.331, H_PATH
    unpol = fl.trace(fl.cylinder(n), fiber_direction(0.0, 0.0), jnp.asarray(H_WAVE), max_events=5, wave=True)
    unpol = _at(unpol, h)
    i = np.arcsin(np.abs(h))
    r = np.arcsin(np.sin(i) / n)
    rho_s = (np.cos(i) - n * np.cos(r)) / (np.cos(i) + n * np.cos(r))
    rho_p = (n * np.cos(i) - np.cos(r)) / (n * np.cos(i) + np.cos(r))
    # the unpolarised R weight is the mean of the two polarisations
    np.testing.assert_allclose(0.5 * (rho_s ** 2 + rho_p ** 2), np.asarray(unpol.weight[0, :, 0]), atol=1e-12)


def _segments_cross(p0, d0, l0, p1, d1, l1):
    """Do the 2D segments p0 + s d0 (0<s<l0) and p1 + t d1 (0<t<l1) intersect?"""
    M = np.array([[d0[0], -d1[0]], [d0[1], -d1[1]]])
    if abs(np.linalg.det(M)) < 1e-300:
        return False
    s, t = np.linalg.solve(M, np.asarray(p1) - np.asarray(p0))
    return 0 < s < l0 and 0 < t < l1


def _polyline(h, n, p):
    """Brute-force 2D trace of a unit circle at normal incidence (plain numpy)."""
    pts = [np.array([-10.0, h])]
    d = np.array([1.0, 0.0])
    x = np.array([-np.sqrt(1 - h * h), h])
    pts.append(x)
    nrm = x.copy()
    # refract in
    ci = -d @ nrm
    eta = 1 / n
    ct = np.sqrt(1 - eta ** 2 * (1 - ci ** 2))
    d = eta * d + (eta * ci - ct) * nrm
    for k in range(p):
        t = -2 * (x @ d)
        x = x + t * d
        pts.append(x.copy())
        if k < p - 1:
            d = d - 2 * (d @ x) * x
    ci = d @ x
    ct = np.sqrt(1 - n ** 2 * (1 - ci ** 2))
    d = n * d + (ct - n * ci) * x
    return pts, d


@pytest.mark.parametrize("p", [1, 2, 3])
def test_meridional_foci_equal_brute_force_neighbour_crossings(p, water_cylinder):
    n, dh = 1.331, 1e-6
    hs = H_FOCI
    # the count is symmetric in h, so the side convention of the brute force does not matter
    rec = _at(water_cylinder[0], hs)                   # wave=True, polarised (perpendicular), 5 events
    for j, h in enumerate(hs):
        a, da = _polyline(h, n, p)
        b, db = _polyline(h + dh, n, p)
        count = 0
        for k in range(1, len(a) - 1):
            la = np.linalg.norm(a[k + 1] - a[k])
            lb = np.linalg.norm(b[k + 1] - b[k])
            count += _segments_cross(a[k], (a[k + 1] - a[k]) / la, la, b[k], (b[k + 1] - b[k]) / lb, lb)
        count += _segments_cross(a[-1], da, 1e9, b[-1], db, 1e9)
        assert int(rec.foci[p, j]) == count, (h, int(rec.foci[p, j]), count)


# The caustics program is compiled per lobe (its number of events is static): p = 2 runs by
# default, p = 3 (the same code with one more event) under slow; the secondary bow's angle at
# n = 1.331 is checked by default on the drop tracer (test_drop.py's C15 table, a = 0.4 mm).
@pytest.mark.parametrize("p, regression_deg", [(2, 137.630), pytest.param(3, 129.635, marks=pytest.mark.slow)])
def test_water_cylinder_rainbows_at_descartes_angles(p, regression_deg):
    """Primary (p = 2) and secondary (p = 3) rainbows of a water column at normal incidence,
    found on the tracer, vs Descartes' minimum deviation (cos^2 i = (n^2 - 1)/(p^2 - 1))."""
    water = load_material("water_H2O_Daimon-20.0C")
    for wl in (450.0, 650.0):
        n = float(water(wl)[0])
        c = fl.caustics(fl.cylinder(n), fiber_direction(0.0, 0.0), p)
        ang = np.degrees(np.asarray(c.scattering_angle)[np.asarray(c.valid)])
        i = np.arccos(np.sqrt((n * n - 1) / (p * p - 1)))
        r = np.arcsin(np.sin(i) / n)
        D = 2 * (i - r) + (p - 1) * (np.pi - 2 * r)
        ref = np.degrees(np.arccos(np.cos(D)))
        assert ang.size == 2                      # +h and -h branches
        np.testing.assert_allclose(ang, ref, atol=1e-6)   # issue: 0.01 deg
        h_ref = np.sin(i)
        np.testing.assert_allclose(np.sort(np.abs(np.asarray(c.h)[np.asarray(c.valid)])), [h_ref, h_ref],
                                   atol=1e-7)
    # the spec's regression numbers at n = 1.331 (C2): 137.630 / 129.635 deg
    c = fl.caustics(fl.cylinder(1.331), fiber_direction(0.0, 0.0), p)
    assert abs(np.degrees(float(c.scattering_angle[np.argmax(c.valid)])) - regression_deg) < 1e-3


def test_thin_film_interface_gives_airy_reflectance():
    wl = jnp.array([450.0, 550.0, 650.0])
    itf = fl.Interface("film", film_nm=jnp.asarray(300.0), film_eta=jnp.asarray(1.33), wavelength_nm=wl)
    shp = fl.Shape(interface=itf)
    sec = fl.Section((shp,), (fl.Medium(1.0, 0.0), fl.Medium(1.55, 0.0)))
    theta_i, h = 0.4, np.array([0.0, 0.5, 0.9])
    rec = fl.trace(sec, _dir(theta_i, 0.0), jnp.asarray(h), max_events=3)
    cos3d = np.cos(theta_i) * np.sqrt(1 - h ** 2)
    # (one compiled program: eagerly airy's ~40 operations compile one by one)
    R = jax.jit(lambda c: airy(c, wl, 300.0, 1.0, 1.33, 1.55).R)(jnp.asarray(cos3d)[:, None])
    np.testing.assert_allclose(np.asarray(rec.weight[0]), np.asarray(R), rtol=1e-10)
    total = rec.weight.sum(0) + rec.absorbed + rec.lost + rec.residual
    np.testing.assert_allclose(np.asarray(total), 1.0, atol=1e-10)


def test_gradient_of_smooth_lobe_albedo_matches_finite_differences():
    wi = _dir(0.3, 0.0)

    # (lobe 1 is TT whatever the number of events). The fiber is built outside the compiled
    # program: inside it its zero roughness would be traced, which counts as rough
    smooth = fl.fiber(1.55, 0.4)

    def tt(x):
        sec = smooth.with_media(sigma_a=x[0], eta=x[1])
        return fl.smooth_lobes(sec, wi, n_h=512, n_lobes=4, max_events=12).albedo[1, 0]

    # one compiled program, a jvp along a given direction: the value for the finite differences
    # and one derivative per call (jacfwd of the eager smooth_lobes compiled a vmapped jvp of the
    # trace and dozens of small programs)
    jvp = jax.jit(lambda x, v: jax.jvp(tt, (x,), (v,)))
    e = np.eye(2)
    testing.assert_gradients(lambda x: jvp(jnp.stack(x), e[0])[0], (0.4, 1.55), step=1e-6, rtol=1e-6,
                             grad_fn=lambda x: tuple(jvp(jnp.stack(x), e[k])[1] for k in range(2)),
                             name="TT albedo")
