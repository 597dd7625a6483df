"""Padrón's feather surface BSDF (bsdf.feather, Eq. 5.4, spec M25): the energy identity of Eq. 5.4 by
quadrature against the lobes of the separately validated fibre BCSDF (from above and from below the
vane), the pdf's normalisation, the four-event sampler against the quadrature and the delta, the
barb angle as a rotation, the transmission's trends (Q-F9, Fig. 5.12), gradients against central
differences with common random numbers, edges and bad input."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.bcsdf import feather_fiber as ff
from appearance_jax.bsdf import feather
from appearance_jax.core.frame import spherical_direction
from appearance_jax.core.quadrature import sphere_rule
from appearance_jax.core.vec import Vec3

# lossless fibres (sigma = 0, white medulla) with wide detectors, so a 48 x 96 rule resolves the lobes
WIDE = dict(sigma_a_b=(0.0, 0.0, 0.0), sigma_a_bb=(0.0, 0.0, 0.0), medulla_albedo=(1.0, 1.0, 1.0), beta_m_b=0.3,
            beta_n_b=0.35, beta_m_bb=0.3, beta_n_bb=0.35, n_h=8)
VIEWS = ((0.5, 0.3), (2.3, 2.0))  # (theta, phi) of wi: above the vane, and below it


def _dir(theta, phi):
    return spherical_direction(jnp.asarray(theta, jnp.float64), jnp.asarray(phi, jnp.float64))


def _lobe_albedo(p, wi):
    """sum_j w_j A_j(h) per offset (n_h, bands) and the masking, from feather_fiber.lobes at the offsets,
    ranges and keys that feather.eval uses with its default key (common random numbers)."""
    m = feather.masking_of(p, wi)
    k_h, k_b, k_bb = jax.random.split(feather._key(None), 3)
    u = (jnp.arange(p.n_h) + jax.random.uniform(k_h, (p.n_h,), jnp.float64)) / p.n_h
    R = feather._frames(p)
    barb, barbule = feather.fibres(p)
    out = 0.0
    for j, (fp, key) in enumerate(((barb, k_b), (barbule, k_bb), (barbule, k_bb))):
        wj = feather._to(R[j], wi)
        lob = ff.lobes(fp, wj, m.h_lo[j] + (m.h_hi[j] - m.h_lo[j]) * u, key=key)
        out = out + float(m.weight[j]) * np.asarray(lob.amplitude).sum(0)
    return out, m


@pytest.fixture(scope="module")
def wide():
    """eval and pdf of the lossless vane on a sphere rule for both views, in one call each."""
    p = feather.Params(**WIDE)
    wo, W = sphere_rule(48, 96)
    n = wo.x.size
    # the views (2, 1) against the rule (1, n): each view's masking and fibres are traced once
    wi = _dir(np.array([[v[0]] for v in VIEWS]), np.array([[v[1]] for v in VIEWS]))
    wo2 = Vec3(*(c[None, :] for c in wo))
    f, se = feather.eval(p, wi, wo2)
    pdf, _ = feather.pdf(p, wi, wo2)
    assert np.shape(f) == (2, n, 3)
    return dict(p=p, wo=wo, W=np.asarray(W), f=np.asarray(f), se=np.asarray(se), pdf=np.asarray(pdf))


@pytest.mark.parametrize("view", [0, 1], ids=["above", "below"])
def test_eval_integrates_to_the_masked_fibre_lobes(wide, view):
    """Eq. 5.4 with normalised detectors: int f |wo . n| dwo = sum_j w_j E_h[sum_k A_k,j] for the offsets
    eval used (each fibre's albedo with D = 1, from feather_fiber.lobes in the fibre's own frame); so
    with lossless fibres, int f |wo . n| + w_t = 1 - the energy the five lobes leave out [T:1121].
    A wrong G, |wo . n| or frame rotation changes the integral."""
    p, W, f = wide["p"], wide["W"], wide["f"][view]
    wi = _dir(*VIEWS[view])
    cos = np.abs(np.asarray(wide["wo"].z))
    albedo = (f * (cos * W)[:, None]).sum(0)
    per_h, m = _lobe_albedo(p, wi)
    np.testing.assert_allclose(albedo, per_h.mean(0), rtol=2e-3)
    w_t = float(m.w_t)
    assert 0.05 < w_t < 0.6 and abs(float(m.weight.sum()) + w_t - 1.0) < 1e-12
    lost = 1.0 - w_t - albedo
    print(f"view {VIEWS[view]}: w = {np.asarray(m.weight)}, w_t = {w_t:.4f}, energy the 5 lobes leave out {lost}")
    assert np.all(lost > -2e-3) and np.all(lost < 0.05)
    # the reflected and transmitted halves both carry light (a two-sided, transmissive vane)
    up = np.asarray(wide["wo"].z) > 0
    assert (f[up, 0] * (cos * W)[up]).sum() > 0.05 and (f[~up, 0] * (cos * W)[~up]).sum() > 0.05


def test_pdf_integrates_to_one(wide):
    """pdf = sum_j w_j E_h[pdf_h,j] / (1 - w_t): a density of the continuous sampler on the sphere."""
    for view in (0, 1):
        assert abs((wide["pdf"][view] * wide["W"]).sum() - 1.0) < 3e-3


def test_four_event_sampler_estimates_the_bsdf_with_its_delta(wide):
    """Padrón's sampler [T:1056]: E[weight g(wo)] = int f |wo . n| g dwo + w_t g(-wi) for g = 1, wo.x,
    wo.z; sample() (the continuous part) averages to int f |wo . n|. Tolerances: 4.5 standard errors of
    the samples plus 4.5 x a bound of the quadrature's (int stderr |g| |wo . n|, the estimate over 8
    offsets)."""
    p, W, f, se_f = wide["p"], wide["W"], wide["f"][0], wide["se"][0]
    wo_q = wide["wo"]
    wi = _dir(*VIEWS[0])
    n = 2**14
    wis = Vec3(*(jnp.full(n, c) for c in wi))
    wo, weight, event = feather.sample_events(p, wis, jax.random.key(5))
    weight, event = np.asarray(weight), np.asarray(event)
    assert np.all(np.isfinite(weight)) and set(np.unique(event)) == {0, 1, 2, 3}
    m = feather.masking_of(p, wi)
    np.testing.assert_allclose(np.bincount(event, minlength=4) / n, [*np.asarray(m.weight), float(m.w_t)],
                               atol=4.5 * 0.5 / math.sqrt(n))
    delta = event == 3
    np.testing.assert_allclose(np.asarray(wo.x)[delta], -float(wi.x), atol=1e-12)
    assert np.all(weight[delta] == 1.0)
    cos = np.abs(np.asarray(wo_q.z))
    for g_s, g_q, g_t in ((1.0, 1.0, 1.0), (np.asarray(wo.x), np.asarray(wo_q.x), -float(wi.x)),
                          (np.asarray(wo.z), np.asarray(wo_q.z), -float(wi.z))):
        est = weight * np.broadcast_to(g_s, (n,))[:, None]
        q = (f * (cos * W * g_q)[:, None]).sum(0) + float(m.w_t) * g_t
        se_q = (se_f * (cos * W * np.abs(g_q))[:, None]).sum(0)
        assert np.all(np.abs(est.mean(0) - q) <= 4.5 * est.std(0) / math.sqrt(n) + 4.5 * se_q), (est.mean(0), q)
    _, w_c, pdf_c = feather.sample(p, wis, jax.random.key(6))
    w_c = np.asarray(w_c)
    q = (f * (cos * W)[:, None]).sum(0)
    se_q = (se_f * (cos * W)[:, None]).sum(0)
    assert np.all(np.abs(w_c.mean(0) - q) <= 4.5 * w_c.std(0) / math.sqrt(n) + 4.5 * se_q), (w_c.mean(0), q)
    assert np.mean(np.asarray(pdf_c) > 0) > 0.99


def _binned_rule(n_mu, n_phi, k_mu, k_phi):
    """Directions and weights of a product Gauss-Legendre rule inside each of n_mu x n_phi bins uniform
    in cos(theta) and phi (k_mu x k_phi points per bin), and each point's bin."""
    from appearance_jax.core.quadrature import gauss_legendre
    t, wt = gauss_legendre(k_mu, 0.0, 1.0)
    mu = ((np.arange(n_mu)[:, None] + t[None]) * (2.0 / n_mu) - 1.0).ravel()
    w_mu = np.tile(wt * (2.0 / n_mu), n_mu)
    u, wu = gauss_legendre(k_phi, 0.0, 1.0)
    phi = ((np.arange(n_phi)[:, None] + u[None]) * (2.0 * np.pi / n_phi)).ravel()
    w_phi = np.tile(wu * (2.0 * np.pi / n_phi), n_phi)
    MU, PHI = np.meshgrid(mu, phi, indexing="ij")
    W = (w_mu[:, None] * w_phi[None, :]).ravel()
    b = ((np.arange(n_mu * k_mu) // k_mu)[:, None] * n_phi + (np.arange(n_phi * k_phi) // k_phi)[None, :]).ravel()
    return _dir(np.arccos(MU.ravel()), PHI.ravel()), W, b


@pytest.mark.parametrize("view", [0, pytest.param(1, marks=pytest.mark.slow)], ids=["above", "below"])
def test_sampler_histogram_is_its_pdf_chi_square(wide, view):
    """Chi-square of sample()'s directions (2^14, the sampler of the tests above: it does not use n_h) in
    8 x 12 bins uniform in cos(theta) and phi, against N x the pdf integrated over each bin (3 x 4
    Gauss-Legendre points per bin), with the pdf's standard error in each bin's variance. The pdf is an
    estimate over n_h offsets, and where only few of their lobes reach (light scattered by the medulla,
    a lobe sweeping fast near grazing offsets) its sample standard error is ~0 while the estimate is
    low: at n_h = 8 (above) or 64 (below) the histogram is off by up to 12 reported sigma; above at 64
    and below at 256, chi2/dof ~ 0.8 (docs/feathers.md). Bins expecting >= 10 samples: max |z| < 4.5
    and chi2 / dof < 1.6."""
    p = wide["p"]
    wo_q, W, b = _binned_rule(8, 12, 3, 4)
    wi = _dir(*VIEWS[view])
    pdf, pdf_se = (np.asarray(v) for v in feather.pdf(p.replace(n_h=(64, 256)[view]), wi, wo_q))
    n = 2**14
    expect = n * np.bincount(b, weights=pdf * W, minlength=96)
    e_se = n * np.bincount(b, weights=pdf_se * W, minlength=96)
    wo, _, pdf_s = feather.sample(p, Vec3(*(jnp.full(n, c) for c in wi)), jax.random.key(7 + view))
    mu, phi = np.asarray(wo.z), np.mod(np.arctan2(np.asarray(wo.y), np.asarray(wo.x)), 2 * np.pi)
    ok = np.asarray(pdf_s) > 0
    k = np.clip(((mu + 1.0) * 4).astype(int), 0, 7) * 12 + np.clip((phi / (2 * np.pi) * 12).astype(int), 0, 11)
    count = np.bincount(k[ok], minlength=96)
    sel = expect >= 10
    z = (count - expect)[sel] / np.sqrt(expect[sel] + e_se[sel] ** 2)
    chi = float(np.mean(z ** 2))
    print(f"view {VIEWS[view]}: {sel.sum()} bins hold {count[sel].sum() / ok.sum():.4f} of the samples, "
          f"max |z| {np.abs(z).max():.2f}, chi2/dof {chi:.2f}, pdf integral {(pdf * W).sum():.4f}")
    assert count[sel].sum() > 0.95 * ok.sum() and ok.mean() > 0.99
    assert np.abs(z).max() < 4.5 and chi < 1.6


# rotation pairs: (theta, phi) of wi and wo, and the barb angles of the turned copies
ROT_I = (np.array([0.4, 1.0, 2.6]), np.array([0.2, -1.3, 2.0]))
ROT_O = (np.array([0.9, 2.0, 0.3]), np.array([2.2, 0.4, -0.7]))
ROT_A = np.array([0.7, -2.1, 3.0])


def _edge_pairs(p):
    """grazing viewers (along the barb, across it), the normal, along the proximal barbule's axis, and a
    grazing light"""
    ct, st = math.cos(p.theta_bb), math.sin(p.theta_bb)
    axis = (ct * math.cos(math.pi / 4), -ct * math.sin(math.pi / 4), st)
    wi = (np.array([1.0, 0.6, 0.0, axis[0], axis[0]]), np.array([0.0, 0.8, 0.0, axis[1], axis[1]]),
          np.array([0.0, 0.0, 1.0, axis[2], axis[2]]))
    wo = (np.array([0.3, 0.0, 0.5, 0.2, 1.0]), np.array([0.0, 0.6, 0.0, 0.4, 0.0]),
          np.array([math.sqrt(0.91), 0.8, -math.sqrt(0.75), -math.sqrt(0.8), 0.0]))
    return wi, wo


@pytest.fixture(scope="module")
def small():
    """One eval call (one compiled program): the rotation pairs at barb angle 0, the same pairs turned by
    ROT_A with that barb angle (an array: one angle per pair, as texels have), and the edge pairs."""
    p = feather.Params(n_h=4, max_events=8)
    c = lambda th, ph: np.stack([np.asarray(v) for v in _dir(th, ph)])  # noqa: E731  (3, n)
    e_i, e_o = _edge_pairs(p)
    wi = np.concatenate([c(*ROT_I), c(ROT_I[0], ROT_I[1] + ROT_A), np.asarray(e_i)], axis=1)
    wo = np.concatenate([c(*ROT_O), c(ROT_O[0], ROT_O[1] + ROT_A), np.asarray(e_o)], axis=1)
    angle = np.concatenate([np.zeros(3), ROT_A, np.zeros(5)])
    q = p.replace(barb_angle=angle)
    f, se = feather.eval(q, Vec3(*wi), Vec3(*wo))
    t = feather.transmission(q, Vec3(*wi))
    return np.asarray(f), np.asarray(se), np.asarray(t)


def test_barb_angle_turns_the_frame_about_the_normal(small):
    """f(barb_angle = a; R_a wi, R_a wo) = f(0; wi, wo) with R_a the rotation by a about n (the texture's
    R channel turns the barb frame), with one angle per pair; the same for the delta's mass."""
    f, _, t = small
    np.testing.assert_allclose(f[3:6], f[:3], rtol=1e-9, atol=1e-14)
    assert np.all(f[:3] > 0)
    np.testing.assert_allclose(t[3:6], t[:3], rtol=1e-12, atol=1e-15)


def test_transmission_trends():
    """Q-F9 / Fig. 5.10: wider barbule gaps pass more light; Fig. 5.12: the backlit vane's transparency
    falls as it turns away from the view (rotation about the barb axis); the barbs alone (no barbules)
    close the vane when they touch (l_bb = 0)."""
    normal = _dir(0.0, 0.0)
    t = [float(feather.transmission(feather.Params(delta_bb=d), normal)) for d in (0.1, 0.5, 1.0, 3.0)]
    assert all(b > a for a, b in zip(t, t[1:])) and t[0] >= 0
    turn = _dir(jnp.asarray([0.0, 0.3, 0.6, 0.9, 1.2]), jnp.full(5, 0.5 * math.pi))
    tt = np.asarray(feather.transmission(feather.Params(delta_bb=3.0), turn))
    assert np.all(np.diff(tt) < 0) and tt[0] > 0.3
    assert float(feather.transmission(feather.Params(l_bb=0.0), normal)) == pytest.approx(0.0, abs=1e-12)


def test_gradients_match_central_differences_with_common_random_numbers():
    """d eval / d(sigma_a_b, d_m, eta_b, beta_m_b, eta_bb, beta_n_bb, delta_bb, e_bb) in forward mode against
    central differences of the same estimator (fixed key), away from the masking's case switches."""
    base = dict(n_h=4, max_events=8, sigma_a_b=0.4, medulla_albedo=0.7, eta_b=1.5, beta_m_b=0.2, eta_bb=1.55,
                beta_n_bb=0.25, delta_bb=0.8, e_bb=1.3)
    names = ("sigma_a_b", "medulla_albedo", "eta_b", "beta_m_b", "eta_bb", "beta_n_bb", "delta_bb", "e_bb")
    wi, wo = _dir(0.6, 0.9), _dir(0.8, 3.0)

    def f(v):
        q = feather.Params(**{**base, **dict(zip(names, v))})
        return jnp.sum(feather.eval.kernel(q, wi, wo, key=3)[0])

    x0 = jnp.asarray([base[k] for k in names], jnp.float64)
    g = np.asarray(jax.jit(jax.jacfwd(lambda v: f(list(v))))(x0))
    fj = jax.jit(lambda v: f(list(v)))
    for i, name in enumerate(names):
        e = 1e-5
        fd = (float(fj(x0.at[i].add(e))) - float(fj(x0.at[i].add(-e)))) / (2 * e)
        assert abs(g[i] - fd) <= 1e-6 + 1e-4 * abs(fd), (name, g[i], fd)
    assert np.count_nonzero(g) == len(names)


def test_edges_give_zero_or_finite_values(small):
    """A grazing viewer or light (in the vane plane) gives 0, and so does the delta for a grazing viewer;
    views along the normal and along a barbule's axis are finite and positive (their derivatives:
    tests/testing/test_special_directions.py)."""
    f, se, t = (a[6:] for a in small)
    assert np.all(np.isfinite(f)) and np.all(np.isfinite(se))
    assert np.all(f[:2] == 0.0) and np.all(f[4] == 0.0) and np.all(f[2:4] > 0)
    assert np.all(t[:2] == 0.0) and t[2] > 0 and np.all(t[3:] >= 0)  # (15 deg above the vane: barbs close it)


def test_bad_input_names_the_parameter():
    for kw, what in ((dict(theta_bb=0.5 * math.pi), "theta_bb"), (dict(delta_bb=-0.1), "delta_bb"),
                     (dict(l_bb=-1.0), "l_bb"), (dict(e_b=0.9), "e_b"), (dict(e_bb=0.0), "e_bb"),
                     (dict(medulla_albedo=1.2), "medulla_albedo"), (dict(beta_m_b=0.0), "beta_m_b"),
                     (dict(sigma_a_bb=-1.0), "sigma_a_bb"), (dict(eta_b=0.9), "eta_b"), (dict(n_lobes=0), "n_lobes"),
                     (dict(e_b=1.0, medulla_a=0.95, medulla_y=0.1), "medulla"), (dict(corner=0), "corner"),
                     (dict(n_lobes=8, max_events=6), "max_events")):
        with pytest.raises(ValueError, match=what):
            feather.Params(**kw)
    with pytest.raises(ValueError, match="key"):
        feather.sample(feather.Params(), _dir(0.3, 0.0), 3)
