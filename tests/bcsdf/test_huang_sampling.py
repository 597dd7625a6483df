"""Huang's importance sampler and stochastic pdf (Huang 2022, Sec. 4.3.4, Eq. 4.33; spec seed-001
§1.3.11-1.3.12, check H-14), the mirror furnace of the R lobe (H-3) and the energy beyond TRT
(H-16, against the flatland tracer).

All sampler runs share one shape (N directions, uniforms passed as arrays) so that each jitted
kernel compiles once per parameter structure."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import flatland as fl
from appearance_jax.bcsdf import fiber, huang, huang_sampling
from appearance_jax.core.frame import fiber_angles, fiber_direction
from appearance_jax.core.spectral import LUMINANCE_WEIGHTS
from appearance_jax.core.quadrature import gauss_legendre

DEG = np.pi / 180
N = 2 ** 18
THETA_I, PHI_I = 0.3, 0.4
N_TH, N_PH, N_SUB = 10, 16, 3     # equal-solid-angle bins in sin(theta_o) x phi_o; sub-nodes per axis

_sample_path = huang_sampling._sample_path_jit     # the public sampler's compiled stage


def _uniforms(seed, n_u, n=N):
    rng = np.random.default_rng(seed)
    return tuple(jnp.asarray(rng.random(n)) for _ in range(n_u))


def _wi(n=N):
    return fiber_direction(jnp.full(n, THETA_I), jnp.full(n, PHI_I))


def _bins():
    s_edges = np.linspace(-1, 1, N_TH + 1)
    p_edges = np.linspace(-np.pi, np.pi, N_PH + 1)
    return s_edges, p_edges


def _bin_index(wo):
    th, ph = (np.asarray(a) for a in fiber_angles(wo))
    s_edges, p_edges = _bins()
    it = np.clip(np.searchsorted(s_edges, np.sin(th)) - 1, 0, N_TH - 1)
    ip = np.clip(np.searchsorted(p_edges, ph) - 1, 0, N_PH - 1)
    return it * N_PH + ip


def _bin_nodes():
    """Gauss nodes inside every bin in (sin theta, phi): d omega = d(sin theta) d phi."""
    s_edges, p_edges = _bins()
    xs, ws = gauss_legendre(N_SUB)
    xs, ws = np.asarray(xs), np.asarray(ws)
    S, P, W = [], [], []
    for i in range(N_TH):
        for j in range(N_PH):
            a, b, c, d = s_edges[i], s_edges[i + 1], p_edges[j], p_edges[j + 1]
            s = 0.5 * (a + b) + 0.5 * (b - a) * xs
            p = 0.5 * (c + d) + 0.5 * (d - c) * xs
            ss, pp = np.meshgrid(s, p, indexing="ij")
            S.append(ss.ravel()), P.append(pp.ravel())
            W.append(np.outer(ws, ws).ravel() * 0.25 * (b - a) * (d - c))
    return np.arcsin(np.array(S)), np.array(P), np.array(W)   # (bins, N_SUB^2)


def _histograms(p, seed):
    wo, w, lobe, P, A, Vis, good = _sample_path(p, _wi(), _uniforms(seed, huang_sampling._n_uniforms(p)))
    w, good = np.asarray(w[:, 0]), np.asarray(good)
    assert np.all(np.isfinite(w)) and np.all(w >= 0)
    idx = _bin_index(wo)
    nb = N_TH * N_PH
    sw = np.bincount(idx, w, nb) / N
    sw_se = np.sqrt(np.maximum(np.bincount(idx, w * w, nb) / N - sw ** 2, 0) / (N - 1))
    cnt = np.bincount(idx[good], minlength=nb) / N
    cnt_se = np.sqrt(cnt * (1 - cnt) / (N - 1))
    return dict(w=w, lobe=np.asarray(lobe), good=good, sw=sw, sw_se=sw_se, cnt=cnt, cnt_se=cnt_se, P=np.asarray(P))


def _z(a, sa, b, sb, sel):
    z = (a - b)[sel] / np.hypot(sa, sb)[sel]
    return z, float(np.sum(z ** 2) / z.size)


# every sampler run has the same static settings, shapes and bands (3): one compilation
_STATIC = dict(n_intervals=32, n_paths=8)
_SIGMA = np.asarray(huang.Params.from_melanin(0.3, 0.3).sigma_a)      # ~(0.15, 0.23, 0.45) per radius
PARAMS = {
    "circle": huang.Params(roughness=0.3, tilt=3 * DEG, sigma_a=_SIGMA, **_STATIC),
    "ellipse": huang.Params(roughness=0.3, tilt=-3 * DEG, sigma_a=_SIGMA, eccentricity=0.5, **_STATIC),
}


@functools.lru_cache(maxsize=None)
def _reference(name):
    """eval and the stochastic pdf integrated over every bin (Gauss nodes)."""
    p = PARAMS[name]
    th, ph, wq = _bin_nodes()
    n = th.size
    wi = fiber_direction(jnp.full(n, THETA_I), jnp.full(n, PHI_I))
    wo = fiber_direction(jnp.asarray(th.ravel()), jnp.asarray(ph.ravel()))
    S, S_se = huang.eval(p, wi, wo, key=jax.random.PRNGKey(3))
    pdf, pdf_se = huang.pdf(p, wi, wo, key=jax.random.PRNGKey(4))
    S = np.asarray(S[:, 0]).reshape(th.shape) * np.cos(th)
    S_se = np.asarray(S_se[:, 0]).reshape(th.shape) * np.cos(th)
    pdf, pdf_se = np.asarray(pdf).reshape(th.shape), np.asarray(pdf_se).reshape(th.shape)
    assert np.all(np.isfinite(pdf)) and np.all(pdf >= 0) and np.all(np.isfinite(pdf_se))
    # the estimators use common random numbers across directions: add standard errors linearly
    return (np.sum(S * wq, 1), np.sum(S_se * wq, 1), np.sum(pdf * wq, 1), np.sum(pdf_se * wq, 1))


@pytest.mark.parametrize("name", ["circle", pytest.param("ellipse", marks=pytest.mark.slow)])
def test_h14_weighted_histogram_is_s_cos_and_unweighted_is_the_pdf(name):
    """H-14: E[weight; w_o in bin] = int_bin S cos(theta_o) dw_o (eval), the successful samples'
    frequency per bin = int_bin pdf (Eq. 4.33), and sum over bins: mean weight = albedo."""
    p = PARAMS[name]
    h = _histograms(p, 11)
    S, S_se, pdf, pdf_se = _reference(name)
    sel = h["cnt"] * N > 100
    z, chi = _z(h["sw"], h["sw_se"], S, S_se, sel)
    zp, chip = _z(h["cnt"], h["cnt_se"], pdf, pdf_se, sel)
    alb, alb_se = h["w"].mean(), h["w"].std() / np.sqrt(N)
    alb_ref, alb_ref_se = S.sum(), S_se.sum()
    print(f"{name}: weighted vs eval: {sel.sum()} bins, max|z| {np.abs(z).max():.2f}, chi2/dof {chi:.2f}; "
          f"counts vs pdf: max|z| {np.abs(zp).max():.2f}, chi2/dof {chip:.2f}; success {h['good'].mean():.4f} "
          f"vs int pdf {pdf.sum():.4f}; albedo {alb:.5f} +- {alb_se:.5f} vs eval {alb_ref:.5f} +- {alb_ref_se:.5f}")
    assert np.abs(z).max() < 4.5 and chi < 2.0
    assert np.abs(zp).max() < 4.5 and chip < 2.0
    assert abs(alb - alb_ref) < 4 * np.hypot(alb_se, alb_ref_se)
    assert abs(h["good"].mean() - pdf.sum()) < 4 * (np.sqrt(h["good"].mean() / N) + pdf_se.sum())


def test_lobe_attenuations_probabilities_and_weights():
    """Sec. 4.3.4: with beta -> 0, alpha = 0 the lobe attenuations of a path at offset h are the
    smooth-cylinder A_p(h) (fiber.smooth_attenuation: Fresnel at the 3D angle, chord
    2 cos(gamma_t) / cos(theta_t)); the lobe is chosen with probability lum(A_p) / sum lum(A_q)
    (stratified lobe uniforms over one fixed path); weight = A_p Vis_p / P_p, i.e.
    sum_q A_q x G for gray absorption."""
    p = huang.Params(roughness=1e-3, tilt=0.0, sigma_a=_SIGMA, **_STATIC)
    u = list(_uniforms(5, huang_sampling._n_uniforms(p)))
    hs = np.linspace(-0.8, 0.8, N)
    u[0] = jnp.asarray(0.5 * (hs + 1))                                 # h = 2 u - 1 (circle: D_i = 1)
    wo, w, lobe, P, A, Vis, good = _sample_path(p, _wi(), tuple(u))
    A, P = np.asarray(A), np.asarray(P)
    ref = np.asarray(fiber.smooth_attenuation(jnp.asarray(hs), THETA_I, p.eta, jnp.asarray(_SIGMA), p_max=3))
    # GGX's long tails: among 2^18 microfacets a few are far from the mesonormal; the 99th
    # percentile of the deviation is O(beta)
    err = np.percentile(np.abs(A - ref[:3]).max(axis=2), 99, axis=1)
    print("99th percentile of |A_p - A_p(smooth)| per lobe:", err)
    assert np.all(err < 1e-3)
    lum = A @ np.asarray(LUMINANCE_WEIGHTS)
    np.testing.assert_allclose(P, lum / lum.sum(0), rtol=1e-12)
    # weight of the chosen lobe
    onehot = np.arange(3)[:, None] == np.asarray(lobe)[None]
    Ak, Pk, Vk = (np.sum(np.where(onehot[..., None], A, 0), 0), np.sum(np.where(onehot, P, 0), 0),
                  np.sum(np.where(onehot, np.asarray(Vis), 0), 0))
    g = np.asarray(good)
    np.testing.assert_allclose(np.asarray(w)[g], (Ak * (Vk / Pk)[:, None])[g], rtol=1e-10)
    # one fixed path (h = 0.3), stratified lobe uniforms: the frequencies are P_p to 1/N
    p2 = huang.Params(roughness=0.3, tilt=3 * DEG, sigma_a=_SIGMA, **_STATIC)
    # float64, not weakly typed (jnp.full's default): the argument types of the other sampler runs
    u = [jnp.full(N, 0.1, jnp.float64) for _ in range(huang_sampling._n_uniforms(p2))]
    u[0] = jnp.full(N, 0.65, jnp.float64)
    u[1] = jnp.asarray((np.arange(N) + 0.5) / N)
    _, w, lobe, P, A, Vis, good = _sample_path(p2, _wi(), tuple(u))
    freq = np.bincount(np.asarray(lobe), minlength=3) / N
    print("lobe frequencies", freq, "P", np.asarray(P)[:, 0])
    assert np.all(np.asarray(P)[:, 0] > 0.02)
    np.testing.assert_allclose(freq, np.asarray(P)[:, 0], atol=2.0 / N)
    assert np.all(np.isfinite(np.asarray(w)))


def test_public_sample_protocol():
    """Model protocol: (wo, weight, pdf) with unit wo, finite weights >= 0; same uniforms => same
    numbers; the Eq. 4.33 estimate at sampled directions is finite, >= 0 and > 0 at successful
    samples (a stage compiled by the histogram test: same shapes). The with_pdf=True path
    (pdf = 0 exactly at failed samples) is in test_public_sample_with_pdf (slow)."""
    p = PARAMS["circle"]
    u = _uniforms(21, huang_sampling._n_uniforms(p))
    wo, w, none = huang.sample(p, _wi(), u, with_pdf=False)
    _, w2, _ = huang.sample(p, _wi(), u, with_pdf=False)
    assert none is None
    np.testing.assert_array_equal(np.asarray(w), np.asarray(w2))
    w = np.asarray(w)
    assert w.shape == (N, 3) and np.all(np.isfinite(w)) and np.all(w >= 0)
    np.testing.assert_allclose(np.sqrt(sum(np.asarray(c) ** 2 for c in wo)), 1.0, atol=1e-9)
    n = _bin_nodes()[0].size
    sub = lambda v: type(v)(*(c[:n] for c in v))  # noqa: E731
    est, se = huang.pdf(p, sub(_wi()), sub(wo), key=jax.random.PRNGKey(4))
    est, se = np.asarray(est), np.asarray(se)
    ok = w[:n, 1] > 0
    assert np.all(np.isfinite(est)) and np.all(est >= 0) and np.all(np.isfinite(se))
    assert ok.mean() > 0.8 and np.all(est[ok] > 0)


@pytest.mark.slow
def test_public_sample_with_pdf():
    p = PARAMS["circle"]
    n = 64
    wi = fiber_direction(jnp.concatenate([jnp.linspace(-1.4, 1.4, n - 1), jnp.asarray([np.pi / 2])]),
                         jnp.linspace(-3, 3, n))
    key = jax.random.PRNGKey(9)
    wo, w, pdf = huang.sample(p, wi, key)
    _, w2, pdf2 = huang.sample(p, wi, key)
    np.testing.assert_array_equal(np.asarray(pdf), np.asarray(pdf2))
    w, pdf = np.asarray(w), np.asarray(pdf)
    assert np.all(np.isfinite(w)) and np.all(np.isfinite(pdf)) and np.all(pdf >= 0)
    ok = w[:, 1] > 0
    assert ok.mean() > 0.8 and not ok[-1]            # the fiber-axis direction fails cleanly
    assert np.all(pdf[~ok] == 0) and np.all(pdf[ok] > 0)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["circle", "ellipse"])
def test_mean_weight_per_lobe_matches_flatland(name):
    """Mean sample weight per lobe (n_lobes = 4: R, TT, TRT, TRRT) = the per-lobe albedo of the
    flatland tracer (split mode, 4 events), an independent implementation of the same rough
    interfaces. For the ellipse the weights carry D_i / D_o (S cos convention) and the tracer's
    power fraction does not: both are compared as power (weight x D_o / D_i)."""
    p = PARAMS[name].replace(n_lobes=4)
    e = float(p.eccentricity)
    wo, w, lobe, *_ = _sample_path(p, _wi(), _uniforms(31, huang_sampling._n_uniforms(p)))
    D = lambda phi: np.sqrt(1 - e * e * np.sin(phi) ** 2)  # noqa: E731
    w = np.asarray(w) * (D(np.asarray(fiber_angles(wo)[1])) / D(PHI_I))[:, None]
    lobe = np.asarray(lobe)
    sec = fl.fiber(float(p.eta), _SIGMA, eccentricity=e, roughness=float(p.roughness), tilt=float(p.tilt))
    hist = fl.trace_fiber(sec, fiber_direction(THETA_I, PHI_I), jax.random.PRNGKey(32), 2 ** 18, n_theta=2,
                          n_phi=2, n_lobes=5, max_events=4)
    ref = np.asarray(hist.albedo)[:4]
    for k in range(4):
        x = np.where((lobe == k)[:, None], w, 0.0)
        m, se = x.mean(0), x.std(0) / np.sqrt(N)
        z = (m - ref[k]) / np.hypot(se, se)        # the tracer's spread is similar: sqrt(2) se
        print(f"{name} lobe {k}: sampler {np.round(m, 5)} flatland {np.round(ref[k], 5)} z {np.round(z, 2)}")
        assert np.all(np.abs(z) < 4)


@pytest.mark.slow
def test_trrt_lobe_matches_flatland_pointwise():
    """The optional TRRT lobe (n_lobes = 4; Sec. 4.5: 'could be added the same way') of the
    Monte Carlo-Simpson estimator vs the flatland next-event estimate of lobe p = 3."""
    beta, alpha, sa = 0.2, 3 * DEG, 0.1
    p = huang.Params(roughness=beta, tilt=alpha, sigma_a=sa, n_paths=128, n_lobes=4)
    sec = fl.fiber(1.55, sa, roughness=beta, tilt=alpha)
    wi = fiber_direction(0.3, 0.4)
    dirs = [(-0.3, 0.5), (-0.2, 2.0), (-0.35, -2.9), (-0.5, -1.2), (0.1, 2.6), (-0.3, -0.6)]
    wo = fiber_direction(jnp.asarray([d[0] for d in dirs]), jnp.asarray([d[1] for d in dirs]))
    v, se = (np.asarray(a)[3, :, 0] * np.cos(0.3) for a in huang.eval_lobes(p, wi, wo, key=jax.random.PRNGKey(5)))
    for k, (th, ph) in enumerate(dirs):
        r, s = fl.nee_bcsdf(sec, wi, fiber_direction(th, ph), jax.random.PRNGKey(40 + k), 2 ** 15, n_lobes=5,
                            max_events=5)
        r, s = float(r[3, 0]), float(s[3, 0])
        z = (v[k] - r) / np.hypot(se[k], s)
        print(f"TRRT at {th, ph}: eval {v[k]:.5f} +- {se[k]:.5f}, flatland {r:.5f} +- {s:.5f}, z {z:.2f}")
        assert abs(z) < 4


def _energy(sa, beta, alpha, thi, dist="beckmann", n=2 ** 16):
    sec = fl.fiber(1.55, sa, roughness=beta, tilt=alpha, distribution=dist)
    return fl.trace_fiber(sec, fiber_direction(thi, 0.0), jax.random.PRNGKey(50), n, n_theta=2, n_phi=2,
                          n_lobes=4, max_events=64)


@pytest.mark.slow
def test_h16_energy_and_orders_beyond_trt():
    """H-16 (Sec. 4.5, Fig. 4.16): sigma_a = 0, alpha = 0, beta -> 0: all orders together carry
    all the energy (emitted + still inside after 64 events = 1 - lost, lost -> 0) while
    R + TT + TRT < 1; with Fig. 4.16's setting (Beckmann 0.15, alpha = 2 deg) the energy beyond
    TRT is visible for blond (rho = 0.06) and negligible for rho = 0.6, 1.8 (Huang's spectral
    melanin constants, fiber.melanin_sigma_a_spectral)."""
    for thi in (0.0, 0.8):
        h = _energy(0.0, 0.02, 0.0, thi)
        a = np.asarray(h.albedo)[:, 0]
        total = a.sum() + float(h.residual[0])
        print(f"theta_i={thi}: sigma_a=0 beta=0.02: lobes {np.round(a, 5)}, emitted+residual {total:.5f}, "
              f"lost {float(h.lost[0]):.1e}")
        assert abs(total - 1) < 1e-3 and a[:3].sum() < 0.99 and a[3] > 0.01
    fr = {}
    for rho in (0.06, 0.6, 1.8):
        sa = np.asarray(fiber.melanin_sigma_a_spectral(rho, rho))
        a = np.asarray(_energy(sa, 0.15, 2 * DEG, 0.0).albedo)
        fr[rho] = a[3] / a.sum(0)
        print(f"rho={rho}: R+TT+TRT {np.round(a[:3].sum(0), 4)}, beyond TRT {np.round(a[3], 4)} "
              f"(fraction {np.round(fr[rho], 4)})")
    assert fr[0.06].max() > 0.02 and fr[0.6].max() < 0.01 and fr[1.8].max() < 1e-3
