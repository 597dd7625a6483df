"""Padrón's feather surface BSDF (Padrón 2025 Eq. 5.4 [T:996-1056]; spec seed-000 M25): a pennaceous
vane as a surface whose microgeometry (barbs, proximal and distal barbules, gaps) is a masking term
and whose fibres are :mod:`appearance_jax.bcsdf.feather_fiber` BCSDFs.

In the barb frame (x = the barb's tangent, at ``barb_angle`` from the shading frame's x about the
normal n; y = n x x; z = n), with ``wi`` the viewer and ``wo`` the light (see "Directions" below):

    f(wi, wo) = [ w_b(wi)  S_b (wi, wo; h_b)  G_b(wo)
                + w_bp(wi) S_bb(T_bp wi, T_bp wo; h_bp) G_bp(wo)
                + w_bd(wi) S_bb(T_bd wi, T_bd wo; h_bd) G_bd(wo) ] / |wo . n|
                + w_t(wi) delta(wo = -wi)                                  (Padrón Eq. 5.4)

- w_b, w_bp, w_bd, w_t: the fractions of the vane's projected area where the viewer sees a barb, a
  proximal barbule, a distal barbule or through the vane (sum 1; :func:`~appearance_jax.bsdf.
  feather_masking.barb_masking` with the barbules' own coverages from :func:`~appearance_jax.bsdf.
  feather_masking.barbule_masking`, spec M23/M24); h_j = [h_lo, h_hi] the visible part of each fibre's
  projected diameter (the range of its offsets, Padrón Eq. 5.1).
- S_b: the barb (cortex of axis ratio e_b + the diffuse medulla), S_bb: a barbule (cortex of axis
  ratio e_bb, no medulla), both :mod:`~appearance_jax.bcsdf.feather_fiber` with D = 1 [T:1004]
  (the masking carries the projected widths). G_j(wo) = cos(theta_o) in fibre j's frame.
- T_bp, T_bd: the barbule frames (spec D10): axes a = (cos th_bb cos ph_bb, -/+ cos th_bb sin ph_bb,
  sin th_bb) in the barb frame (proximal -, distal +; ph_bb = 45 deg [T:1004]); their z is n made
  orthogonal to a (Gram-Schmidt), y = z x a. A barbule row's masking is taken in the (y, z) plane of
  its frame (spec D8, D10).
- The delta (spec D21): light passing straight through the gaps, mass w_t. It is not part of
  ``eval`` (a delta has no density): :func:`transmission` gives w_t, and :func:`sample_events` is the
  thesis' four-event sampler with it [T:1056].

**Directions.** Padrón evaluates the masking on the camera-side direction, the known one in a path
tracer [T:1056]. Here ``wi`` is the given (viewer) direction, as for the library's BCSDFs: the masking,
the h ranges and the fibres' traced rays all start from ``wi``; G and |. n|^-1 apply to ``wo``. The
model is not reciprocal. Both sides of the vane are valid for both directions (transmissive); an
exactly grazing ``wi`` or ``wo`` (in the vane plane) gives 0.

**Energy.** int f |wo . n| dwo + w_t = sum_j w_j E_h[sum_k A_k] <= 1, equality for lossless fibres up to
the energy that the K kept lobes leave out (``feather_fiber.lobes``' ``discarded``; [T:1121]).

**Estimator** (``Model.stochastic``): ``eval`` and ``pdf`` average ``n_h`` stratified offsets in each
fibre's visible range, the same offsets (and medulla bounces) for every direction pair, and return
``(value, stderr)``. ``sample`` draws the continuous part: a fibre j with probability w_j / (1 - w_t),
one offset in its range, then the fibre's own sampler; its weight is (1 - w_t) x the fibre's S_h
cos / pdf_h (unbiased for the part of f |wo . n| outside the delta), its pdf (P_j pdf_h) that of the
drawn event and offset. ``pdf`` is sum_j w_j E_h[pdf_h,j] / (1 - w_t), that sampler's density.
The standard error is the offsets' sample error: where only one or two offsets' lobes reach a
direction (medulla light, a lobe sweeping fast near grazing offsets) it is ~0 while the estimate is too
low (measured: up to 12 reported sigma at n_h = 8); use n_h >= 64 (256 where the medulla dominates) for
error bars (docs/feathers.md). Derivatives: those of the estimator at its fixed offsets (common random
numbers); the masking is continuous in its parameters, the fibres' caveat applies to e_b and the
medulla's geometry (:mod:`~appearance_jax.bcsdf.feather_fiber`).

Units: lengths relative to the barb's width (masking, spec D9) and, inside a fibre, to its horizontal
semi-axis (spec D17); sigma_a per unit semi-axis; angles in radians. Following Table 5.1 [T:912], a
fibre's axis ratio is the masking's: e_b is the barb cortex's b_c / a_c, e_bb the barbule's.

| parameter          | default             | range         | unit   | meaning                                            |
|--------------------|---------------------|---------------|--------|----------------------------------------------------|
| e_b                | 1.6                 | [1, 10]       | 1      | barb axis ratio (height / width) [T:1069]          |
| l_bb               | 1.0                 | [0, 100]      | 1      | barbule length / barb width                        |
| theta_bb           | 0.2618 (15 deg)     | [0, pi/2)     | rad    | barbule inclination (Fig. B.5: 0-45 deg)           |
| e_bb               | 1.0                 | [1, 10]       | 1      | barbule axis ratio [T:1083]                        |
| delta_bb           | 1.0                 | [0, 100]      | 1      | gap between barbules / barbule width [T:1083]      |
| phi_bb             | 0.7854 (45 deg)     | [0, pi/2]     | rad    | barbule rotation from the barb [T:1004]            |
| barb_angle         | 0                   | [-2pi, 2pi]   | rad    | barb tangent from the shading x (texture R)        |
| eta_b, eta_bb      | 1.53                | (1, 3]        | 1      | cortex index [T:1069]                              |
| sigma_a_b, _bb     | (0.133, 1.967, 2.1) | [0, inf)      | 1/unit | cortex absorption per band [T:1069]                |
| beta_m_b, _bb      | 0.13                | (0, 1.5]      | rad    | longitudinal detector width [T:1069]               |
| beta_n_b, _bb      | 0.12                | (0, 1.5]      | rad    | azimuthal detector width [T:1069]                  |
| medulla_a, _b      | 0.6, 0.6            | (0, 10)       | unit   | barb medulla semi-axes along y, z [T:1069]         |
| medulla_y, _z      | -0.1, 0.1           | (-10, 10)     | unit   | medulla centre [T:1069]                            |
| medulla_albedo     | 1.0                 | [0, 1]        | 1      | d_m per band (white; spongy-layer blue < 1)        |
| medulla            | True                | bool          | -      | barbs with a medulla (False: Fig. 5.8 "only masking") |
| corner             | 1                   | +1, -1        | -      | barbule V opens towards +n (+1) or -n (-1)         |
| n_lobes, max_events| 5, 16               | >= 1          | -      | lobes kept per offset, tracer events [T:992]       |
| n_h                | 16                  | >= 1          | -      | stratified offsets per fibre and evaluation        |
| longitudinal       | "gaussian_cos"      | see feather_fiber | -  | longitudinal detector form                         |

Example::

    from appearance_jax.bsdf import feather
    from appearance_jax.core.frame import spherical_direction
    p = feather.Params(medulla_albedo=(0.2, 0.45, 0.9))          # a blue medulla
    wi, wo = spherical_direction(0.5, 0.0), spherical_direction(0.7, 2.5)
    f, se = feather.eval(p, wi, wo)                                # (3,) 1/sr and its standard error
    t = feather.transmission(p, wi)                                # the delta's mass w_t
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..bcsdf import feather_fiber as ff
from ..bcsdf import detectors
from ..core.arrays import stacked
from ..core.model import Model, boundary
from ..core.params import Bands, integer, param, params_class, Real, replace_unchecked, static, validate
from ..core.frame import rotate_z
from ..core.rng import as_key, is_prng_key
from ..core.vec import as_directions, Vec3
from . import feather_masking as masking

_TINY = 1e-12
_DEFAULT_KEY = 20252
_HALF_PI = 0.5 * math.pi


@params_class
class Params:
    e_b: Real = param(1.6, lo=1.0, hi=10.0, unit="1", doc="barb axis ratio (height / width)")
    l_bb: Real = param(1.0, lo=0.0, hi=100.0, unit="1", doc="barbule length / barb width")
    theta_bb: Real = param(0.2617993877991494, lo=0.0, hi=_HALF_PI, hi_open=True, unit="rad",
                           doc="barbule inclination")
    e_bb: Real = param(1.0, lo=1.0, hi=10.0, unit="1", doc="barbule axis ratio (height / width)")
    delta_bb: Real = param(1.0, lo=0.0, hi=100.0, unit="1", doc="gap between barbules / barbule width")
    phi_bb: Real = param(0.25 * math.pi, lo=0.0, hi=_HALF_PI, unit="rad", doc="barbule rotation from the barb")
    barb_angle: Real = param(0.0, lo=-2.0 * math.pi, hi=2.0 * math.pi, unit="rad",
                             doc="barb tangent from the shading frame's x")
    eta_b: Real = param(1.53, lo=1.0, hi=3.0, lo_open=True, unit="1", doc="barb cortex index")
    sigma_a_b: Bands = param((0.133, 1.967, 2.1), lo=0.0, unit="1/unit", bands=True, doc="barb cortex absorption")
    beta_m_b: Real = param(0.13, lo=0.0, hi=1.5, lo_open=True, unit="rad", doc="barb longitudinal detector width")
    beta_n_b: Real = param(0.12, lo=0.0, hi=1.5, lo_open=True, unit="rad", doc="barb azimuthal detector width")
    medulla_a: Real = param(0.6, lo=0.0, hi=10.0, lo_open=True, hi_open=True, unit="unit", doc="medulla semi-axis, y")
    medulla_b: Real = param(0.6, lo=0.0, hi=10.0, lo_open=True, hi_open=True, unit="unit", doc="medulla semi-axis, z")
    medulla_y: Real = param(-0.1, lo=-10.0, hi=10.0, lo_open=True, hi_open=True, unit="unit", doc="medulla centre, y")
    medulla_z: Real = param(0.1, lo=-10.0, hi=10.0, lo_open=True, hi_open=True, unit="unit", doc="medulla centre, z")
    medulla_albedo: Bands = param(1.0, lo=0.0, hi=1.0, unit="1", bands=True, doc="medulla albedo d_m")
    eta_bb: Real = param(1.53, lo=1.0, hi=3.0, lo_open=True, unit="1", doc="barbule cortex index")
    sigma_a_bb: Bands = param((0.133, 1.967, 2.1), lo=0.0, unit="1/unit", bands=True,
                              doc="barbule cortex absorption")
    beta_m_bb: Real = param(0.13, lo=0.0, hi=1.5, lo_open=True, unit="rad", doc="barbule longitudinal detector width")
    beta_n_bb: Real = param(0.12, lo=0.0, hi=1.5, lo_open=True, unit="rad", doc="barbule azimuthal detector width")
    medulla: bool = static(True, choices=(False, True), doc="barbs with a diffuse medulla")
    corner: int = static(1, choices=(1, -1), doc="barbule V opens towards +n (1) or -n (-1)")
    n_lobes: int = static(5, doc="lobes kept per offset (K)", convert=integer(1))
    max_events: int = static(16, doc="tracer events per offset", convert=integer(1))
    n_h: int = static(16, doc="stratified offsets per fibre and evaluation", convert=integer(1))
    longitudinal: str = static("gaussian_cos", choices=detectors.LONGITUDINAL_KINDS, doc="longitudinal detector form")

    def _validate(self):
        if self.max_events < self.n_lobes:
            raise ValueError(f"feather.Params: max_events = {self.max_events} < n_lobes = {self.n_lobes}: "
                             "each kept lobe needs an event")
        if self.medulla:
            ff.check_medulla("feather.Params", self.e_b, self.medulla_a, self.medulla_b, self.medulla_y,
                             self.medulla_z)


# ----------------------------------------------------------------------------------- frames and fibres

def _to_barb(w: Vec3, angle) -> Vec3:
    """Coordinates of w (shading frame) in the barb frame, turned by ``angle`` about the normal."""
    return rotate_z(w, -angle)


def barbule_frames(theta_bb, phi_bb):
    """The proximal and distal barbule frames as rows (x = axis, y, z) in barb coordinates, (2, 3, 3)
    (spec D10: z is n made orthogonal to the axis, y = z x x)."""
    ct, st, cp, sp = jnp.cos(theta_bb), jnp.sin(theta_bb), jnp.cos(phi_bb), jnp.sin(phi_bb)
    out = []
    for sign in (-1.0, 1.0):
        a = jnp.stack([ct * cp, sign * ct * sp, st])
        z = (jnp.array([0.0, 0.0, 1.0]) - st * a) / ct           # |n - (n.a) a| = cos theta_bb
        y = jnp.cross(z, a)
        out.append(jnp.stack([a, y, z]))
    return jnp.stack(out)


def _to(R, w: Vec3) -> Vec3:
    """w in the frame whose axes are the rows of R (3, 3), or of one R per direction (..., 3, 3)."""
    return Vec3(*(R[..., i, 0] * w.x + R[..., i, 1] * w.y + R[..., i, 2] * w.z for i in range(3)))


def _from(R, w: Vec3) -> Vec3:
    """The inverse of :func:`_to`."""
    return Vec3(*(R[..., 0, i] * w.x + R[..., 1, i] * w.y + R[..., 2, i] * w.z for i in range(3)))


def _frames(p: Params):
    """Rows of the barb (identity), proximal and distal frames in barb coordinates, (3, 3, 3)."""
    eye = jnp.eye(3, dtype=jnp.result_type(float))
    return jnp.concatenate([eye[None], barbule_frames(p.theta_bb, p.phi_bb).astype(eye.dtype)])


@functools.lru_cache(maxsize=64)
def _fibre_base(medulla, n_lobes, max_events, n_h, longitudinal):
    # built outside any trace (a Params' checks need concrete values); the fields are replaced below
    with jax.ensure_compile_time_eval():
        return ff.Params(medulla=medulla, n_lobes=n_lobes, max_events=max_events, n_h=n_h,
                         longitudinal=longitudinal, projected_width=False)


def fibres(p: Params):
    """The barb's and a barbule's :class:`~appearance_jax.bcsdf.feather_fiber.Params` (D = 1)."""
    statics = (p.n_lobes, p.max_events, p.n_h, p.longitudinal)
    barb = replace_unchecked(_fibre_base(p.medulla, *statics), eta=p.eta_b, sigma_a=p.sigma_a_b,
                             beta_m=p.beta_m_b, beta_n=p.beta_n_b, eccentricity=p.e_b, medulla_a=p.medulla_a,
                             medulla_b=p.medulla_b, medulla_y=p.medulla_y, medulla_z=p.medulla_z,
                             medulla_albedo=p.medulla_albedo)
    barbule = replace_unchecked(_fibre_base(False, *statics), eta=p.eta_bb, sigma_a=p.sigma_a_bb,
                                beta_m=p.beta_m_bb, beta_n=p.beta_n_bb, eccentricity=p.e_bb)
    return barb, barbule


def _fibre_stack(p: Params):
    """The fibres of barb, proximal and distal barbule stacked along a leading axis of 3, and the medulla's
    switch (3,) (None without a medulla). The barbules carry the barb's medulla switched off as data
    (``Shape.present``), so the three fibres share static fields and one compiled trace (vmapped over
    them) instead of a barb and a barbule variant: a third of the eval's compile time."""
    barb, barbule = fibres(p)
    present = None
    if p.medulla:
        barbule = replace_unchecked(barb, eta=p.eta_bb, sigma_a=p.sigma_a_bb, beta_m=p.beta_m_bb,
                                    beta_n=p.beta_n_bb, eccentricity=p.e_bb)
        present = jnp.asarray([True, False, False])

    def stack(*leaves):
        return stacked(*(jnp.asarray(v, jnp.result_type(float)) for v in leaves))

    return jax.tree_util.tree_map(stack, barb, barbule, barbule), present


class Masking(NamedTuple):
    """The masking seen from a direction: the weights (3, ...) of barb, proximal and distal barbule,
    the transmitted fraction w_t (...), and each fibre's visible offset range h_lo, h_hi (3, ...)."""

    weight: jax.Array
    w_t: jax.Array
    h_lo: jax.Array
    h_hi: jax.Array


def _masking(p: Params, wb: Vec3, R) -> Masking:
    """Padrón's two-scale masking (spec M23, M24) for directions wb in barb coordinates."""
    loc = [_to(R[j], wb) for j in (1, 2)]
    cov, lo, hi = zip(*(masking.barbule_masking(w.y, w.z, p.e_bb, p.delta_bb) for w in loc))
    w_b, w_p, w_d, w_t, lo_b, hi_b = masking.barb_masking(wb.y, wb.z, p.e_b, p.l_bb, p.theta_bb, cov[0], cov[1],
                                                          corner=p.corner)
    return Masking(jnp.stack([w_b, w_p, w_d]), w_t, jnp.stack([lo_b, *lo]), jnp.stack([hi_b, *hi]))


def _masking_public(p: Params, wi: Vec3) -> Masking:
    """The masking seen from ``wi`` (shading frame): :class:`Masking`."""
    return _masking(p, _to_barb(wi, p.barb_angle), _frames(p))


# ----------------------------------------------------------------------------------- estimators

def _key(key):
    return as_key(key, _DEFAULT_KEY)


def _safe_inv(x):
    ok = x != 0
    return jnp.where(ok, 1.0 / jnp.where(ok, x, 1.0), 0.0)


def _estimate(p: Params, wi: Vec3, wo: Vec3, key, what):
    """Mean and standard error over n_h offsets per fibre of f (``"eval"``) or the sampler's density. The
    masking and the three fibres' lobes are computed once per distinct viewer direction (and barb angle)."""
    # the barb angle turns both directions: it belongs to the viewer's side of the grouping
    s_i = jnp.broadcast_shapes(jnp.shape(p.barb_angle), *(jnp.shape(c) for c in wi))
    angle_i = jnp.broadcast_to(jnp.asarray(p.barb_angle), s_i)
    wi_r = _to_barb(Vec3(*(jnp.broadcast_to(c, s_i) for c in wi)), angle_i)
    shape = jnp.broadcast_shapes(s_i, *(jnp.shape(c) for c in wo))
    angle_o = jnp.broadcast_to(angle_i.reshape((1,) * (len(shape) - len(s_i)) + s_i), shape)
    wi_u, idx, wo_f, shape = ff.by_incidence(wi_r, _to_barb(Vec3(*(jnp.broadcast_to(c, shape) for c in wo)),
                                                              angle_o))
    R = _frames(p)
    m = _masking(p, wi_u, R)
    fib, present = _fibre_stack(p)
    n = p.n_h
    dtype = jnp.result_type(float)
    keys = jax.random.split(_key(key), 3)            # offsets, barb, barbules (both barbules share theirs)
    u = (jnp.arange(n, dtype=dtype) + jax.random.uniform(keys[0], (n,), dtype)) / n   # stratified, shared
    keys = keys[jnp.asarray([1, 2, 2])]
    # one vmap over (direction, fibre) and over (pair, fibre): the three fibres run one program, and a
    # single level of batching keeps the tracing as cheap as one fibre's
    M = wi_u.x.shape[0]
    j_u = jnp.tile(jnp.arange(3), M)                                                # fibre of row k = 3 i + j
    at = lambda t, j: jax.tree_util.tree_map(lambda v: v[j], t)  # noqa: E731

    def trace(a: Vec3, j, lo, hi):
        fp, on = at(fib, j), (None if present is None else present[j])
        aj, ok = ff.off_axis(_to(R[j], a))
        aj = Vec3(*(jnp.broadcast_to(c, (n,)) for c in aj))
        return ff.trace_lobes(fp, aj, lo + (hi - lo) * u, keys[j], on), aj, ok

    rep = lambda v: jnp.repeat(v, 3, axis=0)  # noqa: E731
    traced = jax.vmap(trace)(Vec3(*(rep(c) for c in wi_u)), j_u, m.h_lo.T.reshape(-1), m.h_hi.T.reshape(-1))

    def one_pair(k, j, b: Vec3):
        lob, aj, ok = at(traced, k)
        # light along the fibre's axis: G = 0; a stand-in keeps the derivatives finite (the fibre
        # angles' asin and atan2 are singular there, and a rotation of the frame moves it)
        bj = _to(R[j], b)
        ok_o = 1.0 - bj.x * bj.x > _TINY
        bj = Vec3(jnp.where(ok_o, bj.x, 0.0), jnp.where(ok_o, bj.y, 1.0), jnp.where(ok_o, bj.z, 0.0))
        bj = Vec3(*(jnp.broadcast_to(c, (n,)) for c in bj))
        fp = at(fib, j)
        if what == "eval":
            g = jnp.sqrt(jnp.maximum(1.0 - bj.x * bj.x, 0.0))                   # G_j(wo) = cos theta_o
            xj = ff.lobe_value(fp, lob, aj, bj) * g[:, None]
        else:
            xj = ff.lobe_density(fp, lob, bj)[:, None]
        return jnp.where(ok & ok_o, xj, 0.0)

    j_p = jnp.tile(jnp.arange(3), idx.shape[0])
    x = jax.vmap(one_pair)(rep(idx) * 3 + j_p, j_p, Vec3(*(rep(c) for c in wo_f)))  # (3 pairs, n, bands)
    x = x.reshape((-1, 3) + x.shape[1:]) * m.weight.T[idx][:, :, None, None]
    x = x[:, 0] + x[:, 1] + x[:, 2]                                                # (pairs, n, bands)
    live = wi_u.z[idx] != 0
    if what == "eval":
        x = x * (_safe_inv(jnp.abs(wo_f.z)) * live)[:, None, None]
    else:
        x = x * (_safe_inv(1.0 - m.w_t[idx]) * live * (wo_f.z != 0))[:, None, None]
    return ff.offsets_mean(x, shape, what)


def _eval(p: Params, wi: Vec3, wo: Vec3, key=None):
    """f(wi, wo) without the delta (1/sr, bands last) and its standard error over the offsets."""
    return _estimate(p, wi, wo, key, "eval")


def _pdf(p: Params, wi: Vec3, wo: Vec3, key=None):
    """The density of :func:`sample` at wo (1/sr), averaged over the offsets, and its standard error."""
    return _estimate(p, wi, wo, key, "pdf")


def _transmission(p: Params, wi: Vec3):
    """w_t(wi): the mass of the delta wo = -wi (per direction; no bands axis)."""
    m = _masking_public(p, wi)
    return jnp.where(wi.z != 0, m.w_t, 0.0)


def _draw(p: Params, wi: Vec3, key, with_delta):
    """One event and sample per direction of wi: ``(wo, weight (bands), pdf, event)``; event 0 barb,
    1 proximal, 2 distal barbule, 3 the delta (only where ``with_delta``, a traced bool: :func:`sample`
    and :func:`sample_events` run one compiled program)."""
    shape = jnp.broadcast_shapes(jnp.shape(p.barb_angle), *(jnp.shape(c) for c in wi))
    wi_s = Vec3(*(jnp.broadcast_to(c, shape).reshape(-1) for c in wi))
    angle = jnp.broadcast_to(jnp.asarray(p.barb_angle), shape).reshape(-1)
    N = wi_s.x.shape[0]
    dtype = jnp.result_type(float)
    wb = _to_barb(wi_s, angle)
    R = _frames(p)
    m = _masking(p, wb, R)
    fib, present = _fibre_stack(p)
    k_e, k_h, k_b, k_bb = jax.random.split(key, 4)
    ue, uh = jax.random.uniform(k_e, (N,), dtype), jax.random.uniform(k_h, (N,), dtype)
    w = jnp.concatenate([m.weight, jnp.where(with_delta, m.w_t, 0.0)[None]])      # (events, N)
    tot = jnp.sum(w, axis=0)
    cdf = jnp.cumsum(w, axis=0)
    event = jnp.minimum(jnp.sum(cdf <= (ue * tot)[None], axis=0), w.shape[0] - 1)
    # the barb and one barbule (the frame and range of the drawn one) are traced for every direction
    sel = jnp.where(event == 2, 2, 1)
    h = m.h_lo + (m.h_hi - m.h_lo) * uh[None]
    pick = lambda a: jnp.take_along_axis(a, sel[None], axis=0)[0]  # noqa: E731
    R_bb = R[sel]                                                                     # (N, 3, 3)
    # the barb and the barbule as one program (vmapped over the two fibres; _fibre_stack)
    first2 = lambda t: jax.tree_util.tree_map(lambda v: v[:2], t)  # noqa: E731
    w_loc = Vec3(*(jnp.stack([c_b, c_l]) for c_b, c_l in zip(wb, _to(R_bb, wb))))
    wo2, wt2, pdf2 = jax.vmap(ff.sample_at)(first2(fib), w_loc, jnp.stack([h[0], pick(h)]),
                                            jnp.stack([k_b, k_bb]), first2(present))
    wo_b, wt_b, pdf_b = Vec3(*(c[0] for c in wo2)), wt2[0], pdf2[0]
    wo_l, wt_l, pdf_l = Vec3(*(c[1] for c in wo2)), wt2[1], pdf2[1]
    wo_bb = _from(R_bb, wo_l)
    is_barb = event == 0
    wo = Vec3(*(jnp.where(is_barb, c1, c2) for c1, c2 in zip(wo_b, wo_bb)))
    weight = jnp.where(is_barb[:, None], wt_b, wt_l)
    pdf_f = jnp.where(is_barb, pdf_b, pdf_l)
    w_ev = jnp.take_along_axis(w, event[None], axis=0)[0]
    prob = w_ev * _safe_inv(tot)
    delta = event == 3
    wo = Vec3(*(jnp.where(delta, -c_d, c) for c_d, c in zip(wb, wo)))
    # with the delta: a fibre event's weight is the fibre's (w_j / P_j = 1), the delta's 1; without it
    # the fibres' probabilities are renormalised: (1 - w_t) x the fibre's
    weight = jnp.where(delta[:, None], 1.0, weight * jnp.where(with_delta, 1.0, tot)[:, None])
    pdf = jnp.where(delta, 0.0, prob * pdf_f)
    live = (wi_s.z != 0) & (tot > 0) & (wo.z != 0)
    weight = jnp.where(live[:, None], weight, 0.0)
    pdf = jnp.where(live, pdf, 0.0)
    wo = rotate_z(wo, angle)
    return (Vec3(*(c.reshape(shape) for c in wo)), weight.reshape(shape + weight.shape[-1:]), pdf.reshape(shape),
            event.reshape(shape))


def _sample(p: Params, wi: Vec3, key):
    wo, weight, pdf, _ = _draw(p, wi, key, False)
    return wo, weight, pdf


def _sample_events(p: Params, wi: Vec3, key):
    wo, weight, _, event = _draw(p, wi, key, True)
    return wo, weight, event


_draw_jit = jax.jit(_draw)


eval = boundary(_eval, Params)
pdf = boundary(_pdf, Params)
transmission = boundary(_transmission, Params)
masking_of = boundary(_masking_public, Params)

#: the events of :func:`sample_events`
EVENTS = ("barb", "proximal", "distal", "transmission")


def _checked(params, wi, key, name):
    validate(params, Params)
    (wi,) = as_directions(wi=wi)
    if not is_prng_key(key):
        raise ValueError(f"feather.{name}: key must be a jax PRNG key (the event, the offset, the lobe and the "
                         "medulla's bounces all draw from it)")
    return wi


def sample(params, wi, key):
    """``(wo, weight, pdf)``: the continuous part of f (the delta excluded; :func:`transmission`). A fibre
    j is drawn with probability w_j / (1 - w_t), then an offset and a lobe; ``weight`` = (1 - w_t) x
    that fibre's S_h cos / pdf_h (bands), ``pdf`` = its event's probability x pdf_h (1/sr)."""
    wo, weight, pdf, _ = _draw_jit(params, _checked(params, wi, key, "sample"), key, False)
    return wo, weight, pdf


def sample_events(params, wi, key):
    """Padrón's sampler [T:1056]: one of the four events (:data:`EVENTS`) with probabilities (w_b, w_bp,
    w_bd, w_t), then the fibre's sampler or the straight pass wo = -wi. Returns ``(wo, weight, event)``:
    E[weight g(wo)] = int f |wo . n| g dwo + w_t g(-wi) for any g; a fibre event's weight is that fibre's
    S_h cos / pdf_h, the delta's 1."""
    wo, weight, _, event = _draw_jit(params, _checked(params, wi, key, "sample_events"), key, True)
    return wo, weight, event


sample.kernel = _sample
sample_events.kernel = _sample_events

# Fig. 5.7's fibre (off-centre medulla, e_b = 1.6) with Fig. 5.9's barbules; the "only masking"
# ablation of Fig. 5.8 (no medulla); the most transparent vane of Fig. 5.10 (delta_bb = 3)
PRESETS = {
    "thesis": Params(),
    "no_medulla": Params(medulla=False),
    "transparent": Params(delta_bb=3.0),
}

MODEL = Model(
    name="feather",
    kind="bsdf",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="feather vane BSDF: two-scale barb/barbule masking + feather_fiber BCSDFs (T: transmission())",
    source="Padrón 2025, Ch. 5 (Eq. 5.4), spec seed-000 M23-M25",
    reciprocal=False,
    transmissive=True,
    presets=PRESETS,
    stochastic=True,
)
