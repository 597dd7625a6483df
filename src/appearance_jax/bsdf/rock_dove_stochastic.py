"""The rock-dove barbule BSDF with Huang's stochastic TRT: one random lit point per evaluation.

:func:`appearance_jax.bsdf.rock_dove.eval` integrates the TRT term's rho (Huang Eq. 5.17)
with a deterministic quadrature (smooth and differentiable, for fits). Huang's renderer instead
draws one random surface point per evaluation ([T:1708-1733]: an offset h across the lit arc and
a longitudinal offset l); this module is that estimator, unbiased for the same S:

    S_R exact (Huang Eq. 5.14, as rock_dove.eval),
    S_TRT ~ f V_o(w_m) I_TRT(<w_i, w_m>, <w_o, w_m>) / pi,        f = Delta h' / Delta h,

with w_m drawn from the visible normals lit from w_i: h uniform over the lit projected length
(Delta h'), theta_m from its conditional law given h (uniform in the projected longitudinal
offset l seen from w_i), exactly as :func:`rock_dove.sample` draws its mirror normal;
V_o = 1 where that point also sees w_o (faces it and its ray misses the neighbours). Since
``rho = <w_i, n> f E[V_o I_TRT]`` (the visible-normal density restricted to the lit arc is
``D <w_i, w_m> / (<w_i, n> f)``), E[S_TRT estimate] = rho / (pi <w_i, n>) = the deterministic
S_TRT at infinitely many nodes. One draw costs one visibility pass from w_i (as sampling) and
one film evaluation instead of ``n_phi * n_theta``.

Example::

    import jax
    from appearance_jax.bsdf import rock_dove, rock_dove_stochastic
    from appearance_jax.core.frame import spherical_direction
    p = rock_dove.Params()
    wi, wo = spherical_direction(0.3, 0.0), spherical_direction(0.4, 3.0)
    f = rock_dove_stochastic.eval(p, wi, wo, jax.random.PRNGKey(0))  # (3,) 1/sr, one draw
"""

from __future__ import annotations

import jax.numpy as jnp

from ..core import vec as V
from ..core.model import boundary, with_bands
from ..core.rng import uniforms
from ..core.special import atan2
from ..core.vec import Vec3
from . import rock_dove as rd


def _s_trt(p: rd.Params, wi: Vec3, bi: Vec3, bo: Vec3, key):
    """One-draw estimate of S_TRT (bands last); ``p`` already limited by ``_arc_within_pi``, ``bi``, ``bo``
    the directions in the barbule frame."""
    uh, ut = uniforms(key, jnp.shape(wi.z), 2)
    mirror, any_lit = rd._sample_mirror(p, bi, uh, ut)
    m = V.normalize(bi + mirror)  # the drawn normal (barbule frame)
    cos_i = jnp.clip(V.dot(bi, m), 0.0, 1.0)
    cos_o = V.dot(bo, m)
    dxo, dzo, _, _ = rd._transverse(bo)
    sees = rd._sees(p, atan2(m.x, m.z), dxo, dzo) & (cos_o > 0) & any_lit & (wi.z > 0)
    f = rd.valid_fraction(p, wi)
    trt = rd.film_trt(p, cos_i, jnp.clip(cos_o, 0.0, 1.0))
    return jnp.where(with_bands(sees), with_bands(f / jnp.pi) * trt, 0.0)


def _eval(p: rd.Params, wi: Vec3, wo: Vec3, key):
    p = rd._arc_within_pi(p)
    bi, bo = rd.to_barbule(p, wi), rd.to_barbule(p, wo)
    f = rd._s_r(p, wi, wo, bi, bo) + _s_trt(p, wi, bi, bo, key)
    ok = (wi.z > 0) & (wo.z > 0)
    return jnp.where(with_bands(ok), f, 0.0)


def _trt(p: rd.Params, wi: Vec3, wo: Vec3, key):
    p = rd._arc_within_pi(p)
    ok = (wi.z > 0) & (wo.z > 0)
    return jnp.where(with_bands(ok), _s_trt(p, wi, rd.to_barbule(p, wi), rd.to_barbule(p, wo), key), 0.0)


#: S_R + a one-draw S_TRT (1/sr, ``wi.shape + (bands,)``); ``key``: a PRNG key (one draw per pair)
eval = boundary(_eval, rd.Params)
#: the one-draw S_TRT alone (1/sr, bands last)
trt = boundary(_trt, rd.Params)
