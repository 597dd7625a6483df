"""Soap-film thickness fields: Table 3.2 (SS-1), the equilibrium profile Eq. 3.36 (SS-2), maps.

References: seed-001-spec.md §1.2.10, §1.2.11 and checks SS-1, SS-2 (Huang 2022, Ch. 3).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate

from appearance_jax import testing
from appearance_jax.core.frame import spherical_direction
from appearance_jax.core.vec import Vec3
from appearance_jax.soapfilm import thickness as th

# --------------------------------------------------------------------------------------
# SS-1: Table 3.2 consistency


def test_table_3_2_numbers_ss1():
    d = th.dimensionless_numbers(R=0.05, eta0=5e-7, U=1.0, Gamma0=1.669e-7)
    assert round(float(d.epsilon), 7) == 1.0e-5
    assert round(float(d.Re)) == 56011
    assert round(float(d.Cr), 4) == 2.0990
    assert round(float(d.g), 2) == 0.49
    assert round(float(d.M), 2) == 0.83
    # Gamma_0 giving M = 0.83 (spec SS-1: 1.669e-7 mol m^-2)
    assert float(th.gamma0_for_marangoni(0.83, eta0=5e-7)) == pytest.approx(1.669e-7, rel=1e-3)
    # defaults are the Table 3.2 setting
    assert np.allclose(th.dimensionless_numbers(), d)


def test_drag_coefficient_uses_bubble_radius_not_gas_constant():
    # the OCR fix: Cr = rho_a sqrt(nu_a R) / (rho eta_0 sqrt(U)) with R the bubble radius
    c1 = th.dimensionless_numbers(R=0.02).Cr
    c4 = th.dimensionless_numbers(R=0.08).Cr
    assert float(c4 / c1) == pytest.approx(2.0, rel=1e-12)
    k = th.TABLE_3_1
    with_gas_constant = k.rho_a * math.sqrt(k.nu_a * k.R_gas) / (k.rho * 5e-7)
    assert abs(with_gas_constant - 2.1) > 10.0  # the printed formula could not give 2.1


# --------------------------------------------------------------------------------------
# SS-2: equilibrium profile


@pytest.mark.parametrize("R, g_over_M, top, bottom", [
    (0.02, 0.473, 0.590, 1.518),
    (0.05, 1.182, 0.222, 2.361),
    (0.10, 2.364, 0.0317, 3.583),
])
def test_equilibrium_fig_3_13_values_ss2(R, g_over_M, top, bottom):
    d = th.dimensionless_numbers(R=R, eta0=4e-7, U=1.0, Gamma0=6.67e-8)
    assert round(float(d.M), 4) == 0.4146
    a = float(d.g_over_M)
    assert a == pytest.approx(g_over_M, abs=5e-4)
    digits = 4 if top < 0.1 else 3
    assert round(float(th.equilibrium_thickness(0.0, a)), digits) == top
    assert round(float(th.equilibrium_thickness(math.pi, a)), 3) == bottom


@pytest.mark.parametrize("a", [-0.7, 0.0, 1e-6, 0.473, 2.364, 40.0])
def test_normalisations_against_quadrature(a):
    unnorm = lambda t: math.exp(-a * math.cos(t))  # noqa: E731
    mean_theta = integrate.quad(unnorm, 0.0, math.pi, epsabs=0, epsrel=1e-13)[0] / math.pi
    area = integrate.quad(lambda t: unnorm(t) * math.sin(t), 0.0, math.pi, epsabs=0, epsrel=1e-13)[0]
    t = np.linspace(0.0, math.pi, 7)
    ref = np.array([unnorm(x) for x in t])
    np.testing.assert_allclose(th.equilibrium_thickness(t, a, "printed"), ref / mean_theta, rtol=1e-11)
    np.testing.assert_allclose(th.equilibrium_thickness(t, a, "volume"), ref * 2.0 / area, rtol=1e-11)


def test_equilibrium_solves_force_balance_and_is_thinner_on_top():
    # Eq. 3.35: -(M / eta) d eta / d theta + g sin theta = 0  <=>  d ln eta / d theta = (g/M) sin theta
    a = 1.3
    theta = jnp.linspace(0.05, math.pi - 0.05, 9)
    dlog = jax.vmap(jax.grad(lambda t: jnp.log(th.equilibrium_thickness(t, a))))(theta)
    np.testing.assert_allclose(dlog, a * np.sin(theta), rtol=1e-12)
    eta = th.equilibrium_thickness(theta, a)
    assert np.all(np.diff(eta) > 0)  # thickens from the top (theta = 0) to the bottom
    assert th.equilibrium_thickness(0.0, a) < 1.0 < th.equilibrium_thickness(math.pi, a)


def test_larger_radius_over_gamma0_thins_top_and_same_ratio_same_profile():
    d1 = th.dimensionless_numbers(R=0.02, eta0=4e-7, Gamma0=6.67e-8)
    d2 = th.dimensionless_numbers(R=0.04, eta0=4e-7, Gamma0=1.334e-7)  # same R / Gamma_0
    d3 = th.dimensionless_numbers(R=0.04, eta0=4e-7, Gamma0=6.67e-8)  # larger R / Gamma_0
    t = np.linspace(0.0, math.pi, 11)
    p1, p2, p3 = (th.equilibrium_thickness(t, d.g_over_M) for d in (d1, d2, d3))
    np.testing.assert_allclose(p1, p2, rtol=1e-12)
    assert p3[0] < p1[0] and p3[-1] > p1[-1]


def test_gradient_in_g_over_M_matches_finite_differences():
    t = jnp.array([0.0, 1.0, 2.5, math.pi])
    for norm in ("printed", "volume"):
        for a in (0.0, 0.8, 30.0):
            testing.assert_gradients(lambda a: th.equilibrium_thickness(t, a, norm), a, step=1e-6 / max(a, 1.0),
                                     rtol=1e-6, atol=1e-8, elementwise=True, mode="fwd",
                                     name=f"equilibrium_thickness[{norm}]")


def test_equilibrium_field_is_twice_eta0_times_profile():
    f = th.equilibrium_field(1.182, eta0_nm=400.0)
    n = spherical_direction(jnp.array([0.0, 1.0, math.pi]), jnp.array([0.3, 2.0, 0.0]))
    np.testing.assert_allclose(f(n), 800.0 * th.equilibrium_thickness(jnp.array([0.0, 1.0, math.pi]), 1.182),
                               rtol=1e-12)
    # another up axis: the top is where n = up
    g = th.equilibrium_field(1.182, eta0_nm=400.0, up=(1.0, 0.0, 0.0))
    assert float(g(Vec3(1.0, 0.0, 0.0))) == pytest.approx(800.0 * 0.2221, rel=1e-3)


# --------------------------------------------------------------------------------------
# equirectangular maps


def test_latlong_cell_centres_interior_bilinear_and_wrap():
    n_t, n_p = 8, 12
    T, P = th.latlong_grid(n_t, n_p)
    vals = 3.0 + np.cos(T) + 0.5 * np.sin(2 * P)
    # exact at the cell centres
    got = th.latlong_thickness(vals, spherical_direction(T, P))
    np.testing.assert_allclose(got, vals, rtol=1e-12)
    # a map linear in theta is reproduced exactly between interior rows
    lin = np.asarray(T) * 2.0 + 1.0
    t = np.array([0.5, 1.0, 2.0, 2.6])
    p = np.array([0.1, 3.0, 6.2, 5.0])
    np.testing.assert_allclose(th.latlong_thickness(lin, spherical_direction(t, p)), 2 * t + 1, rtol=1e-12)
    # phi wraps: half-way between the last and the first column
    row = 3
    w = th.latlong_thickness(vals, spherical_direction(T[row, 0], 0.0))
    assert float(w) == pytest.approx(0.5 * (vals[row, 0] + vals[row, -1]), rel=1e-12)
    # trailing channel axes are carried along
    two = np.stack([vals, 2 * vals], -1)
    np.testing.assert_allclose(th.latlong_thickness(two, spherical_direction(T, P)), two, rtol=1e-12)


def test_latlong_is_continuous_across_the_pole():
    n_t, n_p = 6, 16
    T, P = th.latlong_grid(n_t, n_p)
    vals = 2.0 + np.cos(P) * np.sin(T)  # a smooth field on the sphere (the x coordinate)
    eps = 1e-7
    for phi in (0.2, 1.3, 4.0):
        a = th.latlong_thickness(vals, spherical_direction(eps, phi))
        b = th.latlong_thickness(vals, spherical_direction(eps, phi + math.pi))
        assert float(a) == pytest.approx(float(b), abs=1e-6)
    # at the pole the interpolation averages the two meridians: cos(phi) and cos(phi + pi) cancel
    assert float(th.latlong_thickness(vals, Vec3(0.0, 0.0, 1.0))) == pytest.approx(2.0, abs=1e-3)
    assert float(th.latlong_thickness(vals, Vec3(0.0, 0.0, -1.0))) == pytest.approx(2.0, abs=1e-3)


def test_latlong_jit_and_gradient_in_values():
    vals = jnp.ones((4, 8)) * 500.0
    n = spherical_direction(jnp.array([0.4, 2.0]), jnp.array([1.0, 5.0]))
    f = jax.jit(lambda v: jnp.sum(th.latlong_thickness(v, n)))
    np.testing.assert_allclose(f(vals), 1000.0)
    g = jax.grad(f)(vals)
    assert float(jnp.sum(g)) == pytest.approx(2.0)  # bilinear weights sum to one per lookup


# --------------------------------------------------------------------------------------
# bad input


def test_bad_input_names_the_argument():
    with pytest.raises(ValueError, match="normalization"):
        th.equilibrium_thickness(0.0, 1.0, "area")
    with pytest.raises(ValueError, match="thickness_nm"):
        th.uniform_field(-1.0)
    with pytest.raises(ValueError, match="eta0_nm"):
        th.equilibrium_field(1.0, eta0_nm=-5.0)
    with pytest.raises(ValueError, match="values_nm"):
        th.latlong_field(-np.ones((2, 4)))
    with pytest.raises(ValueError, match="R = -0.1"):
        th.dimensionless_numbers(R=-0.1)
    with pytest.raises(ValueError, match="g_over_M"):
        th.equilibrium_thickness(0.0, float("nan"))
