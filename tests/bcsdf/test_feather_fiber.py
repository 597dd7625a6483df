"""Padrón's feather fibre BCSDF (bcsdf.feather_fiber, Eqs. 5.1-5.3, spec M21): the traced lobes against
the smooth-cylinder closed form (spec M18), energy bookkeeping, the medulla's mirror symmetry (Q-F8),
the normalisation of eval and pdf by quadrature, the sampler against eval, gradients against central
differences with common random numbers, edges and bad input."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.bcsdf import feather_fiber as ff
from appearance_jax.bcsdf import fiber
from appearance_jax.core.frame import fiber_direction

THETA_I = math.pi / 4
H = np.linspace(-0.95, 0.95, 39)
FIG57_SIGMA = (0.133, 1.967, 2.1)


def _wrap(x):
    return (np.asarray(x) + np.pi) % (2 * np.pi) - np.pi


@pytest.fixture(scope="module")
def circular_lobes():
    """Fig. 5.7's circular cortex without medulla, eta_c = 1.53, theta_i = 45 deg; sigma = 0 and Fig. 5.7's."""
    p = ff.Params(eta=1.53, sigma_a=((0.0,) + FIG57_SIGMA)[:3])
    return p, ff.lobes(p, fiber_direction(THETA_I, 0.3), jnp.asarray(H))


def test_circular_cortex_lobes_are_the_smooth_cylinder_closed_form(circular_lobes):
    """Circular cortex, no medulla: lobe p is the p-th emission, A_p = M18's closed form (Fresnel at the 3D
    angle, chord 2 cos(gamma_t) / cos(theta_t)), on the specular cone Theta = -theta_i, at azimuth
    phi_i + Phi(p, h) (spec M21's limit)."""
    p, lob = circular_lobes
    ref = np.asarray(fiber.smooth_attenuation(jnp.asarray(H), THETA_I, 1.53, jnp.asarray(p.sigma_a), p_max=5))
    A = np.asarray(lob.amplitude)
    np.testing.assert_allclose(A[:5], ref[:5], atol=1e-6, rtol=0)
    assert np.all(A[5:] == 0.0)  # K = 5 lobes kept
    np.testing.assert_allclose(np.asarray(lob.theta)[:5], -THETA_I, atol=1e-9)
    eta_p = math.sqrt(1.53**2 - math.sin(THETA_I) ** 2) / math.cos(THETA_I)
    for k in range(5):
        want = 0.3 + np.asarray(fiber.exit_azimuth(k, jnp.asarray(H), eta_p))
        np.testing.assert_allclose(_wrap(np.asarray(lob.phi)[k] - want), 0.0, atol=1e-6)
    np.testing.assert_allclose(np.asarray(lob.width), 1.0, atol=1e-12)


def test_energy_outside_the_five_lobes(circular_lobes):
    """Lobes + absorbed + discarded = 1 for every ray; the discarded part is the closed form's residual
    beyond p = 4. Reported: the h-averaged energy outside 5 lobes (the thesis' "five lobes seem accurate
    enough" [T:992])."""
    _, lob = circular_lobes
    total = np.asarray(lob.amplitude).sum(0) + np.asarray(lob.absorbed) + np.asarray(lob.discarded)
    np.testing.assert_allclose(total, 1.0, atol=1e-12)
    ref = np.asarray(fiber.smooth_attenuation(jnp.asarray(H), THETA_I, 1.53, 0.0, p_max=5))[5, :, 0]
    np.testing.assert_allclose(np.asarray(lob.discarded)[:, 0], ref, atol=1e-6)
    outside = float(np.mean(np.asarray(lob.discarded)[:, 0]))
    print(f"sigma = 0, eta = 1.53, theta_i = 45 deg: energy outside 5 lobes, mean over h = {outside:.2e}")
    assert 0.0 < outside < 2e-3


def test_white_medulla_conserves_energy_and_a_black_one_absorbs():
    """d_m = 1, sigma = 0: lobes + discarded = 1 (nothing absorbed); d_m = 0: the medulla absorbs what
    reaches it and nothing else is lost."""
    wi = fiber_direction(0.4, 1.0)
    h = jnp.asarray(H)
    for albedo in (1.0, 0.0):
        p = ff.Params(sigma_a=(0.0, 0.0, 0.0), medulla=True, medulla_y=-0.1, medulla_z=0.1,
                      medulla_albedo=(albedo,) * 3, eccentricity=1.6)
        lob = ff.lobes(p, wi, h)  # bands, shapes and key as in the tests below: one compiled program
        kept = np.asarray(lob.amplitude).sum(0)[:, 0]
        total = kept + np.asarray(lob.absorbed)[:, 0] + np.asarray(lob.discarded)[:, 0]
        np.testing.assert_allclose(total, 1.0, atol=1e-12)
        if albedo == 1.0:
            np.testing.assert_allclose(np.asarray(lob.absorbed), 0.0, atol=1e-15)
        else:
            assert np.asarray(lob.absorbed).max() > 0.3  # central rays reach the medulla


def _mirror_lobes(centre):
    """Deterministic lobes (a black medulla: no random bounce) at (phi_i, h) and (-phi_i, -h)."""
    p = ff.Params(sigma_a=(0.2, 0.5, 1.0), medulla=True, medulla_a=0.5, medulla_b=0.4,
                  medulla_y=centre[0], medulla_z=centre[1], medulla_albedo=(0.0,) * 3, eccentricity=1.3)
    h = jnp.asarray(H)
    a = ff.lobes(p, fiber_direction(0.3, 0.7), h)
    b = ff.lobes(p, fiber_direction(0.3, -0.7), -h)
    return a, b


def test_concentric_medulla_is_mirror_symmetric_and_an_off_centre_one_is_not():
    """Q-F8: with a concentric medulla the section is symmetric under z -> -z (phi -> -phi), so the lobes of
    (phi_i, h) mirror those of (-phi_i, -h): same amplitudes, Phi -> -Phi. Off the centre (Fig. 5.7's
    (-0.1, 0.1)) they do not."""
    a, b = _mirror_lobes((0.0, 0.0))
    np.testing.assert_allclose(np.asarray(a.amplitude), np.asarray(b.amplitude), atol=1e-12)
    on = np.asarray(a.amplitude).sum(-1) > 0
    np.testing.assert_allclose(_wrap(np.asarray(a.phi) + np.asarray(b.phi))[on], 0.0, atol=1e-9)
    c, d = _mirror_lobes((-0.1, 0.1))
    assert np.abs(np.asarray(c.amplitude) - np.asarray(d.amplitude)).max() > 1e-2


def _sphere_grid(n_theta=32, n_phi=64):
    """Gauss-Legendre in sin(theta) x midpoint in phi: nodes and weights of the measure cos(theta) dtheta dphi."""
    x, w = np.polynomial.legendre.leggauss(n_theta)
    th = np.arcsin(x)
    ph = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi - np.pi
    T, P = np.meshgrid(th, ph, indexing="ij")
    W = (w[:, None] * np.ones(n_phi)[None]) * 2 * np.pi / n_phi   # dw = d(sin theta) dphi
    return T.ravel(), P.ravel(), W.ravel()


# extra pairs evaluated with the grid (one compiled program): a view along the fibre axis, light along it
EDGE_WI = [(0.5, 0.4), (0.5, 0.4), (math.pi / 2, 0.0)]
EDGE_WO = [(math.pi / 2, 0.0), (-math.pi / 2, 1.0), (-0.3, 1.0)]


@pytest.fixture(scope="module")
def wide():
    """Wide detectors (so a 32 x 64 grid resolves them), an elliptical cortex and an off-centre medulla."""
    p = ff.Params(beta_m=0.3, beta_n=0.35, eccentricity=1.4, medulla=True, medulla_y=-0.1, medulla_z=0.1,
                  medulla_albedo=(0.9, 0.6, 0.3), n_h=16)
    T, P, W = _sphere_grid()
    ti = np.concatenate([np.full(T.size, 0.5), [a for a, _ in EDGE_WI]])
    pi = np.concatenate([np.full(T.size, 0.4), [b for _, b in EDGE_WI]])
    to = np.concatenate([T, [a for a, _ in EDGE_WO]])
    po = np.concatenate([P, [b for _, b in EDGE_WO]])
    wi, wo = fiber_direction(jnp.asarray(ti), jnp.asarray(pi)), fiber_direction(jnp.asarray(to), jnp.asarray(po))
    S, se = ff.eval(p, wi, wo)
    pdf, _ = ff.pdf(p, wi, wo)
    k_h, k_t = jax.random.split(ff._key(None))  # the offsets and bounces eval used (its default key)
    lob = ff.lobes(p, fiber_direction(0.5, 0.4), ff._offsets(p, k_h, p.n_h, jnp.float64), key=k_t)
    n = T.size
    return dict(p=p, T=T, W=W, S=np.asarray(S)[:n], pdf=np.asarray(pdf)[:n], lob=lob,
                edge=(np.asarray(S)[n:], np.asarray(se)[n:], np.asarray(pdf)[n:]))


def test_eval_integrates_to_the_kept_lobes_and_pdf_to_one(wide):
    """Normalised detectors: int S cos(theta_o) dw_o = E_h[D sum_k A_k] exactly for the offsets eval used
    (common random numbers: the same h); the pdf integrates to 1 (a mixture of normalised densities)."""
    T, W, S, pdf, lob = (wide[k] for k in ("T", "W", "S", "pdf", "lob"))
    albedo = (S * np.cos(T)[:, None] * W[:, None]).sum(0)
    want = np.mean(np.asarray(lob.width)[:, None] * np.asarray(lob.amplitude).sum(0), axis=0)
    np.testing.assert_allclose(albedo, want, rtol=1e-3)
    assert abs((pdf * W).sum() - 1.0) < 1e-3
    # D(phi_i): the projected half width of the cortex (semi-axes 1 along y, 1.4 along z) seen from phi_i = 0.4
    np.testing.assert_allclose(np.asarray(lob.width), math.hypot(math.sin(0.4), 1.4 * math.cos(0.4)), rtol=1e-12)


def test_sampler_weights_average_to_the_albedo(wide):
    """E[weight] = E_h[D sum_k A_k], the albedo: the mean weight of 2^14 samples (each with its own h)
    against the quadrature of eval over its 16 stratified offsets, within both standard errors (the
    quadrature's: the spread of D sum_k A_k over the offsets)."""
    p, T, W, S, lob = (wide[k] for k in ("p", "T", "W", "S", "lob"))
    n = 2**14
    _, w, pdf = ff.sample(p, fiber_direction(jnp.full(n, 0.5), jnp.full(n, 0.4)), jax.random.PRNGKey(11))
    w = np.asarray(w)
    assert np.all(np.isfinite(w)) and np.all(np.asarray(pdf) >= 0)
    mean, se = w.mean(0), w.std(0) / math.sqrt(n)
    q = (S * np.cos(T)[:, None] * W[:, None]).sum(0)
    per_h = np.asarray(lob.width)[:, None] * np.asarray(lob.amplitude).sum(0)
    se_q = per_h.std(0) / math.sqrt(p.n_h - 1)
    z = (mean - q) / np.hypot(se, se_q)
    print("sampler mean weight", mean, "+-", se, "quadrature", q, "+-", se_q)
    assert np.all(np.abs(z) < 4.5), z


def test_gradients_match_central_differences_with_common_random_numbers():
    """d eval / d(eta, sigma_a, beta_m, beta_n, d_m, eccentricity) by reverse mode against central
    differences of the same estimator (fixed key: the same offsets and medulla bounces)."""
    base = dict(eta=1.5, sigma_a=0.4, beta_m=0.2, beta_n=0.25, medulla_albedo=0.7, eccentricity=1.2,
                medulla=True, medulla_a=0.4, medulla_b=0.4, medulla_y=0.05, n_h=4)
    wi, wo = fiber_direction(0.3, 0.2), fiber_direction(-0.35, 2.4)
    names = ("eta", "sigma_a", "beta_m", "beta_n", "medulla_albedo", "eccentricity")

    def f(vals):
        q = ff.Params(**{**base, **dict(zip(names, vals))})
        return jnp.sum(ff.eval.kernel(q, wi, wo, key=3)[0])

    x0 = jnp.asarray([base[n] for n in names], jnp.float64)
    g = np.asarray(jax.jit(jax.jacfwd(lambda v: f(list(v))))(x0))  # forward mode: one program, 6 tangents
    fj = jax.jit(lambda v: f(list(v)))
    for i, name in enumerate(names):
        e = 1e-5
        fd = (float(fj(x0.at[i].add(e))) - float(fj(x0.at[i].add(-e)))) / (2 * e)
        assert abs(g[i] - fd) <= 1e-5 + 1e-4 * abs(fd), (name, g[i], fd)
    assert np.all(g != 0.0)


def test_edges_are_finite(wide):
    """A view along the fibre axis, light along it, tangent offsets h = +-1: finite values, errors and pdfs."""
    for a in wide["edge"]:
        assert np.all(np.isfinite(a))
    assert np.all(wide["edge"][0][2] == 0.0)  # light along the axis meets no projected width
    p = ff.Params(medulla=True, medulla_albedo=(1.0,) * 3)
    lob = ff.lobes(p, fiber_direction(0.3, 0.0), jnp.asarray(H).at[0].set(-1.0).at[-1].set(1.0))
    for a in lob:
        assert np.all(np.isfinite(np.asarray(a)))
    np.testing.assert_allclose(np.asarray(lob.amplitude).sum(0) + np.asarray(lob.absorbed) + np.asarray(lob.discarded),
                               1.0, atol=1e-12)


def test_bad_input_names_the_parameter():
    for kw, what in ((dict(eccentricity=0.9), "eccentricity"), (dict(medulla_albedo=1.2), "medulla_albedo"),
                     (dict(beta_m=0.0), "beta_m"), (dict(beta_n=-0.1), "beta_n"), (dict(sigma_a=-1.0), "sigma_a"),
                     (dict(eta=0.9), "eta"), (dict(n_lobes=0), "n_lobes"), (dict(h_lo=0.5, h_hi=0.5), "h_lo"),
                     (dict(medulla=True, medulla_a=0.95, medulla_y=0.1), "medulla"),
                     (dict(n_lobes=8, max_events=6), "max_events")):
        with pytest.raises(ValueError, match=what):
            ff.Params(**kw)
    with pytest.raises(ValueError, match="key"):
        ff.sample(ff.Params(), fiber_direction(0.3, 0.0), 3)


def test_narrow_detectors_reproduce_the_tracers_random_walk_histogram():
    """beta -> 0 (issue 21): the far-field histogram of feather_fiber.sample's weights (split-mode lobes,
    the lobe choice by lum(A_k), the detectors, the weight S_h cos / pdf_h) equals flatland.trace_fiber's
    random-mode histogram (one stochastic branch per path at every interface) for Fig. 5.7's barb with
    its off-centre medulla: every (theta_o, phi_o) bin within 4.5 combined standard errors, and the
    chi-square of all bins within its expectation. All lobes kept (K = max_events = 16) so that both
    count the same light."""
    from appearance_jax.flatland import trace_fiber

    p = ff.Params(eccentricity=1.6, medulla=True, medulla_y=-0.1, medulla_z=0.1, beta_m=0.004, beta_n=0.004,
                  n_lobes=16, max_events=16, sigma_a=FIG57_SIGMA, projected_width=False)  # the tracer: per path
    wi = fiber_direction(THETA_I, 0.3)
    n, nt, nph = 2**16, 13, 24  # no bin edge on the specular cone theta_o = -45 deg (the lobes sit there)
    wo, w, _ = ff.sample(p, fiber_direction(jnp.full(n, THETA_I), jnp.full(n, 0.3)), jax.random.key(21))
    th, ph = (np.asarray(a) for a in (jnp.arcsin(jnp.clip(wo.x, -1, 1)), jnp.arctan2(wo.z, wo.y)))
    it = np.clip(((th + np.pi / 2) / np.pi * nt).astype(int), 0, nt - 1)
    ip = np.clip(((ph + np.pi) / (2 * np.pi) * nph).astype(int), 0, nph - 1)
    w = np.asarray(w)[:, 0]                                    # red
    idx = it * nph + ip
    s1 = np.bincount(idx, w, nt * nph) / n
    var1 = (np.bincount(idx, w * w, nt * nph) / n - s1**2) / n
    h = trace_fiber(ff.section(p), wi, jax.random.key(22), n, n_theta=nt, n_phi=nph, n_lobes=1, max_events=16,
                    mode="random")
    s2 = np.asarray(h.power)[0, ..., 0].ravel() / h.n_paths
    var2 = (np.asarray(h.power_sq)[0, ..., 0].ravel() / h.n_paths - s2**2) / h.n_paths
    se = np.sqrt(var1 + var2)
    live = se > 0
    z = (s1 - s2)[live] / se[live]
    print(f"bins with light {live.sum()}, max |z| {np.abs(z).max():.2f}, chi2/dof {np.mean(z**2):.3f}, "
          f"totals {s1.sum():.4f} vs {s2.sum():.4f}")
    assert np.abs(z).max() < 4.5 and np.mean(z**2) < 1.0 + 5.0 * math.sqrt(2.0 / z.size)
    assert live.sum() > 100 and abs(s1.sum() - s2.sum()) < 4.5 * math.sqrt(np.sum(se[live] ** 2)) + 1e-3
