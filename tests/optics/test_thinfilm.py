"""Thin films: Airy identities, limit cases and the reference numbers of the specs.

References: spec M10 of Padron 2025 (seed-000-spec.md) and checks TF-1..TF-6 of Huang 2022
(seed-001-spec.md §3.1). The cross-check against another program (tmm) is in
tests/validation/test_thinfilm_tmm.py.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import testing
from appearance_jax.optics import fresnel
from appearance_jax.optics import thinfilm as tf

RGB = np.array([650.0, 510.0, 475.0])


def _R(theta_deg, wl, d, e0, e1, e2):
    return np.asarray(tf.airy(np.cos(np.radians(theta_deg)), wl, d, e0, e1, e2).R)


# spec M10 reference table: air / 1.56 / air, 900 nm, unpolarised R at 650 / 510 / 475 nm
REFERENCE = {
    0: (0.1308, 0.1743, 0.0156),
    30: (0.0177, 0.0793, 0.1637),
    45: (0.0536, 0.0227, 0.1274),
    60: (0.2659, 0.2689, 0.0377),
    75: (0.5663, 0.5285, 0.5501),
}


@pytest.mark.parametrize("theta", list(REFERENCE))
def test_reference_table_keratin_film(theta):
    np.testing.assert_allclose(_R(theta, RGB, 900.0, 1.0, 1.56, 1.0), REFERENCE[theta], atol=5e-5)


def test_reference_table_other_indices():
    np.testing.assert_allclose(_R(0, RGB, 900.0, 1.0, 1.53, 1.0), (0.0810, 0.1480, 0.0633), atol=5e-5)
    np.testing.assert_allclose(_R(45, RGB, 900.0, 1.0, 1.53, 1.0), (0.1039, 0.0857, 0.0451), atol=5e-5)
    np.testing.assert_allclose(_R(0, RGB, 900.0, 1.0, 1.56, 1.5), (0.0517, 0.0563, 0.0412), atol=5e-5)
    np.testing.assert_allclose(_R(45, RGB, 900.0, 1.0, 1.56, 1.5), (0.0539, 0.0517, 0.0602), atol=5e-5)


@pytest.mark.parametrize("e0, e1, e2", [(1.0, 1.56, 1.0), (1.0, 1.33, 1.5), (1.33, 1.8, 1.0), (1.5, 1.2, 1.5)])
def test_energy_lossless_any_angle_including_tir(e0, e1, e2):
    """R + T = 1 per polarisation for real indices, also under TIR in the film or substrate."""
    th = np.radians(np.linspace(0.0, 89.9, 60))[:, None]
    wl = np.linspace(380.0, 780.0, 9)[None, :]
    r = tf.airy(np.cos(th), wl, 420.0, e0, e1, e2)
    for R, T in ((r.R_s, r.T_s), (r.R_p, r.T_p), (r.R, r.T)):
        np.testing.assert_allclose(np.asarray(R + T), 1.0, atol=1e-12)
        assert np.all(np.asarray(R) >= -1e-15) and np.all(np.asarray(R) <= 1 + 1e-12)


def test_zero_thickness_is_the_bare_interface():
    """d = 0: R = F(eta0 -> eta2) (Stokes), and R = 0 for eta0 = eta2 (TF-1)."""
    c = np.cos(np.radians(np.linspace(0.0, 89.0, 30)))
    for e1 in (1.33, 1.56, 2.4):
        F, *_ = fresnel.fresnel_dielectric(c, 1.5)
        np.testing.assert_allclose(np.asarray(tf.airy(c, 550.0, 0.0, 1.0, e1, 1.5).R), np.asarray(F), atol=1e-13)
        r = tf.airy(c, 550.0, 0.0, 1.0, e1, 1.0)
        np.testing.assert_allclose(np.asarray(r.R), 0.0, atol=1e-14)
        np.testing.assert_allclose(np.asarray(r.T), 1.0, atol=1e-13)
    # glass -> air beyond the critical angle: the film of zero thickness still reflects totally
    c = np.cos(np.radians(60.0))
    assert abs(float(tf.airy(c, 550.0, 0.0, 1.5, 1.33, 1.0).R) - 1.0) < 1e-13


def test_film_index_equal_to_a_neighbour_makes_thickness_irrelevant():
    c = np.cos(np.radians([0.0, 35.0, 70.0]))[:, None]
    d = np.array([0.0, 137.0, 600.0, 1999.0])[None, :]
    for e1, e2 in ((1.0, 1.5), (1.5, 1.5)):  # eta1 = eta0, eta1 = eta2
        R = np.asarray(tf.airy(c, 500.0, d, 1.0, e1, e2).R)
        np.testing.assert_allclose(R, R[:, :1] * np.ones_like(R), atol=1e-14)


def test_quarter_and_half_wave():
    """(c) eta1 = sqrt(eta0 eta2), eta1 d = lambda/4 => R = 0; (d) eta1 d = lambda/2 => absentee layer."""
    lam, e2 = 550.0, 1.5
    e1 = math.sqrt(e2)
    assert float(tf.airy(1.0, lam, lam / (4 * e1), 1.0, e1, e2).R) < 1e-28
    for e1 in (1.2, 1.38, 2.0):
        R = float(tf.airy(1.0, lam, lam / (2 * e1), 1.0, e1, e2).R)
        assert abs(R - 0.04) < 1e-14


def test_periodic_in_optical_thickness():
    c = np.cos(np.radians([0.0, 40.0, 80.0]))
    for wl in (450.0, 600.0):
        period = np.asarray(tf.film_period_nm(c, wl, 1.0, 1.56))
        np.testing.assert_allclose(period, wl / (2 * np.sqrt(1.56**2 - (1 - c**2))), rtol=1e-14)
        a = np.asarray(tf.airy(c, wl, 313.0, 1.0, 1.56, 1.3).R)
        b = np.asarray(tf.airy(c, wl, 313.0 + 3 * period, 1.0, 1.56, 1.3).R)
        np.testing.assert_allclose(a, b, atol=1e-12)


@pytest.mark.parametrize("n, Rmax, Rmean", [(1.33, 0.07711, 0.03933), (1.55, 0.16991, 0.08891)])
def test_free_standing_film_extremes_and_phase_average(n, Rmax, Rmean):
    """TF-3 (R = 0 at phi = 2 pi m), TF-4 (max 4 R0/(1+R0)^2 at odd pi), TF-5 (mean 2 R0/(1+R0))."""
    lam = 500.0
    period = lam / (2 * n)
    d = period * np.arange(0, 256) / 256.0
    R = np.asarray(tf.airy(1.0, lam, d, 1.0, n, 1.0).R)
    assert R[0] < 1e-30 and abs(R[128] - Rmax) < 5e-6
    np.testing.assert_allclose(R.max(), Rmax, atol=5e-6)
    # the mean over 256 equispaced phases converges geometrically to the period average
    np.testing.assert_allclose(R.mean(), Rmean, atol=5e-6)


def test_keratin_spectral_extrema_tf6():
    """TF-6: d = 590 nm, n = 1.55, normal incidence: maxima 406.4, 522.6, 731.6; minima 457.2, 609.7 nm."""
    wl = np.arange(380.0, 780.0, 0.05)
    R = np.asarray(tf.airy(1.0, wl, 590.0, 1.0, 1.55, 1.0).R)
    inner = R[1:-1]
    maxima = wl[1:-1][(inner > R[:-2]) & (inner > R[2:])]
    minima = wl[1:-1][(inner < R[:-2]) & (inner < R[2:])]
    np.testing.assert_allclose(maxima, [406.4, 522.6, 731.6], atol=0.1)
    np.testing.assert_allclose(minima, [457.2, 609.7], atol=0.1)


def test_printed_thesis_eq_3_1_is_the_transmittance():
    """The expression printed as I_R (Eq. 3.1 of Padron 2025) equals our T, and 1 - it our R."""
    th = np.radians(np.array([0.0, 20.0, 50.0, 70.0]))
    wl, d, n0, n1, n2 = 510.0, 900.0, 1.0, 1.56, 1.3
    c0 = np.cos(th)
    c1 = np.sqrt(1 - (n0 / n1) ** 2 * (1 - c0**2))
    c2 = np.sqrt(1 - (n0 / n2) ** 2 * (1 - c0**2))
    phi = 4 * np.pi / wl * n1 * d * c1
    printed = []
    for pol in ("s", "p"):
        # signed amplitudes written out here, independently of the library
        if pol == "s":
            r10 = (n1 * c1 - n0 * c0) / (n1 * c1 + n0 * c0)
            r12 = (n1 * c1 - n2 * c2) / (n1 * c1 + n2 * c2)
            t01 = 2 * n0 * c0 / (n0 * c0 + n1 * c1)
            t12 = 2 * n1 * c1 / (n1 * c1 + n2 * c2)
        else:
            r10 = (n0 * c1 - n1 * c0) / (n0 * c1 + n1 * c0)
            r12 = (n2 * c1 - n1 * c2) / (n2 * c1 + n1 * c2)
            t01 = 2 * n0 * c0 / (n1 * c0 + n0 * c1)
            t12 = 2 * n1 * c1 / (n2 * c1 + n1 * c2)
        printed.append(n2 * c2 / (n0 * c0) * (t01 * t12) ** 2 / ((r10 * r12) ** 2 - 2 * r10 * r12 * np.cos(phi) + 1))
    printed = 0.5 * (printed[0] + printed[1])
    r = tf.airy(c0, wl, d, n0, n1, n2)
    np.testing.assert_allclose(np.asarray(r.T), printed, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(r.R), 1 - printed, rtol=1e-12)


def test_multilayer_three_media_equals_airy_and_two_media_the_interface():
    c = np.cos(np.radians(np.linspace(0, 89, 17)))[:, None]
    wl = np.array([420.0, 555.0, 690.0])[None, :]
    for e in [(1.0, 1.56, 1.0), (1.0, 1.4 + 0.05j, 0.2 + 3.0j), (1.5, 1.0, 1.5)]:
        a = tf.airy(c, wl, 333.0, *e)
        m = tf.multilayer(c, wl, np.array(e), np.array([333.0]))
        for x, y in zip(a, m):
            np.testing.assert_allclose(np.asarray(x), np.asarray(y), atol=1e-12)
    two = tf.multilayer(c, wl, np.array([1.0, 1.5]), np.zeros((0,)))
    F, *_ = fresnel.fresnel_dielectric(c, 1.5)
    np.testing.assert_allclose(np.asarray(two.R) * np.ones_like(np.asarray(F)), np.asarray(F) * np.ones(3), atol=1e-13)


def test_multilayer_thick_absorbing_layer_does_not_overflow():
    """A 1 mm metal layer: the normalised propagation keeps numbers finite, T -> 0."""
    r = tf.multilayer(0.8, 500.0, np.array([1.0, 1.5, 0.2 + 3.0j, 1.5]), np.array([100.0, 1e6]))
    assert np.isfinite(float(r.R)) and float(r.T) < 1e-12
    # and the reflectance is the one of the semi-infinite metal under the same coating
    semi = tf.airy(0.8, 500.0, 100.0, 1.0, 1.5, 0.2 + 3.0j)
    assert abs(float(r.R) - float(semi.R)) < 1e-12


def test_conductor_substrate_energy_and_limit():
    """Absorbing substrate: 0 <= R <= 1, R + T = 1 (T = power entering the metal); d = 0 => conductor Fresnel."""
    c = np.cos(np.radians(np.linspace(0, 89, 30)))
    r = tf.airy(c, 550.0, 250.0, 1.0, 1.5, 0.27 + 2.94j)
    np.testing.assert_allclose(np.asarray(r.R + r.T), 1.0, atol=1e-12)
    r0 = tf.airy(c, 550.0, 0.0, 1.0, 1.5, 0.27 + 2.94j)
    np.testing.assert_allclose(np.asarray(r0.R), np.asarray(fresnel.fresnel_conductor(c, 0.27, 2.94)), atol=1e-12)


def test_grazing_incidence_and_tf8():
    """cos0 = 0: R = 1, T = 0, no NaN; R -> 1 towards grazing (TF-8)."""
    r = tf.airy(0.0, 550.0, 300.0, 1.0, 1.55, 1.0)
    assert float(r.R) == pytest.approx(1.0, abs=1e-14) and float(r.T) == 0.0
    R = np.asarray(tf.airy(np.cos(np.radians([80.0, 85.0, 89.0, 89.9])), 550.0, 300.0, 1.0, 1.55, 1.0).R)
    assert np.all(np.diff(R) > 0) and R[-1] > 0.97


def test_gradients_match_finite_differences():
    """d R / d (thickness, eta1, eta2, cos0, wavelength, k of the substrate) vs central differences."""

    def R(x):
        return tf.airy(x["c"], x["wl"], x["d"], 1.0, x["e1"], x["e2"] + 1j * x["k"]).R

    names = ("c", "d", "e1", "e2", "wl", "k")
    h = (1e-6, 1e-4, 1e-6, 1e-6, 1e-4, 1e-6)  # absolute steps (the harness scales its step by max(|x|, 1))
    for x0 in ([0.7, 480.0, 1.56, 1.3, 530.0, 1e-3], [0.95, 120.0, 1.38, 0.3, 610.0, 2.5], [0.2, 900.0, 1.8, 1.5, 450.0, 0.1]):
        steps = {n: s / max(abs(v), 1.0) for n, s, v in zip(names, h, x0)}
        testing.assert_gradients(R, dict(zip(names, x0)), step=steps, rtol=1e-5, atol=1e-8, name="airy R")


def test_airy_trt_derivatives_are_those_of_its_formula():
    """airy_trt's custom JVP (derivatives from one stacked film) equals forward and reverse AD of the
    two-film formula T_s(i) T_s(o) + T_p(i) T_p(o) written out with airy, for every argument, at
    broadcast shapes (bands on a trailing axis, a per-pair thickness), grazing pair included.
    (airy's own derivatives are checked against central differences above.)"""
    wl = jnp.asarray([450.0, 550.0, 650.0])
    x0 = dict(ci=jnp.asarray([[0.9], [0.3], [1.0], [0.05]]), co=jnp.asarray([[0.6], [0.8], [0.2], [0.0]]),
              d=jnp.asarray([[590.0], [300.0], [1200.0], [50.0]]), eta=jnp.asarray(1.55), m=jnp.asarray(0.06))
    rng = np.random.default_rng(3)
    w = jnp.asarray(rng.uniform(0.5, 1.5, (4, 3)))  # a generic cotangent
    ts = jax.tree_util.tree_map(lambda v: jnp.asarray(rng.normal(size=(5,) + v.shape)), x0)  # 5 tangents

    def trt(x):
        return tf.airy_trt(x["ci"], x["co"], wl, x["d"], x["eta"], x["m"])

    def written_out(x):
        a, b = (tf.airy(c, wl, x["d"], 1.0, x["eta"], 1.0) for c in (x["ci"], x["co"]))
        return x["m"] * 0.5 * (a.T_s * b.T_s + a.T_p * b.T_p)

    @jax.jit  # one program; forward mode for the reference (its reverse pass is the slow compile)
    def run(x):
        jvps = [jax.vmap(lambda t, f=f: jax.jvp(f, (x,), (t,))[1])(ts) for f in (trt, written_out)]
        return trt(x), written_out(x), jvps, jax.grad(lambda y: jnp.sum(w * trt(y)))(x)

    v, v_ref, (j, j_ref), g = run(x0)
    np.testing.assert_allclose(v, v_ref, rtol=1e-14)
    np.testing.assert_allclose(j, j_ref, rtol=1e-12, atol=1e-15)
    assert np.all(np.abs(np.asarray(j)).reshape(5, -1).max(axis=1) > 1e-3)
    # reverse mode is the transpose of the rule: <grad, t> = <w, J t> for every tangent
    g_dot_t = sum(np.asarray(ts[k]).reshape(5, -1) @ np.asarray(g[k]).ravel() for k in x0)
    np.testing.assert_allclose(g_dot_t, np.einsum("kij,ij->k", np.asarray(j), np.asarray(w)), rtol=1e-12)
    assert all(np.all(np.isfinite(g[k])) for k in x0)


def test_value_and_gradient_finite_at_normal_grazing_and_critical_angle():
    def R(c):
        return tf.airy(c, 500.0, 300.0, 1.5, 1.0, 1.5).R + tf.airy(c, 500.0, 300.0, 1.0, 1.0, 1.0).R

    crit = math.sqrt(1 - (1 / 1.5) ** 2)
    for c in (0.0, 1.0, crit):
        assert np.isfinite(float(R(c))) and np.isfinite(float(jax.grad(R)(jnp.asarray(c))))
    # exactly at the critical angle of the film the value is the limit from either side (continuity)
    assert abs(float(R(crit)) - float(R(crit + 1e-9))) < 1e-6
    assert abs(float(R(crit)) - float(R(crit - 1e-9))) < 1e-6


def test_film_rgb_modes_and_chart():
    # rgb3 is the film reflectance at 650/510/475 nm
    rgb3 = np.asarray(tf.film_rgb(1.0, 900.0, 1.0, 1.56, 1.0, mode="rgb3"))
    np.testing.assert_allclose(rgb3, REFERENCE[0], atol=5e-5)
    # cie: a zero-thickness film on glass is grey: R = 0.04 at every wavelength -> (0.04,)*3
    grey = np.asarray(tf.film_rgb(1.0, 0.0, 1.0, 1.33, 1.5))
    np.testing.assert_allclose(grey, 0.04, atol=1e-4)
    # reflectance + transmittance colours add up to white for a lossless film
    a = np.asarray(tf.film_rgb(0.6, 420.0, 1.0, 1.33, 1.0))
    b = np.asarray(tf.film_rgb(0.6, 420.0, 1.0, 1.33, 1.0, quantity="transmittance"))
    white = np.asarray(tf.film_rgb(0.6, 0.0, 1.0, 1.0, 1.0, quantity="transmittance"))  # T = 1: the white point
    np.testing.assert_allclose(white, 1.0, atol=1e-12)  # white-balanced CIE conversion
    np.testing.assert_allclose(a + b, white, atol=1e-12)
    assert np.ptp(a) > 0.02  # and it is coloured
    chart = np.asarray(tf.color_chart(np.linspace(0, 1000, 21), np.array([0.0, 45.0, 80.0])))
    assert chart.shape == (21, 3, 3) and np.all((chart >= 0) & (chart <= 1))
    with pytest.raises(ValueError, match="mode"):
        tf.film_rgb(1.0, 100.0, 1.0, 1.33, 1.0, mode="xyz")


def test_thicker_film_needed_at_oblique_incidence_tf7():
    """The first reflectance maximum at 550 nm moves to larger thickness with angle (Huang Fig. 3.3)."""
    d = np.linspace(1.0, 200.0, 4000)
    first_max = []
    for th in (0.0, 40.0, 70.0):
        R = np.asarray(tf.airy(np.cos(np.radians(th)), 550.0, d, 1.0, 1.33, 1.0).R)
        first_max.append(d[np.argmax(R)])
    assert first_max[0] < first_max[1] < first_max[2]
    np.testing.assert_allclose(first_max[0], 550.0 / (4 * 1.33), atol=0.1)


def test_polarization_argument_checked():
    r = tf.airy(0.5, 500.0, 100.0, 1.0, 1.5, 1.0)
    assert float(r.reflectance("s")) > float(r.reflectance("p"))
    with pytest.raises(ValueError, match="polarization"):
        r.reflectance("x")
    with pytest.raises(ValueError, match="media"):
        tf.multilayer(1.0, 500.0, np.array([1.0]), np.zeros(0))
    with pytest.raises(ValueError, match="thicknesses"):
        tf.multilayer(1.0, 500.0, np.array([1.0, 1.5, 1.2, 1.0]), np.array([10.0]))
