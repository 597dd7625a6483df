"""Cloth weave families with few parameters, for fitting :mod:`appearance_jax.bsdf.cloth` to measured BRDFs.

:mod:`appearance_jax.bsdf.cloth` takes whole tangent curves (offsets and lengths per family): flexible, but a
least-squares fit of every control point of an isotropic measurement is degenerate. Here a
weave *family* fixes the shape of the curves and the coverages, and one angle ``alpha`` (the
largest tangent offset) scales them; the two thread families keep their own thread
parameters (Table 5.1: albedo, k_d, gamma_s, gamma_v; a shared eta).

=======  =========================================================  ==============  =========
weave    family 1 (along the surface tangent x)                     family 2 (y)    coverage
=======  =========================================================  ==============  =========
plain    ramp {-a, a} (Linen, Table E.1)                            ramp {-a, a}    0.5, 0.5
satin    flat at -a, 0, +a with knees at +-0.5625 a (Polyester      straight {0,0}  0.9, 0.1
         Satin Charmeuse front, Table E.1: a = 32, knee 18 deg)
twill    :func:`.weave.twill` over 2 (this library's twill curve)   ramp {-a, a}    2/3, 1/3
=======  =========================================================  ==============  =========

``n_rotations`` (default 8) averages over the weave rotated by 360 k / K deg
(:func:`.model._rotation_average`): a measurement that assumes isotropy, such as MERL's (the
fabric is wrapped around a sphere or cylinder and every orientation is seen), is compared
with the orientation-averaged model. The BRDF form and the energy gate are those of
:mod:`appearance_jax.bsdf.cloth` (``eval`` = R / N.w_i, 1/sr).

| parameter        | default | range      | unit | meaning                                  |
|------------------|---------|------------|------|------------------------------------------|
| eta              | 1.46    | [1, 3]     | 1    | refractive index of both thread families |
| albedo_1, _2     | 0.3     | [0, 1]     | 1    | A per band (Eq. 5.9)                      |
| k_d_1, _2        | 0.3     | [0, 1]     | 1    | isotropic volume fraction                |
| gamma_s_1, _2    | 8       | [0.5, 60]  | deg  | surface Gaussian std (Eq. 5.7)           |
| gamma_v_1, _2    | 16      | [0.5, 90]  | deg  | volume Gaussian std (Eq. 5.9)            |
| alpha            | 25      | [0, 80]    | deg  | largest tangent offset of the weave      |
| weave            | "satin" | plain, satin, twill | - | the family (table above)            |
| n_rotations      | 8       | [1, 64]    | -    | orientation average (1 = the weave as is) |
| n_samples        | 16      | [1, 1024]  | -    | T, samples per tangent curve             |

Example::

    from appearance_jax.bsdf.cloth import weaves as cloth_weaves
    p = cloth_weaves.Params(weave="twill", alpha=20.0)
    f = cloth_weaves.eval(p, wi, wo)            # (..., bands), 1/sr
    q = cloth_weaves.to_cloth(p)                # the equivalent cloth.Params
"""

from __future__ import annotations

import jax.numpy as jnp

from ...core.model import Model, boundary
from ...core.params import Bands, integer, param, params_class, Real, static
from . import model, weave

KNEE_RATIO = 18.0 / 32.0  # Polyester Satin Charmeuse front (Table E.1): knee 18 deg of 32


def _curves(kind: str, a):
    if kind == "plain":
        return [weave.plain(a), weave.plain(a)], (0.5, 0.5)
    if kind == "satin":
        return [weave.satin(alpha=a, knee=KNEE_RATIO * a), weave.straight()], (0.9, 0.1)
    return [weave.twill(a, over=2), weave.plain(a)], weave.twill_coverage(2, 1)


@params_class
class Params:
    eta: Real = param(1.46, lo=1.0, hi=3.0, unit="1", doc="refractive index of the threads")
    albedo_1: Bands = param(0.3, lo=0.0, hi=1.0, unit="1", doc="albedo A of family 1, per band", bands=True)
    albedo_2: Bands = param(0.3, lo=0.0, hi=1.0, unit="1", doc="albedo A of family 2, per band", bands=True)
    k_d_1: Real = param(0.3, lo=0.0, hi=1.0, unit="1", doc="isotropic volume fraction of family 1")
    k_d_2: Real = param(0.3, lo=0.0, hi=1.0, unit="1", doc="isotropic volume fraction of family 2")
    gamma_s_1: Real = param(8.0, lo=0.5, hi=60.0, unit="deg", doc="surface lobe std of family 1")
    gamma_s_2: Real = param(8.0, lo=0.5, hi=60.0, unit="deg", doc="surface lobe std of family 2")
    gamma_v_1: Real = param(16.0, lo=0.5, hi=90.0, unit="deg", doc="volume lobe std of family 1")
    gamma_v_2: Real = param(16.0, lo=0.5, hi=90.0, unit="deg", doc="volume lobe std of family 2")
    alpha: Real = param(25.0, lo=0.0, hi=80.0, unit="deg", doc="largest tangent offset of the weave")
    weave: str = static("satin", choices=("plain", "satin", "twill"), doc="weave family")
    n_rotations: int = static(8, convert=integer(1, 64), doc="orientation average (1 = off)")
    n_samples: int = static(16, convert=integer(1, 1024), doc="T, samples per tangent curve")


def to_cloth(p: Params) -> model.Params:
    """The :class:`.model.Params` of this weave (works on traced values inside jit)."""
    curves, coverage = _curves(p.weave, p.alpha)
    albedo = jnp.stack(jnp.broadcast_arrays(jnp.atleast_1d(p.albedo_1), jnp.atleast_1d(p.albedo_2)))
    pair = lambda a, b: jnp.stack(jnp.broadcast_arrays(jnp.asarray(a), jnp.asarray(b)))  # noqa: E731
    return model.from_weave(curves, coverage, eta=p.eta, albedo=albedo, k_d=pair(p.k_d_1, p.k_d_2),
                            gamma_s=pair(p.gamma_s_1, p.gamma_s_2), gamma_v=pair(p.gamma_v_1, p.gamma_v_2),
                            n_samples=p.n_samples, n_rotations=p.n_rotations)


def _eval(p: Params, wi, wo):
    return model.eval.kernel(to_cloth(p), wi, wo)


def _pdf(p: Params, wi, wo):
    return model.pdf.kernel(to_cloth(p), wi, wo)


def _sample(p: Params, wi, u):
    return model.sample.kernel(to_cloth(p), wi, u)


eval = boundary(_eval, Params)
pdf = boundary(_pdf, Params)
sample = boundary(_sample, Params)

MODEL = Model(
    name="cloth_weave",
    kind="bsdf",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="Sadeghi's cloth with a plain/satin/twill weave scaled by one angle, orientation-averaged",
    source="Sadeghi 2011 Ch. 5 and App. E (weave shapes), this library (families, averaging)",
    reciprocal=False,
    band_separable=True,
)
