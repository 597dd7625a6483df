"""Tallies of the flatland tracer: far-field histograms, the BCSDF, per-lobe albedo, the
deterministic smooth mode and the camera-side next-event estimator.

Flux bookkeeping (spec seed-001 §4.3 item 6; Huang Eqs. 4.9-4.10, 4.27): rays are
launched uniformly over the projected width 2 D_i of the object, so each carries the flux
2 D_i cos(theta_i) / N per unit fiber length (unit irradiance). A histogram bin of solid
angle dOmega = (sin theta_1 - sin theta_0) dphi collecting power W estimates the density
p(omega_o) = W / (N dOmega), and the BCSDF (Huang's convention, per unit projected width of
the outgoing side) is

    S(omega_i, omega_o) = (D_i / D_o) p(omega_o) / cos(theta_o),

so that the integral of S cos(theta_o) D_o / D_i over the sphere is the albedo. For a
circle D = 1. Angles follow :func:`core.frame.fiber_angles` (x = fiber axis).
"""

from __future__ import annotations

import math
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..core.frame import fiber_angles
from ..core.params import check_int
from ..core.quadrature import gauss_legendre
from ..core.vec import Vec3
from . import geometry as G
from .section import Section
from .tracer import _trace, check_direction, launch, n_bands


class Histogram(NamedTuple):
    """Far-field tallies of :func:`trace_fiber` (sums over all paths)."""

    power: jax.Array        # sum of emitted power, (lobes, n_theta, n_phi, bands)
    power_sq: jax.Array     # sum over paths of (per-path power in the bin)^2
    s_sum: jax.Array        # sum of power * D_i / (D_o cos theta_o) (the BCSDF estimator)
    s_sq: jax.Array         # its per-path squares
    n_paths: int
    theta_edges: jax.Array  # (n_theta + 1,) radians, [-pi/2, pi/2]
    phi_edges: jax.Array    # (n_phi + 1,) radians, [-pi, pi]
    albedo: jax.Array       # per-lobe albedo (power fraction), (lobes, bands)
    absorbed: jax.Array     # (bands,) fractions of the incident power
    lost: jax.Array
    residual: jax.Array


def _outer_half_width(section: Section, d: Vec3):
    o = section.outer()
    return G.half_width(*G.unit_2d(d.y, d.z), o.a, o.b, o.psi)


def _stratified_offsets(key, n, dtype):
    """n offsets h in (-1, 1): one jittered sample per stratum of width 2 / n."""
    u = (jnp.arange(n, dtype=dtype) + jax.random.uniform(key, (n,), dtype)) / n
    return 2.0 * u - 1.0


@partial(jax.jit, static_argnames=("n_chunks", "chunk", "n_theta", "n_phi", "n_lobes", "max_events",
                                   "mode"))
def _histogram(section, wi, key, n_chunks, chunk, n_theta, n_phi, n_lobes, max_events, mode):
    dtype = jnp.result_type(float)
    nb = n_bands(section)
    _, _, D_i = launch(section, wi, jnp.zeros((1,), dtype))
    D_i = D_i[0] if jnp.ndim(D_i) else D_i
    t_edges = jnp.linspace(-jnp.pi / 2, jnp.pi / 2, n_theta + 1, dtype=dtype)
    p_edges = jnp.linspace(-jnp.pi, jnp.pi, n_phi + 1, dtype=dtype)
    n_bins = n_lobes * n_theta * n_phi

    def one(carry, k):
        kh, kt = jax.random.split(k)
        rec = _trace(section, wi, _stratified_offsets(kh, chunk, dtype), kt, None, max_events, mode, False, False)
        th, ph = fiber_angles(rec.direction)
        it = jnp.clip(jnp.floor((th + jnp.pi / 2) / jnp.pi * n_theta).astype(jnp.int32), 0, n_theta - 1)
        ip = jnp.clip(jnp.floor((ph + jnp.pi) / (2 * jnp.pi) * n_phi).astype(jnp.int32), 0, n_phi - 1)
        lobe = jnp.clip(rec.lobe, 0, n_lobes - 1)
        idx = (lobe * n_theta + it) * n_phi + ip                        # (E, N)
        w = rec.weight                                                  # (E, N, nb)
        D_o = _outer_half_width(section, rec.direction)
        cos_o = jnp.cos(th)
        # empty emission slots carry weight 0 and may have a zero direction (D_o = 0)
        ok = (cos_o > 1e-6) & (D_o > 0)
        sw = jnp.where(ok[..., None], w * (D_i / jnp.where(ok, D_o * cos_o, 1.0))[..., None], 0.0)
        # squares per event: the events of one path fall in different lobes (p grows by at
        # least one between emissions), except in the catch-all last lobe, whose standard
        # error therefore treats a path's emissions as independent
        flat = idx.reshape(-1)
        wf, sf = w.reshape(-1, nb), sw.reshape(-1, nb)
        out = dict(power=jax.ops.segment_sum(wf, flat, n_bins), power_sq=jax.ops.segment_sum(wf * wf, flat, n_bins),
                   s_sum=jax.ops.segment_sum(sf, flat, n_bins), s_sq=jax.ops.segment_sum(sf * sf, flat, n_bins),
                   absorbed=rec.absorbed.sum(0), lost=rec.lost.sum(0), residual=rec.residual.sum(0))
        out["albedo"] = jax.ops.segment_sum(w.reshape(-1, nb), lobe.reshape(-1), n_lobes)
        return jax.tree_util.tree_map(jnp.add, carry, out), None

    zero = dict(power=jnp.zeros((n_bins, nb), dtype), power_sq=jnp.zeros((n_bins, nb), dtype),
                s_sum=jnp.zeros((n_bins, nb), dtype), s_sq=jnp.zeros((n_bins, nb), dtype),
                albedo=jnp.zeros((n_lobes, nb), dtype), absorbed=jnp.zeros((nb,), dtype),
                lost=jnp.zeros((nb,), dtype), residual=jnp.zeros((nb,), dtype))
    acc, _ = jax.lax.scan(one, zero, jax.random.split(key, n_chunks))
    shape = (n_lobes, n_theta, n_phi, nb)
    n = n_chunks * chunk
    return Histogram(acc["power"].reshape(shape), acc["power_sq"].reshape(shape), acc["s_sum"].reshape(shape),
                     acc["s_sq"].reshape(shape), n, t_edges, p_edges, acc["albedo"] / n, acc["absorbed"] / n,
                     acc["lost"] / n, acc["residual"] / n)


def trace_fiber(section: Section, wi: Vec3, key, n_paths: int = 2 ** 16, *, n_theta: int = 90,
                n_phi: int = 180, n_lobes: int = 4, max_events: int = 16, mode: str = "split",
                chunk: int = 2 ** 14) -> Histogram:
    """Trace ``n_paths`` rays from the direction ``wi`` (a single unit :class:`Vec3`) and
    tally the emitted power per lobe (p = 0, ..., n_lobes - 1; the last collects p >= n_lobes
    - 1), per (theta_o, phi_o) bin and per band.

    Paths run in chunks of ``chunk`` rays inside one ``lax.scan`` (memory stays
    ~ max_events x chunk), so 1e8+ paths need no Python loop; ``n_paths`` is rounded up to a
    multiple of ``chunk``. Offsets h are stratified over [-1, 1] within each chunk.
    Convert with :func:`bcsdf_from_histogram`.
    """
    section = section.validate()
    check_direction("flatland.trace_fiber.wi", wi)
    if mode not in ("split", "random"):
        raise ValueError(f"flatland.trace_fiber: mode = {mode!r}; valid: 'split', 'random'")
    if section.periodic:
        raise ValueError("flatland.trace_fiber: periodic rows have no BCSDF; use "
                         "flatland.masking_fraction or flatland.trace")
    check_int("flatland.trace_fiber.n_paths", n_paths, 1)
    chunk = min(check_int("flatland.trace_fiber.chunk", chunk, 1), int(n_paths))
    for name, v in (("n_theta", n_theta), ("n_phi", n_phi), ("n_lobes", n_lobes), ("max_events", max_events)):
        check_int(f"flatland.trace_fiber.{name}", v, 1)
    n_chunks = -(-int(n_paths) // chunk)
    return _histogram(section, wi, key, n_chunks, chunk, int(n_theta), int(n_phi), int(n_lobes),
                      int(max_events), mode)


class BCSDF(NamedTuple):
    """Bin averages of the BCSDF and the density, with standard errors."""

    S: jax.Array            # mean of S over each bin (1/sr), (lobes, n_theta, n_phi, bands)
    S_se: jax.Array
    density: jax.Array      # p(omega_o) = power / (N dOmega)  (1/sr)
    density_se: jax.Array
    theta: jax.Array        # bin centres (rad)
    phi: jax.Array


def bcsdf_from_histogram(hist: Histogram) -> BCSDF:
    """S(omega_i, omega_o) = (D_i / D_o) p(omega_o) / cos(theta_o), averaged over each bin,
    with standard errors from the per-path spread (Huang Eqs. 4.9-4.10, 4.27)."""
    te, pe = hist.theta_edges, hist.phi_edges
    d_omega = (jnp.sin(te[1:]) - jnp.sin(te[:-1]))[:, None] * (pe[1:] - pe[:-1])[None, :]
    d_omega = d_omega[None, :, :, None]
    n = hist.n_paths

    def mean_se(s, sq):
        m = s / n
        var = jnp.maximum(sq / n - m * m, 0.0) / max(n - 1, 1)
        return m / d_omega, jnp.sqrt(var) / d_omega

    S, S_se = mean_se(hist.s_sum, hist.s_sq)
    p, p_se = mean_se(hist.power, hist.power_sq)
    return BCSDF(S, S_se, p, p_se, 0.5 * (te[1:] + te[:-1]), 0.5 * (pe[1:] + pe[:-1]))


class SmoothLobes(NamedTuple):
    """Deterministic lobes of a smooth section from a Gauss-Legendre quadrature over h."""

    h: jax.Array            # nodes, (n_h,)
    weight: jax.Array       # quadrature weights / 2 (sum to 1), (n_h,)
    phi: jax.Array          # exit azimuth per event and node, (events, n_h)
    theta: jax.Array        # exit longitudinal angle
    power: jax.Array        # A_p(h) per event and node, (events, n_h, bands)
    lobe: jax.Array         # p per event and node
    albedo: jax.Array       # per-lobe albedo (1/2) int A_p(h) dh, (n_lobes, bands)


def smooth_lobes(section: Section, wi: Vec3, n_h: int = 256, *, n_lobes: int = 4, max_events: int = 16,
                 panels: int = 8) -> SmoothLobes:
    """The smooth-section mode: no randomness, a composite Gauss-Legendre rule over
    h = sin(u).

    Each node is traced in split mode, so lobe p carries exactly A_p(h) (Fresnel products
    and Beer-Lambert attenuation) and leaves at Phi_p(h); the per-lobe albedo
    (1/2) int A_p(h) dh is exact up to the quadrature (spec seed-001 §4.3 item 7; H-5).
    Rough interfaces are rejected: use :func:`trace_fiber`.
    """
    section = section.validate()
    check_direction("flatland.smooth_lobes.wi", wi)
    for s in section.shapes:
        if s.interface.rough or s.interface.kind == "diffuse":
            raise ValueError("flatland.smooth_lobes needs smooth, non-diffuse interfaces; "
                             "use flatland.trace_fiber for rough or diffuse ones")
    check_int("flatland.smooth_lobes.n_h", n_h, 1)
    check_int("flatland.smooth_lobes.panels", panels, 1)
    per = -(-int(n_h) // int(panels))
    x, w = gauss_legendre(per)
    x, w = np.asarray(x), np.asarray(w)
    # h = sin(u): the Fresnel factors have a square-root edge at h = +-1 (grazing entry),
    # which the substitution makes smooth (composite Gauss-Legendre in u)
    edges = np.linspace(-np.pi / 2, np.pi / 2, int(panels) + 1)
    us = np.concatenate([0.5 * (edges[k + 1] - edges[k]) * x + 0.5 * (edges[k + 1] + edges[k])
                         for k in range(int(panels))])
    wu = np.concatenate([0.5 * (edges[k + 1] - edges[k]) * w for k in range(int(panels))])
    hs, ws = np.sin(us), 0.5 * wu * np.cos(us)
    dtype = jnp.result_type(float)
    hs, ws = jnp.asarray(hs, dtype), jnp.asarray(ws, dtype)
    rec = _trace(section, wi, hs, jax.random.PRNGKey(0), None, int(max_events), "split", False, False)
    th, ph = fiber_angles(rec.direction)
    lobe = jnp.clip(rec.lobe, 0, n_lobes - 1)
    alb = jax.ops.segment_sum((rec.weight * ws[None, :, None]).reshape(-1, rec.weight.shape[-1]),
                              lobe.reshape(-1), n_lobes)
    return SmoothLobes(hs, ws, ph, th, rec.weight, rec.lobe, alb)


@partial(jax.jit, static_argnames=("n_chunks", "chunk", "n_lobes", "max_events"))
def _nee(section, wi, wo, key, n_chunks, chunk, n_lobes, max_events):
    dtype = jnp.result_type(float)
    nb = n_bands(section)

    def one(carry, k):
        kh, kt = jax.random.split(k)
        rec = _trace(section, wo, _stratified_offsets(kh, chunk, dtype), kt, None, max_events, "random", False,
                     False, True, wi)
        lobe = jnp.clip(rec.lobe, 0, n_lobes - 1)
        path = jnp.broadcast_to(jnp.arange(chunk), lobe.shape)
        per = jax.ops.segment_sum(rec.weight.reshape(-1, nb), (lobe * chunk + path).reshape(-1),
                                  n_lobes * chunk).reshape(n_lobes, chunk, nb)
        s, sq = carry
        return (s + per.sum(1), sq + (per * per).sum(1)), None

    z = jnp.zeros((n_lobes, nb), dtype)
    (s, sq), _ = jax.lax.scan(one, (z, z), jax.random.split(key, n_chunks))
    n = n_chunks * chunk
    m = s / n
    se = jnp.sqrt(jnp.maximum(sq / n - m * m, 0.0) / max(n - 1, 1))
    return m, se


def nee_bcsdf(section: Section, wi: Vec3, wo: Vec3, key, n_paths: int = 2 ** 14, *, n_lobes: int = 4,
              max_events: int = 16, chunk: int = 2 ** 14):
    """Camera-side next-event estimate of S(omega_i, omega_o) cos(theta_i) per lobe.

    Rays are launched from ``wo`` (the viewer) uniformly over the projected width 2 D_o and
    followed with the tracer's random choices; every hit on a rough interface bordering the
    exterior is connected to the delta light ``wi`` (unit irradiance) through the interface's
    BSDF (:func:`interfaces.dielectric_eval`), in the lobe of the path so far. The mean is
    S cos(theta_i) by reciprocity (spec seed-001 §4.3 item 6b; what the thesis's Mitsuba
    set-up computes). Gives pointwise values with much lower variance than histograms for
    glossy lobes; smooth interfaces contribute nothing (delta lobes). Returns
    ``(value, stderr)`` of shape (n_lobes, bands).
    """
    section = section.validate()
    check_direction("flatland.nee_bcsdf.wi", wi)
    check_direction("flatland.nee_bcsdf.wo", wo)
    if section.periodic:
        raise ValueError("flatland.nee_bcsdf needs a bounded section")
    if not any(s.interface.rough for s in section.shapes):
        raise ValueError("flatland.nee_bcsdf needs a rough interface (smooth lobes are deltas); "
                         "use flatland.smooth_lobes")
    check_int("flatland.nee_bcsdf.n_paths", n_paths, 1)
    chunk = min(check_int("flatland.nee_bcsdf.chunk", chunk, 1), int(n_paths))
    n_chunks = -(-int(n_paths) // chunk)
    return _nee(section, wi, wo, key, n_chunks, chunk, int(n_lobes), int(max_events))


class FirstHits(NamedTuple):
    """What :func:`first_hits` returns (shape order of the section; the last class: no hit)."""

    fraction: jax.Array   # (S + 1,): fractions of the rays whose first hit is shape i; last: none
    stderr: jax.Array     # (S + 1,): their binomial standard errors
    h_range: jax.Array    # (S, 2): min and max offset h at which rays first hit shape i (+inf, -inf: never)
    truncated: jax.Array  # fraction of rays that may have needed more copies of a periodic row


@partial(jax.jit, static_argnames=("n",))
def _first_hits(section, wo, key, n):
    dtype = jnp.result_type(float)
    kh, kt = jax.random.split(key)
    rec = _trace(section, wo, _stratified_offsets(kh, n, dtype), kt, None, 1, "random", False, False)
    cls = jnp.where(rec.first_shape >= 0, rec.first_shape, len(section.shapes))
    frac = jnp.stack([jnp.mean((cls == i).astype(dtype)) for i in range(len(section.shapes) + 1)])
    se = jnp.sqrt(frac * (1 - frac) / max(n - 1, 1))
    h_range = jnp.stack([jnp.stack([jnp.min(jnp.where(cls == i, rec.first_h, jnp.inf)),
                                    jnp.max(jnp.where(cls == i, rec.first_h, -jnp.inf))])
                         for i in range(len(section.shapes))])
    return FirstHits(frac, se, h_range, jnp.mean(rec.truncated.astype(dtype)))


def first_hits(section: Section, wo: Vec3, key, n_paths: int = 2 ** 16) -> FirstHits:
    """What a viewer along ``wo`` sees first of a periodic row, per shape: the masking tallies
    (spec seed-000 §5.2). Rays are launched towards -wo uniformly (stratified) over one period, from
    above the row (wo.z > 0) or below it (wo.z < 0), and classified by the first shape they meet
    (semi-transparent shapes by their coin: a ray that passes one is not stopped by it); for each shape
    the range of the offsets h (across its projected width, to the left of the travel, as
    :func:`launch`) at which rays meet it first. Each shape's fraction is the share of the row's
    projected period where it is seen: Padrón's masking weights (App. B). Only the projection of ``wo``
    on the section plane matters (it need not be a unit vector)."""
    section = section.validate()
    if not section.periodic:
        raise ValueError("flatland.first_hits needs a periodic row (flatland.ellipse_row, or a Section "
                         "with a period)")
    check_int("flatland.first_hits.n_paths", n_paths, 1)
    wy, wz = float(wo.y), float(wo.z)
    if not (math.isfinite(wy) and math.isfinite(wz) and wz != 0):
        raise ValueError(f"flatland.first_hits: wo = ({float(wo.x)}, {wy}, {wz}); the viewer must be above "
                         "(wo.z > 0) or below (wo.z < 0) the row, not in its plane")
    # what is hit first depends on the direction's projection on the section plane only
    r = math.hypot(wy, wz)
    d = Vec3(*(jnp.asarray(v, jnp.result_type(float)) for v in (0.0, wy / r, wz / r)))
    return _first_hits(section, d, key, int(n_paths))


def masking_fraction(section: Section, wo: Vec3, key, n_paths: int = 2 ** 16):
    """Fraction of the projected period of a periodic row covered by its shapes, seen from
    ``wo`` (the barbule weight w'_bb of Padrón App. B, spec M23): :func:`first_hits` summed over
    the shapes. Returns ``(fraction, stderr, truncated_fraction)``."""
    r = first_hits(section, wo, key, n_paths)
    m = 1.0 - r.fraction[-1]
    return m, r.stderr[-1], r.truncated
