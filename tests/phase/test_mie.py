"""Lorenz–Mie (phase/mie_series.py, phase/mie.py) against references it did not write:

- the same Bohren–Huffman series evaluated in 40-digit arithmetic (mpmath), which checks the
  recurrences' rounding, truncation and start values independently of any other program;
- miepython 3.3 (``norm="wiscombe"``; it uses m = n - ik and returns conj(S) for real m);
- closed forms: the Rayleigh limit, Q_ext = Q_sca for real m, Q_back = 4 |S1(pi)|^2 / x^2,
  the normalisation of the phase function, extinction paradox Q_ext -> 2;
- the spec's verified rainbow numbers (seed-002 §3.2 C6, C13).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.phase import mie
from appearance_jax.phase import mie_series as S


def _mp_coefficients(m, x, terms, dps=40):
    """a_n, b_n by the textbook recurrences in ``dps``-digit arithmetic (test-only oracle)."""
    mp = pytest.importorskip("mpmath")
    with mp.workdps(dps):
        m, x = mp.mpc(m), mp.mpf(x)
        mx = m * x
        N = int(abs(mx) + 4 * abs(mx) ** (1 / 3.0) + 40)
        D = [mp.mpc(0)] * (N + 1)
        for n in range(N, 0, -1):
            D[n - 1] = n / mx - 1 / (D[n] + n / mx)
        psi_p, psi, chi_p, chi = mp.cos(x), mp.sin(x), -mp.sin(x), mp.cos(x)
        a, b = [], []
        for n in range(1, terms + 1):
            psi_n = (2 * n - 1) / x * psi - psi_p  # exact enough at 40 digits
            chi_n = (2 * n - 1) / x * chi - chi_p
            xi_n, xi_p = psi_n - 1j * chi_n, psi - 1j * chi
            da, db = D[n] / m + n / x, m * D[n] + n / x
            a.append(complex((da * psi_n - psi) / (da * xi_n - xi_p)))
            b.append(complex((db * psi_n - psi) / (db * xi_n - xi_p)))
            psi_p, psi, chi_p, chi = psi, psi_n, chi, chi_n
    return np.array(a), np.array(b)


# x = 4 pi and 16 pi: psi_0 = sin x = 0, where a psi from the ratio psi_{n-1}/psi_n alone was
# wrong by O(1) and its gradient by 1e14 (found with round radii: 1.2 um at 600 nm)
@pytest.mark.parametrize("m,x", [(1.333, 1000.0), (1.333, 4000.0), (1.5 + 0.1j, 60.0), (1.33, 0.05),
                                 (1.45 + 0.01j, 4 * math.pi), (1.5 + 0.001j, 16 * math.pi)])
def test_coefficients_match_40_digit_series(m, x):
    terms = S.series_length(x)
    a_ref, b_ref = _mp_coefficients(m, x, terms)
    a, b = (np.asarray(v) for v in S.coefficients(m, x, terms))
    scale = np.maximum(np.abs(a_ref), 1e-300)
    # relative per coefficient, so the tiny Rayleigh-limit coefficients at x = 0.05 count too
    # ; at x = 4000 the worst, ~1e-10, are
    # orders near zeros of psi_n, where any double-precision psi_n has that relative error
    assert np.max(np.abs(a - a_ref) / scale) < 1e-9
    assert np.max(np.abs(b - b_ref) / np.maximum(np.abs(b_ref), 1e-300)) < 1e-9


def test_last_term_is_kept():
    # the Wiscombe length is a ceiling: dropping order ceil(x + 4 x^(1/3) + 2) cost 2e-6
    # relative in S1 near backscatter at x = 4000 (a bug caught by the 40-digit series)
    x = 4000.0
    terms = S.series_length(x)
    a, _ = S.coefficients(1.333, x, terms)
    assert abs(complex(a[terms - 1])) > 0


def _miepython():
    mp = pytest.importorskip("miepython")
    return mp


# x = 4000 is slow-only (miepython's own evaluation of 4066 orders at 1801 angles dominates its
# ~20 s): the default run keeps x = 1000 against miepython, and x = 4000 is covered by the
# 40-digit series (test_coefficients_match_40_digit_series[1.333-4000.0]) and test_closed_forms
@pytest.mark.parametrize("m,x", [(1.333, 10.0), (1.5 + 0.1j, 100.0), (1.333, 1000.0),
                                 pytest.param(1.333, 4000.0, marks=pytest.mark.slow)])
def test_against_miepython(m, x):
    miepython = _miepython()
    m_mp = complex(m.real, -m.imag) if isinstance(m, complex) else m  # miepython: m = n - ik
    k = int(x + 4.05 * x ** 0.33333 + 2.0)  # miepython's own truncation, to compare like with like
    terms = max(S.series_length(x), k)
    a, b = S.coefficients(m, x, terms)
    a, b = a[:k], b[:k]
    theta = np.linspace(0.0, 180.0, 1801)
    mu = np.cos(np.radians(theta))
    S1, S2 = (np.asarray(v) for v in S.amplitudes(a, b, mu))
    r1, r2 = (np.conj(np.asarray(v)) for v in miepython.S1_S2(m_mp, x, mu, norm="wiscombe"))
    for got, ref in ((S1, r1), (S2, r2)):
        rel = np.abs(got - ref) / np.abs(ref)
        # <= 1e-8 at 99 % of the angles; the few others sit in deep interference minima
        # where either program's rounding shows (the 40-digit test above settles ours)
        assert np.percentile(rel, 99) < 1e-8, (x, np.percentile(rel, 99))
        assert rel.max() < 1e-7
    q = S.efficiencies(a, b, x)
    q_ref = miepython.efficiencies_mx(m_mp, x)
    for name, got, ref in zip(("q_ext", "q_sca", "q_back", "g"), q, q_ref):
        assert abs(float(got) - ref) <= 1e-8 * abs(ref), (name, float(got), ref)


def test_dn_start_above_mx():
    # Q_ext(m = 1.333, x = 1000) = 2.02281; a D_n recurrence started at max(n_max, |mx|) + 15
    # (the spec recipe) gives 2.01960 (issue 23)
    terms = S.series_length(1000.0)
    assert S.dn_start(terms) >= 1.333 * 1000 + 4 * (1.333 * 1000) ** (1 / 3) + 15
    a, b = S.coefficients(1.333, 1000.0, terms)
    q_ext = float(S.efficiencies(a, b, 1000.0)[0])
    assert abs(q_ext - 2.02281) < 5e-6


def test_closed_forms():
    # real m: no absorption; Q_back from S1(180 deg); extinction paradox at large x. One series
    # length for every x (terms past series_length(x) are exact, masked): one compiled program
    # for the coefficients, amplitudes and efficiencies instead of one per x
    terms = S.series_length(4000.0)
    for x in (3.0, 50.0, 4000.0):
        a, b = S.coefficients(1.333, x, terms)
        q_ext, q_sca, q_back, g = (float(v) for v in S.efficiencies(a, b, x))
        assert abs(q_ext - q_sca) < 1e-10 * q_ext
        S1, S2 = S.amplitudes(a, b, jnp.asarray(-1.0))
        assert abs(q_back - 4 * abs(complex(S1)) ** 2 / x ** 2) < 1e-9 * q_back
        assert abs(complex(S1) + complex(S2)) < 1e-9 * abs(complex(S1))  # S2(pi) = -S1(pi)
    assert abs(q_ext - 2.0) < 0.01
    # absorbing sphere: Q_ext > Q_sca
    a, b = S.coefficients(1.5 + 0.1j, 20.0, terms)
    q_ext, q_sca, _, _ = (float(v) for v in S.efficiencies(a, b, 20.0))
    assert q_ext > q_sca * 1.05


def test_rayleigh_limit():
    x, m = 1e-3, 1.5 + 0.01j
    p = mie.Params(radius_um=x * 550.0 / (2e3 * np.pi), wavelength_nm=550.0, n_particle=1.5, k_particle=0.01)
    theta = jnp.linspace(0.0, jnp.pi, 19)
    f = np.asarray(mie.phase_function(p, jnp.cos(theta)))[:, 0]
    rayleigh = 3.0 / (16.0 * np.pi) * (1.0 + np.cos(np.asarray(theta)) ** 2)
    np.testing.assert_allclose(f, rayleigh, rtol=1e-5)
    q = mie.efficiencies(p)
    alpha = (m * m - 1) / (m * m + 2)
    assert abs(float(q.q_sca[0]) - 8.0 / 3.0 * x ** 4 * abs(alpha) ** 2) < 1e-5 * float(q.q_sca[0])
    assert abs(float(q.q_ext[0]) - 4.0 * x * alpha.imag) < 1e-3 * float(q.q_ext[0])  # absorption dominates


def test_phase_function_normalised():
    p = mie.Params(radius_um=2.0, wavelength_nm=(650.0, 450.0), n_particle=(1.331, 1.338), k_particle=(0.0, 0.01))
    mu, w = np.polynomial.legendre.leggauss(600)
    # the forward peak of width ~1/x = 0.05 rad needs nodes near mu = 1: map mu = 1 - 2 t^2
    t = 0.5 * (mu + 1.0)
    cos_t, jac = 1.0 - 2.0 * t * t, 2.0 * t  # d mu / d t = -4 t; dt = dmu_gl / 2
    f = np.asarray(mie.phase_function(p, jnp.asarray(cos_t)))
    total = 2 * np.pi * np.sum(f * (w * jac)[:, None], axis=0)
    np.testing.assert_allclose(total, 1.0, atol=1e-9)


def test_mean_cosine_is_g():
    p = mie.Params(radius_um=1.0, wavelength_nm=550.0, n_particle=1.5, k_particle=0.02)
    mu, w = np.polynomial.legendre.leggauss(800)
    f = np.asarray(mie.phase_function(p, jnp.asarray(mu)))[:, 0]
    g_quad = 2 * np.pi * np.sum(f * mu * w)
    assert abs(g_quad - float(mie.efficiencies(p).g[0])) < 1e-9


def _smooth_peak(theta_deg, intensity, lo, hi, sigma_deg=0.05):
    """Maximum of the intensity smoothed by a small Gaussian (removes the p = 0 ripple)."""
    dt = theta_deg[1] - theta_deg[0]
    k = np.arange(-int(4 * sigma_deg / dt), int(4 * sigma_deg / dt) + 1) * dt
    ker = np.exp(-0.5 * (k / sigma_deg) ** 2)
    sm = np.convolve(intensity, ker / ker.sum(), mode="same")
    sel = (theta_deg > lo) & (theta_deg < hi)
    return theta_deg[sel][np.argmax(sm[sel])], sm


@pytest.mark.parametrize("radius_mm,peak", [(0.1, 138.6), (0.2, 138.22), (0.3, 138.06), (0.4, 138.04),
                                             (0.5, 137.99), (1.0, 137.84)])
def test_rainbow_peak_c6(radius_mm, peak):
    # spec seed-002 C6 (verified against miepython there): Mie primary peak at 650 nm, n = 1.331
    p = mie.Params(radius_um=radius_mm * 1e3, wavelength_nm=650.0, n_particle=1.331)
    theta = np.arange(124.0, 146.0, 0.004)
    S1, S2 = mie.amplitudes(p, jnp.cos(jnp.radians(theta)))
    x = 2 * np.pi * radius_mm * 1e6 / 650.0
    i_perp = np.abs(np.asarray(S1)[:, 0]) ** 2 / (np.pi * x * x)
    i_par = np.abs(np.asarray(S2)[:, 0]) ** 2 / (np.pi * x * x)
    theta_peak, sm_perp = _smooth_peak(theta, i_perp, 137.0, 140.0)
    assert abs(theta_peak - peak) < 0.05, theta_peak
    # C13: both bows strongly polarised, perpendicular dominant
    _, sm_par = _smooth_peak(theta, i_par, 137.0, 140.0)
    j = np.argmin(np.abs(theta - theta_peak))
    assert (sm_perp[j] - sm_par[j]) / (sm_perp[j] + sm_par[j]) > 0.7
    sec, _ = _smooth_peak(theta, i_perp, 126.0, 130.0, sigma_deg=0.1)
    js = np.argmin(np.abs(theta - sec))
    assert (sm_perp[js] - sm_par[js]) / (sm_perp[js] + sm_par[js]) > 0.7
    # Alexander's dark band (C4): ~20x darker than the bright side of the primary
    band = (theta > 131.5) & (theta < 135.5)
    bright = (theta > 139.0) & (theta < 141.0)
    total = i_perp + i_par
    assert total[band].mean() * 10 < total[bright].mean()


def test_float32_accuracy():
    p64 = mie.Params(radius_um=4.0, wavelength_nm=500.0, n_particle=1.5, k_particle=0.001)  # x ~ 50
    mu = np.linspace(-1, 1, 301)
    ref = np.asarray(mie.phase_function(p64, jnp.asarray(mu)))
    with jax.enable_x64(False):
        p32 = mie.Params(radius_um=4.0, wavelength_nm=500.0, n_particle=1.5, k_particle=0.001)
        got = np.asarray(mie.phase_function(p32, jnp.asarray(mu, jnp.float32)))
    assert got.dtype == np.float32
    assert np.max(np.abs(got - ref) / ref) < 2e-3


def test_gradients_match_finite_differences():
    cos_t = jnp.cos(jnp.radians(jnp.array([20.0, 90.0, 150.0])))

    @jax.jit
    def f(r, n, k):
        p = mie.Params(radius_um=r, wavelength_nm=600.0, n_particle=n, k_particle=k, terms=64)
        return jnp.sum(jnp.log(mie.phase_function.kernel(p, cos_t)))

    # one program for the values and the gradient (the differences below reuse its values)
    value_and_grad = jax.jit(jax.value_and_grad(f, argnums=(0, 1, 2)))
    args = (1.2, 1.45, 0.01)
    _, grads = value_and_grad(*args)
    for i, g in enumerate(grads):
        h = 1e-6
        up = list(args); up[i] += h
        dn = list(args); dn[i] -= h
        fd = (value_and_grad(*up)[0] - value_and_grad(*dn)[0]) / (2 * h)
        assert abs(float(g) - float(fd)) < 1e-5 * max(1.0, abs(float(fd))), (i, float(g), float(fd))


def test_jit_with_traced_radius():
    p0 = mie.Params(radius_um=1.0, wavelength_nm=550.0, terms=mie.terms_for(3.0, 550.0))

    @jax.jit
    def q(r):
        return mie.efficiencies.__wrapped__(mie.Params(radius_um=r, wavelength_nm=550.0, terms=p0.terms)).q_sca

    for r in (0.5, 2.0, 3.0):
        ref = mie.efficiencies(mie.Params(radius_um=r, wavelength_nm=550.0)).q_sca
        np.testing.assert_allclose(q(r), ref, rtol=1e-12)


def test_bad_inputs():
    with pytest.raises(ValueError, match="terms = 64 is too short.*x = 1142"):
        mie.Params(radius_um=100.0, terms=64)
    with pytest.raises(ValueError, match=r"\|m\| = 10.*\(0, 6.0\]"):
        mie.Params(radius_um=1.0, n_particle=10.0)
    with pytest.raises(ValueError, match="radius_um"):
        mie.Params(radius_um=-1.0)
    with pytest.raises(ValueError, match="k_particle"):
        mie.Params(k_particle=-0.1)

    @jax.jit
    def traced(r):
        return mie.phase_function.kernel(mie.Params(radius_um=r), jnp.asarray(0.5))

    with pytest.raises(ValueError, match="terms is None"):
        traced(1.0)


def test_series_length_checks():
    assert S.series_length(1000.0) == math.ceil(1000 + 4 * 10 + 2)
    with pytest.raises(ValueError, match="x = "):
        S.series_length(0.0)
