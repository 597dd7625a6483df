"""Flatland feather mode: a traced reference for the rock-dove barbule BSDF (spec seed-001 §4.3
item 8; Huang 2022 Ch. 5). Not in the thesis; it checks the model's NDF (Huang Eq. 5.7), binary
visibility and valid length Delta h'/Delta h (Eqs. 5.14-5.15) by tracing rays instead.

The transverse section of a barb is an infinite row of open elliptic arcs (semi-axes 1 and b,
outward normals at azimuths [phi_0, phi_1]) rotated by mu and spaced H along the barb plane
(:func:`barbule_row`, a :func:`~appearance_jax.flatland.section.ellipse_row`). Along the barbule,
each arc point sits on a circular arc of half-angle theta_d; it is not traced in 3D (a saddle
cell: it only tilts the normal), the ``"barbule"`` interface draws the longitudinal position
uniformly per hit and weights it by the flux it receives
(:func:`~appearance_jax.flatland.interfaces.barbule`). Rays are launched uniformly over one
period, so a tally divided by the number of rays is a fraction of the incident power per unit
barb-plane area.

Frames. The model's local frame (:mod:`appearance_jax.bsdf.rock_dove`): z = the barb-plane
normal n, y = the barbule axis, x across the barbules. Flatland's section frame: x = the axis,
(y, z) the section, the row along y: local (x, y, z) = section (y, x, z) (:func:`from_local`, its
own inverse).

:func:`feather_histogram` tallies what leaves the row by the number of events before it left:
0 = passed between the barbules (Huang's T, a delta at -w_i), 1 = one scattering (R or TRT
of the first hit; for ``saddle_mirror`` with reflectance 1 this estimates S_R with I_R = 1,
``rock_dove.reflection_geometry``), 2 = two or more. Bins are uniform in y_o (the sine of the
longitudinal angle) and in psi_o = atan2(x_o, z_o) in [-pi/2, pi/2], where the solid angle is
d y_o d psi_o: a bin's power / (N d y d psi) estimates S <w_o, n> averaged over the bin.

Example::

    import jax
    from appearance_jax.core.frame import spherical_direction
    from appearance_jax.flatland import feather
    sec = feather.barbule_row(0.25, -0.37, 2.64, 1.25, -0.35, 0.0785, mirror=1.0)
    h = feather.feather_histogram(sec, spherical_direction(0.5, 0.3), jax.random.PRNGKey(0), 2 ** 16)
    h.fraction  # (3, bands): passed, one scattering, more
"""

from __future__ import annotations

import math
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..core.params import check_int
from ..core.spectral import RGB_WAVELENGTHS
from ..core.vec import Vec3
from .section import Interface, Section, ellipse_row
from .tallies import _stratified_offsets
from .tracer import _trace, check_direction, n_bands

CLASSES = ("passed", "single", "multiple")


def from_local(w: Vec3) -> Vec3:
    """A direction of the model's local frame in flatland's section frame (and back: a swap)."""
    return Vec3(w.y, w.x, w.z)


def arc_range(b, phi0, phi1):
    """The arc of outward normal azimuths [phi0, phi1] (rock_dove's convention: from the ellipse's
    minor axis towards its major axis) as flatland's parametric range ``(lo, span)``."""
    g_hi = math.atan2(b * math.cos(phi0), math.sin(phi0))
    g_lo = math.atan2(b * math.cos(phi1), math.sin(phi1))
    return g_lo, (g_hi - g_lo) % (2.0 * math.pi)


def barbule_row(b, phi0, phi1, H, mu, theta_d, *, thickness_nm=590.0, eta=1.55, melanin=0.0604,
                wavelength_nm=RGB_WAVELENGTHS, mirror=None, copies=8) -> Section:
    """The row of barbule arcs of rock_dove's parameters (b, phi0, phi1, H, mu in its units; theta_d
    rad) with barbule interfaces: a keratin film of ``thickness_nm`` nm and index ``eta`` in air over
    melanin of diffuse reflectance ``melanin`` (per band at ``wavelength_nm``), or, with ``mirror``
    = a reflectance, film-free mirrors (no TRT). Concrete numbers only (the arc's range is computed
    eagerly); ``copies`` neighbours on each side are tested per event."""
    lo, span = arc_range(float(b), float(phi0), float(phi1))
    if mirror is not None:
        itf = Interface("saddle_mirror", tilt=jnp.asarray(theta_d, float), albedo=jnp.asarray(mirror, float))
    else:
        wl = jnp.asarray(wavelength_nm, float)
        itf = Interface("barbule", tilt=jnp.asarray(theta_d, float), albedo=jnp.broadcast_to(
            jnp.asarray(melanin, float), wl.shape), film_nm=jnp.asarray(thickness_nm, float),
            film_eta=jnp.asarray(eta, float), wavelength_nm=wl)
    # the ellipse's first axis (semi-axis 1) is the barbule frame's X = (cos mu, -sin mu) in (x, z)
    return ellipse_row(H, 1.0, b, psi=-mu, arc=(lo, span), interface=itf, copies=copies)


class FeatherHistogram(NamedTuple):
    """Tallies of :func:`feather_histogram`; classes as :data:`CLASSES`."""

    power: jax.Array       # (3, n_y, n_psi, bands): summed power per bin
    power_sq: jax.Array    # per-path squares (a path leaves once)
    n_paths: int
    y_edges: jax.Array     # (n_y + 1,) in [-1, 1]
    psi_edges: jax.Array   # (n_psi + 1,) in [-pi/2, pi/2]
    fraction: jax.Array    # (3, bands): fraction of the incident power per class (bins: upwards only)
    absorbed: jax.Array    # (bands,)
    lost: jax.Array        # (bands,) killed (facing tests)
    residual: jax.Array    # (bands,) still travelling after max_events
    truncated: jax.Array   # fraction of paths that may have missed shapes beyond `copies`

    def density(self):
        """(mean, stderr) of S <w_o, n> per bin (1/sr): power / (N bin solid angle)."""
        dy = jnp.diff(self.y_edges)[:, None, None]
        dpsi = jnp.diff(self.psi_edges)[None, :, None]
        n = self.n_paths
        mean = self.power / n
        var = jnp.maximum(self.power_sq / n - mean * mean, 0.0) / max(n - 1, 1)
        return mean / (dy * dpsi), jnp.sqrt(var) / (dy * dpsi)


@partial(jax.jit, static_argnames=("n_chunks", "chunk", "n_y", "n_psi", "max_events"))
def _feather(section, wi, key, n_chunks, chunk, n_y, n_psi, max_events):
    dtype = jnp.result_type(float)
    nb = n_bands(section)
    n_bins = 3 * n_y * n_psi
    ev = jnp.minimum(jnp.arange(max_events), 2)[:, None]  # event index -> class

    def one(carry, k):
        kh, kt = jax.random.split(k)
        rec = _trace(section, wi, _stratified_offsets(kh, chunk, dtype), kt, None, max_events, "random", False,
                     False)
        d = rec.direction                                   # section frame: x = axis = local y
        it = jnp.clip(jnp.floor((d.x + 1.0) * 0.5 * n_y).astype(jnp.int32), 0, n_y - 1)
        psi = jnp.arctan2(d.y, d.z)
        ip = jnp.clip(jnp.floor((psi / jnp.pi + 0.5) * n_psi).astype(jnp.int32), 0, n_psi - 1)
        up = d.z > 0                                        # emissions leave upwards or pass (T)
        w = jnp.where((up | (ev == 0))[..., None], rec.weight, 0.0)  # (E, N, nb)
        idx = ((ev * n_y + it) * n_psi + ip).reshape(-1)
        wf = w.reshape(-1, nb)
        out = dict(power=jax.ops.segment_sum(wf, idx, n_bins), power_sq=jax.ops.segment_sum(wf * wf, idx, n_bins),
                   fraction=jax.ops.segment_sum(rec.weight.reshape(-1, nb),
                                                jnp.broadcast_to(ev, w.shape[:2]).reshape(-1), 3),
                   absorbed=rec.absorbed.sum(0), lost=rec.lost.sum(0), residual=rec.residual.sum(0),
                   truncated=jnp.sum(rec.truncated.astype(dtype)))
        return jax.tree_util.tree_map(jnp.add, carry, out), None

    zero = dict(power=jnp.zeros((n_bins, nb), dtype), power_sq=jnp.zeros((n_bins, nb), dtype),
                fraction=jnp.zeros((3, nb), dtype), absorbed=jnp.zeros((nb,), dtype), lost=jnp.zeros((nb,), dtype),
                residual=jnp.zeros((nb,), dtype), truncated=jnp.zeros((), dtype))
    acc, _ = jax.lax.scan(one, zero, jax.random.split(key, n_chunks))
    n = n_chunks * chunk
    shape = (3, n_y, n_psi, nb)
    return FeatherHistogram(acc["power"].reshape(shape), acc["power_sq"].reshape(shape), n,
                            jnp.linspace(-1.0, 1.0, n_y + 1, dtype=dtype),
                            jnp.linspace(-0.5 * jnp.pi, 0.5 * jnp.pi, n_psi + 1, dtype=dtype),
                            acc["fraction"] / n, acc["absorbed"] / n, acc["lost"] / n, acc["residual"] / n,
                            acc["truncated"] / n)


def feather_histogram(section: Section, wi: Vec3, key, n_paths: int = 2 ** 16, *, n_y: int = 40,
                      n_psi: int = 36, max_events: int = 4, chunk: int = 2 ** 15) -> FeatherHistogram:
    """Trace ``n_paths`` rays from the local direction ``wi`` (model frame, towards the light,
    ``wi.z > 0``) over one period of the barbule row ``section`` (:func:`barbule_row`) and tally what
    leaves by class and direction (module docstring). ``max_events`` (static) bounds the events per
    ray; what is still bouncing after them is ``residual``."""
    section = section.validate()
    if not section.periodic:
        raise ValueError("flatland.feather_histogram needs a periodic row (flatland.feather.barbule_row)")
    check_direction("flatland.feather_histogram.wi", wi)
    if not float(wi.z) > 0:
        raise ValueError(f"flatland.feather_histogram: wi.z = {float(wi.z)}; the light must be above the "
                         "barb plane (wi.z > 0)")
    n_paths = check_int("flatland.feather_histogram.n_paths", n_paths, 1)
    chunk = min(check_int("flatland.feather_histogram.chunk", chunk, 1), n_paths)
    for name, v, lo in (("n_y", n_y, 1), ("n_psi", n_psi, 1), ("max_events", max_events, 2)):
        check_int(f"flatland.feather_histogram.{name}", v, lo)
    return _feather(section, from_local(wi), key, -(-n_paths // chunk), chunk, int(n_y), int(n_psi),
                    int(max_events))


def bin_average(f, wi: Vec3, hist: FeatherHistogram, k: int = 256, seed: int = 0):
    """What a model predicts for each bin of ``hist``: the mean of ``f(wi, wo) <w_o, n>`` over the bin and
    its standard error, from ``k`` jittered points per bin (numpy arrays ``(n_y, n_psi, bands)``), in
    the units of :meth:`FeatherHistogram.density`. ``f`` maps local directions (``Vec3`` of shape
    (m,)) to values ``(m,)`` or ``(m, bands)``, e.g. ``lambda wi, wo: rock_dove.eval(p, wi, wo)``. A bin
    that a lobe's hard edge cuts in a thin sliver needs many points: with 48, one bin of Huang's fit
    had none on the lobe (standard error 0) while 25 traced rays landed there."""
    ye, pe = np.asarray(hist.y_edges), np.asarray(hist.psi_edges)
    ny, npsi = len(ye) - 1, len(pe) - 1
    u = np.random.default_rng(seed).random((ny, npsi, k, 2))
    y = ye[:-1, None, None] + np.diff(ye)[:, None, None] * u[..., 0]
    psi = pe[None, :-1, None] + np.diff(pe)[None, :, None] * u[..., 1]
    r = np.sqrt(1.0 - y * y)
    wo = Vec3(*(jnp.asarray(v.ravel()) for v in (r * np.sin(psi), y, r * np.cos(psi))))
    w = Vec3(*(jnp.broadcast_to(jnp.asarray(c), wo.x.shape) for c in wi))
    v = np.asarray(f(w, wo)).reshape(ny, npsi, k, -1) * (r * np.cos(psi))[..., None]
    return v.mean(2), v.std(2, ddof=1) / math.sqrt(k)
