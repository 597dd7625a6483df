"""Far-field collectors: a :class:`~appearance_jax.flatland.fan.Fan` to intensities on a grid of
outgoing angles (Sadeghi 2011 §3.4.3, spec seed-002 §1.2.4 (c)–(h), §1.2.5, §4 items 5–6, 9).

Adjacent rays of one family that are both valid bound a *segment* that maps ``[s_k, s_k+1]``
onto ``[psi_k, psi_k+1]`` (the 1-D "patch" of the thesis). Every output angle sums every
segment that contains it (the thesis's set Υ(r)); inside a segment the amplitudes and the
optical path (never the wrapped phase) are interpolated linearly in the angle, and the
amplitude is scaled by the square root of the geometric spreading ``|ds/dψ|`` (the 2-D
``a_i / s_i`` of the thesis):

- ``spreading="vertex"`` (default): ``|ds/dψ|`` estimated at every ray from its two
  segments (``Σ|Δs| / Σ|Δψ|``, bounded at a fold) and interpolated linearly inside each
  segment. The output is continuous in the fan's angles, so its gradients with respect to
  whatever moves the rays (index, shape) match finite differences;
- ``spreading="segment"``: the segment's own ``|Δs/Δψ|``, constant inside it (the thesis's
  patch ratio; integrates to the exact segment energy). The output then jumps whenever a
  grid angle crosses a ray's angle, and AD gradients with respect to ray angles miss those
  jumps, an error that does not shrink with more rays. Both agree with Mie to 4 digits in
  correlation (spec C8 setting).

Lifts (outputs per polarisation, ``[..., 0]`` = ⊥, ``[..., 1]`` = ∥):

- ``"cylinder"`` (2-D, infinite cylinder at normal incidence): angles are the signed ``psi``
  in (-pi, pi]; returns ``(1/2a) dσ/dψ = ½ |ds/dψ| |A|^2`` (exact counterpart
  ``|T|^2/(pi x)``, TM ↔ ⊥). Axis counts are ignored; the fan must span the whole
  section (s in (-1, 1)).
- ``"sphere"`` (3-D axisymmetric): only segments with ``s >= 0`` are used, angles are the
  scattering angle ``θ = |ψ|`` in [0, pi] (both signs of ψ land on θ and add coherently);
  returns ``(1/πa^2) dσ/dΩ = s |ds/dθ| / (π sin θ) |A|^2``, i.e. ``|S1|^2/(π x^2)`` and
  ``|S2|^2/(π x^2)`` of Mie with Bohren–Huffman normalisation. θ = 0 and π return 0
  (the forward and glory singularities are outside geometric optics).

Modes: ``"coherent"`` (phasors ``A exp(i(x L - π/2 N))`` summed, then ``|·|^2``),
``"incoherent"`` (``|A|^2`` summed; the thesis's "dispersion only" curve) and ``"kde"``
(every ray deposits a Gaussian of standard deviation ``width`` (rad) in angle carrying its
share of the energy: smooth in every input, for fitting). ``x = k a = 2π a / λ``.

Focal phase (decision D-R3): ``"maslov"`` (default) counts ``N = foci`` (+ ``axis`` for the
sphere), -π/2 each; ``"thesis"`` is the literal Eq. 3.3 heuristic, +π/2 on segments with
``dθ/db > 0`` and no axis term (it anti-phases the supernumeraries: for reproduction studies
only). A segment uses the counts of its first ray.

Precision (spec §5.2 item 2): ``x L`` reaches ~1e4 rad, so each family's mean path is
subtracted before interpolating and its phase added back modulo 2π, and angle differences
are wrapped without rounding them to ulp(π). With a fan computed accurately and stored in
float32 the coherent sphere lift agrees with Mie as in float64 (4 digits in correlation,
spec C8 setting); a float32 *tracer* may not resolve the caustic's segments as well.

Segments are matched to sorted angles with ``searchsorted`` and each segment adds to at
most ``max_hits`` consecutive angles (a ``lax.scan`` over hit slots: memory O(rays +
angles), never rays × angles). ``max_hits=None`` takes the exact need from a concrete fan
(:func:`needed_hits`); with a traced fan or traced angles (inside ``jit``/``vmap``) it must
be given (static), because a segment that spans more grid angles than ``max_hits`` drops
the excess: size it with :func:`needed_hits` on a representative concrete fan, with margin.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from .fan import Fan

LIFTS = ("cylinder", "sphere")
MODES = ("coherent", "incoherent", "kde")
FOCAL_PHASES = ("maslov", "thesis")
SPREADINGS = ("segment", "vertex")
KDE_SIGMAS = 8.0  # the windowed KDE cuts each Gaussian here (exp(-32): below float64 noise)


def _wrap(a, xp=jnp):
    """Angle to (-pi, pi], exact for angles already in range (a small difference of two
    angles keeps all its bits: pi - mod(pi - a, 2 pi) would round it to ulp(pi), which in
    float32 wipes out the segments near a caustic)."""
    w = a - (2.0 * np.pi) * xp.round(a / (2.0 * np.pi))
    return xp.where(w <= -np.pi, w + 2.0 * np.pi, w)


def _pick(fan: Fan, families):
    if families is None:
        return fan
    idx = np.asarray(families, int)
    return fan._replace(psi=fan.psi[idx], amp=fan.amp[idx], opl=fan.opl[idx], foci=fan.foci[idx],
                        axis=fan.axis[idx], valid=fan.valid[idx])


def _segments(fan: Fan, lift, focal_phase):
    """Flattened segment data over (family, k): start values, increments, counts and validity."""
    s0, s1 = fan.s[:-1], fan.s[1:]
    ok = fan.valid[:, :-1] & fan.valid[:, 1:]
    if lift == "sphere":
        ok = ok & (s0 >= 0)[None] & (s1 >= 0)[None]
    psi0 = _wrap(fan.psi[:, :-1])
    dpsi = _wrap(fan.psi[:, 1:] - fan.psi[:, :-1])
    F, S = psi0.shape
    # per-family reference path (mean over valid rays): x * (L - ref) stays small
    w = fan.valid.astype(fan.opl.dtype)
    ref = jnp.sum(fan.opl * w, 1) / jnp.maximum(jnp.sum(w, 1), 1.0)
    if focal_phase == "maslov":
        count = fan.foci[:, :-1] + (fan.axis[:, :-1] if lift == "sphere" else 0)
    else:  # thesis Eq. 3.3: +pi/2 where d theta / d b > 0 (theta = |psi|, b = |s|)
        dth = jnp.abs(_wrap(fan.psi[:, 1:])) - jnp.abs(psi0)
        db = jnp.abs(s1) - jnp.abs(s0)
        count = -(dth * db[None] > 0).astype(jnp.int32)
    # |ds/dpsi| at each ray from its valid neighbouring segments (centred, with absolute
    # increments so that it stays bounded at a fold): the "vertex" spreading interpolates it
    okf = ok.astype(fan.opl.dtype)
    ads, adp = jnp.abs(s1 - s0)[None] * okf, jnp.abs(dpsi) * okf
    pad = jnp.zeros((F, 1), fan.opl.dtype)
    num = jnp.concatenate([ads, pad], 1) + jnp.concatenate([pad, ads], 1)
    den = jnp.concatenate([adp, pad], 1) + jnp.concatenate([pad, adp], 1)
    dens = jnp.where(den > 0, num / jnp.where(den > 0, den, 1.0), 0.0)
    seg = dict(
        psi0=psi0, dpsi=dpsi, s0=jnp.broadcast_to(s0, (F, S)), ds=jnp.broadcast_to(s1 - s0, (F, S)),
        d0=dens[:, :-1], d1=dens[:, 1:],
        A0=fan.amp[:, :-1], dA=fan.amp[:, 1:] - fan.amp[:, :-1],
        L0=fan.opl[:, :-1] - ref[:, None], dL=fan.opl[:, 1:] - fan.opl[:, :-1],
        ref=jnp.broadcast_to(ref[:, None], (F, S)), count=count.astype(fan.opl.dtype),
        ok=ok)
    return {k: v.reshape((F * S,) + v.shape[2:]) for k, v in seg.items()}


def _query(angles, lift):
    """Signed query angles for the lift (the sphere's: +θ then -θ) and their sort order."""
    angles = jnp.asarray(angles)
    if lift == "sphere":
        th = jnp.abs(angles)
        q = jnp.concatenate([th, _wrap(-th)])
    else:
        q = _wrap(angles)
    order = jnp.argsort(q)
    return q, order


def _ranges(xp, psi0, dpsi, ok, q_sorted):
    """First and one-past-last index into ``[q, q + 2pi]`` that each segment covers (half-open
    from its first ray: [psi_k, psi_k+1)); ``xp`` is numpy (concrete, no compile) or jnp."""
    q_ext = xp.concatenate([q_sorted, q_sorted + 2.0 * np.pi])
    up = dpsi >= 0
    lo_ang = xp.where(up, psi0, psi0 + dpsi)
    lo_ang = xp.where(lo_ang <= -np.pi, lo_ang + 2.0 * np.pi, lo_ang)
    ends = xp.stack([lo_ang, lo_ang + xp.abs(dpsi)])
    if xp is jnp:  # only integer indices come out of the search
        ends = jax.lax.stop_gradient(ends)
    # side="right" for the segments that run backwards, as "left" of the next float up
    ends = xp.where(up, ends, xp.nextafter(ends, np.inf))
    lo, hi = xp.searchsorted(q_ext, ends, side="left")
    return q_ext, lo_ang, lo, xp.where(ok, hi, lo)


def _seg_angles_np(fan: Fan, lift):
    s, psi = np.asarray(fan.s), np.asarray(fan.psi)
    ok = np.asarray(fan.valid)[:, :-1] & np.asarray(fan.valid)[:, 1:]
    if lift == "sphere":
        ok = ok & (s[:-1] >= 0)[None] & (s[1:] >= 0)[None]
    psi0, dpsi = _wrap(psi[:, :-1], np), _wrap(psi[:, 1:] - psi[:, :-1], np)
    return psi0.ravel(), dpsi.ravel(), ok.ravel()


def needed_hits(fan: Fan, angles, *, lift="cylinder", families=None) -> int:
    """Largest number of grid angles one valid segment covers (concrete fan only, numpy)."""
    fan = _pick(fan, families)
    angles = np.asarray(angles, float)
    q = np.concatenate([np.abs(angles), -np.abs(angles)]) if lift == "sphere" else angles
    q = np.sort(_wrap(q, np))
    _, _, lo, hi = _ranges(np, *_seg_angles_np(fan, lift), q)
    return max(int(np.max(hi - lo, initial=0)), 1)


@partial(jax.jit, static_argnames=("lift", "mode", "focal_phase", "max_hits", "spreading"))
def _collect(fan, angles, x, lift, mode, focal_phase, max_hits, spreading):
    seg = _segments(fan, lift, focal_phase)
    q, order = _query(angles, lift)
    qs = q[order]
    Q = qs.shape[0]
    q_ext, lo_ang, lo, hi = _ranges(jnp, seg["psi0"], seg["dpsi"], seg["ok"], qs)
    up = seg["dpsi"] >= 0
    width = jnp.abs(seg["dpsi"])
    width = jnp.where(width > 0, width, 1.0)
    seg_dsdpsi = jnp.abs(seg["ds"]) / width
    const = jnp.mod(x * seg["ref"], 2.0 * jnp.pi) - 0.5 * jnp.pi * seg["count"]
    cdtype = jnp.result_type(fan.amp.dtype, jnp.complex64)
    coherent = mode == "coherent"
    out0 = jnp.zeros((Q, 2), cdtype if coherent else fan.opl.dtype)

    @jax.checkpoint
    def step(out, j):
        idx = lo + j
        hit = idx < hi
        idx_c = jnp.clip(idx, 0, 2 * Q - 1)
        qv = q_ext[idx_c]
        u = jnp.clip((qv - lo_ang) / width, 0.0, 1.0)
        t = jnp.where(up, u, 1.0 - u)
        s = seg["s0"] + t * seg["ds"]
        dsdpsi = seg_dsdpsi if spreading == "segment" else seg["d0"] + t * (seg["d1"] - seg["d0"])
        if lift == "sphere":
            sin_th = jnp.sin(jnp.abs(qv))
            good = hit & (sin_th > 1e-12)
            wgt = s * dsdpsi / (jnp.pi * jnp.where(good, sin_th, 1.0))
        else:
            good = hit
            wgt = 0.5 * dsdpsi
        good = good & (wgt > 0)
        wgt = jnp.where(good, wgt, 1.0)  # double where: no NaN gradient through sqrt(0)
        A = seg["A0"] + t[:, None] * seg["dA"]
        if coherent:
            ph = x * (seg["L0"] + t * seg["dL"]) + const
            c = (jnp.sqrt(wgt) * jnp.exp(1j * ph))[:, None] * A
        else:
            c = wgt[:, None] * (A.real ** 2 + A.imag ** 2)
        c = jnp.where(good[:, None], c, 0.0)
        return out.at[idx_c % Q].add(c.astype(out.dtype)), None

    out, _ = jax.lax.scan(step, out0, jnp.arange(max_hits))
    out = jnp.zeros_like(out).at[order].set(out)  # back to the caller's (internal) order
    if lift == "sphere":
        n = out.shape[0] // 2
        out = out[:n] + out[n:]
    return out


@partial(jax.jit, static_argnames=("lift", "chunk"))
def _kde(fan, angles, width, lift, chunk):
    """Dense KDE: every ray against every angle, in chunks of rays (exact, O(rays x angles))."""
    w, ang = _kde_rays(fan, lift)
    pad = (-ang.shape[0]) % chunk
    w = jnp.pad(w, ((0, pad), (0, 0)))
    ang = jnp.pad(ang, (0, pad))
    q = jnp.asarray(angles)
    norm = 1.0 / (jnp.sqrt(2.0 * jnp.pi) * width)

    def g(d):
        return norm * jnp.exp(-0.5 * (d / width) ** 2)

    def body(acc, blk):
        a, ww = blk
        if lift == "sphere":  # images at -theta and 2pi - theta keep the mass inside [0, pi]
            th = jnp.abs(q)[None, :]
            k = g(th - a[:, None]) + g(th + a[:, None]) + g(2.0 * jnp.pi - th - a[:, None])
        else:
            k = g(_wrap(q[None, :] - a[:, None]))
        return acc + k.T @ ww, None

    acc0 = jnp.zeros((q.shape[0], 2), w.dtype)
    acc, _ = jax.lax.scan(body, acc0, (ang.reshape(-1, chunk), w.reshape(-1, chunk, 2)))
    return _per_steradian(acc, q) if lift == "sphere" else acc


def _kde_rays(fan, lift):
    """Per-ray energies (R, 2) and angles (R,) for the KDE (midpoint cells in s)."""
    s = fan.s
    # midpoint cells; the end rays get their neighbour's spacing (rays at cell centres)
    cell = jnp.concatenate([2.0 * (s[1:2] - s[:1]), s[2:] - s[:-2], 2.0 * (s[-1:] - s[-2:-1])]) * 0.5
    A2 = fan.amp.real ** 2 + fan.amp.imag ** 2  # (F, N, 2)
    if lift == "sphere":
        w = (2.0 * jnp.maximum(s, 0.0) * cell)[None, :, None] * A2
        ang = jnp.abs(_wrap(fan.psi))
    else:
        w = (0.5 * cell)[None, :, None] * A2
        ang = _wrap(fan.psi)
    w = jnp.where(fan.valid[..., None], w, 0.0).reshape(-1, 2)
    return w, ang.reshape(-1)


def _per_steradian(acc, q):
    sin_th = jnp.sin(jnp.abs(q))
    good = sin_th > 1e-12
    return jnp.where(good[:, None], acc / (2.0 * jnp.pi * jnp.where(good, sin_th, 1.0))[:, None], 0.0)


@partial(jax.jit, static_argnames=("lift", "hits"))
def _kde_window(fan, angles, width, lift, hits):
    """KDE with the Gaussians cut at KDE_SIGMAS: each ray adds to the <= ``hits`` sorted grid
    angles inside its window (scan over hit slots, O(rays x hits))."""
    w, ang = _kde_rays(fan, lift)
    q = jnp.asarray(angles)
    if lift == "sphere":  # images at -theta and 2pi - theta keep the mass inside [0, pi]
        q = jnp.abs(q)
        ang = jnp.concatenate([ang, -ang, 2.0 * jnp.pi - ang])
        w = jnp.concatenate([w, w, w])
    order = jnp.argsort(q)
    qs = q[order]
    Q = qs.shape[0]
    q_ext = qs if lift == "sphere" else jnp.concatenate([qs - 2.0 * jnp.pi, qs, qs + 2.0 * jnp.pi])
    half = jax.lax.stop_gradient(KDE_SIGMAS * width)
    a0 = jax.lax.stop_gradient(ang)
    lo = jnp.searchsorted(q_ext, a0 - half, side="left")
    hi = jnp.searchsorted(q_ext, a0 + half, side="right")
    norm = 1.0 / (jnp.sqrt(2.0 * jnp.pi) * width)

    def step(out, j):
        idx = lo + j
        hit = idx < hi
        idx_c = jnp.clip(idx, 0, q_ext.shape[0] - 1)
        d = q_ext[idx_c] - ang
        val = jnp.where(hit[:, None], (norm * jnp.exp(-0.5 * (d / width) ** 2))[:, None] * w, 0.0)
        return out.at[idx_c % Q].add(val), None

    out, _ = jax.lax.scan(step, jnp.zeros((Q, 2), w.dtype), jnp.arange(hits))
    out = jnp.zeros_like(out).at[order].set(out)
    return _per_steradian(out, q) if lift == "sphere" else out


def _kde_hits(angles, width, lift):
    """Most grid angles inside one KDE window (concrete angles and width), else None."""
    try:
        q, half = np.asarray(angles, float), float(KDE_SIGMAS * width)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError, TypeError):
        return None
    if half >= np.pi:
        return None
    q = np.sort(np.abs(q) if lift == "sphere" else _wrap(q, np))
    if lift != "sphere":
        q = np.concatenate([q - 2 * np.pi, q, q + 2 * np.pi])
    return int(np.max(np.searchsorted(q, q + 2 * half, side="right") - np.arange(q.size), initial=1))


def _check(lift, mode, focal_phase, spreading="vertex"):
    if spreading not in SPREADINGS:
        raise ValueError(f"spreading must be one of {SPREADINGS}, got {spreading!r}")
    if lift not in LIFTS:
        raise ValueError(f"lift must be one of {LIFTS}, got {lift!r}")
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if focal_phase not in FOCAL_PHASES:
        raise ValueError(f"focal_phase must be one of {FOCAL_PHASES}, got {focal_phase!r}")


def _hits(fan, angles, lift, max_hits):
    if max_hits is not None:
        return int(max_hits)
    if any(isinstance(a, jax.core.Tracer) for a in jax.tree_util.tree_leaves((fan, angles))):
        # a guessed cap would silently drop hits (a plausible wrong intensity): ask instead
        raise ValueError("flatland.far_field: max_hits = None with a traced fan or traced angles (inside "
                         "jit/vmap); pass max_hits (static), e.g. needed_hits(fan, angles, lift=...) of a "
                         "concrete fan with some margin")
    return needed_hits(fan, angles, lift=lift)


def far_field(fan: Fan, angles, size_parameter=None, *, lift="cylinder", mode="coherent",
              focal_phase="maslov", spreading="vertex", families=None, width=None, max_hits=None,
              chunk=None):
    """Far-field intensity per polarisation, shape ``angles.shape + (2,)`` (⊥, ∥).

    Args:
      fan: the rays (:class:`Fan`), lengths in units of the radius ``a``.
      angles: 1-D output angles (rad): signed ψ for ``lift="cylinder"``, the scattering
        angle θ in [0, pi] for ``lift="sphere"``. Any order.
      size_parameter: ``x = 2π a / λ`` (needed by ``mode="coherent"`` only).
      lift: ``"cylinder"`` → ``(1/2a) dσ/dψ``; ``"sphere"`` → ``(1/πa^2) dσ/dΩ``.
      mode: ``"coherent"``, ``"incoherent"`` or ``"kde"`` (Gaussian of std ``width`` rad per
        ray). With concrete ``angles`` and ``width`` the KDE visits only the grid angles
        within ``KDE_SIGMAS * width`` of each ray (O(rays × window)); otherwise (a traced
        width, or windows covering a third of the grid) every ray meets every angle, in
        chunks of ``chunk`` rays (O(rays × angles)).
      focal_phase: ``"maslov"`` (default, D-R3) or ``"thesis"`` (literal Eq. 3.3).
      spreading: ``"vertex"`` (default) or ``"segment"`` (see the module docstring).
      families: static tuple of family indices to include (default: all).
      max_hits: static cap on grid angles per segment (see module docstring).
    """
    _check(lift, mode, focal_phase, spreading)
    fan = _pick(fan, families)
    angles = jnp.asarray(angles)
    if mode == "kde":
        if width is None:
            raise ValueError("mode='kde' needs width (rad)")
        hits = _kde_hits(angles, width, lift)
        if hits is not None and 3 * hits < angles.shape[0]:
            return _kde_window(fan, angles, jnp.asarray(width, fan.opl.dtype), lift, hits)
        if chunk is None:
            chunk = max(1, min(fan.psi.size, int(4_000_000 // max(angles.shape[0], 1))))
        return _kde(fan, angles, width, lift, int(chunk))
    if mode == "coherent" and size_parameter is None:
        raise ValueError("mode='coherent' needs size_parameter = 2 pi a / lambda")
    x = jnp.asarray(0.0 if size_parameter is None else size_parameter, fan.opl.dtype)
    out = _collect(fan, angles, x, lift, mode, focal_phase, _hits(fan, angles, lift, max_hits), spreading)
    return jnp.abs(out) ** 2 if mode == "coherent" else out


def far_field_amplitude(fan: Fan, angles, size_parameter, *, lift="cylinder", focal_phase="maslov",
                        spreading="vertex", families=None, max_hits=None):
    """Coherent complex far field per polarisation (⊥, ∥), ``|E|^2`` = :func:`far_field`.

    The global phase is arbitrary (reference planes through the centre); the relative phase
    of ⊥ and ∥ is meaningful (for Jones/Stokes outputs and polarising filters).
    """
    _check(lift, "coherent", focal_phase, spreading)
    fan = _pick(fan, families)
    x = jnp.asarray(size_parameter, fan.opl.dtype)
    return _collect(fan, jnp.asarray(angles), x, lift, "coherent", focal_phase,
                    _hits(fan, angles, lift, max_hits), spreading)


def family_energy(fan: Fan, *, lift="cylinder"):
    """Exact integral of the incoherent output per family and polarisation, shape (F, 2).

    Per segment ``∫ |A|^2 ds`` with A linear (no angle grid): ``½ ∫ |A|^2 ds`` for the
    cylinder (integral over ψ of ``(1/2a) dσ/dψ``), ``2 ∫ s |A|^2 ds`` over s >= 0 for the
    sphere (integral over 4π of ``(1/πa^2) dσ/dΩ``). Both are 1 for a lossless particle
    summed over all orders (unpolarised); spec C11.
    """
    _check(lift, "incoherent", "maslov")
    return _family_energy(fan, lift)


@partial(jax.jit, static_argnames=("lift",))
def _family_energy(fan, lift):
    s0, s1 = fan.s[:-1], fan.s[1:]
    ok = fan.valid[:, :-1] & fan.valid[:, 1:]
    a, b = fan.amp[:, :-1], fan.amp[:, 1:]
    ds = (s1 - s0)[None, :, None]
    # ∫_0^1 |a + t (b - a)|^2 dt and ∫_0^1 t |a + t(b - a)|^2 dt, exactly
    aa, bb, ab = jnp.abs(a) ** 2, jnp.abs(b) ** 2, jnp.real(a * jnp.conj(b))
    m0 = (aa + bb + ab) / 3.0
    m1 = aa / 12.0 + bb / 4.0 + ab / 6.0
    if lift == "sphere":
        ok = ok & (s0 >= 0)[None] & (s1 >= 0)[None]
        seg = 2.0 * ds * (s0[None, :, None] * m0 + ds * m1)
    else:
        seg = 0.5 * ds * m0
    return jnp.sum(jnp.where(ok[..., None], seg, 0.0), 1)


def phase_function(intensity, fan: Fan, *, lift="cylinder", families=None):
    """Normalised phase function of the represented orders: ``intensity`` (any collector
    output for ``lift``) divided by the unpolarised energy of the included families
    (:func:`family_energy`), so that it integrates to 1 over the circle (dψ) or the sphere
    (dΩ). The forward diffraction peak (about half of Mie's Q_sca for large x) is absent from
    ray optics and therefore from this normalisation; for p <= 3 the represented energy is
    0.9968 (sphere) or 0.9984 (cylinder) of the incident power (n = 1.331).
    """
    e = family_energy(_pick(fan, families), lift=lift)
    return intensity / jnp.sum(jnp.mean(e, -1))
