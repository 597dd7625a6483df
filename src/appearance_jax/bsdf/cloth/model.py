"""Sadeghi's practical cloth model: a weave of thread families scattered by the thread BCSDF,
with tangent curves, masking/shadowing and reweighting (Sadeghi 2011 Ch. 5, Sadeghi Eqs.
5.12-5.20, App. E; Sadeghi et al. 2013, "A practical microcylinder appearance model for cloth
rendering", ACM TOG 32(2)). Spec seed-002 §1.4.

The smallest repeating patch of the weave holds J thread families (J = 2 in the thesis: "the
formulations ... can be trivially extended to any number of threads", L2394). Family j runs
along u_j = (cos b_j, sin b_j, 0), b_j = ``rotation`` + ``family_angle[j]`` (family 1 along the
surface tangent x, family 2 along y = N x x), covers the fraction ``coverage[j]`` = a_j of the
patch, and has a tangent curve (``offsets``, ``lengths``; :mod:`.weave`) sampled at T =
``n_samples`` points C_j. Each tangent sample t(alpha) = cos(alpha) u_j + sin(alpha) N with
local normal n(alpha) = -sin(alpha) u_j + cos(alpha) N and v_j = N x u_j scatters with the thread
BCSDF f_s of :mod:`appearance_jax.bcsdf.thread` (Sadeghi Eq. 5.11) with family j's parameters,
is masked by M(t) (Sadeghi Eqs. 5.14-5.16) and reweighted by its projected length P(t) (Sadeghi
Eqs. 5.18-5.19):

    R(w_i, w_r) = sum_j a_j [sum_{t in C_j} f_s(t, w_i, w_r) M(t) P(t) cos theta_i(t)] / sum_{k in C} P(k)   (5.12, 5.20)

with C = C_1 u ... u C_J (J T samples) and cos theta_i(t) = sqrt(1 - (w_i.t)^2) the *thread*
(curve-irradiance) cosine of Sadeghi Eq. 5.6.

**Output convention (D-C4).** The thesis' L_r(w_r) = int L_i(w_i) R(w_i, w_r) dw_i (Sadeghi
Eq. 5.20) makes R a *radiance response* with no N.w_i (:func:`radiance_response`); :func:`eval`
returns the BRDF

    f(w_i, w_r) = R(w_i, w_r) / (N . w_i)                           (1/sr)

(what gonioreflectometer and MERL tables measure; ``f cos theta_o`` is the integrand of the
albedo). Neither form is reciprocal (cos theta_i(t) / (N.w_i) is asymmetric), although f_s, M
and P each are: ``MODEL.reciprocal = False``.

**Energy (this library's decisions; not in the thesis).** Taken literally, the albedo exceeds 1
near grazing incidence. Three options bound it; :func:`thesis_form` switches all three off:

- ``incident_cosine="patch"`` (default; ``"thread"`` is the thesis' formula) gates the response
  by min(1, N.w_i / E), E the weave's average intercepted light per unit area (the weights of
  Sadeghi Eq. 5.20; :func:`_patch_gate`): it acts only on tilted tangents facing a grazing light
  and is 1 below ~75 deg incidence for every preset.
- ``thread_energy="capped"`` (D-C10; ``"thesis"``) divides each tangent sample's f_s by
  max(1, rho), rho its exit albedo (:mod:`.energy`): no sample sends out more than it intercepts.
  Where every rho <= 1 the model is the thesis' (bit-identical).
- ``normalization_floor="grazing"`` (D-C11; ``"always"``, ``"none"`` = Sadeghi Eq. 5.20) raises
  Sadeghi Eq. 5.20's denominator sum_k P(t_k, w_i, w_r) to at least s F, F = sum_k a_k P(t_k, w_i), with s
  ramped smoothly (smoothstep in cos theta_i) from 0 at 75 deg to 1 at 85 deg incidence; the
  patch gate's E becomes the larger of its Sadeghi Eq. 5.20 value and s E_W (the intercepted light under
  the floor's weights). With s = 1 and the cap the albedo is <= 1 by construction; below 75 deg the
  model is the thesis' normalisation, bit for bit. With ``reweighting=False`` the floor does nothing.

The measured albedos, the effect of each decision on the presets and their history:
``docs/cloth.md``.

Other decisions (spec seed-002 §6): D-C1 ``theta_d`` and D-C2 ``volume_fresnel`` as in
:mod:`~appearance_jax.bcsdf.thread`; D-C3 gammas in degrees at this boundary; D-C5
``masking_width`` = 20 deg; D-C6 ``tangent_sign`` +1 (t = cos a u + sin a N) or -1;
D-C8 velvet gamma_s 6 deg (:func:`velvet`); D-C9 T = ``n_samples`` = 64 (midpoint samples).
``normalization="all"`` is Sadeghi Eq. 5.20 (divide by the sum of P over all J T tangents: with
P = 1 each family is weighted a_j / J); ``"per_family"`` divides family j by the sum over C_j only
(a coverage-weighted mean; not in the thesis). ``masking``/``reweighting`` = False set
M = 1 / P = 1 (Sadeghi Eqs. 5.17 and 5.13).

Family parameters are arrays with the family axis last (bands after it for ``albedo``):

| parameter     | default              | range       | unit | meaning                                           |
|---------------|----------------------|-------------|------|---------------------------------------------------|
| eta           | 1.46                 | [1, 3]      | 1    | refractive index of the threads                   |
| albedo        | (J, bands) 0.3       | [0, 1]      | 1    | A per family and band (Eq. 5.9)                   |
| k_d           | (J,) 0.3             | [0, 1]      | 1    | isotropic volume fraction per family              |
| gamma_s       | (J,) 12              | (0, 90]     | deg  | surface Gaussian std per family (Eq. 5.7)         |
| gamma_v       | (J,) 24              | (0, 90]     | deg  | volume Gaussian std per family (Eq. 5.9)          |
| coverage      | (J,) 0.5             | [0, 1]      | 1    | a_j, area fraction per family (Eq. 5.12)          |
| offsets       | (J, K) {-25, 25}     | [-90, 90]   | deg  | tangent-curve offsets (App. E)                    |
| lengths       | (J, K-1) {1}         | [0, inf)    | 1    | tangent-curve segment lengths (0 = jump)          |
| family_angle  | (J,) (0, 90)         | [-360, 360] | deg  | direction of family j in the surface plane        |
| rotation      | 0                    | [-360, 360] | deg  | rotation of the whole weave about N               |
| masking_width | 20                   | (0, 90]     | deg  | std of u(.) in Eqs. 5.16, 5.19 (D-C5)             |
| n_samples     | 64                   | [1, 1024]   | -    | T, samples per tangent curve (D-C9)               |
| theta_d, volume_fresnel | "half", "longitudinal" | | -  | D-C1, D-C2                                        |
| tangent_sign  | 1                    | 1, -1       | -    | D-C6                                              |
| masking, reweighting | True, True    |             | -    | M and P on/off                                    |
| normalization | "all"                | all, per_family | - | denominator of Eq. 5.20                        |
| n_rotations   | 1                    | [1, 64]     | -    | average over K weave rotations (isotropic samples)|
| incident_cosine | "patch"            | patch, thread | -  | energy gate (above) or the thesis' formula        |
| thread_energy | "capped"             | capped, thesis | -   | D-C10 albedo cap (above) or the thesis' formula   |
| normalization_floor | "grazing"      | grazing, always, none | - | D-C11 floor of Eq. 5.20's denominator (above) |

Presets (``PRESETS``, :mod:`.presets`, with the OCR repairs documented there):
``linen_plain``, ``silk_crepe_de_chine``, ``polyester_satin_front``, ``polyester_satin_back``,
``silk_shot``, ``velvet``. The two imaginary fabrics of Fig. 5.32 (Shantung; asymmetric
specular peaks) have no parameters in the thesis and are not presets.

Sampling: with probability P_D = 0.2 a cosine-weighted direction about N (covers k_d and the
tails); else a tangent sample (j, k) is chosen with probability
w_jk proportional to a_j (cos theta_i(t) M(t, w_i) P(t, w_i) + 0.1), one of the two Gaussians
(gamma_s or gamma_v, probability 1/2 each) gives theta_h ~ N(0, gamma), theta_r = 2 theta_h -
theta_i(t) (so theta_r ~ N(-theta_i, 2 gamma): the specular cone), and phi_r ~ U(-pi/2, pi/2)
about n(alpha) (the front half; M = 0 behind). |theta_r| >= pi/2 or w_o below the horizon is a
failed sample (weight 0, pdf 0). ``pdf`` is the exact density of this procedure: the mixture
over all J T tangents, p(w) = P_D cos theta_o / pi + (1 - P_D) sum_jk w_jk
[g(2 gamma_s, theta_r + theta_i) + g(2 gamma_v, theta_r + theta_i)] / 2 [w.n > 0] / (pi cos theta_r).

Example::

    from appearance_jax.bsdf import cloth
    from appearance_jax.core.frame import in_plane_directions
    p = cloth.PRESETS["polyester_satin_front"]
    wi, wo = in_plane_directions(0.0, jnp.linspace(-1.4, 1.4, 57))   # the plane through u (family 1)
    f = cloth.eval(p, wi, wo)                                        # (57, 3) BRDF, 1/sr
    r = cloth.radiance_response(p, wi, wo)                           # = f * cos(theta_i)
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from ...bcsdf import thread
from ...core import warp
from ...core.fusion import materialize
from ...core.model import LazyPresets, Model, boundary, with_bands
from ...core.params import Bands, integer, param, params_class, Real, static
from ...core.rng import uniforms
from ...core.special import erfinv, safe_asin, safe_div, safe_sqrt, smoothstep
from ...core.vec import Vec3
from . import energy, presets, weave

DEG = math.pi / 180.0
P_DIFFUSE = 0.2  # probability of the cosine-weighted lobe in the sampler
TANGENT_FLOOR = 0.1  # keeps every tangent's selection weight positive
FLOORS = ("grazing", "always", "none")  # D-C11
FLOOR_RAMP = (75.0, 85.0)  # deg: the "grazing" floor's weight rises from 0 to 1 over this range of theta_i


def _width(v):
    v = float(v)
    if not (0.0 < v <= 90.0):
        raise ValueError("must be in (0, 90] degrees")
    return v


@params_class
class Params:
    eta: Real = param(1.46, lo=1.0, hi=3.0, doc="refractive index of the threads")
    albedo: Bands = param(((0.3, 0.3, 0.3), (0.3, 0.3, 0.3)), lo=0.0, hi=1.0,
                           doc="A per family (rows) and band (last axis)", bands=True)
    k_d: Real = param((0.3, 0.3), lo=0.0, hi=1.0, doc="isotropic volume fraction per family")
    gamma_s: Real = param((12.0, 12.0), lo=0.0, hi=90.0, lo_open=True, unit="deg",
                            doc="surface Gaussian std per family")
    gamma_v: Real = param((24.0, 24.0), lo=0.0, hi=90.0, lo_open=True, unit="deg",
                            doc="volume Gaussian std per family")
    coverage: Real = param((0.5, 0.5), lo=0.0, hi=1.0, doc="area coverage a_j per family")
    offsets: Real = param(((-25.0, 25.0), (-25.0, 25.0)), lo=-90.0, hi=90.0, unit="deg",
                            doc="tangent-curve offsets per family (rows)")
    lengths: Real = param(((1.0,), (1.0,)), lo=0.0, doc="tangent-curve segment lengths per family (0 = jump)")
    family_angle: Real = param((0.0, 90.0), lo=-360.0, hi=360.0, unit="deg",
                                 doc="direction of each family in the surface plane")
    rotation: Real = param(0.0, lo=-360.0, hi=360.0, unit="deg", doc="rotation of the weave about the normal")
    masking_width: float = static(20.0, convert=_width, doc="std (deg) of u() in Sadeghi Eqs. 5.16, 5.19 (D-C5)")
    n_samples: int = static(64, convert=integer(1, 1024), doc="T, samples per tangent curve (D-C9)")
    theta_d: str = static("half", choices=thread.THETA_D, doc="D-C1: theta_d in 1/cos^2 theta_d")
    volume_fresnel: str = static("longitudinal", choices=thread.VOLUME_FRESNEL, doc="D-C2: volume Fresnel")
    tangent_sign: int = static(1, choices=(1, -1), doc="D-C6: t = cos a u + sign sin a N")
    masking: bool = static(True, choices=(True, False), doc="masking/shadowing M (Sadeghi Eqs. 5.14-5.16)")
    reweighting: bool = static(True, choices=(True, False), doc="reweighting P (Sadeghi Eqs. 5.18-5.19)")
    normalization: str = static("all", choices=("all", "per_family"), doc="denominator of Sadeghi Eq. 5.20")
    n_rotations: int = static(1, convert=integer(1, 64),
                              doc="average over this many weave rotations 360 k / K deg (1 = off)")
    incident_cosine: str = static("patch", choices=("patch", "thread"),
                                  doc="thread cosine gated by the patch's irradiance (default) or as in the thesis")
    thread_energy: str = static("capped", choices=("capped", "thesis"),
                                doc="D-C10: f_s / max(1, rho) per tangent sample (default) or as in the thesis")
    normalization_floor: str = static("grazing", choices=FLOORS,
                                      doc="D-C11: Sadeghi Eq. 5.20's denominator floored at sum_k a_k P(t_k, w_i) above "
                                          "75 deg incidence (default), at every incidence, or never (the thesis)")

    def _validate(self):
        label = "cloth.Params"
        j = np.shape(self.coverage)[-1]
        for name in ("k_d", "gamma_s", "gamma_v", "family_angle"):
            if np.shape(getattr(self, name))[-1:] != (j,):
                raise ValueError(f"{label}.{name} has shape {np.shape(getattr(self, name))}: its last axis must be "
                                 f"the {j} families of coverage")
        if np.ndim(self.albedo) < 2 or np.shape(self.albedo)[-2] != j:
            raise ValueError(f"{label}.albedo has shape {np.shape(self.albedo)}: expected (..., {j}, bands)")
        o, ln = np.shape(self.offsets), np.shape(self.lengths)
        if len(o) < 2 or o[-2] != j or o[-1] < 2 or ln[-2:] != (j, o[-1] - 1):
            raise ValueError(f"{label}.offsets {o} / lengths {ln}: expected (..., {j}, K >= 2) / (..., {j}, K - 1)")
        total = np.sum(np.asarray(self.lengths), axis=-1)
        if np.any(total <= 0):
            raise ValueError(f"{label}.lengths: total length {float(np.min(total)):g} of a tangent curve must be > 0")


# ----------------------------------------------------------------------------------------
# geometry of the tangent samples


def _family(p: Params):
    """Per-sample arrays, shape (..., J, T): alpha (rad); per family (..., J, 1): cos/sin b."""
    alpha = weave.sample_curve(p.offsets, p.lengths, p.n_samples) * (DEG * p.tangent_sign)
    b = (p.rotation[..., None] + p.family_angle) * DEG
    return alpha, jnp.cos(b)[..., None], jnp.sin(b)[..., None]


def _components(w: Vec3, alpha, cb, sb):
    """(w.t, w.n, w.v) per tangent sample; w's components get two trailing axes (J, T)."""
    x, y, z = (jnp.asarray(c)[..., None, None] for c in w)
    wu = x * cb + y * sb
    wv = -x * sb + y * cb
    ca, sa = materialize((jnp.cos(alpha), jnp.sin(alpha)))  # (J, T) curve: not recomputed per consumer
    return materialize((ca * wu + sa * z, -sa * wu + ca * z, wv))


def _fam(x):
    """A per-family array (..., J) -> (..., J, 1) to broadcast over the T samples."""
    return jnp.asarray(x)[..., None]


def _patch_gate(in_, weights, wi_z, floor_weights=None, strength=0.0):
    """min(1, N.w_i / E): the share of the weave's intercepted light that the patch can receive
    (``incident_cosine="patch"``; not in the thesis, see the module docstring).

    M(t, w_i) cos theta_i(t) = max(n(alpha).w_i, 0) is the light a tangent sample intercepts per
    unit area of its own (tilted) element; E = sum_t weights_t max(n(alpha).w_i, 0) is its
    average over the weave (``weights`` (..., J, T): Sadeghi Eq. 5.20's). A flat patch can intercept no
    more than N.w_i per unit area, so where E > N.w_i (tilted tangents facing a grazing light,
    which a real weave shadows) every sample is scaled down by N.w_i / E. For alpha = 0,
    max(n.w_i, 0) = N.w_i and, with weights summing to <= 1, the gate is 1: only tilted
    tangents can trigger it. With the normalisation floor (D-C11) E is at least ``strength``
    times the same average under ``floor_weights`` (w_i alone; :func:`_weights`).
    """
    lit = jnp.maximum(in_, 0.0)
    e = jnp.sum(weights * lit, axis=(-2, -1))
    if floor_weights is not None:
        e = jnp.maximum(e, strength * jnp.sum(floor_weights * lit, axis=(-2, -1)))
    # e > 0 as well: below the horizon (wi_z < 0, value 0) e can be 0, and wi_z / 0 = -inf there
    # made the masked response NaN and every gradient NaN; above the horizon e > wi_z > 0 anyway
    ok = (e > wi_z) & (e > 0.0)
    return jnp.where(ok, wi_z / jnp.where(ok, e, 1.0), 1.0)


def _floor_strength(p: Params, wi_z):
    """s(theta_i) of D-C11: 1 (``"always"``) or a smoothstep from 0 to 1 over FLOOR_RAMP."""
    if p.normalization_floor == "always":
        return jnp.ones_like(wi_z)
    lo, hi = (math.cos(v * DEG) for v in FLOOR_RAMP)
    return smoothstep((lo - wi_z) / (lo - hi))  # 0 below 75 deg, 1 above 85 deg (in cos theta_i)


def _weights(p: Params, P, P_i, wi_z):
    """Eq. 5.20's sample weights a_j P(t) / D (..., J, T), and (floor_weights, strength) for
    the patch gate (None, 0 without the floor).

    D = sum_k P(t_k, w_i, w_r) over all J T samples (``normalization="all"``) or over family j's
    (``"per_family"``). The floor (D-C11) raises D to at least s F, F = sum_k a_k P(t_k, w_i)
    (``"all"``; per family: sum_j a_j times sum_{k in C_j} P(t_k, w_i)), s = :func:`_floor_strength`.
    Where s = 1 every weight is <= W_t = a_j P(t, w_i) / F, since P(t, w_i, w_r) <= P(t, w_i):
    the W_t depend on w_i alone and sum to 1, so with the gate taken over them and each sample
    capped (D-C10) the albedo is <= 1 (module docstring). F is the smallest floor for which flat
    weaves (all alpha = 0) stay ungated.
    """
    a = _fam(p.coverage)
    axes = (-2, -1) if p.normalization == "all" else (-1,)
    den = jnp.sum(P, axis=axes, keepdims=True)
    if p.normalization_floor == "none" or not p.reweighting:  # P = 1: the weights depend on w_i alone
        return a * safe_div(P, den), None, 0.0
    if p.normalization == "all":
        floor = jnp.sum(a * P_i, axis=axes, keepdims=True)
    else:
        floor = jnp.sum(P_i, axis=axes, keepdims=True) * jnp.sum(a, axis=-2, keepdims=True)
    s = _floor_strength(p, wi_z)
    den = jnp.maximum(den, s[..., None, None] * floor)
    return a * safe_div(P, den), a * safe_div(P_i, floor), s


def _response(p: Params, wi: Vec3, wo: Vec3):
    """R(w_i, w_r) of Eq. 5.20 (bands last), 0 where either direction is at/below the horizon."""
    alpha, cb, sb = _family(p)
    it, in_, iv = _components(wi, alpha, cb, sb)
    ot, on, ov = _components(wo, alpha, cb, sb)
    fs = thread.from_dots(p, it, in_, iv, ot, on, ov, eta=jnp.asarray(p.eta)[..., None, None],
                          albedo=jnp.asarray(p.albedo)[..., :, None, :], k_d=_fam(p.k_d),
                          gamma_s=_fam(p.gamma_s) * DEG, gamma_v=_fam(p.gamma_v) * DEG)
    if p.thread_energy == "capped":  # D-C10: no sample sends out more than it intercepts
        tables = energy.exit_tables(p, p.eta, p.albedo, p.k_d, jnp.asarray(p.gamma_s) * DEG,
                                          jnp.asarray(p.gamma_v) * DEG)
        fs = fs * energy.cap(energy.exit_albedo(tables, safe_asin(jnp.clip(it, -1.0, 1.0)), alpha))
    width = p.masking_width * DEG
    M = weave.masking(in_, iv, on, ov, width) if p.masking else jnp.ones_like(it)
    if p.reweighting:
        P, P_i = weave.reweighting(it, in_, ot, on, width), weave.single(it, in_, iv)[1]
    else:
        P = P_i = jnp.ones_like(it)
    wi_z = jnp.asarray(wi.z)
    weights, floor_weights, strength = _weights(p, P, P_i, wi_z)
    w = weights * M * safe_sqrt(1.0 - it * it)  # cos theta_i(t): the thread (curve-irradiance) cosine
    r = jnp.sum(fs * w[..., None], axis=(-3, -2))
    if p.incident_cosine == "patch":
        r = r * _patch_gate(in_, weights, wi_z, floor_weights, strength)[..., None]
    ok = (wi.z > 0) & (wo.z > 0)
    return jnp.where(with_bands(ok), r, 0.0)


def _rotate_z(w: Vec3, c, s):
    """w rotated by the angle (c = cos, s = sin) about the normal z."""
    return Vec3(c * w.x - s * w.y, s * w.x + c * w.y, w.z * jnp.ones_like(c))


def _rotation_average(fn, p: Params, wi: Vec3, wo: Vec3):
    """fn averaged over the weave rotated by 360 k / K deg, k < K = ``n_rotations`` (rotating
    the weave by b is rotating both directions by -b): the model of a sample whose weave
    orientation varies over the measured area, or an isotropic measurement such as MERL's."""
    K = p.n_rotations
    if K == 1:
        return fn(p, wi, wo)
    b = -2.0 * jnp.pi * jnp.arange(K) / K
    c, s = (v.reshape((K,) + (1,) * len(jnp.broadcast_shapes(wi.shape, wo.shape))) for v in (jnp.cos(b), jnp.sin(b)))
    return jnp.mean(fn(p, _rotate_z(wi, c, s), _rotate_z(wo, c, s)), axis=0)


def _brdf(p: Params, wi: Vec3, wo: Vec3):
    r = _response(p, wi, wo)
    ok = wi.z > 0
    return r / with_bands(jnp.where(ok, wi.z, 1.0))


def _eval(p: Params, wi: Vec3, wo: Vec3):
    return _rotation_average(_brdf, p, wi, wo)


def _radiance_response(p: Params, wi: Vec3, wo: Vec3):
    return _rotation_average(_response, p, wi, wo)


# ----------------------------------------------------------------------------------------
# sampling


def _tangent_weights(p: Params, wi: Vec3):
    """Selection probabilities w_jk of the tangent samples (..., J, T) and the geometry."""
    alpha, cb, sb = _family(p)
    it, in_, iv = _components(wi, alpha, cb, sb)
    Mi, Pi = weave.single(it, in_, iv)
    w = _fam(p.coverage) * (safe_sqrt(1.0 - it * it) * Mi * Pi + TANGENT_FLOOR)
    w = w / jnp.sum(w, axis=(-2, -1), keepdims=True)
    return w, alpha, cb, sb, it


def _gauss(sigma, x):
    return thread.gaussian(sigma, x)


def _lobe_density(p: Params, wi: Vec3, wo: Vec3):
    """Density of the tangent lobes (..., ) and of the cosine lobe, per unit solid angle."""
    w, alpha, cb, sb, it = _tangent_weights(p, wi)
    ot, on, ov = _components(wo, alpha, cb, sb)
    th_i = safe_asin(jnp.clip(it, -1.0, 1.0))
    th_r = safe_asin(jnp.clip(ot, -1.0, 1.0))
    cr = safe_sqrt(1.0 - ot * ot)
    x = th_r + th_i
    dens = 0.5 * (_gauss(2.0 * _fam(p.gamma_s) * DEG, x) + _gauss(2.0 * _fam(p.gamma_v) * DEG, x))
    ok = (on > 0) & (cr > 1e-9)
    q = jnp.where(ok, dens / (jnp.pi * jnp.where(ok, cr, 1.0)), 0.0)
    return jnp.sum(w * q, axis=(-2, -1))


def _pdf(p: Params, wi: Vec3, wo: Vec3):
    ok = (wi.z > 0) & (wo.z > 0)
    lobes = _rotation_average(_lobe_density, p, wi, wo)
    pdf = P_DIFFUSE * jnp.maximum(wo.z, 0.0) / jnp.pi + (1.0 - P_DIFFUSE) * lobes
    return jnp.where(ok, pdf, 0.0)


def _sample(p: Params, wi: Vec3, u):
    shape = wi.shape
    u0, u1, u2, u3, u4 = uniforms(u, shape, 5)
    wi_given = wi
    if p.n_rotations > 1:  # rotation k from u0, uniform on [P_DIFFUSE, 1) in the tangent branch
        k = jnp.floor((u0 - P_DIFFUSE) / (1.0 - P_DIFFUSE) * p.n_rotations)
        b = -2.0 * jnp.pi * jnp.clip(k, 0, p.n_rotations - 1) / p.n_rotations
        wi = _rotate_z(wi, jnp.cos(b), jnp.sin(b))
    w, alpha, cb, sb, it = _tangent_weights(p, wi)
    J, T = w.shape[-2:]
    flat = jnp.broadcast_to(w, shape + (J, T)).reshape(shape + (J * T,))
    cdf = jnp.cumsum(flat, axis=-1)
    idx = jnp.clip(jnp.sum(cdf <= (u1 * cdf[..., -1])[..., None], axis=-1), 0, J * T - 1)

    def pick(a):  # (..., J, T) or (..., J, 1) -> value at the chosen sample
        a = jnp.broadcast_to(a, shape + (J, T)).reshape(shape + (J * T,))
        return jnp.take_along_axis(a, idx[..., None], axis=-1)[..., 0]

    a_k, cb_k, sb_k, it_k = pick(alpha), pick(cb), pick(sb), pick(it)
    gam = jnp.where(u2 < 0.5, pick(_fam(p.gamma_s)), pick(_fam(p.gamma_v))) * DEG
    # theta_h ~ N(0, gamma) by the inverse normal CDF; theta_r = 2 theta_h - theta_i
    z = math.sqrt(2.0) * erfinv(jnp.clip(2.0 * u3 - 1.0, -1.0 + 1e-12, 1.0 - 1e-12))
    th_r = 2.0 * gam * z - safe_asin(jnp.clip(it_k, -1.0, 1.0))
    ph_r = (u4 - 0.5) * jnp.pi
    ct, st = jnp.cos(th_r), jnp.sin(th_r)
    ca, sa = jnp.cos(a_k), jnp.sin(a_k)
    # t = ca u + sa N, n = -sa u + ca N, v = N x u = (-sb, cb, 0)
    wt_c, wn_c, wv_c = st, ct * jnp.cos(ph_r), ct * jnp.sin(ph_r)
    ux, uy = cb_k, sb_k
    lx = wt_c * ca * ux - wn_c * sa * ux - wv_c * sb_k
    ly = wt_c * ca * uy - wn_c * sa * uy + wv_c * cb_k
    lz = wt_c * sa + wn_c * ca
    wo_t = Vec3(lx, ly, lz)
    if p.n_rotations > 1:
        wo_t = _rotate_z(wo_t, jnp.cos(b), -jnp.sin(b))
        wi = wi_given
    wo_d = warp.square_to_cosine_hemisphere(u1, u3)
    diffuse = u0 < P_DIFFUSE
    wo = Vec3(*(jnp.where(diffuse, a, b) for a, b in zip(wo_d, wo_t)))
    valid = diffuse | (jnp.abs(th_r) < 0.5 * jnp.pi)
    pdf = _pdf(p, wi, wo)
    ok = valid & (wi.z > 0) & (wo.z > 0) & (pdf > 0)
    pdf = jnp.where(ok, pdf, 0.0)
    f = _eval(p, wi, wo)
    scale = jnp.where(ok, wo.z / jnp.where(ok, pdf, 1.0), 0.0)
    return wo, f * with_bands(scale), pdf


eval = boundary(_eval, Params)
"""BRDF f = R / (N.w_i) in 1/sr, bands last (D-C4; module docstring)."""
radiance_response = boundary(_radiance_response, Params)
"""The thesis' radiance response R(w_i, w_r) of Sadeghi Eq. 5.20 (= eval * N.w_i), bands last."""
pdf = boundary(_pdf, Params)
sample = boundary(_sample, Params)


def from_weave(curves, coverage, *, eta=1.46, albedo=0.3, k_d=0.3, gamma_s=12.0, gamma_v=24.0,
               family_angle=None, **kw) -> Params:
    """Params from a list of :class:`.weave.Curve` (one per family) and per-family (or shared)
    thread parameters; ``family_angle`` defaults to 0, 90, 0, 90, ... deg."""
    c = weave.stack(curves)
    j = len(curves)
    fam = lambda v: jnp.broadcast_to(jnp.asarray(v, dtype=jnp.result_type(float)), (j,))  # noqa: E731
    alb = jnp.asarray(albedo, dtype=jnp.result_type(float))
    alb = jnp.broadcast_to(alb if alb.ndim == 2 else jnp.atleast_1d(alb)[None, :], (j, max(alb.shape[-1:] or (1,))))
    if family_angle is None:
        family_angle = [90.0 * (k % 2) for k in range(j)]
    return Params(eta=eta, albedo=alb, k_d=fam(k_d), gamma_s=fam(gamma_s), gamma_v=fam(gamma_v),
                  coverage=fam(coverage), offsets=c.offsets, lengths=c.lengths, family_angle=fam(family_angle), **kw)


def thesis_form(p: Params) -> Params:
    """``p`` with this library's three energy decisions switched off: the thread cosine of
    Sadeghi Eq. 5.6 (``incident_cosine="thread"``), the thesis' thread BCSDF (``thread_energy="thesis"``)
    and Sadeghi Eq. 5.20's denominator (``normalization_floor="none"``). The result is Sadeghi's model
    literally, whose albedo exceeds 1 near grazing incidence (module docstring)."""
    return p.replace(incident_cosine="thread", thread_energy="thesis", normalization_floor="none")


def preset(name: str, velvet_gamma_s: float = 6.0, **kw) -> Params:
    """A fabric of Table 5.2 / E.1 (``presets.TABLE``); ``kw`` overrides fields/options."""
    return Params(**{**presets.kwargs(name, velvet_gamma_s=velvet_gamma_s), **kw})


def velvet(gamma_s: float = 6.0, **kw) -> Params:
    """Velvet (Table 5.2 / E.1); gamma_s = 6 deg (repaired) or 9 (the OCR reading), D-C8."""
    return preset("velvet", velvet_gamma_s=gamma_s, **kw)


# built on first use: stacking the curves of six fabrics is work no `import` should pay for
PRESETS = LazyPresets(presets.TABLE, preset)

MODEL = Model(
    name="cloth",
    kind="bsdf",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="Sadeghi's microcylinder cloth: thread BCSDF over tangent curves, masking, reweighting",
    source="Sadeghi 2011 Ch. 5, App. E; Sadeghi et al. 2013 (ACM TOG 32(2))",
    reciprocal=False,
    presets=PRESETS,
)
