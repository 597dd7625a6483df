"""layered/ordinates.py: the deterministic solver of the cosmetic medium, against references it
did not write (issue 25): the HG adding-doubling of layered/adding_doubling.py, the closed
forms of single scattering and of a Lambertian base under a dielectric, energy conservation,
reciprocity, its own exact-query mode, and the random walk (layered/random_walk.py)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.core.vec import Vec3
from appearance_jax.layered import adding_doubling as ad
from appearance_jax.layered import medium as med
from appearance_jax.layered import ordinates as od
from appearance_jax.layered import single_scattering as ssm
from appearance_jax.layered.random_walk import walk
from appearance_jax.optics.fresnel import fresnel_dielectric

MEDIUM = dict(c_d=0.7, albedo_d=(0.9, 0.95, 0.99), albedo_p=(0.8, 0.9, 0.7), w_g=0.7, g1=0.6, g2=-0.3,
              alpha=0.3, theta=0.3)


def media(layers):
    """medium.Params with a leading layer axis from a list of field dicts (MEDIUM's defaults)."""
    rows = [{**MEDIUM, **kw} for kw in layers]
    return med.Params(**{k: jnp.asarray(np.array([r[k] for r in rows], float)) for k in med.FIELDS})


def directions(n, seed, mu_min=0.02):
    rng = np.random.default_rng(seed)
    mu = rng.uniform(mu_min, 1.0, n)
    ph = rng.uniform(0.0, 2.0 * np.pi, n)
    s = np.sqrt(1.0 - mu**2)
    return Vec3(jnp.asarray(s * np.cos(ph)), jnp.asarray(s * np.sin(ph)), jnp.asarray(mu))


WI, WO = directions(48, 0), directions(48, 1)
RHO = jnp.array([0.2, 0.5, 0.9])
# black and white bases as RGB arrays like RHO: the tilted media below (default settings) then
# share two compiled solutions, without and with a dielectric top (compilation is most of the cost)
BLACK, WHITE = jnp.zeros(3), jnp.ones(3)
# media without tilted platelets: the tilt correction is exactly 0, and its coarse solve only
# costs compile time
NO_TILT = od.Settings(tilt=False)
# WI, WO and one more pair: normal incidence (odd modes vanish there), grazing 89 deg out. The
# untilted two-layer stacks without a top interface (the adding-doubling and Chandrasekhar
# comparisons) query these: one compiled solution and one query program for both tests.
WI_N = Vec3(*(jnp.concatenate([v, jnp.asarray(e)]) for v, e in zip(WI, ([0.0], [0.0], [1.0]))))
WO_G = Vec3(*(jnp.concatenate([v, jnp.asarray(e)]) for v, e in zip(WO, ([0.99985], [0.0], [0.01745]))))


def test_hg_stack_matches_adding_doubling():
    """Diffusers only (c_d = 1: isotropic extinction, the HG mixture), two layers over a
    Lambertian base, full azimuth: the independent HG adding-doubling (Legendre moments,
    30 doublings, queries on the node list) agrees to 2e-4 (measured 1.2e-4 at mu 0.03),
    except near the horizon (below).
    Directions include the normal (odd modes vanish there) and grazing 89 deg."""
    wi, wo = WI_N, WO_G
    m = media([dict(c_d=1.0, g1=0.6, g2=-0.3, w_g=0.7), dict(c_d=1.0, albedo_d=(0.5, 0.8, 0.95), g1=0.3, w_g=1.0)])
    f = od.brdf(m, jnp.array([1.0, 2.5]), wi, wo, base=RHO, settings=NO_TILT)
    layers = [ad.HGLayer(albedo=jnp.asarray(m.albedo_d[k]), thickness=t, g1=float(m.g1[k]), g2=float(m.g2[k]),
                         w_g=float(m.w_g[k])) for k, t in enumerate((1.0, 2.5))]
    ref = ad.brdf(layers, RHO, wi, wo)
    np.testing.assert_allclose(np.asarray(f)[:-1], np.asarray(ref)[:-1], rtol=2e-4)
    # normal incidence, 89 deg out: the interpolation in mu near the horizon (the kernel is not
    # polynomial there) costs 1.5e-3 at 24 nodes (8e-5 at 48)
    np.testing.assert_allclose(np.asarray(f)[-1], np.asarray(ref)[-1], rtol=2e-3)


def test_semi_infinite_isotropic_limit_is_chandrasekhar():
    """Isotropic diffusers (c_d = 1, g = 0), t = 64 over black: Chandrasekhar's half-space
    f = w H(mu_i) H(mu_o) / (4 pi (mu_i + mu_o)) with layers.h_function, to 2e-4 at arbitrary
    directions (one layer of 64, measured 7e-4 with 20 doublings (t0 = 6e-5), 5e-5 with the
    default 24; two layers of 32, 4.9e-5), 2e-3 at the grazing pair (the interpolation near the
    horizon, see above; measured 2.4e-4). The 64 mean free paths are two layers of 32 over a
    black Lambertian base: the compiled solution and queries of test_hg_stack_matches_adding_doubling."""
    from appearance_jax.layered import h_function as hf
    w = 0.9
    iso = dict(c_d=1.0, albedo_d=(w, w, w), g1=0.0, g2=0.0, w_g=1.0)
    f = np.asarray(od.brdf(media([iso, iso]), jnp.array([32.0, 32.0]), WI_N, WO_G, base=BLACK, settings=NO_TILT))
    f = f[:, 0]
    ref = np.asarray(hf.brdf(w, WI_N, WO_G))
    np.testing.assert_allclose(f[:-1], ref[:-1], rtol=2e-4)
    np.testing.assert_allclose(f[-1], ref[-1], rtol=2e-3)


def test_interpolated_queries_match_exact_queries():
    """f at arbitrary directions (multiply scattered modes interpolated from the Gauss nodes,
    single scattering exact) equals the solver's own exact mode, where the query cosines sit on
    the node list with zero weight, to 1e-4 (untilted platelets over diffusers, a dielectric top,
    a base; measured 6.4e-5). Without the sqrt(1 - mu^2) factor of the odd modes the error near the
    normal is 6e-4 (one platelet layer)."""
    # alpha = 0.6: the exact mode's single scattering uses the grid-resolvable alpha
    # (ordinates.resolvable_alpha: 0.6 -> 0.60005), the interpolated one the true alpha. Two
    # layers (diffusers below): the compiled solution of the random-walk comparison below
    m = media([dict(theta=0.0, alpha=0.6), dict(theta=0.0, c_d=1.0, albedo_d=(0.6, 0.8, 0.9), g1=0.4)])
    t = jnp.array([1.5, 1.0])
    f = od.brdf(m, t, WI, WO, base=RHO, eta=1.4, settings=NO_TILT)
    mu_in = lambda w: jnp.sqrt(1.0 - (1.0 - w.z**2) / 1.4**2)  # noqa: E731
    mu = jnp.concatenate([mu_in(WI), mu_in(WO)])
    K = np.asarray(od.fourier_kernels(m, t, mu, base=RHO, eta=1.4))  # (B, M, k, k)
    q = np.arange(WI.z.shape[0])
    dphi = np.arctan2(np.asarray(WO.y), np.asarray(WO.x)) - np.arctan2(np.asarray(WI.y), np.asarray(WI.x)) - np.pi
    mm = np.arange(K.shape[1])
    cos = np.where(mm == 0, 1.0, 2.0)[:, None] * np.cos(mm[:, None] * dphi[None, :])
    inside = np.einsum("bmq,mq->qb", K[:, :, q.size + q, q], cos)
    Fi = np.asarray(fresnel_dielectric(WI.z, 1.4)[0])
    Fo = np.asarray(fresnel_dielectric(WO.z, 1.4)[0])
    ref = inside * ((1 - Fi) * (1 - Fo) / 1.4**2)[:, None]
    np.testing.assert_allclose(np.asarray(f), ref, rtol=1e-4)


def test_thin_limit_is_single_scattering():
    """A tilted, oriented medium (azimuth 'fixed') of vanishing thickness: f -> the
    single-scattering closed form of layered/single_scattering.py; the multiply scattered
    remainder falls linearly with t (measured 6.4e-3 at t = 1e-3, 7.1e-4 at 1e-4)."""
    m = media([{}])
    errs = []
    for t in (1e-3, 1e-4):
        f = od.brdf(m, jnp.array([t]), WI, WO, base=BLACK, azimuth="fixed")
        s = ssm.brdf(od._layer(m, 0), t, WI, WO)
        errs.append(float(np.max(np.abs(np.asarray(f) / np.asarray(s) - 1.0))))
    assert errs[1] < 2e-3 and 5.0 < errs[0] / errs[1] < 20.0, errs


def test_zero_thickness_is_the_base_and_the_dielectric_closed_form():
    """t = 0: exactly the Lambertian base; under a smooth dielectric the closed form
    f = (1 - F_i)(1 - F_o) rho / (pi eta^2 (1 - rho F_int)), F_int = 2 int F mu dmu from inside
    (total internal reflection beyond the critical angle), to 3e-8 (measured 6e-9, the
    reference's own convergence; 1.3e-5 with the earlier interface weights, a Gauss rule in mu
    split at the critical angle; the plain Gauss rule over the kink of F would give 0.9 %)."""
    m = media([{}])
    f0 = od.brdf(m, jnp.array([0.0]), WI, WO, base=RHO)
    np.testing.assert_allclose(np.asarray(f0), np.broadcast_to(np.asarray(RHO) / np.pi, f0.shape), rtol=1e-12)
    eta = 1.5
    f1 = od.brdf(m, jnp.array([0.0]), WI, WO, base=RHO, eta=eta)
    x, w = np.polynomial.legendre.leggauss(400)  # converged to 3e-9 (2000 nodes: a seconds-long eigen-solve)
    mu_c = np.sqrt(1.0 - 1.0 / eta**2)
    F_int = 0.0
    for a, b in ((0.0, mu_c), (mu_c, 1.0)):
        xs, ws = 0.5 * (b - a) * (x + 1.0) + a, 0.5 * (b - a) * w
        F_int += 2.0 * np.sum(np.asarray(fresnel_dielectric(jnp.asarray(xs), 1.0 / eta)[0]) * xs * ws)
    Fi = np.asarray(fresnel_dielectric(WI.z, eta)[0])
    Fo = np.asarray(fresnel_dielectric(WO.z, eta)[0])
    ref = ((1 - Fi) * (1 - Fo))[:, None] * np.asarray(RHO) / (np.pi * eta**2 * (1.0 - np.asarray(RHO) * F_int))
    np.testing.assert_allclose(np.asarray(f1), ref, rtol=3e-8)


def test_white_furnace_discrete_energy():
    """Albedo 1 everywhere over a white base: the discrete solution's albedo sum_o c_o R_0(o, i)
    (the Gauss rule the solver composes with) is 1 to the accuracy of the discretisation:
    diffusers only 8.8e-6 (the 24 doublings' starting layer; 1.4e-4 at 20, 1e-7 at 30), with
    tilted platelets ~5e-4 (the Gauss x azimuth rule of the platelets' lobe)."""
    x, _ = np.polynomial.legendre.leggauss(od.Settings().n_nodes)
    x = 0.5 * (x + 1.0)
    c = 2.0 * np.pi * x * 0.5 * np.polynomial.legendre.leggauss(od.Settings().n_nodes)[1]
    white = dict(albedo_d=(1.0, 1.0, 1.0), albedo_p=(1.0, 1.0, 1.0))
    for kw, tol, floor in ((dict(c_d=1.0), 3e-5, 1e-6), ({}, 1e-3, 1e-4)):
        K = np.asarray(od.fourier_kernels(media([{**white, **kw}]), jnp.array([3.0]), jnp.asarray(x), base=1.0))
        alb = np.einsum("o,boi->bi", c, K[:, 0])
        loss = 1.0 - alb
        # lossy by a small positive amount (a starting layer that omits its own multiple scattering)
        assert np.all(loss < tol) and np.all(loss > 0.0) and np.max(loss) > floor, (kw, loss.max(), loss.min())


# eta = None is `slow`: the same queries without the top's Fresnel term (its own compiled query);
# the default case 1.5 and test_white_furnace_discrete_energy (no top) cover energy conservation
@pytest.mark.parametrize("eta", [pytest.param(None, marks=pytest.mark.slow), 1.5])
def test_white_furnace(eta):
    """Albedo 1 everywhere over a white base: the directional albedo int f cos dwo of the
    interpolated f (what a user integrates) is 1 minus the Fresnel reflection of the top (a
    delta lobe, not part of f), to 3e-3: the discrete loss above plus this Gauss x 256-azimuth
    rule over the platelets' lobe and the interpolation near the horizon (measured 2.0e-3 at
    mu_i = 0.9 without a top)."""
    m = media([dict(albedo_d=(1.0, 1.0, 1.0), albedo_p=(1.0, 1.0, 1.0))])
    x, w = np.polynomial.legendre.leggauss(64)
    mu_o, w_o = 0.5 * (x + 1.0), 0.5 * w
    phi = 2.0 * np.pi * np.arange(256) / 256
    s = np.sqrt(1.0 - mu_o**2)
    wo = Vec3(*(jnp.asarray(v.ravel()) for v in (s[:, None] * np.cos(phi), s[:, None] * np.sin(phi),
                                                  np.broadcast_to(mu_o[:, None], (64, 256)))))
    for mu_i in (0.9, 0.5, 0.15):
        wi = Vec3(jnp.asarray(np.sqrt(1 - mu_i**2)), jnp.asarray(0.0), jnp.asarray(mu_i))
        f = np.asarray(od.brdf(m, jnp.array([3.0]), wi, wo, base=WHITE, eta=eta))[:, 0].reshape(64, 256)
        alb = np.sum(f.mean(axis=1) * mu_o * w_o) * 2.0 * np.pi
        top = 0.0 if eta is None else float(fresnel_dielectric(jnp.asarray(mu_i), eta)[0])
        assert abs(alb + top - 1.0) < 3e-3, (mu_i, alb, top)


@pytest.mark.parametrize("azimuth", ["fixed", "averaged"])
def test_reciprocity(azimuth):
    """f(wi, wo) = f(wo, wi) for a strongly tilted medium (theta_p = 52 deg, Matte 2's) under a
    dielectric over a base (the medium's sigma_s f is symmetric; the mixture's rotation average,
    interpolation and single scattering are symmetric): 1e-12. Rotation pairs that started at
    the rotation instead of centring on it broke this by up to 1.7e-3 (n_rot = 16)."""
    m = media([dict(theta=0.91)])
    a = od.brdf(m, jnp.array([1.5]), WI, WO, base=RHO, eta=1.4, azimuth=azimuth)
    b = od.brdf(m, jnp.array([1.5]), WO, WI, base=RHO, eta=1.4, azimuth=azimuth)
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12)


def test_horizon_gives_zero_with_finite_gradients():
    """Grazing and below-horizon directions give 0 in both azimuth modes (under a dielectric top,
    over a base) with finite derivatives in the thickness and the index."""
    m = media([{}])
    wi = Vec3(jnp.array([1.0, 0.6, 0.0]), jnp.array([0.0, 0.0, 0.0]), jnp.array([0.0, 0.8, -1.0]))
    wo = Vec3(jnp.array([0.6, 1.0, 0.6]), jnp.array([0.0, 0.0, 0.0]), jnp.array([0.8, 0.0, 0.8]))
    small = od.Settings(n_nodes=8, n_modes=4, n_az=16, n_rot=4, tilt_mu=4, tilt_phi=8)  # compiles fast

    def fn(t, eta):
        f = jnp.stack([od.brdf_traced(m, t, wi, wo, base=RHO, eta=eta, azimuth=a, settings=small)
                       for a in ("fixed", "averaged")])
        return f.sum(), f

    # the values are the primal of the derivative's program: one compilation; forward mode: 8x
    # faster to compile than reverse
    g, f = jax.jit(jax.jacfwd(fn, argnums=(0, 1), has_aux=True))(jnp.array([1.0]), jnp.asarray(1.3))
    assert np.all(np.asarray(f) == 0.0)
    assert all(np.all(np.isfinite(np.asarray(v))) for v in g)


def _fresnel_from_inside(mu, eta):
    """Unpolarised reflectance of light inside a host of index eta meeting its boundary with
    air at cosine mu (textbook s and p amplitudes; 1 beyond the critical angle)."""
    st2 = eta * eta * (1.0 - mu * mu)
    if st2 >= 1.0:
        return 1.0
    mt = np.sqrt(1.0 - st2)
    rs = (eta * mu - mt) / (eta * mu + mt)
    rp = (mu - eta * mt) / (mu + eta * mt)
    return 0.5 * (rs * rs + rp * rp)


def test_interface_weights_are_exact_and_differentiable_at_eta_one():
    """The interface's weights W_j = 2 pi int F l_j mu dmu against adaptive quadrature (SciPy,
    split at the critical cosine) of a textbook Fresnel term: 1e-12 for eta - 1 from 1e-4 to 1.5
    (the Gauss rule in mu over the kink was off by up to 8e-6). At eta = 1, the domain's end
    (no interface), W = 0 and the derivative is the right derivative, checked two ways: the
    closed form 2 pi (7/6) l_j(0), and the one-sided differences of the adaptive quadrature
    extrapolated to h -> 0 (W has an s^(3/2) term, s = 1 - 1/eta^2, so the differences carry
    sqrt(h) and h errors, removed by Richardson steps; the plain difference at h = 1e-6 is 5 % off).
    Before the fix the derivative at exactly eta = 1, the default, was 0."""
    from scipy.integrate import quad

    nodes, _ = np.polynomial.legendre.leggauss(12)
    nodes = 0.5 * (nodes + 1.0)
    js = (0, 4, 11)

    def lag(m, j):
        return np.prod([(m - nodes[k]) / (nodes[j] - nodes[k]) for k in range(nodes.size) if k != j])

    def ref(eta, j):
        mc = np.sqrt(max(0.0, 1.0 - 1.0 / eta**2))
        a = quad(lambda m: lag(m, j) * m, 0.0, mc, epsabs=1e-15, epsrel=1e-13)[0] if mc > 0 else 0.0
        pts = [mc + d for d in (1e-8, 1e-6, 1e-4, 1e-2) if mc + d < 1.0]
        b = quad(lambda m: _fresnel_from_inside(m, eta) * lag(m, j) * m, mc, 1.0, points=pts, epsabs=1e-15,
                 epsrel=1e-13, limit=400)[0]
        return 2.0 * np.pi * (a + b)

    def weights(eta):
        return od._interface_weights(nodes, eta, jnp.float64)

    for eta in (1.0001, 1.05, 1.5, 2.5):
        w = np.asarray(weights(jnp.asarray(eta)))
        np.testing.assert_allclose(w[list(js)], [ref(eta, j) for j in js], rtol=0, atol=1e-12)
    assert np.all(np.asarray(weights(jnp.asarray(1.0))) == 0.0)
    d_fwd = np.asarray(jax.jacfwd(weights)(jnp.asarray(1.0)))
    d_rev = np.asarray(jax.jacrev(weights)(jnp.asarray(1.0)))
    closed = 2.0 * np.pi * 7.0 / 6.0 * np.array([lag(0.0, j) for j in range(nodes.size)])
    np.testing.assert_allclose(d_fwd, closed, rtol=1e-12)
    np.testing.assert_allclose(d_rev, closed, rtol=1e-12)

    def one_sided(h):
        return np.array([ref(1.0 + h, j) for j in js]) / h  # W(1) = 0

    h = 1e-6
    r1 = [2.0 * one_sided(h / 4**(k + 1)) - one_sided(h / 4**k) for k in range(2)]  # sqrt(h) removed
    extrapolated = (4.0 * r1[1] - r1[0]) / 3.0  # then h (the next terms: 2e-5 of l_0 at this h)
    np.testing.assert_allclose(d_fwd[list(js)], extrapolated, rtol=3e-4)
    # without the extrapolation the plain difference is far off: the check has power
    assert np.max(np.abs(one_sided(h) / d_fwd[list(js)] - 1.0)) > 0.02


def test_bad_input_is_named():
    m = media([{}])
    with pytest.raises(ValueError, match="eta"):
        od.brdf(m, jnp.array([1.0]), WI, WO, eta=0.9)
    with pytest.raises(ValueError, match="n_nodes"):
        od.brdf(m, jnp.array([1.0]), WI, WO, settings=od.Settings(n_nodes=1))
    with pytest.raises(ValueError, match="n_az"):
        od.brdf(m, jnp.array([1.0]), WI, WO, settings=od.Settings(n_modes=24, n_az=32))
    with pytest.raises(ValueError, match="azimuth"):
        od.brdf(m, jnp.array([1.0]), WI, WO, azimuth="rotated")


@pytest.mark.slow
def test_random_walk_agreement_tilted_two_layers():
    """Tilted platelets (20 deg, alpha 0.35) over a second tilted layer (40 deg, alpha 0.5) over a
    base, oriented (azimuth fixed: the tilt correction's full-azimuth form), incidence 0-75 deg and
    out-of-plane directions: within 3.5 standard errors of a 16384-path, 512-step walk."""
    m = media([dict(theta=0.35, alpha=0.35, c_d=0.6), dict(theta=0.7, alpha=0.5, c_d=0.4, albedo_p=(0.7, 0.8, 0.9))])
    t = jnp.array([1.5, 3.0])
    th_i = np.deg2rad([0, 15, 30, 45, 60, 75.0, 30, 60])
    wi = Vec3(jnp.asarray(np.sin(th_i)), jnp.asarray(0 * th_i), jnp.asarray(np.cos(th_i)))
    wo = directions(8, 9, mu_min=0.2)
    f = np.asarray(od.brdf(m, t, wi, wo, base=RHO, azimuth="fixed"))
    from appearance_jax.bsdf import lambert
    from appearance_jax.layered.random_walk import Bottom
    fw, se = walk(m, t, wi, wo, jax.random.key(12), bottom=Bottom(lambert.MODEL, lambert.Params(reflectance=RHO)),
                  n_samples=16384, max_bounces=512)
    z = (f - np.asarray(fw)) / np.asarray(se)
    assert np.all(np.abs(z) < 3.5), z


def test_random_walk_agreement_two_layers_interface_base():
    """Independent reference: the position-free random walk (8192 paths per pair, 64
    steps) through two untilted layers (platelets over diffusers) under a dielectric (eta 1.4)
    over a Lambertian base, azimuth fixed; every value within 3.5 standard errors (fixed keys;
    the pairs x three bands of a call share their paths)."""
    m = media([dict(theta=0.0, alpha=0.25, c_d=0.5), dict(theta=0.0, c_d=1.0, albedo_d=(0.6, 0.8, 0.9), g1=0.4)])
    t = jnp.array([0.8, 1.5])
    wi = directions(6, 5, mu_min=0.2)
    wo = directions(6, 6, mu_min=0.2)
    f = np.asarray(od.brdf(m, t, wi, wo, base=RHO, eta=1.4, settings=NO_TILT))
    from appearance_jax.bsdf import lambert
    from appearance_jax.layered.random_walk import Bottom
    # two calls of three pairs, 8192 paths, 64 steps: the compiled two-layer walk of
    # tests/layered/test_random_walk.py (its STAT sizing). 64 steps: every z below is within 0.06
    # of its value after 128 steps (same keys; measured: max |z| 1.81 both; 2e-5 from 128 to 256)
    half = lambda w, h: Vec3(*(c[h] for c in w))  # noqa: E731
    runs = [walk(m, t, half(wi, h), half(wo, h), k, eta=jnp.array([1.4, 1.4]),
                 bottom=Bottom(lambert.MODEL, lambert.Params(reflectance=RHO)), n_samples=8192, max_bounces=64)
            for h, k in zip((slice(0, 3), slice(3, 6)), jax.random.split(jax.random.key(11)))]
    fw, se = (np.concatenate([np.asarray(r[i]) for r in runs]) for i in (0, 1))
    z = (f - fw) / se
    assert np.all(np.abs(z) < 3.5), z


def test_tilt_grid_algebra_modes_and_mirror_doubling():
    """The tilt correction's two shortcuts against the dense operators they replace: (1) a
    rotation-invariant grid kernel composes per azimuthal mode (the mixture's solve), (2) an
    oriented slab doubled with Rs = P R P, Ts = P T P (P: azimuth + pi) equals the general
    adding equations (kernel_ops.add with all four kernels and both direct beams)."""
    from appearance_jax.layered import kernel_ops as ko
    from appearance_jax.layered import ordinates_tilt as ot

    with jax.enable_x64(True):
        n_mu, n_phi = 3, 8
        mu, az, c, x = ot._grid(n_mu, n_phi, jnp.float64)
        rng = np.random.default_rng(7)

        def even_kappa():
            k = rng.uniform(size=(1, n_mu, n_mu, n_phi))
            return jnp.asarray(0.5 * (k + k[..., (-np.arange(n_phi)) % n_phi]))  # kappa(-k) = kappa(k)

        a, b = even_kappa(), even_kappa()
        c_x = c.reshape(n_mu, n_phi)[:, 0]

        # each part one compiled program (op by op, its ~170 small programs took ~9 s to compile)
        @jax.jit
        def part1(a, b):
            average = ot.rotation_average(ot._expand(a, n_phi), n_mu, n_phi)
            dense = ko.cmul(ot._expand(a, n_phi), ot._expand(b, n_phi), c, n_mu * n_phi)
            modes = ko.cmul(ot._to_modes(a), ot._to_modes(b), c_x, n_mu)
            return average, dense, ot._expand(ot._from_modes(modes, n_phi), n_phi)

        average, dense, from_modes = part1(a, b)
        np.testing.assert_allclose(np.asarray(average), np.asarray(a), atol=1e-15)
        np.testing.assert_allclose(np.asarray(from_modes), np.asarray(dense), rtol=1e-12, atol=1e-14)

        # (2) a tilted layer on a 3 x 6 grid
        n_mu, n_phi = 3, 6
        mu, az, c, _ = ot._grid(n_mu, n_phi, jnp.float64)
        m = od._layer(media([dict(theta=0.9, alpha=0.4)]), 0)
        opp = ot._opposite(n_mu, n_phi)
        t, levels, n = 3.0, 4, n_mu * n_phi

        @jax.jit
        def part2(m):
            K, ext, sig_s = ot._raw_kernels(m, mu, az)
            K = ot._balance(K, sig_s, c / mu, n_mu, n_phi)
            fast = ot._slab(K, ext, t, mu, c, n, levels, opp)
            a_up, a_dn = ext / mu, ext[opp] / mu
            t0 = t * 2.0 ** (-levels)
            inv = t0 / (mu[:, None] * mu[None, :])
            r = lambda ao, ai: inv * ko.phi(t0 * (ao[:, None] + ai[None, :]))  # noqa: E731
            tr = lambda ao, ai: jnp.exp(-t0 * ao)[:, None] * inv * ko.phi(t0 * (ai[None, :] - ao[:, None]))  # noqa: E731
            op = ko.Op(K["R"] * r(a_up, a_dn), K["T"] * tr(a_dn, a_dn), K["Rs"] * r(a_dn, a_up),
                       K["Ts"] * tr(a_up, a_up), jnp.exp(-t0 * a_dn), jnp.exp(-t0 * a_up))
            for level in range(levels):
                op = ko.add(op, op, c, n)
            return K, fast, op

        K, fast, op = part2(m)
        np.testing.assert_allclose(np.asarray(K["Rs"]), np.asarray(K["R"][:, opp][:, :, opp]), rtol=1e-10)
        for name in ("R", "T", "Rs", "Ts", "e", "es"):
            np.testing.assert_allclose(np.asarray(getattr(fast, name)), np.asarray(getattr(op, name)), rtol=1e-9,
                                       atol=1e-12, err_msg=name)
