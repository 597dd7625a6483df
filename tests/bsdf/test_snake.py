"""Snake-skin BSDF (Padrón 2025, Ch. 3): the spec's check values, closed forms, the white
furnace, the Nyström solution against an independent random walk, limits, gradients.

Compile time dominates here (each static configuration and each shape compiles the Airy
film and the Nyström solve), so checks are grouped by static configuration and shapes.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.special import expn

from appearance_jax import testing
from appearance_jax.bsdf import snake
from appearance_jax.core.vec import Vec3
from appearance_jax.optics.fresnel import fresnel_dielectric
from appearance_jax.optics.thinfilm import airy

RGB = np.array([650.0, 510.0, 475.0])


def _dirs(mu, phi=0.0):
    mu = jnp.asarray(mu, jnp.float64)
    s = jnp.sqrt(jnp.maximum(1.0 - mu * mu, 0.0))
    return Vec3(s * jnp.cos(phi), s * jnp.sin(phi), mu)


N_PAD = 8  # every small check evaluates 8 direction pairs: one compile per static configuration


def _b(x):
    """A band-valued parameter (3 equal values): the harness checks share programs compiled for them."""
    return (x, x, x)


def _all(p, mu_i, mu_o, phi_o=0.0):
    """(f_d, R, A_d) at cosines mu_i, mu_o (<= 8 of them) through ``snake.components``."""
    mu_i, mu_o = np.atleast_1d(np.asarray(mu_i, float)), np.atleast_1d(np.asarray(mu_o, float))
    n = max(mu_i.size, mu_o.size)
    assert n <= N_PAD
    pad = lambda m: np.concatenate([np.broadcast_to(m, (n,)), np.full(N_PAD - n, 0.5)])  # noqa: E731
    out = snake.components(p, _dirs(pad(mu_i)), _dirs(pad(mu_o), phi_o))
    return tuple(np.asarray(x)[:n] for x in out)


@jax.jit
def _airy_jit(mu, wl):
    return airy(mu[:, None], wl, 900.0, 1.0, 1.56, 1.0).R


def _airy_R(mu, wl=RGB):
    """The Airy reflectance of the default film (air / 1.56 / air, 900 nm), (n, n_wl)."""
    mu = np.atleast_1d(np.asarray(mu, float))
    return np.asarray(_airy_jit(jnp.asarray(np.r_[mu, np.full(N_PAD - mu.size, 0.5)]), jnp.asarray(wl)))[:mu.size]


# ----------------------------------------------------------------------------------------
# the spec's numbers

# spec M26 check table: eta = 1 / 1.56 / 1, delta_0 = 900 nm, sigma_a delta_1 = 1.4, kd = 0.3;
# columns R_spec(1), diffuse albedo(mu_i = 1), f_diff(1, 1), R_spec(0.5), diffuse albedo(0.5);
# rows 650, 510, 475 nm
M26 = {
    "product": [[0.1308, 0.0311, 0.0178, 0.2659, 0.0047],
                [0.1743, 0.0286, 0.0161, 0.2689, 0.0045],
                [0.0156, 0.0340, 0.0229, 0.0377, 0.0059]],
    "beer_sum": [[0.1308, 0.0077, 0.0044, 0.2659, 0.0016],
                 [0.1743, 0.0070, 0.0040, 0.2689, 0.0015],
                 [0.0156, 0.0084, 0.0056, 0.0377, 0.0020]],
}


@pytest.mark.parametrize("form", list(M26))
def test_spec_m26_check_table(form):
    """f_diff(1, 1) is the non-delta f_d = T F T at mu_i = mu_o = 1 (T factors included), the
    diffuse albedo is 2 pi int f_d mu_o dmu_o. The printed values (30 over both forms) agree to half a unit of
    the 4th decimal, except two that the spec double-rounded (0.005847 -> 0.0059 for product
    475 nm albedo(0.5), 0.007647 -> 0.0077 for beer_sum 650 nm albedo(1)): an independent
    4000-cell midpoint solve gives the same 0.005847 / 0.007647, so the tolerance is 6e-5."""
    p = snake.Params(absorption=form, thickness=900.0, eta0=1.0, eta1=1.56, eta2=1.0, sigma_a=0.7, depth=2.0, kd=0.3)
    assert p == snake.PRESETS["spec_m26_check"].replace(absorption=form)
    f, R, A = _all(p, [1.0, 0.5], [1.0, 1.0])
    got = np.stack([R[0], A[0], f[0], R[1], A[1]], axis=-1)  # (bands, 5)
    np.testing.assert_allclose(got, np.array(M26[form]), rtol=0, atol=6e-5)
    # R_spec is the Airy reflectance itself (spec M10 table)
    np.testing.assert_allclose(R, _airy_R([1.0, 0.5]), rtol=1e-13)
    # the two double-rounded entries, to the 5th digit
    if form == "product":
        assert abs(A[1, 2] - 0.005847) < 1e-6
    else:
        assert abs(A[0, 0] - 0.007647) < 1e-6


@pytest.mark.parametrize("form", ["product", "beer_sum"])
def test_no_film_is_f1_and_its_albedo_closed_form(form):
    """delta_0 = 0, eta_0 = eta_1 = eta_2: R = 0, T = 1, so f_d = f_1 exactly (Eq. 3.6) and the
    albedo is 2 E_3(tau / mu) (product) or 2 e^{-tau / mu} E_3(tau) (beer_sum) (spec M26, Q-S7)."""
    tau = 1.4
    p = snake.Params(thickness=0.0, eta0=1.0, eta1=1.0, eta2=1.0, sigma_a=0.7, depth=2.0, kd=1.0, absorption=form)
    mu_i = np.array([1.0, 0.5, 0.2])
    mu_o = np.array([0.3, 0.9, 0.6])
    f, R, A = _all(p, mu_i, mu_o, 2.0)
    mi, mo = mu_i[:, None], mu_o[:, None]
    x = tau / (mi * mo) if form == "product" else tau * (1 / mi + 1 / mo)
    np.testing.assert_allclose(f, np.broadcast_to(np.exp(-x) / math.pi, f.shape), rtol=1e-12)
    assert np.all(R < 1e-20)  # an index-matched film reflects nothing
    mu = mu_i
    closed = 2 * expn(3, tau / mu) if form == "product" else 2 * np.exp(-tau / mu) * expn(3, tau)
    np.testing.assert_allclose(A, np.broadcast_to(closed[:, None], A.shape), rtol=1e-9)
    printed = {"product": [0.12915, 0.02269, 0.00019], "beer_sum": [0.03185, 0.00785, 0.00012]}[form]
    np.testing.assert_allclose(A[:, 0], printed, rtol=0, atol=0.5e-5)


# ----------------------------------------------------------------------------------------
# energy


FURNACE = {
    "default_film": dict(),
    "thick_high_index": dict(thickness=4000.0, eta1=2.5),
    "eta2_below_eta0_tir": dict(eta0=1.33, eta2=1.0),
}


def test_white_furnace_specular_plus_albedo_is_one():
    """kd = 1, sigma_a = 0: R(mu) + A_d(mu) = 1 at every angle and wavelength (Q-S6), for films
    with and without a TIR kink in the underside reflectance, both underside conventions."""
    mu = [1.0, 0.8, 0.5, 0.2, 0.05, 0.01, 1e-4]
    for underside, form in (("top", "product"), ("airy", "beer_sum")):  # sigma_a = 0: the form is moot
        for name, kw in FURNACE.items():
            e = dict(kw)
            if underside == "airy" and name == "eta2_below_eta0_tir":
                e = dict(eta0=1.0, eta2=1.5)  # TIR from below
            p = snake.Params(kd=1.0, sigma_a=0.0, underside=underside, absorption=form, **e)
            _, R, A = _all(p, mu, mu)
            np.testing.assert_allclose(np.asarray(R + A), 1.0, rtol=0, atol=1e-12, err_msg=f"{underside} {name}")


def test_white_furnace_harness():
    """The property harness: A <= 1 with a film (lossy: the mirror lobe carries R), and A == 1
    for the film-less white case (f = 1/pi)."""
    model = snake.MODEL
    kw = dict(key=2, n_wi=2, n_samples=2**12, n_theta=32, n_phi=4)  # eval on 256 pairs, as above
    testing.assert_white_furnace(model, snake.Params(kd=_b(1.0), sigma_a=_b(0.0), eta1=2.0), **kw)
    white = snake.Params(thickness=0.0, eta1=1.0, kd=_b(1.0), sigma_a=_b(0.0))
    testing.assert_white_furnace(model, white, lossless=True, **kw)


# ----------------------------------------------------------------------------------------
# Nyström against the random walk

MU_I = np.array([1.0, 0.75, 0.45, 0.2])
MU_O = np.array([0.9, 0.3, 0.6, 0.85])
MC = {
    # (static configuration, [parameter sets sharing it])
    "product": (dict(absorption="product"), [dict(), dict(kd=0.9, sigma_a=0.05, eta1=2.5)]),
    "beer_sum_airy_roulette": (dict(absorption="beer_sum", underside="airy"),
                               [dict(kd=0.9, sigma_a=0.05, eta1=2.5), dict(kd=0.9, sigma_a=0.02, eta2=1.5)]),
}


@pytest.mark.parametrize("name", list(MC))
def test_nystrom_matches_random_walk(name):
    """eval (Nyström) within 3 standard errors of eval_mc (fixed key, 2e4 paths), including
    strong inter-reflection (kd = 0.9, sigma_a small, eta_1 = 2.5) and the Airy underside
    with TIR (eta_2 = 1.5), with the underside reflection as a weight and by roulette."""
    static, cases = MC[name]
    roulette = "roulette" in name
    wi, wo = _dirs(MU_I), _dirs(MU_O, 1.3)
    for kw in cases:
        p = snake.Params(**static, **kw)
        f = _all(p, MU_I, MU_O, 1.3)[0]
        est, se = (np.asarray(x) for x in snake.eval_mc(p, wi, wo, jax.random.key(11), n_paths=20_000,
                                                        max_bounces=32, roulette=roulette))
        # exits beyond the critical angle of the Airy underside (eta_2 > eta_0): T(mu_o) = 0, so
        # both estimators are 0 there (up to rounding); elsewhere compare in standard errors
        dark = f < 1e-12 * f.max()
        assert np.all(np.abs(est[dark]) < 1e-12 * f.max()), (est, f)
        assert np.all(se[~dark] > 0) and np.all(se[~dark] < 0.01 * f[~dark]), (se, f)
        z = np.abs(est[~dark] - f[~dark]) / se[~dark]
        assert np.all(z < 3.0), f"{name} {kw}: z = {z}"
        if kw is cases[0]:  # same key => same numbers
            est2, _ = snake.eval_mc(p, wi, wo, jax.random.key(11), n_paths=20_000, max_bounces=32,
                                    roulette=roulette)
            np.testing.assert_array_equal(np.asarray(est2), est)


# ----------------------------------------------------------------------------------------
# symmetry, limits


def _pairs(n=256):
    """Uniform direction pairs over the upper hemisphere (shape (n,), fixed keys)."""
    return testing.random_directions(jax.random.key(1), n), testing.random_directions(jax.random.key(2), n)


@pytest.mark.parametrize("form", ["product", "beer_sum"])
def test_reciprocity(form):
    p = snake.Params(absorption=form, kd=(0.9, 0.5, 0.2), sigma_a=(0.05, 0.3, 0.7), eta1=2.0, eta2=1.3)
    wi, wo = _pairs()
    r = testing.assert_reciprocity(snake.MODEL, p, wi=wi, wo=wo)
    assert r.max_value > 0.01
    a, b = snake.eval(p, wi, wo), snake.eval(p, wo, wi)
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12, atol=1e-16)


def test_kd_zero_is_the_bare_film():
    """Q-S5: kd = 0 => f_1 = 0, so f_d = 0 exactly and the BSDF is R(mu) delta_mirror."""
    mu_i, mu_o = np.linspace(0.05, 1.0, 8), np.linspace(1.0, 0.1, 8)
    p = snake.PRESETS["fig_3_6d"]
    assert float(p.kd) == 0.0
    f, R, A = _all(p, mu_i, mu_o)
    assert np.all(f == 0) and np.all(A == 0)
    np.testing.assert_allclose(R, _airy_R(mu_i), rtol=1e-12)


def test_zero_thickness_is_bare_fresnel_and_no_film_is_lambert():
    mu_i, mu_o = np.linspace(0.05, 1.0, 8), np.linspace(1.0, 0.1, 8)
    # delta_0 = 0, eta_2 != eta_0: the film is the bare eta_0 | eta_2 interface
    p = snake.Params(thickness=0.0, eta0=1.0, eta1=1.56, eta2=1.5, kd=1.0, sigma_a=0.0)
    f, R, A = _all(p, mu_i, mu_o)
    F = np.asarray(fresnel_dielectric(jnp.asarray(mu_i), 1.5)[0])
    np.testing.assert_allclose(R, np.broadcast_to(F[:, None], R.shape), rtol=1e-10, atol=1e-15)
    np.testing.assert_allclose(R + A, 1.0, atol=1e-12)
    # no film and sigma_a = 0: Lambert kd / pi (the Fig. 3.6(a) preset)
    f, R, A = _all(snake.PRESETS["fig_3_6a_diffuse"], mu_i, mu_o)
    np.testing.assert_allclose(f, 0.3 / math.pi, rtol=1e-12)
    np.testing.assert_allclose(A, 0.3, rtol=1e-12)


def _functional(p, z, zo, c):
    """A fixed linear functional of (f_d, R, A_d) at in-plane directions with cosines z, zo."""
    zero = jnp.zeros_like(z)
    wi = Vec3(jnp.sqrt(jnp.maximum(1 - z * z, 0.0)), zero, z)
    wo = Vec3(zero, jnp.sqrt(jnp.maximum(1 - zo * zo, 0.0)), zo)
    f, R, A = snake.components.kernel(p, wi, wo)
    return jnp.sum(c[0] * f) + jnp.sum(c[1] * R) + jnp.sum(c[2] * A)


# one compiled program for value and gradients (w.r.t. the parameters and both cosines)
_value_and_grad = jax.jit(jax.value_and_grad(_functional, argnums=(0, 1, 2)))
C = jax.random.uniform(jax.random.key(6), (3, 8, 3), jnp.float64)


def test_below_horizon_and_grazing_are_zero_with_finite_gradients():
    z = np.array([0.0, -0.4, 0.5, 1e-300, 0.5, 0.5, -0.2, 1e-9])
    zo = np.array([0.5, 0.5, 0.0, 0.5, -0.1, 1e-300, 0.0, 0.5])
    masked = [0, 1, 2, 4, 6]
    for sigma_a in (0.7, 0.0):  # sigma_a = 0: f_1 does not vanish at grazing by itself
        f, R, A = _all(snake.Params(sigma_a=sigma_a), z, zo)
        assert np.all(f[masked] == 0) and np.all(np.isfinite(f))
        assert np.all(R[[0, 1, 6]] == 0) and np.all(A[[0, 1, 6]] == 0)
        p = snake.Params(kd=_b(0.3), sigma_a=_b(sigma_a))  # band-valued: the program of the gradient test
        _, (gp, gz, gzo) = _value_and_grad(p, jnp.asarray(z), jnp.asarray(zo), C)
        for g in jax.tree_util.tree_leaves((gp, gz, gzo)):
            assert np.all(np.isfinite(np.asarray(g)))
        assert np.all(np.asarray(gz)[[0, 1, 6]] == 0) and np.all(np.asarray(gzo)[masked] == 0)


# ----------------------------------------------------------------------------------------
# gradients, sampling


def test_gradients_vs_finite_differences():
    """jax.grad of a fixed functional of (f_d, R, A_d) w.r.t. every parameter element
    (thickness, the three indices, sigma_a and kd per band, depth) against central
    differences (h = 1e-5 max(|x|, 1)) in float64; then eta_0 and eta_2 at eta_0 = eta_2,
    where a TIR kink (and its panel edge) appears on one side: the rule is continuous there."""
    z, zo = jnp.asarray(np.r_[MU_I, MU_O]), jnp.asarray(np.r_[MU_O, MU_I])

    def check(p, names, rtol):
        r = testing.assert_gradients(lambda q: _value_and_grad(q, z, zo, C)[0], p, fields=names, rtol=rtol,
                                     atol=1e-9, elementwise=True, grad_fn=lambda q: _value_and_grad(q, z, zo, C)[1][0],
                                     name="snake")
        return sum(np.size(ad) for ad in r.ad)  # elements checked

    p = snake.Params(thickness=700.0, eta1=1.7, eta2=1.2, kd=(0.8, 0.5, 0.3), sigma_a=(0.1, 0.3, 0.5), depth=1.5)
    assert check(p, p._data_fields, 1e-6) == 11
    p = snake.Params(thickness=700.0, eta0=1.0, eta1=1.7, eta2=1.0, kd=_b(0.6), sigma_a=_b(0.2))
    check(p, ("eta0", "eta2"), 1e-5)


def test_vmap_and_spatially_varying_parameters():
    """vmap over a parameter, and parameters with a leading axis matching the directions,
    give the per-parameter results."""
    mu_i, mu_o = np.linspace(0.1, 1.0, 8), np.linspace(0.9, 0.2, 8)
    wi, wo = _dirs(mu_i), _dirs(mu_o, 0.5)
    ts = jnp.array([0.0, 350.0, 1200.0])
    p = snake.Params()
    f = jax.jit(jax.vmap(lambda t: snake.components.kernel(p.replace(thickness=t), wi, wo)[0]))(ts)
    ref = np.stack([_all(p.replace(thickness=t), mu_i, mu_o, 0.5)[0] for t in np.asarray(ts)])
    np.testing.assert_allclose(np.asarray(f), ref, rtol=1e-12, atol=1e-16)
    # a thickness per direction pair: the Nyström solve is batched over it
    t8 = jnp.asarray(np.r_[np.asarray(ts), np.full(5, 900.0)])
    g = np.asarray(snake.eval(p.replace(thickness=t8), wi, wo))
    np.testing.assert_allclose(g[:3], ref[np.arange(3), np.arange(3)], rtol=1e-12, atol=1e-16)


def test_sampling_and_chi2():
    """The harness on the non-delta part (cosine sampling): weight == f cos / pdf, importance
    vs uniform estimates, chi-square. Shapes chosen to share compiled programs."""
    p = snake.Params(kd=_b(0.9), sigma_a=_b(0.1), eta1=2.0)
    testing.assert_sampling(snake.MODEL, p, key=3, n_wi=2, n_samples=2**12, n_uniform=2**12)
    testing.assert_chi2(snake.MODEL, p, key=4, n_wi=2, n_samples=2**12, res_theta=8, res_phi=16)


def test_sample_full_mixes_delta_and_diffuse():
    """sample_full: mean weight = R + A_d (the whole albedo), mirror chosen with P = R/(R + A_d)."""
    p = snake.Params(kd=0.9, sigma_a=0.1, eta1=2.0)
    n = 2**15
    wi = _dirs(jnp.full(n, 0.6), 0.7)
    wo, w, is_delta = snake.sample_full(p, wi, jax.random.key(5))
    w, is_delta = np.asarray(w), np.asarray(is_delta)
    _, R, A = _all(p, 0.6, 0.6)
    R, A = R[0], A[0]
    se = w.std(0) / math.sqrt(n)
    assert np.all(np.abs(w.mean(0) - (R + A)) < 4 * se + 1e-12)
    P = R.mean() / (R.mean() + A.mean())
    assert abs(is_delta.mean() - P) < 4 * math.sqrt(P * (1 - P) / n)
    np.testing.assert_allclose(np.asarray(wo.z)[is_delta], 0.6, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(wo.x)[is_delta], -np.asarray(wi.x)[is_delta], rtol=1e-12)


# ----------------------------------------------------------------------------------------
# parameters, colour, convergence


def test_bad_inputs_raise():
    wi = _dirs(jnp.array([0.5]))
    with pytest.raises(ValueError, match=r"kd = 1\.5 .*\[0, 1\]"):
        snake.eval(snake.Params(kd=1.5), wi, wi)
    with pytest.raises(ValueError, match="absorption"):
        snake.Params(absorption="sum")
    with pytest.raises(ValueError, match="underside"):
        snake.Params(underside="bottom")
    with pytest.raises(ValueError, match="n_nodes"):
        snake.Params(n_nodes=1)
    with pytest.raises(ValueError, match="wavelengths"):
        snake.Params(color="spectral", wavelengths=(400.0, -1.0))
    with pytest.raises(ValueError, match=r"kd has 3 values.*81"):
        snake.eval(snake.Params(color="cie", kd=(0.1, 0.2, 0.3)), wi, wi)
    with pytest.raises(ValueError, match="n_paths"):
        snake.eval_mc(snake.Params(), wi, wi, jax.random.key(0), n_paths=0)
    with pytest.raises(ValueError, match="max_bounces"):
        snake.eval_mc(snake.Params(), wi, wi, 0, max_bounces=2.5)


def test_colour_modes():
    mu_i, mu_o = [0.5, 0.9], [0.7, 0.2]
    p = snake.Params(color="spectral", wavelengths=(400, 500), kd=(0.2, 0.6))
    f, R, A = _all(p, mu_i, mu_o)
    assert f.shape == R.shape == A.shape == (2, 2)
    np.testing.assert_allclose(R, _airy_R(mu_i, np.array([400.0, 500.0])), rtol=1e-13)
    assert np.all(f > 0) and np.all(A > 0)
    # cie: 3 sRGB bands; the film-less white diffuser is (1, 1, 1) / pi, its albedo (1, 1, 1)
    white = snake.Params(color="cie", thickness=0.0, eta1=1.0, kd=1.0, sigma_a=0.0)
    f, R, A = _all(white, mu_i, mu_o)
    assert f.shape == (2, 3)
    np.testing.assert_allclose(f * math.pi, 1.0, atol=1e-3)
    np.testing.assert_allclose(A, 1.0, atol=1e-3)


def test_default_nodes_converged():
    """Default n_nodes (48) vs 256 nodes: max relative difference ~1e-11 (measured 2e-11)."""
    wi, wo = _pairs()
    a = np.asarray(snake.eval(snake.Params(), wi, wo))
    b = np.asarray(snake.eval(snake.Params(n_nodes=256), wi, wo))
    assert np.max(np.abs(a - b)) / np.max(np.abs(b)) < 1e-10


def test_presets_and_registry_record():
    P = snake.PRESETS
    assert float(P["table_3_1"].eta1) == 1.53 and float(P["fig_3_5"].eta1) == 1.56
    for name in ("table_3_1", "fig_3_5", "fig_3_6d"):
        assert float(P[name].sigma_a) * float(P[name].depth) == pytest.approx(1.4)
        assert float(P[name].kd) == 0.0  # Q-S5
    assert snake.MODEL.name == "snake" and snake.MODEL.kind == "bsdf" and snake.MODEL.reciprocal
    assert snake.Params().n_nodes == 48
