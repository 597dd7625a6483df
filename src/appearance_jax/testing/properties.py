"""Physical-property checks of a model: reciprocity, white furnace, sample/pdf consistency.

Each ``check_*`` takes a model (any object with the fields of
:class:`appearance_jax.core.model.Model`: ``name``, ``kind``, ``eval``, ``sample``, ``pdf``,
``transmissive``), a parameter pytree, and fixed keys; it returns a result dataclass (numbers,
``passed``, ``message``). ``assert_*`` runs the check and raises ``AssertionError(message)``
when it fails.

Statistical tolerances come from the estimators' standard errors: a Monte Carlo estimate
``m`` with standard error ``se`` is compared as ``|m - ref| <= k se + atol`` where ``k`` is
the two-sided normal quantile of the requested family-wise ``significance``,
Sidak-corrected over the number of comparisons (:func:`.results.z_threshold`). ``atol``
is a rounding floor for estimators whose variance is 0 (e.g. a Lambertian sampler's
weights are constant). The quadrature's error is estimated by comparing with a rule of
half the resolution, ``err = |Q(n) - Q(n/2)|`` (conservative: Gauss-Legendre converges
fast, so Q(n) is usually far better than that); quadrature comparisons allow
``quad_tol + err``, and a quadrature with ``err > max_quad_error`` is declared unconverged
(a failure: raise ``n_theta``/``n_phi`` for peaked lobes).

Parameters must broadcast against direction arrays of shape ``(n_wi, n)`` (band-valued
fields with a trailing bands axis are fine; spatially varying leading axes are not).
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ..core.quadrature import sphere_rule
from ..core.vec import Vec3
from .directions import (
    as_key,
    call_chunked,
    domain_solid_angle,
    incident_domain,
    np_basis,
    np_vec,
    projection_cosine,
    random_directions,
    sample_chunked,
    scattering_domain,
)
from .results import CheckResult, default_atol, default_rtol, fmt, z_threshold


def _np(x) -> np.ndarray:
    return np.asarray(x)


def _vec_np(w: Vec3, idx) -> tuple:
    return tuple(float(np.asarray(c)[idx]) for c in (w.x, w.y, w.z))


def _default_wi(model, key, n_wi: int, min_cos: float) -> Vec3:
    return np_vec(random_directions(key, n_wi, incident_domain(model), min_cos=min_cos))


def _repeat(wi: Vec3, n: int) -> Vec3:
    """``wi`` of shape ``(m,)`` -> jax arrays of shape ``(m, n)`` (for ``sample``)."""
    m = np.shape(wi.x)[0]
    return Vec3(*(jnp.asarray(np.broadcast_to(np.asarray(c).reshape(m, 1), (m, n))) for c in wi))


def _cos_np(cosine, w: Vec3) -> np.ndarray:
    return np.asarray(cosine(Vec3(*(jnp.asarray(c) for c in w))))


# ======================================================================================
# reciprocity


@dataclass(frozen=True)
class ReciprocityResult(CheckResult):
    n_pairs: int
    max_abs_error: float  # max |f(wi, wo) - f(wo, wi)| [1/sr]
    max_rel_error: float  # the same relative to max(|f(wi, wo)|, |f(wo, wi)|)
    max_value: float  # max |f| over the pairs [1/sr], the scale of the comparison
    worst_wi: tuple
    worst_wo: tuple
    rtol: float
    atol: float


def reciprocity_pairs(model, params, key=0, n: int = 512) -> tuple[Vec3, Vec3]:
    """Test pairs for reciprocity: half uniform, half with wo drawn by the model's sampler.

    Uniform pairs alone rarely land in a narrow lobe, where a non-reciprocal term would
    be largest; sampled pairs concentrate where f is large. Failed samples fall back to
    the uniform directions.
    """
    k1, k2, k3 = jax.random.split(as_key(key), 3)
    dom = incident_domain(model)
    wi = random_directions(k1, n, dom)
    wo = np_vec(random_directions(k2, n, dom))
    if getattr(model, "sample", None) is not None:
        ws, _, pdf = sample_chunked(model, params, wi, k3)
        use = (np.arange(n) % 2 == 1) & (np.asarray(pdf) > 0)
        wo = Vec3(*(np.where(use, np.asarray(a), b) for a, b in zip(ws, wo)))
    return np_vec(wi), wo


def check_reciprocity(model, params, *, key=0, n: int = 512, wi: Vec3 | None = None, wo: Vec3 | None = None,
                      rtol: float | None = None, atol: float | None = None) -> ReciprocityResult:
    """f(wi, wo) == f(wo, wi) within ``atol + rtol * max(|f(wi, wo)|, |f(wo, wi)|)`` at ``n`` pairs.

    Pairs are :func:`reciprocity_pairs` unless ``wi``/``wo`` (same shape) are given.
    Defaults: ``rtol`` 1e-6 (float64) / 1e-3 (float32), ``atol`` 1e-10 / 1e-5 [1/sr].
    A non-finite value fails.
    """
    rtol = default_rtol() if rtol is None else rtol
    atol = default_atol() if atol is None else atol
    if wi is None or wo is None:
        wi, wo = reciprocity_pairs(model, params, key, n)
    wi, wo = np_vec(wi), np_vec(wo)
    a = call_chunked(model.eval, params, wi, wo)
    b = call_chunked(model.eval, params, wo, wi)
    finite = bool(np.all(np.isfinite(a)) and np.all(np.isfinite(b)))
    err = np.abs(a - b)
    scale = np.maximum(np.abs(a), np.abs(b))
    excess = err - (atol + rtol * scale)
    flat = int(np.nanargmax(np.where(np.isfinite(excess), excess, np.inf)))
    pair = np.unravel_index(flat, a.shape)[: a.ndim - 1]
    max_rel = float(np.max(np.where(scale > 0, err / np.where(scale > 0, scale, 1.0), 0.0))) if a.size else 0.0
    passed = finite and bool(np.all(excess <= 0))
    name = getattr(model, "name", "model")
    if not finite:
        msg = f"{name}: reciprocity: non-finite f at some of {a.shape[0]} pairs"
    else:
        msg = (f"{name}: reciprocity {'passed' if passed else 'FAILED'} over {err.shape[0]} pairs: "
               f"max |f(wi,wo) - f(wo,wi)| = {fmt(err.max())} 1/sr, max relative error {fmt(max_rel)} "
               f"(tolerance {atol:g} + {rtol:g} |f|; max |f| = {fmt(scale.max())}); worst pair "
               f"wi={_fmt_vec(_vec_np(wi, pair))}, wo={_fmt_vec(_vec_np(wo, pair))}: "
               f"f(wi,wo)={fmt(a[pair].max())}, f(wo,wi)={fmt(b[pair].max())}")
    return ReciprocityResult("reciprocity", passed, msg, int(err.shape[0]), float(err.max()), max_rel,
                             float(scale.max()), _vec_np(wi, pair), _vec_np(wo, pair), rtol, atol)


def assert_reciprocity(model, params, **kw) -> ReciprocityResult:
    return check_reciprocity(model, params, **kw).raise_if_failed()


def _fmt_vec(v) -> str:
    return "(" + ", ".join(f"{c:.4f}" for c in v) + ")"


# ======================================================================================
# albedo: importance sampling and deterministic quadrature


def albedo_mc(model, params, wi: Vec3, *, key=0, n_samples: int = 2**14, cosine=None):
    """Importance-sampled albedo ``A(wi) = int f cos_o dwo``: mean of the sample weights.

    Returns ``(mean, standard_error)``, each of shape ``wi.shape + (n_bands,)``
    (``wi`` of shape ``(m,)``). Failed samples count with weight 0. ``cosine`` defaults to
    :func:`.directions.projection_cosine`; it only matters for the uniform estimate of
    :func:`check_sampling`, since the model's weights already include it.
    """
    del cosine  # the model's weights carry the cosine
    _, weight, _ = sample_chunked(model, params, _repeat(np_vec(wi), n_samples), key)
    return weight.mean(axis=1), weight.std(axis=1, ddof=1) / np.sqrt(n_samples)


def _quadrature_nodes(model, wi: Vec3, n_theta: int, n_phi: int):
    """Quadrature nodes (shape ``(m, M)``) and weights (``(M,)``) over the scattering domain.

    The rule is oriented so that the integrand's features fall on its structure:
    reflection BSDFs use the upper hemisphere of the local frame (f jumps to 0 at the
    horizon); transmissive BSDFs use one hemisphere rule per side (the jump is at an
    endpoint of both); phase functions use a sphere rule whose pole is wi (their
    natural axis: the forward and backward peaks sit on the poles, where the
    Gauss-Legendre nodes in cos theta cluster); fiber BCSDFs use the fiber axis x as pole.
    """
    m = np.shape(wi.x)[0]
    r, wq = sphere_rule(n_theta, n_phi, hemisphere=model.kind == "bsdf")
    r, wq = np_vec(r), np.asarray(wq)
    if model.kind == "phase":
        pole = np_vec(wi).map(lambda a: a.reshape(m, 1))
        s, t = np_basis(pole)
        nodes = s * r.x + t * r.y + pole * r.z
    elif model.kind == "bcsdf":
        nodes = Vec3(r.z[None, :], r.x[None, :], r.y[None, :])
    else:
        if scattering_domain(model) == "sphere":
            # mirror the upper rule into the lower hemisphere
            r = Vec3(np.concatenate([r.x, r.x]), np.concatenate([r.y, r.y]), np.concatenate([r.z, -r.z]))
            wq = np.concatenate([wq, wq])
        nodes = r.map(lambda a: a[None, :])
    return np_vec(nodes, (m, wq.shape[0])), wq


def albedo_quadrature(model, params, wi: Vec3, *, n_theta: int = 128, n_phi: int = 256, cosine=None):
    """Deterministic albedo ``A(wi) = int f(wi, wo) cos_o dwo`` by a product rule.

    Gauss-Legendre in cos theta x midpoint in phi (:func:`appearance_jax.core.quadrature.sphere_rule`),
    oriented per model kind (see :func:`_quadrature_nodes`). Shape ``wi.shape + (n_bands,)``.
    """
    cosine = projection_cosine(model) if cosine is None else cosine
    wi = np_vec(wi)
    nodes, wq = _quadrature_nodes(model, wi, n_theta, n_phi)
    wb = wi.map(lambda a: a[:, None])
    f = call_chunked(model.eval, params, wb, nodes)
    return np.sum(f * (_cos_np(cosine, nodes) * wq)[..., None], axis=1)


@dataclass(frozen=True)
class FurnaceResult(CheckResult):
    wi: np.ndarray  # (n_wi, 3) incident directions
    albedo_mc: np.ndarray  # (n_wi, n_bands) importance-sampled albedo
    se_mc: np.ndarray  # its standard error
    albedo_quad: np.ndarray  # (n_wi, n_bands) quadrature albedo
    quad_error: np.ndarray  # |quadrature - half-resolution quadrature|, an error estimate
    k: float  # standard errors allowed (from the significance)
    quad_tol: float
    lossless: bool
    max_albedo: float


def check_white_furnace(model, params, *, key=0, wi: Vec3 | None = None, n_wi: int = 8, min_cos: float = 0.05,
                        n_samples: int = 2**14, n_theta: int = 128, n_phi: int = 256, lossless: bool = False,
                        significance: float = 1e-4, quad_tol: float = 1e-3, max_quad_error: float = 0.02,
                        atol: float | None = None,
                        quadrature: bool = True, cosine=None) -> FurnaceResult:
    """White furnace: the albedo ``A(wi) = int f cos_o dwo`` is <= 1 (== 1 if ``lossless``).

    ``A`` is estimated twice, by importance sampling (mean of ``sample`` weights and its
    standard error se) and by quadrature; checks, for every incident direction and band:

    - ``A_mc <= 1 + k se + atol`` and ``A_quad <= 1 + tq`` (no energy created);
    - ``|A_mc - A_quad| <= k se + tq + atol`` (sampler weights vs eval);
    - the quadrature is converged: ``err = |A_quad(n) - A_quad(n/2)| <= max_quad_error``;
    - if ``lossless``: ``|A_mc - 1| <= k se + atol`` and ``|A_quad - 1| <= tq``;

    with ``tq = quad_tol + err`` per incident direction and band.

    ``k`` is the two-sided normal quantile of ``significance`` Sidak-corrected over the
    ``3 n_wi n_bands`` Monte Carlo comparisons. Incident directions default to
    ``n_wi`` random ones over the model's incident domain with ``|cos theta_i| >= min_cos``.
    A model without ``sample`` gets the quadrature checks only; ``quadrature=False``
    skips the quadrature.
    """
    kw, ks = jax.random.split(as_key(key))
    atol = default_atol() if atol is None else atol
    wi = _default_wi(model, kw, n_wi, min_cos) if wi is None else np_vec(wi)
    has_mc = getattr(model, "sample", None) is not None
    problems = []
    A_mc = se = A_q = q_err = None
    if has_mc:
        A_mc, se = albedo_mc(model, params, wi, key=ks, n_samples=n_samples)
        bands = A_mc.shape[-1]
    if quadrature:
        A_q = albedo_quadrature(model, params, wi, n_theta=n_theta, n_phi=n_phi, cosine=cosine)
        A_q2 = albedo_quadrature(model, params, wi, n_theta=max(n_theta // 2, 1), n_phi=max(n_phi // 2, 1),
                                 cosine=cosine)
        q_err = np.abs(A_q - A_q2)
        bands = A_q.shape[-1]
    if not has_mc and not quadrature:
        raise ValueError("check_white_furnace: the model has no sampler and quadrature=False: nothing to check")
    k = z_threshold(significance, 3 * wi.shape[0] * bands)
    name = getattr(model, "name", "model")

    def worst(mask, vals, what):
        if np.any(mask):
            i = np.unravel_index(int(np.argmax(np.where(mask, vals, -np.inf))), mask.shape)
            problems.append(f"{what} at wi={_fmt_vec(_vec_np(wi, i[0]))}, band {i[1]}")
            return i
        return None

    for arr in (A_mc, se, A_q):
        if arr is not None and not np.all(np.isfinite(arr)):
            problems.append("non-finite albedo estimate")
    if has_mc:
        bad = A_mc > 1.0 + k * se + atol
        i = worst(bad, A_mc, "A_mc > 1 + k se")
        if i is not None:
            problems[-1] += f" (A_mc={fmt(A_mc[i])} +- {fmt(se[i])})"
    if quadrature:
        tq = quad_tol + q_err
        bad = A_q > 1.0 + tq
        i = worst(bad, A_q, "A_quad > 1 + quad_tol + err")
        if i is not None:
            problems[-1] += f" (A_quad={fmt(A_q[i])})"
        bad = q_err > max_quad_error
        i = worst(bad, q_err, "quadrature not converged (raise n_theta/n_phi)")
        if i is not None:
            problems[-1] += f" (|Q(n) - Q(n/2)| = {fmt(q_err[i])} > {max_quad_error:g})"
    if has_mc and quadrature:
        d = np.abs(A_mc - A_q)
        bad = d > k * se + tq + atol
        i = worst(bad, d / np.maximum(se, 1e-300), "|A_mc - A_quad| > k se + quad_tol + err")
        if i is not None:
            problems[-1] += f" (A_mc={fmt(A_mc[i])} +- {fmt(se[i])}, A_quad={fmt(A_q[i])})"
    if lossless:
        if has_mc:
            d = np.abs(A_mc - 1.0)
            i = worst(d > k * se + atol, d / np.maximum(se, 1e-300), "lossless but |A_mc - 1| > k se")
            if i is not None:
                problems[-1] += f" (A_mc={fmt(A_mc[i])} +- {fmt(se[i])})"
        if quadrature:
            d = np.abs(A_q - 1.0)
            i = worst(d > tq, d, "lossless but |A_quad - 1| > quad_tol + err")
            if i is not None:
                problems[-1] += f" (A_quad={fmt(A_q[i])})"
    passed = not problems
    max_a = float(np.max([np.max(a) for a in (A_mc, A_q) if a is not None]))
    summary = []
    if has_mc:
        summary.append(f"A_mc in [{fmt(A_mc.min())}, {fmt(A_mc.max())}] (max se {fmt(se.max())}, "
                       f"{n_samples} samples)")
    if quadrature:
        summary.append(f"A_quad in [{fmt(A_q.min())}, {fmt(A_q.max())}] (max error estimate {fmt(q_err.max())}, "
                       f"{n_theta}x{n_phi} nodes)")
    msg = (f"{name}: white furnace {'passed' if passed else 'FAILED'} over {wi.shape[0]} incident directions"
           f"{' (lossless: A == 1)' if lossless else ''}: " + "; ".join(summary)
           + f"; k = {k:.2f}, quad_tol = {quad_tol:g}"
           + ("" if passed else ". Problems: " + "; ".join(problems)))
    z = lambda a: np.zeros((wi.shape[0], bands)) if a is None else a  # noqa: E731
    return FurnaceResult("white_furnace", passed, msg, np.stack(list(wi), axis=-1), z(A_mc), z(se), z(A_q), z(q_err),
                         k, quad_tol, lossless, max_a)


def assert_white_furnace(model, params, **kw) -> FurnaceResult:
    return check_white_furnace(model, params, **kw).raise_if_failed()


# ======================================================================================
# sample / pdf / eval consistency


@dataclass(frozen=True)
class SamplingResult(CheckResult):
    n_samples: int  # per incident direction
    failed_fraction: float  # samples with pdf == 0
    max_weight_rel_error: float  # |weight - f cos / pdf| / scale at successful samples
    max_pdf_rel_error: float  # |pdf_sample - pdf(wi, wo)| / scale
    estimate_is: np.ndarray  # (n_wi, n_bands) importance-sampled int f cos dwo
    se_is: np.ndarray
    estimate_uniform: np.ndarray  # (n_wi, n_bands) uniform-sampled estimate of the same
    se_uniform: np.ndarray
    max_z: float  # max |is - uniform| / combined standard error
    k: float


def _rel_err(a, b, atol):
    """Max of |a - b| / max(|a|, |b|, atol), and the elementwise excess test helper."""
    scale = np.maximum(np.maximum(np.abs(a), np.abs(b)), atol)
    return np.abs(a - b) / scale


def check_sampling(model, params, *, key=0, wi: Vec3 | None = None, n_wi: int = 8, min_cos: float = 0.05,
                   n_samples: int = 2**14, n_uniform: int | None = None, rtol: float | None = None,
                   atol: float | None = None, significance: float = 1e-4, cosine=None) -> SamplingResult:
    """``sample`` agrees with ``eval`` and ``pdf``.

    At ``n_samples`` sampled directions per incident direction:

    - every output is finite, ``pdf >= 0``, ``weight >= 0``, successful ``wo`` are unit;
    - failed samples (``pdf == 0``) have ``weight == 0``;
    - at successful samples ``weight == f cos_o / pdf`` and ``pdf == pdf(wi, wo)``, within
      ``atol + rtol * scale`` (rounding identities; default rtol 1e-6 in float64);
    - the importance-sampled estimate of ``int f cos_o dwo`` (mean weight) and a uniform
      estimate (``n_uniform`` directions uniform over the scattering domain, mean of
      ``f cos / p_uniform``) agree within ``k`` combined standard errors (+ ``atol``):
      catches a sampler whose directions do not follow the density it reports.
    """
    rtol = default_rtol() if rtol is None else rtol
    atol = default_atol() if atol is None else atol
    n_uniform = 4 * n_samples if n_uniform is None else n_uniform
    cosine = projection_cosine(model) if cosine is None else cosine
    kw, ks, ku = jax.random.split(as_key(key), 3)
    if wi is None:
        wi = _default_wi(model, kw, n_wi, min_cos)
    wi = np_vec(wi)
    m = wi.shape[0]
    name = getattr(model, "name", "model")
    wo, weight, pdf_s = sample_chunked(model, params, _repeat(wi, n_samples), ks)
    wo = np_vec(wo, pdf_s.shape)
    ok = pdf_s > 0
    problems = []
    if not (np.all(np.isfinite(weight)) and np.all(np.isfinite(pdf_s))
            and all(np.all(np.isfinite(c)) for c in wo)):
        problems.append("non-finite sample outputs (wo, weight or pdf)")
    if np.any(pdf_s < 0):
        problems.append(f"negative pdf ({int(np.sum(pdf_s < 0))} samples)")
    if np.any(weight < 0):
        problems.append(f"negative weight ({int(np.sum(weight < 0))} samples)")
    bad_fail = np.any(~ok[..., None] & (weight != 0), axis=-1)
    if np.any(bad_fail):
        problems.append(f"failed samples (pdf = 0) with weight != 0: {int(np.sum(bad_fail))}")
    norm_err = np.abs(np.sqrt(wo.x**2 + wo.y**2 + wo.z**2) - 1.0)
    if np.any(ok & (norm_err > 100 * rtol)):
        problems.append(f"sampled directions not unit (max | |wo| - 1 | = {fmt(np.max(np.where(ok, norm_err, 0)))})")

    wb = wi.map(lambda a: a[:, None])
    f = call_chunked(model.eval, params, wb, wo)
    cos_o = _cos_np(cosine, wo)
    ref_w = f * (cos_o / np.where(ok, pdf_s, 1.0))[..., None]
    w_err = np.where(ok[..., None], _rel_err(weight, ref_w, atol), 0.0)
    pdf_e = call_chunked(model.pdf, params, wb, wo)
    p_err = np.where(ok, _rel_err(pdf_s, pdf_e, atol), 0.0)
    max_w_err = float(np.max(w_err)) if w_err.size else 0.0
    max_p_err = float(np.max(p_err)) if p_err.size else 0.0
    if max_w_err > rtol:
        i = np.unravel_index(int(np.argmax(w_err)), w_err.shape)
        problems.append(f"weight != f cos / pdf: max relative error {fmt(max_w_err)} > {rtol:g} "
                        f"(weight={fmt(weight[i])}, f cos/pdf={fmt(ref_w[i])} at wi={_fmt_vec(_vec_np(wi, i[0]))})")
    if max_p_err > rtol:
        i = np.unravel_index(int(np.argmax(p_err)), p_err.shape)
        problems.append(f"sample pdf != pdf(wi, wo): max relative error {fmt(max_p_err)} > {rtol:g} "
                        f"(sample: {fmt(pdf_s[i])}, pdf(): {fmt(pdf_e[i])})")

    # the same integral by importance sampling and by uniform sampling
    est_is = weight.mean(axis=1)
    se_is = weight.std(axis=1, ddof=1) / np.sqrt(n_samples)
    dom = scattering_domain(model)
    u_dirs = np_vec(random_directions(ku, m * n_uniform, dom)).map(lambda a: a.reshape(m, n_uniform))
    fu = call_chunked(model.eval, params, wb, u_dirs) * _cos_np(cosine, u_dirs)[..., None] \
        * float(domain_solid_angle(dom))
    est_u = fu.mean(axis=1)
    se_u = fu.std(axis=1, ddof=1) / np.sqrt(n_uniform)
    k = z_threshold(significance, est_is.size)
    comb = np.sqrt(se_is**2 + se_u**2)
    z = np.abs(est_is - est_u) / np.maximum(comb, 1e-300)
    bad = np.abs(est_is - est_u) > k * comb + atol
    if np.any(bad):
        i = np.unravel_index(int(np.argmax(np.where(bad, z, -np.inf))), bad.shape)
        problems.append(f"importance-sampled and uniform estimates differ by {z[i]:.1f} standard errors "
                        f"(> k = {k:.2f}): "
                        f"{fmt(est_is[i])} +- {fmt(se_is[i])} vs {fmt(est_u[i])} +- {fmt(se_u[i])} "
                        f"at wi={_fmt_vec(_vec_np(wi, i[0]))}, band {i[1]}")
    passed = not problems
    failed_frac = float(np.mean(~ok))
    max_z = float(np.max(np.where(comb > 0, z, 0.0))) if z.size else 0.0
    msg = (f"{name}: sample/pdf consistency {'passed' if passed else 'FAILED'} ({m} x {n_samples} samples, "
           f"{n_uniform} uniform): weight vs f cos/pdf max rel. error {fmt(max_w_err)}, pdf vs pdf() "
           f"{fmt(max_p_err)}, failed fraction {failed_frac:.4f}, IS vs uniform max {max_z:.2f} se (k = {k:.2f})"
           + ("" if passed else ". Problems: " + "; ".join(problems)))
    return SamplingResult("sampling", passed, msg, n_samples, failed_frac, max_w_err, max_p_err, est_is, se_is,
                          est_u, se_u, max_z, k)


def assert_sampling(model, params, **kw) -> SamplingResult:
    return check_sampling(model, params, **kw).raise_if_failed()
