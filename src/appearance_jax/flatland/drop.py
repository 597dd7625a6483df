"""Deterministic 2-D fan tracer through a water drop's section (a circle, or the
Beard–Chuang meridian), returning a :class:`~appearance_jax.flatland.fan.Fan` (Sadeghi 2011
§3.4, L1168–1290; spec seed-002 §1.2.4–§1.2.5, §4 items 1–4).

Frame: the meridian plane ``(x, z)`` of :mod:`.polar_curve` (z up along the symmetry axis).
A collimated beam arrives with propagation direction ``(cos alpha, -sin alpha)``, where
``alpha`` = ``inclination`` is the sun's elevation above the horizontal (0 = horizontal
light, the axis vertical; the light travels downwards for alpha > 0). Every convention of
the output (units of a, signs of s and psi, (⊥, ∥) amplitudes, optical path between the
centre planes, foci and axis counts) is that of :mod:`.fan`. The impact parameter s is
measured from the curve's origin; the rays that hit fill the drop's projected extent, which
is (-1, 1) for a circle but not for a flattened drop (e.g. (-0.929, 0.970) for 1 mm at
inclination 0): :func:`impact_grid` spans it.

Families p = 0 .. F-1 share one trace: the entry hit gives p = 0 (external reflection) and
the refracted ray; the k-th internal hit gives family k (refraction out) and the reflected
ray that continues (k-1 internal reflections so far). The internal bounces are a
``lax.scan`` of static length F - 1, so F = 30 compiles like F = 4.

Amplitudes are products of the complex Fresnel amplitude coefficients of
:mod:`appearance_jax.optics.fresnel` (the thesis's signs, decision D-O2: A_0 = rho(i),
A_p = (1 - rho^2)(-rho)^(p-1) on a circle), with the transmissions power-normalised
(t sqrt(eta_t cos_t / (eta_i cos_i))) so that |A|^2 is the fraction of the ray's power;
on a circle this equals the plain product t t'. Internal reflections beyond the critical
angle are total with a complex coefficient of modulus 1; a family whose exit would be
totally reflected is ``valid`` = False for that ray (its power stays in family p + 1).

``foci`` (decision D-R3) counts where a ray and its neighbour in the fan cross, on each
chord and on the outgoing half-line, from the forward-mode derivative of the trace with
respect to s (:func:`appearance_jax.flatland.rays._crossing`); ``axis`` counts the sign
changes of the transverse coordinate x . n_perp along the polyline hit points and the
outgoing half-line (the axis through the centre along the incident direction; for the
axisymmetric 3-D lift only).

Gradients: hits are differentiated by the implicit-function theorem (one Newton step at
the converged root; :mod:`.polar_curve`), so the fan is differentiable in the shape's
coefficients, the drop radius (through Table 3.1), the index and the inclination, away
from grazing rays and caustics. Not modelled: rays that leave and hit the drop again
(impossible for the convex Table 3.1 shapes), absorption.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from ..core.arrays import is_concrete
from ..optics.fresnel import fresnel_amplitudes_complex, snell_cos_t
from . import polar_curve as pcv
from .fan import Fan
from .polar_curve import PolarCurve
from .rays import _crossing

sg = jax.lax.stop_gradient


def _fresnel(cos_i, eta_i, eta_t):
    """(r_perp, r_par) complex, power-normalised (t_perp, t_par), TIR flag; cos_i >= 0."""
    r_s, r_p, t_s, t_p, cos_t = fresnel_amplitudes_complex(cos_i, eta_i, eta_t)
    rel = eta_t / eta_i
    ct, ok = snell_cos_t(cos_i, rel)
    pos = ok & (cos_i > 0)
    k = jnp.sqrt(jnp.where(pos, rel * ct / jnp.where(pos, cos_i, 1.0), 0.0))
    return (r_s, r_p), (t_s * k, t_p * k), ~ok


def _refract(dx, dz, nx, nz, cos_i, eta_rel):
    """Snell refraction of d at a normal n that points to the incident side (cos_i = -d . n),
    eta_rel = eta_t / eta_i; returns the direction (and cos_t, validity)."""
    ct, ok = snell_cos_t(cos_i, eta_rel)
    e = 1.0 / eta_rel
    k = e * cos_i - ct
    return e * dx + k * nx, e * dz + k * nz, ok


def _reflect(dx, dz, nx, nz):
    k = 2.0 * (dx * nx + dz * nz)
    return dx - k * nx, dz - k * nz


def _chain(curve, eta, alpha, s, F):
    """The geometry of the trace (hit points, directions, cosines), differentiated along s
    for the foci counts; amplitudes and paths follow from it in :func:`_trace`."""
    dx0, dz0 = jnp.cos(alpha), -jnp.sin(alpha)
    ux, uz = -dz0, dx0                                     # n_perp: the s axis
    rb = sg(1.0 + jnp.sum(jnp.abs(curve.c)))               # bound on r / a
    px0, pz0 = s * ux - 1.5 * rb * dx0, s * uz - 1.5 * rb * dz0
    dxs, dzs = jnp.broadcast_to(dx0, s.shape), jnp.broadcast_to(dz0, s.shape)
    t1, hit = pcv.hit_from_outside(curve, px0, pz0, dxs, dzs, 3.0 * rb)
    x1, z1 = px0 + t1 * dx0, pz0 + t1 * dz0
    nx, nz = pcv.normal(curve, x1, z1)
    ci = -(dx0 * nx + dz0 * nz)
    ox, oz = _reflect(dxs, dzs, nx, nz)
    dx, dz, _ = _refract(dxs, dzs, nx, nz, ci, eta)

    def step(carry, _):
        x, z, dx, dz = carry
        t, ok = pcv.hit_from_inside(curve, x, z, dx, dz, 2.2 * rb)
        qx, qz = x + t * dx, z + t * dz
        nx, nz = pcv.normal(curve, qx, qz)
        ci = dx * nx + dz * nz
        ex, ez, _ = _refract(dx, dz, -nx, -nz, ci, 1.0 / eta)
        rx, rz = _reflect(dx, dz, nx, nz)
        return (qx, qz, rx, rz), dict(px=x, pz=z, dx=dx, dz=dz, t=t, ok=ok, qx=qx, qz=qz, ci=ci, ox=ex, oz=ez)

    # (F = 1 still runs one step, sliced off: a zero-length scan has no body to trace)
    _, chords = jax.lax.scan(step, (x1, z1, dx, dz), None, length=max(F - 1, 1))
    chords = jax.tree_util.tree_map(lambda a: a[:F - 1], chords)
    entry = dict(x=x1, z=z1, ci=ci, ox=ox, oz=oz, hit=hit)
    return entry, chords


@partial(jax.jit, static_argnames=("F",))
def _trace(curve, eta, alpha, s, F):
    dtype = s.dtype
    dx0, dz0 = jnp.cos(alpha), -jnp.sin(alpha)
    ux, uz = -dz0, dx0
    lo, hi = pcv.extent(sg(curve), sg(ux), sg(uz))
    hit_s = (s > lo) & (s < hi)
    s_eff = jnp.where(hit_s, s, 0.5 * (lo + hi))            # missed rays: a safe stand-in
    (en, ch), (ten, tch) = jax.jvp(lambda v: _chain(curve, eta, alpha, v, F), (s_eff,),
                                   (jnp.ones_like(s_eff),))
    cat = lambda a, b: jnp.concatenate([a[None], b], 0)
    one = jnp.ones((), dtype)
    # amplitudes: entry reflection (p = 0); entry transmission x internal reflections so far
    # x exit transmission (p >= 1)
    (r_s, r_p), (t_s, t_p), _ = _fresnel(en["ci"], one, eta)
    (R_s, R_p), (T_s, T_p), tir = _fresnel(ch["ci"], eta, one)
    before = lambda R: jnp.cumprod(cat(jnp.ones(s.shape, R.dtype), R), 0)[:F - 1]
    amp = cat(jnp.stack([r_s, r_p], -1),
              jnp.stack([t_s * before(R_s) * T_s, t_p * before(R_p) * T_p], -1))
    opl_in = en["x"] * dx0 + en["z"] * dz0                  # centre plane -> entry point
    ox, oz = cat(en["ox"], ch["ox"]), cat(en["oz"], ch["oz"])
    ex, ez = cat(en["x"], ch["qx"]), cat(en["z"], ch["qz"])
    opl = opl_in + cat(jnp.zeros_like(opl_in), eta * jnp.cumsum(ch["t"], 0)) - (ex * ox + ez * oz)
    entered = jnp.cumsum(~ch["ok"], 0) == 0
    valid = cat(en["hit"], en["hit"] & entered & ~tir) & hit_s
    # foci (D-R3): on chords 1 .. p (cumulative), then on the family's outgoing half-line
    chord = _crossing(dict(py=ch["px"], pz=ch["pz"], dy=ch["dx"], dz=ch["dz"]),
                      dict(py=tch["px"], pz=tch["pz"], dy=tch["dx"], dz=tch["dz"]), ch["t"], True)
    foci = cat(jnp.zeros(s.shape, jnp.int32), jnp.cumsum(chord, 0))
    tox, toz = cat(ten["ox"], tch["ox"]), cat(ten["oz"], tch["oz"])
    tex, tez = cat(ten["x"], tch["qx"]), cat(ten["z"], tch["qz"])
    foci = foci + _crossing(dict(py=ex, pz=ez, dy=ox, dz=oz), dict(py=tex, pz=tez, dy=tox, dz=toz),
                            jnp.inf, True)
    # axis: sign changes of x . n_perp along the hit points and the outgoing half-line
    u = ex * ux + ez * uz
    flips = (u[:-1] * u[1:] < 0).astype(jnp.int32)
    ax = cat(jnp.zeros(s.shape, jnp.int32), jnp.cumsum(flips, 0))
    ax = ax + (u * (ox * ux + oz * uz) < 0).astype(jnp.int32)
    psi = jnp.arctan2(dx0 * oz - dz0 * ox, dx0 * ox + dz0 * oz)
    zero = jnp.zeros((), dtype)
    return Fan(s=s, psi=jnp.where(valid, psi, zero), amp=jnp.where(valid[..., None], amp, 0j),
               opl=jnp.where(valid, opl, zero), foci=jnp.where(valid, foci, 0),
               axis=jnp.where(valid, ax, 0), valid=valid)


def impact_grid(curve: PolarCurve, n_rays: int, inclination=0.0):
    """``n_rays`` impact parameters at the midpoints of equal cells spanning the drop's
    projected extent for the given sun inclination ((-1, 1) for a circle)."""
    n_rays = int(n_rays)
    if n_rays < 2:
        raise ValueError(f"flatland.impact_grid: n_rays = {n_rays}; valid range [2, inf)")
    a = jnp.asarray(inclination, jnp.result_type(float))
    lo, hi = pcv.extent(sg(curve), sg(jnp.sin(a)), sg(jnp.cos(a)))
    u = (jnp.arange(n_rays, dtype=a.dtype) + 0.5) / n_rays
    return lo + (hi - lo) * u


def trace_drop(curve: PolarCurve, eta, *, inclination=0.0, s=None, n_rays: int = 4096,
               families: int = 4) -> Fan:
    """Trace a collimated beam through a drop section and return its :class:`Fan`.

    Args:
        curve: the section, lengths in units of a (:func:`~.polar_curve.beard_chuang` with the
            radius in mm, :func:`~.polar_curve.circle_curve`, :func:`~.polar_curve.cosine_series`).
        eta: relative refractive index of the drop (> 1; scalar).
        inclination: the sun's elevation above the horizontal in radians (the tilt of the
            incident direction in the meridian plane; 0 = horizontal light).
        s: impact parameters b / a, 1-D, sorted increasing, inside the projected extent
            ((-1, 1) for a circle); default :func:`impact_grid` with ``n_rays`` rays.
        families: F, the number of path families p = 0 .. F-1 (static).

    Returns:
        :class:`Fan` with fields of shape (F, N); see :mod:`.fan` for the conventions. Float64
        is recommended (``jax_enable_x64``): wave phases k a L reach 1e4 rad.

    Example: ``trace_drop(beard_chuang(0.5), 1.331, s=jnp.linspace(-0.99, 0.99, 1001))``.
    """
    if not isinstance(curve, PolarCurve):
        raise TypeError("flatland.trace_drop: curve must be a PolarCurve (beard_chuang, circle_curve, "
                        f"cosine_series), got {type(curve).__name__}")
    F = int(families)
    if F < 1:
        raise ValueError(f"flatland.trace_drop: families = {F}; valid range [1, inf)")
    dtype = jnp.result_type(float)
    eta = jnp.asarray(eta, dtype)
    alpha = jnp.asarray(inclination, dtype)
    if eta.ndim != 0 or alpha.ndim != 0:
        raise ValueError("flatland.trace_drop: eta and inclination must be scalars (vmap for more)")
    if is_concrete(eta) and not (np.isfinite(float(eta)) and float(eta) > 1.0):
        raise ValueError(f"flatland.trace_drop: eta = {float(eta)}; valid range (1, inf)")
    if is_concrete(alpha) and not np.isfinite(float(alpha)):
        raise ValueError(f"flatland.trace_drop: inclination = {float(alpha)} must be finite")
    if s is None:
        s = impact_grid(curve, n_rays, alpha)
    s = jnp.asarray(s, dtype)
    if s.ndim != 1 or s.shape[0] < 1:
        raise ValueError(f"flatland.trace_drop: s must be 1-D and non-empty, got shape {s.shape}")
    if is_concrete(s, curve, alpha):
        sv = np.asarray(s)
        lo, hi = (float(v) for v in pcv.extent(curve, jnp.sin(alpha), jnp.cos(alpha)))
        if not np.all(np.isfinite(sv)) or np.any(np.diff(sv) <= 0):
            raise ValueError("flatland.trace_drop: s must be finite and strictly increasing")
        if sv[0] <= lo or sv[-1] >= hi:
            raise ValueError(f"flatland.trace_drop: s must lie inside the drop's projected extent "
                             f"({lo:.6g}, {hi:.6g}) (a circle: (-1, 1)); got [{sv[0]:.6g}, {sv[-1]:.6g}]")
    return _trace(curve, eta, alpha, s, F)
