"""Tabulated phase function: any p(θ) given on a uniform grid of scattering angles, as a
registered phase-function model (measured phase functions; computed ones such as the rainbow
tables of :mod:`appearance_jax.flatland.rainbow`, Sadeghi 2011 Ch. 3, which are stored as
such tables in the thesis: "the phase function ... sampled ... and stored on disk", L1296).

    f(wi, wo) = v(θ) / Z,     cos θ = -(wi . wo),  θ in [0, pi] from the forward direction   [1/sr]

with ``v`` the piecewise-linear interpolation in θ of ``values`` on ``G`` equally spaced
angles ``θ_j = j pi / (G - 1)`` and ``Z = 2 pi ∫ v(θ) sin θ dθ`` computed exactly for that
interpolant, so the model integrates to 1 over the sphere whatever the table's scale
(a table in units of (1/πa²) dσ/dΩ, or any other, can be passed as is). Reciprocal (it
depends on θ only); no horizon.

| parameter | default            | range     | unit | meaning                                            |
|-----------|--------------------|-----------|------|----------------------------------------------------|
| values    | isotropic (2 rows) | [0, inf)  | any  | p(θ_j), shape (G,) or (G, bands), G >= 2, not all 0 |

Sampling: bins between grid angles, piecewise constant in cos θ inside a bin with the
bin's exact probability (mixed with 1 % of the uniform density so that no direction has zero
density); ``pdf()`` is that density and ``weight = f / pdf`` per band: unbiased for any table.
Band-valued tables are sampled with the band mean.

Example::

    import numpy as np
    from appearance_jax.phase import tabulated
    th = np.linspace(0, np.pi, 181)
    p = tabulated.Params(values=1 + np.cos(th) ** 2)     # Rayleigh, normalised by the model
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..core.model import Model, boundary, with_bands
from ..core.params import Real, param, params_class
from ..core.vec import dot
from . import binned

@params_class
class Params:
    # a table, not a per-band scalar: its first axis is the angle grid, its optional second the bands
    values: Real = param((1.0, 1.0), lo=0.0, unit="any", doc="p at G equally spaced angles in [0, pi]; (G,) or (G, bands)")

    def _validate(self):
        v = np.asarray(self.values, float)
        if v.ndim == 0 or v.shape[0] < 2:
            raise ValueError(f"tabulated.Params.values has shape {v.shape}: it needs >= 2 angles on its first axis")
        if v.ndim > 2:
            raise ValueError(f"tabulated.Params.values has shape {v.shape}: valid shapes (G,) or (G, bands)")
        if np.any(np.sum(v.reshape(v.shape[0], -1), axis=0) <= 0):
            raise ValueError("tabulated.Params.values: a band is zero everywhere (it cannot be normalised)")


def _table(p: Params):
    v = jnp.asarray(p.values)
    return v if v.ndim == 2 else v[:, None]  # (G, B)


def _bin_integrals(G, dtype):
    """Per bin j (θ_j .. θ_j+1): ∫ w0(θ) sinθ dθ and ∫ w1(θ) sinθ dθ for the two hat halves."""
    h = np.pi / (G - 1)
    t0 = np.arange(G - 1) * h
    t1 = t0 + h
    # ∫ (θ1 - θ)/h sinθ and ∫ (θ - θ0)/h sinθ over [θ0, θ1], in closed form
    c0, c1, s0, s1 = np.cos(t0), np.cos(t1), np.sin(t0), np.sin(t1)
    a = c0 - (s1 - s0) / h  # weight of the left node
    b = -c1 + (s1 - s0) / h  # weight of the right node
    return jnp.asarray(a, dtype), jnp.asarray(b, dtype)


def _normaliser(v):
    a, b = _bin_integrals(v.shape[0], v.dtype)
    mass = a[:, None] * v[:-1] + b[:, None] * v[1:]  # ∫ v sinθ dθ per bin and band
    return 2.0 * jnp.pi * jnp.sum(mass, axis=0), mass


def _value(v, cos_t):
    G = v.shape[0]
    theta = jnp.arccos(jnp.clip(cos_t, -1.0, 1.0))
    u = theta * ((G - 1) / jnp.pi)
    j = jnp.clip(jnp.floor(u).astype(jnp.int32), 0, G - 2)
    w = (u - j)[..., None]
    return v[j] * (1.0 - w) + v[j + 1] * w


def _eval(p: Params, wi, wo):
    v = _table(p)
    z, _ = _normaliser(v)
    return _value(v, -dot(wi, wo)) / z


def _sampling(v):
    """Bin edges in mu (the grid's, decreasing) and probabilities of the band-mean table."""
    _, mass = _normaliser(v)
    edges = jnp.cos(jnp.linspace(0.0, jnp.pi, v.shape[0], dtype=v.dtype))
    return edges, binned.probabilities(jnp.mean(mass / jnp.sum(mass, axis=0), axis=-1), edges)


def _pdf(p: Params, wi, wo):
    edges, prob = _sampling(_table(p))
    return binned.density(edges, prob, -dot(wi, wo))


def _sample(p: Params, wi, u):
    v = _table(p)
    edges, prob = _sampling(v)
    wo, c = binned.sample(edges, prob, wi, u)
    pdf = binned.density(edges, prob, c)
    z, _ = _normaliser(v)
    return wo, _value(v, c) / z / with_bands(pdf), pdf


eval = boundary(_eval, Params)
pdf = boundary(_pdf, Params)
sample = boundary(_sample, Params)


def _preset_rayleigh():
    th = np.linspace(0.0, np.pi, 361)
    return Params(values=1.0 + np.cos(th) ** 2)


def _preset_two_lobes():
    th = np.linspace(0.0, np.pi, 721)
    fwd = np.exp(-0.5 * (th / 0.15) ** 2)
    back = 0.05 * np.exp(-0.5 * ((th - np.radians(138.0)) / 0.03) ** 2)  # a narrow bow-like lobe
    return Params(values=np.stack([fwd + back, 0.5 * fwd + back + 0.01, fwd + 0.002], axis=-1))


MODEL = Model(
    name="tabulated_phase",
    kind="phase",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="phase function tabulated on a uniform grid of scattering angles (normalised exactly; e.g. rainbow tables)",
    source="this library; the thesis stores its rainbow phase functions as tables (Sadeghi 2011 L1296)",
    reciprocal=True,
    transmissive=True,
    presets={"rayleigh": _preset_rayleigh(), "two_lobes_rgb": _preset_two_lobes()},
)
