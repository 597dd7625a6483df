"""A whole feather as one textured surface (Padrón 2025 §5.6.2 [T:889, 982, 998]; spec seed-000 M25,
"Texture encoding"): each texel's mask chooses what the surface is there.

- **vane** (:data:`~appearance_jax.bsdf.feather_texture.VANE`): Padrón's feather BSDF, Eq. 5.4
  (:mod:`appearance_jax.bsdf.feather`), with the barb frame turned by the texel's angle (texture R);
- **shaft** (:data:`~appearance_jax.bsdf.feather_texture.SHAFT`, the rachis): a coloured diffuse
  surface [T:982] ("we assume that the diffuse scattering medulla is dominant"), on both faces:
  f = albedo / pi where wi and wo lie on the same side of the surface, 0 otherwise; its albedo defaults
  to the barb medulla's d_m;
- **background** (:data:`~appearance_jax.bsdf.feather_texture.BACKGROUND`): no feather, a null
  surface: f = 0 and all light passes straight on (transmission 1).

Texels are the decoded texture (:func:`~appearance_jax.bsdf.feather_texture.decode_rgb8` or
:func:`~appearance_jax.bsdf.feather_texture.rasterize`): ``angle`` (rad) and ``mask`` (int) arrays that
broadcast with the directions. The texture's (x, y) are the shading frame's (x, y) (its normal z), so the
texel angle is the feather's ``barb_angle``. The barb length (texture G) does not enter the BSDF.

``eval`` returns ``(value, stderr)`` as :func:`feather.eval <appearance_jax.bsdf.feather.eval>` (the
vane is a Monte Carlo estimate; the shaft and the background are exact: stderr 0). ``transmission`` is
the mass of the straight-through delta wo = -wi. ``sample_events`` draws one event per texel:
the vane's four (:data:`feather.EVENTS <appearance_jax.bsdf.feather.EVENTS>`), :data:`SHAFT_EVENT`
(a cosine-distributed wo on the viewer's side, weight = albedo) or, on the background, the straight
pass (event 3, weight 1).

Example::

    import numpy as np
    from appearance_jax.bsdf import feather, feather_surface, feather_texture as ft
    angle, length, mask = ft.decode_rgb8(rgb8_image, max_length=40.0)
    f, se = feather_surface.eval(feather.Params(), angle, mask, wi, wo)   # (h, w, bands)
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..core import warp
from ..core.params import replace_unchecked
from ..core.vec import as_directions, Vec3
from . import feather
from .feather_texture import BACKGROUND, SHAFT, VANE

#: the event of :func:`sample_events` on a shaft texel (0-3 are ``feather.EVENTS``)
SHAFT_EVENT = 4


def _texels(angle, mask):
    """Eager checks of concrete texels; traced ones pass."""
    if not isinstance(mask, jax.core.Tracer):
        m = np.asarray(mask)
        if not (np.issubdtype(m.dtype, np.integer) or np.all(m == np.round(m))) or \
                np.any((m != BACKGROUND) & (m != SHAFT) & (m != VANE)):
            bad = m[(m != BACKGROUND) & (m != SHAFT) & (m != VANE)].ravel()[:3].tolist()
            raise ValueError(f"feather_surface: mask holds {bad}: valid values {BACKGROUND} (background), "
                             f"{SHAFT} (shaft), {VANE} (vane)")
    if not isinstance(angle, jax.core.Tracer):
        a = np.asarray(angle, dtype=np.float64)
        if np.any(~np.isfinite(a)) or np.any(np.abs(a) > 2 * math.pi):
            raise ValueError(f"feather_surface: angle holds {a[~(np.abs(a) <= 2 * math.pi)].ravel()[:3].tolist()}"
                             " rad: valid range [-2 pi, 2 pi] (texture R, decoded)")
    return jnp.asarray(angle, jnp.result_type(float)), jnp.asarray(mask, jnp.int32)


def _albedo(p, shaft_albedo):
    a = p.medulla_albedo if shaft_albedo is None else shaft_albedo
    return jnp.atleast_1d(jnp.asarray(a, jnp.result_type(float)))


def _check_albedo(shaft_albedo):
    if shaft_albedo is not None and not isinstance(shaft_albedo, jax.core.Tracer):
        a = np.asarray(shaft_albedo, dtype=np.float64)
        if a.ndim > 1 or np.any(~(a >= 0)) or np.any(a > 1):
            raise ValueError(f"feather_surface: shaft_albedo = {a.tolist()}: a scalar or one value per band "
                             "in [0, 1]")


@jax.jit
def _dispatch_eval(p, mask, f, se, wi: Vec3, wo: Vec3, shaft_albedo):
    same_side = (wi.z * wo.z > 0)[..., None]
    diffuse = jnp.where(same_side, _albedo(p, shaft_albedo) / math.pi, 0.0)
    m = mask[..., None]
    value = jnp.where(m == VANE, f, jnp.where(m == SHAFT, diffuse, 0.0))
    return value, jnp.where(m == VANE, se, 0.0)


@jax.jit
def _dispatch_transmission(mask, t, wi: Vec3):
    return jnp.where(mask == VANE, t, jnp.where(mask == BACKGROUND, jnp.where(wi.z != 0, 1.0, 0.0), 0.0))


@jax.jit
def _dispatch_sample(p, mask, wi: Vec3, wo_v: Vec3, w_v, ev_v, key, shaft_albedo):
    shape = ev_v.shape
    u1, u2 = jax.random.uniform(jax.random.fold_in(key, 1), (2,) + shape, jnp.result_type(float))
    d = warp.square_to_cosine_hemisphere(u1, u2)
    wi_b = Vec3(*(jnp.broadcast_to(c, shape) for c in wi))
    wo_s = Vec3(d.x, d.y, jnp.where(wi_b.z < 0, -d.z, d.z))
    w_s = jnp.where((wi_b.z != 0)[..., None], jnp.broadcast_to(_albedo(p, shaft_albedo), w_v.shape), 0.0)
    m = jnp.broadcast_to(mask, shape)
    vane, shaft = m == VANE, m == SHAFT
    pick = lambda a, b, c: jnp.where(vane, a, jnp.where(shaft, b, c))  # noqa: E731
    wo = Vec3(*(pick(a, b, -c) for a, b, c in zip(wo_v, wo_s, wi_b)))
    weight = jnp.where(vane[..., None], w_v,
                       jnp.where(shaft[..., None], w_s, jnp.where((wi_b.z != 0)[..., None], 1.0, 0.0)))
    return wo, weight, pick(ev_v, SHAFT_EVENT, 3)


# The vane runs feather's own compiled programs (shared with direct calls of the same shapes); the mask's
# dispatch is a small program of its own. Every texel runs the vane (branch-free, as a renderer's wavefront).


def eval(params, angle, mask, wi, wo, key=None, *, shaft_albedo=None):
    """f(wi, wo) of the texels ``(angle, mask)`` without the delta (1/sr, bands last) and its standard
    error (module docstring). ``shaft_albedo``: the rachis' diffuse albedo per band (default: the
    medulla's d_m); ``key``: the vane estimator's (default fixed)."""
    _check_albedo(shaft_albedo)
    angle, mask = _texels(angle, mask)
    wi, wo = as_directions(wi=wi, wo=wo)
    # feather.eval validates the parameters; the key is passed only when given (an explicit None is
    # another signature of feather.eval's compiled program: a second compile)
    f, se = feather.eval(replace_unchecked(params, barb_angle=angle), wi, wo, *(() if key is None else (key,)))
    return _dispatch_eval(params, mask, f, se, wi, wo, shaft_albedo)


def transmission(params, angle, mask, wi):
    """The mass of the straight-through delta wo = -wi per texel: the vane's w_t(wi), 0 on the shaft,
    1 on the background (0 for a grazing wi)."""
    angle, mask = _texels(angle, mask)
    (wi,) = as_directions(wi=wi)
    # (feather.transmission validates the parameters)
    return _dispatch_transmission(mask, feather.transmission(replace_unchecked(params, barb_angle=angle), wi), wi)


def sample_events(params, angle, mask, wi, key, *, shaft_albedo=None):
    """``(wo, weight, event)`` per texel: E[weight g(wo)] = int f |wo . n| g dwo + transmission g(-wi) for
    any g (module docstring; events 0-3 as ``feather.sample_events``, 4 = the shaft's diffuse bounce)."""
    _check_albedo(shaft_albedo)
    angle, mask = _texels(angle, mask)
    wi = feather._checked(params, wi, key, "feather_surface.sample_events")  # validates the parameters
    # feather.sample_events' compiled program, without checking the same arguments again
    wo, w, _, ev = feather._draw_jit(replace_unchecked(params, barb_angle=angle), wi, key, True)
    return _dispatch_sample(params, mask, wi, wo, w, ev, key, shaft_albedo)
