"""Fresnel equations against closed forms, the Stokes relations and energy conservation."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import testing
from appearance_jax.optics.fresnel import (
    critical_angle,
    fresnel_amplitudes_complex,
    fresnel_conductor,
    fresnel_dielectric,
    fresnel_dielectric_amplitudes,
    schlick,
    schlick_f0,
)


@pytest.mark.parametrize("eta, expected", [(1.5, 0.04), (1.53, 0.04388), (1.55, 0.04652), (1.56, 0.04785)])
def test_normal_incidence_reflectance(eta, expected):
    # ((eta - 1) / (eta + 1))^2; the three keratin indices of the theses
    F = fresnel_dielectric(1.0, eta)[0]
    assert F == pytest.approx(expected, abs=5e-6)
    assert schlick_f0(eta) == pytest.approx(expected, abs=5e-6)


def test_normal_incidence_same_from_inside():
    # reflectance at normal incidence is symmetric in the direction of travel
    assert fresnel_dielectric(-1.0, 1.5)[0] == pytest.approx(0.04, abs=1e-12)


def test_known_oblique_value():
    # Brewster angle: r_p = 0 at tan(theta_B) = eta; F = R_s / 2 there
    eta = 1.5
    tb = np.arctan(eta)
    r_s, r_p, _, _ = fresnel_dielectric_amplitudes(np.cos(tb), eta)
    assert abs(r_p) < 1e-12
    ci, ct = np.cos(tb), np.cos(np.arcsin(np.sin(tb) / eta))
    assert r_s == pytest.approx((ci - eta * ct) / (ci + eta * ct), rel=1e-12)
    assert fresnel_dielectric(np.cos(tb), eta)[0] == pytest.approx(0.5 * float(r_s) ** 2, rel=1e-12)


def test_critical_angle_and_tir():
    # from glass (1.5) into air: eta seen from inside = 1/1.5; normal points into air
    tc = critical_angle(1.5)
    assert np.degrees(tc) == pytest.approx(41.8103149, abs=1e-6)
    # light arriving from inside: cos_i < 0 with eta = eta_inside / eta_outside = 1.5
    th = np.radians(np.array([41.9, 50.0, 70.0, 89.0]))
    F, cos_t, eta_it, _ = fresnel_dielectric(-np.cos(th), 1.5)
    np.testing.assert_allclose(F, 1.0)
    np.testing.assert_allclose(cos_t, 0.0)
    np.testing.assert_allclose(eta_it, 1 / 1.5)
    # just below the critical angle: partial reflection, transmitted ray near grazing
    F2, cos_t2, _, _ = fresnel_dielectric(-np.cos(tc - 1e-3), 1.5)
    assert 0.0 < F2 < 1.0
    assert 0.0 < cos_t2 < 0.1  # transmitted on the outside (cos_t > 0), near grazing


def test_transmitted_cosine_obeys_snell():
    th = np.linspace(0.0, 1.5, 7)
    for eta in (1.33, 1.5, 2.4):
        _, cos_t, _, _ = fresnel_dielectric(np.cos(th), eta)
        sin_t = np.sqrt(1.0 - np.asarray(cos_t) ** 2)
        np.testing.assert_allclose(sin_t * eta, np.sin(th), atol=1e-12)
        assert np.all(np.asarray(cos_t) <= 0)  # transmitted into the lower hemisphere


@pytest.mark.parametrize("eta", [1.33, 1.5, 2.0])
def test_stokes_relations(eta):
    # Stokes: r_ji = -r_ij and t_ij t_ji - r_ij r_ji = 1 for both polarisations
    th_i = np.linspace(0.0, 1.5, 11)
    ci = np.cos(th_i)
    ct = np.sqrt(1.0 - (np.sin(th_i) / eta) ** 2)  # cos of the refracted angle
    rs_ij, rp_ij, ts_ij, tp_ij = fresnel_dielectric_amplitudes(ci, eta)
    rs_ji, rp_ji, ts_ji, tp_ji = fresnel_dielectric_amplitudes(ct, 1.0 / eta)
    np.testing.assert_allclose(rs_ji, -rs_ij, atol=1e-12)
    np.testing.assert_allclose(rp_ji, -rp_ij, atol=1e-12)
    np.testing.assert_allclose(ts_ij * ts_ji - rs_ij * rs_ji, 1.0, atol=1e-12)
    np.testing.assert_allclose(tp_ij * tp_ji - rp_ij * rp_ji, 1.0, atol=1e-12)


@pytest.mark.parametrize("eta", [1.33, 1.5, 1 / 1.5])
def test_energy_conservation_per_polarisation(eta):
    # R + T = 1 with T = (eta_t cos_t)/(eta_i cos_i) |t|^2 (eta_i = 1), s and p
    th_i = np.linspace(0.0, 1.55, 23)
    ci = np.cos(th_i)
    r_s, r_p, t_s, t_p = fresnel_dielectric_amplitudes(ci, eta)
    sin2_t = np.sin(th_i) ** 2 / eta**2
    ok = sin2_t < 1.0
    ct = np.sqrt(np.maximum(1.0 - sin2_t, 0.0))
    factor = eta * ct / ci
    np.testing.assert_allclose((r_s**2 + factor * t_s**2)[ok], 1.0, atol=1e-12)
    np.testing.assert_allclose((r_p**2 + factor * t_p**2)[ok], 1.0, atol=1e-12)
    # unpolarised F equals the mean of |r_s|^2 and |r_p|^2, and is 1 under TIR
    F = fresnel_dielectric(ci, eta)[0]
    np.testing.assert_allclose(F[ok], (0.5 * (r_s**2 + r_p**2))[ok], atol=1e-12)
    np.testing.assert_allclose(F[~ok], 1.0)


def test_complex_amplitudes_match_real_ones_below_tir():
    ci = np.cos(np.linspace(0.0, 1.5, 9))
    for eta in (1.33, 1.7):
        real = fresnel_dielectric_amplitudes(ci, eta)
        cplx = fresnel_amplitudes_complex(ci, 1.0, eta)[:4]
        for a, b in zip(real, cplx):
            np.testing.assert_allclose(np.asarray(b).real, a, atol=1e-12)
            np.testing.assert_allclose(np.asarray(b).imag, 0.0, atol=1e-12)


def test_complex_amplitudes_tir_has_unit_modulus():
    ci = np.cos(np.radians([45.0, 60.0, 85.0]))
    r_s, r_p, _, _, _ = fresnel_amplitudes_complex(ci, 1.5, 1.0)
    np.testing.assert_allclose(np.abs(r_s), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.abs(r_p), 1.0, atol=1e-12)


def test_conductor_with_zero_k_equals_dielectric():
    ci = np.cos(np.linspace(0.0, np.pi / 2, 13))
    for eta in (1.2, 1.5, 2.5):
        np.testing.assert_allclose(fresnel_conductor(ci, eta, 0.0), fresnel_dielectric(ci, eta)[0], atol=1e-12)


@pytest.mark.parametrize("n, k", [(0.2, 3.0), (1.5, 0.0), (2.9, 3.0), (0.05, 4.0), (1.0, 1e-3)])
def test_conductor_normal_incidence(n, k):
    expected = ((n - 1) ** 2 + k**2) / ((n + 1) ** 2 + k**2)
    assert fresnel_conductor(1.0, n, k) == pytest.approx(expected, rel=1e-12)


def test_conductor_grazing_is_one():
    np.testing.assert_allclose(fresnel_conductor(0.0, np.array([0.2, 1.5, 2.9]), np.array([3.0, 0.5, 3.0])), 1.0)


def test_conductor_real_formula_matches_complex_amplitudes():
    rng = np.random.default_rng(7)
    ci = rng.uniform(0.0, 1.0, 500)
    n = rng.uniform(0.05, 4.0, 500)
    k = rng.uniform(0.0, 6.0, 500)
    r_s, r_p, _, _, _ = fresnel_amplitudes_complex(ci, 1.0, n + 1j * k)
    ref = 0.5 * (np.abs(r_s) ** 2 + np.abs(r_p) ** 2)
    np.testing.assert_allclose(fresnel_conductor(ci, n, k), ref, rtol=1e-10, atol=1e-12)


def test_conductor_broadcasts_rgb():
    n = jnp.array([0.18, 0.42, 1.37])
    k = jnp.array([3.42, 2.35, 1.77])
    F = fresnel_conductor(jnp.array([[1.0], [0.5]]), n, k)
    assert F.shape == (2, 3)
    assert np.all((np.asarray(F) > 0) & (np.asarray(F) < 1))


def test_schlick_end_points():
    f0 = np.array([0.04, 0.5, 0.9])
    np.testing.assert_allclose(schlick(1.0, f0), f0, atol=1e-15)
    np.testing.assert_allclose(schlick(0.0, f0), 1.0, atol=1e-15)
    # an approximation of the exact curve for eta = 1.5: measured max |error| 0.0357 at
    # cos = 0.09, 0.00078 for cos >= 0.9
    ci = np.linspace(0.0, 1.0, 201)
    err = np.abs(schlick(ci, 0.04) - fresnel_dielectric(ci, 1.5)[0])
    assert np.max(err) < 0.04
    assert np.max(err[ci >= 0.9]) < 0.001


def _assert_finite_grads(f, *args):
    for i in range(len(args)):
        g = jax.grad(f, argnums=i)(*args)
        assert np.all(np.isfinite(np.asarray(g))), (f, args, i, g)


def test_gradients_finite_at_grazing_and_tir_boundary():
    eta = 1.5
    cos_crit = float(np.sqrt(1.0 - 1.0 / eta**2))
    for c in (0.0, 1e-12, 1.0, -1.0, -cos_crit, -(cos_crit - 1e-9), -(cos_crit + 1e-9), -1e-12):
        _assert_finite_grads(lambda c_, e_: fresnel_dielectric(c_, e_)[0], c, eta)
        _assert_finite_grads(lambda c_, e_: fresnel_dielectric(c_, e_)[1], c, eta)
    for c in (0.0, 1e-12, 1.0, cos_crit):
        _assert_finite_grads(lambda c_, e_: sum(fresnel_dielectric_amplitudes(c_, e_)), c, 1 / eta)
    for c in (0.0, 1.0, 0.3):
        for n, k in ((0.2, 3.0), (1.5, 0.0), (1.0, 0.0)):
            _assert_finite_grads(fresnel_conductor, c, n, k)
        _assert_finite_grads(schlick, c, 0.04)


def test_gradient_matches_finite_differences():
    # d F / d cos and d F / d eta of the dielectric, d F / d (cos, n, k) of the conductor, away from kinks
    testing.assert_gradients(lambda x: fresnel_dielectric(*x)[0], (0.37, 1.45), rtol=1e-6, name="dielectric")
    testing.assert_gradients(lambda x: fresnel_conductor(*x), (0.37, 0.4, 2.1), rtol=1e-6, name="conductor")


def test_jit_and_vmap():
    f = jax.jit(jax.vmap(lambda c: fresnel_dielectric(c, 1.5)[0]))
    c = jnp.linspace(-1.0, 1.0, 9)
    np.testing.assert_allclose(f(c), fresnel_dielectric(c, 1.5)[0], atol=1e-12)
