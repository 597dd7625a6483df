"""Padrón's feather fibre BCSDF (Padrón 2025 Eqs. 5.1-5.3 [T:962-994]): a barb or barbule as a straight
fibre with an elliptical keratin cortex and, for barbs, an off-centre diffuse medulla, whose delta lobes
are traced in the cross-section and spread by Gaussian detectors.

For an offset h drawn uniformly in [h_lo, h_hi] (the visible part of the projected width; the feather's
masking supplies it, [-1, 1] for a whole fibre), :func:`appearance_jax.flatland.trace` follows the ray in
its deterministic split mode: at every cortex crossing the part that leaves is a lobe k with amplitude
A_k (bands) and direction (Theta_k, Phi_k); Beer-Lambert absorption sigma_a inside the cortex; at the
medulla (a Lambertian reflector of albedo d_m, spec decision D7) a cosine-distributed bounce about the
medulla's normal. The first ``n_lobes`` = K lobes are kept (K = 5 in the thesis [T:992]); what is
still inside then, or leaves later, is discarded (:func:`lobes` reports it). One h gives (Padrón Eq. 5.2,
spec M21)

    "gaussian" (the thesis' literal form, Padrón Eq. 5.1 with its cos^-2 theta_i):
        S_h = D(phi_i) cos^-2(theta_i) sum_k A_k G_M(theta_o - Theta_k | beta_m) G_N(phi_o - Phi_k | beta_n)
    "gaussian_cos" (default) and "deon" (normalised longitudinal factors L_k, int L_k cos = 1):
        S_h = D(phi_i) sum_k A_k L_k(theta_o) G_N(phi_o - Phi_k | beta_n) / cos(theta_o)

with the detectors of :mod:`appearance_jax.bcsdf.detectors`. The normalised forms follow the library's
BCSDF convention (the albedo int S cos(theta_o) dw_o is D sum_k A_k, so a lossless circular fibre with
all its lobes kept is white); on the specular cone (Theta_k = -theta_i) and for narrow beta_m they
equal the literal form, whose cos^-2(theta_i) is the projected solid angle of that cone [T:970], and
differ for the medulla's off-cone lobes. D(phi_i) is the cortex's projected half width seen from
omega_i in units of its horizontal semi-axis (1 for a circle; ``projected_width=False`` sets D = 1, as
inside the feather BSDF [T:1004]).

``eval`` is a Monte Carlo estimator over h (``Model.stochastic``): ``n_h`` stratified offsets, the same
for every direction pair (common random numbers; a fixed default key), returning ``(S, stderr)``.
``sample`` draws one h, picks lobe k with probability proportional to lum(A_k) [T:994], theta_o from
G_M truncated to [-pi/2, pi/2] and phi_o from G_N; its weight is S_h cos(theta_o) / pdf_h with the
same lobe set (unbiased for S cos(theta_o)); ``pdf`` is the stochastic mixture density over ``n_h``
offsets (1/sr).

Derivatives are those of the estimator at its fixed offsets and bounces (common random numbers): exact
for eta, sigma_a, beta_m, beta_n and d_m. With a medulla, an offset switches between hitting and missing
it as the medulla's size, position or the cortex's eccentricity change; the estimate is piecewise in
those fields and its derivative omits the switches (docs/feathers.md, the fibre-fit stand-in).

Geometry (spec D13, D17): fibre frame of :mod:`appearance_jax.core.frame` (x = fibre axis, the
cross-section is the (y, z) plane, z = the vane normal); the cortex ellipse has semi-axis 1 along y and
``eccentricity`` = e >= 1 along z; lengths and sigma_a are per unit horizontal semi-axis. The medulla
is the ellipse of semi-axes (``medulla_a`` along y, ``medulla_b`` along z) centred at (``medulla_y``,
``medulla_z``); it must lie strictly inside the cortex.

| parameter       | default              | range        | unit   | meaning                                         |
|-----------------|----------------------|--------------|--------|-------------------------------------------------|
| eta             | 1.53                 | (1, 3]       | 1      | cortex index eta_c (beta-keratin) [T:1069]       |
| sigma_a         | (0.133, 1.967, 2.1)  | [0, inf)     | 1/unit | cortex absorption per band [T:1069]              |
| beta_m          | 0.13                 | (0, 1.5]     | rad    | longitudinal detector width [T:1069]             |
| beta_n          | 0.12                 | (0, 1.5]     | rad    | azimuthal detector width [T:1069]                |
| eccentricity    | 1.0                  | [1, 10]      | 1      | cortex axis ratio b_c / a_c (vertical / horizontal) |
| medulla_a, _b   | 0.6, 0.6             | (0, 10)      | unit   | medulla semi-axes along y, z (with ``medulla``)  |
| medulla_y, _z   | 0, 0                 | (-10, 10)    | unit   | medulla centre (Fig. 5.7: (-0.1, 0.1))           |
| medulla_albedo  | 1.0                  | [0, 1]       | 1      | d_m per band (white to spongy-layer blue)        |
| h_lo, h_hi      | -1, 1                | [-1, 1]      | 1      | visible offset range, h_lo < h_hi                |
| medulla         | False                | bool         | -      | barb (True) or barbule / plain cortex (False)    |
| n_lobes         | 5                    | >= 1         | -      | K lobes kept [T:992]                             |
| max_events      | 16                   | >= n_lobes   | -      | tracer events (medulla bounces emit no lobe)     |
| n_h             | 32                   | >= 1         | -      | offsets per evaluation (stratified)              |
| longitudinal    | "gaussian_cos"       | see above    | -      | longitudinal detector form                       |
| projected_width | True                 | bool         | -      | D(phi_i) (True) or D = 1 (inside the feather BSDF) |

Example::

    from appearance_jax.bcsdf import feather_fiber as ff
    from appearance_jax.core.frame import fiber_direction
    p = ff.Params(eccentricity=1.6, medulla=True, medulla_y=-0.1, medulla_z=0.1,
                  medulla_albedo=(0.3, 0.5, 0.9))
    S, se = ff.eval(p, fiber_direction(0.78, 0.0), fiber_direction(-0.7, 2.0))   # (3,) 1/sr
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..core.frame import fiber_angles, fiber_direction
from ..core.model import Model, boundary
from ..core.params import Bands, integer, param, params_class, Real, static, validate
from ..core.rng import as_key, is_prng_key
from ..core.spectral import luminance_or_mean
from ..core.vec import as_directions, Vec3
from ..flatland import geometry as G
from ..flatland import tracer
from ..flatland.section import Interface, Medium, Section, Shape
from . import detectors

_TINY = 1e-12
_DEFAULT_KEY = 20251


@params_class
class Params:
    eta: Real = param(1.53, lo=1.0, hi=3.0, lo_open=True, unit="1", doc="cortex refractive index eta_c")
    sigma_a: Bands = param((0.133, 1.967, 2.1), lo=0.0, unit="1/unit", bands=True,
                           doc="cortex absorption per unit horizontal semi-axis")
    beta_m: Real = param(0.13, lo=0.0, hi=1.5, lo_open=True, unit="rad", doc="longitudinal detector width")
    beta_n: Real = param(0.12, lo=0.0, hi=1.5, lo_open=True, unit="rad", doc="azimuthal detector width")
    eccentricity: Real = param(1.0, lo=1.0, hi=10.0, unit="1", doc="cortex axis ratio b_c / a_c (z over y)")
    medulla_a: Real = param(0.6, lo=0.0, hi=10.0, lo_open=True, hi_open=True, unit="unit",
                            doc="medulla semi-axis along y")
    medulla_b: Real = param(0.6, lo=0.0, hi=10.0, lo_open=True, hi_open=True, unit="unit",
                            doc="medulla semi-axis along z")
    medulla_y: Real = param(0.0, lo=-10.0, hi=10.0, lo_open=True, hi_open=True, unit="unit",
                            doc="medulla centre, y")
    medulla_z: Real = param(0.0, lo=-10.0, hi=10.0, lo_open=True, hi_open=True, unit="unit",
                            doc="medulla centre, z")
    medulla_albedo: Bands = param(1.0, lo=0.0, hi=1.0, unit="1", bands=True, doc="medulla albedo d_m")
    h_lo: Real = param(-1.0, lo=-1.0, hi=1.0, unit="1", doc="visible offsets: lower end")
    h_hi: Real = param(1.0, lo=-1.0, hi=1.0, unit="1", doc="visible offsets: upper end")
    medulla: bool = static(False, choices=(False, True), doc="a medulla (barb) or none (barbule)")
    n_lobes: int = static(5, doc="lobes kept per offset (K)", convert=integer(1))
    max_events: int = static(16, doc="tracer events per offset", convert=integer(1))
    n_h: int = static(32, doc="stratified offsets per evaluation", convert=integer(1))
    longitudinal: str = static("gaussian_cos", choices=detectors.LONGITUDINAL_KINDS,
                               doc="longitudinal detector form")
    projected_width: bool = static(True, choices=(False, True), doc="D(phi_i), or D = 1")

    def _validate(self):
        lo, hi = np.asarray(self.h_lo, np.float64), np.asarray(self.h_hi, np.float64)
        if np.any(lo >= hi):
            raise ValueError(f"feather_fiber.Params: h_lo = {self.h_lo}, h_hi = {self.h_hi}: need h_lo < h_hi "
                             "(a non-empty visible offset range in [-1, 1])")
        if self.max_events < self.n_lobes:
            raise ValueError(f"feather_fiber.Params: max_events = {self.max_events} < n_lobes = {self.n_lobes}: "
                             "each kept lobe needs an event")
        if self.medulla:
            check_medulla("feather_fiber.Params", self.eccentricity, self.medulla_a, self.medulla_b,
                          self.medulla_y, self.medulla_z)


def check_medulla(label, eccentricity, a, b, y, z):
    """Raise a ValueError naming the values unless the medulla ellipse (semi-axes a, b centred at (y, z))
    lies strictly inside the cortex (semi-axes 1, ``eccentricity``); traced values are not checked."""
    if any(isinstance(v, jax.core.Tracer) for v in (eccentricity, a, b, y, z)):
        return
    # the medulla's extreme point in every direction must be inside the cortex y^2 + z^2 / e^2 < 1:
    # sample its boundary densely (an ellipse inside an ellipse: no closed form worth its branches)
    t = np.linspace(0.0, 2.0 * np.pi, 721)
    f = lambda v: np.asarray(v, np.float64)[..., None]  # noqa: E731
    py, pz = f(y) + f(a) * np.cos(t), f(z) + f(b) * np.sin(t)
    if np.any(py * py + (pz / f(eccentricity)) ** 2 >= 1.0 - 1e-9):
        raise ValueError(
            f"{label}: the medulla (semi-axes {a}, {b} at ({y}, {z})) is not strictly inside the cortex "
            f"(semi-axes 1, eccentricity = {eccentricity}): shrink it or move its centre")


def section(p: Params, medulla_present=None) -> Section:
    """The cross-section traced by :func:`lobes`: the cortex (and the medulla when ``p.medulla``).
    ``medulla_present``: None, or a traced bool that removes the medulla as data (``Shape.present``), so a
    barb and its barbules run one compiled trace (``bsdf.feather``)."""
    f = lambda v: jnp.asarray(v, dtype=jnp.result_type(float))  # noqa: E731
    cortex = Shape(f(0.0), f(0.0), f(1.0), f(p.eccentricity), f(0.0), Interface("dielectric"), inside=1, outside=0)
    media = [Medium(f(1.0), f(0.0)), Medium(f(p.eta), f(p.sigma_a))]
    shapes = [cortex]
    if p.medulla:
        media.append(Medium(f(p.eta), f(0.0)))
        shapes.append(Shape(f(p.medulla_y), f(p.medulla_z), f(p.medulla_a), f(p.medulla_b), f(0.0),
                            Interface("diffuse", albedo=f(p.medulla_albedo)), inside=2, outside=1,
                            present=medulla_present))
    return Section(tuple(shapes), tuple(media))


class Lobes(NamedTuple):
    """The kept lobes of rays launched at offsets h: event arrays (max_events, N) (+ bands), zero where
    no kept lobe left."""

    amplitude: jax.Array   # A_k per band, (E, N, bands)
    theta: jax.Array       # Theta_k [rad], (E, N)
    phi: jax.Array         # Phi_k [rad], (E, N)
    width: jax.Array       # D(phi_i): projected half width of the cortex seen from omega_i, (N,)
    absorbed: jax.Array    # power absorbed in the cortex and the medulla, (N, bands)
    discarded: jax.Array   # power in lobes after the K-th, or still inside after max_events, (N, bands)


def _lobes(p: Params, wi: Vec3, h, key, medulla_present=None) -> Lobes:
    """Trace rays (wi and h of shape (N,)) and keep each ray's first n_lobes emissions."""
    sec = section(p, medulla_present)
    rec = tracer._trace(sec, wi, h, key, None, p.max_events, "split", False, False)
    emitted = jnp.any(rec.weight > 0.0, axis=-1)                           # (E, N)
    kept = emitted & (jnp.cumsum(emitted.astype(jnp.int32), axis=0) <= p.n_lobes)
    amp = jnp.where(kept[..., None], rec.weight, 0.0)
    theta, phi = fiber_angles(rec.direction)
    late = jnp.sum(rec.weight, axis=0) - jnp.sum(amp, axis=0)
    uy, uz = G.unit_2d(-wi.y, -wi.z)
    o = sec.outer()
    width = G.half_width(uy, uz, o.a, o.b, o.psi)
    return Lobes(amp, theta, phi, width, rec.absorbed, late + rec.residual + rec.lost)


def _key(key):
    return as_key(key, _DEFAULT_KEY)


def _flat_pairs(*dirs):
    """Broadcast direction Vec3s to one flat axis; returns the flat Vec3s and the broadcast shape."""
    shape = jnp.broadcast_shapes(*(jnp.shape(c) for d in dirs for c in d))
    return [Vec3(*(jnp.broadcast_to(c, shape).reshape(-1) for c in d)) for d in dirs], shape


def _offsets(p: Params, key, n: int, dtype):
    """n stratified offsets in [h_lo, h_hi] (the same for every direction pair)."""
    u = (jnp.arange(n, dtype=dtype) + jax.random.uniform(key, (n,), dtype)) / n
    lo, hi = jnp.asarray(p.h_lo, dtype), jnp.asarray(p.h_hi, dtype)
    return lo + (hi - lo) * u


def _lobe_sum(p: Params, lob: Lobes, wi: Vec3, wo: Vec3):
    """S_h(wo) per ray (N, bands) from its kept lobes (module docstring)."""
    tho, pho = fiber_angles(wo)
    g_n = detectors.azimuthal(pho[None] - lob.phi, p.beta_n)                        # (E, N)
    if p.longitudinal == "gaussian":
        l_m = detectors.gaussian(tho[None] - lob.theta, p.beta_m)
        norm = 1.0 / jnp.maximum(1.0 - wi.x * wi.x, _TINY)                           # cos^-2 theta_i
    else:
        l_m = detectors.longitudinal(tho[None], lob.theta, p.beta_m, p.longitudinal)
        norm = 1.0 / jnp.maximum(jnp.cos(tho), _TINY)
    d = lob.width if p.projected_width else jnp.ones_like(lob.width)
    return jnp.sum(lob.amplitude * (l_m * g_n)[..., None], axis=0) * (d * norm)[:, None]


def _lobe_pdf(p: Params, lob: Lobes, wo: Vec3):
    """The sampler's solid-angle density of wo per ray (N,) for its kept lobes."""
    tho, pho = fiber_angles(wo)
    lum = jnp.maximum(luminance_or_mean(lob.amplitude), 0.0)                         # (E, N)
    tot = jnp.sum(lum, axis=0)
    prob = lum / jnp.where(tot > 0, tot, 1.0)
    a, b = detectors.truncation_cdfs(lob.theta, p.beta_m)
    p_theta = detectors.gaussian(tho[None] - lob.theta, p.beta_m) / jnp.maximum(b - a, _TINY)
    g_n = detectors.azimuthal(pho[None] - lob.phi, p.beta_n)
    return jnp.sum(prob * p_theta * g_n, axis=0) / jnp.maximum(jnp.cos(tho), _TINY)


def _off_axis(wi: Vec3):
    """Light along the fibre axis has no direction in the cross-section and meets no projected width:
    a safe stand-in direction (so values and derivatives stay finite) and the mask that zeroes it."""
    ok = wi.y * wi.y + wi.z * wi.z > _TINY
    return Vec3(jnp.where(ok, wi.x, 0.0), jnp.where(ok, wi.y, 1.0), jnp.where(ok, wi.z, 0.0)), ok


def by_incidence(wi: Vec3, wo: Vec3):
    """Pairs grouped by their incident direction: ``(wi_u, idx, wo_f, shape)`` with ``wi_u`` the M
    directions of ``wi`` as given (broadcast among its own components only, flattened), ``idx`` (pairs,)
    the index into them of every pair of the broadcast ``shape`` and ``wo_f`` (pairs,). The lobes depend on
    wi and the offset only, so a Monte Carlo evaluator traces M directions, not every pair (a lat-long
    table of one wi traces once)."""
    shape = jnp.broadcast_shapes(*(jnp.shape(c) for d in (wi, wo) for c in d))
    s_i = jnp.broadcast_shapes(*(jnp.shape(c) for c in wi))
    wi_u = Vec3(*(jnp.broadcast_to(c, s_i).reshape(-1) for c in wi))
    m = wi_u.x.shape[0]
    idx = jnp.broadcast_to(jnp.arange(m).reshape((1,) * (len(shape) - len(s_i)) + s_i), shape).reshape(-1)
    wo_f = Vec3(*(jnp.broadcast_to(c, shape).reshape(-1) for c in wo))
    return wi_u, idx, wo_f, shape


def _estimate(p: Params, wi: Vec3, wo: Vec3, key, what):
    """Mean and standard error over n_h offsets of S_h (``what="eval"``) or pdf_h. Every pair traces the
    same offsets with the same key (common random numbers across directions, medulla bounces included);
    each distinct wi is traced once (:func:`by_incidence`)."""
    wi_u, idx, wo_f, shape = by_incidence(wi, wo)
    n = p.n_h
    k_h, k_t = jax.random.split(_key(key))
    h = _offsets(p, k_h, n, jnp.result_type(float))

    def trace(a: Vec3):
        a, ok = _off_axis(a)
        a = Vec3(*(jnp.broadcast_to(c, (n,)) for c in a))
        return _lobes(p, a, h, k_t), a, ok

    lob_u, a_u, ok_u = jax.vmap(trace)(wi_u)

    def one_pair(i, b: Vec3):
        lob, a = jax.tree_util.tree_map(lambda v: v[i], (lob_u, a_u))
        b = Vec3(*(jnp.broadcast_to(c, (n,)) for c in b))
        x = _lobe_sum(p, lob, a, b) if what == "eval" else _lobe_pdf(p, lob, b)[:, None]
        return jnp.where(ok_u[i], x, 0.0)

    return offsets_mean(jax.vmap(one_pair)(idx, wo_f), shape, what)


def offsets_mean(x, shape, what):
    """Mean and standard error over the offsets of per-offset values x (pairs, n_h, bands), 0 where not
    finite, reshaped to the pairs' broadcast ``shape`` (+ bands for ``what="eval"``, none for "pdf")."""
    n = x.shape[1]
    mean = jnp.mean(x, axis=1)
    se = jnp.std(x, axis=1) / math.sqrt(max(n - 1, 1))
    ok = jnp.isfinite(mean)
    mean, se = jnp.where(ok, mean, 0.0), jnp.where(ok, se, 0.0)
    if what == "pdf":
        return mean[:, 0].reshape(shape), se[:, 0].reshape(shape)
    out = shape + mean.shape[-1:]
    return mean.reshape(out), se.reshape(out)


def _eval(p: Params, wi: Vec3, wo: Vec3, key=None):
    """S(wi, wo) (1/sr, bands last) and its standard error over the n_h offsets."""
    return _estimate(p, wi, wo, key, "eval")


def _pdf(p: Params, wi: Vec3, wo: Vec3, key=None):
    """The sampler's density of wo (1/sr), averaged over n_h offsets, and its standard error."""
    return _estimate(p, wi, wo, key, "pdf")


def sample_at(p: Params, wi: Vec3, h, key, medulla_present=None):
    """One sample per ray of flat ``wi`` (N,) launched at offsets ``h`` (N,): ``(wo, weight, pdf_h)`` with
    weight = S_h cos(theta_o) / pdf_h (bands) for the lobe set of that offset (zero where nothing left).
    For composing models (``bsdf.feather``) that choose the offsets; :func:`sample` draws them.
    ``medulla_present``: as in :func:`section`."""
    N = wi.x.shape[0]
    dtype = jnp.result_type(float)
    k_t, k_l, k_m, k_n = jax.random.split(key, 4)
    wi, on = _off_axis(wi)
    lob = _lobes(p, wi, h, k_t, medulla_present)
    lum = jnp.maximum(luminance_or_mean(lob.amplitude), 0.0) * on
    cdf = jnp.cumsum(lum, axis=0)
    tot = cdf[-1]
    u = jax.random.uniform(k_l, (N,), dtype) * tot
    k = jnp.minimum(jnp.sum(cdf <= u[None], axis=0), lum.shape[0] - 1)
    pick = lambda a: jnp.take_along_axis(a, k[None], axis=0)[0]  # noqa: E731
    tho, _ = detectors.sample_longitudinal(jax.random.uniform(k_m, (N,), dtype), pick(lob.theta), p.beta_m)
    pho, _ = detectors.sample_azimuthal(jax.random.uniform(k_n, (N,), dtype), pick(lob.phi), p.beta_n)
    wo = fiber_direction(tho, pho)
    s = _lobe_sum(p, lob, wi, wo)
    pdf = _lobe_pdf(p, lob, wo)
    good = (tot > 0) & (pdf > 0)
    weight = jnp.where(good[:, None], s * jnp.cos(tho)[:, None] / jnp.where(good, pdf, 1.0)[:, None], 0.0)
    return wo, weight, jnp.where(good, pdf, 0.0)


def _sample(p: Params, wi: Vec3, key):
    """(wo, weight = S_h cos(theta_o) / pdf_h (bands), pdf_h) for one offset per direction."""
    (wi_f,), shape = _flat_pairs(wi)
    dtype = jnp.result_type(float)
    k_h, k_s = jax.random.split(key)
    lo, hi = jnp.asarray(p.h_lo, dtype), jnp.asarray(p.h_hi, dtype)
    h = lo + (hi - lo) * jax.random.uniform(k_h, wi_f.x.shape, dtype)
    wo, weight, pdf = sample_at(p, wi_f, h, k_s)
    return (Vec3(*(c.reshape(shape) for c in wo)), weight.reshape(shape + weight.shape[-1:]), pdf.reshape(shape))


def _lobes_public(p: Params, wi: Vec3, h, key=None) -> Lobes:
    """The kept lobes of rays from one direction ``wi`` at offsets ``h`` (N,) in [-1, 1]."""
    h = jnp.atleast_1d(jnp.asarray(h, jnp.result_type(float)))
    wi = Vec3(*(jnp.broadcast_to(c, h.shape) for c in wi))
    return _lobes(p, wi, h, _key(key))


# for composing models (bsdf.feather): the lobes at given offsets, S_h and pdf_h of their lobe sets
trace_lobes, lobe_value, lobe_density, off_axis = _lobes, _lobe_sum, _lobe_pdf, _off_axis
eval = boundary(_eval, Params)
pdf = boundary(_pdf, Params)
lobes = boundary(_lobes_public, Params)
_sample_jit = jax.jit(_sample)


def sample(params, wi, key):
    """``(wo, weight, pdf)``: one offset and one lobe per direction of ``wi`` (a PRNG key drives all
    choices); ``weight`` = S_h cos(theta_o) / pdf_h (bands), ``pdf`` = pdf_h (1/sr, 0 where nothing left)."""
    validate(params, Params)
    (wi,) = as_directions(wi=wi)
    if not is_prng_key(key):
        raise ValueError("feather_fiber.sample: key must be a jax PRNG key (the offset, the lobe choice and "
                         "the medulla's bounces all draw from it)")
    return _sample_jit(params, wi, key)


sample.kernel = _sample
MODEL = Model(
    name="feather_fiber",
    kind="bcsdf",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="feather barb/barbule BCSDF: elliptical cortex, off-centre diffuse medulla, K traced lobes + detectors",
    source="Padrón 2025, Ch. 5 (Eqs. 5.1-5.3), spec seed-000 M20-M21",
    reciprocal=False,
    transmissive=True,
    stochastic=True,
)
