"""Iridescent microfacet BRDF: limits against rough_conductor, the Airy reference table,
colour modes, periodicity, the property harness, gradients, edge cases and validation.

Compilation dominates the run time (the complex Airy film in float64), so most tests share
one parameter-tree structure (``_p``) and one direction set (WI, WO) and hence one set of
compiled kernels."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import testing
from appearance_jax.bsdf import iridescent as ir
from appearance_jax.bsdf import rough_conductor as rc
from appearance_jax.core import spectral
from appearance_jax.core.frame import spherical_direction
from appearance_jax.core.vec import Vec3, dot, normalize
from appearance_jax.optics.thinfilm import airy, film_period_nm

N = 1500


def _upper(seed, n=N):
    v = np.random.default_rng(seed).standard_normal((3, n))
    v /= np.linalg.norm(v, axis=0)
    return Vec3(jnp.asarray(v[0]), jnp.asarray(v[1]), jnp.asarray(np.abs(v[2])))


WI, WO = _upper(0), _upper(1)
COS_H = dot(WI, normalize(WI + WO))  # the facet angle of each pair
# The shared setting: Beckmann, anisotropic, separable Smith, 3 reflectance bands, rgb3.
MICRO = dict(alpha=0.15, alpha_v=0.5, distribution="beckmann", shadowing="separable")
SPEC = (1.0, 0.7, 0.4)


def _p(**kw):
    return ir.Params(**{**MICRO, "specular_reflectance": SPEC, **kw})


def _rc(eta, k):
    return rc.Params(eta=(eta,) * 3, k=(k,) * 3, **{**MICRO, "specular_reflectance": SPEC})


MIRROR = _rc(0.0, 1.0)  # relative index i: F = 1 (a lossless mirror), the bare microfacet term


def _close(a, b, rtol=1e-10, atol=1e-13):
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=rtol, atol=atol)


@jax.jit
def _film_times_mirror(wl, thickness, eta0, eta1, eta2):
    """The expected f per wavelength: airy R at the facet angle times the F = 1 microfacet term."""
    R = airy(COS_H[:, None], wl, thickness, eta0, eta1, eta2).R
    return R, R * rc.eval.kernel(MIRROR, WI, WO)[:, :1]


# ----------------------------------------------------------------------------------
# limits: the film disappears -> rough_conductor (the whole microfacet pipeline)


@pytest.mark.parametrize("sub", [(1.0, 1.5, 0.0), (1.0, 0.2, 3.5), (1.33, 1.0, 0.0), (1.2, 1.1, 2.0)],
                         ids=["dielectric", "conductor", "tir_under_water", "conductor_in_oil"])
def test_zero_thickness_is_rough_conductor(sub):
    """d = 0: R = Fresnel of eta_outside | eta_substrate + i k: eval, pdf and sample equal
    rough_conductor with the relative index (eta + i k) / eta_outside."""
    eta0, eta, k = sub
    p = _p(thickness=0.0, eta_film=1.8, eta_substrate=eta, k_substrate=k, eta_outside=eta0)
    q = _rc(eta / eta0, k / eta0)
    f = ir.eval(p, WI, WO)
    assert f.shape == (N, 3) and float(jnp.max(f)) > 0
    _close(f, rc.eval(q, WI, WO))
    _close(ir.pdf(p, WI, WO), rc.pdf(q, WI, WO))
    key = jax.random.PRNGKey(3)
    for a, b in zip(jax.tree_util.tree_leaves(ir.sample(p, WI, key)), jax.tree_util.tree_leaves(rc.sample(q, WI, key))):
        _close(a, b)


@pytest.mark.parametrize("sub", [(1.5, 0.0), (0.3, 2.5)], ids=["dielectric", "conductor"])
def test_index_matched_film_is_independent_of_thickness(sub):
    """eta_film == eta_outside: r_01 = 0, so R = |r_12|^2 for every thickness."""
    kw = dict(eta_film=1.2, eta_outside=1.2, eta_substrate=sub[0], k_substrate=sub[1])
    ref = ir.eval(_p(thickness=0.0, **kw), WI, WO)
    for d in (137.0, 900.0, 4321.0):
        _close(ir.eval(_p(thickness=d, **kw), WI, WO), ref)


def test_lossless_film_on_perfect_mirror_reflects_everything():
    """A real film over a lossless mirror (substrate index i: |r_12| = 1) reflects R = 1 at
    every thickness, wavelength and angle: f is the bare microfacet term (F = 1)."""
    for d, eta1 in ((733.0, 1.7), (2100.0, 1.1)):
        _close(ir.eval(_p(thickness=d, eta_film=eta1, eta_substrate=0.0, k_substrate=1.0), WI, WO),
               rc.eval(MIRROR, WI, WO))


# ----------------------------------------------------------------------------------
# the film at the facet angle; the thesis' reference table


def test_normal_incidence_reference_table():
    """wi = wo = n: G2 = 1, D(n) = 1/(pi ax ay) (GGX and Beckmann), so f = s R(lambda, 1) / (4 pi ax ay).
    R: spec M10 table, air | 1.56 | air, 900 nm, theta = 0 (650 / 510 / 475 nm)."""
    table = np.array([0.1308, 0.1743, 0.0156])
    n = Vec3(jnp.zeros(N), jnp.zeros(N), jnp.ones(N))
    f = np.asarray(ir.eval(_p(thickness=900.0, eta_film=1.56), n, n))[0]
    np.testing.assert_allclose(f * 4 * math.pi * 0.15 * 0.5 / np.array(SPEC), table, atol=6e-5)
    # the GGX snake preset of Fig. 3.6(c) has the same film
    snake = ir.PRESETS["snake_fig_3_6c"]
    assert snake.distribution == "ggx"
    f = np.asarray(ir.eval(snake, Vec3(0.0, 0.0, 1.0), Vec3(0.0, 0.0, 1.0)))
    np.testing.assert_allclose(f * 4 * math.pi * 0.1**2, table, atol=6e-5)


def test_film_at_the_facet_angle_and_spectral_mode():
    """f = s R(lambda, wi.h) x (the microfacet term with F = 1), R from optics.thinfilm.airy,
    one band per wavelength; rgb3 == spectral at 650 / 510 / 475 nm."""
    wl = (650.0, 510.0, 475.0, 420.0, 700.5)
    kw = dict(thickness=640.0, eta_film=1.45, eta_substrate=1.9, k_substrate=0.4, eta_outside=1.1)
    p = _p(**kw, color="spectral", wavelengths=list(wl), specular_reflectance=1.0)
    assert p.wavelengths == wl  # normalised to a tuple of floats
    f = ir.eval(p, WI, WO)
    assert f.shape == (N, 5)
    R, ref = _film_times_mirror(jnp.asarray(wl), 640.0, 1.1, 1.45, 1.9 + 0.4j)
    _close(f, ref)
    assert float(jnp.std(R[:, 1])) > 0.02  # the colour varies over the pairs: the facet angle matters
    _close(ir.eval(_p(**kw), WI, WO), f[:, :3] * np.array(SPEC), rtol=1e-12, atol=0)


@jax.jit
def _cie_reference(thickness, eta1):
    """White-balanced linear sRGB (D65) of the 81-wavelength spectrum, clipped at 0, and the
    unbalanced colour of a white spectrum (the balance: ~1 within 3e-4)."""
    grid = spectral.band_wavelengths("cie")
    spec = _film_times_mirror(grid, thickness, 1.0, eta1, 1.0)[1]
    white = spectral.spectrum_to_linear_srgb(jnp.ones(81), grid, "D65")
    return jnp.maximum(spectral.spectrum_to_linear_srgb(spec, grid, "D65") / white, 0.0), white


def test_cie_mode():
    """cie = white-balanced linear sRGB (D65) of the spectrum on the 380-780/5 nm grid, clipped
    at 0; a wavelength-independent reflectance (d = 0, no dispersion) maps to R x (1, 1, 1)."""
    assert spectral.band_wavelengths("cie").shape == (81,)
    f = np.asarray(ir.eval(_p(thickness=380.0, eta_film=1.6, color="cie"), WI, WO))
    assert f.shape == (N, 3)
    ref, white = (np.asarray(a) for a in _cie_reference(380.0, 1.6))
    _close(f, ref * np.array(SPEC), rtol=1e-12, atol=1e-15)
    # a 380 nm film is coloured: the channels differ markedly (and some are clipped at 0)
    big = f.max(axis=1) > 1e-6
    assert np.max(np.abs(f[big, 0] - f[big, 2]) / f[big].max(axis=1)) > 0.3
    assert np.mean(f == 0) > 0.01
    np.testing.assert_allclose(white, 1.0, atol=1e-3)
    for kw in (dict(thickness=0.0, eta_substrate=1.7, k_substrate=0.6), dict(thickness=380.0, eta_film=1.0)):
        grey = np.asarray(ir.eval(_p(**kw), WI, WO)) / np.array(SPEC)
        assert np.max(np.abs(grey[:, 0] - grey[:, 2])) < 1e-14
        _close(ir.eval(_p(**kw, color="cie"), WI, WO), grey * np.array(SPEC), rtol=1e-12, atol=1e-15)


def test_thickness_period_at_the_facet_angle():
    """R is periodic in d with period lambda / (2 eta_1 cos theta_1) at the facet angle wi.h
    of the pair (510 nm: the G band)."""
    kw = dict(eta_film=1.56, eta_substrate=1.2, k_substrate=1.5)
    a = ir.eval(_p(thickness=300.0, **kw), WI, WO)[:, 1]
    for j in (0, 1, int(jnp.argmin(COS_H))):
        period = float(film_period_nm(COS_H[j], 510.0, 1.0, 1.56))
        assert period > 510.0 / (2 * 1.56) - 1e-9
        b = ir.eval(_p(thickness=300.0 + period, **kw), WI, WO)[:, 1]
        c = ir.eval(_p(thickness=300.0 + 0.5 * period, **kw), WI, WO)[:, 1]
        _close(a[j], b[j], rtol=1e-9)
        assert abs(float(a[j] - c[j])) > 0.02 * float(a[j] + c[j])  # not trivially constant


# ----------------------------------------------------------------------------------
# property harness

HARNESS = _p(thickness=350.0, eta_film=1.4, eta_substrate=0.3, k_substrate=3.0)  # a film on a conductor


# n_wi x n_samples is the same in the three sampling checks: one compiled sampler
def test_reciprocity_and_white_furnace():
    testing.assert_reciprocity(ir.MODEL, HARNESS, wi=WI, wo=WO)
    testing.assert_white_furnace(ir.MODEL, HARNESS, key=2, n_wi=2, n_samples=2**14, n_theta=96, n_phi=192)


def test_sampling_and_chi2():
    testing.assert_sampling(ir.MODEL, HARNESS, key=3, n_wi=2, n_samples=2**14)
    testing.assert_chi2(ir.MODEL, HARNESS, key=4, n_wi=2, n_samples=2**14)


# ----------------------------------------------------------------------------------
# gradients and edge cases (one compiled function for both)


def _vec(a):
    return Vec3(a[0], a[1], a[2])


def test_gradients_and_below_horizon():
    """Pairs not both strictly above the surface give exactly 0 (eval, pdf, sample) with finite
    gradients, also where eta_film == eta_outside (q_1 = 0 at grazing: the film's singular
    point); on random pairs, d/d(every parameter) of eval + pdf matches central finite
    differences."""
    edge = np.array([[0.0, 0.0, 1.0], [0.6, 0.8, 0.0], [0.6, 0.0, -0.8], [0.0, 0.0, -1.0], [-0.6, -0.8, 0.0]]).T
    wi_r, wo_r = _upper(5, 24), _upper(6, 24)
    # 50 edge pairs (all ordered pairs of the 5 directions, twice), then 24 random pairs
    W = np.concatenate([np.tile(np.repeat(edge, 5, axis=1), 2), np.stack(list(_upper(5, 24)))], axis=1)
    O = np.concatenate([np.tile(np.tile(edge, 5), 2), np.stack(list(_upper(6, 24)))], axis=1)
    eta_film = np.repeat([1.5, 1.05, 1.45], [25, 25, 24])
    p = ir.Params(alpha=0.25, alpha_v=0.4, thickness=610.0, eta_film=eta_film, eta_substrate=1.3, k_substrate=0.7,
                  eta_outside=1.05, specular_reflectance=(0.9, 0.8, 0.7))
    u = (np.linspace(0.05, 0.95, 74), np.linspace(0.9, 0.1, 74))
    rng = np.random.default_rng(7)
    c = rng.uniform(size=(74, 3))

    @jax.jit
    def total(p, wi, wo):
        f = ir.eval.kernel(p, _vec(wi), _vec(wo))
        pdf = ir.pdf.kernel(p, _vec(wi), _vec(wo))
        return jnp.sum(c * f) + 0.1 * jnp.sum(pdf), (f, pdf)

    W, O = jnp.asarray(W), jnp.asarray(O)
    grads, (f, pdf) = jax.jit(jax.grad(total, argnums=(0, 1, 2), has_aux=True))(p, W, O)
    grads, f, pdf = jax.tree_util.tree_map(np.asarray, (grads, f, pdf))
    for g in jax.tree_util.tree_leaves(grads):
        assert np.all(np.isfinite(g))
    masked = np.asarray((W[2] <= 0) | (O[2] <= 0))
    assert masked[:50].sum() == 2 * 24 and not np.any(masked[50:])
    assert np.all(f[masked] == 0) and np.all(pdf[masked] == 0) and np.all(f[~masked] > 0)
    _, w, pdf_s = (np.asarray(a) for a in ir.sample(p, _vec(W), u))  # its film factor is eval's (above)
    below = np.asarray(W[2] <= 0)
    assert np.all(w[below] == 0) and np.all(pdf_s[below] == 0)
    assert np.all(np.isfinite(w)) and np.mean(pdf_s[50:] > 0) > 0.5

    # every element of every field (eta_film, 74 elements: 4 random directions), the gradient above
    r = testing.assert_gradients(lambda q: total(q, W, O)[0], p, rtol=2e-6, grad_fn=lambda q: grads[0],
                                 name="iridescent")
    assert len(r.leaves) == 8 and all(np.max(np.abs(ad)) > 1e-3 for ad in r.ad), r.message


# ----------------------------------------------------------------------------------
# validation, the record


@pytest.mark.parametrize(
    "kw,field,rng",
    [(dict(thickness=-1.0), "thickness", "[0, 5000]"), (dict(thickness=6000.0), "thickness", "[0, 5000]"),
     (dict(eta_film=0.5), "eta_film", "[1, 3]"), (dict(eta_outside=0.9), "eta_outside", "[1, 3]"),
     (dict(k_substrate=-0.1), "k_substrate", "[0, 50]"), (dict(eta_substrate=float("nan")), "eta_substrate", ""),
     (dict(alpha=0.0), "alpha", "[0.001, 2]"), (dict(specular_reflectance=(1.0, 1.5, 1.0)), "specular_reflectance", ""),
     (dict(eta_substrate=0.0, k_substrate=0.0), "eta_substrate", "k_substrate")],
)
def test_invalid_params_raise(kw, field, rng):
    wi = spherical_direction(0.3, 0.0)
    with pytest.raises(ValueError, match=rf"Params\.{field}") as e:
        ir.eval(ir.Params(**kw), wi, wi)
    assert rng in str(e.value)


def test_invalid_static_fields():
    with pytest.raises(ValueError, match=r"Params\.color.*'xyz'"):
        ir.Params(color="xyz")
    with pytest.raises(ValueError, match=r"Params\.wavelengths"):
        ir.Params(color="spectral", wavelengths=(500.0, -3.0))
    with pytest.raises(ValueError, match="distribution"):
        ir.Params(distribution="phong")


def test_model_record_and_presets():
    m = ir.MODEL
    assert m.name == "iridescent" and m.kind == "bsdf" and m.reciprocal and not m.transmissive
    assert m.Params is ir.Params and m.pdf is ir.pdf and m.sample is ir.sample
    assert set(m.presets) == {"soap_film", "keratin_on_melanin", "snake_fig_3_6c"}
    wi = spherical_direction(0.4, 0.1)
    wo = spherical_direction(0.45, 0.1 + math.pi)
    for name, p in m.presets.items():
        f = np.asarray(ir.eval(p, wi, wo))
        assert f.shape == (3,) and np.all(np.isfinite(f)) and np.all(f > 0), name
