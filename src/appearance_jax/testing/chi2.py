"""Chi-square goodness of fit of a model's sampler against its ``pdf``.

The procedure of Mitsuba's ``ChiSquareTest`` (re-derived here, not copied): sampled
directions are histogrammed over a grid of equal solid-angle cells in (cos theta, phi);
each cell's expected count is ``n`` times the integral of ``pdf`` over the cell, by
``sub x sub`` Gauss-Legendre rules per cell refined adaptively where the pdf is peaked
(:func:`_integrate_cells`); cells expecting fewer than ``min_expected``
samples are pooled into one bin (the chi-square approximation needs ~5 per bin); then
Pearson's statistic ``X^2 = sum (obs - exp)^2 / exp`` with ``dof = bins - 1`` gives the
p-value ``Q(dof/2, X^2/2)`` (``jax.scipy.special.gammaincc``). The test rejects when the
p-value is below the Sidak-corrected significance ``1 - (1 - alpha)^(1/N)`` over the
``N = n_tests x n_wi`` tests run (pass ``n_tests`` = how many such calls a test suite
makes, so the suite as a whole fails by chance with probability alpha).

Also checked: no sample lands in a cell whose expected count is 0, no successful sample
leaves the scattering domain, and the total sampled mass matches the integral of ``pdf``
(a sampler that fails with probability q returns ``pdf = 0``, ``weight = 0`` for those
samples, and then ``int pdf dw = 1 - q``): ``|n_ok / n - int pdf| <= k sqrt(p (1 - p) / n) +
mass_tol``.

Binning frame (``frame``): ``"local"`` (pole = the normal z; BSDFs), ``"wi"`` (pole =
-wi, the propagation direction; phase functions, whose lobes are organised around it),
``"fiber"`` (pole = the fiber tangent x; BCSDFs). ``None`` picks by model kind.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ..core.quadrature import gauss_legendre
from ..core.vec import Vec3
from .directions import (
    as_key,
    call_chunked,
    incident_domain,
    np_basis,
    np_dot,
    np_vec,
    random_directions,
    sample_chunked,
    scattering_domain,
)
from .results import CheckResult, fmt, sidak, z_threshold


@dataclass(frozen=True)
class Chi2Result(CheckResult):
    wi: np.ndarray  # (n_wi, 3)
    chi2: np.ndarray  # (n_wi,) Pearson statistic
    dof: np.ndarray  # (n_wi,) degrees of freedom after pooling
    p_value: np.ndarray  # (n_wi,)
    alpha: float  # per-test (Sidak-corrected) significance
    pdf_integral: np.ndarray  # (n_wi,) integral of pdf over the domain
    sampled_fraction: np.ndarray  # (n_wi,) fraction of successful samples
    n_samples: int
    observed: np.ndarray  # (n_wi, res_theta, res_phi) histogram
    expected: np.ndarray  # (n_wi, res_theta, res_phi)


def _default_frame(model) -> str:
    return {"phase": "wi", "bcsdf": "fiber"}.get(model.kind, "local")


def _pole(frame: str, wi: Vec3) -> Vec3:
    """The binning pole per incident direction, numpy arrays of shape ``(m, 1)``."""
    m = wi.shape[0]
    one, zero = np.ones((m, 1)), np.zeros((m, 1))
    if frame == "wi":
        return Vec3(*(-np.asarray(c).reshape(m, 1) for c in wi))
    if frame == "fiber":
        return Vec3(one, zero, zero)
    if frame == "local":
        return Vec3(zero, zero, one)
    raise ValueError(f"frame = {frame!r} must be 'local', 'wi' or 'fiber'")


def pool_cells(observed: np.ndarray, expected: np.ndarray, min_expected: float = 5.0):
    """Pool the cells expecting fewer than ``min_expected`` samples; returns ``(obs, exp)`` bins.

    The low cells are summed into one bin; if that bin still expects fewer than
    ``min_expected`` it is merged into the smallest remaining cell. Cells expecting 0
    samples are dropped here (samples in them are reported separately).
    """
    obs, exp = observed.ravel().astype(float), expected.ravel()
    keep = exp >= min_expected
    low = (~keep) & (exp > 0)
    bins_o, bins_e = list(obs[keep]), list(exp[keep])
    po, pe = float(obs[low].sum()), float(exp[low].sum())
    if pe > 0:
        if pe >= min_expected or not bins_e:
            bins_o.append(po)
            bins_e.append(pe)
        else:
            j = int(np.argmin(bins_e))
            bins_o[j] += po
            bins_e[j] += pe
    return np.asarray(bins_o), np.asarray(bins_e)


def chi2_pvalue(chi2: float, dof: int) -> float:
    """Upper tail P(X > chi2) of the chi-square distribution with ``dof`` degrees of freedom."""
    if dof < 1:
        return 1.0
    dt = jnp.result_type(float)
    return float(jax.scipy.special.gammaincc(jnp.asarray(0.5 * dof, dt), jnp.asarray(0.5 * chi2, dt)))


def _gl_cells(pdf_fn, wi: Vec3, pole: Vec3, s: Vec3, t: Vec3, cells, n: int) -> np.ndarray:
    """Integral of pdf over each cell ``(j, mu0, mu1, phi0, phi1)`` by an n x n Gauss-Legendre rule."""
    J, A, B, C, D = cells
    K = J.shape[0]
    x, wx = gauss_legendre(n, 0.0, 1.0)
    mu = A[:, None, None] + (B - A)[:, None, None] * x[None, :, None]  # (K, n, 1)
    ph = C[:, None, None] + (D - C)[:, None, None] * x[None, None, :]  # (K, 1, n)
    w = ((B - A) * (D - C))[:, None, None] * wx[None, :, None] * wx[None, None, :]
    mu, ph = (a.reshape(K, n * n) for a in np.broadcast_arrays(mu, ph))
    st = np.sqrt(np.maximum(1.0 - mu * mu, 0.0))
    take = lambda v: v.map(lambda a: np.asarray(a)[J].reshape(K, 1))  # noqa: E731
    pj, sj, tj, wij = take(pole), take(s), take(t), take(wi)
    nodes = sj * (st * np.cos(ph)) + tj * (st * np.sin(ph)) + pj * mu
    vals = call_chunked(pdf_fn, None, wij, nodes)
    return (vals.reshape(K, n, n) * w).sum(axis=(1, 2))


def _integrate_cells(pdf_fn, wi, pole, s, t, cells, sub, n_samples, depth):
    """Adaptive cubature of pdf over the cells (vectorised per refinement level).

    Each cell is integrated with sub x sub and 2sub x 2sub Gauss-Legendre nodes; where
    they differ by more than 1e-4 relative or 1e-3 expected samples the cell is split
    into 2 x 2 children, recursively, ``depth`` levels at most. Peaked pdfs (HG with
    g = 0.9 has a lobe narrower than a cell) need this; smooth ones stop at level 0.
    """
    lo = _gl_cells(pdf_fn, wi, pole, s, t, cells, sub)
    hi = _gl_cells(pdf_fn, wi, pole, s, t, cells, 2 * sub)
    bad = np.abs(hi - lo) * n_samples > np.maximum(1e-4 * np.abs(hi) * n_samples, 1e-3)
    if depth > 0 and np.any(bad):
        J, A, B, C, D = (a[bad] for a in cells)
        M, N = 0.5 * (A + B), 0.5 * (C + D)
        kids = (np.tile(J, 4), np.concatenate([A, M, A, M]), np.concatenate([M, B, M, B]),
                np.concatenate([C, C, N, N]), np.concatenate([N, N, D, D]))
        sub_int = _integrate_cells(pdf_fn, wi, pole, s, t, kids, sub, n_samples, depth - 1)
        hi = hi.copy()
        hi[bad] = sub_int.reshape(4, -1).sum(axis=0)
    return hi


def chi2_test(model, params, *, key=0, wi: Vec3 | None = None, n_wi: int = 4, min_cos: float = 0.05,
              n_samples: int = 2**18, res_theta: int = 32, res_phi: int = 64, sub: int = 4,
              min_expected: float = 5.0, significance: float = 0.01, n_tests: int = 1,
              mass_tol: float = 1e-3, frame: str | None = None, max_depth: int = 6) -> Chi2Result:
    """Chi-square test of ``model.sample`` against ``model.pdf`` (module docstring).

    ``n_samples`` per incident direction; incident directions default to ``n_wi`` random
    ones over the model's incident domain with ``|cos theta_i| >= min_cos``.
    """
    frame = _default_frame(model) if frame is None else frame
    kw, ks = jax.random.split(as_key(key))
    if wi is None:
        wi = random_directions(kw, n_wi, incident_domain(model), min_cos=min_cos)
    wi = np_vec(wi)
    m = wi.shape[0]
    name = getattr(model, "name", "model")
    hemi = frame == "local" and scattering_domain(model) == "upper"
    mu_lo = 0.0 if hemi else -1.0
    pole = _pole(frame, wi)
    s, t = np_basis(pole)

    # --- histogram of the sampled directions
    wb = Vec3(*(jnp.asarray(np.broadcast_to(np.asarray(c)[:, None], (m, n_samples))) for c in wi))
    wo, _, pdf_s = sample_chunked(model, params, wb, ks)
    ok = np.asarray(pdf_s) > 0
    wo = np_vec(wo, ok.shape)
    mu = np_dot(wo, pole)
    phi = np.mod(np.arctan2(np_dot(wo, t), np_dot(wo, s)), 2.0 * np.pi)
    outside = ok & (mu <= mu_lo) if hemi else np.zeros_like(ok)
    i_mu = np.clip(((mu - mu_lo) / (1.0 - mu_lo) * res_theta).astype(np.int64), 0, res_theta - 1)
    i_phi = np.clip((phi / (2.0 * np.pi) * res_phi).astype(np.int64), 0, res_phi - 1)
    ncell = res_theta * res_phi
    flat = np.arange(m)[:, None] * ncell + i_mu * res_phi + i_phi
    use = ok & ~outside
    observed = np.bincount(flat[use], minlength=m * ncell).reshape(m, res_theta, res_phi)

    # --- expected counts: integrate pdf over each cell (adaptive Gauss-Legendre)
    dmu = (1.0 - mu_lo) / res_theta
    dphi = 2.0 * np.pi / res_phi
    J, IM, IP = np.meshgrid(np.arange(m), np.arange(res_theta), np.arange(res_phi), indexing="ij")
    J, IM, IP = J.ravel(), IM.ravel(), IP.ravel()
    cells = (J, mu_lo + IM * dmu, mu_lo + (IM + 1) * dmu, IP * dphi, (IP + 1) * dphi)
    pdf_fn = lambda _, w_in, w_out: model.pdf(params, w_in, w_out)  # noqa: E731
    cell_int = _integrate_cells(pdf_fn, wi, pole, s, t, cells, sub, n_samples, max_depth)
    cell_int = cell_int.reshape(m, res_theta, res_phi)
    expected = n_samples * cell_int

    # --- statistics per incident direction
    n_total_tests = max(int(n_tests), 1) * m
    alpha = sidak(significance, n_total_tests)
    k = z_threshold(significance, n_total_tests)
    chi2 = np.zeros(m)
    dof = np.zeros(m, dtype=np.int64)
    pval = np.ones(m)
    problems = []
    integral = cell_int.reshape(m, -1).sum(axis=1)
    frac = ok.mean(axis=1)
    for j in range(m):  # a few incident directions, not samples
        wstr = "(" + ", ".join(f"{float(np.asarray(c)[j]):.4f}" for c in wi) + ")"
        zero_hits = int(observed[j][expected[j] <= 0].sum())
        if zero_hits:
            problems.append(f"wi={wstr}: {zero_hits} samples in cells where pdf integrates to 0")
        if outside[j].any():
            problems.append(f"wi={wstr}: {int(outside[j].sum())} successful samples below the horizon")
        o, e = pool_cells(observed[j], expected[j], min_expected)
        chi2[j] = float(np.sum((o - e) ** 2 / e)) if e.size else 0.0
        dof[j] = max(e.size - 1, 0)
        pval[j] = chi2_pvalue(chi2[j], int(dof[j]))
        if pval[j] < alpha:
            problems.append(f"wi={wstr}: chi2 = {chi2[j]:.1f} with {dof[j]} dof, p = {pval[j]:.3g} < {alpha:.3g}")
        se = np.sqrt(max(integral[j] * (1.0 - integral[j]), 0.0, 1.0 / n_samples) / n_samples)
        if abs(frac[j] - integral[j]) > k * se + mass_tol:
            problems.append(f"wi={wstr}: sampled fraction {frac[j]:.6f} != integral of pdf {integral[j]:.6f} "
                            f"(tolerance {k * se + mass_tol:.2g})")
    passed = not problems
    msg = (f"{name}: chi-square sampling test {'passed' if passed else 'FAILED'} ({m} incident directions x "
           f"{n_samples} samples, {res_theta}x{res_phi} cells, frame {frame!r}): min p-value {fmt(pval.min())} "
           f"(alpha per test {alpha:.3g}), chi2/dof max {fmt(np.max(chi2 / np.maximum(dof, 1)))}, "
           f"int pdf in [{fmt(integral.min())}, {fmt(integral.max())}], sampled fraction in "
           f"[{fmt(frac.min())}, {fmt(frac.max())}]" + ("" if passed else ". Problems: " + "; ".join(problems)))
    return Chi2Result("chi2", passed, msg, np.stack(list(wi), axis=-1), chi2, dof, pval, alpha, integral, frac,
                      n_samples, observed, expected)


def assert_chi2(model, params, **kw) -> Chi2Result:
    return chi2_test(model, params, **kw).raise_if_failed()
