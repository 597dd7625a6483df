"""Energy-conserving hair BCSDF of d'Eon et al. (2011) with the practical parametrisation and
importance sampling of Chiang et al. (2016): the model of pbrt-v3/v4 ``HairBSDF`` and of
Mitsuba 3's ``hair`` plugin.

A smooth dielectric cylinder (index ``eta``, absorption ``sigma_a`` per unit radius) lit at
offset h in [-1, 1] (h = sin gamma_i, see :mod:`appearance_jax.bcsdf.fiber`) scatters into
lobes p = 0 (R), 1 (TT), 2 (TRT) and a residual p >= 3; each lobe is a product of an
attenuation A_p(h, theta_i), a longitudinal lobe M_p and an azimuthal lobe N_p:

    S(wi, wo; h) = [ sum_{p<3} A_p M_p(theta_i^(p), theta_o) N_p(phi_o - phi_i - Phi(p, h))
                     + A_3 M_3(theta_i, theta_o) / (2 pi) ] / cos(theta_o)

* A_p: Fresnel at cos(theta_i) cos(gamma_i), chord 2 cos(gamma_t)/cos(theta_t), residual
  A_3 = A_2 f T / (1 - f T) (:func:`fiber.smooth_attenuation` with p_max = 3; Chiang Eqs. 3-6).
* M_p: d'Eon et al. 2011 Eq. 7, M = csch(1/v)/(2v) exp(-sin ti sin to / v) I0(cos ti cos to / v),
  evaluated for every v in the overflow-free form
  log M = log k - log(1 - e^(-2k)) - 2k sin^2((ti + to)/2) + log(I0e(k cos ti cos to)), k = 1/v
  (I0e(x) = e^-x I0(x); the log-I0 form of d'Eon's appendix, exact rather than asymptotic); the
  eval kernel takes its exponential, k / (1 - e^(-2k)) e^(-2k s^2) I0e(.), whose factors are all
  bounded (no log per pair).
  int M_p(ti, to) cos(to) dto = 1 for every ti. Variances (Chiang Eq. 7, pbrt):
  v0 = (0.726 b_m + 0.812 b_m^2 + 3.7 b_m^20)^2, v1 = v0/4, v2 = v3 = 4 v0.
* Cuticle tilt (Chiang Sec. 4.3, pbrt): theta_i^(p) = theta_i - 2 alpha, + alpha, + 4 alpha for
  R, TT, TRT (folded back into [-pi/2, pi/2], i.e. cos taken as |cos|); the residual is untilted.
* N_p: trimmed logistic on [-pi, pi] with scale s = sqrt(pi/8) (0.265 b_n + 1.194 b_n^2 +
  5.372 b_n^22) (Chiang Eqs. 8, 10-12), centred on Phi(p, h) = 2p gamma_t - 2 gamma_i + p pi;
  the residual is uniform, 1/(2 pi).

Conventions (library BCSDF convention, :mod:`appearance_jax.testing.directions`): the albedo is
int S cos(theta_o) dwo = sum_p A_p (= 1 for sigma_a = 0: the model is energy conserving), so S
carries 1/cos(theta_o). ``wi`` is the *given* direction (the one that fixes h, A_p and the tilt;
a renderer's camera-side direction) and ``wo`` the integrated / sampled one. pbrt's
``f(wo_pbrt, wi_pbrt)`` = S(wi=wo_pbrt, wo=wi_pbrt) cos(theta_o) / |cos(wi_pbrt, n)| and
Mitsuba's ``hair`` ``eval(si.wi=wi, wo)`` = S(wi, wo; h) cos(theta_o) with h =
:func:`offset_from_normal` (wi) (see tests/validation/test_mitsuba_hair.py).

Offset h (near field, as in Chiang 2016, pbrt and Mitsuba: one h per ray hit): ``eval``,
``pdf`` and ``sample`` take ``h`` (default 0, any array broadcasting against the directions).
With ``Params(far_field=True)`` h is integrated out, S_far = 1/2 int_{-1}^{1} S(h) dh, by an
``n_h``-point Gauss-Legendre rule (the sampler draws the node with probability w_k / 2, so the
mixture is sampled exactly and ``weight = S cos / pdf`` holds to rounding; narrow azimuthal
lobes, b_n < ~0.2, need n_h of a few hundred for a ripple-free far field).

Sampling (Chiang Sec. 4.4, pbrt): lobe p with probability proportional to the luminance
(Rec. 709, 3 bands; the band mean otherwise) of A_p, exact sampling of M_p (d'Eon's projected
von Mises-Fisher), exact sampling of the trimmed logistic. With sigma_a = 0 the lobe
probabilities equal A_p and every sample weight is exactly 1.
Not reciprocal in general (A_p and the tilt depend on theta_i only, N_p on h); see the tests.

| parameter | default           | range          | unit     | meaning                                    |
|-----------|-------------------|----------------|----------|--------------------------------------------|
| eta       | 1.55              | (1, 4]         | 1        | refractive index of the fiber (keratin)     |
| sigma_a   | (0.545, 0.906, 1.781) | [0, 1e3]   | 1/radius | absorption per band (eumelanin 1.3: brown) |
| beta_m    | 0.3               | (0, 1]         | 1        | longitudinal roughness                     |
| beta_n    | 0.3               | (0, 1]         | 1        | azimuthal roughness                        |
| alpha     | 0.0349 (2 deg)    | [-pi/8, pi/8]  | rad      | cuticle scale tilt                         |
| far_field | False             | {False, True}  | -        | integrate the offset h out (Gauss-Legendre) |
| n_h       | 32                | [2, 4096]      | -        | Gauss-Legendre nodes in h (far field)      |

``Params.from_melanin(eumelanin, pheomelanin)`` and ``Params.from_color(rgb, beta_n=...)`` set
sigma_a with :func:`fiber.melanin_sigma_a_rgb` (or the spectral form, given wavelengths) and
:func:`fiber.sigma_a_from_color` (Chiang Eq. 9).

Example::

    from appearance_jax.bcsdf import chiang
    from appearance_jax.core.frame import fiber_direction
    p = chiang.Params.from_melanin(0.3, 0.0, beta_m=0.1, beta_n=0.2)      # blond
    wi = fiber_direction(0.3, 0.0); wo = fiber_direction(-0.35, 2.5)
    S = chiang.eval(p, wi, wo, h=0.2)                                     # shape (3,), 1/sr
    S_far = chiang.eval(p.replace(far_field=True), wi, wo)                # h integrated out

Validation (flatland, closed forms, Mitsuba 3's ``hair``): docs/hair.md. In float32, atan2,
arcsin, exp I0e and the Fresnel term take the short forms of :mod:`appearance_jax.bcsdf.fast32`
(a few ulp; tests/bcsdf/test_chiang_fast32.py); float64 is computed as before.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import i0e

from ..core.frame import fiber_angles, fiber_direction
from ..core.model import Model, as_bands, boundary
from ..core.params import Bands, integer, param, params_class, Real, replace_unchecked, static
from ..core.rng import uniforms
from ..core.special import safe_asin, safe_sqrt
from ..core.spectral import luminance_or_mean
from ..core.vec import Vec3
from . import fast32, fiber

P_MAX = 3  # lobes R, TT, TRT + residual
_DEFAULT_SIGMA_A = tuple(1.3 * c for c in fiber.EUMELANIN_RGB)


def _bool(v):
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    raise ValueError("must be True or False")


@params_class
class Params:
    eta: Real = param(1.55, lo=1.0, hi=4.0, lo_open=True, unit="1", doc="refractive index of the fiber")
    sigma_a: Bands = param(_DEFAULT_SIGMA_A, lo=0.0, hi=1e3, unit="1/radius",
                            doc="absorption coefficient per unit radius, per band", bands=True)
    beta_m: Real = param(0.3, lo=0.0, hi=1.0, lo_open=True, unit="1", doc="longitudinal roughness")
    beta_n: Real = param(0.3, lo=0.0, hi=1.0, lo_open=True, unit="1", doc="azimuthal roughness")
    alpha: Real = param(math.radians(2.0), lo=-math.pi / 8, hi=math.pi / 8, unit="rad",
                          doc="cuticle scale tilt")
    far_field: bool = static(False, choices=(False, True), doc="integrate the offset h over [-1, 1]",
                             convert=_bool)
    n_h: int = static(32, doc="Gauss-Legendre nodes in h for the far field", convert=integer(2, 4096))

    @classmethod
    def from_melanin(cls, eumelanin, pheomelanin=0.0, wavelength_nm=None, **kw):
        """sigma_a from melanin concentrations: linear RGB (Chiang 2016 / pbrt / Mitsuba
        coefficients) or, given ``wavelength_nm``, the spectral form of seed-001 §1.3.13."""
        if wavelength_nm is None:
            s = fiber.melanin_sigma_a_rgb(eumelanin, pheomelanin)
        else:
            s = fiber.melanin_sigma_a_spectral(eumelanin, pheomelanin, wavelength_nm)
        return cls(sigma_a=np.asarray(s, dtype=float), **kw)

    @classmethod
    def from_color(cls, color, beta_n=0.3, **kw):
        """sigma_a giving the multiply scattered colour ``color`` (linear RGB, Chiang Eq. 9)."""
        return cls(sigma_a=np.asarray(fiber.sigma_a_from_color(color, beta_n), dtype=float),
                   beta_n=beta_n, **kw)


# ----------------------------------------------------------------------------------------
# lobe functions


def longitudinal_variances(beta_m):
    """(v0, v1, v2, v3) of the R, TT, TRT and residual lobes (Chiang 2016 Eq. 7; pbrt)."""
    b = jnp.asarray(beta_m)
    v0 = (0.726 * b + 0.812 * b * b + 3.7 * b ** 20) ** 2
    return v0, 0.25 * v0, 4.0 * v0, 4.0 * v0


def azimuthal_scale(beta_n):
    """Logistic scale s = sqrt(pi/8) (0.265 b + 1.194 b^2 + 5.372 b^22) (Chiang 2016 Eq. 8)."""
    b = jnp.asarray(beta_n)
    return math.sqrt(math.pi / 8.0) * (0.265 * b + 1.194 * b * b + 5.372 * b ** 22)


def longitudinal_lobe(theta_i, theta_o, v):
    """d'Eon et al. 2011 M(theta_i, theta_o; v), in the overflow-free log form (docstring).

    Normalised as int M cos(theta_o) dtheta_o = 1; symmetric in (theta_i, theta_o).
    Both angles in [-pi/2, pi/2].
    """
    k = 1.0 / v
    x = k * jnp.cos(theta_i) * jnp.cos(theta_o)
    s = jnp.sin(0.5 * (theta_i + theta_o))
    log_m = jnp.log(k) - jnp.log(-jnp.expm1(-2.0 * k)) - 2.0 * k * s * s + jnp.log(i0e(jnp.maximum(x, 0.0)))
    return jnp.exp(log_m)


def azimuthal_lobe(dphi, s):
    """Trimmed logistic on [-pi, pi] of scale s, of the wrapped offset ``dphi`` (Chiang Eq. 12);
    int N dphi = 1 over one period."""
    # 1/s and the normalisation are per-lobe scalars: no division per element
    inv_s, norm = 1.0 / s, 1.0 / (s * jnp.tanh(jnp.pi / (2.0 * s)))
    e = jnp.exp(-jnp.abs(fiber.wrap_pi(dphi)) * inv_s)
    return e / (1.0 + e) ** 2 * norm


def _sample_trimmed_logistic(u, s):
    """Inverse CDF of the trimmed logistic on [-pi, pi] (Chiang Eq. 13)."""
    k = jnp.tanh(jnp.pi / (2.0 * s))
    c_lo = 1.0 / (1.0 + jnp.exp(jnp.pi / s))
    q = jnp.clip(u * k + c_lo, 1e-300, 1.0)
    x = -s * jnp.log(jnp.maximum(1.0 / q - 1.0, 1e-300))
    return jnp.clip(x, -jnp.pi, jnp.pi)


def _fold(theta):
    """An angle shifted by the tilt, folded back into [-pi/2, pi/2] (sin kept, cos -> |cos|)."""
    return jnp.where(theta > jnp.pi / 2, jnp.pi - theta, jnp.where(theta < -jnp.pi / 2, -jnp.pi - theta, theta))


def tilted_angles(theta_i, alpha):
    """theta_i of the R, TT, TRT and residual lobes: theta_i - 2a, + a, + 4a, + 0 (pbrt/Mitsuba
    signs; Chiang 2016 Sec. 4.3), stacked on a leading axis."""
    shifts = (-2.0 * alpha, alpha, 4.0 * alpha, 0.0 * alpha)
    return jnp.stack([_fold(theta_i + a) for a in shifts])


def offset_from_normal(wi: Vec3):
    """The offset h that Mitsuba 3's ``hair`` (and a renderer hitting a fiber whose normal at
    the hit point is +z) uses: h = sin(gamma_i) = -wi.y / sqrt(wi.y^2 + wi.z^2), so that the R lobe
    is centred on the mirror direction about +z. 0 for wi along the fiber."""
    r2 = wi.y * wi.y + wi.z * wi.z
    ok = r2 > 0
    return jnp.where(ok, -wi.y / jnp.sqrt(jnp.where(ok, r2, 1.0)), 0.0)


def _lobe_probabilities(A):
    """Lobe selection probabilities from A_p (shape (4, ..., bands)) -> (4, ...)."""
    w = luminance_or_mean(A)
    tot = jnp.sum(w, axis=0)
    return jnp.where(tot > 0, w / jnp.where(tot > 0, tot, 1.0), jnp.where(jnp.arange(4) == 0, 1.0, 0.0)
                     .reshape((4,) + (1,) * (w.ndim - 1)))


def _store(tree):
    """The arrays of ``tree`` unchanged (x / 1 = x exactly), computed once and stored: the shared
    values that XLA:CPU would otherwise fuse into, and recompute in, each consumer.

    Not :func:`core.fusion.materialize`: its divisor is a scalar, and XLA's simplifier turns a
    division by a broadcast scalar into a multiplication by its reciprocal, which it then
    duplicates like any cheap op (seen here: the atan2 of phi_o - phi_i recomputed in each of
    the three N_p). A per-element divisor ``where(v == v, 1, 1)`` is not folded (v == v is
    false for NaN), so the divide, and the store, stay."""
    one = jax.lax.optimization_barrier(jnp.ones((), jnp.result_type(float)))

    def keep(v):
        v = jnp.asarray(v)
        return v / jnp.where(v == v, one.astype(v.dtype), 1.0)

    return jax.tree.map(keep, tree)


def _m_lobes(p: Params, si, ci, so, co):
    """[M_p], p = R, TT, TRT, residual, from sines and cosines (ci, co >= 0): the tilted lobes by
    angle addition, sin^2((ti + to)/2) as a squared chord (no cancellation near the specular
    cone), exp(-2k s^2) I0e(k cp co) as one exponential (:func:`fast32.exp_i0e`)."""
    M = []
    for shift, v in zip((-2.0 * p.alpha, p.alpha, 4.0 * p.alpha, 0.0 * p.alpha), longitudinal_variances(p.beta_m)):
        ca, sa = jnp.cos(shift), jnp.sin(shift)
        sp = si * ca + ci * sa            # sin(theta_i + a_p)
        cp = jnp.abs(ci * ca - si * sa)   # |cos(theta_i + a_p)|: the fold of _fold
        k = 1.0 / v
        s2 = 0.25 * ((cp - co) ** 2 + (sp + so) ** 2)  # sin^2((tp + to)/2) = |(cp, sp) - (co, -so)|^2 / 4
        M.append(k / -jnp.expm1(-2.0 * k) * fast32.exp_i0e(-2.0 * k * s2, k * cp * co))
    return M


def _n_lobes(p: Params, dphi, h, eta_p):
    """[N_p], p = R, TT, TRT, residual (uniform), of phi_o - phi_i = ``dphi``. gamma_i and gamma_t
    are stored once (_store): fused into each lobe, XLA:CPU would recompute both arcsines
    three times."""
    s = azimuthal_scale(p.beta_n)
    g_i, g_t = _store((fast32.asin(h), fast32.asin(h / eta_p)))
    N = [azimuthal_lobe(dphi - fiber.exit_azimuth_of(j, g_i, g_t), s) for j in range(P_MAX)]
    N.append(jnp.full(jnp.shape(N[0]), 1.0 / (2.0 * jnp.pi), dtype=N[0].dtype))
    return N


def _lobe_terms(p: Params, si, ci, so, co, dphi, h):
    """Per-lobe lists [A_p (..., bands)], [M_p (...)], [N_p (...)], p = R, TT, TRT, residual, from
    sines and cosines (ci, co >= 0) and phi_o - phi_i. Lists, not arrays stacked on a lobe axis:
    XLA:CPU runs elementwise work broadcast over a leading lobe axis (and reductions over it)
    several times slower than the same work written per lobe (measured: M_p 32 ms vs 6 ms per
    1e6 pairs)."""
    A = fiber.smooth_attenuation_sc(h, si, ci, p.eta, as_bands(p.sigma_a), p_max=P_MAX)
    N = _n_lobes(p, dphi, h, fiber.bravais_eta_sc(p.eta, si, ci))
    return [A[j] for j in range(P_MAX + 1)], _m_lobes(p, si, ci, so, co), N


def _direction_sc(wi: Vec3, wo: Vec3):
    """(sin ti, cos ti, sin to, cos to, phi_o - phi_i) straight from the components (one atan2)."""
    shape = jnp.broadcast_shapes(jnp.shape(wi.x), jnp.shape(wo.x))
    ci = jnp.sqrt(wi.y * wi.y + wi.z * wi.z)
    co = jnp.sqrt(wo.y * wo.y + wo.z * wo.z)
    dphi = fast32.atan2(wi.y * wo.z - wi.z * wo.y, wi.y * wo.y + wi.z * wo.z)
    return tuple(jnp.broadcast_to(a, shape) for a in (wi.x, ci, wo.x, co, dphi))


def _gl(n):
    x, w = np.polynomial.legendre.leggauss(int(n))
    return x, 0.5 * w  # weights of the average over h in [-1, 1]


def _sum_terms(p: Params, wi: Vec3, wo: Vec3, h):
    """(sum_p A_p M_p N_p (..., bands), sum_p P_p M_p N_p (...), cos theta_o), near or far field."""
    si, ci, so, co, dphi = _direction_sc(wi, wo)
    if p.far_field:
        x, w = _gl(p.n_h)
        A, M, N = (jnp.stack(t) for t in _lobe_terms(p, si[..., None], ci[..., None], so[..., None], co[..., None],
                                                      dphi[..., None], jnp.asarray(x, dtype=si.dtype)))
        MN = M * N  # (4, ..., n_h)
        wq = jnp.asarray(w, dtype=si.dtype)
        f = jnp.einsum("p...kb,p...k,k->...b", A, MN, wq)
        pdf = jnp.einsum("p...k,p...k,k->...", _lobe_probabilities(A), MN, wq)
    else:
        h = jnp.broadcast_to(jnp.asarray(h, dtype=si.dtype), si.shape)
        A, M, N = _lobe_terms(p, si, ci, so, co, dphi, h)
        # materialised before the per-band sums: fused into the (..., bands) loop, XLA:CPU would
        # re-derive M_p N_p for every band (measured ~10 % faster this way)
        MN = jax.lax.optimization_barrier([m * n for m, n in zip(M, N)])
        P = _lobe_probabilities(jnp.stack(A))
        f = sum(a * mn[..., None] for a, mn in zip(A, MN))
        pdf = sum(P[j] * MN[j] for j in range(P_MAX + 1))
    return f, pdf, co


def _finite(x):
    return jnp.where(jnp.isfinite(x), x, 0.0)


def _eval(p: Params, wi: Vec3, wo: Vec3, h=0.0):
    if not p.far_field:
        return _eval_near(p, wi, wo, h)
    f, _, cos_o = _sum_terms(p, wi, wo, h)
    ok = (cos_o > 0)[..., None]
    return _finite(jnp.where(ok, f / jnp.where(ok, cos_o[..., None], 1.0), 0.0))


# pairs per step of the near-field eval loop: the ~30 intermediates of one step (256 kB each in
# float32) stay in cache, and a 1e6-pair batch takes 16 steps of ~25 XLA kernels each (measured
# on a 2-core EPYC, interleaved runs: 65536 best; 131072 and 32768 1.0-1.2x, 8192 1.2-1.5x slower)
_CHUNK = 65536
_GROUPS = 16  # see _eval_near


def _per_pair(p: Params, names, values):
    """``p`` with the per-pair parameters ``names`` set to ``values`` (no checks: traced)."""
    return replace_unchecked(p, **dict(zip(names, values))) if names else p


def _near_bands(p: Params, wix, wiy, wiz, wox, woy, woz, h, sigma_a):
    """S(wi, wo; h) bands first: (bands,) + shape of the inputs (all of one shape); ``sigma_a``
    is (bands,) + that shape or broadcasts to it. The band-independent factors are stored
    (_store) before the per-band sums: XLA:CPU would otherwise fuse them, M_p's polynomials
    included, into the band loop and recompute them for every band."""
    si, ci, so, co, dphi = _direction_sc(Vec3(wix, wiy, wiz), Vec3(wox, woy, woz))
    f, chord = fiber.attenuation_factors(h, si, ci, p.eta)
    M = _m_lobes(p, si, ci, so, co)
    N = _n_lobes(p, _store(dphi), h, fiber.bravais_eta_sc(p.eta, si, ci))
    ok = co > 0
    inv_co = jnp.where(ok, 1.0 / jnp.where(ok, co, 1.0), 0.0)
    w = _store([m * n * inv_co for m, n in zip(M, N)])
    f, chord = _store((f, chord))
    A = fiber.lobe_attenuations(f, jnp.exp(-sigma_a * chord), p_max=P_MAX)
    return _finite(sum(a * wj for a, wj in zip(A, w)))


def _eval_near(p: Params, wi: Vec3, wo: Vec3, h):
    """Near-field eval on one flat batch axis (directions, h and any per-pair parameter
    broadcast and flattened), in steps of _CHUNK pairs (fori_loop), each computed bands first
    (:func:`_near_bands`) and written into the (n, bands) result band by band. Float32 takes
    the short special functions of :mod:`fast32` (float64: the exact ones).

    Why (measured, 1e6 float32 pairs, XLA:CPU, benchmarks/hair_throughput.py): a minor band
    axis of 3 keeps the per-band loops from vectorising, and XLA fuses the whole per-pair
    computation into them (3x the work); every intermediate of a 1e6-pair batch is a fresh
    4 MB buffer whose page faults cost about as much as the arithmetic (the 40-odd
    intermediates of this kernel: ~half its time). In steps of _CHUNK pairs they stay in cache.
    Bands-major blocks gathered by one transpose at the end cost a further 12 MB copy."""
    sig = as_bands(p.sigma_a)
    nb = sig.shape[-1]
    cols = [wi.x, wi.y, wi.z, wo.x, wo.y, wo.z, h]
    scal = {k: jnp.asarray(getattr(p, k)) for k in ("eta", "beta_m", "beta_n", "alpha")}
    batch = jnp.broadcast_shapes(*(jnp.shape(c) for c in cols), *(v.shape for v in scal.values()), sig.shape[:-1])
    n = math.prod(batch)
    dtype = jnp.result_type(*cols, float)
    cols = [jnp.broadcast_to(jnp.asarray(c, dtype), batch).reshape(n) for c in cols]
    # parameters that vary per pair ride along the batch axis; constant ones stay scalars
    per_pair = [k for k, v in scal.items() if v.ndim]
    cols += [jnp.broadcast_to(scal[k], batch).reshape(n) for k in per_pair]
    if sig.ndim > 1:
        cols += list(jnp.moveaxis(jnp.broadcast_to(sig, batch + (nb,)).reshape(n, nb), -1, 0))
    if n <= _CHUNK:
        s_a = jnp.stack(cols[7 + len(per_pair):]) if sig.ndim > 1 else sig[:, None]
        return _near_bands(_per_pair(p, per_pair, cols[7:]), *cols[:7], s_a).T.reshape(batch + (nb,))
    # (groups, m) with the steps along m: a batch split over devices (contiguous shards) is
    # split along the groups, so that each device steps through its own pairs (stepping
    # along a sharded axis would gather the whole batch on every device)
    g = _GROUPS
    while n % g:
        g //= 2
    m, c = n // g, max(_CHUNK // g, 1)
    cols = [x.reshape(g, m) for x in cols]
    sig_const = sig.reshape(nb, 1, 1) if sig.ndim == 1 else None

    def run(xs):
        s_a = jnp.stack(xs[7 + len(per_pair):]) if sig.ndim > 1 else sig_const
        return _near_bands(_per_pair(p, per_pair, xs[7:]), *xs[:7], s_a)

    steps, last = -(-m // c), m - c  # m > c (n > _CHUNK)

    def step(i, out):  # the last step starts at m - c: it overlaps the one before, no padding
        start = jnp.minimum(i * c, last)
        # checkpointed, the slicing included: reverse mode keeps only the step index per step and
        # recomputes the block (storing the ~40 intermediates of 1e6 pairs made grad 2.5x slower)
        block = jax.checkpoint(lambda st: run([jax.lax.dynamic_slice_in_dim(x, st, c, axis=1) for x in cols]))(start)
        for b in range(nb):  # one strided column per band: no (bands, ...) -> (..., bands) copy
            out = jax.lax.dynamic_update_slice(out, block[b][..., None], (0, start, b))
        return out

    out_dtype = jax.eval_shape(run, [x[:, :c] for x in cols]).dtype
    out = jax.lax.fori_loop(0, steps, step, jnp.zeros((g, m, nb), out_dtype))
    return out.reshape(batch + (nb,))


def _pdf(p: Params, wi: Vec3, wo: Vec3, h=0.0):
    _, pdf, _ = _sum_terms(p, wi, wo, h)
    return _finite(pdf)


def _eval_pdf(p: Params, wi: Vec3, wo: Vec3, h=0.0):
    """(S cos(theta_o), pdf) at once (what the sampler's weight needs)."""
    f, pdf, _ = _sum_terms(p, wi, wo, h)
    return _finite(f), _finite(pdf)


def _sample(p: Params, wi: Vec3, u, h=0.0):
    """Uniforms, in order: lobe, longitudinal (2), azimuth, far-field node (5 in all)."""
    shape = jnp.shape(wi.x)
    u_lobe, u_m1, u_m2, u_phi, u_h = uniforms(u, shape, 5)
    theta_i, phi_i = fiber_angles(wi)
    if p.far_field:
        x, w = _gl(p.n_h)
        cdf = jnp.asarray(np.cumsum(w)[:-1], dtype=theta_i.dtype)
        k = jnp.sum(u_h[..., None] >= cdf, axis=-1)
        hs = jnp.asarray(x, dtype=theta_i.dtype)[k]
    else:
        hs = jnp.broadcast_to(jnp.asarray(h, dtype=theta_i.dtype), shape)
    A = fiber.smooth_attenuation(hs, theta_i, p.eta, as_bands(p.sigma_a), p_max=P_MAX)
    P = _lobe_probabilities(A)  # (4, ...)
    cdf_p = jnp.cumsum(P, axis=0)
    lobe = jnp.sum(u_lobe[None] >= cdf_p[:P_MAX], axis=0)  # 0..3
    onehot = jnp.arange(P_MAX + 1).reshape((4,) + (1,) * len(shape)) == lobe[None]
    v = jnp.stack(jnp.broadcast_arrays(*longitudinal_variances(p.beta_m)))
    v = jnp.sum(jnp.where(onehot, v.reshape((4,) + (1,) * len(shape)), 0.0), axis=0)
    theta_ip = jnp.sum(jnp.where(onehot, tilted_angles(theta_i, p.alpha), 0.0), axis=0)
    # longitudinal: d'Eon's projected von Mises-Fisher about -theta_ip (exact sampling of M_p)
    u1 = jnp.maximum(u_m1, 1e-300)
    cos_t = 1.0 + v * jnp.log(u1 + (1.0 - u1) * jnp.exp(-2.0 / v))
    sin_t = safe_sqrt(1.0 - cos_t * cos_t)
    sin_to = -cos_t * jnp.sin(theta_ip) + sin_t * jnp.cos(2.0 * jnp.pi * u_m2) * jnp.cos(theta_ip)
    theta_o = safe_asin(sin_to)
    # azimuth: trimmed logistic about Phi(p, h), uniform for the residual
    eta_p = fiber.bravais_eta(p.eta, theta_i)
    centre = fiber.exit_azimuth(jnp.minimum(lobe, P_MAX - 1), hs, eta_p)
    dphi = jnp.where(lobe < P_MAX, centre + _sample_trimmed_logistic(u_phi, azimuthal_scale(p.beta_n)),
                     2.0 * jnp.pi * u_phi)
    wo = fiber_direction(theta_o, phi_i + dphi)
    f_cos, pdf = _eval_pdf(p, wi, wo, h)
    ok = (pdf > 0) & jnp.isfinite(pdf)
    weight = jnp.where(ok[..., None], f_cos / jnp.where(ok, pdf, 1.0)[..., None], 0.0)
    return wo, _finite(weight), jnp.where(ok, pdf, 0.0)


def _lobes(p: Params, wi: Vec3, wo: Vec3, h=0.0):
    """Per-lobe factors (A_p (4, ..., bands), M_p (4, ...), N_p (4, ...)) at offset h (near field)."""
    si, ci, so, co, dphi = _direction_sc(wi, wo)
    terms = _lobe_terms(p, si, ci, so, co, dphi, jnp.broadcast_to(jnp.asarray(h, dtype=si.dtype), si.shape))
    return tuple(jnp.stack(t) for t in terms)


def _with_h(fn):
    """Public entry: validates ``h`` (finite, in [-1, 1]) eagerly, like the parameters."""
    from ..core.params import ParamSpec, check_value

    spec = ParamSpec(-1.0, 1.0, unit="1", doc="fiber offset h = sin(gamma_i)")

    def public(params, *args, h=0.0):
        check_value("chiang.h", h, spec)
        return fn(params, *args, h=h)

    public.__doc__ = fn.__doc__
    public.__name__ = fn.__name__
    public.kernel = fn.kernel
    return public


eval = _with_h(boundary(_eval, Params))
pdf = _with_h(boundary(_pdf, Params))
sample = _with_h(boundary(_sample, Params))
eval_pdf = _with_h(boundary(_eval_pdf, Params))
lobes = _with_h(boundary(_lobes, Params))

PRESETS = {
    "brown": Params.from_melanin(1.3, 0.0),
    "blond": Params.from_melanin(0.3, 0.0, beta_m=0.1, beta_n=0.2),
    "black": Params.from_melanin(8.0, 0.0, beta_m=0.6, beta_n=0.8),
    "red": Params.from_melanin(0.3, 1.2),
    "white": Params(sigma_a=0.0),
}

MODEL = Model(
    name="chiang_hair",
    kind="bcsdf",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="energy-conserving hair BCSDF (R, TT, TRT + residual), d'Eon M_p, logistic N_p, tilt",
    source="d'Eon et al. 2011; Chiang et al. 2016 (pbrt-v3, Mitsuba 3 'hair')",
    reciprocal=False,
    transmissive=True,
    presets=PRESETS,
)
