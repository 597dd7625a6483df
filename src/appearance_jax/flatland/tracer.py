"""The 2.5D path tracer: 2D hits in the cross-section, 3D directions (spec seed-001 §4.2).

For an infinite, translation-invariant object, hit positions depend only on the 2D
projection of a ray, while Fresnel, microfacet sampling and absorption need the 3D
direction. :func:`trace` follows ``N`` rays launched from ``omega_i`` at offsets ``h`` for a
fixed number of events in one ``lax.scan`` with an alive mask (no Russian roulette, no
data-dependent shapes) and returns, per event and ray, what left the object.

Modes (static):

- ``"split"`` (bounded sections only): at every interface with the exterior on one side the
  child that leaves is **emitted** (recorded) and the other continues, so a smooth fiber is
  traced deterministically and every lobe gets its exact weight: R is the first emission,
  TT the second, ... (the deterministic split of spec M21 / §5.1). Interior interfaces
  (a medulla) choose one child at random.
- ``"random"``: every interface chooses one child with probability proportional to its
  power (one-sample weight, unbiased, stop-gradient probability); a ray is emitted when it
  escapes. Needed for periodic rows.

Lobes are indexed by ``p`` = the number of segments travelled inside the object (R = 0,
TT = 1, TRT = 2, ...). Energy bookkeeping per ray and band:
``sum(emitted) + absorbed + lost + residual = 1``, exactly in split mode, in expectation in
random mode (``lost`` is the energy killed by microfacet masking and validity tests,
``residual`` what is still inside after ``max_events``).

Wave data (``wave=True``): the optical path length ``opl`` between the plane through the
origin perpendicular to omega_i and the plane through the origin perpendicular to the
outgoing direction (Sadeghi 2011 §3.4.3; for a circle L = -2 cos i + 2 p n cos r in units of
the radius, spec seed-002 §1.2.5), and the number of meridional foci ``foci`` (where the
ray and its neighbour in the fan over h cross, counted on every chord and on the outgoing
half-line: the Maslov count), computed from the forward-mode derivative of the trace with
respect to h. ``polarized=True`` carries the complex field as a 3-vector (Jones calculus in
the local s/p bases, power-normalised so that |E|^2 is the power).
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple, Optional

import jax
import jax.numpy as jnp

from ..core import vec as V
from ..core.vec import Vec3
from . import geometry as G
from . import interfaces as I
from .rays import _crossing, _default_field, check_direction  # noqa: F401  (check_direction: re-exported)
from .section import BARBULE_KINDS, Section


class Records(NamedTuple):
    """Output of :func:`trace`. Event arrays have shape ``(max_events, N)`` (+ bands)."""

    direction: Vec3          # emitted propagation direction (= omega_o), per event
    weight: jax.Array        # emitted power per band (0 where nothing left), (E, N, bands)
    lobe: jax.Array          # p = internal segments before the emission, (E, N)
    opl: jax.Array           # optical path length (wave=True), (E, N)
    foci: jax.Array          # meridional foci count (wave=True), (E, N)
    field: Optional[Vec3]    # complex emitted field (polarized=True), (E, N)
    h: jax.Array             # launch offsets, (N,)
    absorbed: jax.Array      # absorbed power per band, (N, bands)
    lost: jax.Array          # power killed by masking / validity tests, (N, bands)
    residual: jax.Array      # power still inside after max_events, (N, bands)
    first_shape: jax.Array   # index of the first shape hit (-1: none), (N,)
    first_h: jax.Array       # offset h on that shape's projected width where it was hit (0: none), (N,)
    truncated: jax.Array     # periodic rows: a ray may have needed more copies, (N,)


def n_bands(section: Section) -> int:
    """Number of bands implied by the section's per-band leaves (1 if all are scalars)."""
    sizes = [1]
    for m in section.media:
        sizes.append(jnp.size(m.sigma_a))
    for s in section.shapes:
        itf = s.interface
        if itf.kind == "diffuse" or itf.kind in BARBULE_KINDS:
            sizes.append(jnp.size(itf.albedo))
        if itf.kind in ("film", "barbule"):
            sizes.append(jnp.size(itf.wavelength_nm))
    return int(max(sizes))


def _bands(x, nb):
    return jnp.broadcast_to(jnp.asarray(x, dtype=jnp.result_type(float)), (nb,))


def launch(section: Section, wi: Vec3, h):
    """Origin (2D), the derivative of the origin with respect to h, and the projected half
    width ``D_i`` of the object seen from ``wi`` (bounded sections) or the period (rows).

    Bounded: ``h`` in [-1, 1] spans the projected width of the outer shape (B.8 with the
    weights fixed to (1 - h)/2, (1 + h)/2, seed-000 spec M22). Rows: ``h`` in [-1, 1) spans
    one period on the line above the row (wi.z > 0) or below it (wi.z < 0).
    """
    uy, uz = G.unit_2d(-wi.y, -wi.z)
    if section.periodic:
        top = _row_reach(section) * 1.0001
        P = section.period
        oy = (h + 1.0) * 0.5 * P
        oz = jnp.broadcast_to(jnp.where(wi.z < 0, -top, top), jnp.shape(oy))
        return (oy, oz), (0.5 * P * jnp.ones_like(oy), jnp.zeros_like(oy)), 0.5 * P
    o = section.outer()
    # an offset of exactly +-1 is a tangent ray (cos_i = 0 at the hit), where reverse-mode
    # derivatives of the interface terms are 0 * inf; moving it 1e-9 inside changes a
    # measure-zero set of offsets and keeps gradients finite
    h = jnp.clip(h, -1.0 + 1e-9, 1.0 - 1e-9)
    (y0, z0), (y1, z1) = G.tangent_points(uy, uz, o.cy, o.cz, o.a, o.b, o.psi)
    # start just outside the shape's bounding circle (not 10 radii away as B.8 suggests): the
    # origin's magnitude sets the float32 error of the hit, which grazing rays amplify
    far = 1.001 * jnp.maximum(o.a, o.b) + jnp.abs(o.cy) + jnp.abs(o.cz)
    oy = y0 * (1 - h) * 0.5 + y1 * (1 + h) * 0.5 - far * uy
    oz = z0 * (1 - h) * 0.5 + z1 * (1 + h) * 0.5 - far * uz
    D = G.half_width(uy, uz, o.a, o.b, o.psi)
    return (oy, oz), (0.5 * (y1 - y0) * jnp.ones_like(oy), 0.5 * (z1 - z0) * jnp.ones_like(oy)), D


def _select(idx, values):
    out = values[0]
    for i, v in enumerate(values[1:], start=1):
        out = jnp.where(idx == i, v, out)
    return out


def _select_vec(idx, vecs):
    return Vec3(*(_select(idx, [tuple(v)[k] for v in vecs]) for k in range(3)))


def _event_uniforms(key, shape, dtype, needed):
    """The five uniforms of an event (microfacet 2 or barbule tilt 1, choice 1, diffuse 2); slots the section
    never uses are constants, so a smooth fiber in split mode draws no random numbers."""
    keys = jax.random.split(key, 5)
    half = jnp.full(shape, 0.5, dtype)
    return tuple(jax.random.uniform(k, shape, dtype) if need else half for k, need in zip(keys, needed))


def _uniforms_needed(section, mode):
    rough = any(s.interface.kind == "dielectric" and s.interface.rough for s in section.shapes)
    tilted = any(s.interface.kind in BARBULE_KINDS for s in section.shapes)
    diffuse = any(s.interface.kind in ("diffuse", "barbule") for s in section.shapes)
    # split mode still chooses at interfaces between two interior regions
    interior = any(s.inside != 0 and s.outside != 0 and s.interface.kind in ("dielectric", "film")
                   for s in section.shapes)
    choice = mode != "split" or interior
    return (rough or tilted, rough, choice, diffuse, diffuse)


def _coin_slots(section):
    """Static: for each shape, the row of the per-event coin array its copies use (None: solid)."""
    n_copies = 2 * section.copies + 1 if section.periodic else 1
    slots, k = [], 0
    for s in section.shapes:
        slots.append(k if s.interface.semi_transparent else None)
        k += n_copies if s.interface.semi_transparent else 0
    return slots, k


@partial(jax.jit, static_argnames=("max_events", "mode", "wave", "polarized", "nee"))
def _trace(section, wi, h, key, E0, max_events, mode, wave, polarized, nee=False, wl=None):
    dtype = jnp.result_type(float)
    h = jnp.asarray(h, dtype)
    N = h.shape[0]
    nb = n_bands(section)
    shapes = section.shapes
    S = len(shapes)
    media_eta = [jnp.asarray(m.eta, dtype) for m in section.media]
    media_sig = [_bands(m.sigma_a, nb) for m in section.media]
    eta0 = media_eta[0]
    periodic = section.periodic
    M = section.copies if periodic else 0
    n_copies = 2 * M + 1

    (oy, oz), (toy, toz), _ = launch(section, wi, h)
    d = Vec3(*(jnp.broadcast_to(-c, (N,)).astype(dtype) for c in wi))
    zeros = jnp.zeros((N,), dtype)
    izeros = jnp.zeros((N,), jnp.int32)
    # initial OPL: the origin's coordinate along the incident direction (reference plane
    # through the section's origin perpendicular to omega_i)
    opl0 = eta0 * (oy * d.y + oz * d.z)
    fstate = dict(py=oy, pz=oz, px=zeros, dx=d.x, dy=d.y, dz=d.z, opl=opl0)
    tstate = dict(py=toy, pz=toz, px=zeros, dx=zeros, dy=zeros, dz=zeros, opl=eta0 * (toy * d.y + toz * d.z))
    if polarized:
        fstate["E"] = E0
        tstate["E"] = Vec3(*(jnp.zeros_like(c) for c in E0))
    istate = dict(region=izeros, last=izeros - 1, last_copy=izeros, seg=izeros, foci=izeros,
                  alive=jnp.ones((N,), bool), first=izeros - 1, first_h=zeros)
    w = jnp.ones((N, nb), dtype)
    acc = dict(w=w, absorbed=jnp.zeros((N, nb), dtype), lost=jnp.zeros((N, nb), dtype),
               truncated=jnp.zeros((N,), bool))

    def geometry_of(i, k):
        s = shapes[i]
        cy = s.cy + (k * section.period if periodic else 0.0)
        return cy, s.cz, s.a, s.b, s.psi

    slots, _ = _coin_slots(section)
    any_seg = any(s.is_segment for s in shapes)
    is_seg = jnp.asarray([s.is_segment for s in shapes]) if any_seg else None

    def core(f, ist, w, u, coins):
        """One event (differentiable in the float state ``f``)."""
        p_y, p_z, dd = f["py"], f["pz"], Vec3(f["dx"], f["dy"], f["dz"])
        k0 = jnp.round(p_y / section.period).astype(jnp.int32) if periodic else izeros
        # all copies of a shape at once: (copies, N) arrays, one traced intersection per shape
        kk = k0[None, :] + jnp.arange(-M, M + 1, dtype=jnp.int32)[:, None]
        P1 = lambda v: v[None, :]  # noqa: E731
        ts = []
        for i in range(S):
            s = shapes[i]
            lo, span = s.arc if s.arc is not None else (None, None)   # closed: no arc test
            cy, cz, a, b, psi = geometry_of(i, kk)
            leaving = P1(ist["last"] == i) & ((P1(ist["last_copy"]) == kk) if periodic else True)
            if s.is_segment:
                t, _ = G.intersect_segment(P1(p_y), P1(p_z), P1(dd.y), P1(dd.z), cy, cz, a, psi, leaving)
            else:
                t, _ = G.intersect(P1(p_y), P1(p_z), P1(dd.y), P1(dd.z), cy, cz, a, b, psi, lo, span, leaving)
            if slots[i] is not None:  # semi-transparent: each crossing is there with probability coverage
                t = jnp.where(coins[slots[i]:slots[i] + n_copies] < s.interface.coverage, t, jnp.inf)
            if s.present is not None:  # a shape switched off as data
                t = jnp.where(s.present, t, jnp.inf)
            ts.append(jnp.broadcast_to(t, kk.shape))
        T = jnp.concatenate(ts)                               # (S copies, N): shape-major
        j_best = jnp.argmin(T, axis=0)
        t = jnp.min(T, axis=0)
        sid = (j_best // n_copies).astype(jnp.int32)
        kcopy = jnp.take_along_axis(kk, (j_best % n_copies)[None, :], axis=0)[0] if periodic else izeros
        alive = ist["alive"]
        hit = alive & jnp.isfinite(t)
        t_s = jnp.where(hit, t, 0.0)
        region = ist["region"]
        ny_, nz_ = p_y + t_s * dd.y, p_z + t_s * dd.z
        px = f["px"] + t_s * dd.x
        eta_here = _select(region, media_eta)
        sig = _select(region[:, None], [m[None, :] for m in media_sig])
        att = jnp.exp(-sig * t_s[:, None])
        opl = f["opl"] + eta_here * t_s

        # geometry at the hit (of the selected shape and copy)
        geo = [geometry_of(i, kcopy) for i in range(S)]
        cy, cz, a, b, psi = (_select(sid, [g[q] for g in geo]) for q in range(5))
        uy, uz = G.unit_2d(dd.y, dd.z)
        if any_seg:
            seg = is_seg[sid]
            n_y, n_z = G.normal_at(ny_, nz_, cy, cz, jnp.where(seg, 1.0, a), jnp.where(seg, 1.0, b), psi)
            s_y, s_z = G.segment_normal(psi)
            n_y, n_z = jnp.where(seg, s_y, n_y), jnp.where(seg, s_z, n_z)
            half = jnp.where(seg, G.segment_half_width(uy, uz, a, psi), G.half_width(uy, uz, a, b, psi))
        else:  # (static) only ellipses: the segment branches are not compiled
            n_y, n_z = G.normal_at(ny_, nz_, cy, cz, a, b, psi)
            half = G.half_width(uy, uz, a, b, psi)
        n_out = Vec3(jnp.zeros_like(n_y), n_y, n_z)
        from_out = V.dot(dd, n_out) < 0
        # the hit's offset across the shape's projected width, to the left of the travel (h of launch)
        h_hit = ((ny_ - cy) * -uz + (nz_ - cz) * uy) / jnp.where(half > 0, half, 1.0)

        children = []
        for i, s in enumerate(shapes):
            itf = s.interface
            other = jnp.where(from_out, s.inside, s.outside)
            here = jnp.where(from_out, s.outside, s.inside)
            e1, e2 = _select(here, media_eta), _select(other, media_eta)
            if itf.kind == "dielectric":
                d_r, g_r, d_t, g_t, E_r, E_t = I.dielectric(dd, n_out, from_out, e1, e2, itf, u[0], u[1],
                                                            polarized, f.get("E"))
                g_r, g_t = jnp.broadcast_to(g_r[:, None], (N, nb)), jnp.broadcast_to(g_t[:, None], (N, nb))
            elif itf.kind == "film":
                d_r, g_r, d_t, g_t, E_r, E_t = I.film(dd, n_out, from_out, e1, e2, itf, polarized, f.get("E"))
                g_r, g_t = jnp.broadcast_to(g_r, (N, nb)), jnp.broadcast_to(g_t, (N, nb))
            elif itf.kind in BARBULE_KINDS:
                if polarized:
                    raise ValueError("flatland.trace: polarized=True cannot pass a barbule (diffuse TRT)")
                d_r, g_r, d_t, g_t = I.barbule(dd, n_out, from_out, itf, u[0], u[3], u[4])
                g_r, g_t = jnp.broadcast_to(g_r, (N, nb)), jnp.broadcast_to(g_t, (N, nb))
                E_r = E_t = None
            elif itf.kind == "diffuse":
                if polarized:
                    raise ValueError("flatland.trace: polarized=True cannot pass a diffuse "
                                     "(depolarising) interface")
                d_r = I.diffuse(dd, n_out, from_out, u[3], u[4])
                g_r = jnp.broadcast_to(_bands(itf.albedo, nb), (N, nb))
                d_t, g_t, E_r, E_t = dd, jnp.zeros((N, nb), dtype), None, None
            else:  # absorber
                d_r = d_t = dd
                g_r = g_t = jnp.zeros((N, nb), dtype)
                E_r = E_t = f.get("E")
            children.append((d_r, g_r, d_t, g_t, here, other, E_r, E_t, itf.kind))

        d_r = _select_vec(sid, [c[0] for c in children])
        g_r = _select(sid[:, None], [c[1] for c in children])
        d_t = _select_vec(sid, [c[2] for c in children])
        g_t = _select(sid[:, None], [c[3] for c in children])
        reg_r = _select(sid, [c[4] for c in children])
        reg_t = _select(sid, [c[5] for c in children])
        opaque = _select(sid, [jnp.asarray(c[8] in ("diffuse", "absorber") + BARBULE_KINDS) for c in children])
        if polarized:
            E_r = _select_vec(sid, [c[6] for c in children])
            E_t = _select_vec(sid, [c[7] for c in children])

        w_in = w * att
        if nee:
            # camera-side next-event estimation towards the delta light wl: every hit on a
            # rough interface with the exterior on one side connects to the light
            cs = []
            for i, s in enumerate(shapes):
                itf = s.interface
                if itf.kind == "dielectric" and itf.rough and s.closed and 0 in (s.inside, s.outside):
                    here = jnp.where(from_out, s.outside, s.inside)
                    other = jnp.where(from_out, s.inside, s.outside)
                    c_r, c_t = I.dielectric_eval(dd, n_out, from_out, _select(here, media_eta),
                                                 _select(other, media_eta), itf, wl)
                    # outside: reflect to the light; inside: transmit to it (the light is
                    # in the exterior, so no other connection is possible)
                    cs.append(jnp.where(here == 0, c_r, jnp.where(other == 0, c_t, 0.0)))
                else:
                    cs.append(jnp.zeros((N,), dtype))
            w_nee = jnp.where(hit[:, None], w_in * _select(sid, cs)[:, None], 0.0)
        # emission: split -> the child that is (or goes) outside; random -> escapes
        escape = alive & ~hit & (region == 0)
        if mode == "split":
            emit_r = hit & (region == 0)
            emit_t = hit & (reg_t == 0) & (region != 0) & ~opaque
            emit = emit_r | emit_t
            chance = ~emit
        else:
            emit = emit_r = emit_t = jnp.zeros_like(hit)
            chance = jnp.ones_like(hit)
        m_r = jnp.mean(g_r, -1)
        m_t = jnp.mean(g_t, -1)
        tot = m_r + m_t
        p_r = jax.lax.stop_gradient(jnp.where(tot > 0, m_r / jnp.where(tot > 0, tot, 1.0), 0.0))
        pick_r = jnp.where(chance, u[2] < p_r, emit_t)    # split: continue the other child
        p_pick = jnp.where(chance, jnp.where(pick_r, p_r, 1.0 - p_r), 1.0)
        p_pick = jnp.where(p_pick > 0, p_pick, 1.0)
        g_c = jnp.where(pick_r[:, None], g_r, g_t) / p_pick[:, None]
        d_c = V.where(pick_r, d_r, d_t)
        reg_c = jnp.where(pick_r, reg_r, reg_t)
        w_next = jnp.where(hit[:, None], w_in * g_c, w)

        g_e = jnp.where(emit_r[:, None], g_r, g_t)
        d_e = V.where(emit_r, d_r, d_t)
        w_emit = jnp.where(emit[:, None], w_in * g_e, 0.0) if mode == "split" else jnp.zeros_like(w)
        d_emit = d_e if mode == "split" else dd
        w_emit = jnp.where(escape[:, None], w, w_emit)
        d_emit = V.where(escape, dd, d_emit)
        if nee:
            w_emit = w_nee
            escape = jnp.zeros_like(escape)
        opl_emit = jnp.where(escape, f["opl"] - eta0 * (p_y * dd.y + p_z * dd.z + f["px"] * dd.x),
                             opl - eta0 * (ny_ * d_e.y + nz_ * d_e.z + px * d_e.x))

        absorbed = jnp.where(hit[:, None], w * (1 - att), 0.0)
        absorbed = absorbed + jnp.where((hit & opaque)[:, None], w_in * (1 - g_r - g_t), 0.0)
        lost = jnp.where((hit & ~opaque)[:, None], w_in * (1 - g_r - g_t), 0.0)
        lost = lost + jnp.where((alive & ~hit & (region != 0))[:, None], w, 0.0)

        f_new = dict(py=jnp.where(hit, ny_, p_y), pz=jnp.where(hit, nz_, p_z), px=jnp.where(hit, px, f["px"]),
                     dx=jnp.where(hit, d_c.x, dd.x), dy=jnp.where(hit, d_c.y, dd.y),
                     dz=jnp.where(hit, d_c.z, dd.z), opl=jnp.where(hit, opl, f["opl"]))
        emitted_E = None
        if polarized:
            E_c = V.where(pick_r, E_r, E_t)
            scale = jnp.sqrt(1.0 / p_pick)
            f_new["E"] = V.where(hit, E_c * scale, f["E"])
            emitted_E = V.where(escape, f["E"], V.where(emit_r, E_r, E_t))
        emission_f = dict(dx=d_emit.x, dy=d_emit.y, dz=d_emit.z, py=jnp.where(escape, p_y, ny_),
                          pz=jnp.where(escape, p_z, nz_))
        new_alive = hit & (jnp.sum(g_c, -1) > 0)
        ist_new = dict(region=jnp.where(hit, reg_c, region), last=jnp.where(hit, sid, ist["last"]),
                       last_copy=jnp.where(hit, kcopy, ist["last_copy"]),
                       seg=ist["seg"] + (hit & (region != 0)).astype(jnp.int32), foci=ist["foci"],
                       alive=new_alive, first=jnp.where(ist["first"] < 0, jnp.where(hit, sid, -2), ist["first"]),
                       first_h=jnp.where(ist["first"] < 0, jnp.where(hit, h_hit, 0.0), ist["first_h"]))
        emitted = (emit | escape) if not nee else hit
        aux = dict(ist=ist_new, w=w_next, w_emit=w_emit, emit=emitted, seg_emit=ist["seg"] + (
            hit & (region != 0)).astype(jnp.int32) * (~escape).astype(jnp.int32), opl_emit=opl_emit,
            E_emit=emitted_E, absorbed=absorbed, lost=lost, t=t_s, hit=hit, escape=escape,
            trunc=_truncated(section, p_y, p_z, dd, alive, region) if periodic else jnp.zeros_like(hit))
        return (f_new, emission_f), aux

    def body(carry, key_e):
        f, tf, ist, acc = carry
        coins = None
        if n_coins:  # (solid sections keep their random streams)
            key_e, key_c = jax.random.split(key_e)
            coins = jax.random.uniform(key_c, (n_coins, N), dtype)
        u = _event_uniforms(key_e, (N,), dtype, needed)
        fn = lambda ff: core(ff, ist, acc["w"], u, coins)
        if wave:
            (f_new, em), (tf_new, tem), aux = jax.jvp(fn, (f,), (tf,), has_aux=True)
            # meridional foci on the chord just travelled: the transverse offset
            # (dp + s dd) . n_perp of the neighbouring ray changes sign at 0 < s < t
            foci = ist["foci"] + _crossing(f, tf, aux["t"], aux["hit"] & ~aux["escape"])
            # ... and on the outgoing half-line of the emitted ray
            foci_emit = foci + _crossing(em, tem, jnp.inf, aux["emit"])
            aux["ist"]["foci"] = foci
        else:
            (f_new, em), aux = fn(f)
            tf_new = tf
            foci_emit = izeros
        ist_new = aux["ist"]
        acc = dict(w=aux["w"], absorbed=acc["absorbed"] + aux["absorbed"], lost=acc["lost"] + aux["lost"],
                   truncated=acc["truncated"] | aux["trunc"])
        rec = (Vec3(em["dx"], em["dy"], em["dz"]), aux["w_emit"], aux["seg_emit"], aux["opl_emit"],
               jnp.where(aux["emit"], foci_emit, 0), aux["E_emit"])
        return (f_new, tf_new, ist_new, acc), rec

    needed = _uniforms_needed(section, mode)
    n_coins = _coin_slots(section)[1]
    keys = jax.random.split(key, max_events)
    (f, tf, ist, acc), rec = jax.lax.scan(body, (fstate, tstate, istate, acc), keys)
    direction, weight, lobe, opl, foci, field = rec
    residual = jnp.where(ist["alive"][:, None], acc["w"], 0.0)
    return Records(direction, weight, lobe, opl, foci, field, h, acc["absorbed"], acc["lost"], residual,
                   jnp.maximum(ist["first"], -1), ist["first_h"], acc["truncated"])


def _row_reach(section):
    """Half height of the band |z| <= reach that holds every shape of a periodic row."""
    return jnp.max(jnp.stack([jnp.abs(s.cz) + jnp.maximum(s.a, s.b) for s in section.shapes]))


def _truncated(section, p_y, p_z, d, alive, region):
    """Periodic rows: True where a ray crossing the row's band could reach shapes beyond the
    ``copies`` neighbours tested per event."""
    reach = _row_reach(section)
    dz = jnp.where(jnp.abs(d.z) > 1e-12, jnp.abs(d.z), 1e-12)
    span = (2.0 * reach * jnp.abs(d.y) / dz + 2.0 * reach) / section.period
    return alive & (span > section.copies)


def trace(section: Section, wi: Vec3, h, key=None, *, max_events: int = 16, mode: str = "split",
          wave: bool = False, polarized: bool = False, field=None) -> Records:
    """Trace rays launched from direction ``wi`` (unit, pointing to the light, fiber frame)
    at offsets ``h`` (array of shape (N,), in [-1, 1]) through ``section``.

    Args:
        key: PRNG key for rough interfaces, diffuse surfaces and random choices (default
            key 0; a smooth fiber in split mode uses none).
        max_events: scan length (static); what is still inside afterwards is ``residual``.
        mode: ``"split"`` or ``"random"`` (see the module docstring). Periodic rows need
            ``"random"``.
        wave: also compute optical path lengths and meridional foci (forward-mode derivative
            over h; meaningful for smooth interfaces).
        polarized: carry the complex field; ``field`` = incident field, a complex
            :class:`Vec3` perpendicular to -wi (default: along the fiber axis projected).

    Returns:
        :class:`Records`. Everything is differentiable with respect to the section's
        parameters (hits are exact; silhouettes and branch switches are not differentiated).
    """
    section = section.validate()
    check_direction("flatland.trace.wi", wi)
    if mode not in ("split", "random"):
        raise ValueError(f"flatland.trace: mode = {mode!r}; valid: 'split', 'random'")
    if mode == "split" and section.periodic:
        raise ValueError("flatland.trace: mode = 'split' needs a bounded section; periodic rows "
                         "need mode = 'random'")
    max_events = int(max_events)
    if max_events < 1:
        raise ValueError(f"flatland.trace: max_events = {max_events}; valid range [1, inf)")
    h = jnp.atleast_1d(jnp.asarray(h, dtype=jnp.result_type(float)))
    if h.ndim != 1:
        raise ValueError(f"flatland.trace: h must be 1D, got shape {h.shape}")
    if not isinstance(h, jax.core.Tracer):
        import numpy as np
        hv = np.asarray(h)
        if np.any(~np.isfinite(hv)) or np.any(np.abs(hv) > 1):
            raise ValueError("flatland.trace: h must lie in [-1, 1]")
    key = jax.random.PRNGKey(0) if key is None else key
    E0 = None
    if polarized:
        E0 = _default_field(wi, h.shape[0]) if field is None else Vec3(
            *(jnp.broadcast_to(jnp.asarray(c, jnp.complex64 if jnp.result_type(float) == jnp.float32
                                           else jnp.complex128), h.shape) for c in field))
    return _trace(section, wi, h, key, E0, max_events, mode, wave, polarized)
